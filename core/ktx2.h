/* KTX 2.0 textures: the container glTF's KHR_texture_basisu names, and the
 * one Blender and Bevy export .ktx2 images in.
 *
 * OpenImageIO reads no KTX2. Many real files are not Basis Universal at all
 * but plain 8-bit texels (VK_FORMAT_R8G8B8_UNORM and friends) compressed
 * with Zstandard or zlib (Bevy's AnisotropyBarnLamp: all three of its .ktx2
 * images), which libzstd and zlib decode. Those are read here, straight to
 * dr_image's eight-bit storage (image.h), with no image library loaded.
 *
 * Read: a 2D image (not an array, cube map or volume), its level 0, of a
 * format with 8-bit UNORM or SRGB channels (R, RG, RGB, BGR, RGBA, BGRA),
 * supercompression none, Zstandard or zlib, and KTXorientation rd or ru
 * (rows bottom-up, flipped). Basis Universal (ETC1S/BasisLZ, UASTC) and
 * GPU block formats need transcoders Debian does not package: refused with
 * the reason, so that the loader can say which image and what to do. */
#ifndef DR_KTX2_H
#define DR_KTX2_H

#include <stdbool.h>
#include <stddef.h>

#include "image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Starts with KTX2's 12-byte identifier. */
bool dr_ktx2_is(const void *bytes, size_t size);

/* Can dr_ktx2_read8 decode it? 0, or DR_ERR_FORMAT with the reason (what the
 * file holds, e.g. "Basis Universal (UASTC) texels") in why. Looks at the
 * header only. */
int dr_ktx2_probe(const void *bytes, size_t size, char *why, size_t why_size);

/* Decodes level 0 into img (eight-bit storage: bytes and lut; file_is_srgb
 * for SRGB formats). R and RG images come as three channels, the missing
 * ones 0, as a GPU samples them. 0, or DR_ERR_FORMAT (malformed or
 * unsupported; the message names `label`), DR_ERR_NOMEM (including an image
 * larger than the memory drender may use, dr_image_max_bytes). img is zeroed
 * on failure. */
int dr_ktx2_read8(const void *bytes, size_t size, const char *label, struct dr_image *img);

#ifdef __cplusplus
}
#endif

#endif
