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
/* Same, but an 8-bit file's pixels come in eight-bit storage (image.h:
 * bytes and a table of the floats dr_image_read_memory would give, no float
 * copy made on the way); other files as float. For scene textures. */
int dr_image_read_memory8(const void *bytes, size_t size, const char *name_hint, struct dr_image *img);

/* Largest decoded image dr_image_read* accept, in bytes of float pixels plus
 * their linear copy (width x height x channels x 4 x 2; dr_image_read_memory8
 * of an 8-bit file: one byte per value); a larger image is
 * refused from its header, before any pixel memory is allocated, with
 * DR_ERR_NOMEM and a message naming the image and its size. 0 = no limit.
 * Default: the machine's physical memory. */
void dr_image_set_max_bytes(unsigned long long bytes);
/* That limit (until it is set: the physical memory; 0 if unknown). Readers
 * of drender's own (core/ktx2.h) honour it too. */
unsigned long long dr_image_max_bytes(void);
/* The threads the image library may use (OpenEXR's compression):
 * --threads; n <= 0: its default, one per CPU. Does not load the library. */
void dr_image_set_threads(int n);

/* Loads the image library (core/image_plugin.h) if it is not loaded yet;
 * false, with dr_last_error naming where it looked, when it cannot be loaded
 * (an installation problem, not a problem of the user's file). */
bool dr_image_library_ok(void);
/* Starts loading the image library on a thread of its own and returns at
 * once (no-op after the first call, or if the thread cannot be made: the
 * first use loads it then). The first use waits for that load instead of
 * doing its own; an error is reported there, as without the preload. A
 * program calls it once its own threads exist (dr_parallel_set_started_hook),
 * so that the render overlaps the load's 0.2 s (image_plugin.h), and only
 * with a CPU to spare: the load takes one CPU for that time. */
void dr_image_library_preload(void);

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

/* One float grid of a volume file: an OpenVDB file through OpenImageIO's
 * openvdb reader, which presents each float (1 channel) or vec3 (3 channels)
 * grid as a tiled volume subimage named after the grid, whose display window
 * is the grid's active voxel bounding box in index space. */
struct dr_volume {
    int nx, ny, nz;     /* the active voxel bounding box, in voxels */
    int x0, y0, z0;     /* index coordinates of its first voxel */
    float *data;        /* nx*ny*nz voxels, x fastest, then y, then z; release with free() */
    char grid[64];      /* the name of the grid read */
};

/* Most voxels a volume may have (the density grids' limit). */
#define DR_VOLUME_MAX_VOXELS (1 << 28)

/* Reads the float grid named `grid` (NULL or "": the grid named "density",
 * else the first float grid) of a volume file: the voxels of its active
 * bounding box (inactive ones inside it as the reader fills them: the
 * background). Refused from the header, before any voxel memory is taken,
 * when the decoded volume (the reader's tile-aligned buffer, the copy and the
 * file's grid as OpenVDB holds it) would need more than dr_image_set_max_bytes
 * allows (DR_ERR_NOMEM) or the box has more than DR_VOLUME_MAX_VOXELS.
 * 0 or negative DR_ERR_*: DR_ERR_IO when the file cannot be read,
 * DR_ERR_FORMAT when it is not an OpenVDB file, has no float grid (or none of
 * that name) or the grid has no active voxel; the message names the path. */
int dr_volume_read(const char *path, const char *grid, struct dr_volume *vol);

#ifdef __cplusplus
}
#endif
#endif
