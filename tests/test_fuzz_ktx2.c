/* The fuzz/corpus/ktx2 inputs (seeds and regress-* crashers) replayed through
 * fuzz/fuzz_ktx2.c without libFuzzer; see tests/fuzz_driver.h. */
#include "../fuzz/fuzz_ktx2.c"
#include "fuzz_driver.h"

DR_FUZZ_DRIVER("ktx2")
