/* What OpenImageIO 2.4's BMP reader must not be given: see bmp_check.h. */
#include "bmp_check.h"

#include <stdint.h>
#include <stdio.h>

static uint32_t u16(const unsigned char *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8; }
static uint32_t u32(const unsigned char *p) { return u16(p) | u16(p + 2) << 16; }

/* Palette entry of pixel x in a row of a bpp-bit image (1, 4 or 8). */
static uint32_t pixel_index(const unsigned char *row, int64_t x, uint32_t bpp)
{
    if (bpp == 8)
        return row[x];
    if (bpp == 4)
        return (x & 1) ? (row[x / 2] & 0x0fu) : (uint32_t)(row[x / 2] >> 4);
    return (row[x / 8] >> (7 - x % 8)) & 1u;
}

/* 0, or -1 with why: a pixel of the palette image uses an entry past the
 * colour table's `entries` (rows from `offset`, as the reader finds them;
 * rows past the end of the data are the reader's to refuse). */
static int check_indices(const unsigned char *b, size_t n, uint32_t offset, int64_t w, int64_t h, uint32_t bpp,
                         uint32_t entries, char *why, size_t why_size)
{
    const int64_t padded = ((w * bpp + 7) / 8 + 3) & ~(int64_t)3;
    for (int64_t y = 0; y < h; y++) {
        const int64_t at = (int64_t)offset + y * padded;
        if (at < 0 || at + padded > (int64_t)n)
            return 0;
        for (int64_t x = 0; x < w; x++) {
            const uint32_t i = pixel_index(b + at, x, bpp);
            if (i >= entries) {
                snprintf(why, why_size,
                         "BMP pixel %lld of stored row %lld uses colour %u of a %u-entry colour table (OpenImageIO 2.4 "
                         "reads past the table)",
                         (long long)x, (long long)y, (unsigned)i, (unsigned)entries);
                return -1;
            }
        }
    }
    return 0;
}

int dr_bmp_check(const unsigned char *b, size_t n, bool whole, char *why, size_t why_size)
{
    if (!dr_bmp_magic(b, n))
        return 0;
    if (n < 18) {
        snprintf(why, why_size, "truncated BMP header (%zu bytes)", n);
        return -1;
    }
    const uint32_t dib = u32(b + 14), offset = u32(b + 10);
    int64_t w, h;
    uint32_t bpp, compression = 0, palette = 0;
    if ((dib == 12 && n < 26) || (dib >= 40 && n < 54)) {
        snprintf(why, why_size, "truncated BMP header (%zu bytes, %u of them the bitmap header's)", n, (unsigned)dib);
        return -1;
    }
    if (dib == 12) {   /* OS/2 1.x: 16-bit sizes, no compression, a full table */
        w = (int16_t)u16(b + 18);
        h = (int16_t)u16(b + 20);
        bpp = u16(b + 24);
    } else if (dib >= 40) {
        w = (int32_t)u32(b + 18);
        h = (int32_t)u32(b + 22);
        bpp = u16(b + 28);
        compression = u32(b + 30);
        palette = u32(b + 46);
    } else {
        snprintf(why, why_size, "BMP header of %u bytes (%zu in the file) is not one drender reads (12, or 40 and more)",
                 (unsigned)dib, n);
        return -1;
    }
    if (compression == 1 || compression == 2) {
        snprintf(why, why_size,
                 "RLE%d-compressed BMP (OpenImageIO 2.4's RLE decoder writes and reads out of bounds on malformed "
                 "files, so drender does not read any); convert it to PNG",
                 compression == 1 ? 8 : 4);
        return -1;
    }
    if (bpp != 1 && bpp != 4 && bpp != 8 && bpp != 16 && bpp != 24 && bpp != 32) {
        snprintf(why, why_size, "BMP with %u bits a pixel (1, 4, 8, 16, 24 or 32 are read)", (unsigned)bpp);
        return -1;
    }
    if (w <= 0 || h == 0)
        return 0;   /* (a size the reader refuses itself) */
    /* the reader seeks to the data offset unchecked, which from memory reads
     * outside the buffer: every row must lie in the bytes (checked wherever
     * they are all at hand, a file's too) */
    const int64_t rows = h < 0 ? -h : h, padded = ((w * bpp + 7) / 8 + 3) & ~(int64_t)3;
    if (whole && (offset < 14 + (dib == 12 ? 12u : 40u) || offset > n || rows > ((int64_t)n - offset) / padded)) {
        snprintf(why, why_size,
                 "BMP of %lldx%lld pixels whose pixel data (from byte %u, %lld rows of %lld bytes) is not all inside "
                 "its %zu bytes",
                 (long long)w, (long long)rows, (unsigned)offset, (long long)rows, (long long)padded, n);
        return -1;
    }
    if (bpp > 8 || palette == 0 || palette >= (1u << bpp))
        return 0;   /* (no table, a full one, or one the reader refuses itself) */
    if (!whole) {
        snprintf(why, why_size, "BMP with a %u-entry colour table for %u-bit pixels, too large to check",
                 (unsigned)palette, (unsigned)bpp);
        return -1;
    }
    return check_indices(b, n, offset, w, rows, bpp, palette, why, why_size);
}
