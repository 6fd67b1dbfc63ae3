#include "params.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bsdf.h"
#include "error.h"
#include "medium.h"
#include "parallel.h"
#include "zero_blocks.h"

/* ---- participating media (the DR_medium parameters, params.h) ---- */

static const char *const medium_fields[] = {
    [DR_PARAM_MEDIUM_EXTINCTION - DR_PARAM_MEDIUM_EXTINCTION] = "/extinction",
    [DR_PARAM_MEDIUM_ALBEDO - DR_PARAM_MEDIUM_EXTINCTION] = "/albedo",
    [DR_PARAM_MEDIUM_G - DR_PARAM_MEDIUM_EXTINCTION] = "/g",
    [DR_PARAM_MEDIUM_DENSITY_SCALE - DR_PARAM_MEDIUM_EXTINCTION] = "/density_scale",
    [DR_PARAM_MEDIUM_DENSITY - DR_PARAM_MEDIUM_EXTINCTION] = "/density",
};

static bool is_medium_kind(enum dr_param_kind k)
{
    return k >= DR_PARAM_MEDIUM_EXTINCTION && k <= DR_PARAM_MEDIUM_DENSITY;
}

void dr_medium_param_prefix(int material, char *buf, size_t size)
{
    if (material >= 0)
        snprintf(buf, size, "/materials/%d/extensions/DR_medium", material);
    else
        snprintf(buf, size, "/extensions/DR_medium");
}

/* The parameters of every medium: appended to list, returns how many. */
static int list_medium_params(const struct dr_scene *s, struct dr_param *list)
{
    int n = 0;
    for (int i = 0; i < s->n_media; i++) {
        const struct dr_medium *m = &s->media[i];
        char base[64];
        dr_medium_param_prefix(m->material, base, sizeof base);
        for (int k = DR_PARAM_MEDIUM_EXTINCTION; k <= DR_PARAM_MEDIUM_DENSITY; k++) {
            if (k == DR_PARAM_MEDIUM_DENSITY && !m->has_grid)
                continue;
            struct dr_param *p = &list[n++];
            memset(p, 0, sizeof *p);
            p->kind = (enum dr_param_kind)k;
            p->target = i;
            p->size = k == DR_PARAM_MEDIUM_EXTINCTION || k == DR_PARAM_MEDIUM_ALBEDO ? 3 : 1;
            if (k == DR_PARAM_MEDIUM_DENSITY) {
                p->size = (int64_t)m->grid.nx * m->grid.ny * m->grid.nz;
                p->width = m->grid.nx;
                p->height = m->grid.ny * m->grid.nz;
                p->channels = 1;
            }
            snprintf(p->name, sizeof p->name, "%s%s", base, medium_fields[k - DR_PARAM_MEDIUM_EXTINCTION]);
        }
    }
    return n;
}

static void medium_param_get(const struct dr_scene *s, const struct dr_param *p, double *v)
{
    const struct dr_medium *m = &s->media[p->target];
    switch (p->kind) {
    case DR_PARAM_MEDIUM_EXTINCTION: v[0] = m->extinction.x; v[1] = m->extinction.y; v[2] = m->extinction.z; return;
    case DR_PARAM_MEDIUM_ALBEDO: v[0] = m->albedo.x; v[1] = m->albedo.y; v[2] = m->albedo.z; return;
    case DR_PARAM_MEDIUM_G: v[0] = m->g; return;
    case DR_PARAM_MEDIUM_DENSITY_SCALE: v[0] = m->density_scale; return;
    default:
        for (int64_t i = 0; i < p->size; i++)
            v[i] = m->grid.density[i];
        return;
    }
}

/* Values are clamped into what the tracker can take (a negative density or
 * |g| >= 1 has no meaning); the caller refreshes the scene (majorants). */
static void medium_param_put(struct dr_scene *s, const struct dr_param *p, const double *v)
{
    struct dr_medium *m = &s->media[p->target];
    switch (p->kind) {
    case DR_PARAM_MEDIUM_EXTINCTION:
        m->extinction = dr_v3(dr_max(v[0], 0.0), dr_max(v[1], 0.0), dr_max(v[2], 0.0));
        return;
    case DR_PARAM_MEDIUM_ALBEDO:
        m->albedo = dr_v3(dr_clamp(v[0], 0.0, 1.0), dr_clamp(v[1], 0.0, 1.0), dr_clamp(v[2], 0.0, 1.0));
        return;
    case DR_PARAM_MEDIUM_G: m->g = dr_clamp(v[0], -0.999, 0.999); return;
    case DR_PARAM_MEDIUM_DENSITY_SCALE: m->density_scale = dr_max(v[0], 0.0); return;
    default:
        for (int64_t i = 0; i < p->size; i++)
            m->grid.density[i] = (float)dr_max(v[i], 0.0);
        return;
    }
}

static const char *const mat_fields[] = {
    [DR_PARAM_BASE_COLOR] = "/pbrMetallicRoughness/baseColorFactor",
    [DR_PARAM_METALLIC] = "/pbrMetallicRoughness/metallicFactor",
    [DR_PARAM_ROUGHNESS] = "/pbrMetallicRoughness/roughnessFactor",
    [DR_PARAM_EMISSIVE_FACTOR] = "/emissiveFactor",
    [DR_PARAM_EMISSIVE_STRENGTH] = "/extensions/KHR_materials_emissive_strength/emissiveStrength",
    [DR_PARAM_CLEARCOAT] = "/extensions/KHR_materials_clearcoat/clearcoatFactor",
    [DR_PARAM_CLEARCOAT_ROUGHNESS] = "/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor",
    [DR_PARAM_ANISOTROPY_STRENGTH] = "/extensions/KHR_materials_anisotropy/anisotropyStrength",
    [DR_PARAM_SHEEN_COLOR] = "/extensions/KHR_materials_sheen/sheenColorFactor",
    [DR_PARAM_SHEEN_ROUGHNESS] = "/extensions/KHR_materials_sheen/sheenRoughnessFactor",
};

const char *dr_param_type_name(const struct dr_param *p)
{
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR:
    case DR_PARAM_EMISSIVE_FACTOR:
    case DR_PARAM_SHEEN_COLOR:
    case DR_PARAM_LIGHT_COLOR:
    case DR_PARAM_MEDIUM_EXTINCTION:
    case DR_PARAM_MEDIUM_ALBEDO:
    case DR_PARAM_ENV_COLOR: return "color";
    case DR_PARAM_ENV_MAP:
    case DR_PARAM_IMAGE: return "image";
    case DR_PARAM_MEDIUM_DENSITY: return "grid";
    default: return "scalar";
    }
}

void dr_param_range(const struct dr_param *p, double *lo, double *hi)
{
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR:
    case DR_PARAM_METALLIC:
    case DR_PARAM_CLEARCOAT:
    case DR_PARAM_ANISOTROPY_STRENGTH:
    case DR_PARAM_SHEEN_COLOR: *lo = 0.0; *hi = 1.0; break;
    /* the BSDF's floor (below it the derivative is 0: a fit that starts at
     * glTF's default, 0, is moved up to where it has one) */
    case DR_PARAM_SHEEN_ROUGHNESS: *lo = DR_SHEEN_MIN_ROUGHNESS; *hi = 1.0; break;
    case DR_PARAM_ROUGHNESS:
    case DR_PARAM_CLEARCOAT_ROUGHNESS: *lo = 0.001; *hi = 1.0; break;   /* the BSDF's floor */
    case DR_PARAM_IMAGE: *lo = 0.0; *hi = 1.0; break;        /* colour or data texels */
    case DR_PARAM_MEDIUM_ALBEDO: *lo = 0.0; *hi = 1.0; break;
    case DR_PARAM_MEDIUM_G: *lo = -0.99; *hi = 0.99; break;
    default: *lo = 0.0; *hi = INFINITY; break;               /* emission, light, environment */
    }
}

void dr_param_display_name(const struct dr_scene *s, const struct dr_param *p, char *buf, size_t size)
{
    if (p->kind <= DR_PARAM_LAST_MATERIAL && s->materials[p->target].name[0] &&
        !strchr(s->materials[p->target].name, '/')) {
        int same = 0;
        for (int i = 0; i < s->n_file_materials; i++)
            same += strcmp(s->materials[i].name, s->materials[p->target].name) == 0;
        if (same == 1) {
            snprintf(buf, size, "/materials/%s%s", s->materials[p->target].name, mat_fields[p->kind]);
            return;
        }
    }
    snprintf(buf, size, "%s", p->name);
}

/* ---- which images are looked up as colour (sRGB-decoded) or as data ---- */

static void image_usage(const struct dr_scene *s, int image, bool *as_colour, bool *as_data)
{
    *as_colour = *as_data = false;
    for (int i = 0; i < s->n_materials; i++) {
        const struct dr_material *m = &s->materials[i];
        const struct dr_texref *colour[2] = {&m->base_color_tex, &m->emissive_tex};
        for (int k = 0; k < 2; k++)
            if (colour[k]->texture >= 0 && s->textures[colour[k]->texture].image == image)
                *as_colour = true;
        for (int which = 0; which < 2; which++)   /* (a clear coat's textures: data) */
            if (dr_material_coat_tex(m, which) && s->textures[dr_material_coat_tex(m, which)->texture].image == image)
                *as_data = true;
        if (m->metallic_roughness_tex.texture >= 0 && s->textures[m->metallic_roughness_tex.texture].image == image)
            *as_data = true;
    }
}

/* The texel array a parameter writes (NULL: out of memory). An image in
 * eight-bit storage (image.h) goes back to floats first (writers call
 * dr_param_set_writable before, which says when there is no memory). */
static float *param_texels(const struct dr_scene *s, const struct dr_param *p)
{
    if (p->kind == DR_PARAM_ENV_MAP)
        return s->env.map.linear ? s->env.map.linear : s->env.map.data;
    struct dr_image *img = &s->images[p->target];
    if (img->bytes && dr_image_expand(img) != 0)
        return NULL;
    bool colour, data;
    image_usage(s, p->target, &colour, &data);
    return colour && img->linear ? img->linear : img->data;
}

/* ---- listing ---- */

static bool light_instanced(const struct dr_scene *s, int gltf_index)
{
    for (int i = 0; i < s->n_lights; i++)
        if (s->lights[i].gltf_index == gltf_index)
            return true;
    return false;
}

static int max_light_index(const struct dr_scene *s)
{
    int m = -1;
    for (int i = 0; i < s->n_lights; i++)
        if (s->lights[i].gltf_index > m)
            m = s->lights[i].gltf_index;
    return m;
}

static struct dr_param make(enum dr_param_kind kind, int target, int64_t size, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static struct dr_param make(enum dr_param_kind kind, int target, int64_t size, const char *fmt, ...)
{
    struct dr_param p;
    memset(&p, 0, sizeof p);
    p.kind = kind;
    p.target = target;
    p.size = size;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(p.name, sizeof p.name, fmt, ap);
    va_end(ap);
    return p;
}

/* Material m is thin-walled glass, which is clear and does not emit
 * (scene.h): every material field but its roughness leaves the image as it
 * is, and is no parameter (not listed; refused by name with the reason). */
static bool thin_glass_unused(const struct dr_scene *s, int m, enum dr_param_kind kind)
{
    return s->materials[m].thin_ior > 0.0 && kind != DR_PARAM_ROUGHNESS;
}

/* A specular-glossiness material's base colour, metallic and roughness are
 * the loader's mapping of the extension's factors (scene.h): no parameters;
 * its other fields (emission, layers) are glTF's own and are. */
static bool spec_gloss_mapped(const struct dr_scene *s, int m, enum dr_param_kind kind)
{
    return s->materials[m].spec_gloss &&
           (kind == DR_PARAM_BASE_COLOR || kind == DR_PARAM_METALLIC || kind == DR_PARAM_ROUGHNESS);
}

/* The coat's factors are parameters of coated materials only, the
 * anisotropy's strength of anisotropic ones, the sheen's factors of sheened
 * ones (scene.h); an unlit material's
 * factors are none (its colour is the loader's copy), nor a specular-
 * glossiness material's mapped ones. */
static bool uncoated_unused(const struct dr_scene *s, int m, enum dr_param_kind kind)
{
    return s->materials[m].unlit || spec_gloss_mapped(s, m, kind) ||
           ((kind == DR_PARAM_CLEARCOAT || kind == DR_PARAM_CLEARCOAT_ROUGHNESS) && !s->materials[m].coated) ||
           (kind == DR_PARAM_ANISOTROPY_STRENGTH && !s->materials[m].anisotropic) ||
           ((kind == DR_PARAM_SHEEN_COLOR || kind == DR_PARAM_SHEEN_ROUGHNESS) && !s->materials[m].sheened);
}

int dr_params_list(const struct dr_scene *s, struct dr_param **out, int *count)
{
    int cap = (DR_PARAM_LAST_MATERIAL + 1) * s->n_file_materials + 2 * (max_light_index(s) + 1) + 3 + s->n_images + 5 * s->n_media + 1;
    struct dr_param *list = calloc((size_t)cap, sizeof *list);
    if (!list) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int n = 0;
    for (int m = 0; m < s->n_file_materials; m++)
        for (int k = DR_PARAM_BASE_COLOR; k <= DR_PARAM_LAST_MATERIAL; k++) {
            if (thin_glass_unused(s, m, (enum dr_param_kind)k) || uncoated_unused(s, m, (enum dr_param_kind)k))
                continue;
            int64_t size = (k == DR_PARAM_BASE_COLOR || k == DR_PARAM_EMISSIVE_FACTOR || k == DR_PARAM_SHEEN_COLOR) ? 3 : 1;
            list[n++] = make(k, m, size, "/materials/%d%s", m, mat_fields[k]);
        }
    for (int l = 0; l <= max_light_index(s); l++) {
        if (!light_instanced(s, l))
            continue;   /* a light no node places is not rendered */
        list[n++] = make(DR_PARAM_LIGHT_COLOR, l, 3, "/extensions/KHR_lights_punctual/lights/%d/color", l);
        list[n++] = make(DR_PARAM_LIGHT_INTENSITY, l, 1, "/extensions/KHR_lights_punctual/lights/%d/intensity", l);
    }
    if (s->env.present) {
        list[n++] = make(DR_PARAM_ENV_COLOR, -1, 3, "/extensions/DR_environment/color");
        list[n++] = make(DR_PARAM_ENV_STRENGTH, -1, 1, "/extensions/DR_environment/strength");
        if (s->env.map.data) {
            const struct dr_image *im = &s->env.map;
            struct dr_param p = make(DR_PARAM_ENV_MAP, -1, (int64_t)im->width * im->height * im->channels,
                                     "/extensions/DR_environment/uri");
            p.width = im->width;
            p.height = im->height;
            p.channels = im->channels;
            list[n++] = p;
        }
    }
    for (int i = 0; i < s->n_images - s->n_derived_images; i++) {
        const struct dr_image *im = &s->images[i];
        bool colour, data;
        image_usage(s, i, &colour, &data);
        if ((!colour && !data) || !dr_image_has_pixels(im))
            continue;   /* only a normal/occlusion map, or unused: its texels cannot change the image;
                           no data: a KTX2 image skipped by --ignore-unsupported */
        struct dr_param p = make(DR_PARAM_IMAGE, i, (int64_t)im->width * im->height * im->channels, "/images/%d", i);
        p.width = im->width;
        p.height = im->height;
        p.channels = im->channels;
        list[n++] = p;
    }
    n += list_medium_params(s, list + n);
    *out = list;
    *count = n;
    return 0;
}

/* ---- resolving ---- */

/* Splits a JSON pointer into unescaped tokens (~1 -> '/', ~0 -> '~'). */
static int split_pointer(const char *ptr, char tokens[][DR_PARAM_NAME_MAX], int max)
{
    if (ptr[0] != '/')
        return -1;
    int n = 0;
    const char *p = ptr + 1;
    for (;;) {
        if (n == max)
            return -1;
        int len = 0;
        while (*p && *p != '/') {
            char c = *p++;
            if (c == '~' && (*p == '0' || *p == '1'))
                c = *p++ == '0' ? '~' : '/';
            if (len < DR_PARAM_NAME_MAX - 1)
                tokens[n][len++] = c;
        }
        tokens[n++][len] = '\0';
        if (!*p)
            return n;
        p++;
    }
}

static bool parse_index(const char *tok, int *out)
{
    if (!*tok)
        return false;
    long v = 0;
    for (const char *c = tok; *c; c++) {
        if (*c < '0' || *c > '9' || v > 100000000)
            return false;
        v = v * 10 + (*c - '0');
    }
    *out = (int)v;
    return true;
}

/* Material by index or by name; -2 when ambiguous. */
static int find_material(const struct dr_scene *s, const char *tok)
{
    int idx;
    if (parse_index(tok, &idx))
        return idx < s->n_file_materials ? idx : -1;
    int found = -1;
    for (int i = 0; i < s->n_file_materials; i++)
        if (strcmp(s->materials[i].name, tok) == 0) {
            if (found >= 0)
                return -2;
            found = i;
        }
    return found;
}

static int edit_distance(const char *a, const char *b)
{
    int la = (int)strlen(a), lb = (int)strlen(b);
    int *row = malloc(sizeof(int) * (size_t)(lb + 1));
    if (!row)
        return 1 << 20;
    for (int j = 0; j <= lb; j++)
        row[j] = j;
    for (int i = 1; i <= la; i++) {
        int diag = row[0];
        row[0] = i;
        for (int j = 1; j <= lb; j++) {
            int up = row[j];
            int sub = diag + (a[i - 1] != b[j - 1]);
            int best = up + 1 < row[j - 1] + 1 ? up + 1 : row[j - 1] + 1;
            row[j] = sub < best ? sub : best;
            diag = up;
        }
    }
    int d = row[lb];
    free(row);
    return d;
}

/* Error message: the pointer, the reason, and up to three nearest names. */
static int fail_with_suggestions(const struct dr_scene *s, const char *ptr, const char *why)
{
    struct dr_param *list = NULL;
    int n = 0;
    char msg[1024];
    int len = snprintf(msg, sizeof msg, "%s: %s", ptr, why);
    if (dr_params_list(s, &list, &n) == 0 && n > 0) {
        int best[3] = {-1, -1, -1}, dist[3] = {1 << 30, 1 << 30, 1 << 30};
        for (int i = 0; i < n; i++) {
            /* compare against the index form and the material-name form */
            int d = edit_distance(ptr, list[i].name);
            if (list[i].kind <= DR_PARAM_LAST_MATERIAL) {
                char named[2 * DR_PARAM_NAME_MAX];
                snprintf(named, sizeof named, "/materials/%s%s", s->materials[list[i].target].name,
                         mat_fields[list[i].kind]);
                int dn = edit_distance(ptr, named);
                d = dn < d ? dn : d;
            }
            for (int k = 0; k < 3; k++)
                if (d < dist[k]) {
                    for (int j = 2; j > k; j--) {
                        dist[j] = dist[j - 1];
                        best[j] = best[j - 1];
                    }
                    dist[k] = d;
                    best[k] = i;
                    break;
                }
        }
        len += snprintf(msg + len, len < (int)sizeof msg ? sizeof msg - (size_t)len : 0, "; nearest valid names:");
        for (int k = 0; k < 3 && best[k] >= 0; k++)
            len += snprintf(msg + len, len < (int)sizeof msg ? sizeof msg - (size_t)len : 0, " %s",
                            list[best[k]].name);
        snprintf(msg + len, len < (int)sizeof msg ? sizeof msg - (size_t)len : 0,
                 " ('drender params' lists them all)");
    } else {
        snprintf(msg + len, len < (int)sizeof msg ? sizeof msg - (size_t)len : 0,
                 "; this scene has no differentiable parameters");
    }
    free(list);
    dr_set_error("%s", msg);
    return DR_ERR_ARG;
}

int dr_param_resolve(const struct dr_scene *s, const char *ptr, struct dr_param *out)
{
    char tok[8][DR_PARAM_NAME_MAX];
    int n = split_pointer(ptr, tok, 8);
    if (n < 0)
        return fail_with_suggestions(s, ptr, "not a JSON pointer (it must start with '/')");
    struct dr_param *list = NULL;
    int count = 0;
    if (dr_params_list(s, &list, &count) != 0)
        return DR_ERR_NOMEM;
    int want = -1;  /* index into list */
    if (n >= 3 && strcmp(tok[0], "materials") == 0) {
        int m = find_material(s, tok[1]);
        if (m == -2) {
            free(list);
            return fail_with_suggestions(s, ptr, "several materials have that name: use the index");
        }
        if (m < 0) {
            free(list);
            return fail_with_suggestions(s, ptr, "no such material");
        }
        char field[4 * DR_PARAM_NAME_MAX] = "";
        for (int i = 2; i < n; i++) {
            strcat(field, "/");
            strcat(field, tok[i]);
        }
        for (int k = DR_PARAM_BASE_COLOR; k <= DR_PARAM_LAST_MATERIAL; k++)
            if (strcmp(field, mat_fields[k]) == 0)
                for (int i = 0; i < count; i++)
                    if (list[i].kind == (enum dr_param_kind)k && list[i].target == m)
                        want = i;
        bool thin_field = false;   /* a field of m that thin glass does not use */
        bool mapped_field = false; /* a field of m the spec-gloss mapping fills */
        for (int k = DR_PARAM_BASE_COLOR; k <= DR_PARAM_LAST_MATERIAL; k++) {
            thin_field |= thin_glass_unused(s, m, (enum dr_param_kind)k) && strcmp(field, mat_fields[k]) == 0;
            mapped_field |= spec_gloss_mapped(s, m, (enum dr_param_kind)k) && strcmp(field, mat_fields[k]) == 0;
        }
        if (want < 0 && s->materials[m].unlit) {
            free(list);
            return fail_with_suggestions(s, ptr, "the material is unlit (KHR_materials_unlit): its base colour is "
                                                 "shown as it is, and its factors are not parameters (the texels of "
                                                 "its baseColorTexture are: /images/N)");
        }
        if (want < 0 && mapped_field) {
            free(list);
            return fail_with_suggestions(s, ptr, "the material is KHR_materials_pbrSpecularGlossiness, loaded onto "
                                                 "the metallic-roughness model: its base colour, metallic and "
                                                 "roughness factors are not parameters (the texels of its "
                                                 "diffuseTexture are: /images/N)");
        }
        if (want < 0 && thin_field) {
            free(list);
            return fail_with_suggestions(s, ptr, "the material is thin-walled glass (KHR_materials_transmission), "
                                                 "rendered clear and not emitting: only its roughnessFactor enters "
                                                 "the image");
        }
        /* a medium's parameters, by the material's index or name */
        char canonical[5 * DR_PARAM_NAME_MAX];
        snprintf(canonical, sizeof canonical, "/materials/%d%s", m, field);
        for (int i = 0; want < 0 && i < count; i++)
            if (is_medium_kind(list[i].kind) && strcmp(list[i].name, canonical) == 0)
                want = i;
    } else {
        /* everything else is named by its canonical pointer */
        for (int i = 0; i < count; i++)
            if (strcmp(list[i].name, ptr) == 0)
                want = i;
    }
    if (want < 0) {
        free(list);
        int img = -1;
        char end = 0;
        if (sscanf(ptr, "/images/%d%c", &img, &end) == 1 && img >= 0 && img < s->n_images - s->n_derived_images)
            return fail_with_suggestions(s, ptr, "this image's texels cannot change the rendered image (it is "
                                                 "used by no base colour, metallic-roughness or emissive texture "
                                                 "drender renders, e.g. only as a normal or occlusion map)");
        return fail_with_suggestions(s, ptr, "names nothing differentiable in this scene");
    }
    *out = list[want];
    free(list);
    return 0;
}

/* ---- values ---- */

static double *mat_scalar(struct dr_material *m, enum dr_param_kind k)
{
    switch (k) {
    case DR_PARAM_METALLIC: return &m->metallic;
    case DR_PARAM_ROUGHNESS: return &m->roughness;
    case DR_PARAM_EMISSIVE_STRENGTH: return &m->emissive_strength;
    case DR_PARAM_CLEARCOAT: return &m->coat;
    case DR_PARAM_CLEARCOAT_ROUGHNESS: return &m->coat_roughness;
    case DR_PARAM_ANISOTROPY_STRENGTH: return &m->anisotropy_strength;
    case DR_PARAM_SHEEN_ROUGHNESS: return &m->sheen_roughness;
    default: return NULL;
    }
}

static dr_vec3 *param_vec3(struct dr_scene *s, const struct dr_param *p, int *light_first)
{
    *light_first = -1;
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR: return &s->materials[p->target].base_color;
    case DR_PARAM_EMISSIVE_FACTOR: return &s->materials[p->target].emissive_factor;
    case DR_PARAM_SHEEN_COLOR: return &s->materials[p->target].sheen_color;
    case DR_PARAM_ENV_COLOR: return &s->env.color;
    case DR_PARAM_LIGHT_COLOR:
        for (int i = 0; i < s->n_lights; i++)
            if (s->lights[i].gltf_index == p->target) {
                *light_first = i;
                return &s->lights[i].color;
            }
        return NULL;
    default: return NULL;
    }
}

void dr_param_get(const struct dr_scene *cs, const struct dr_param *p, double *v)
{
    struct dr_scene *s = (struct dr_scene *)cs;   /* read only */
    if (is_medium_kind(p->kind)) {
        medium_param_get(s, p, v);
        return;
    }
    int first;
    dr_vec3 *c = param_vec3(s, p, &first);
    if (c) {
        v[0] = c->x;
        v[1] = c->y;
        v[2] = c->z;
        return;
    }
    switch (p->kind) {
    case DR_PARAM_LIGHT_INTENSITY:
        for (int i = 0; i < s->n_lights; i++)
            if (s->lights[i].gltf_index == p->target) {
                v[0] = s->lights[i].intensity;
                return;
            }
        v[0] = 0.0;
        return;
    case DR_PARAM_ENV_STRENGTH: v[0] = s->env.strength; return;
    case DR_PARAM_ENV_MAP: {
        const float *t = param_texels(s, p);
        for (int64_t i = 0; i < p->size; i++)
            v[i] = t[i];
        return;
    }
    case DR_PARAM_IMAGE: {   /* read in either storage: `drender params` expands nothing */
        bool colour, data;
        image_usage(s, p->target, &colour, &data);
        for (int64_t i = 0; i < p->size; i++)
            v[i] = dr_image_value(&s->images[p->target], (size_t)i, colour);
        return;
    }
    default: v[0] = *mat_scalar(&s->materials[p->target], p->kind); return;
    }
}

/* A texel array's floats from the values, [begin, end) (dr_parallel_elements),
 * written only where they changed (as bits: -0 over +0 is a change). */
struct texels_put {
    float *t;
    const double *v;
    const uint64_t *changed;   /* put_marked: the values' block mask, entry 0 at global entry `offset` */
    int64_t offset;
};

static void put_texels(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct texels_put *x = ctx;
    for (int64_t i = begin; i < end; i++) {
        const float f = (float)x->v[i];
        uint32_t now, was;
        memcpy(&now, &f, sizeof now);
        memcpy(&was, &x->t[i], sizeof was);
        if (now != was)
            x->t[i] = f;
    }
}

/* put_texels over the runs of blocks x->changed marks (the other values
 * did not change, so neither do their floats). */
static void put_marked(void *ctx, int thread, int64_t begin, int64_t end)
{
    const struct texels_put *x = ctx;
    const int64_t o = x->offset, e = o + end;
    for (int64_t i = dr_mask_next(x->changed, NULL, o + begin, e); i < e;) {
        const int64_t j = dr_mask_run_end(x->changed, NULL, i, e);
        put_texels(ctx, thread, i - o, j - o);
        i = dr_mask_next(x->changed, NULL, j, e);
    }
}

void dr_param_put(struct dr_scene *s, const struct dr_param *p, const double *v)
{
    if (is_medium_kind(p->kind)) {
        medium_param_put(s, p, v);
        return;
    }
    int first;
    dr_vec3 *c = param_vec3(s, p, &first);
    if (c) {
        *c = dr_v3(v[0], v[1], v[2]);
        /* a glTF light placed by several nodes: every instance changes */
        if (first >= 0)
            for (int i = first + 1; i < s->n_lights; i++)
                if (s->lights[i].gltf_index == p->target)
                    s->lights[i].color = *c;
        return;
    }
    switch (p->kind) {
    case DR_PARAM_LIGHT_INTENSITY:
        for (int i = 0; i < s->n_lights; i++)
            if (s->lights[i].gltf_index == p->target)
                s->lights[i].intensity = v[0];
        return;
    case DR_PARAM_ENV_STRENGTH: s->env.strength = v[0]; return;
    case DR_PARAM_ENV_MAP:
    case DR_PARAM_IMAGE: {
        struct texels_put x = {param_texels(s, p), v, NULL, 0};
        if (x.t)   /* (no memory for its floats: nothing changes) */
            put_texels(&x, 0, 0, p->size);
        return;
    }
    default: *mat_scalar(&s->materials[p->target], p->kind) = v[0]; return;
    }
}

/* ---- sets ---- */

void dr_param_set_destroy(struct dr_param_set *set)
{
    if (!set)
        return;
    free(set->params);
    free(set->mat_base_color);
    free(set->mat_metallic);
    free(set->mat_roughness);
    free(set->mat_emissive_factor);
    free(set->mat_emissive_strength);
    free(set->mat_coat);
    free(set->mat_coat_roughness);
    free(set->mat_anisotropy);
    free(set->mat_sheen_color);
    free(set->mat_sheen_roughness);
    free(set->light_color);
    free(set->light_intensity);
    free(set->image);
    free(set->mat_bsdf_active);
    free(set->mat_emission_active);
    free(set->med_extinction);
    free(set->med_albedo);
    free(set->med_g);
    free(set->med_density_scale);
    free(set->med_density);
    free(set->med_active);
    free(set);
}

static int64_t *offsets(int n)
{
    int64_t *a = malloc(sizeof(int64_t) * (size_t)(n > 0 ? n : 1));
    if (a)
        for (int i = 0; i < n; i++)
            a[i] = -1;
    return a;
}

static bool texref_active(const struct dr_param_set *set, const struct dr_scene *s, const struct dr_texref *t)
{
    return t->texture >= 0 && set->image[s->textures[t->texture].image] >= 0;
}

/* Records parameter p in the per-object lookups the tracer reads. */
static void index_param(struct dr_param_set *set, const struct dr_scene *s, const struct dr_param *p)
{
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR: set->mat_base_color[p->target] = p->offset; break;
    case DR_PARAM_METALLIC: set->mat_metallic[p->target] = p->offset; break;
    case DR_PARAM_ROUGHNESS: set->mat_roughness[p->target] = p->offset; break;
    case DR_PARAM_EMISSIVE_FACTOR: set->mat_emissive_factor[p->target] = p->offset; break;
    case DR_PARAM_EMISSIVE_STRENGTH: set->mat_emissive_strength[p->target] = p->offset; break;
    case DR_PARAM_CLEARCOAT: set->mat_coat[p->target] = p->offset; break;
    case DR_PARAM_CLEARCOAT_ROUGHNESS: set->mat_coat_roughness[p->target] = p->offset; break;
    case DR_PARAM_ANISOTROPY_STRENGTH: set->mat_anisotropy[p->target] = p->offset; break;
    case DR_PARAM_SHEEN_COLOR: set->mat_sheen_color[p->target] = p->offset; break;
    case DR_PARAM_SHEEN_ROUGHNESS: set->mat_sheen_roughness[p->target] = p->offset; break;
    case DR_PARAM_LIGHT_COLOR:
    case DR_PARAM_LIGHT_INTENSITY:
        for (int l = 0; l < s->n_lights; l++)
            if (s->lights[l].gltf_index == p->target)
                (p->kind == DR_PARAM_LIGHT_COLOR ? set->light_color : set->light_intensity)[l] = p->offset;
        set->lights_active = true;
        break;
    case DR_PARAM_ENV_COLOR: set->env_color = p->offset; set->env_active = true; break;
    case DR_PARAM_ENV_STRENGTH: set->env_strength = p->offset; set->env_active = true; break;
    case DR_PARAM_ENV_MAP: set->env_map = p->offset; set->env_active = true; break;
    case DR_PARAM_IMAGE: set->image[p->target] = p->offset; break;
    case DR_PARAM_MEDIUM_EXTINCTION: set->med_extinction[p->target] = p->offset; break;
    case DR_PARAM_MEDIUM_ALBEDO: set->med_albedo[p->target] = p->offset; break;
    case DR_PARAM_MEDIUM_G: set->med_g[p->target] = p->offset; break;
    case DR_PARAM_MEDIUM_DENSITY_SCALE: set->med_density_scale[p->target] = p->offset; break;
    case DR_PARAM_MEDIUM_DENSITY: set->med_density[p->target] = p->offset; break;
    default: break;
    }
}

/* The set's per-material, light, image and medium indices, all "none"
 * (offsets()), and room for n parameters; false when out of memory. */
static bool alloc_indices(struct dr_param_set *set, const struct dr_scene *s, int n)
{
    set->n_materials = s->n_materials;
    set->n_lights = s->n_lights;
    set->n_images = s->n_images;
    set->n_media = s->n_media;
    set->params = calloc((size_t)(n > 0 ? n : 1), sizeof *set->params);
    set->mat_base_color = offsets(s->n_materials);
    set->mat_metallic = offsets(s->n_materials);
    set->mat_roughness = offsets(s->n_materials);
    set->mat_emissive_factor = offsets(s->n_materials);
    set->mat_emissive_strength = offsets(s->n_materials);
    set->mat_coat = offsets(s->n_materials);
    set->mat_coat_roughness = offsets(s->n_materials);
    set->mat_anisotropy = offsets(s->n_materials);
    set->mat_sheen_color = offsets(s->n_materials);
    set->mat_sheen_roughness = offsets(s->n_materials);
    set->light_color = offsets(s->n_lights);
    set->light_intensity = offsets(s->n_lights);
    set->image = offsets(s->n_images);
    set->mat_bsdf_active = calloc((size_t)s->n_materials + 1, sizeof(bool));
    set->mat_emission_active = calloc((size_t)s->n_materials + 1, sizeof(bool));
    set->env_color = set->env_strength = set->env_map = -1;
    set->med_extinction = offsets(s->n_media);
    set->med_albedo = offsets(s->n_media);
    set->med_g = offsets(s->n_media);
    set->med_density_scale = offsets(s->n_media);
    set->med_density = offsets(s->n_media);
    set->med_active = calloc((size_t)s->n_media + 1, sizeof(bool));
    return set->med_extinction && set->med_albedo && set->med_g && set->med_density_scale && set->med_density &&
           set->med_active && set->params && set->mat_base_color && set->mat_metallic && set->mat_roughness &&
           set->mat_emissive_factor && set->mat_emissive_strength && set->mat_coat && set->mat_coat_roughness &&
           set->mat_anisotropy && set->mat_sheen_color && set->mat_sheen_roughness && set->light_color && set->light_intensity &&
           set->image && set->mat_bsdf_active && set->mat_emission_active;
}

/* Resolves `pointer` and appends it at offset *total (advanced); 0, or an
 * error with dr_set_error (an unknown or repeated parameter, an image used
 * both as colour and as data, no memory for a texture's floats). */
static int add_param(struct dr_param_set *set, const struct dr_scene *s, const char *pointer, int64_t *total)
{
    struct dr_param p;
    if (dr_param_resolve(s, pointer, &p) != 0)
        return DR_ERR_ARG;
    for (int j = 0; j < set->n; j++)
        if (strcmp(set->params[j].name, p.name) == 0) {
            dr_set_error("%s: requested twice (as %s)", pointer, p.name);
            return DR_ERR_ARG;
        }
    if (p.kind == DR_PARAM_IMAGE) {
        bool colour, data;
        image_usage(s, p.target, &colour, &data);
        if (colour && data) {
            dr_set_error("%s: this image is used both as a colour texture (sRGB) and as metallic-roughness "
                         "data; drender cannot differentiate it as one parameter",
                         pointer);
            return DR_ERR_ARG;
        }
    }
    p.offset = *total;
    *total += p.size;
    set->params[set->n++] = p;
    index_param(set, s, &p);
    return 0;
}

/* Which materials' BSDFs and emission, which media, and whether any
 * radiance, have a parameter. */
static void mark_active(struct dr_param_set *set, const struct dr_scene *s)
{
    for (int m = 0; m < s->n_materials; m++) {
        const struct dr_material *mat = &s->materials[m];
        set->mat_bsdf_active[m] = set->mat_base_color[m] >= 0 || set->mat_metallic[m] >= 0 ||
                                  set->mat_roughness[m] >= 0 || set->mat_coat[m] >= 0 ||
                                  set->mat_coat_roughness[m] >= 0 || set->mat_anisotropy[m] >= 0 ||
                                  set->mat_sheen_color[m] >= 0 || set->mat_sheen_roughness[m] >= 0 ||
                                  texref_active(set, s, &mat->base_color_tex) ||
                                  texref_active(set, s, &mat->metallic_roughness_tex) ||
                                  (dr_material_coat_tex(mat, 0) && texref_active(set, s, dr_material_coat_tex(mat, 0))) ||
                                  (dr_material_coat_tex(mat, 1) && texref_active(set, s, dr_material_coat_tex(mat, 1)));
        set->mat_emission_active[m] = set->mat_emissive_factor[m] >= 0 || set->mat_emissive_strength[m] >= 0 ||
                                      texref_active(set, s, &mat->emissive_tex);
        set->radiance_active |= set->mat_emission_active[m];
    }
    set->radiance_active |= set->lights_active || set->env_active;
    for (int i = 0; i < s->n_media; i++) {
        set->med_active[i] = set->med_extinction[i] >= 0 || set->med_albedo[i] >= 0 || set->med_g[i] >= 0 ||
                             set->med_density_scale[i] >= 0 || set->med_density[i] >= 0;
        set->media_active |= set->med_active[i];
    }
}

struct dr_param_set *dr_param_set_create(const struct dr_scene *s, const char *const *pointers, int n)
{
    struct dr_param_set *set = calloc(1, sizeof *set);
    if (!set || !alloc_indices(set, s, n)) {
        dr_set_error("out of memory");
        dr_param_set_destroy(set);
        return NULL;
    }
    int64_t total = 0;
    for (int i = 0; i < n; i++)
        if (add_param(set, s, pointers[i], &total) != 0) {
            dr_param_set_destroy(set);
            return NULL;
        }
    set->total = total;
    mark_active(set, s);
    return set;
}

void dr_param_set_get(const struct dr_scene *s, const struct dr_param_set *set, double *values)
{
    for (int i = 0; i < set->n; i++)
        dr_param_get(s, &set->params[i], values + set->params[i].offset);
}

int dr_param_set_writable(struct dr_scene *s, const struct dr_param_set *set)
{
    for (int i = 0; i < set->n; i++) {
        const struct dr_param *p = &set->params[i];
        if (p->kind == DR_PARAM_IMAGE && dr_image_expand(&s->images[p->target]) != 0) {
            dr_set_error("%s: out of memory for its texels as floats", p->name);
            return DR_ERR_NOMEM;
        }
    }
    return 0;
}

void dr_param_set_put(struct dr_scene *s, const struct dr_param_set *set, const double *values)
{
    for (int i = 0; i < set->n; i++)
        dr_param_put(s, &set->params[i], values + set->params[i].offset);
}

void dr_param_set_put_threads(struct dr_scene *s, const struct dr_param_set *set, const double *values, int threads,
                              const uint64_t *changed)
{
    for (int i = 0; i < set->n; i++) {
        const struct dr_param *p = &set->params[i];
        const bool texels = p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP;
        float *t = texels ? param_texels(s, p) : NULL;
        if (!texels)
            dr_param_put(s, p, values + p->offset);
        if (!t)   /* (as dr_param_put: a texel parameter without floats does not change) */
            continue;
        struct texels_put x = {t, values + p->offset, changed, p->offset};
        dr_parallel_elements(p->size, threads, changed ? put_marked : put_texels, &x);
    }
}

int dr_param_set_refresh(struct dr_scene *scene, const struct dr_param_set *set)
{
    return set->radiance_active ? dr_scene_refresh(scene) : dr_scene_refresh_keep_lights(scene);
}
