/* A glTF material evaluated at a surface point: factors times textures. */
#ifndef DR_MATERIAL_H
#define DR_MATERIAL_H

#include "bsdf.h"
#include "geometry.h"
#include "scene.h"

/* Fills b with the BSDF parameters at hit (baseColorTexture is sRGB-decoded
 * rgb; metallicRoughnessTexture: G = roughness, B = metallic, linear). */
void dr_material_eval(const struct dr_scene *scene, const struct dr_hit *hit, struct dr_bsdf *b);

#endif
