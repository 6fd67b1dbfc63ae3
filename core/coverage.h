/* Surfaces a ray may pass through, as glTF says:
 *  - alphaMode MASK: the surface is there where alpha >= alphaCutoff, a hole
 *    elsewhere (alpha = baseColorFactor.a x the base colour texture's alpha);
 *  - alphaMode BLEND: stochastic transparency: a ray stops at the surface with
 *    probability alpha and passes otherwise (an unbiased estimate of
 *    alpha x surface + (1 - alpha) x what lies behind);
 *  - thin-walled glass (dr_material.thin_ior): a ray stops at the sheet with
 *    probability R, the sheet's reflectance for the ray's angle
 *    (dr_thin_reflectance), and passes straight through otherwise: an
 *    unbiased estimate of R x reflection + (1 - R) x what lies behind, for
 *    shadow rays too, so next-event estimation sees lights through glass.
 *    What stops is shaded by the material as a white metal (scene.h);
 *  - doubleSided false: back faces are culled, a ray arriving at the back of
 *    the triangle passes. Media boundaries (a material bounding a medium,
 *    medium_scene.h) are never culled: closed meshes crossed from both sides.
 * These hold for every ray: camera, extension and shadow rays alike.
 *
 * The BLEND decision is a pure function of (query key, triangle): the walker
 * derives the key from its path's sampler key, the vertex depth and the ray's
 * purpose (path.h), so a replay, a tape sweep and a finite-difference run see
 * the same surfaces; the triangle in the hash makes two BLEND layers along one
 * ray independent. Accepting with probability alpha does not depend on any
 * differentiable parameter, so gradients of the others stay unbiased; alpha
 * itself is not differentiated.
 *
 * The tests run inside Embree's filter callbacks (accel.c); triangles whose
 * material needs none of this sit in a geometry without a filter. */
#ifndef DR_COVERAGE_H
#define DR_COVERAGE_H

#include <stdbool.h>
#include <stdint.h>

#include "sampler.h"   /* dr_hash64 */
#include "scene.h"
#include "vec.h"

enum dr_cover_bits {
    DR_COVER_CULL = 1,    /* single-sided: the back passes */
    DR_COVER_MASK = 2,
    DR_COVER_BLEND = 4,
    DR_COVER_THIN = 8
};

/* Reflectance of a thin non-absorbing sheet of index ior for a ray at
 * |cos| = cos_i to its normal: both faces' Fresnel reflections summed over
 * the bounces between them, R = 2F / (1 + F) (F the single interface's
 * unpolarised Fresnel reflectance; no interference). */
double dr_thin_reflectance(double cos_i, double ior);

/* Effects whose surfaces a ray passes by a draw keyed on the query (BLEND,
 * thin glass): traces need their keys then; shadow rays also where a light
 * point may lie in a MASK hole (dr_coverage_point_present). */
#define DR_FX_KEYED_TRACES (DR_FX_ALPHA_BLEND | DR_FX_THIN_TRANSMISSION)
#define DR_FX_KEYED_SHADOWS (DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND | DR_FX_THIN_TRANSMISSION)

/* The enum dr_cover_bits of material m (0: an ordinary opaque surface). */
unsigned dr_material_coverage(const struct dr_scene *scene, int m);

/* alpha at barycentrics (b1, b2) of triangle tri: baseColorFactor.a times the
 * base colour texture's alpha at its TEXCOORD set, through its KHR_texture_transform. */
double dr_surface_alpha(const struct dr_scene *scene, int64_t tri, double b1, double b2);

/* The uniform number in [0, 1) a BLEND surface draws for a query. */
static inline double dr_blend_uniform(uint64_t key, int64_t tri)
{
    uint64_t x = dr_hash64(key ^ ((uint64_t)tri * 0x9e3779b97f4a7c15ULL + 0x632be59bd9b4e019ULL));
    return (double)(x >> 11) * 0x1.0p-53;
}

/* Does triangle tri (coverage bits bits) stop a ray of direction d at
 * barycentrics (b1, b2)? key: the query's key (BLEND). */
bool dr_coverage_blocks(const struct dr_scene *scene, unsigned bits, int64_t tri, double b1, double b2, dr_vec3 d,
                        uint64_t key);

/* Is the surface there at a point sampled on an emissive triangle (next-event
 * estimation: a light point in a MASK hole or on a BLEND surface that lets
 * this query through emits nothing)? Culling does not apply: emission from
 * the back is already zero (lights.c). */
bool dr_coverage_point_present(const struct dr_scene *scene, int64_t tri, double b1, double b2, uint64_t key);

/* Query keys (see above): one per path vertex and purpose. */
enum dr_ray_purpose { DR_RAY_TRACE = 1, DR_RAY_SHADOW = 2 };
static inline uint64_t dr_coverage_key(uint64_t path_key, int depth, enum dr_ray_purpose purpose)
{
    return dr_hash64(path_key ^ ((uint64_t)depth * 0xd6e8feb86659fd93ULL) ^ ((uint64_t)purpose << 56));
}

#endif
