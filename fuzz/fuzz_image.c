/* libFuzzer target: the image-loading path (core/image_io.cpp) as glTF
 * textures reach it: dr_image_read_memory, then dr_image_make_linear and a
 * texture lookup (core/image.c).
 *
 * The first input byte picks the name hint (and so the decoder when the
 * magic bytes do not): byte % N_HINTS indexes hints[] below; the rest is the
 * encoded file. Note: OpenImageIO and the codec libraries are the system's
 * uninstrumented shared libraries, so libFuzzer sees coverage only in our
 * wrapper and ASan checks only what crosses into instrumented code. */
#include "fuzz_common.h"
#include "image.h"
#include "image_io.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* (the formats after "image/png" were added later: the older inputs' first
 * bytes are all below 14, so they still pick what they picked) */
#define N_HINTS 26
static const char *const hints[N_HINTS] = {
    "fuzz",   "x.png", "x.jpg",  "x.exr", "x.hdr",  "x.tif", "x.bmp", "x.tga", "x.pfm",
    "x.ppm",  "x.gif", "x.psd",  "x.dds", "image/png", "x.dpx", "x.fits", "x.iff", "x.sgi",
    "x.rla",  "x.ico", "x.webp", "x.jp2", "x.pnm", "x.heic", "x.cin", "x.pic"};

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_setup();
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    struct dr_image img = {0};
    if (dr_image_read_memory(data + 1, size - 1, hints[data[0] % N_HINTS], &img) == 0) {
        if (img.width <= 0 || img.height <= 0 || img.channels < 1 || img.channels > 4 || !img.data)
            abort();   /* the reader's contract */
        if (dr_image_make_linear(&img) == 0) {
            struct dr_texture tex = {0, DR_WRAP_REPEAT, DR_WRAP_MIRROR};
            double out[4];
            dr_texture_eval(&tex, &img, 0.3, -1.7, true, out);
        }
    }
    dr_image_release(&img);
    return 0;
}
