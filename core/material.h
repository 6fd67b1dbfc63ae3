/* A glTF material evaluated at a surface point: factors times textures. */
#ifndef DR_MATERIAL_H
#define DR_MATERIAL_H

#include "bsdf.h"
#include "geometry.h"
#include "grad_sink.h"
#include "params.h"
#include "scene.h"

/* Fills b with the BSDF parameters at hit (baseColorTexture is sRGB-decoded
 * rgb, times COLOR_0 when the mesh has vertex colours; metallicRoughnessTexture:
 * G = roughness, B = metallic, linear). Textures are looked up at their texref's
 * uv set through its KHR_texture_transform (dr_texref_uv). */
void dr_material_eval(const struct dr_scene *scene, const struct dr_hit *hit, struct dr_bsdf *b);
/* Prefetches the texels that shading hit will read from its material's
 * textures (base colour, metallic-roughness, emission, normal map), for a
 * packet tracer that locates all its hits before shading them
 * (dr_texture_prefetch). Changes no result; a material without textures
 * costs a few loads. */
void dr_material_prefetch(const struct dr_scene *scene, const struct dr_hit *hit);
/* Adjoint: d_b (of dr_material_eval's output) into the requested factors and
 * texels of the hit's material. */
void d_material_eval(const struct dr_scene *scene, const struct dr_param_set *params, const struct dr_hit *hit,
                     const struct dr_d_bsdf *d_b, struct dr_grad_sink *sink);

/* Adjoint of dr_material_eval with respect to the hit's interpolated
 * attributes (attached sampling): d_b into d_hit->uv, uv1 (+=) through the
 * textures' slopes and transforms, and into d_hit->color (vertex colours). */
void d_material_eval_uv(const struct dr_scene *scene, const struct dr_hit *hit, const struct dr_d_bsdf *d_b,
                        struct dr_d_hit *d_hit);

#endif
