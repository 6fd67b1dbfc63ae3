/* Reading and writing images through OpenImageIO (image_io.cpp). */
#ifndef DR_IMAGE_IO_H
#define DR_IMAGE_IO_H

#include <stdbool.h>
#include <stddef.h>

#include "image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Reads any format OpenImageIO knows into img->data as float, values as
 * stored (no colour conversion); sets file_is_srgb from the file's colour
 * space (8-bit PNG/JPEG are sRGB). 0 or negative DR_ERR_*, message names path. */
int dr_image_read(const char *path, struct dr_image *img);
/* Same, decoding an in-memory encoded file (glTF data URIs, .glb buffers);
 * `name_hint` is used for the format and for messages. */
int dr_image_read_memory(const void *bytes, size_t size, const char *name_hint,
                         struct dr_image *img);

/* Largest decoded image dr_image_read* accept, in bytes of float pixels plus
 * their linear copy (width x height x channels x 4 x 2); a larger image is
 * refused from its header, before any pixel memory is allocated, with
 * DR_ERR_NOMEM and a message naming the image and its size. 0 = no limit.
 * Default: the machine's physical memory. */
void dr_image_set_max_bytes(unsigned long long bytes);

/* Loads the image library (core/image_plugin.h) if it is not loaded yet;
 * false, with dr_last_error naming where it looked, when it cannot be loaded
 * (an installation problem, not a problem of the user's file). */
bool dr_image_library_ok(void);

/* True when OpenImageIO can write this file name's format. */
bool dr_image_can_write(const char *path);

/* Writes linear float RGB(A) pixels. The format follows the extension: float
 * formats (EXR, HDR, TIFF, PFM) stay linear float; 8-bit formats (PNG, JPEG,
 * ...) are sRGB-encoded. Written to a temporary file beside `path` and renamed,
 * so a failure never leaves a partial file. 0 or negative DR_ERR_*. */
int dr_image_write(const char *path, int width, int height, int channels,
                   const float *pixels);
/* Same, but 8-bit formats get the sRGB curve only when `srgb_encode` (colour
 * textures, images); without it the values are quantised as they are (data
 * textures such as glTF metallic-roughness) and the file carries no colour-space
 * tag. Float formats ignore the flag. dr_image_write(...) is
 * dr_image_write_encoded(..., true). */
int dr_image_write_encoded(const char *path, int width, int height, int channels,
                           const float *pixels, bool srgb_encode);

#ifdef __cplusplus
}
#endif
#endif
