/* What OpenImageIO 2.4's BMP reader must not be given (it crashes or reads
 * and writes out of bounds on such files: found by make fuzz, and fixed in
 * OpenImageIO 3.0.16, CVE-2026-50291; Debian 12 ships 2.4.7):
 *  - RLE4/RLE8 compression: its decoder runs while the file opens, writes
 *    rows past its buffer when the stream moves beyond the last row, and
 *    looks pixels up in a colour table that a 24-bit file does not have
 *    (a 261-byte file: segmentation fault);
 *  - a palette image (1, 4 or 8 bits a pixel) whose pixels use entries past
 *    the end of a short colour table (its lookups are unchecked);
 *  - a bit depth other than 1, 4, 8, 16, 24 or 32;
 *  - pixel data that is not all inside the bytes (its memory reader seeks
 *    to the header's data offset unchecked: an offset of -44 read before
 *    the buffer).
 * Checked from the file's bytes before the reader sees them; anything that
 * is not a BMP ("BM"), or that this check does not reach, is left to the
 * reader. */
#ifndef DR_BMP_CHECK_H
#define DR_BMP_CHECK_H

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Does b (n bytes: the whole file, or its first bytes when whole is false)
 * start a BMP? */
static inline bool dr_bmp_magic(const unsigned char *b, size_t n)
{
    return n >= 2 && b[0] == 'B' && b[1] == 'M';
}

/* 0 when the BMP in b (n bytes; whole: the complete file, so its pixels can
 * be checked against a short colour table, else a short table is refused)
 * is safe to hand to the reader, or not a BMP at all; else -1 and why in
 * why (a sentence fragment: "RLE8-compressed BMP ..."). */
int dr_bmp_check(const unsigned char *b, size_t n, bool whole, char *why, size_t why_size);

#ifdef __cplusplus
}
#endif

#endif
