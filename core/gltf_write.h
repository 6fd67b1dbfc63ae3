/* Writing a scene back as glTF with parameter values replaced (gltf_write.cpp),
 * for `drender optimize -o result.gltf`. */
#ifndef DR_GLTF_WRITE_H
#define DR_GLTF_WRITE_H

#include "scene.h"

#ifdef __cplusplus
extern "C" {
#endif

#include "params.h"   /* (params.h has no extern "C" of its own) */

/* Writes a copy of the glTF file scene->path to out_path (.gltf: JSON plus an
 * external .bin; .glb: binary, chosen by the extension) with every parameter of
 * `params` (NULL: none) replaced by its current value in `scene`.
 *
 * - Materials: baseColorFactor (the file's alpha is kept), metallicFactor,
 *   roughnessFactor, emissiveFactor, KHR_materials_emissive_strength
 *   (the extension object is added when absent). glTF requires each
 *   emissiveFactor component in [0,1]: when an optimised factor exceeds 1, the
 *   excess moves into the strength (factor / m, strength * m, m = the largest
 *   component), so factor * strength, which is what renders, is unchanged.
 *   Light colours above 1 move into the intensity the same way
 *   (KHR_lights_punctual colours are in [0,1] too). Values outside glTF's
 *   ranges are clamped (base colour, metallic, roughness to [0,1], factors,
 *   strengths and intensities to >= 0) with a warning; a non-finite value is
 *   an error (DR_ERR_ARG).
 * - Image parameters /images/N become new files next to out_path,
 *   <out-stem>.image<N>.png (8-bit; sRGB-encoded when the image is a colour
 *   texture, as-is when it is metallic-roughness data), the image's uri points
 *   at them (mimeType and bufferView cleared).
 * - The environment map parameter becomes <out-stem>.environment.exr (float)
 *   and DR_environment/uri points at it; its color and strength are updated.
 * - Everything else is kept: other images keep their uri (external files are
 *   copied into out_path's directory when it differs from the source's, so the
 *   result is self-contained; a uri that climbs out with ".." is copied as
 *   <out-stem>.image<N>.<ext> and the uri changed; data: URIs, bufferView
 *   images, absolute paths and URIs with a scheme stay as they are), buffers
 *   become <out-stem>.bin (<out-stem>.<i>.bin for buffer i > 0; in a .glb the
 *   first buffer is the binary chunk), extensions and extras are kept, and
 *   extensionsUsed is completed with every extension the output uses.
 *
 * Atomic: everything is written into a private temporary directory beside
 * out_path and renamed into place at the end; on failure nothing is left
 * (files already renamed are removed again). Returns 0 or a negative DR_ERR_*
 * with dr_last_error() naming the file. */
int dr_gltf_write(const struct dr_scene *scene, const struct dr_param_set *params, const char *out_path);

#ifdef __cplusplus
}
#endif
#endif
