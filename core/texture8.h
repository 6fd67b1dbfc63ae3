/* Texture lookups for eight lanes at once (simd.h): dr_texture_eval's
 * bilinear lookup. For materials (dr_texref8_*), through dr_texref_uv's
 * transform and its TEXCOORD set (0 or 1), of images in eight-bit storage
 * (the kind nearly every glTF file's PNG and JPEG textures are) or float
 * storage (texture parameters, HDR files), grey or colour, with or without
 * alpha (up to four channels). dr_texture8_rgb reads any image (the environment
 * map's, env8.h). The same operations as image.c's dr_texture_taps, texel8,
 * texels and add_texel on the same inputs, so the results are the scalar
 * lookup's to the bit (test_texture8 checks both against each other). */
#ifndef DR_TEXTURE8_H
#define DR_TEXTURE8_H

#include <stdbool.h>

#include "scene.h"
#include "simd.h"

/* Each lane's texture coordinates at its hit: u[k], v[k] of TEXCOORD_k
 * (set 1: dr_hit_uv1's, 0 where the mesh has no second set). A texref
 * reads the set its texcoord names. */
struct dr_uv8 {
    dr_f8 u[2], v[2];
};

/* Does the eight-lane lookup read texref r: a texture that is there, an
 * image of 1 to 4 channels with pixels (either storage), TEXCOORD_0 or _1. */
bool dr_texref8_accepts(const struct dr_scene *s, const struct dr_texref *r);

/* For each lane i of on whose r[i] is not NULL (a texref dr_texref8_accepts):
 * the colour channels dr_texture_eval returns for r[i]'s texture at
 * dr_texref_uv of the lane's coordinates in uv, use_linear as there. Other
 * lanes get 1 in every channel, so a product with the result leaves them
 * as they were, exactly. Lanes sharing a texref are looked up together. */
dr_v3x8 dr_texref8_rgb(const struct dr_scene *s, const struct dr_texref *const r[DR_SIMD_W], dr_m8 on,
                       const struct dr_uv8 *uv, bool use_linear);

/* dr_texture_eval(tex, img, u[i], v[i], use_linear)'s colour channels (a
 * grey image's one in all three) for the lanes of on, whatever the image's
 * storage and channel count; the other lanes get 0. img must have pixels
 * (dr_image_has_pixels; an environment map always does). */
dr_v3x8 dr_texture8_rgb(const struct dr_texture *tex, const struct dr_image *img, dr_m8 on, dr_f8 u, dr_f8 v,
                        bool use_linear);

/* Asks the cache for the texels dr_texref8_rgb(s, r, on, uv, use_linear)
 * will read, without waiting (dr_texture_prefetch's job). */
void dr_texref8_prefetch(const struct dr_scene *s, const struct dr_texref *const r[DR_SIMD_W], dr_m8 on,
                         const struct dr_uv8 *uv, bool use_linear);

#endif
