/* Differentiable scene parameters, named by JSON pointers into the glTF
 * document (material names may stand in for indices):
 *   /materials/M/pbrMetallicRoughness/baseColorFactor                  3 (rgb; alpha is not rendered)
 *   /materials/M/pbrMetallicRoughness/metallicFactor                   1
 *   /materials/M/pbrMetallicRoughness/roughnessFactor                  1
 *   /materials/M/emissiveFactor                                        3
 *   /materials/M/extensions/KHR_materials_emissive_strength/emissiveStrength  1
 *   /extensions/KHR_lights_punctual/lights/L/color                     3
 *   /extensions/KHR_lights_punctual/lights/L/intensity                 1
 *   /extensions/DR_environment/color                                   3
 *   /extensions/DR_environment/strength                                1
 *   /extensions/DR_environment/uri            every texel of the environment map (w*h*3)
 *   /images/I                                 every texel of image I (w*h*channels, rgb(a))
 * Participating media (medium.h), MEDIUM = /materials/M/extensions/DR_medium
 * for the medium a material bounds (also when KHR_materials_volume declares
 * it), /extensions/DR_medium for the global medium:
 *   MEDIUM/extinction                                                  3 (1/m at density 1)
 *   MEDIUM/albedo                                                      3
 *   MEDIUM/g                                                           1
 *   MEDIUM/density_scale                                               1
 *   MEDIUM/density                            every voxel of the grid (nx*ny*nz)
 * Image texels are the linear values the renderer looks up: sRGB-decoded for
 * colour textures, as stored for metallic-roughness data. */
#ifndef DR_PARAMS_H
#define DR_PARAMS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "scene.h"

/* (the material kinds come first: DR_PARAM_BASE_COLOR .. DR_PARAM_LAST_MATERIAL) */
enum dr_param_kind {
    DR_PARAM_BASE_COLOR,
    DR_PARAM_METALLIC,
    DR_PARAM_ROUGHNESS,
    DR_PARAM_EMISSIVE_FACTOR,
    DR_PARAM_EMISSIVE_STRENGTH,
    DR_PARAM_CLEARCOAT,             /* KHR_materials_clearcoat, coated materials only */
    DR_PARAM_CLEARCOAT_ROUGHNESS,
    DR_PARAM_ANISOTROPY_STRENGTH,   /* KHR_materials_anisotropy, anisotropic materials only */
    DR_PARAM_SHEEN_COLOR,           /* KHR_materials_sheen, sheened materials only */
    DR_PARAM_SHEEN_ROUGHNESS,
    DR_PARAM_LIGHT_COLOR,
    DR_PARAM_LIGHT_INTENSITY,
    DR_PARAM_ENV_COLOR,
    DR_PARAM_ENV_STRENGTH,
    DR_PARAM_ENV_MAP,
    DR_PARAM_IMAGE,
    DR_PARAM_MEDIUM_EXTINCTION,   /* media: target = medium index */
    DR_PARAM_MEDIUM_ALBEDO,
    DR_PARAM_MEDIUM_G,
    DR_PARAM_MEDIUM_DENSITY_SCALE,
    DR_PARAM_MEDIUM_DENSITY,
    DR_PARAM_KIND_COUNT
};

#define DR_PARAM_LAST_MATERIAL DR_PARAM_SHEEN_ROUGHNESS
#define DR_PARAM_NAME_MAX 160

struct dr_param {
    char name[DR_PARAM_NAME_MAX]; /* canonical pointer, with indices */
    enum dr_param_kind kind;
    int target;                   /* material, glTF light or image index (-1: environment) */
    int64_t size;                 /* number of scalars */
    int64_t offset;               /* first scalar in a gradient vector (set by dr_param_set_create) */
    int width, height, channels;  /* images and the environment map */
};

/* A parameter with one scalar per texel or voxel (images, the environment
 * map, density grids): listed, checked and written as an array. */
static inline bool dr_param_is_array(const struct dr_param *p)
{
    return p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP || p->kind == DR_PARAM_MEDIUM_DENSITY;
}

/* The name with the material's name in place of its index when that name
 * is unique (what a user would type), else the canonical name. */
void dr_param_display_name(const struct dr_scene *scene, const struct dr_param *p, char *buf, size_t size);

/* "color", "scalar", "image": a word for listings. */
const char *dr_param_type_name(const struct dr_param *p);
/* Physical range of each scalar (for optimisers and finite differences). */
void dr_param_range(const struct dr_param *p, double *lo, double *hi);
/* The JSON pointer prefix of a medium's parameters: "/materials/M/extensions/DR_medium"
 * for the medium bounded by material M, "/extensions/DR_medium" for the global one (-1). */
void dr_medium_param_prefix(int material, char *buf, size_t size);

/* Every differentiable parameter the scene offers, in document order.
 * *out is malloc'd. 0 or DR_ERR_NOMEM. */
int dr_params_list(const struct dr_scene *scene, struct dr_param **out, int *count);

/* Resolves a pointer (indices or material names). On failure returns
 * DR_ERR_ARG with a message that lists the nearest valid names. */
int dr_param_resolve(const struct dr_scene *scene, const char *pointer, struct dr_param *out);

/* Current values (size scalars) / new values of a parameter. Setting changes
 * the scene; call dr_scene_refresh() before rendering again. */
void dr_param_get(const struct dr_scene *scene, const struct dr_param *p, double *values);
void dr_param_put(struct dr_scene *scene, const struct dr_param *p, const double *values);

/* The requested parameters, laid out in one gradient vector, with per-object
 * lookups for the tracer: an offset of -1 means "not requested", so a vertex
 * whose material, emitter or texture has no requested parameter does no
 * derivative work at all. */
struct dr_param_set {
    struct dr_param *params;
    int n;
    int64_t total;                       /* scalars in the gradient vector */
    int n_materials, n_lights, n_images;
    int64_t *mat_base_color, *mat_metallic, *mat_roughness;      /* per material */
    int64_t *mat_emissive_factor, *mat_emissive_strength;        /* per material */
    int64_t *mat_coat, *mat_coat_roughness;                      /* per material */
    int64_t *mat_anisotropy;                                     /* per material: anisotropyStrength */
    int64_t *mat_sheen_color, *mat_sheen_roughness;              /* per material: KHR_materials_sheen's */
    int64_t *light_color, *light_intensity;                      /* per scene light instance */
    int64_t *image;                                              /* per image: texel (0,0) */
    int64_t env_color, env_strength, env_map;
    bool *mat_bsdf_active;      /* base colour, metallic, roughness, the coat's, the anisotropy's, the sheen's or one of their textures */
    bool *mat_emission_active;  /* emissive factor, strength or texture */
    bool lights_active;         /* some punctual light parameter */
    bool env_active;
    bool radiance_active;       /* some light's radiance: an emission, the environment or a punctual light */
    /* participating media, per medium (scene->media): */
    int n_media;
    int64_t *med_extinction, *med_albedo, *med_g, *med_density_scale, *med_density;
    bool *med_active;           /* some parameter of that medium */
    bool media_active;
};

/* Resolves every pointer; duplicates and images used both as colour and as
 * data are refused. NULL + dr_last_error on failure. */
struct dr_param_set *dr_param_set_create(const struct dr_scene *scene, const char *const *pointers, int n);
void dr_param_set_destroy(struct dr_param_set *set);

/* All values of the set, concatenated (total scalars) / written back. A
 * texture kept in eight bits (image.h) is read in place; writing it needs
 * its floats: call dr_param_set_writable once before the first put. */
void dr_param_set_get(const struct dr_scene *scene, const struct dr_param_set *set, double *values);
void dr_param_set_put(struct dr_scene *scene, const struct dr_param_set *set, const double *values);
/* Makes the set's textures writable: those kept in eight bits go back to
 * floats (the same values; a change of storage, not of the scene). Only
 * callers that put values pay for it: `grad` reads a texture's eight bits
 * (a 2k colour texture: 12 MB, not 50 of floats plus the faults that make
 * them). 0, or DR_ERR_NOMEM with the parameter named. */
int dr_param_set_writable(struct dr_scene *scene, const struct dr_param_set *set);
/* The same with a big parameter's values (a texture's texels) converted on
 * up to `threads` workers (dr_parallel_elements; the same floats), writing
 * only the ones that changed (an optimisation step moves a preview's
 * texture in few places): optimize's step, 5 % of a 2k texture's
 * iteration on one thread. changed, when not NULL, is a block mask of
 * values (zero_blocks.h: dr_adam_changed) outside which no value changed
 * since the last put: a texture's floats are then looked at only there. */
void dr_param_set_put_threads(struct dr_scene *scene, const struct dr_param_set *set, const double *values,
                              int threads, const uint64_t *changed);
/* After dr_param_set_put: dr_scene_refresh where a radiance has a parameter
 * (an emission, a light, the environment: their sampling tables change),
 * else dr_scene_refresh_keep_lights, which keeps the tables (the lights are as
 * they were). Optimising a 2k base-colour texture rebuilt its scene's
 * emissive-texture grid every iteration: 30 ms of each. */
int dr_param_set_refresh(struct dr_scene *scene, const struct dr_param_set *set);

#endif
