/* Files OpenImageIO 2.4's readers must not see: see unsafe_images.h. */
#include "unsafe_images.h"

#include <stdio.h>
#include <string.h>

#include "bmp_check.h"

static bool maya_iff(const unsigned char *b, size_t n)
{
    return n >= 4 && memcmp(b, "FOR", 3) == 0 && (b[3] == '4' || b[3] == '8');
}

static bool sgi(const unsigned char *b, size_t n)
{
    return n >= 2 && b[0] == 0x01 && b[1] == 0xDA;   /* (big-endian 474, the only byte order SGI has) */
}

/* Softimage PIC: magic 0x5380F634, big-endian. */
static bool softimage(const unsigned char *b, size_t n)
{
    return n >= 4 && b[0] == 0x53 && b[1] == 0x80 && b[2] == 0xF6 && b[3] == 0x34;
}

/* "00 00 01 00" and at least one image: an ICO directory. (A TGA cannot
 * start so: image type 1 needs a colour map, byte 1. CUR, type 2, is left
 * alone: "00 00 02 00" starts most TGA files; dr_unsafe_reader catches an
 * ICO reader that opens anything.) */
static bool ico(const unsigned char *b, size_t n)
{
    return n >= 6 && b[0] == 0 && b[1] == 0 && b[2] == 1 && b[3] == 0 && (b[4] | b[5]) != 0;
}

static uint32_t dpx_u32(const unsigned char *p, bool big)
{
    return big ? (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3]
               : (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | p[0];
}

static uint32_t le32(const unsigned char *p)
{
    return (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | p[0];
}

/* A DDS whose pixel format is uncompressed (no FOURCC, flag 0x4) and names
 * a channel whose bit mask is 0: RGB (0x40) without all of R, G and B,
 * luminance (0x20000) without R, alpha (0x1 or 0x2) without A. The reader
 * finds a mask's shift by shifting it until its low bit is set: forever. */
static bool dds_empty_mask(const unsigned char *b, size_t n, char *why, size_t why_size)
{
    if (n < 4 + 124 || memcmp(b, "DDS ", 4) != 0)
        return false;
    const unsigned char *pf = b + 4 + 72;   /* DDS_PIXELFORMAT: size, flags, fourCC, bits, R G B A masks */
    const uint32_t flags = le32(pf + 4);
    if (flags & 0x4)
        return false;   /* (compressed: no masks) */
    const uint32_t r = le32(pf + 16), g = le32(pf + 20), bl = le32(pf + 24), a = le32(pf + 28);
    if (!(((flags & 0x40) && !(r && g && bl)) || ((flags & 0x20000) && !r) || ((flags & 0x3) && !a)))
        return false;
    snprintf(why, why_size, "DDS whose pixel format (flags %#x) names a channel with an empty bit mask "
             "(OpenImageIO 2.4's DDS reader loops forever on it)", (unsigned)flags);
    return true;
}

/* A DDS that says it has more mipmap levels (flags' 0x20000 and caps'
 * 0x400000, count at byte 28) than halving its largest side down to 1
 * gives: the reader walks the levels one by one (a 140-byte file claiming
 * 1886257152 levels kept it busy for minutes). */
static bool dds_too_many_levels(const unsigned char *b, size_t n, char *why, size_t why_size)
{
    if (n < 4 + 124 || memcmp(b, "DDS ", 4) != 0)
        return false;
    const uint32_t flags = le32(b + 8), levels = le32(b + 28), caps = le32(b + 108);
    if (!(flags & 0x20000) || !(caps & 0x400000))
        return false;
    uint32_t side = le32(b + 12) | le32(b + 16) | le32(b + 24), most = 1;   /* (height, width, depth) */
    while (side >>= 1)
        most++;   /* 1 + floor(log2 of the largest side) */
    if (levels <= most)
        return false;
    snprintf(why, why_size, "DDS that claims %u mipmap levels, more than its size allows (%u) (OpenImageIO 2.4's "
             "DDS reader walks them all)", (unsigned)levels, (unsigned)most);
    return true;
}

static uint32_t be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* A Photoshop file ("8BPS", version 1, or 2 for PSB) whose color mode data,
 * image resources or layer and mask sections (each a length, then its
 * bytes, one after the other from byte 26) run past the file's end: the
 * reader allocates a section by its length before reading it (3 GB and 3 s
 * for a 101-byte file). at(ctx, off, out, len) reads the file's bytes
 * (false past what it has: the sections from there are not checked). */
static bool psd_impossible(bool (*at)(void *, uint64_t, unsigned char *, size_t), void *ctx, uint64_t file_size,
                           char *why, size_t why_size)
{
    unsigned char h[26];
    if (!at(ctx, 0, h, sizeof h) || memcmp(h, "8BPS", 4) != 0)
        return false;
    const bool psb = h[4] == 0 && h[5] == 2;
    static const char *const names[3] = {"color mode data", "image resources", "layer and mask information"};
    uint64_t off = 26;
    for (int k = 0; k < 3; k++) {
        const size_t width = k == 2 && psb ? 8 : 4;   /* (PSB's layer section has an 8-byte length) */
        unsigned char l[8];
        if (!at(ctx, off, l, width))
            return false;
        const uint64_t len = width == 8 ? (uint64_t)be32(l) << 32 | be32(l + 4) : be32(l);
        if (len > file_size || off + width + len > file_size) {
            snprintf(why, why_size, "Photoshop file whose %s claims %llu bytes, more than its %llu bytes hold "
                     "(OpenImageIO 2.4's PSD reader would allocate them first)", names[k],
                     (unsigned long long)len, (unsigned long long)file_size);
            return true;
        }
        off += width + len;
    }
    return false;
}

struct bytes_at { const unsigned char *b; size_t n; };
static bool from_bytes(void *ctx, uint64_t off, unsigned char *out, size_t len)
{
    const struct bytes_at *m = ctx;
    if (off > m->n || len > m->n - off)
        return false;
    memcpy(out, m->b + off, len);
    return true;
}
static bool from_file(void *ctx, uint64_t off, unsigned char *out, size_t len)
{
    FILE *f = ctx;
    return off <= (uint64_t)INT64_MAX && fseeko(f, (off_t)off, SEEK_SET) == 0 && fread(out, 1, len, f) == len;
}

int dr_unsafe_image_file_check(FILE *f, uint64_t file_size, char *why, size_t why_size)
{
    return psd_impossible(from_file, f, file_size, why, why_size) ? -1 : 0;
}

/* A DPX ("SDPX" big-endian, "XPDS" little-endian) whose header claims more
 * than the file holds: user data (bytes 32-35; all ones is the format's
 * "undefined", none) past its end after the 2048-byte generic header, or
 * pixels (bytes 772-779: per line, lines) that cannot fit at one bit each. */
static bool dpx_impossible(const unsigned char *b, size_t n, uint64_t file_size, char *why, size_t why_size)
{
    if (n < 36 || !(memcmp(b, "SDPX", 4) == 0 || memcmp(b, "XPDS", 4) == 0))
        return false;
    const bool big = b[0] == 'S';
    const uint32_t user = dpx_u32(b + 32, big);
    if (user != 0xffffffffu && (uint64_t)user + 2048 > file_size) {
        snprintf(why, why_size, "DPX whose header gives %u bytes of user data, more than its %llu bytes hold "
                 "(OpenImageIO 2.4's DPX reader would allocate them and abort)", (unsigned)user,
                 (unsigned long long)file_size);
        return true;
    }
    if (n < 780)
        return false;   /* (too short for the image header: the reader refuses it) */
    const uint64_t w = dpx_u32(b + 772, big), h = dpx_u32(b + 776, big);
    if (w * h / 8 > file_size) {
        snprintf(why, why_size, "DPX of %llux%llu pixels whose image data cannot fit in its %llu bytes "
                 "(OpenImageIO 2.4's DPX reader would read past the end line by line)", (unsigned long long)w,
                 (unsigned long long)h, (unsigned long long)file_size);
        return true;
    }
    return false;
}

int dr_unsafe_image_check(const unsigned char *b, size_t n, bool whole, uint64_t file_size, char *why,
                          size_t why_size)
{
    if (dpx_impossible(b, n, file_size, why, why_size) || dds_empty_mask(b, n, why, why_size) ||
        dds_too_many_levels(b, n, why, why_size))
        return -1;
    struct bytes_at m = {b, n};
    if (psd_impossible(from_bytes, &m, file_size, why, why_size))
        return -1;
    if (maya_iff(b, n)) {
        snprintf(why, why_size, "Maya IFF (OpenImageIO 2.4's IFF reader writes out of bounds on malformed files, "
                 "so drender reads none); convert it to PNG or EXR");
        return -1;
    }
    if (ico(b, n)) {
        snprintf(why, why_size, "ICO icon (OpenImageIO 2.4's ICO reader writes past its pixel buffer when an "
                 "icon's bitmap header disagrees with its directory entry, so drender reads none); convert it to "
                 "PNG");
        return -1;
    }
    if (softimage(b, n)) {
        snprintf(why, why_size, "Softimage PIC image (OpenImageIO 2.4's Softimage reader crashes on malformed files, "
                 "so drender reads none); convert it to PNG or EXR");
        return -1;
    }
    if (sgi(b, n)) {
        snprintf(why, why_size, "SGI image (OpenImageIO 2.4's SGI reader takes gigabytes and half a minute to open "
                 "a malformed file of a few bytes, so drender reads none); convert it to PNG or EXR");
        return -1;
    }
    return dr_bmp_check(b, n, whole, why, why_size);
}

const char *dr_unsafe_reader(const char *format_name)
{
    if (format_name && strcmp(format_name, "rla") == 0)
        return "Wavefront RLA image (OpenImageIO 2.4's RLA reader can loop for minutes on a malformed file, so "
               "drender reads none); convert it to PNG or EXR";
    if (format_name && strcmp(format_name, "softimage") == 0)   /* (softimage() above refuses them by magic) */
        return "Softimage PIC image (OpenImageIO 2.4's Softimage reader crashes on malformed files, so drender "
               "reads none); convert it to PNG or EXR";
    if (format_name && strcmp(format_name, "ico") == 0)   /* (ico() above refuses most before they open) */
        return "ICO icon (OpenImageIO 2.4's ICO reader writes past its pixel buffer when an icon's bitmap header "
               "disagrees with its directory entry, so drender reads none); convert it to PNG";
    if (format_name && strcmp(format_name, "null") == 0)   /* (OpenImageIO's test reader) */
        return "no image: OpenImageIO's null reader makes a black 1024x1024 image of any file named .null, "
               "whatever it holds (or of the size its name asks for)";
    if (format_name && strcmp(format_name, "ffmpeg") == 0)
        return "a video file (OpenImageIO's ffmpeg reader: drender reads textures and environments from image "
               "files, and hands no video container to libavformat's parsers); save the frame as PNG or EXR";
    return NULL;
}
