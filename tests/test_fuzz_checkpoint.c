/* The fuzz/corpus/checkpoint inputs (seeds and regress-* crashers) replayed through
 * fuzz/fuzz_checkpoint.c without libFuzzer; see tests/fuzz_driver.h. */
#include "../fuzz/fuzz_checkpoint.c"
#include "fuzz_driver.h"

DR_FUZZ_DRIVER("checkpoint")
