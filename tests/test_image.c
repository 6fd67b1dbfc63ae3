/* Tests for core/image.c (sRGB curves, texture lookup) and core/image_io.cpp
 * (reading and writing through OpenImageIO). */
#include <dirent.h>
#include <errno.h>
#include <ftw.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "error.h"
#include "image.h"
#include "image_io.h"
#include "image_plugin.h"
#include "test.h"

#if defined(__SANITIZE_ADDRESS__)
/* OpenImageIO 2.4's PNG reader leaks a std::string when libpng longjmps out
 * of PNGInput::PngReadCallback on a truncated file (the corrupt-file cases
 * below). Not ours to fix. Matching the frame needs full stacks at malloc
 * (libstdc++ has no frame pointers). */
const char *__asan_default_options(void);
const char *__asan_default_options(void) { return "fast_unwind_on_malloc=0"; }
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void) { return "leak:PngReadCallback\n"; }
#endif

static char tmpdir[256];

static void path_in_tmp(char *buf, size_t size, const char *name)
{
    snprintf(buf, size, "%s/%s", tmpdir, name);
}

static int count_entries(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, ".."))
            n++;
    closedir(d);
    return n;
}

/* Number of entries whose name contains `needle`. */
static int count_matching(const char *dir, const char *needle)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        if (strstr(e->d_name, needle))
            n++;
    closedir(d);
    return n;
}

static unsigned char *slurp(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    unsigned char *buf = NULL;
    size_t cap = 0, n = 0;
    for (;;) {
        if (n == cap) {
            cap = cap ? 2 * cap : 65536;
            unsigned char *nb = realloc(buf, cap);
            if (!nb) {
                free(buf);
                fclose(f);
                return NULL;
            }
            buf = nb;
        }
        size_t k = fread(buf + n, 1, cap - n, f);
        n += k;
        if (k == 0)
            break;
    }
    fclose(f);
    *size = n;
    return buf;
}

static bool file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static int rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st;
    (void)flag;
    (void)ftw;
    return remove(path);
}

static bool zeroed(const struct dr_image *img)
{
    return img->width == 0 && img->height == 0 && img->channels == 0 && !img->data &&
           !img->linear && !img->file_is_srgb && !img->bytes && !img->lut && !img->lut_linear && !img->linear_in_data;
}

/* ------------------------------------------------------------------------ */

static void test_srgb_curves(void)
{
    CHECK_NEAR(dr_linear_to_srgb(0.5), 0.7353569830524495, 1e-12, "linear 0.5 -> sRGB");
    CHECK_NEAR(dr_linear_to_srgb(0.0), 0.0, 0.0, "linear 0");
    CHECK_NEAR(dr_linear_to_srgb(1.0), 1.0, 1e-12, "linear 1");
    CHECK_NEAR(dr_srgb_to_linear(1.0), 1.0, 1e-12, "sRGB 1");
    CHECK_NEAR(dr_srgb_to_linear(0.5), 0.21404114048223255, 1e-12, "sRGB 0.5 -> linear");
    CHECK_NEAR(dr_srgb_to_linear(0.02), 0.02 / 12.92, 1e-15, "linear segment");
    CHECK_NEAR(dr_linear_to_srgb(0.001), 0.01292, 1e-15, "linear segment");
    /* Continuity at the thresholds (the standard's constants leave ~1e-7). */
    double t = 0.0031308;
    CHECK_NEAR(dr_linear_to_srgb(t), dr_linear_to_srgb(nextafter(t, 1.0)), 1e-6,
               "linear_to_srgb continuity");
    double s = 0.04045;
    CHECK_NEAR(dr_srgb_to_linear(s), dr_srgb_to_linear(nextafter(s, 1.0)), 1e-6,
               "srgb_to_linear continuity");
    /* Round trips, and monotonicity. */
    double worst = 0.0, prev = -1.0;
    bool mono = true;
    for (int i = 0; i <= 1000; ++i) {
        double x = i / 1000.0;
        double y = dr_linear_to_srgb(x);
        worst = fmax(worst, fabs(dr_srgb_to_linear(y) - x));
        worst = fmax(worst, fabs(dr_linear_to_srgb(dr_srgb_to_linear(x)) - x));
        if (y < prev)
            mono = false;
        prev = y;
    }
    CHECK(worst < 1e-12, "round trip error %g", worst);
    CHECK(mono, "linear_to_srgb not monotonic");
}

/* 3x2 single-channel image:  row 0 (top): 0  1  2
 *                            row 1:       10 20 40 */
static const float grid[6] = {0, 1, 2, 10, 20, 40};

static double eval1(enum dr_wrap ws, enum dr_wrap wt, double u, double v)
{
    struct dr_image img = {.width = 3, .height = 2, .channels = 1, .data = (float *)grid, .file_is_srgb = false};
    struct dr_texture tex = {0, ws, wt};
    double out[4];
    dr_texture_eval(&tex, &img, u, v, false, out);
    CHECK(out[0] == out[1] && out[1] == out[2], "grey not replicated");
    CHECK(out[3] == 1.0, "alpha of a 1-channel image: %g", out[3]);
    return out[0];
}

/* dr_image_make_linear remembers each 8-bit level's decoded value: the
 * result must still be dr_srgb_to_linear of every stored value, bit for
 * bit, for 8-bit levels, for values between levels (same nearest level,
 * different input), out of range and NaN; alpha kept. */
static void test_make_linear_exact(void)
{
    enum { N = 600 };
    float *data = malloc(sizeof(float) * N * 4);
    for (int i = 0; i < N; i++) {
        float v = i < 256 ? (float)i / 255.0f                       /* the levels */
                  : i < 512 ? (float)(i - 256) / 255.0f + 1e-4f      /* near them */
                  : i == 512 ? -0.25f : i == 513 ? 1.5f : i == 514 ? NAN : (float)(i % 7) * (1.0f / 255.0f);
        data[4 * i] = v;
        data[4 * i + 1] = 1.0f - v;
        data[4 * i + 2] = (float)((i * 37) % 256) * (1.0f / 255.0f);   /* another rounding of k/255 */
        data[4 * i + 3] = 0.5f;
    }
    struct dr_image img = {.width = N, .height = 1, .channels = 4, .data = data, .file_is_srgb = true};
    CHECK(dr_image_make_linear(&img) == DR_OK, "make_linear");
    int bad = 0;
    for (int i = 0; i < N * 4 && img.linear; i++) {
        float want = i % 4 == 3 ? data[i] : (float)dr_srgb_to_linear(data[i]);
        if (memcmp(&want, &img.linear[i], sizeof want) != 0)
            bad++;
    }
    CHECK(img.linear && bad == 0, "%d decoded values differ from dr_srgb_to_linear", bad);
    /* in place (an image only used as colour): the same values in data itself */
    float *copy = malloc(sizeof(float) * N * 4);
    memcpy(copy, data, sizeof(float) * N * 4);
    struct dr_image in = {.width = N, .height = 1, .channels = 4, .data = copy, .file_is_srgb = true};
    CHECK(dr_image_make_linear_in_place(&in) == DR_OK && in.linear == in.data && in.linear_in_data,
          "make_linear_in_place: linear is data");
    CHECK(img.linear && memcmp(in.linear, img.linear, sizeof(float) * N * 4) == 0,
          "in place: values differ from make_linear's");
    CHECK(dr_image_make_linear_in_place(&in) == DR_OK && in.linear == copy, "in place: idempotent");
    dr_image_release(&in);   /* (one buffer: freed once; ASan checks) */
    CHECK(!in.data && !in.linear && !in.linear_in_data, "in place: release zeroes");
    dr_image_release(&img);
}

static void test_bilinear(void)
{
    const enum dr_wrap R = DR_WRAP_REPEAT, C = DR_WRAP_CLAMP, M = DR_WRAP_MIRROR;
    const double tol = 1e-12;
    enum dr_wrap all[3] = {R, C, M};
    for (int m = 0; m < 3; ++m) {
        enum dr_wrap w = all[m];
        /* Texel centres: exact texel values in every mode. */
        CHECK_NEAR(eval1(w, w, 1.0 / 6, 0.25), 0, tol, "centre (0,0)");
        CHECK_NEAR(eval1(w, w, 0.5, 0.25), 1, tol, "centre (1,0)");
        CHECK_NEAR(eval1(w, w, 5.0 / 6, 0.75), 40, tol, "centre (2,1)");
        CHECK_NEAR(eval1(w, w, 0.5, 0.75), 20, tol, "centre (1,1): v runs down");
        /* Interior: between rows. */
        CHECK_NEAR(eval1(w, w, 0.5, 0.5), 10.5, tol, "interior (1, 0.5)");
        /* Interior, both axes: x = 0.75, y = 0.25 */
        CHECK_NEAR(eval1(w, w, 1.25 / 3, 0.375),
                   0.75 * (0.25 * 0 + 0.75 * 1) + 0.25 * (0.25 * 10 + 0.75 * 20), tol,
                   "interior both axes");
    }
    /* Left edge u = 0 (x = -0.5): REPEAT blends texel 2 and texel 0. */
    CHECK_NEAR(eval1(R, R, 0.0, 0.25), 1.0, tol, "repeat u=0");
    CHECK_NEAR(eval1(C, C, 0.0, 0.25), 0.0, tol, "clamp u=0");
    CHECK_NEAR(eval1(M, M, 0.0, 0.25), 0.0, tol, "mirror u=0");
    /* Negative u = -0.25: x = -1.25, i0 = -2, frac 0.75. */
    CHECK_NEAR(eval1(R, R, -0.25, 0.25), 0.25 * 1 + 0.75 * 2, tol, "repeat u=-0.25");
    CHECK_NEAR(eval1(C, C, -0.25, 0.25), 0.0, tol, "clamp u=-0.25");
    CHECK_NEAR(eval1(M, M, -0.25, 0.25), 0.25 * 1 + 0.75 * 0, tol, "mirror u=-0.25");
    /* u = 1.25: x = 3.25, i0 = 3, frac 0.25. */
    CHECK_NEAR(eval1(R, R, 1.25, 0.25), 0.75 * 0 + 0.25 * 1, tol, "repeat u=1.25");
    CHECK_NEAR(eval1(C, C, 1.25, 0.25), 2.0, tol, "clamp u=1.25");
    CHECK_NEAR(eval1(M, M, 1.25, 0.25), 0.75 * 2 + 0.25 * 1, tol, "mirror u=1.25");
    /* Mirror: the period is 2, and u and -u agree. */
    CHECK_NEAR(eval1(M, M, 2.3, 0.6), eval1(M, M, 0.3, 0.6), 1e-9, "mirror period 2");
    CHECK_NEAR(eval1(M, M, -0.3, 0.6), eval1(M, M, 0.3, 0.6), 1e-9, "mirror symmetry");
    CHECK_NEAR(eval1(M, M, 1.7, 0.6), eval1(M, M, 0.3, 0.6), 1e-9, "mirror about 1");
    CHECK_NEAR(eval1(R, R, -3.7, 0.6), eval1(R, R, 0.3, 0.6), 1e-9, "repeat period 1");
    /* v = -0.375 (column 1 holds 1 and 20): y = -1.25, j0 = -2, frac 0.75. */
    CHECK_NEAR(eval1(R, R, 0.5, -0.375), 0.25 * 1 + 0.75 * 20, tol, "repeat v=-0.375");
    CHECK_NEAR(eval1(C, C, 0.5, -0.375), 1.0, tol, "clamp v=-0.375");
    CHECK_NEAR(eval1(M, M, 0.5, -0.375), 0.25 * 20 + 0.75 * 1, tol, "mirror v=-0.375");
    /* v = 1.125: y = 1.75, j0 = 1, frac 0.75. */
    CHECK_NEAR(eval1(R, R, 0.5, 1.125), 0.25 * 20 + 0.75 * 1, tol, "repeat v=1.125");
    CHECK_NEAR(eval1(C, C, 0.5, 1.125), 20.0, tol, "clamp v=1.125");
    CHECK_NEAR(eval1(M, M, 0.5, 1.125), 20.0, tol, "mirror v=1.125");
    /* Corner u = v = 1 with REPEAT: the average of the four corners. */
    CHECK_NEAR(eval1(R, R, 1.0, 1.0), 0.25 * (0 + 2 + 10 + 40), tol, "repeat corner");
    CHECK_NEAR(eval1(C, C, 1.0, 1.0), 40.0, tol, "clamp corner");
    CHECK_NEAR(eval1(M, M, 1.0, 1.0), 40.0, tol, "mirror corner");
    /* Different modes per axis: s repeats, t clamps. */
    CHECK_NEAR(eval1(R, C, 0.0, 0.0), 0.5 * 2 + 0.5 * 0, tol, "repeat s, clamp t");
    CHECK_NEAR(eval1(C, R, 0.0, 0.0), 0.5 * 0 + 0.5 * 10, tol, "clamp s, repeat t");

    /* NaN, infinite and huge coordinates: finite results inside the range. */
    const double bad[] = {NAN, INFINITY, -INFINITY, 1e300, -1e300, 1e18 + 0.3, -4e9};
    for (int m = 0; m < 3; ++m)
        for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i)
            for (size_t j = 0; j < sizeof bad / sizeof bad[0]; ++j) {
                double r = eval1(all[m], all[m], bad[i], bad[j]);
                CHECK(isfinite(r) && r >= 0.0 && r <= 40.0, "mode %d uv (%g, %g) -> %g", m,
                      bad[i], bad[j], r);
            }
    CHECK_NEAR(eval1(R, R, NAN, 0.25), eval1(R, R, 0.0, 0.25), tol, "NaN u acts as 0");
}

static void test_channels(void)
{
    struct dr_texture tex = {0, DR_WRAP_CLAMP, DR_WRAP_CLAMP};
    double out[4];
    /* 2 channels: grey + alpha. 2x1 image. */
    float ga[4] = {0.2f, 0.5f, 0.6f, 1.0f};
    struct dr_image img2 = {.width = 2, .height = 1, .channels = 2, .data = ga, .file_is_srgb = false};
    dr_texture_eval(&tex, &img2, 0.5, 0.5, false, out);
    CHECK_NEAR(out[0], 0.5 * ((double)0.2f + (double)0.6f), 1e-12, "grey r");
    CHECK_NEAR(out[1], out[0], 0, "grey g");
    CHECK_NEAR(out[2], out[0], 0, "grey b");
    CHECK_NEAR(out[3], 0.5 * ((double)0.5f + 1.0), 1e-12, "grey alpha");
    /* 3 channels: alpha 1. */
    float rgb[3] = {0.1f, 0.2f, 0.3f};
    struct dr_image img3 = {.width = 1, .height = 1, .channels = 3, .data = rgb, .file_is_srgb = false};
    dr_texture_eval(&tex, &img3, 0.9, 0.1, false, out);
    CHECK(out[0] == (double)0.1f && out[1] == (double)0.2f && out[2] == (double)0.3f &&
              out[3] == 1.0,
          "rgb: %g %g %g %g", out[0], out[1], out[2], out[3]);
    /* 4 channels. */
    float rgba[4] = {0.1f, 0.2f, 0.3f, 0.4f};
    struct dr_image img4 = {.width = 1, .height = 1, .channels = 4, .data = rgba, .file_is_srgb = false};
    dr_texture_eval(&tex, &img4, 0.3, 0.7, false, out);
    CHECK_NEAR(out[3], 0.4f, 1e-7, "rgba alpha");
    /* No image data: black, opaque. */
    struct dr_image empty = {.width = 0, .height = 0, .channels = 0, .data = NULL, .file_is_srgb = false};
    dr_texture_eval(&tex, &empty, 0.3, 0.7, false, out);
    CHECK(out[0] == 0 && out[1] == 0 && out[2] == 0 && out[3] == 1, "empty image");

    /* make_linear: decodes colour, keeps alpha, idempotent. */
    struct dr_image s = {0};
    s.width = 1;
    s.height = 1;
    s.channels = 4;
    s.file_is_srgb = true;
    s.data = malloc(4 * sizeof(float));
    CHECK(s.data != NULL, "malloc");
    if (!s.data)
        return;
    s.data[0] = 0.5f;
    s.data[1] = 0.02f;
    s.data[2] = 1.0f;
    s.data[3] = 0.5f;
    CHECK(dr_image_make_linear(&s) == 0, "make_linear");
    float *first = s.linear;
    CHECK(dr_image_make_linear(&s) == 0 && s.linear == first, "make_linear idempotent");
    CHECK_NEAR(s.linear[0], dr_srgb_to_linear(0.5), 1e-7, "decoded r");
    CHECK_NEAR(s.linear[1], 0.02 / 12.92, 1e-9, "decoded g");
    CHECK_NEAR(s.linear[2], 1.0, 1e-7, "decoded b");
    CHECK_NEAR(s.linear[3], 0.5, 0, "alpha kept");
    dr_texture_eval(&tex, &s, 0.5, 0.5, true, out);
    CHECK_NEAR(out[0], dr_srgb_to_linear(0.5), 1e-7, "lookup in linear");
    dr_texture_eval(&tex, &s, 0.5, 0.5, false, out);
    CHECK_NEAR(out[0], 0.5, 0, "lookup in data");
    dr_image_release(&s);
    CHECK(zeroed(&s), "release zeroes");
    dr_image_release(&s); /* twice is harmless */

    /* A linear file's "linear" copy is the data itself. */
    float lin[1] = {0.5f};
    struct dr_image l = {.width = 1, .height = 1, .channels = 1, .data = NULL, .file_is_srgb = false};
    l.data = malloc(sizeof lin);
    if (l.data) {
        memcpy(l.data, lin, sizeof lin);
        CHECK(dr_image_make_linear(&l) == 0 && l.linear[0] == 0.5f, "linear file not decoded");
    }
    dr_image_release(&l);
}

/* ------------------------------------------------------------------------ */

#define W 5
#define H 4

static void fill_pixels(float *p, int channels)
{
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (int c = 0; c < channels; ++c) {
                float v = (float)(x + 1) / W * (float)(y + 1) / H;
                if (c == 1)
                    v = 1.0f - v;
                if (c == 2)
                    v = 0.37f * v * v;
                if (c == 3)
                    v = (float)((x + 2 * y) % 5) / 4.0f;
                p[(y * W + x) * channels + c] = v;
            }
}

static void test_exr(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "round.exr");
    float px[W * H * 4];
    fill_pixels(px, 4);
    px[0] = 1e-30f;  /* awkward values must survive bit for bit */
    px[1] = 65504.5f;
    px[2] = -3.25f;
    px[3] = 1234567.8f;
    CHECK(dr_image_write(path, W, H, 4, px) == 0, "write exr: %s", dr_last_error());
    struct dr_image img;
    int rc = dr_image_read(path, &img);
    CHECK(rc == 0, "read exr: %s", dr_last_error());
    if (rc == 0) {
        CHECK(img.width == W && img.height == H && img.channels == 4, "exr dims %dx%dx%d",
              img.width, img.height, img.channels);
        CHECK(!img.file_is_srgb, "exr is linear");
        CHECK(img.linear == NULL, "linear not made by read");
        if (img.channels == 4)
            CHECK(memcmp(img.data, px, sizeof px) == 0, "exr not bit-exact");
    }
    dr_image_release(&img);
    CHECK(count_matching(tmpdir, ".tmp") == 0, "temporary left behind");

    /* 1-channel float. */
    path_in_tmp(path, sizeof path, "grey.exr");
    float g[W * H];
    fill_pixels(g, 1);
    CHECK(dr_image_write(path, W, H, 1, g) == 0, "write grey exr: %s", dr_last_error());
    rc = dr_image_read(path, &img);
    CHECK(rc == 0 && img.channels == 1 && memcmp(img.data, g, sizeof g) == 0,
          "grey exr round trip (rc %d, %d channels)", rc, img.channels);
    dr_image_release(&img);
}

/* The compression an OpenEXR file's header names (its "compression"
 * attribute: 0 none, 1 RLE, 3 zip, ...), or -1. */
static int exr_compression(const char *path)
{
    unsigned char head[4096];
    FILE *f = fopen(path, "rb");
    size_t n = f ? fread(head, 1, sizeof head, f) : 0;
    if (f)
        fclose(f);
    static const char key[] = "compression\0compression\0\1\0\0\0";   /* name, type, size 1 */
    const size_t k = sizeof key - 1;
    for (size_t i = 0; i + k < n; i++)
        if (memcmp(head + i, key, k) == 0)
            return head[i + k];
    return -1;
}

/* A float image mostly of exact zeros (a texture's gradient) is written
 * run-length encoded, bit for bit; one of dense values keeps zip. */
static void test_exr_compression(void)
{
    enum { SW = 64, SH = 48 };
    static float px[SW * SH * 3];
    char path[512];
    for (int dense = 0; dense < 2; dense++) {
        for (int i = 0; i < SW * SH * 3; i++)
            px[i] = dense || i % 7 == 3 ? (float)(0.001 * (i % 997) - 0.3) : 0.0f;
        px[3] = -0.0f;   /* (a zero too, and its sign must survive) */
        path_in_tmp(path, sizeof path, dense ? "dense.exr" : "sparse.exr");
        CHECK(dr_image_write(path, SW, SH, 3, px) == 0, "write %s: %s", path, dr_last_error());
        const int c = exr_compression(path);
        CHECK(c == (dense ? 3 : 1), "%s: compression %d, expected %s", path, c, dense ? "zip (3)" : "RLE (1)");
        struct dr_image img;
        int rc = dr_image_read(path, &img);
        CHECK(rc == 0 && img.channels == 3 && memcmp(img.data, px, sizeof px) == 0, "%s: not bit-exact (rc %d)",
              path, rc);
        dr_image_release(&img);
    }
}

static void test_png(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "round.png");
    float px[W * H * 4];
    fill_pixels(px, 4);
    px[4] = 0.8f; /* pixel 1: colour with alpha 0 must not be premultiplied away */
    px[7] = 0.0f;
    px[8] = 2.0f;  /* out of range: clamped */
    px[9] = -1.0f; /* negative: clamped */
    px[10] = NAN;  /* NaN: 0 */
    CHECK(dr_image_write(path, W, H, 4, px) == 0, "write png: %s", dr_last_error());
    struct dr_image img;
    int rc = dr_image_read(path, &img);
    CHECK(rc == 0, "read png: %s", dr_last_error());
    if (rc != 0)
        return;
    CHECK(img.width == W && img.height == H && img.channels == 4, "png dims %dx%dx%d",
          img.width, img.height, img.channels);
    CHECK(img.file_is_srgb, "png is sRGB");
    if (img.channels == 4) {
        double worst_code = 0.0, worst_lin = 0.0, worst_alpha = 0.0;
        for (int i = 0; i < W * H; ++i)
            for (int c = 0; c < 4; ++c) {
                double src = px[i * 4 + c], got = img.data[i * 4 + c];
                if ((i == 1 || i == 2) && c < 3)
                    continue; /* the special pixels, checked below */
                if (c == 3) {
                    worst_alpha = fmax(worst_alpha, fabs(got - src));
                    continue;
                }
                double want = dr_linear_to_srgb(src);
                worst_code = fmax(worst_code, fabs(got - want));
                /* decoded: within half a step times the curve's slope (<= 2.4) */
                worst_lin = fmax(worst_lin, fabs(dr_srgb_to_linear(got) - src));
                /* stored values are exact 8-bit codes */
                double code = got * 255.0;
                CHECK(fabs(code - floor(code + 0.5)) < 1e-4, "not an 8-bit code: %g", code);
            }
        CHECK(worst_code <= 0.5 / 255 + 1e-6, "sRGB code error %g", worst_code);
        CHECK(worst_lin <= 2.4 * 0.5 / 255, "linear error %g", worst_lin);
        CHECK(worst_alpha <= 0.5 / 255 + 1e-6, "alpha error %g", worst_alpha);
        CHECK_NEAR(img.data[4], dr_linear_to_srgb(0.8), 0.5 / 255 + 1e-6,
                   "colour kept under alpha 0");
        CHECK_NEAR(img.data[7], 0.0, 0, "alpha 0");
        CHECK_NEAR(img.data[8], 1.0, 0, "clamped above");
        CHECK_NEAR(img.data[9], 0.0, 0, "clamped below");
        CHECK_NEAR(img.data[10], 0.0, 0, "NaN written as 0");
        CHECK_NEAR(img.data[0], round(dr_linear_to_srgb(px[0]) * 255) / 255, 1e-6,
                   "rounded to nearest");
        CHECK(dr_image_make_linear(&img) == 0, "make_linear");
        CHECK_NEAR(img.linear[0], px[0], 0.5 / 255, "make_linear decodes");
        CHECK_NEAR(img.linear[3], img.data[3], 0, "make_linear keeps alpha");
    }
    dr_image_release(&img);

    /* RGB and grey PNGs. */
    float rgb[W * H * 3];
    fill_pixels(rgb, 3);
    path_in_tmp(path, sizeof path, "rgb.png");
    CHECK(dr_image_write(path, W, H, 3, rgb) == 0, "write rgb png: %s", dr_last_error());
    rc = dr_image_read(path, &img);
    CHECK(rc == 0 && img.channels == 3 && img.file_is_srgb, "rgb png: rc %d, %d channels", rc,
          img.channels);
    if (rc == 0 && img.channels == 3)
        CHECK_NEAR(img.data[5], dr_linear_to_srgb(rgb[5]), 0.5 / 255 + 1e-6, "rgb png value");
    dr_image_release(&img);

    /* Grey + alpha, and other 8-bit formats with alpha. */
    float ga[W * H * 2];
    fill_pixels(ga, 2);
    const char *names[] = {"ga.png", "ga.tga", "rgba.tga", "rgba.bmp", "ga.jpg"};
    const int chans[] = {2, 2, 4, 4, 2};
    const int want[] = {2, 2, 4, 4, 1};
    for (int k = 0; k < 5; ++k) {
        path_in_tmp(path, sizeof path, names[k]);
        const float *src = chans[k] == 2 ? ga : px;
        rc = dr_image_write(path, W, H, chans[k], src);
        CHECK(rc == 0, "write %s: %s", names[k], dr_last_error());
        rc = dr_image_read(path, &img);
        CHECK(rc == 0 && img.channels == want[k] && img.file_is_srgb,
              "%s: rc %d, %d channels, srgb %d", names[k], rc, img.channels, img.file_is_srgb);
        if (rc == 0 && img.channels == want[k] && k < 4) {
            /* pixel 6: colour and alpha */
            int c = chans[k];
            CHECK_NEAR(img.data[6 * c], dr_linear_to_srgb(src[6 * c]), 0.5 / 255 + 1e-6,
                       names[k]);
            CHECK_NEAR(img.data[6 * c + c - 1], src[6 * c + c - 1], 0.5 / 255 + 1e-6,
                       names[k]);
        }
        dr_image_release(&img);
    }
}

static void test_hdr(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "round.hdr");
    float px[W * H * 3];
    fill_pixels(px, 3);
    px[0] = 1000.0f;
    CHECK(dr_image_write(path, W, H, 3, px) == 0, "write hdr: %s", dr_last_error());
    struct dr_image img;
    int rc = dr_image_read(path, &img);
    CHECK(rc == 0, "read hdr: %s", dr_last_error());
    if (rc == 0) {
        CHECK(img.width == W && img.height == H && img.channels == 3, "hdr dims %dx%dx%d",
              img.width, img.height, img.channels);
        CHECK(!img.file_is_srgb, "hdr is linear");
        if (img.channels == 3) {
            /* RGBE: 8-bit mantissas sharing the largest component's exponent. */
            double worst = 0.0;
            for (int i = 0; i < W * H; ++i) {
                double m = fmax(px[3 * i], fmax(px[3 * i + 1], px[3 * i + 2]));
                for (int c = 0; c < 3; ++c)
                    worst = fmax(worst, fabs(img.data[3 * i + c] - px[3 * i + c]) / m);
            }
            CHECK(worst <= 1.0 / 128, "hdr error %g (relative to the pixel's max)", worst);
        }
    }
    dr_image_release(&img);
    /* RGBA to HDR: alpha dropped. */
    float px4[W * H * 4];
    fill_pixels(px4, 4);
    path_in_tmp(path, sizeof path, "rgba.hdr");
    CHECK(dr_image_write(path, W, H, 4, px4) == 0, "write rgba hdr: %s", dr_last_error());
    rc = dr_image_read(path, &img);
    CHECK(rc == 0 && img.channels == 3, "rgba hdr read: rc %d, %d channels", rc, img.channels);
    dr_image_release(&img);
    /* Grey to HDR: replicated into RGB. */
    float g[W * H];
    fill_pixels(g, 1);
    path_in_tmp(path, sizeof path, "grey.hdr");
    CHECK(dr_image_write(path, W, H, 1, g) == 0, "write grey hdr: %s", dr_last_error());
    rc = dr_image_read(path, &img);
    CHECK(rc == 0 && img.channels == 3, "grey hdr read: rc %d, %d channels", rc, img.channels);
    if (rc == 0 && img.channels == 3)
        CHECK(img.data[9] == img.data[10] && img.data[10] == img.data[11] &&
                  fabs(img.data[9] - g[3]) <= g[3] / 128,
              "grey hdr pixel: %g %g %g vs %g", img.data[9], img.data[10], img.data[11], g[3]);
    dr_image_release(&img);
}

static void test_jpeg(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "rgba.jpg");
    float px[W * H * 4];
    fill_pixels(px, 4);
    CHECK(dr_image_write(path, W, H, 4, px) == 0, "write rgba jpeg: %s", dr_last_error());
    struct dr_image img;
    int rc = dr_image_read(path, &img);
    CHECK(rc == 0, "read jpeg: %s", dr_last_error());
    if (rc == 0) {
        CHECK(img.channels == 3, "jpeg has no alpha: %d channels", img.channels);
        CHECK(img.file_is_srgb, "jpeg is sRGB");
    }
    dr_image_release(&img);
}

/* Reads `path` from a file and from memory (twice: with the name and with a
 * name that says nothing), and compares. */
static void compare_memory_read(const char *path, const char *what)
{
    struct dr_image a, b, c;
    int ra = dr_image_read(path, &a);
    CHECK(ra == 0, "%s: read: %s", what, dr_last_error());
    size_t size = 0;
    unsigned char *bytes = slurp(path, &size);
    CHECK(bytes != NULL, "%s: slurp", what);
    if (ra != 0 || !bytes) {
        dr_image_release(&a);
        free(bytes);
        return;
    }
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    int rb = dr_image_read_memory(bytes, size, base, &b);
    CHECK(rb == 0, "%s: read_memory: %s", what, dr_last_error());
    int rc = dr_image_read_memory(bytes, size, "embedded-image", &c);
    CHECK(rc == 0, "%s: read_memory (magic bytes): %s", what, dr_last_error());
    const struct dr_image *m[2] = {&b, &c};
    int r[2] = {rb, rc};
    for (int k = 0; k < 2; ++k) {
        if (r[k] != 0)
            continue;
        bool same = m[k]->width == a.width && m[k]->height == a.height &&
                    m[k]->channels == a.channels && m[k]->file_is_srgb == a.file_is_srgb;
        CHECK(same, "%s: memory read differs in shape (%d)", what, k);
        if (same)
            CHECK(memcmp(m[k]->data, a.data,
                         (size_t)a.width * a.height * a.channels * sizeof(float)) == 0,
                  "%s: memory read differs in pixels (%d)", what, k);
    }
    dr_image_release(&a);
    dr_image_release(&b);
    dr_image_release(&c);
    free(bytes);
}

static void test_read_memory(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "round.png");
    compare_memory_read(path, "png");
    path_in_tmp(path, sizeof path, "rgba.jpg");
    compare_memory_read(path, "jpeg");
    path_in_tmp(path, sizeof path, "round.exr");
    compare_memory_read(path, "exr");
    path_in_tmp(path, sizeof path, "round.hdr");
    compare_memory_read(path, "hdr");

    /* A MIME type as the name hint. */
    path_in_tmp(path, sizeof path, "round.png");
    size_t size = 0;
    unsigned char *bytes = slurp(path, &size);
    struct dr_image img;
    if (bytes) {
        CHECK(dr_image_read_memory(bytes, size, "image/png", &img) == 0 && img.channels == 4,
              "mime hint: %s", dr_last_error());
        dr_image_release(&img);
        /* Truncated data: an error and a zeroed image. */
        int rc = dr_image_read_memory(bytes, size / 2, "half.png", &img);
        CHECK(rc < 0, "truncated png accepted");
        CHECK(zeroed(&img), "image not zeroed after failure");
        dr_image_release(&img);
        free(bytes);
    }
    /* Garbage with no useful name. */
    const char junk[] = "this is not an image at all";
    int rc = dr_image_read_memory(junk, sizeof junk, "blob", &img);
    CHECK(rc == DR_ERR_FORMAT, "junk: rc %d", rc);
    CHECK(zeroed(&img), "junk: image not zeroed");
    CHECK(strstr(dr_last_error(), "blob") != NULL, "message names the hint: %s", dr_last_error());

    /* FITS has no ioproxy reader in OIIO 2.4: the temporary-file fallback,
     * which must clean up after itself. */
    path_in_tmp(path, sizeof path, "round.fits");
    float px[W * H * 3];
    fill_pixels(px, 3);
    CHECK(dr_image_can_write(path), "OpenImageIO without FITS?");
    if (dr_image_can_write(path)) {
        CHECK(dr_image_write(path, W, H, 3, px) == 0, "write fits: %s", dr_last_error());
        char sub[512];
        path_in_tmp(sub, sizeof sub, "fitstmp");
        CHECK(mkdir(sub, 0700) == 0, "mkdir");
        const char *old = getenv("TMPDIR");
        char *saved = old ? strdup(old) : NULL;
        setenv("TMPDIR", sub, 1);
        bytes = slurp(path, &size);
        if (bytes) {
            struct dr_image a;
            int ra = dr_image_read(path, &a);
            rc = dr_image_read_memory(bytes, size, "embedded.fits", &img);
            CHECK(ra == 0 && rc == 0, "fits via memory: %s", dr_last_error());
            if (ra == 0 && rc == 0)
                CHECK(img.channels == a.channels && img.width == a.width &&
                          memcmp(img.data, a.data,
                                 (size_t)a.width * a.height * a.channels * sizeof(float)) == 0,
                      "fits via memory differs");
            dr_image_release(&a);
            dr_image_release(&img);
            free(bytes);
        }
        CHECK(count_entries(sub) == 0, "fallback temporary left behind");
        if (saved) {
            setenv("TMPDIR", saved, 1);
            free(saved);
        } else {
            unsetenv("TMPDIR");
        }
    }
}

/* dr_image_read_memory8 (scene textures): 8-bit files in eight-bit storage
 * with the values, stored and decoded, of the float read to the bit; other
 * files as float, the same as dr_image_read_memory. */
static void test_read_eight_bit(void)
{
    const struct {
        const char *name;
        int channels;
        bool eight;
    } cases[] = {{"e8.png", 4, true}, {"e8g.png", 1, true}, {"e8.jpg", 3, true}, {"e8.exr", 3, false}};
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        char path[512];
        path_in_tmp(path, sizeof path, cases[k].name);
        float px[W * H * 4];
        fill_pixels(px, cases[k].channels);
        CHECK(dr_image_write(path, W, H, cases[k].channels, px) == 0, "%s: write: %s", path, dr_last_error());
        size_t size = 0;
        unsigned char *bytes = slurp(path, &size);
        struct dr_image f, e;
        int rf = bytes ? dr_image_read_memory(bytes, size, cases[k].name, &f) : -1;
        int re = bytes ? dr_image_read_memory8(bytes, size, cases[k].name, &e) : -1;
        CHECK(rf == 0 && re == 0, "%s: read: %s", cases[k].name, dr_last_error());
        free(bytes);
        if (rf != 0 || re != 0)
            continue;
        CHECK((e.bytes != NULL) == cases[k].eight && (e.data != NULL) == !cases[k].eight,
              "%s: eight-bit storage %d (want %d)", cases[k].name, e.bytes != NULL, cases[k].eight);
        CHECK(e.width == f.width && e.height == f.height && e.channels == f.channels &&
                  e.file_is_srgb == f.file_is_srgb,
              "%s: the same image", cases[k].name);
        CHECK(dr_image_make_linear(&f) == 0 && dr_image_make_linear(&e) == 0, "%s: decode", cases[k].name);
        int bad = 0;
        for (size_t i = 0; i < (size_t)f.width * f.height * f.channels; i++)
            for (int lin = 0; lin < 2; lin++) {
                float a = dr_image_value(&f, i, lin), b = dr_image_value(&e, i, lin);
                bad += memcmp(&a, &b, sizeof a) != 0;
            }
        CHECK(bad == 0, "%s: %d values differ from the float read", cases[k].name, bad);
        dr_image_release(&f);
        dr_image_release(&e);
    }
}

/* A BMP of w x h pixels at bpp bits: BITMAPINFOHEADER, `palette` colour
 * table entries (a grey ramp), compression comp, and h rows of `row` bytes
 * (the padded size) from pixels. Returns its size in buf (cap bytes; 0 if it
 * does not fit). */
enum { BMP_CAP = 2048 };
static size_t make_bmp(unsigned char buf[BMP_CAP], int w, int h, int bpp, int comp, int palette, int row,
                       const unsigned char *pixels)
{
    const size_t table = (size_t)palette * 4, data = (size_t)row * (size_t)h, size = 54 + table + data;
    CHECK(size <= BMP_CAP, "make_bmp: %zu bytes do not fit", size);
    if (size > BMP_CAP)
        return 0;
    memset(buf, 0, size);
    buf[0] = 'B', buf[1] = 'M';
    const uint32_t fields[][2] = {{2, (uint32_t)size}, {10, (uint32_t)(54 + table)}, {14, 40},
                                  {18, (uint32_t)w},   {22, (uint32_t)h},            {30, (uint32_t)comp},
                                  {34, (uint32_t)data}, {46, (uint32_t)palette}};
    for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++)
        for (int k = 0; k < 4; k++)
            buf[fields[i][0] + k] = (unsigned char)(fields[i][1] >> (8 * k));
    buf[26] = 1;   /* planes */
    buf[28] = (unsigned char)bpp;
    for (int i = 0; i < palette; i++)
        buf[54 + 4 * i] = buf[55 + 4 * i] = buf[56 + 4 * i] = (unsigned char)(255 * i / (palette > 1 ? palette - 1 : 1));
    memcpy(buf + 54 + table, pixels, data);
    return size;
}

/* Writes n bytes to path (a failure is a failed check). */
static void write_bytes(const char *path, const void *bytes, size_t n)
{
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(bytes, 1, n, f) == n, "write %s", path);
    if (f)
        fclose(f);
}

/* OpenImageIO 2.4's BMP reader crashes on RLE files with the wrong depth and
 * reads past a short colour table (core/bmp_check.h): such files are refused
 * with a reason, from memory and from a file alike; the BMPs it reads safely
 * (a short table whose entries the pixels stay inside) still load. */
static void test_bmp_guard(void)
{
    unsigned char buf[BMP_CAP], px[64];
    struct dr_image img;
    char path[512];
    /* 4x2, 8 bits, a 2-entry table, pixels 0 and 1: read, as grey */
    for (int i = 0; i < 8; i++)
        px[i] = (unsigned char)(i & 1);
    size_t n = make_bmp(buf, 4, 2, 8, 0, 2, 4, px);
    int rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == 0 && img.width == 4 && img.height == 2, "short table, pixels inside: rc %d: %s", rc, dr_last_error());
    if (rc == 0) {
        CHECK(img.data[0] == 0.0f && img.data[img.channels] == 1.0f, "short table: values %g %g", img.data[0],
              img.data[img.channels]);
        dr_image_release(&img);
    }
    /* one pixel uses entry 5 of the 2: refused, from memory and from a file */
    px[6] = 5;
    n = make_bmp(buf, 4, 2, 8, 0, 2, 4, px);
    rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "colour 5 of a 2-entry colour table"), "entry 5 of 2: rc %d: %s",
          rc, dr_last_error());
    path_in_tmp(path, sizeof path, "short-table.png");   /* (the content decides, not the name) */
    write_bytes(path, buf, n);
    rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), "2-entry colour table"),
          "entry 5 of 2 (file): rc %d: %s", rc, dr_last_error());
    /* 4-bit pixels past a 3-entry table */
    memset(px, 0x12, sizeof px);
    px[1] = 0x13;
    n = make_bmp(buf, 4, 2, 4, 0, 3, 4, px);
    rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "colour 3 of a 3-entry"), "4-bit: rc %d: %s", rc,
          dr_last_error());
    /* RLE8 and RLE4, whatever the depth: refused before the reader sees them
     * (24-bit RLE8 is make fuzz's crasher, fuzz/corpus/image/regress-bmp-rle8-24bit) */
    memset(px, 0, sizeof px);
    for (int k = 0; k < 3; k++) {
        const int bpp[] = {24, 8, 4}, comp[] = {1, 1, 2};
        n = make_bmp(buf, 4, 2, bpp[k], comp[k], bpp[k] <= 8 ? 1 << bpp[k] : 0, 12, px);
        rc = dr_image_read_memory(buf, n, "x.bmp", &img);
        CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), comp[k] == 1 ? "RLE8-compressed BMP" : "RLE4-compressed"),
              "RLE %d-bit: rc %d: %s", bpp[k], rc, dr_last_error());
    }
    /* a depth the reader has no case for */
    n = make_bmp(buf, 4, 2, 2, 0, 4, 4, px);
    rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "2 bits a pixel"), "2-bit: rc %d: %s", rc, dr_last_error());
    /* pixel data outside the bytes: an offset before them (make fuzz's
     * regress-bmp-negative-offset read before the buffer), and rows cut short */
    memset(px, 200, sizeof px);
    n = make_bmp(buf, 4, 2, 24, 0, 0, 12, px);
    buf[10] = 0xd4, buf[11] = buf[12] = buf[13] = 0xff;
    rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "is not all inside"), "offset -44: rc %d: %s", rc,
          dr_last_error());
    n = make_bmp(buf, 4, 2, 24, 0, 0, 12, px);
    rc = dr_image_read_memory(buf, n - 1, "x.bmp", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "2 rows of 12 bytes"), "a byte short: rc %d: %s", rc,
          dr_last_error());
    /* a plain 24-bit one reads */
    memset(px, 200, sizeof px);
    n = make_bmp(buf, 4, 2, 24, 0, 0, 12, px);
    rc = dr_image_read_memory(buf, n, "x.bmp", &img);
    CHECK(rc == 0 && img.width == 4 && img.channels == 3, "24-bit: rc %d: %s", rc, dr_last_error());
    if (rc == 0)
        dr_image_release(&img);
}

/* fuzz/corpus/image/NAME into buf (cap bytes); returns the length of the
 * image after its first byte (fuzz_image's name selector), 0 if it could
 * not be read whole (a failed check). */
static size_t read_image_corpus_input(const char *name, unsigned char *buf, size_t cap)
{
    char src[600];
    snprintf(src, sizeof src, "%s/../fuzz/corpus/image/%s", getenv("DR_TESTDIR") ? getenv("DR_TESTDIR") : "tests",
             name);
    FILE *f = fopen(src, "rb");
    CHECK(f != NULL, "open %s", src);
    if (!f)
        return 0;
    const size_t n = fread(buf, 1, cap, f);
    fclose(f);
    CHECK(n > 1 && n < cap, "%s: %zu bytes (the buffer holds %zu)", src, n, cap);
    return n > 1 && n < cap ? n - 1 : 0;
}

/* Maya IFF: OpenImageIO 2.4's IFF reader corrupted the heap on a fuzzed
 * file (fuzz/corpus/image/regress-iff-rle-heap): every IFF is refused, from
 * memory and from a file named otherwise, before the reader sees it. */
static void test_iff_refused(void)
{
    static unsigned char buf[16384];
    const size_t n = read_image_corpus_input("regress-iff-rle-heap", buf, sizeof buf) + 1;
    if (n == 1)
        return;
    struct dr_image img;
    int rc = dr_image_read_memory(buf + 1, n - 1, "x.iff", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "Maya IFF"), "IFF from memory: rc %d: %s", rc,
          dr_last_error());
    rc = dr_image_read_memory(buf + 1, n - 1, "x.png", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "Maya IFF"), "IFF named .png: rc %d: %s", rc,
          dr_last_error());
    char path[512];
    path_in_tmp(path, sizeof path, "iff.png");
    write_bytes(path, buf + 1, n - 1);
    rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), "Maya IFF"),
          "IFF file: rc %d: %s", rc, dr_last_error());
}

/* DPX: a header whose user-data length is more than the file holds made
 * OpenImageIO 2.4 allocate and fill it (4 GB for a 2.5 KB file) and then
 * abort (fuzz/corpus/image/regress-dpx-user-data-4gb): refused, from
 * memory and from a file; the corpus's plain DPX still reads. */
static void test_dpx_user_data(void)
{
    static unsigned char buf[16384];
    const size_t n = read_image_corpus_input("small-8.dpx", buf, sizeof buf);
    if (n == 0)
        return;
    unsigned char *dpx = buf + 1;
    struct dr_image img;
    char path[512];
    path_in_tmp(path, sizeof path, "plain.dpx");
    write_bytes(path, dpx, n);
    for (int from_file = 0; from_file < 2; from_file++) {
        int rc = from_file ? dr_image_read(path, &img) : dr_image_read_memory(dpx, n, "x.dpx", &img);
        CHECK(rc == 0 && img.width == 6 && img.height == 5, "the plain DPX reads (%s): rc %d: %s",
              from_file ? "file" : "memory", rc, dr_last_error());
        if (rc == 0)
            dr_image_release(&img);
    }
    int rc;
    /* user data 0xff000000 bytes long, in the file's byte order */
    const bool big = dpx[0] == 'S';
    for (int k = 0; k < 4; k++)
        dpx[32 + k] = (unsigned char)(0xff000000u >> (big ? 24 - 8 * k : 8 * k));
    rc = dr_image_read_memory(dpx, n, "x.dpx", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "4278190080 bytes of user data"), "memory: rc %d: %s", rc,
          dr_last_error());
    path_in_tmp(path, sizeof path, "user.png");
    write_bytes(path, dpx, n);
    rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), "user data"),
          "file: rc %d: %s", rc, dr_last_error());
    /* the user data put right, but 1 x 50348100 pixels in an 8 KB file
     * (make fuzz: the reader read past the end for minutes,
     * regress-dpx-50m-lines-slow) */
    for (int k = 0; k < 4; k++)
        dpx[32 + k] = 0;
    const uint32_t lines = 50348100;
    for (int k = 0; k < 4; k++) {
        dpx[772 + k] = (unsigned char)(1u >> (big ? 24 - 8 * k : 8 * k));
        dpx[776 + k] = (unsigned char)(lines >> (big ? 24 - 8 * k : 8 * k));
    }
    rc = dr_image_read_memory(dpx, n, "x.dpx", &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "1x50348100 pixels whose image data cannot fit"),
          "50M lines (memory): rc %d: %s", rc, dr_last_error());
    write_bytes(path, dpx, n);
    rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "cannot fit"), "50M lines (file): rc %d: %s", rc,
          dr_last_error());
}

/* SGI, Wavefront RLA and ICO (unsafe_images.h): make fuzz found OpenImageIO
 * 2.4's SGI reader taking 5.7 GB and half a minute to open a 155-byte file
 * (regress-sgi-5gb-open), its RLA reader looping for minutes on a 791-byte
 * one (regress-rla-loops), and its ICO reader writing past its pixels
 * (regress-ico-heap-overflow), and its Softimage reader dereferencing a
 * null FILE (regress-pic-null-file-crash). The four formats are refused
 * whole: SGI, ICO and PIC by their magic bytes before any reader sees them, RLA (no magic bytes)
 * once a reader has opened it as RLA, before any pixel is read. Each case must end
 * within a second or so, which a hang would not. */
static void test_sgi_rla_refused(void)
{
    static unsigned char buf[16384];
    const struct { const char *input, *hint, *says; } cases[] = {
        {"regress-sgi-5gb-open", "x.sgi", "SGI image"},
        {"small-8.sgi", "x.sgi", "SGI image"},
        {"regress-rla-loops", "x.rla", "Wavefront RLA"},
        {"small-8.rla", "x.rla", "Wavefront RLA"},
        {"regress-ico-heap-overflow", "x.ico", "ICO icon"},
        {"small-8.ico", "x.ico", "ICO icon"},
        {"regress-pic-null-file-crash", "x.pic", "Softimage PIC image"},
        {"small-8.pic", "x.pic", "Softimage PIC image"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const size_t n = read_image_corpus_input(cases[i].input, buf, sizeof buf);
        if (n == 0)
            continue;
        struct dr_image img;
        int rc = dr_image_read_memory(buf + 1, n, cases[i].hint, &img);
        CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), cases[i].says), "%s from memory: rc %d: %s",
              cases[i].input, rc, dr_last_error());
        /* from a file named .png: OpenImageIO tries every reader in turn */
        char path[512];
        path_in_tmp(path, sizeof path, "unsafe.png");
        write_bytes(path, buf + 1, n);
        rc = dr_image_read(path, &img);
        CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), cases[i].says),
              "%s as a file named .png: rc %d: %s", cases[i].input, rc, dr_last_error());
    }
}

/* A file named .null: OpenImageIO's null reader opens anything so named (a
 * black 1024x1024 image, RGBA), from disk and from memory; refused. (The
 * ffmpeg reader is refused by name the same way; no video is at hand.) */
static void test_null_reader_refused(void)
{
    char path[512];
    path_in_tmp(path, sizeof path, "garbage.null");
    static const unsigned char hello[] = "hello, not an image\n";
    write_bytes(path, hello, sizeof hello - 1);
    struct dr_image img;
    int rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), "null reader"),
          "a file named .null: rc %d: %s", rc, dr_last_error());
    rc = dr_image_read_memory(hello, sizeof hello - 1, "x.null", &img);
    CHECK(rc != 0 && !strstr(dr_last_error(), "1024x1024 image,"), "from memory as x.null: rc %d: %s", rc,
          dr_last_error());
}

/* DDS and Photoshop files whose headers make OpenImageIO 2.4's readers
 * loop forever (a DDS channel with an empty bit mask) or allocate gigabytes
 * (a PSD section longer than the file): refused from memory and from a file
 * named .png, while well-formed ones (the corpus seeds: raw and RLE PSD,
 * RGBA, DXT1 and DXT5 DDS) read with their pixels; on disk, a PSD section
 * past the first kilobyte is found by seeking. */
static void test_dds_psd_headers(void)
{
    static unsigned char buf[16384];
    const struct { const char *input, *hint, *says; } bad[] = {
        {"regress-dds-empty-mask-loops", "x.dds", "DDS whose pixel format (flags 0xfa) names a channel with an empty"},
        {"regress-psd-3gb-color-data", "x.psd", "Photoshop file whose color mode data claims 3115956665 bytes"},
        {"regress-dds-mipmap-levels-loop", "x.dds", "DDS that claims 1886257152 mipmap levels, more than its size "
         "allows (12)"},
    };
    char path[512];
    struct dr_image img;
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        const size_t n = read_image_corpus_input(bad[i].input, buf, sizeof buf);
        if (n == 0)
            continue;
        int rc = dr_image_read_memory(buf + 1, n, bad[i].hint, &img);
        CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), bad[i].says), "%s from memory: rc %d: %s", bad[i].input,
              rc, dr_last_error());
        path_in_tmp(path, sizeof path, "unsafe.png");
        write_bytes(path, buf + 1, n);
        rc = dr_image_read(path, &img);
        CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), path) && strstr(dr_last_error(), bad[i].says),
              "%s as a file named .png: rc %d: %s", bad[i].input, rc, dr_last_error());
    }
    const struct { const char *input, *hint; int channels; } good[] = {
        {"small-8.psd", "x.psd", 3}, {"small-rle.psd", "x.psd", 3}, {"small-8.dds", "x.dds", 4},
        {"small-dxt1.dds", "x.dds", 4}, {"small-dxt5.dds", "x.dds", 4},
    };
    for (size_t i = 0; i < sizeof good / sizeof good[0]; i++) {
        const size_t n = read_image_corpus_input(good[i].input, buf, sizeof buf);
        if (n == 0)
            continue;
        int rc = dr_image_read_memory(buf + 1, n, good[i].hint, &img);
        CHECK(rc == DR_OK && img.width == 6 && img.height == 5 && img.channels == good[i].channels,
              "%s: rc %d, %dx%dx%d: %s", good[i].input, rc, img.width, img.height, img.channels, dr_last_error());
        if (rc == DR_OK && strstr(good[i].input, ".psd")) {   /* (the seeds' texels: (40 x + 7 y + 90 c) mod 256) */
            int wrong = 0;
            for (int y = 0; y < 5; y++)
                for (int x = 0; x < 6; x++)
                    for (int c = 0; c < 3; c++)
                        wrong += fabs(img.data[(y * 6 + x) * 3 + c] - ((x * 40 + y * 7 + c * 90) & 255) / 255.0) > 1e-6;
            CHECK(wrong == 0, "%s: %d texels differ from the file's", good[i].input, wrong);
        }
        if (rc == DR_OK)
            dr_image_release(&img);
    }
    /* the RGBA seed as a mipmapped DDS: 3 levels (6x5, 3x2, 1x1) read; a
     * 4th is refused */
    const size_t dn = read_image_corpus_input("small-8.dds", buf, sizeof buf);
    for (uint32_t levels = 3; dn > 0 && levels <= 4; levels++) {
        unsigned char *d = buf + 1;
        d[10] |= 0x02;                               /* flags |= 0x20000: mipmap count */
        memcpy(d + 28, &levels, 4);                  /* (little-endian, as the test machines) */
        d[110] |= 0x40, d[109] |= 0x10, d[108] |= 0x08;   /* caps |= 0x401008: mipmap, texture, complex */
        memset(d + dn, 0, 3 * 2 * 4 + 4);            /* the smaller levels' texels */
        int rc = dr_image_read_memory(d, dn + 28, "x.dds", &img);
        if (levels == 3)
            CHECK(rc == DR_OK && img.width == 6 && img.height == 5, "a DDS of 3 mipmap levels: rc %d: %s", rc,
                  dr_last_error());
        else
            CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "claims 4 mipmap levels, more than its size allows "
                                                                 "(3)"),
                  "a DDS of 4 mipmap levels at 6x5: rc %d: %s", rc, dr_last_error());
        if (rc == DR_OK)
            dr_image_release(&img);
    }
    /* a PSD with 2000 bytes of image resources, then a layer section of
     * 0x7fffffff bytes (refused: past the first kilobyte, by seeking) or of
     * 0 (read) */
    for (int impossible = 0; impossible < 2; impossible++) {
        unsigned char f[2200];
        size_t k = 0;
        const unsigned char head[26] = {'8', 'B', 'P', 'S', 0, 1, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 1, 0, 0, 0, 1, 0, 8, 0, 3};
        memcpy(f, head, sizeof head), k = sizeof head;   /* 1 x 1, 3 channels, 8 bits, RGB */
        const unsigned char lens[] = {0, 0, 0, 0, 0, 0, 0x07, 0xdc};   /* no colour data; 2012 bytes of resources */
        memcpy(f + k, lens, sizeof lens), k += sizeof lens;
        const unsigned char block[12] = {'8', 'B', 'I', 'M', 0x0f, 0xa0, 0, 0, 0, 0, 0x07, 0xd0};   /* 2000 bytes */
        memcpy(f + k, block, sizeof block), k += sizeof block;
        memset(f + k, 'x', 2000), k += 2000;
        const unsigned char layers[4] = {impossible ? 0x7f : 0, impossible ? 0xff : 0, impossible ? 0xff : 0,
                                         impossible ? 0xff : 0};
        memcpy(f + k, layers, 4), k += 4;
        const unsigned char pixels[] = {0, 0, 200, 100, 50};   /* raw, then R, G, B */
        memcpy(f + k, pixels, sizeof pixels), k += sizeof pixels;
        path_in_tmp(path, sizeof path, "resources.psd");
        write_bytes(path, f, k);
        int rc = dr_image_read(path, &img);
        if (impossible)
            CHECK(rc == DR_ERR_FORMAT && strstr(dr_last_error(), "layer and mask information claims 2147483647"),
                  "PSD with an impossible layer section past the first kilobyte: rc %d: %s", rc, dr_last_error());
        else
            CHECK(rc == DR_OK && img.width == 1 && fabs(img.data[0] - 200 / 255.0) < 1e-6,
                  "PSD with 2000 bytes of resources: rc %d: %s", rc, dr_last_error());
        if (rc == DR_OK)
            dr_image_release(&img);
    }
}

/* Open descriptors of this process (its /proc/self/fd entries). */
static int open_descriptors(void)
{
    DIR *d = opendir("/proc/self/fd");
    int n = 0;
    for (struct dirent *e; d && (e = readdir(d)) != NULL;)
        n += e->d_name[0] != '.';
    if (d)
        closedir(d);
    return n;
}

/* An image the reader takes from a temporary file (ICO: no in-memory
 * reading in OpenImageIO 2.4), whose reader fails and leaves the file open:
 * every read must give its descriptor back (make fuzz ran out of them). */
static void test_no_descriptor_left(void)
{
    const unsigned char two[] = {'B', '&'};
    const int before = open_descriptors();
    for (int i = 0; i < 8; i++) {
        struct dr_image img;
        int rc = dr_image_read_memory(two, sizeof two, "x.ico", &img);
        CHECK(rc == DR_ERR_FORMAT, "2-byte ico: rc %d", rc);
    }
    CHECK(before > 0 && open_descriptors() == before, "2-byte ico: %d descriptors open before 8 reads, %d after",
          before, open_descriptors());
}

static void test_errors(void)
{
    char path[512], other[512];
    struct dr_image img;

    CHECK(!dr_image_can_write("out.xyz"), "can_write .xyz");
    CHECK(!dr_image_can_write("noextension"), "can_write without extension");
    CHECK(dr_image_can_write("out.png"), "can_write .png");
    CHECK(dr_image_can_write("out.exr"), "can_write .exr");
    CHECK(dr_image_can_write("dir/out.JPG"), "can_write .JPG");
    CHECK(!dr_image_can_write("dir.png/noextension"), "can_write: a dot in the directory is no extension");
    CHECK(!dr_image_can_write(".png"), "can_write: a hidden file name is no extension");
    /* The formats answered without loading the library must be ones the
     * library really writes (core/image_plugin.c). */
    for (int i = 0; dr_image_common_write_formats[i]; i++) {
        char name[64];
        snprintf(name, sizeof name, "out.%s", dr_image_common_write_formats[i]);
        CHECK(dr_image_plugin_table()->can_write(name), "OpenImageIO cannot write %s", name);
    }

    /* Reading a missing file. */
    path_in_tmp(path, sizeof path, "missing.png");
    memset(&img, 0x5a, sizeof img);
    int rc = dr_image_read(path, &img);
    CHECK(rc == DR_ERR_IO, "missing file: rc %d", rc);
    CHECK(zeroed(&img), "missing file: image not zeroed");
    CHECK(strstr(dr_last_error(), path) && strstr(dr_last_error(), "cannot read image"),
          "message: %s", dr_last_error());
    /* Reading a corrupt file. */
    path_in_tmp(path, sizeof path, "corrupt.png");
    FILE *f = fopen(path, "wb");
    if (f) {
        fputs("\x89PNG\r\n\x1a\n garbage garbage", f);
        fclose(f);
    }
    rc = dr_image_read(path, &img);
    CHECK(rc < 0, "corrupt file accepted");
    CHECK(zeroed(&img), "corrupt file: image not zeroed");
    remove(path);

    float px[W * H * 3];
    fill_pixels(px, 3);
    int before = count_entries(tmpdir);

    /* Unknown format: DR_ERR_ARG, nothing created. */
    path_in_tmp(path, sizeof path, "out.xyz");
    rc = dr_image_write(path, W, H, 3, px);
    CHECK(rc == DR_ERR_ARG, ".xyz write: rc %d", rc);
    CHECK(strstr(dr_last_error(), "cannot write this format"), "message: %s", dr_last_error());
    CHECK(count_entries(tmpdir) == before, ".xyz write created something");

    /* Nonexistent directory: DR_ERR_IO. */
    path_in_tmp(path, sizeof path, "no/such/dir/out.png");
    rc = dr_image_write(path, W, H, 3, px);
    CHECK(rc == DR_ERR_IO, "write into a missing directory: rc %d", rc);
    CHECK(strstr(dr_last_error(), path) && strstr(dr_last_error(), "cannot write image"),
          "message: %s", dr_last_error());
    CHECK(count_entries(tmpdir) == before, "missing directory: something created");

    /* Invalid arguments. */
    path_in_tmp(path, sizeof path, "bad.png");
    CHECK(dr_image_write(path, 0, H, 3, px) == DR_ERR_ARG, "zero width");
    CHECK(dr_image_write(path, W, H, 5, px) == DR_ERR_ARG, "5 channels");
    CHECK(dr_image_write(path, W, H, 3, NULL) == DR_ERR_ARG, "NULL pixels");
    CHECK(count_entries(tmpdir) == before, "invalid write created something");

    /* The rename fails (the target is a directory): DR_ERR_IO and the
     * temporary, fully written by then, is removed. */
    path_in_tmp(path, sizeof path, "isdir.png");
    CHECK(mkdir(path, 0700) == 0, "mkdir");
    rc = dr_image_write(path, W, H, 3, px);
    CHECK(rc == DR_ERR_IO, "write over a directory: rc %d", rc);
    CHECK(count_matching(tmpdir, ".tmp") == 0, "temporary left behind after failed rename");
    CHECK(count_entries(tmpdir) == before + 1, "unexpected files");
    rmdir(path);

    /* A failed write over an existing file leaves it untouched: block the
     * temporary's name with a directory so OpenImageIO cannot create it. */
    path_in_tmp(path, sizeof path, "keep.png");
    CHECK(dr_image_write(path, W, H, 3, px) == 0, "write keep.png: %s", dr_last_error());
    size_t size0 = 0, size1 = 0;
    unsigned char *orig = slurp(path, &size0);
    char tmpname[128];
    snprintf(tmpname, sizeof tmpname, ".keep.png.tmp%ld.png", (long)getpid());
    path_in_tmp(other, sizeof other, tmpname);
    CHECK(mkdir(other, 0700) == 0, "mkdir %s", other);
    float px2[W * H * 3];
    for (int i = 0; i < W * H * 3; ++i)
        px2[i] = 1.0f - px[i];
    rc = dr_image_write(path, W, H, 3, px2);
    CHECK(rc == DR_ERR_IO, "blocked write: rc %d", rc);
    unsigned char *now = slurp(path, &size1);
    CHECK(orig && now && size0 == size1 && memcmp(orig, now, size0) == 0,
          "existing file changed by a failed write");
    CHECK(file_exists(other), "the blocking directory was removed");
    rmdir(other);
    free(orig);
    free(now);
    /* The same write works once the way is clear, and replaces the file. */
    rc = dr_image_write(path, W, H, 3, px2);
    CHECK(rc == 0, "write after unblocking: %s", dr_last_error());
    rc = dr_image_read(path, &img);
    if (rc == 0 && img.channels == 3)
        CHECK_NEAR(img.data[0], dr_linear_to_srgb(px2[0]), 0.5 / 255 + 1e-6, "file replaced");
    dr_image_release(&img);
    CHECK(count_matching(tmpdir, ".tmp") == 0, "temporary left behind");
    remove(path);
}

/* An image of `channels` values that an 8-bit file gives (level / 255 as
 * float), pseudo-random levels, as float storage. */
static struct dr_image levels_image(int w, int h, int channels, bool srgb, unsigned seed)
{
    struct dr_image img = {.width = w, .height = h, .channels = channels, .file_is_srgb = srgb};
    size_t n = (size_t)w * h * channels;
    img.data = malloc(sizeof(float) * n);
    for (size_t i = 0; i < n; i++) {
        seed = seed * 1103515245u + 12345u;
        img.data[i] = (float)((seed >> 16) % 256) / 255.0f;
    }
    return img;
}

static struct dr_image copy_image(const struct dr_image *a)
{
    struct dr_image b = *a;
    size_t n = (size_t)a->width * a->height * a->channels;
    b.data = malloc(sizeof(float) * n);
    memcpy(b.data, a->data, sizeof(float) * n);
    return b;
}

/* The same image in eight-bit storage (image.h), as dr_image_read_memory8
 * gives it: img's values are each level / 255 (levels_image), so the table
 * holds exactly those floats. */
static bool to_eight_bit(struct dr_image *img)
{
    size_t n = (size_t)img->width * img->height * img->channels;
    img->bytes = malloc(n);
    img->lut = malloc(512 * sizeof(float));
    if (!img->bytes || !img->lut)
        return false;
    for (int k = 0; k < 256; k++)
        img->lut[k] = (float)k / 255.0f;
    for (size_t i = 0; i < n; i++) {
        int k = (int)(img->data[i] * 255.0f + 0.5f);
        if (img->lut[k] != img->data[i])
            return false;
        img->bytes[i] = (uint8_t)k;
    }
    free(img->data);
    img->data = NULL;
    return true;
}

/* Eight-bit storage gives every lookup the float
 * storage's bits, for 1 to 4 channels, colour and data images, decoded
 * apart or in place (image.h), and dr_image_expand gives back the float
 * arrays to the bit. */
static void test_eight_bit(void)
{
    const struct dr_texture tex = {0, DR_WRAP_REPEAT, DR_WRAP_MIRROR};
    int bad = 0, checked = 0;
    for (int c = 1; c <= 4; c++)
        for (int mode = 0; mode < 4; mode++) {   /* 0: data only, 1: decoded apart, 2: decoded in place,
                                                    3: "decoded" without an sRGB curve (a linear file) */
            struct dr_image f = levels_image(7, 5, c, mode == 1 || mode == 2, 40u + (unsigned)c), e = copy_image(&f);
            CHECK(to_eight_bit(&e), "%d channels: in eight bits", c);
            int rf = mode == 2 ? dr_image_make_linear_in_place(&f) : mode ? dr_image_make_linear(&f) : 0;
            int re = mode == 2 ? dr_image_make_linear_in_place(&e) : mode ? dr_image_make_linear(&e) : 0;
            CHECK(rf == 0 && re == 0, "%d channels, mode %d: decode", c, mode);
            CHECK(dr_image_has_linear(&e) == (mode > 0), "%d channels, mode %d: has linear", c, mode);
            for (size_t i = 0; i < (size_t)7 * 5 * c; i++)
                for (int lin = 0; lin < 2; lin++) {
                    float a = dr_image_value(&f, i, lin), b = dr_image_value(&e, i, lin);
                    bad += memcmp(&a, &b, sizeof a) != 0;
                }
            for (int k = 0; k < 40; k++) {
                double u = -1.3 + 0.097 * k, v = 2.2 - 0.061 * k, of[4], oe[4], du[2] = {0, 0}, dv[2] = {0, 0};
                const double d_out[4] = {0.3, -0.7, 1.1, 0.5};
                for (int lin = 0; lin < 2; lin++) {
                    dr_texture_eval(&tex, &f, u, v, lin, of);
                    dr_texture_eval(&tex, &e, u, v, lin, oe);
                    bad += memcmp(of, oe, sizeof of) != 0;
                    d_texture_eval_uv(&tex, &f, u, v, lin, d_out, &du[0], &dv[0]);
                    d_texture_eval_uv(&tex, &e, u, v, lin, d_out, &du[1], &dv[1]);
                    bad += du[0] != du[1] || dv[0] != dv[1];
                    checked++;
                }
            }
            CHECK(dr_image_expand(&e) == 0 && e.data && !e.bytes, "%d channels, mode %d: expand", c, mode);
            size_t bytes = sizeof(float) * 7 * 5 * (size_t)c;
            bad += memcmp(f.data, e.data, bytes) != 0;
            bad += (f.linear == NULL) != (e.linear == NULL) || (f.linear && memcmp(f.linear, e.linear, bytes) != 0);
            bad += (f.linear == f.data) != (e.linear == e.data) || f.linear_in_data != e.linear_in_data;
            dr_image_release(&f);
            dr_image_release(&e);
        }
    CHECK(bad == 0, "eight-bit storage: %d of %d lookups, values or arrays differ from float storage", bad, checked);
    printf("eight-bit storage: %d lookups identical to float storage\n", checked);
}

int main(void)
{
    const char *base = getenv("TMPDIR");
    snprintf(tmpdir, sizeof tmpdir, "%s/drender-test-image-XXXXXX",
             base && *base ? base : "/tmp");
    if (!mkdtemp(tmpdir)) {
        fprintf(stderr, "mkdtemp %s: %s\n", tmpdir, strerror(errno));
        return 1;
    }

    test_srgb_curves();
    test_make_linear_exact();
    test_bilinear();
    test_channels();
    test_eight_bit();
    test_exr();
    test_exr_compression();
    test_png();
    test_hdr();
    test_jpeg();
    test_read_memory();
    test_read_eight_bit();
    test_errors();
    test_bmp_guard();
    test_iff_refused();
    test_sgi_rla_refused();
    test_null_reader_refused();
    test_dds_psd_headers();
    test_dpx_user_data();
    test_no_descriptor_left();

    nftw(tmpdir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
    return TEST_END();
}
