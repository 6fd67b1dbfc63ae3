/* The fuzz/corpus/image inputs (seeds and regress-* crashers) replayed through
 * fuzz/fuzz_image.c without libFuzzer; see tests/fuzz_driver.h. */
#include "../fuzz/fuzz_image.c"
#include "fuzz_driver.h"

DR_FUZZ_DRIVER("image")
