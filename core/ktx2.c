#include "ktx2.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <zlib.h>
#include <zstd.h>

#include "error.h"
#include "image_io.h"   /* dr_image_max_bytes */

static const unsigned char ktx2_magic[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};

enum { HEADER_BYTES = 80, LEVEL_BYTES = 24 };
enum { SC_NONE = 0, SC_BASISLZ = 1, SC_ZSTD = 2, SC_ZLIB = 3 };

/* The header's fields (KTX 2.0 specification, section 3). */
struct ktx2_header {
    uint32_t vk_format, type_size, width, height, depth, layers, faces, levels, scheme;
    uint32_t dfd_offset, dfd_length, kvd_offset, kvd_length;
};

/* What an 8-bit format holds: channels in the file, whether its first and
 * third are swapped (BGR), sRGB. 0 channels: not one of them. */
struct ktx2_format {
    int channels;
    bool bgr, srgb;
};

static uint32_t u32_at(const unsigned char *b) { return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24; }
static uint64_t u64_at(const unsigned char *b) { return (uint64_t)u32_at(b) | (uint64_t)u32_at(b + 4) << 32; }

bool dr_ktx2_is(const void *bytes, size_t size)
{
    return size >= sizeof ktx2_magic && memcmp(bytes, ktx2_magic, sizeof ktx2_magic) == 0;
}

static struct ktx2_format format_of(uint32_t vk)
{
    switch (vk) {   /* VkFormat values */
    case 9: return (struct ktx2_format){1, false, false};    /* R8_UNORM */
    case 15: return (struct ktx2_format){1, false, true};    /* R8_SRGB */
    case 16: return (struct ktx2_format){2, false, false};   /* R8G8_UNORM */
    case 22: return (struct ktx2_format){2, false, true};    /* R8G8_SRGB */
    case 23: return (struct ktx2_format){3, false, false};   /* R8G8B8_UNORM */
    case 29: return (struct ktx2_format){3, false, true};    /* R8G8B8_SRGB */
    case 30: return (struct ktx2_format){3, true, false};    /* B8G8R8_UNORM */
    case 36: return (struct ktx2_format){3, true, true};     /* B8G8R8_SRGB */
    case 37: return (struct ktx2_format){4, false, false};   /* R8G8B8A8_UNORM */
    case 43: return (struct ktx2_format){4, false, true};    /* R8G8B8A8_SRGB */
    case 44: return (struct ktx2_format){4, true, false};    /* B8G8R8A8_UNORM */
    case 50: return (struct ktx2_format){4, true, true};     /* B8G8R8A8_SRGB */
    default: return (struct ktx2_format){0, false, false};
    }
}

static void read_header(const unsigned char *b, struct ktx2_header *h)
{
    uint32_t *f[] = {&h->vk_format, &h->type_size, &h->width,  &h->height,     &h->depth,
                     &h->layers,    &h->faces,     &h->levels, &h->scheme,     &h->dfd_offset,
                     &h->dfd_length, &h->kvd_offset, &h->kvd_length};
    for (size_t i = 0; i < sizeof f / sizeof f[0]; i++)
        *f[i] = u32_at(b + 12 + 4 * i);
}

/* What a vkFormat 0 file holds: Basis Universal's ETC1S (BasisLZ) or
 * UASTC, by its supercompression or its data format descriptor's colour
 * model (KHR_DF_MODEL_UASTC = 166). */
static const char *undefined_format_kind(const unsigned char *b, size_t size, const struct ktx2_header *h)
{
    if (h->scheme == SC_BASISLZ)
        return "Basis Universal ETC1S (BasisLZ) texels";
    if ((uint64_t)h->dfd_offset + 16 <= size && b[h->dfd_offset + 12] == 166)
        return "Basis Universal UASTC texels";
    return "texels of an undefined format (vkFormat 0)";
}

/* 0 when the header describes what dr_ktx2_read8 decodes; else the reason. */
static int check_header(const unsigned char *b, size_t size, const struct ktx2_header *h, char *why, size_t n)
{
    const struct ktx2_format fmt = format_of(h->vk_format);
    if (h->vk_format == 0)
        snprintf(why, n, "it holds %s, which need the Basis Universal transcoder (not packaged by Debian); "
                         "drender reads KTX2 with uncompressed 8-bit texels",
                 undefined_format_kind(b, size, h));
    else if (h->vk_format >= 131 && h->vk_format <= 184)
        snprintf(why, n, "it holds GPU block-compressed texels (vkFormat %u: BC, ETC2 or ASTC); drender reads KTX2 "
                         "with uncompressed 8-bit texels", h->vk_format);
    else if (fmt.channels == 0)
        snprintf(why, n, "vkFormat %u is not one drender reads (8-bit UNORM or SRGB R, RG, RGB, BGR, RGBA, BGRA)",
                 h->vk_format);
    else if (h->scheme != SC_NONE && h->scheme != SC_ZSTD && h->scheme != SC_ZLIB)
        snprintf(why, n, "supercompression scheme %u is not one drender reads (none, Zstandard, zlib)", h->scheme);
    else if (h->depth > 1 || h->layers > 1 || h->faces != 1)
        snprintf(why, n, "it is a %s, not a 2D image", h->depth > 1 ? "3D texture" : h->faces != 1 ? "cube map"
                                                                                                  : "texture array");
    else if (h->width == 0 || h->height == 0 || h->width > (1u << 24) || h->height > (1u << 24))
        snprintf(why, n, "it is %ux%u pixels", h->width, h->height);
    else if (h->type_size != 1)
        snprintf(why, n, "its typeSize is %u, not 1 for 8-bit texels", h->type_size);
    else
        return 0;
    return DR_ERR_FORMAT;
}

int dr_ktx2_probe(const void *bytes, size_t size, char *why, size_t why_size)
{
    const unsigned char *b = bytes;
    if (!dr_ktx2_is(b, size) || size < HEADER_BYTES) {
        snprintf(why, why_size, "not a KTX2 file (%s)", dr_ktx2_is(b, size) ? "truncated header" : "no identifier");
        return DR_ERR_FORMAT;
    }
    struct ktx2_header h;
    read_header(b, &h);
    return check_header(b, size, &h, why, why_size);
}

/* KTXorientation's value ("rd", "ru", "ld", "lu"; rd when absent): x left
 * (flip_x) and y up (flip_y). The key/value data is a list of entries, each
 * a length, "key\0value" and padding to 4 bytes. */
static void orientation(const unsigned char *b, size_t size, const struct ktx2_header *h, bool *flip_x,
                        bool *flip_y)
{
    *flip_x = *flip_y = false;
    uint64_t at = h->kvd_offset, end = (uint64_t)h->kvd_offset + h->kvd_length;
    if (end > size)
        return;
    static const char key[] = "KTXorientation";
    while (at + 4 <= end) {
        const uint64_t len = u32_at(b + at), kv = at + 4;
        if (len > end - kv)
            return;
        if (len >= sizeof key + 2 && memcmp(b + kv, key, sizeof key) == 0) {
            *flip_x = b[kv + sizeof key] == 'l';
            *flip_y = b[kv + sizeof key + 1] == 'u';
            return;
        }
        at = kv + ((len + 3) & ~(uint64_t)3);
    }
}

/* Level 0's bytes, decompressed into out (exactly `need` bytes). */
static int level_bytes(const unsigned char *src, uint64_t src_len, uint32_t scheme, unsigned char *out,
                       uint64_t need, char *why, size_t n)
{
    if (scheme == SC_NONE) {
        if (src_len != need) {
            snprintf(why, n, "level 0 has %llu bytes, not the %llu its size and format make",
                     (unsigned long long)src_len, (unsigned long long)need);
            return DR_ERR_FORMAT;
        }
        memcpy(out, src, need);
        return 0;
    }
    if (scheme == SC_ZSTD) {
        const size_t got = ZSTD_decompress(out, need, src, src_len);
        if (ZSTD_isError(got) || got != need) {
            snprintf(why, n, "level 0's Zstandard data %s", ZSTD_isError(got) ? ZSTD_getErrorName(got)
                                                                               : "decodes to fewer bytes than its size");
            return DR_ERR_FORMAT;
        }
        return 0;
    }
    uLongf got = (uLongf)need;   /* zlib */
    const int zr = uncompress(out, &got, src, (uLong)src_len);
    if (zr != Z_OK || got != need) {
        snprintf(why, n, "level 0's zlib data %s", zr == Z_OK ? "decodes to fewer bytes than its size"
                                                   : zr == Z_BUF_ERROR ? "decodes to more bytes than its size"
                                                                       : "is corrupt");
        return DR_ERR_FORMAT;
    }
    return 0;
}

/* The file's texels (w x h x fmt.channels) into the image's bytes (RGB
 * order, R and RG widened to RGB, flips applied). */
static void place_texels(const unsigned char *in, const struct ktx2_format *fmt, uint32_t w, uint32_t h, bool flip_x,
                         bool flip_y, int out_ch, unsigned char *out)
{
    const int ic = fmt->channels;
    for (uint32_t y = 0; y < h; y++) {
        const unsigned char *row = in + (size_t)(flip_y ? h - 1 - y : y) * w * (size_t)ic;
        unsigned char *o = out + (size_t)y * w * (size_t)out_ch;
        for (uint32_t x = 0; x < w; x++, o += out_ch) {
            const unsigned char *t = row + (size_t)(flip_x ? w - 1 - x : x) * (size_t)ic;
            o[0] = t[fmt->bgr ? 2 : 0];
            o[1] = ic >= 2 ? t[1] : 0;
            o[2] = ic >= 3 ? t[fmt->bgr ? 0 : 2] : 0;
            if (out_ch == 4)
                o[3] = t[3];
        }
    }
}

/* The checks and the decode; dr_ktx2_read8 adds the label to `why`. */
static int read8(const unsigned char *b, size_t size, struct dr_image *img, char *why, size_t n)
{
    int rc = dr_ktx2_probe(b, size, why, n);
    if (rc != 0)
        return rc;
    struct ktx2_header h;
    read_header(b, &h);
    const struct ktx2_format fmt = format_of(h.vk_format);
    if (size < HEADER_BYTES + LEVEL_BYTES) {
        snprintf(why, n, "truncated level index");
        return DR_ERR_FORMAT;
    }
    const uint64_t off = u64_at(b + HEADER_BYTES), len = u64_at(b + HEADER_BYTES + 8),
                   ulen = u64_at(b + HEADER_BYTES + 16);
    if (off > size || len > size - off) {
        snprintf(why, n, "level 0 (bytes %llu..%llu) lies past the file's %zu bytes", (unsigned long long)off,
                 (unsigned long long)off + len, size);
        return DR_ERR_FORMAT;
    }
    const int out_ch = fmt.channels == 4 ? 4 : 3;
    const uint64_t texels = (uint64_t)h.width * h.height, need = texels * (uint64_t)fmt.channels;
    if (h.scheme != SC_NONE && ulen != need) {
        snprintf(why, n, "level 0's uncompressed length is %llu bytes, not the %llu its size and format make",
                 (unsigned long long)ulen, (unsigned long long)need);
        return DR_ERR_FORMAT;
    }
    const unsigned long long limit = dr_image_max_bytes();
    const double bytes_needed = (double)texels * (fmt.channels + out_ch);
    if (limit && bytes_needed > (double)limit) {
        snprintf(why, n, "%ux%u with %d channels needs %.1f MiB decoded, more than the %.1f MiB of memory drender "
                         "may use", h.width, h.height, out_ch, bytes_needed / 1048576.0, (double)limit / 1048576.0);
        return DR_ERR_NOMEM;
    }
    unsigned char *raw = malloc(need);
    uint8_t *bytes = dr_alloc_big(texels * (size_t)out_ch);
    float *lut = malloc(512 * sizeof *lut);   /* (the second half: decoded, image.c) */
    rc = DR_ERR_NOMEM;
    if (!raw || !bytes || !lut) {
        snprintf(why, n, "out of memory");
        goto fail;
    }
    if ((rc = level_bytes(b + off, len, h.scheme, raw, need, why, n)) != 0)
        goto fail;
    bool flip_x, flip_y;
    orientation(b, size, &h, &flip_x, &flip_y);
    place_texels(raw, &fmt, h.width, h.height, flip_x, flip_y, out_ch, bytes);
    free(raw);
    for (int k = 0; k < 256; k++)
        lut[k] = (float)k / 255.0f;
    *img = (struct dr_image){.width = (int)h.width, .height = (int)h.height, .channels = out_ch, .bytes = bytes,
                             .lut = lut, .file_is_srgb = fmt.srgb};
    return 0;
fail:
    free(raw);
    free(bytes);
    free(lut);
    return rc;
}

int dr_ktx2_read8(const void *bytes, size_t size, const char *label, struct dr_image *img)
{
    memset(img, 0, sizeof *img);
    char why[320];
    const int rc = read8(bytes, size, img, why, sizeof why);
    if (rc != 0)
        dr_set_error("%s: cannot read KTX2 image: %s", label, why);
    return rc;
}
