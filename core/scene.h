/* The scene as the tracer sees it: one flattened world-space triangle mesh,
 * materials, textures, cameras, lights and the environment.
 * Filled by the glTF loader (gltf_load.cpp), then prepared by scene.c
 * (acceleration structure, light sampling tables, effect flags). */
#ifndef DR_SCENE_H
#define DR_SCENE_H

#include <stdbool.h>
#include <stdint.h>

#include "image.h"
#include "vec.h"

#ifdef __cplusplus
extern "C" {
#endif

#define DR_NAME_MAX 64

struct dr_texref {
    int texture;   /* index into scene->textures, -1 when absent */
    int texcoord;  /* TEXCOORD_n set; only 0 is loaded */
};

/* glTF metallic-roughness material (+ KHR_materials_specular,
 * KHR_materials_emissive_strength). Colours are linear RGB. */
struct dr_material {
    char name[DR_NAME_MAX];
    dr_vec3 base_color;            /* baseColorFactor rgb */
    double metallic, roughness;    /* metallicFactor, roughnessFactor */
    dr_vec3 emissive_factor;       /* emissiveFactor */
    double emissive_strength;      /* KHR_materials_emissive_strength (1 if absent) */
    double specular;               /* KHR_materials_specular specularFactor (1 if absent) */
    dr_vec3 specular_color;        /* specularColorFactor (1,1,1 if absent) */
    bool double_sided;
    struct dr_texref base_color_tex, metallic_roughness_tex, emissive_tex;
};

enum dr_tri_flags {
    DR_TRI_HAS_NORMALS = 1, /* interpolate vertex normals (else flat) */
    DR_TRI_HAS_UVS = 2
};

/* All triangles of the scene, already in world space. */
struct dr_mesh {
    uint32_t n_vertices, n_triangles;
    float *positions;   /* 3 per vertex, plus 1 padding float (Embree reads 16 bytes) */
    float *normals;     /* 3 per vertex (zero where the primitive had none) */
    float *uvs;         /* 2 per vertex (zero where the primitive had none) */
    uint32_t *indices;  /* 3 per triangle, counter-clockwise = front */
    int32_t *material;  /* per triangle, index into scene->materials */
    uint8_t *flags;     /* per triangle, enum dr_tri_flags */
    /* derived by dr_scene_prepare: per triangle unit geometric normal (x, y, z)
     * and ray-offset distance (see dr_offset_origin), so hits need not redo them */
    double *tri_normal_eps;  /* 4 per triangle */
};

struct dr_camera {
    char name[DR_NAME_MAX];
    dr_vec3 origin;
    dr_vec3 right, up, forward;   /* unit, world space; looks along forward */
    double yfov;                  /* radians, vertical field of view */
    double aspect;                /* glTF aspectRatio, 0 when absent */
};

enum dr_light_type { DR_LIGHT_POINT, DR_LIGHT_SPOT, DR_LIGHT_DIRECTIONAL };

/* KHR_lights_punctual, radiometric (see manual: intensity W/sr for point and
 * spot, irradiance W/m^2 for directional, colour multiplies). */
struct dr_punctual {
    char name[DR_NAME_MAX];
    enum dr_light_type type;
    dr_vec3 color;
    double intensity;
    dr_vec3 position;
    dr_vec3 direction;      /* unit, the direction light travels (node's -Z) */
    double range;           /* 0 = infinite */
    double cos_inner, cos_outer;  /* spot cone, cosines */
    int gltf_index;         /* index in KHR_lights_punctual.lights */
};

/* drender's DR_environment extension: radiance arriving from infinity,
 * color * strength, optionally times an equirectangular image. */
struct dr_environment {
    bool present;
    dr_vec3 color;          /* "color" (default 1,1,1) */
    double strength;        /* "strength" (default 1) */
    struct dr_image map;    /* map.data == NULL: constant radiance */
    char uri[512];
    bool is_default;        /* set by drender (no light in the file), not by the file */
};

struct dr_accel;
struct dr_light_sampler;
struct dr_medium;   /* medium.h */

/* Effects a render of this scene needs, decided once in dr_scene_prepare. */
enum dr_effect {
    DR_FX_AREA_LIGHTS = 1 << 0,
    DR_FX_PUNCTUAL_LIGHTS = 1 << 1,
    DR_FX_ENV_CONSTANT = 1 << 2,
    DR_FX_ENV_MAP = 1 << 3,
    DR_FX_TEXTURES = 1 << 4,
    DR_FX_SPECULAR = 1 << 5,     /* some material has a non-zero specular lobe */
    DR_FX_SHADING_NORMALS = 1 << 6,
    DR_FX_MEDIA = 1 << 7,              /* some participating medium (medium.h) */
    DR_FX_HETEROGENEOUS_MEDIA = 1 << 8, /* ... with a density grid */
    DR_FX_DIELECTRIC_BOUNDARIES = 1 << 9 /* ... bounded by a smooth dielectric (medium.h: ior) */
};

struct dr_scene {
    char *path;
    struct dr_mesh mesh;
    struct dr_material *materials; int n_materials;  /* last one may be the glTF default */
    int n_file_materials;         /* those in the file's "materials" (the rest: the default) */
    struct dr_texture *textures; int n_textures;
    struct dr_image *images; int n_images;
    struct dr_camera *cameras; int n_cameras;
    struct dr_punctual *lights; int n_lights;
    struct dr_environment env;
    dr_vec3 bbox_min, bbox_max;
    /* participating media (all NULL / 0 without any): */
    struct dr_medium *media; int n_media;
    int *material_medium;         /* per material: the medium it bounds, -1; NULL without media */
    int global_medium;            /* the medium outside every medium mesh, -1: vacuum */

    /* built by dr_scene_prepare() */
    struct dr_accel *accel;
    struct dr_light_sampler *light_sampler;
    unsigned effects;             /* enum dr_effect bits */
};

/* Loads a .gltf/.glb and prepares it for rendering. NULL + dr_last_error() on
 * failure; the message names the file and, for content errors, the JSON path. */
struct dr_scene *dr_scene_load(const char *path);
int dr_scene_prepare(struct dr_scene *scene);
/* After materials, lights or the environment changed (parameters set):
 * recomputes the effect flags and the light sampling tables. Geometry must
 * not have changed. 0 or DR_ERR_NOMEM. */
int dr_scene_refresh(struct dr_scene *scene);
void dr_scene_destroy(struct dr_scene *scene);

/* True when something in the scene emits: an emissive triangle with power,
 * a punctual light, or an environment (even one of strength 0: the file
 * asked for it). A scene without is black whatever the materials. */
bool dr_scene_has_light(const struct dr_scene *scene);
/* Replaces the environment with color * strength, times the equirectangular
 * image map_path when it is not NULL (read like DR_environment/uri), and
 * refreshes the scene. is_default marks drender's own default lighting (the
 * glTF writer does not write it back unless its parameters were fitted).
 * 0 or a negative DR_ERR_* with dr_last_error naming the file. */
int dr_scene_set_environment(struct dr_scene *scene, dr_vec3 color, double strength, const char *map_path,
                             bool is_default);
/* Comma-separated names of the effect bits, for --json and messages. */
void dr_effects_describe(unsigned effects, char *buf, int size);

/* The glTF shim (gltf_load.cpp): fills every field above "built by
 * dr_scene_prepare". Returns 0 or a negative DR_ERR_* with dr_last_error set;
 * on failure the scene may hold partial allocations: call dr_scene_destroy. */
int dr_gltf_load(const char *path, struct dr_scene *scene);

#ifdef __cplusplus
}
#endif
#endif
