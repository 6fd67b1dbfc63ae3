/* The fuzz/corpus/cli inputs (seeds and regress-* crashers) replayed through
 * fuzz/fuzz_cli.c without libFuzzer; see tests/fuzz_driver.h. */
#include "../fuzz/fuzz_cli.c"
#include "fuzz_driver.h"

DR_FUZZ_DRIVER("cli")
