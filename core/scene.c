#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "backface.h"
#include "coverage.h"
#include "error.h"
#include "geometry.h"
#include "image_io.h"
#include "lights.h"
#include "medium_scene.h"
#include "normal_map.h"

struct dr_scene *dr_scene_load(const char *path)
{
    return dr_scene_load_opts(path, NULL);
}

struct dr_scene *dr_scene_load_opts(const char *path, const struct dr_load_opts *opts)
{
    struct dr_scene *s = calloc(1, sizeof *s);
    if (!s) {
        dr_set_error("out of memory");
        return NULL;
    }
    s->path = strdup(path);
    /* (before the loader starts the images' decode: accel.h) */
    dr_accel_warm_up();
    if (!s->path || dr_gltf_load_deferred(path, opts, s) != 0 || dr_scene_prepare(s) != 0) {
        if (!s->path)
            dr_set_error("out of memory");
        dr_scene_destroy(s);
        return NULL;
    }
    return s;
}

static bool material_has_specular(const struct dr_material *m)
{
    return m->metallic > 0.0 || (m->specular > 0.0 && !dr_is_black(m->specular_color)) ||
           m->metallic_roughness_tex.texture >= 0;
}

/* Normal maps, alpha modes and sidedness of material m (normal_map.h, coverage.h). */
static unsigned surface_effects(const struct dr_scene *s, int m)
{
    const struct dr_material *mat = &s->materials[m];
    unsigned fx = mat->normal_tex.texture >= 0 ? (unsigned)DR_FX_NORMAL_MAPS : 0u;
    unsigned cover = dr_material_coverage(s, m);
    if (cover & DR_COVER_MASK)
        fx |= DR_FX_ALPHA_MASK;
    if (cover & DR_COVER_BLEND)
        fx |= DR_FX_ALPHA_BLEND;
    if (cover & DR_COVER_CULL)
        fx |= DR_FX_SINGLE_SIDED;
    if (cover & DR_COVER_THIN)
        fx |= DR_FX_THIN_TRANSMISSION;
    return fx;
}

unsigned dr_material_make_thin(struct dr_material *m, double ior)
{
    unsigned dropped = 0;
    if (m->base_color_tex.texture >= 0 || m->base_color.x != 1.0 || m->base_color.y != 1.0 ||
        m->base_color.z != 1.0)
        dropped |= 1;
    if (m->metallic_roughness_tex.texture >= 0)
        dropped |= 2;
    /* (a sheet's emission would be seen only where a ray stops at it, but
     * next-event estimation would count all of it: not rendered) */
    if (m->emissive_tex.texture >= 0 || !dr_is_black(m->emissive_factor))
        dropped |= 4;
    m->emissive_factor = dr_v3s(0.0);
    m->emissive_tex.texture = -1;
    m->thin_ior = ior >= 1.0 ? ior : 1.0;
    m->base_color = dr_v3s(1.0);
    m->metallic = 1.0;
    m->base_color_tex.texture = -1;
    m->metallic_roughness_tex.texture = -1;
    /* (a metal has no dielectric lobe for KHR_materials_specular to weigh) */
    m->specular_tex.texture = m->specular_color_tex.texture = -1;
    if (m->coated)
        dropped |= 8;
    m->coated = false;   /* (the sheet's reflection is already Fresnel's) */
    m->coat = m->coat_roughness = 0.0;
    if (m->sheened)
        dropped |= 16;
    m->sheened = false;   /* (nor has the sheet fibres) */
    m->sheen_color = dr_v3s(0.0);
    m->sheen_roughness = 0.0;
    return dropped;
}

/* dr_scene_refresh's work; the light sampling tables rebuilt only when
 * `lights` (dr_scene_refresh_keep_lights keeps them). */
static int refresh(struct dr_scene *s, bool lights)
{
    const struct dr_mesh *m = &s->mesh;
    s->effects = 0;
    /* Effects follow from what the triangles actually use, not from what the
     * file happens to declare. */
    bool *used = calloc((size_t)s->n_materials + 1, sizeof(bool));
    if (!used) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    if (m->colors)
        s->effects |= DR_FX_VERTEX_COLORS;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        used[m->material[t]] = true;
        if (m->flags[t] & DR_TRI_HAS_NORMALS)
            s->effects |= DR_FX_SHADING_NORMALS;
    }
    for (int i = 0; i < s->n_materials; i++) {
        const struct dr_material *mat = &s->materials[i];
        if (!used[i])
            continue;
        if (mat->base_color_tex.texture >= 0 || mat->metallic_roughness_tex.texture >= 0 ||
            mat->emissive_tex.texture >= 0 || dr_material_coat_tex(mat, 0) || dr_material_coat_tex(mat, 1) ||
            dr_material_anisotropy_tex(mat) || mat->specular_tex.texture >= 0 || mat->specular_color_tex.texture >= 0 ||
            dr_material_sheen_tex(mat, 0) || dr_material_sheen_tex(mat, 1))
            s->effects |= DR_FX_TEXTURES;
        if (material_has_specular(mat))
            s->effects |= DR_FX_SPECULAR;
        if (mat->coated)
            s->effects |= DR_FX_CLEARCOAT;
        if (mat->anisotropic)
            s->effects |= DR_FX_ANISOTROPY;
        if (mat->sheened)
            s->effects |= DR_FX_SHEEN;
        s->effects |= surface_effects(s, i);
    }
    free(used);

    if (lights || !s->light_sampler) {
        dr_light_sampler_destroy(s->light_sampler);
        s->light_sampler = dr_light_sampler_create(s);
        if (!s->light_sampler)
            return DR_ERR_NOMEM;
    }
    for (uint32_t t = 0; t < m->n_triangles; t++)
        if (dr_light_pdf_area_pick(s->light_sampler, t) > 0.0) {
            s->effects |= DR_FX_AREA_LIGHTS;
            break;
        }
    if (s->n_lights > 0)
        s->effects |= DR_FX_PUNCTUAL_LIGHTS;
    if (s->env.present)
        s->effects |= s->env.map.data ? DR_FX_ENV_MAP : DR_FX_ENV_CONSTANT;
    if (s->n_media > 0)
        return dr_media_refresh(s);
    return 0;
}

int dr_scene_refresh(struct dr_scene *s)
{
    return refresh(s, true);
}

int dr_scene_refresh_keep_lights(struct dr_scene *s)
{
    return refresh(s, false);
}

bool dr_scene_has_light(const struct dr_scene *s)
{
    return s->env.present || (s->effects & (DR_FX_AREA_LIGHTS | DR_FX_PUNCTUAL_LIGHTS)) != 0;
}

int dr_scene_set_environment(struct dr_scene *s, dr_vec3 color, double strength, const char *map_path,
                             bool is_default)
{
    struct dr_image map;
    memset(&map, 0, sizeof map);
    if (map_path) {
        int rc = dr_image_read(map_path, &map);
        if (rc == 0 && map.file_is_srgb)   /* an 8-bit sky is sRGB-encoded, as in the loader */
            rc = dr_image_make_linear(&map);
        if (rc != 0) {
            dr_image_release(&map);
            return rc;
        }
    }
    dr_image_release(&s->env.map);
    s->env.map = map;
    s->env.present = true;
    s->env.color = color;
    s->env.strength = strength;
    s->env.is_default = is_default;
    snprintf(s->env.uri, sizeof s->env.uri, "%s", map_path ? map_path : "");
    return dr_scene_refresh(s);
}

int dr_scene_set_light_units(struct dr_scene *s, enum dr_light_units units)
{
    s->light_units = units;
    double w = units == DR_LIGHT_UNITS_PHOTOMETRIC ? 1.0 / DR_LUMENS_PER_WATT : 1.0;
    for (int i = 0; i < s->n_lights; i++)
        s->lights[i].watts_per_unit = w;
    return dr_scene_refresh(s);
}

/* The back-face analysis (for the scene's cameras, those added before and
 * camera, if not NULL) and the ray structure it shapes, replacing any before. */
static int build_accel(struct dr_scene *s, const struct dr_camera *camera)
{
    struct dr_backface *b = dr_backface_analyse(s, s->backface, camera);
    if (!b)
        return DR_ERR_NOMEM;
    dr_accel_destroy(s->accel);
    dr_backface_destroy(s->backface);
    s->backface = b;
    s->accel = dr_accel_create_scene(s);
    if (!s->accel) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s: cannot build the ray acceleration structure: %s", s->path, dr_last_error());
        dr_set_error("%s", msg);
        return DR_ERR_INTERNAL;
    }
    return 0;
}

int dr_scene_prepare(struct dr_scene *s)
{
    if (dr_mesh_derive(&s->mesh) != 0) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int rc = s->n_media > 0 ? dr_media_prepare(s) : 0;
    if (rc == 0)
        rc = dr_mesh_prepare_tangents(s);
    if (rc != 0)
        return rc;
    if (s->pending_images) {
        /* The ray structure reads no pixels: built while the images decode
         * on their thread (dr_gltf_load_deferred), which first loads the
         * image library (0.1-0.3 s of one CPU); then the light tables,
         * which read the emissive textures. (Measured on the bench's big
         * textured scene: its start to the first ray 0.915 x.) */
        rc = build_accel(s, NULL);
        const int rc_images = dr_pending_images_finish(s);
        if (rc == 0)
            rc = rc_images;
        return rc != 0 ? rc : dr_scene_refresh(s);
    }
    rc = dr_scene_refresh(s);
    if (rc != 0)
        return rc;
    return build_accel(s, NULL);
}

int dr_scene_add_viewpoint(struct dr_scene *s, const struct dr_camera *camera)
{
    if (dr_backface_admits(s->backface, s, camera))
        return 0;
    return build_accel(s, camera);
}

int dr_scene_check_viewpoint(const struct dr_scene *s, const struct dr_camera *camera)
{
    if (dr_backface_admits(s->backface, s, camera))
        return 0;
    dr_set_error("%s: camera '%s' at (%g, %g, %g) was not analysed for back faces: rays from it could meet "
                 "backs that the scene's cameras cannot (dr_scene_add_viewpoint)",
                 s->path, camera->name, camera->origin.x, camera->origin.y, camera->origin.z);
    return DR_ERR_ARG;
}

void dr_scene_destroy(struct dr_scene *s)
{
    if (!s)
        return;
    dr_pending_images_discard(s->pending_images);
    dr_accel_destroy(s->accel);
    dr_backface_destroy(s->backface);
    dr_light_sampler_destroy(s->light_sampler);
    free(s->mesh.positions);
    free(s->mesh.normals);
    free(s->mesh.uvs);
    free(s->mesh.uvs1);
    free(s->mesh.colors);
    free(s->mesh.indices);
    free(s->mesh.material);
    free(s->mesh.flags);
    free(s->mesh.tangents);
    free(s->mesh.tri_normal_eps);
    free(s->materials);
    free(s->textures);
    for (int i = 0; i < s->n_images; i++)
        dr_image_release(&s->images[i]);
    free(s->images);
    free(s->cameras);
    free(s->lights);
    dr_media_release(s);
    dr_image_release(&s->env.map);
    free(s->path);
    free(s);
}

void dr_effects_describe(unsigned fx, char *buf, int size)
{
    static const struct { unsigned bit; const char *name; } names[] = {
        {DR_FX_AREA_LIGHTS, "area_lights"},     {DR_FX_PUNCTUAL_LIGHTS, "punctual_lights"},
        {DR_FX_ENV_CONSTANT, "environment"},    {DR_FX_ENV_MAP, "environment_map"},
        {DR_FX_TEXTURES, "textures"},           {DR_FX_SPECULAR, "specular"},
        {DR_FX_SHADING_NORMALS, "shading_normals"}, {DR_FX_MEDIA, "media"},
        {DR_FX_HETEROGENEOUS_MEDIA, "heterogeneous_media"}, {DR_FX_NORMAL_MAPS, "normal_maps"},
        {DR_FX_ALPHA_MASK, "alpha_mask"},       {DR_FX_ALPHA_BLEND, "alpha_blend"},
        {DR_FX_SINGLE_SIDED, "single_sided"},   {DR_FX_VERTEX_COLORS, "vertex_colors"},
        {DR_FX_DIELECTRIC_BOUNDARIES, "dielectric_boundaries"}, {DR_FX_THIN_TRANSMISSION, "thin_transmission"},
        {DR_FX_CLEARCOAT, "clearcoat"},         {DR_FX_ANISOTROPY, "anisotropy"},
        {DR_FX_SHEEN, "sheen"},
    };
    int n = 0;
    buf[0] = '\0';
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (fx & names[i].bit)
            n += snprintf(buf + n, n < size ? (size_t)(size - n) : 0, "%s%s", n ? "," : "", names[i].name);
}
