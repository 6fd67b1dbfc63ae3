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
    int texture;       /* index into scene->textures, -1 when absent */
    int texcoord;      /* TEXCOORD_n set: 0 or 1 (mesh.uvs1 is loaded when some texref reads 1) */
    bool transformed;  /* KHR_texture_transform: the lookup uses xf * (u, v, 1) */
    double xf[6];      /* row-major 2x3 affine map of the uv (identity when !transformed) */
};

/* glTF alphaMode (0 = OPAQUE, so a zeroed material is opaque). */
enum dr_alpha_mode { DR_ALPHA_OPAQUE = 0, DR_ALPHA_MASK, DR_ALPHA_BLEND };

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
    /* ... its textures: specularTexture's A times the factor (linear data),
     * specularColorTexture's RGB (sRGB-decoded) times the colour; no
     * parameters, like the factors (bsdf.h) */
    struct dr_texref specular_tex, specular_color_tex;
    bool double_sided;
    struct dr_texref base_color_tex, metallic_roughness_tex, emissive_tex;
    /* normalTexture (tangent space, normal_tex.texture -1: none) and its scale;
     * not a differentiable parameter (see normal_map.h) */
    struct dr_texref normal_tex;
    double normal_scale;
    /* alphaMode (coverage.h): alpha = baseColorFactor.a x base colour texture alpha */
    enum dr_alpha_mode alpha_mode;
    double alpha;                  /* baseColorFactor[3] (1 if absent) */
    double alpha_cutoff;           /* alphaCutoff (0.5 if absent), MASK only */
    /* Thin-walled glass (KHR_materials_transmission without a volume, or
     * with one on an open mesh): a smooth sheet of this index of refraction
     * that a ray passes straight through with probability 1 - R, R the
     * sheet's reflectance (coverage.h), and that reflects it like a white
     * metal of the material's roughness otherwise; 0: not one. Set by
     * dr_material_make_thin. */
    double thin_ior;
    /* KHR_materials_clearcoat (bsdf_coat.c): coated when the file gives the
     * extension with clearcoatFactor > 0 (decided at load, so that a fit
     * that moves the factor to 0 keeps its derivative). The coat is
     * clearcoatFactor x clearcoatTexture's R, its roughness
     * clearcoatRoughnessFactor x clearcoatRoughnessTexture's G (linear data);
     * the textures are read only where coated (dr_material_coat_tex). */
    bool coated;
    double coat, coat_roughness;
    struct dr_texref coat_tex, coat_roughness_tex;
    /* KHR_materials_unlit: the base colour (factor x texture) is what the
     * surface shows, whatever lights it. Loaded as an emitter of that colour
     * (emissive_factor, emissive_tex; strength 1) that reflects nothing (a
     * black Lambertian BSDF): seen directly it is its colour, and it lights
     * what faces it, as Blender's importer renders it. Its factors are no
     * parameters; the texels of its base colour texture are. */
    bool unlit;
    /* KHR_materials_pbrSpecularGlossiness, loaded onto this model (the
     * loader's load_spec_gloss says how): its base colour, metallic and
     * roughness factors are no parameters (they are the loader's mapping of
     * the extension's); the texels of its diffuse texture, the base colour
     * texture here, are, and so are its emission's. */
    bool spec_gloss;
    /* KHR_materials_anisotropy (anisotropy.h): anisotropic when the file
     * gives the extension with anisotropyStrength > 0 (decided at load, as
     * coated). The BSDF's strength is anisotropyStrength x the texture's B;
     * its direction, in the tangent frame, is the texture's RG (2 texel - 1;
     * (1, 0) without a texture) turned by anisotropyRotation radians
     * counter-clockwise. Read only where anisotropic. */
    bool anisotropic;
    double anisotropy_strength, anisotropy_rotation;
    struct dr_texref anisotropy_tex;
    /* KHR_materials_sheen (bsdf_sheen.c): sheened when the file gives the
     * extension with a sheenColorFactor other than black (decided at load, as
     * coated). The sheen's colour is sheenColorFactor x sheenColorTexture's
     * RGB (sRGB), its roughness sheenRoughnessFactor x
     * sheenRoughnessTexture's A (linear data). Read only where sheened. */
    bool sheened;
    dr_vec3 sheen_color;
    double sheen_roughness;
    struct dr_texref sheen_color_tex, sheen_roughness_tex;
};

/* m's sheen colour texture (which 0) or sheen roughness texture (1), or
 * NULL: none, or m has no sheen. */
static inline const struct dr_texref *dr_material_sheen_tex(const struct dr_material *m, int which)
{
    const struct dr_texref *t = which ? &m->sheen_roughness_tex : &m->sheen_color_tex;
    return m->sheened && t->texture >= 0 ? t : NULL;
}

/* m's anisotropy texture, or NULL: none, or m is not anisotropic. */
static inline const struct dr_texref *dr_material_anisotropy_tex(const struct dr_material *m)
{
    return m->anisotropic && m->anisotropy_tex.texture >= 0 ? &m->anisotropy_tex : NULL;
}

/* Whether m's surface needs the mesh's tangent frame (a normal map, or the
 * anisotropy's direction). */
static inline bool dr_material_needs_tangents(const struct dr_material *m)
{
    return m->normal_tex.texture >= 0 || m->anisotropic;
}

/* m's clear coat texture (which 0) or coat roughness texture (1), or NULL:
 * none, or m is not coated (a material zeroed without them reads none). */
static inline const struct dr_texref *dr_material_coat_tex(const struct dr_material *m, int which)
{
    const struct dr_texref *t = which ? &m->coat_roughness_tex : &m->coat_tex;
    return m->coated && t->texture >= 0 ? t : NULL;
}

/* Makes m thin-walled glass of index ior (>= 1): base colour white and no
 * base colour texture (the sheet is clear: glTF's tint by the base colour
 * is not rendered), metallic 1 and no metallic-roughness texture (what
 * stops at the sheet is its Fresnel reflection, already weighed by the
 * stop's probability), no emission. Returns a bit mask of what was
 * dropped: 1 a base colour other than white or its texture, 2 a
 * metallic-roughness texture, 4 emission, 8 a clear coat, 16 a sheen (the
 * loader warns). */
unsigned dr_material_make_thin(struct dr_material *m, double ior);

enum dr_tri_flags {
    DR_TRI_HAS_NORMALS = 1, /* interpolate vertex normals (else flat) */
    DR_TRI_HAS_UVS = 2
};

/* All triangles of the scene, already in world space. */
struct dr_mesh {
    uint32_t n_vertices, n_triangles;
    float *positions;   /* 3 per vertex, plus 1 padding float (Embree reads 16 bytes) */
    float *normals;     /* 3 per vertex (zero where the primitive had none), plus 1 padding
                           float (path_simd.c's gather_vertex reads 16 bytes) */
    float *uvs;         /* 2 per vertex (zero where the primitive had none) */
    /* Only for the scenes that call for them (NULL otherwise: no memory, no
     * per-hit work): */
    float *uvs1;        /* TEXCOORD_1, 2 per vertex, when some texture reads set 1 (zero where absent) */
    float *colors;      /* COLOR_0 rgb, 3 per vertex, when some primitive has it ((1,1,1) where absent) */
    uint32_t *indices;  /* 3 per triangle, counter-clockwise = front */
    int32_t *material;  /* per triangle, index into scene->materials */
    uint8_t *flags;     /* per triangle, enum dr_tri_flags */
    /* 4 per vertex (xyz unit tangent, w = bitangent sign), NULL unless some
     * material has a normal map or anisotropy (dr_material_needs_tangents):
     * TANGENT where supplied, else generated by
     * dr_mesh_prepare_tangents (w = 0: none, the normal map is not applied) */
    float *tangents;
    /* derived by dr_scene_prepare: per triangle unit geometric normal (x, y, z)
     * and ray-offset distance (see dr_offset_origin), so hits need not redo them */
    double *tri_normal_eps;  /* 4 per triangle */
};

struct dr_camera {
    char name[DR_NAME_MAX];
    dr_vec3 origin;
    dr_vec3 right, up, forward;   /* unit, world space; looks along forward */
    double yfov;                  /* radians, vertical field of view (perspective) */
    double aspect;                /* glTF aspectRatio (orthographic: xmag / ymag), 0 when absent */
    bool orthographic;            /* parallel rays along forward from the film plane */
    double ymag;                  /* orthographic: half the view's height (its width follows W/H) */
    int gltf_index;               /* index in the file's "cameras" (-1: drender's default view) */
};

enum dr_light_type { DR_LIGHT_POINT, DR_LIGHT_SPOT, DR_LIGHT_DIRECTIONAL };

/* How KHR_lights_punctual intensities are read. glTF defines them as
 * photometric (candela for point and spot, lux for directional), and Blender's
 * exporter writes them so (683 lm/W); drender renders radiometrically, so a
 * photometric intensity is divided by 683 lm/W. Files drender's own tests and
 * users write in watts say so with the DR_units extension
 * ({"lights": "radiometric"}) or the --light-units option. */
enum dr_light_units { DR_LIGHT_UNITS_PHOTOMETRIC, DR_LIGHT_UNITS_RADIOMETRIC };
#define DR_LUMENS_PER_WATT 683.0

/* KHR_lights_punctual (see manual: rendered as intensity W/sr for point and
 * spot, irradiance W/m^2 for directional, colour multiplies). */
struct dr_punctual {
    char name[DR_NAME_MAX];
    enum dr_light_type type;
    dr_vec3 color;
    double intensity;       /* the file's value (a parameter), in the scene's light units */
    double watts_per_unit;  /* 1 (radiometric) or 1/683 (photometric): radiant = intensity * this */
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
struct dr_backface;
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
    DR_FX_NORMAL_MAPS = 1 << 9,        /* some material has a normalTexture */
    DR_FX_ALPHA_MASK = 1 << 10,        /* alphaMode MASK: cut-outs (coverage.h) */
    DR_FX_ALPHA_BLEND = 1 << 11,       /* alphaMode BLEND: stochastic transparency */
    DR_FX_SINGLE_SIDED = 1 << 12,      /* doubleSided false: back faces culled */
    DR_FX_VERTEX_COLORS = 1 << 13,     /* COLOR_0 multiplies base colours (mesh.colors) */
    DR_FX_DIELECTRIC_BOUNDARIES = 1 << 14, /* a medium bounded by a smooth dielectric (medium.h: ior) */
    DR_FX_THIN_TRANSMISSION = 1 << 15, /* thin-walled glass (dr_material.thin_ior, coverage.h) */
    DR_FX_CLEARCOAT = 1 << 16,         /* some material has a clear coat (dr_material.coated, bsdf_coat.c) */
    DR_FX_ANISOTROPY = 1 << 17,        /* some material is anisotropic (dr_material.anisotropic, anisotropy.h) */
    DR_FX_SHEEN = 1 << 18              /* some material has a sheen (dr_material.sheened, bsdf_sheen.c) */
};

struct dr_scene {
    char *path;
    struct dr_mesh mesh;
    struct dr_material *materials; int n_materials;  /* last one may be the glTF default */
    int n_file_materials;         /* those in the file's "materials" (the rest: the default) */
    struct dr_texture *textures; int n_textures;
    struct dr_image *images; int n_images;
    int n_derived_images;         /* the last of images, made by the loader rather than read from the
                                     file (a specular-glossiness texture's roughness): no parameters */
    struct dr_camera *cameras; int n_cameras;   /* camera nodes, in depth-first node order */
    int n_unplaced_cameras;       /* entries of the file's "cameras" that no node places (not renderable) */
    struct dr_punctual *lights; int n_lights;
    struct dr_environment env;
    enum dr_light_units light_units;   /* of every lights[i].intensity */
    dr_vec3 bbox_min, bbox_max;
    /* participating media (all NULL / 0 without any): */
    struct dr_medium *media; int n_media;
    int *material_medium;         /* per material: the medium it bounds, -1; NULL without media */
    int global_medium;            /* the medium outside every medium mesh, -1: vacuum */

    /* built by dr_scene_prepare() */
    struct dr_backface *backface; /* the single-sided backs no ray can reach (backface.h) */
    struct dr_accel *accel;
    struct dr_light_sampler *light_sampler;
    unsigned effects;             /* enum dr_effect bits */
    /* Images still being decoded on a thread of their own when the loader
     * returns (dr_gltf_load_deferred): their slots in images are empty
     * until dr_scene_prepare, which needs none of them for the ray
     * structure, joins them (NULL: none) */
    struct dr_pending_images *pending_images;
};

/* How the loader treats what drender cannot render. */
struct dr_load_opts {
    /* Content that does not change the rendered image in drender (a KTX2
     * image used only as a normal or occlusion map) is skipped with one
     * warning instead of failing the load (--ignore-unsupported). */
    bool ignore_unsupported;
};

/* Loads a .gltf/.glb and prepares it for rendering. NULL + dr_last_error() on
 * failure; the message names the file and, for content errors, the JSON path.
 * dr_scene_load uses the default options (all false). */
struct dr_scene *dr_scene_load(const char *path);
struct dr_scene *dr_scene_load_opts(const char *path, const struct dr_load_opts *opts);
int dr_scene_prepare(struct dr_scene *scene);
/* After materials, lights or the environment changed (parameters set):
 * recomputes the effect flags and the light sampling tables. Geometry must
 * not have changed. 0 or DR_ERR_NOMEM. */
int dr_scene_refresh(struct dr_scene *scene);
/* The same after changes no light sampling table reads (BSDF parameters,
 * their textures, media): the effect flags, the light sampling tables kept.
 * dr_param_set_refresh (params.h) picks this or dr_scene_refresh. */
int dr_scene_refresh_keep_lights(struct dr_scene *scene);
void dr_scene_destroy(struct dr_scene *scene);
/* Rays will also come from camera, which is not one of the scene's (tests,
 * library users): unless the back-face analysis (backface.h) already admits
 * it, the analysis is redone with it and the ray structure rebuilt. 0, or
 * DR_ERR_NOMEM / DR_ERR_INTERNAL (the scene is then unusable). */
int dr_scene_add_viewpoint(struct dr_scene *scene, const struct dr_camera *camera);
/* Before rays leave camera: 0 when the analysis admits it, else
 * DR_ERR_ARG with a message (the caller forgot dr_scene_add_viewpoint). */
int dr_scene_check_viewpoint(const struct dr_scene *scene, const struct dr_camera *camera);

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
/* Reads every punctual light's intensity in `units` from now on (the values
 * stay as the file gives them; only their meaning changes) and refreshes the
 * light sampler. 0 or DR_ERR_NOMEM. */
int dr_scene_set_light_units(struct dr_scene *scene, enum dr_light_units units);
/* The radiant intensity (W/sr) or irradiance (W/m^2) of a punctual light. */
static inline double dr_punctual_radiant(const struct dr_punctual *l) { return l->intensity * l->watts_per_unit; }

/* Comma-separated names of the effect bits, for --json and messages. */
void dr_effects_describe(unsigned effects, char *buf, int size);

/* The glTF shim (gltf_load.cpp): fills every field above "built by
 * dr_scene_prepare". Returns 0 or a negative DR_ERR_* with dr_last_error set;
 * on failure the scene may hold partial allocations: call dr_scene_destroy. */
int dr_gltf_load(const char *path, struct dr_scene *scene);
/* The same with options (NULL: the defaults). */
int dr_gltf_load_opts(const char *path, const struct dr_load_opts *opts, struct dr_scene *scene);
/* The same, but the images decode on a thread of their own, started once
 * the file is parsed (scene->pending_images, or NULL when there are none,
 * or a specular-glossiness material reads their pixels while loading):
 * dr_scene_load_opts's, which hands them to dr_scene_prepare. A decode's
 * error then comes from dr_pending_images_finish. */
int dr_gltf_load_deferred(const char *path, const struct dr_load_opts *opts, struct dr_scene *scene);
/* Waits for scene->pending_images, puts the decoded pixels in their slots
 * and sRGB-decodes the colour images as the loader does; frees it. 0 (also
 * when nothing is pending) or a negative DR_ERR_* with dr_last_error
 * naming the file and the image, as dr_gltf_load reports it. */
int dr_pending_images_finish(struct dr_scene *scene);
/* Waits for pending's thread and frees it with what it decoded (NULL: no-op). */
void dr_pending_images_discard(struct dr_pending_images *pending);

#ifdef __cplusplus
}
#endif
#endif
