/* libFuzzer target: drender's own KTX2 reader (core/ktx2.c) as a glTF
 * texture reaches it: dr_ktx2_probe, dr_ktx2_read8, then the lookups a
 * render makes (dr_image_make_linear, a texture lookup). All of it is
 * instrumented code: the header checks, the level index, Zstandard and zlib
 * (the system's libraries, uninstrumented), the orientation key and the
 * texel placement. */
#include "fuzz_common.h"
#include "image.h"
#include "ktx2.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_setup();
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char why[320];
    const int probe = dr_ktx2_probe(data, size, why, sizeof why);
    struct dr_image img;
    const int rc = dr_ktx2_read8(data, size, "fuzz.ktx2", &img);
    if (rc == 0) {
        /* the reader's contract: a probe that refuses means a read that does */
        if (probe != 0 || img.width <= 0 || img.height <= 0 || (img.channels != 3 && img.channels != 4) ||
            !img.bytes || !img.lut)
            abort();
        if (dr_image_make_linear(&img) == 0) {
            struct dr_texture tex = {0, DR_WRAP_REPEAT, DR_WRAP_MIRROR};
            double out[4];
            dr_texture_eval(&tex, &img, 0.3, -1.7, true, out);
        }
    } else if (img.bytes || img.lut || img.width) {
        abort();   /* a refusal leaves nothing */
    }
    dr_image_release(&img);
    return 0;
}
