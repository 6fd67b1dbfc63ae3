/* The fuzz/corpus/gltf inputs (seeds and regress-* crashers) replayed through
 * fuzz/fuzz_gltf.c without libFuzzer; see tests/fuzz_driver.h. */
#include "../fuzz/fuzz_gltf.c"
#include "fuzz_driver.h"

DR_FUZZ_DRIVER("gltf")
