/* Normal maps (glTF material.normalTexture): tangent frames per vertex and
 * the perturbed shading normal at a hit.
 *
 * Tangents: the TANGENT attribute (xyz, w = bitangent sign; bitangent =
 * cross(normal, tangent) * w, glTF 2.0 3.7.2.1) where a primitive supplies it,
 * otherwise generated per vertex the way MikkTSpace does for a smooth mesh:
 * each triangle's tangent dP/du from its UV derivatives, projected into the
 * plane of the corner's normal (Gram-Schmidt) and accumulated with the
 * corner's angle as weight, then normalised; the handedness is the sign of
 * the bitangent against -dP/dv (glTF's v points down the image, the normal
 * map's +Y up). Unlike MikkTSpace no vertex is split: a vertex shared by
 * triangles of opposite UV orientation gets the majority's sign (exporters
 * split such vertices at UV seams anyway). A vertex whose triangles all have
 * degenerate UVs gets no tangent; the normal map is not applied there.
 *
 * The normal map is not a differentiable parameter: its image is not listed
 * by `drender params`, and attached sampling, which would need the adjoint of
 * the perturbed normal with respect to the hit point, is refused on scenes
 * with normal maps when a parameter moves the sampling (estimators/common.c). */
#ifndef DR_NORMAL_MAP_H
#define DR_NORMAL_MAP_H

#include "geometry.h"
#include "scene.h"
#include "vec.h"

/* Gives scene->mesh tangents when a material the triangles use needs them
 * (dr_material_needs_tangents: a normal map or anisotropy): allocates them (zero) if the loader did not, then generates every
 * vertex's whose w is 0. 0 or DR_ERR_NOMEM. */
int dr_mesh_prepare_tangents(struct dr_scene *scene);

/* Generates the tangent of every vertex of m whose w is 0 (m->tangents must
 * exist), from the triangles with UVs. 0 or -1 when out of memory. */
int dr_mesh_generate_tangents(struct dr_mesh *m);

/* Replaces hit->ns by the normal map's normal when hit's material has one
 * (n = normalize(x T + y B + z N), (x, y, z) = (2 texel - 1) * (scale, scale,
 * 1), T and B the interpolated tangent frame made orthonormal to the
 * interpolated normal N). Keeps the interpolated normal where the tangent is
 * missing or degenerate. The result may point below the geometric surface:
 * see dr_shading_normal_valid. path_simd.c's normal_map8 does the same for
 * eight lanes with the same operations: keep the two in step (test_render
 * compares them bit for bit). */
void dr_normal_map_apply(const struct dr_scene *scene, struct dr_hit *hit);

/* The shading normal n (unit, oriented to wo's side of the unit geometric
 * normal ng) bent towards ng just enough that the mirror reflection of wo
 * about it lies above the geometric surface (by min(0.9 wo.ng, 0.01)); n
 * itself when it already does. This is Cycles' ensure_valid_reflection
 * (Blender 3.0, intern/cycles/kernel/bsdf/bsdf_util.h): it keeps wo above the
 * shading hemisphere, so a normal-mapped surface seen at a grazing angle
 * neither turns black (wo below the shading normal: zero BSDF) nor reflects
 * into the surface; light leaks are kept away as for interpolated normals
 * (next-event and continuation directions below ng contribute nothing).
 * Returns ng when no such normal exists; never NaN. */
dr_vec3 dr_shading_normal_valid(dr_vec3 ng, dr_vec3 wo, dr_vec3 n);

/* The authored tangent frame at hit, made orthonormal to hit->ns (as
 * dr_normal_map_apply uses it): the unit tangent *t and the bitangent *b =
 * w cross(N, T) of the authored normal N (hit->ns, or its opposite where
 * the loader flipped it), so that (T, B) keeps the file's handedness on
 * either side. False where there is no frame (see dr_normal_map_apply). */
bool dr_hit_tangent_frame(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 *t, dr_vec3 *b);
/* Its reverse mode where it returned true: d loss / d t and d b add
 * d loss / d hit->ns to d_hit->ns and d loss / d the interpolated tangent
 * to d_hit->tangent (geometry.h; d_hit_compute takes both to the ray). The
 * handedness and the authored side are signs: constant. */
void d_hit_tangent_frame(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 d_t, dr_vec3 d_b,
                         struct dr_d_hit *d_hit);

#endif
