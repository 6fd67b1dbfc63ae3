/* What OpenImageIO 2.4's readers (Debian 12 ships 2.4.7) must not be given:
 * files on which make fuzz found a reader crashing, corrupting memory,
 * allocating gigabytes or reading for minutes. Each case is refused before
 * the reader sees the file, in memory and on disk, whatever the file's name:
 *  - a BMP that its reader mishandles (bmp_check.h);
 *  - a Maya IFF ("FOR4"/"FOR8"): the reader corrupts the heap on malformed
 *    RLE tiles (a 160-byte file freed a block it did not own); whole;
 *  - an ICO icon ("00 00 01 00"): the reader wrote past its pixel buffer
 *    for a 178-byte icon whose bitmap header says 6x5 where its directory
 *    entry says 6x4 (a heap corruption that ASan saw only when its
 *    quarantine recycled the block, 45000 inputs later); whole, and also
 *    when a reader opened a file as ICO (dr_unsafe_reader);
 *  - an SGI image (magic 0x01DA): opening a 155-byte file that claims
 *    53374x3414 RLE pixels took the reader 28-40 s and 5.7 GB; whole;
 *  - a Softimage PIC (magic 0x5380F634): the reader dereferenced a null
 *    FILE reading the scanlines of malformed files (12 crashing inputs
 *    in 3.5 min, a segmentation fault in drender and in oiiotool); whole,
 *    and also when the reader opened a file as Softimage;
 *  - a DPX whose header gives more user data than the file holds (the
 *    reader allocates it, 4.3 GB for a 2.5 KB file, then aborts), or more
 *    pixels than it could hold at a bit each (the reader read a 3 KB file
 *    claiming 1x50348100 pixels past its end for minutes);
 *  - a DDS whose uncompressed pixel format names a channel with an empty bit
 *    mask (the reader looped forever on a 192-byte file), or that claims
 *    more mipmap levels than its size allows (minutes for a 140-byte file);
 *  - a Photoshop file (PSD, PSB) whose sections claim more bytes than the
 *    file holds (the reader allocated 3 GB for a 101-byte file; a file on
 *    disk is checked section by section, dr_unsafe_image_file_check).
 * And a format that has no magic bytes, told only by the reader that opened
 * the file (dr_unsafe_reader):
 *  - Wavefront RLA: the reader looped for minutes reading a 791-byte file;
 *  - OpenImageIO's null reader, which makes a black image of any file named
 *    .null (a garbage texture would render black, silently);
 *  - video (the ffmpeg reader): no glTF texture is a video, and libavformat's
 *    many container parsers are not worth exposing to a scene's files.
 * None of these is a format glTF uses; IFF, ICO, SGI, PIC and RLA are refused whole,
 * DPX, DDS and PSD (film scans, game textures and paintings are plausible
 * targets) only where the header is impossible. */
#ifndef DR_UNSAFE_IMAGES_H
#define DR_UNSAFE_IMAGES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* 0 when the file whose first n bytes are b (whole: b is all of it) may be
 * handed to a reader; else -1 and why (a sentence fragment naming what the
 * file is and why it is refused). file_size: the whole file's length. */
int dr_unsafe_image_check(const unsigned char *b, size_t n, bool whole, uint64_t file_size, char *why,
                          size_t why_size);

/* The checks that need more of a file on disk than its first bytes (a
 * Photoshop file's sections, found by seeking from length to length): 0
 * or -1 and why, as dr_unsafe_image_check. Moves f's position. */
int dr_unsafe_image_file_check(FILE *f, uint64_t file_size, char *why, size_t why_size);

/* Why a file that OpenImageIO opened with the reader `format_name` must not
 * be read any further, or NULL when it may. */
const char *dr_unsafe_reader(const char *format_name);

#ifdef __cplusplus
}
#endif

#endif
