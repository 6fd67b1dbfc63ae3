/* core/ktx2.c: KTX2 files built here byte by byte (with libzstd and zlib
 * compressing their level 0) decode to the texels written, in RGB order,
 * right side up, R and RG widened to RGB, sRGB formats marked; everything
 * else (Basis Universal, block formats, arrays, malformed headers, level
 * data past the end or of the wrong length, corrupt streams, images past the
 * memory limit) is refused with its reason and no image. The shared
 * AnisotropyBarnLamp's three .ktx2 files decode. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <zlib.h>
#include <zstd.h>

#include "error.h"
#include "image_io.h"
#include "ktx2.h"
#include "test.h"

enum { SC_NONE = 0, SC_BASISLZ = 1, SC_ZSTD = 2, SC_ZLIB = 3 };

struct spec {
    uint32_t vk, type_size, w, h, depth, layers, faces, levels, scheme;
    const char *orientation;   /* KTXorientation's value, or NULL for none */
};

static void put32(unsigned char *b, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        b[i] = (unsigned char)(v >> (8 * i));
}

static void put64(unsigned char *b, uint64_t v)
{
    put32(b, (uint32_t)v);
    put32(b + 4, (uint32_t)(v >> 32));
}

/* A KTX2 file of level 0 = texels (n bytes), compressed per scheme; *size
 * its length. ulen_delta skews the level index's uncompressed length. */
static unsigned char *make_ktx2(const struct spec *s, const unsigned char *texels, size_t n, int64_t ulen_delta,
                                size_t *size)
{
    unsigned char kvd[64] = {0};
    size_t kvd_len = 0;
    if (s->orientation) {   /* length, "KTXorientation\0rd\0", padding */
        const size_t kv = strlen("KTXorientation") + 1 + strlen(s->orientation) + 1;
        put32(kvd, (uint32_t)kv);
        memcpy(kvd + 4, "KTXorientation", 15);
        memcpy(kvd + 4 + 15, s->orientation, strlen(s->orientation) + 1);
        kvd_len = (4 + kv + 3) & ~(size_t)3;
    }
    size_t cap = n + 1024;
    unsigned char *data = malloc(cap);
    size_t dlen = n;
    if (s->scheme == SC_ZSTD) {
        dlen = ZSTD_compress(data, cap, texels, n, 3);
        CHECK(!ZSTD_isError(dlen), "zstd compress");
    } else if (s->scheme == SC_ZLIB) {
        uLongf z = (uLongf)cap;
        CHECK(compress(data, &z, texels, (uLong)n) == Z_OK, "zlib compress");
        dlen = (size_t)z;
    } else {
        memcpy(data, texels, n);
    }
    const size_t kvd_off = 80 + 24, data_off = kvd_off + kvd_len;
    *size = data_off + dlen;
    unsigned char *b = calloc(1, *size);
    static const unsigned char magic[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
    memcpy(b, magic, 12);
    const uint32_t f[] = {s->vk, s->type_size, s->w, s->h, s->depth, s->layers, s->faces, s->levels, s->scheme};
    for (int i = 0; i < 9; i++)
        put32(b + 12 + 4 * i, f[i]);
    put32(b + 56, (uint32_t)kvd_off);
    put32(b + 60, (uint32_t)kvd_len);
    put64(b + 80, data_off);
    put64(b + 88, dlen);
    put64(b + 96, (uint64_t)((int64_t)n + ulen_delta));
    memcpy(b + kvd_off, kvd, kvd_len);
    memcpy(b + data_off, data, dlen);
    free(data);
    return b;
}

/* w x h texels of c channels, value (x * 37 + y * 101 + channel * 53) & 255 */
static unsigned char *pattern(uint32_t w, uint32_t h, int c)
{
    unsigned char *t = malloc((size_t)w * h * (size_t)c);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++)
            for (int k = 0; k < c; k++)
                t[((size_t)y * w + x) * (size_t)c + (size_t)k] = (unsigned char)((x * 37 + y * 101 + (uint32_t)k * 53) & 255);
    return t;
}

/* Texel (x, y) channel k of the decoded image against the pattern's texel
 * (sx, sy) channel sk (-1: must be 0). */
static bool texel_is(const struct dr_image *img, uint32_t x, uint32_t y, int k, uint32_t sx, uint32_t sy, int sk)
{
    const unsigned char got = img->bytes[((size_t)y * (size_t)img->width + x) * (size_t)img->channels + (size_t)k];
    const unsigned char want = sk < 0 ? 0 : (unsigned char)((sx * 37 + sy * 101 + (uint32_t)sk * 53) & 255);
    return got == want;
}

/* Decodes each 8-bit layout under each supercompression: channel order,
 * widening, flips, the sRGB flag and the lookup table. */
static void decodes(void)
{
    const struct {
        uint32_t vk;
        int in_ch, out_ch;
        int map[4];   /* output channel k = file channel map[k] (-1: 0) */
        bool srgb;
    } cases[] = {
        {9, 1, 3, {0, -1, -1}, false},   {15, 1, 3, {0, -1, -1}, true},  {16, 2, 3, {0, 1, -1}, false},
        {22, 2, 3, {0, 1, -1}, true},    {23, 3, 3, {0, 1, 2}, false},   {29, 3, 3, {0, 1, 2}, true},
        {30, 3, 3, {2, 1, 0}, false},    {36, 3, 3, {2, 1, 0}, true},    {37, 4, 4, {0, 1, 2, 3}, false},
        {43, 4, 4, {0, 1, 2, 3}, true},  {44, 4, 4, {2, 1, 0, 3}, false}, {50, 4, 4, {2, 1, 0, 3}, true},
    };
    const uint32_t W = 7, H = 5;
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++)
        for (uint32_t scheme = 0; scheme <= SC_ZLIB; scheme++) {
            if (scheme == SC_BASISLZ)
                continue;
            unsigned char *t = pattern(W, H, cases[c].in_ch);
            struct spec s = {cases[c].vk, 1, W, H, 0, 0, 1, 1, scheme, NULL};
            size_t size;
            unsigned char *f = make_ktx2(&s, t, (size_t)W * H * (size_t)cases[c].in_ch, 0, &size);
            char why[320];
            CHECK(dr_ktx2_probe(f, size, why, sizeof why) == 0, "vkFormat %u: probe: %s", cases[c].vk, why);
            struct dr_image img;
            int rc = dr_ktx2_read8(f, size, "t.ktx2", &img);
            CHECK(rc == 0, "vkFormat %u scheme %u: %s", cases[c].vk, scheme, dr_last_error());
            if (rc == 0) {
                CHECK(img.width == (int)W && img.height == (int)H && img.channels == cases[c].out_ch,
                      "vkFormat %u: %dx%d with %d channels", cases[c].vk, img.width, img.height, img.channels);
                CHECK(img.file_is_srgb == cases[c].srgb, "vkFormat %u: sRGB flag", cases[c].vk);
                int bad = 0;
                for (uint32_t y = 0; y < H; y++)
                    for (uint32_t x = 0; x < W; x++)
                        for (int k = 0; k < cases[c].out_ch; k++)
                            bad += !texel_is(&img, x, y, k, x, y, cases[c].map[k]);
                CHECK(bad == 0, "vkFormat %u scheme %u: %d texel values differ", cases[c].vk, scheme, bad);
                CHECK(img.lut[0] == 0.0f && img.lut[255] == 1.0f && img.lut[51] == 0.2f, "the lookup table");
            }
            dr_image_release(&img);
            free(f);
            free(t);
        }
}

/* KTXorientation: rd as none; ru and lu flip rows, columns or both. */
static void orientations(void)
{
    const uint32_t W = 4, H = 3;
    const char *names[] = {"rd", "ru", "ld", "lu"};
    for (int o = 0; o < 4; o++) {
        unsigned char *t = pattern(W, H, 3);
        struct spec s = {23, 1, W, H, 0, 0, 1, 1, SC_ZSTD, names[o]};
        size_t size;
        unsigned char *f = make_ktx2(&s, t, (size_t)W * H * 3, 0, &size);
        struct dr_image img;
        CHECK(dr_ktx2_read8(f, size, "o.ktx2", &img) == 0, "%s: %s", names[o], dr_last_error());
        const bool fx = names[o][0] == 'l', fy = names[o][1] == 'u';
        int bad = 0;
        for (uint32_t y = 0; y < H && img.bytes; y++)
            for (uint32_t x = 0; x < W; x++)
                bad += !texel_is(&img, x, y, 0, fx ? W - 1 - x : x, fy ? H - 1 - y : y, 0);
        CHECK(img.bytes && bad == 0, "KTXorientation %s: %d texels misplaced", names[o], bad);
        dr_image_release(&img);
        free(f);
        free(t);
    }
}

/* A refusal: rc, no pixels, and the message names the file and says why. */
static void refused(const struct spec *s, size_t n, int64_t ulen_delta, size_t cut, int want_rc, const char *what,
                    const char *reason)
{
    unsigned char *t = calloc(1, n ? n : 1);
    size_t size;
    unsigned char *f = make_ktx2(s, t, n, ulen_delta, &size);
    if (cut)
        size = cut < size ? cut : size;
    struct dr_image img;
    memset(&img, 0xff, sizeof img);
    const int rc = dr_ktx2_read8(f, size, "bad.ktx2", &img);
    CHECK(rc == want_rc, "%s: rc %d, want %d (%s)", what, rc, want_rc, dr_last_error());
    CHECK(img.bytes == NULL && img.lut == NULL && img.width == 0, "%s: no image is left", what);
    CHECK(strstr(dr_last_error(), "bad.ktx2") && strstr(dr_last_error(), reason), "%s: message '%s' (want '%s')",
          what, dr_last_error(), reason);
    free(f);
    free(t);
}

static void refusals(void)
{
    const struct spec ok = {23, 1, 4, 4, 0, 0, 1, 1, SC_ZSTD, NULL};
    struct spec s = ok;
    s.vk = 0, s.scheme = SC_BASISLZ;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "ETC1S", "Basis Universal ETC1S");
    s = ok, s.vk = 0, s.scheme = SC_NONE;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "vkFormat 0", "vkFormat 0");
    s = ok, s.vk = 145;   /* BC7_SRGB */
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "BC7", "block-compressed");
    s = ok, s.vk = 97;   /* R16G16B16A16_SFLOAT */
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "half float", "vkFormat 97");
    s = ok, s.scheme = 7;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "scheme 7", "supercompression scheme 7");
    s = ok, s.faces = 6;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "cube map", "cube map");
    s = ok, s.layers = 3;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "array", "texture array");
    s = ok, s.depth = 2;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "3D", "3D texture");
    s = ok, s.w = 0;
    refused(&s, 0, 0, 0, DR_ERR_FORMAT, "0 wide", "0x4 pixels");
    s = ok, s.type_size = 2;
    refused(&s, 48, 0, 0, DR_ERR_FORMAT, "typeSize 2", "typeSize");
    /* the level index and the data */
    refused(&ok, 48, 0, 60, DR_ERR_FORMAT, "truncated header", "truncated header");
    refused(&ok, 48, 0, 90, DR_ERR_FORMAT, "truncated level index", "truncated level index");
    refused(&ok, 48, 0, 110, DR_ERR_FORMAT, "level past the end", "lies past");
    refused(&ok, 48, 5, 0, DR_ERR_FORMAT, "uncompressed length", "uncompressed length");
    s = ok, s.scheme = SC_NONE;
    refused(&s, 47, 0, 0, DR_ERR_FORMAT, "short raw level", "has 47 bytes");
    /* a stream that decodes to fewer bytes than the level index says: the
     * texels of a 4x2 image in a file that says 4x4 */
    s = ok, s.h = 2;
    {
        unsigned char *t = calloc(1, 24);
        size_t size;
        unsigned char *f = make_ktx2(&s, t, 24, 0, &size);
        put32(f + 24, 4);      /* pixelHeight 4 */
        put64(f + 96, 48);     /* uncompressed length 48 */
        struct dr_image img;
        CHECK(dr_ktx2_read8(f, size, "short.ktx2", &img) == DR_ERR_FORMAT && !img.bytes, "short zstd stream");
        CHECK(strstr(dr_last_error(), "Zstandard"), "message: %s", dr_last_error());
        /* corrupt the stream itself */
        put32(f + 24, 2);
        put64(f + 96, 24);
        f[80 + 24] ^= 0xff;   /* the frame's magic number (level 0 starts after the index: no key/values) */
        CHECK(dr_ktx2_read8(f, size, "corrupt.ktx2", &img) == DR_ERR_FORMAT && !img.bytes, "corrupt zstd stream");
        free(f);
        free(t);
    }
    s = ok, s.scheme = SC_ZLIB;
    {
        unsigned char *t = pattern(4, 4, 3);
        size_t size;
        unsigned char *f = make_ktx2(&s, t, 48, 0, &size);
        f[size - 2] ^= 0xff;   /* the adler32 */
        struct dr_image img;
        CHECK(dr_ktx2_read8(f, size, "z.ktx2", &img) == DR_ERR_FORMAT && !img.bytes, "corrupt zlib stream");
        CHECK(strstr(dr_last_error(), "zlib"), "message: %s", dr_last_error());
        free(f);
        free(t);
    }
    /* the memory limit, checked from the header before any allocation */
    s = ok, s.w = s.h = 1u << 14;
    dr_image_set_max_bytes(64u << 20);
    refused(&s, 48, (int64_t)(1u << 28) * 3 - 48, 0, DR_ERR_NOMEM, "over the memory limit", "more than the");
    dr_image_set_max_bytes(0);
    CHECK(!dr_ktx2_is("KTX 11", 6) && dr_ktx2_probe("hello", 5, (char[64]){0}, 64) == DR_ERR_FORMAT,
          "not KTX2 at all");
}

/* The Bevy lamp's three images (R8G8B8_UNORM, Zstandard). */
static void shared_lamp(void)
{
    const char *names[] = {"AnisotropyBarnLamp_anisotropy.ktx2", "AnisotropyBarnLamp_normalbump.ktx2",
                           "AnisotropyBarnLamp_occlusionroughnessmetal.ktx2"};
    const int sizes[] = {512, 1024, 512};
    for (int i = 0; i < 3; i++) {
        char rel[256];
        snprintf(rel, sizeof rel, "AnisotropyBarnLamp-KTX2/glTF/%s", names[i]);
        const char *path = shared_sample(rel);
        if (!path) {
            fprintf(stderr, "%s: not found (../shared/gltf-samples missing): skipped\n", rel);
            continue;
        }
        FILE *f = fopen(path, "rb");
        CHECK(f != NULL, "open %s", path);
        if (!f)
            continue;
        fseek(f, 0, SEEK_END);
        const long n = ftell(f);
        fseek(f, 0, SEEK_SET);
        unsigned char *b = malloc((size_t)n);
        CHECK(fread(b, 1, (size_t)n, f) == (size_t)n, "read %s", path);
        fclose(f);
        struct dr_image img;
        CHECK(dr_ktx2_read8(b, (size_t)n, names[i], &img) == 0, "%s", dr_last_error());
        CHECK(img.width == sizes[i] && img.height == sizes[i] && img.channels == 3 && !img.file_is_srgb,
              "%s: %dx%d, %d channels", names[i], img.width, img.height, img.channels);
        if (i == 1 && img.bytes) {   /* a tangent-space normal map: blue (z) high everywhere */
            double z = 0.0;
            for (int64_t k = 0; k < (int64_t)img.width * img.height; k++)
                z += img.bytes[3 * k + 2];
            z /= (double)img.width * img.height;
            CHECK(z > 200.0, "the normal map's mean blue is %.1f (a normal map points out of the surface)", z);
        }
        dr_image_release(&img);
        free(b);
    }
}

int main(void)
{
    decodes();
    orientations();
    refusals();
    shared_lamp();
    return TEST_END();
}
