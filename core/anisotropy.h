/* KHR_materials_anisotropy: the shading frame of an anisotropic material.
 *
 * The BSDF (bsdf.h) stretches its GGX lobe along the local +x axis by the
 * strength dr_material_eval puts in dr_bsdf.anisotropy; this module puts the
 * anisotropy's direction on that axis. The direction is given in the
 * surface's tangent frame (T, B) (normal_map.h's dr_hit_tangent_frame: the
 * TANGENT attribute, or generated from the UVs): (1, 0), or the anisotropy
 * texture's RG mapped to [-1, 1], turned by anisotropyRotation radians
 * counter-clockwise (from T towards B), as the extension's reference does.
 *
 * Attached sampling moves the hit point, and with it the frame: the
 * tangent's interpolation, the shading normal and the direction texture's
 * texel (d_anisotropy_frame). */
#ifndef DR_ANISOTROPY_H
#define DR_ANISOTROPY_H

#include "geometry.h"
#include "scene.h"
#include "vec.h"

/* The direction of hit's anisotropy in world space, a unit vector along the
 * surface (not yet orthogonal to the shading normal), or false where it has
 * none: no tangent frame (a triangle without UVs or TANGENT, or with
 * degenerate ones), or a texel of direction (0, 0). */
bool dr_anisotropy_direction(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 *dir);

/* Fills *f with the shading frame about the unit normal n (oriented to the
 * viewer's side, possibly bent: path.c) whose +x axis is hit's anisotropy
 * direction projected onto n's plane. False where there is no direction, or
 * it is (nearly) along n: *f is then dr_frame_from_normal(n), and the
 * caller shades the lobe isotropic there (a direction made up by the frame
 * would turn with the normal, not with the surface). */
bool dr_anisotropy_frame(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 n, dr_frame *f);
/* Reverse mode of dr_anisotropy_frame: given d loss / d f->s and d f->t
 * (d_f->n is the caller's: f->n is n itself), adds d loss / d n to *d_n and
 * d loss / d hit to *d_hit: hit->ns (the tangent's Gram-Schmidt and the
 * bitangent), the interpolated tangent and the direction texture's uv.
 * False, touching nothing, where dr_anisotropy_frame returned false (the
 * frame was dr_frame_from_normal's: d_frame_from_normal is its adjoint). */
bool d_anisotropy_frame(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 n, const dr_frame *d_f,
                        dr_vec3 *d_n, struct dr_d_hit *d_hit);

#endif
