/* dr_gltf_write: optimised parameter values written back as glTF.
 *
 *   test_gltf_write        writes into a temporary directory and removes it
 *   test_gltf_write DIR    writes into DIR and keeps the outputs (the .gltf and .glb files
 *                          in DIR), for tests/cli_gltf_validate.sh, which
 *                          runs the Khronos validator on them
 *
 * Every written scene is loaded again with dr_scene_load (which also prepares
 * it for rendering) and compared with what was written. */
#include <dirent.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "error.h"
#include "gltf_write.h"
#include "image.h"
#include "params.h"
#include "scene.h"
#include "test.h"

static char out_dir[4096];
static char warnings[8192];

static void record_warning(const char *msg)
{
    size_t n = strlen(warnings);
    snprintf(warnings + n, sizeof warnings - n, "%s\n", msg);
}

static const char *data_path(const char *name) { return path_in("DR_TESTDIR", "tests", name); }

static const char *out_path(const char *name)
{
    static char buf[4][sizeof out_dir + 256];
    static int k;
    char *b = buf[k++ & 3];
    snprintf(b, sizeof buf[0], "%s/%.250s", out_dir, name);
    return b;
}

static bool exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* Number of entries of a directory (without . and ..), -1 if it cannot be read. */
static int count_entries(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) n++;
    closedir(d);
    return n;
}

static void remove_tree(const char *path)
{
    struct stat st;
    if (lstat(path, &st) != 0) return;
    if (S_ISDIR(st.st_mode)) {
        DIR *d = opendir(path);
        if (d) {
            struct dirent *e;
            while ((e = readdir(d))) {
                if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
                char sub[4096];
                snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
                remove_tree(sub);
            }
            closedir(d);
        }
        rmdir(path);
    } else {
        unlink(path);
    }
}

static struct dr_param_set *make_set(const struct dr_scene *s, const char *const *ptrs, int n)
{
    struct dr_param_set *set = dr_param_set_create(s, ptrs, n);
    CHECK(set != NULL, "dr_param_set_create: %s", dr_last_error());
    return set;
}

static const struct dr_param *find_param(const struct dr_param_set *set, enum dr_param_kind kind, int target)
{
    for (int i = 0; i < set->n; i++)
        if (set->params[i].kind == kind && set->params[i].target == target) return &set->params[i];
    return NULL;
}

static void put3(struct dr_scene *s, const struct dr_param *p, double a, double b, double c)
{
    double v[3] = {a, b, c};
    dr_param_put(s, p, v);
}

static void put1(struct dr_scene *s, const struct dr_param *p, double a) { dr_param_put(s, p, &a); }

/* A recognisable texture: every texel value distinct-ish, within [0, 1]. */
static double pattern(int64_t i, int salt) { return (double)((i * 7 + salt * 3) % 23) / 22.0; }

static void put_pattern(struct dr_scene *s, const struct dr_param *p, int salt)
{
    double *v = malloc(sizeof(double) * (size_t)p->size);
    for (int64_t i = 0; i < p->size; i++) v[i] = pattern(i, salt);
    dr_param_put(s, p, v);
    free(v);
}

static double quantize8(double v)
{
    v = v < 0 ? 0 : v > 1 ? 1 : v;
    return floor(v * 255.0 + 0.5) / 255.0;
}

static void check_v3(dr_vec3 got, dr_vec3 want, double tol, const char *what)
{
    CHECK(fabs(got.x - want.x) <= tol && fabs(got.y - want.y) <= tol && fabs(got.z - want.z) <= tol,
          "%s: (%.9g %.9g %.9g) vs (%.9g %.9g %.9g)", what, got.x, got.y, got.z, want.x, want.y, want.z);
}

static bool v3_eq(dr_vec3 a, dr_vec3 b, double tol)
{
    return fabs(a.x - b.x) <= tol && fabs(a.y - b.y) <= tol && fabs(a.z - b.z) <= tol;
}

/* Everything a write must preserve that no parameter touched. */
static void check_same_scene(const struct dr_scene *a, const struct dr_scene *b, const char *what)
{
    CHECK(a->mesh.n_triangles == b->mesh.n_triangles && a->mesh.n_vertices == b->mesh.n_vertices,
          "%s: mesh %u/%u triangles, %u/%u vertices", what, a->mesh.n_triangles, b->mesh.n_triangles,
          a->mesh.n_vertices, b->mesh.n_vertices);
    check_v3(b->bbox_min, a->bbox_min, 1e-6, "bbox min");
    check_v3(b->bbox_max, a->bbox_max, 1e-6, "bbox max");
    if (a->mesh.n_vertices == b->mesh.n_vertices) {
        int bad = 0;
        for (uint32_t i = 0; i < 3 * a->mesh.n_vertices; i++)
            bad += a->mesh.positions[i] != b->mesh.positions[i] || a->mesh.normals[i] != b->mesh.normals[i];
        for (uint32_t i = 0; i < 2 * a->mesh.n_vertices; i++) bad += a->mesh.uvs[i] != b->mesh.uvs[i];
        CHECK(bad == 0, "%s: %d vertex values differ", what, bad);
    }
    if (a->mesh.n_triangles == b->mesh.n_triangles) {
        int bad = 0;
        for (uint32_t t = 0; t < a->mesh.n_triangles; t++)
            bad += a->mesh.material[t] != b->mesh.material[t] || a->mesh.indices[3 * t] != b->mesh.indices[3 * t];
        CHECK(bad == 0, "%s: %d triangles differ", what, bad);
    }
    CHECK(a->n_materials == b->n_materials && a->n_file_materials == b->n_file_materials,
          "%s: %d/%d materials", what, a->n_materials, b->n_materials);
    CHECK(a->n_textures == b->n_textures && a->n_images == b->n_images, "%s: textures %d/%d, images %d/%d", what,
          a->n_textures, b->n_textures, a->n_images, b->n_images);
    CHECK(a->n_cameras == b->n_cameras, "%s: %d/%d cameras", what, a->n_cameras, b->n_cameras);
    for (int i = 0; i < a->n_cameras && i < b->n_cameras; i++) {
        check_v3(b->cameras[i].origin, a->cameras[i].origin, 1e-9, "camera origin");
        check_v3(b->cameras[i].forward, a->cameras[i].forward, 1e-9, "camera forward");
        check_v3(b->cameras[i].up, a->cameras[i].up, 1e-9, "camera up");
        CHECK_NEAR(b->cameras[i].yfov, a->cameras[i].yfov, 1e-12, "camera yfov");
        CHECK_NEAR(b->cameras[i].aspect, a->cameras[i].aspect, 1e-12, "camera aspect");
        CHECK(strcmp(a->cameras[i].name, b->cameras[i].name) == 0, "camera name %s", b->cameras[i].name);
    }
    CHECK(a->n_lights == b->n_lights, "%s: %d/%d lights", what, a->n_lights, b->n_lights);
    for (int i = 0; i < a->n_lights && i < b->n_lights; i++) {
        check_v3(b->lights[i].position, a->lights[i].position, 1e-9, "light position");
        CHECK(a->lights[i].type == b->lights[i].type && a->lights[i].range == b->lights[i].range &&
              fabs(a->lights[i].cos_outer - b->lights[i].cos_outer) < 1e-12,
              "%s: light %d type/range/cone", what, i);
    }
    CHECK(a->env.present == b->env.present, "%s: environment presence", what);
    for (int i = 0; i < a->n_textures && i < b->n_textures; i++)
        CHECK(a->textures[i].image == b->textures[i].image && a->textures[i].wrap_s == b->textures[i].wrap_s &&
              a->textures[i].wrap_t == b->textures[i].wrap_t, "%s: texture %d", what, i);
    CHECK(a->effects == b->effects, "%s: effects %#x vs %#x", what, a->effects, b->effects);
}

/* Material m of b equals a's except for the listed fields. */
enum { F_BASE = 1, F_METAL = 2, F_ROUGH = 4, F_EMISSION = 8 };
static void check_material(const struct dr_scene *a, const struct dr_scene *b, int m, unsigned changed)
{
    const struct dr_material *x = &a->materials[m], *y = &b->materials[m];
    char what[128];
    snprintf(what, sizeof what, "material %d (%s)", m, x->name);
    CHECK(strcmp(x->name, y->name) == 0, "%s: name %s", what, y->name);
    if (!(changed & F_BASE)) CHECK(v3_eq(x->base_color, y->base_color, 0), "%s: base colour changed", what);
    if (!(changed & F_METAL)) CHECK(x->metallic == y->metallic, "%s: metallic changed", what);
    if (!(changed & F_ROUGH)) CHECK(x->roughness == y->roughness, "%s: roughness changed", what);
    if (!(changed & F_EMISSION))
        CHECK(v3_eq(x->emissive_factor, y->emissive_factor, 0) && x->emissive_strength == y->emissive_strength,
              "%s: emission changed", what);
    CHECK(x->specular == y->specular && v3_eq(x->specular_color, y->specular_color, 0) &&
          x->double_sided == y->double_sided, "%s: specular/doubleSided changed", what);
    CHECK(x->base_color_tex.texture == y->base_color_tex.texture &&
          x->metallic_roughness_tex.texture == y->metallic_roughness_tex.texture &&
          x->emissive_tex.texture == y->emissive_tex.texture, "%s: texture references changed", what);
}

static struct dr_scene *reload(const char *path)
{
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "reloading %s: %s", path, dr_last_error());
    return s;
}

/* ---- the Cornell box: colour texture, materials, emission ---- */

static void test_cornell(const char *name)
{
    struct dr_scene *orig = dr_scene_load(scene_path("cornell-box.gltf"));
    struct dr_scene *s = dr_scene_load(scene_path("cornell-box.gltf"));
    CHECK(orig && s, "cornell-box.gltf: %s", dr_last_error());
    if (!orig || !s) goto out;
    const char *ptrs[] = {
        "/materials/red/pbrMetallicRoughness/baseColorFactor",
        "/materials/0/pbrMetallicRoughness/roughnessFactor",
        "/materials/light/extensions/KHR_materials_emissive_strength/emissiveStrength",
        "/materials/light/emissiveFactor",
        "/materials/rough-gold/pbrMetallicRoughness/metallicFactor",
        "/images/0",
    };
    struct dr_param_set *set = make_set(s, ptrs, 6);
    if (!set) goto out;
    int red = set->params[0].target, light = set->params[2].target, gold = set->params[4].target;
    CHECK(red == 1 && light == 3 && gold == 4, "material indices %d %d %d", red, light, gold);
    put3(s, &set->params[0], 0.5, 0.25, 0.125);
    put1(s, &set->params[1], 0.375);
    put1(s, &set->params[2], 7.0);
    put3(s, &set->params[3], 2.0, 1.5, 0.5);   /* above 1: the excess must move into the strength */
    put1(s, &set->params[4], 0.625);
    put_pattern(s, &set->params[5], 1);

    int rc = dr_gltf_write(s, set, out_path(name));
    CHECK(rc == 0, "dr_gltf_write %s: %s", name, dr_last_error());
    struct dr_scene *r = rc == 0 ? reload(out_path(name)) : NULL;
    if (r) {
        check_same_scene(orig, r, name);
        check_v3(r->materials[red].base_color, dr_v3(0.5, 0.25, 0.125), 0, "red base colour");
        CHECK(r->materials[0].roughness == 0.375, "roughness %g", r->materials[0].roughness);
        CHECK(r->materials[gold].metallic == 0.625, "metallic %g", r->materials[gold].metallic);
        const struct dr_material *L = &r->materials[light];
        check_v3(L->emissive_factor, dr_v3(1.0, 0.75, 0.25), 1e-15, "emissive factor normalised to max 1");
        CHECK_NEAR(L->emissive_strength, 14.0, 1e-12, "strength took the factor's excess");
        check_v3(dr_scale(L->emissive_factor, L->emissive_strength), dr_v3(14.0, 10.5, 3.5), 1e-12,
                 "emission = factor * strength preserved");
        for (int m = 0; m < orig->n_materials; m++) {
            unsigned changed = m == red ? F_BASE : m == 0 ? F_ROUGH : m == light ? F_EMISSION : m == gold ? F_METAL : 0;
            check_material(orig, r, m, changed);
        }
        /* the colour texture: sRGB-encoded 8-bit, decoded again on load */
        const struct dr_image *im = &r->images[0];
        const struct dr_param *p = &set->params[5];
        CHECK(im->width == p->width && im->height == p->height && im->channels == p->channels &&
                  dr_image_has_linear(im),
              "image 0: %dx%dx%d", im->width, im->height, im->channels);
        if (dr_image_has_linear(im) && im->width == p->width && im->height == p->height && im->channels == p->channels) {
            int bad = 0;
            double worst = 0;
            for (int64_t i = 0; i < p->size; i++) {
                double want = dr_srgb_to_linear(quantize8(dr_linear_to_srgb(pattern(i, 1))));
                double err = fabs(dr_image_value(im, (size_t)i, true) - want);
                worst = err > worst ? err : worst;
                bad += err > 1e-6;
                /* and within 8-bit sRGB quantisation of the value that was put */
                bad += fabs(dr_image_value(im, (size_t)i, true) - pattern(i, 1)) > 0.5 / 255.0 * 2.4 + 1e-6;
            }
            CHECK(bad == 0, "image 0: %d texels off (worst %g)", bad, worst);
        }
        dr_scene_destroy(r);
    }
    /* the new texture and the buffer sit next to a .gltf; a .glb embeds both */
    char stem[256], file[512];
    bool glb = strstr(name, ".glb") != NULL;
    snprintf(stem, sizeof stem, "%.*s", (int)(strrchr(name, '.') - name), name);
    snprintf(file, sizeof file, "%s.image0.png", stem);
    CHECK(exists(out_path(file)) == !glb, "%s %s", file, glb ? "not written (embedded)" : "written");
    snprintf(file, sizeof file, "%s.bin", stem);
    CHECK(exists(out_path(file)) == !glb, "%s %s", file, glb ? "not written (embedded)" : "written");
    dr_param_set_destroy(set);
out:
    dr_scene_destroy(orig);
    dr_scene_destroy(s);
}

/* A written scene written again into the same directory, unchanged: its
 * texture uri (the first output's image) is kept, nothing is copied. */
static void test_rewrite_same_dir(void)
{
    struct dr_scene *a = dr_scene_load(out_path("cornell.gltf"));
    CHECK(a != NULL, "cornell.gltf: %s", dr_last_error());
    if (!a) return;
    int before = count_entries(out_dir);
    int rc = dr_gltf_write(a, NULL, out_path("cornell-again.gltf"));
    CHECK(rc == 0, "rewrite: %s", dr_last_error());
    CHECK(count_entries(out_dir) == before + 2, "rewrite adds exactly .gltf and .bin: %d -> %d", before,
          count_entries(out_dir));
    struct dr_scene *b = rc == 0 ? reload(out_path("cornell-again.gltf")) : NULL;
    if (b) {
        check_same_scene(a, b, "rewrite");
        for (int m = 0; m < a->n_materials; m++) check_material(a, b, m, 0);
        int bad = 0;
        for (int64_t i = 0; i < (int64_t)a->images[0].width * a->images[0].height * a->images[0].channels; i++)
            bad += dr_image_value(&a->images[0], (size_t)i, false) != dr_image_value(&b->images[0], (size_t)i, false);
        CHECK(bad == 0, "rewrite: %d texels differ", bad);
        dr_scene_destroy(b);
    }
    dr_scene_destroy(a);
}

/* ---- lights, environment, a data (metallic-roughness) texture ---- */

/* The same size and values as stored (in either storage, image.h). */
static bool same_pixels(const struct dr_image *a, const struct dr_image *b)
{
    if (a->width != b->width || a->height != b->height || a->channels != b->channels)
        return false;
    for (size_t i = 0; i < (size_t)a->width * a->height * a->channels; i++)
        if (dr_image_value(a, i, false) != dr_image_value(b, i, false))
            return false;
    return true;
}

static void test_basic(const char *src, const char *name)
{
    struct dr_scene *orig = dr_scene_load(data_path(src));
    struct dr_scene *s = dr_scene_load(data_path(src));
    CHECK(orig && s, "%s: %s", src, dr_last_error());
    if (!orig || !s) goto out;
    const char *ptrs[] = {
        "/extensions/KHR_lights_punctual/lights/0/color",
        "/extensions/KHR_lights_punctual/lights/0/intensity",
        "/extensions/KHR_lights_punctual/lights/2/color",
        "/extensions/DR_environment/color",
        "/extensions/DR_environment/strength",
        "/materials/0/emissiveFactor",
        "/images/1",
    };
    struct dr_param_set *set = make_set(s, ptrs, 7);
    if (!set) goto out;
    put3(s, &set->params[0], 2.0, 1.0, 0.5);     /* above 1: moves into the intensity */
    put1(s, &set->params[1], 3.0);
    put3(s, &set->params[2], 0.25, 0.5, 0.75);   /* no intensity parameter: kept */
    put3(s, &set->params[3], 0.4, 0.5, 0.6);
    put1(s, &set->params[4], 1.5);
    put3(s, &set->params[5], 0.2, 3.0, 0.6);     /* above 1, strength from the file (5) */
    put_pattern(s, &set->params[6], 2);

    int rc = dr_gltf_write(s, set, out_path(name));
    CHECK(rc == 0, "dr_gltf_write %s: %s", name, dr_last_error());
    struct dr_scene *r = rc == 0 ? reload(out_path(name)) : NULL;
    if (r) {
        check_same_scene(orig, r, name);
        for (int i = 0; i < r->n_lights; i++) {
            const struct dr_punctual *l = &r->lights[i];
            if (l->gltf_index == 0) {
                check_v3(l->color, dr_v3(1.0, 0.5, 0.25), 1e-15, "light 0 colour normalised");
                CHECK_NEAR(l->intensity, 6.0, 1e-12, "light 0 intensity took the colour's excess");
            } else if (l->gltf_index == 2) {
                check_v3(l->color, dr_v3(0.25, 0.5, 0.75), 0, "light 2 colour");
                CHECK(l->intensity == orig->lights[i].intensity, "light 2 intensity kept");
            } else {
                check_v3(l->color, orig->lights[i].color, 0, "light 1 colour kept");
                CHECK(l->intensity == orig->lights[i].intensity, "light 1 intensity kept");
            }
        }
        check_v3(r->env.color, dr_v3(0.4, 0.5, 0.6), 0, "environment colour");
        CHECK(r->env.strength == 1.5, "environment strength %g", r->env.strength);
        const struct dr_material *M = &r->materials[0];
        check_v3(dr_scale(M->emissive_factor, M->emissive_strength), dr_v3(1.0, 15.0, 3.0), 1e-12,
                 "emission preserved");
        CHECK_NEAR(M->emissive_strength, 15.0, 1e-12, "strength 5 * 3");
        check_material(orig, r, 0, F_EMISSION);
        /* the data texture: written as-is (no sRGB curve), read as stored */
        const struct dr_image *im = &r->images[1];
        const struct dr_param *p = &set->params[6];
        CHECK(im->width == p->width && im->height == p->height && im->channels == p->channels,
              "image 1: %dx%dx%d", im->width, im->height, im->channels);
        if (im->width == p->width && im->height == p->height && im->channels == p->channels) {
            int bad = 0;
            for (int64_t i = 0; i < p->size; i++)
                bad += fabs(dr_image_value(im, (size_t)i, false) - quantize8(pattern(i, 2))) > 1e-6;
            CHECK(bad == 0, "image 1: %d texels off", bad);
        }
        /* the untouched colour texture was copied, pixels intact */
        const struct dr_image *a = &orig->images[0], *b = &r->images[0];
        CHECK(same_pixels(a, b), "image 0 kept");
        CHECK(exists(out_path("checker.png")), "checker.png copied next to the output");
        dr_scene_destroy(r);
    }
    dr_param_set_destroy(set);
out:
    dr_scene_destroy(orig);
    dr_scene_destroy(s);
}

/* ---- the environment map (float EXR) ---- */

static void test_env_map(void)
{
    /* env_map.gltf has no geometry; dr_gltf_load without prepare is enough */
    struct dr_scene *s = calloc(1, sizeof *s);
    int rc = dr_gltf_load(data_path("data/gltf/env_map.gltf"), s);
    CHECK(rc == 0, "env_map.gltf: %s", dr_last_error());
    const char *ptrs[] = {"/extensions/DR_environment/uri", "/extensions/DR_environment/strength"};
    struct dr_param_set *set = rc == 0 ? make_set(s, ptrs, 2) : NULL;
    if (set) {
        const struct dr_param *map = find_param(set, DR_PARAM_ENV_MAP, -1);
        double *v = malloc(sizeof(double) * (size_t)map->size);
        for (int64_t i = 0; i < map->size; i++) v[i] = 0.001 + 37.5 * pattern(i, 3);   /* HDR values */
        dr_param_put(s, map, v);
        put1(s, find_param(set, DR_PARAM_ENV_STRENGTH, -1), 2.5);
        rc = dr_gltf_write(s, set, out_path("env.gltf"));
        CHECK(rc == 0, "dr_gltf_write env.gltf: %s", dr_last_error());
        CHECK(exists(out_path("env.environment.exr")), "env.environment.exr written");
        struct dr_scene *r = calloc(1, sizeof *r);
        rc = rc == 0 ? dr_gltf_load(out_path("env.gltf"), r) : rc;
        CHECK(rc == 0, "reloading env.gltf: %s", dr_last_error());
        if (rc == 0) {
            CHECK(strcmp(r->env.uri, "env.environment.exr") == 0, "uri %s", r->env.uri);
            CHECK(r->env.strength == 2.5, "strength %g", r->env.strength);
            const struct dr_image *im = &r->env.map;
            CHECK(im->width == map->width && im->height == map->height && im->channels == map->channels,
                  "map %dx%dx%d", im->width, im->height, im->channels);
            if (im->width == map->width && im->height == map->height && im->channels == map->channels) {
                int bad = 0;
                const float *t = im->linear ? im->linear : im->data;
                for (int64_t i = 0; i < map->size; i++) bad += t[i] != (float)v[i];
                CHECK(bad == 0, "environment map: %d texels differ (float round trip)", bad);
            }
        }
        free(v);
        dr_scene_destroy(r);
        dr_param_set_destroy(set);
    }
    dr_scene_destroy(s);
}

/* ---- data: URIs, images in subdirectories and outside ---- */

/* Embedded images (data: URIs) stay embedded, unchanged; the data: buffer
 * becomes a .bin file. */
static void test_embedded(void)
{
    struct dr_scene *a = dr_scene_load(data_path("data/gltf/basic_embedded.gltf"));
    CHECK(a != NULL, "basic_embedded.gltf: %s", dr_last_error());
    if (!a) return;
    int rc = dr_gltf_write(a, NULL, out_path("embedded.gltf"));
    CHECK(rc == 0, "embedded.gltf: %s", dr_last_error());
    struct dr_scene *b = rc == 0 ? reload(out_path("embedded.gltf")) : NULL;
    if (b) {
        check_same_scene(a, b, "embedded");
        for (int m = 0; m < a->n_materials; m++) check_material(a, b, m, 0);
        for (int i = 0; i < a->n_images && i < b->n_images; i++)
            CHECK(same_pixels(&a->images[i], &b->images[i]), "embedded image %d kept", i);
        CHECK(exists(out_path("embedded.bin")), "embedded.bin written");
        dr_scene_destroy(b);
    }
    FILE *f = fopen(out_path("embedded.gltf"), "r");
    char text[16384] = "";
    if (f) {
        size_t n = fread(text, 1, sizeof text - 1, f);
        text[n] = 0;
        fclose(f);
    }
    CHECK(strstr(text, "data:image/png;base64,iVBORw0KGgo") != NULL, "images still data: URIs");
    dr_scene_destroy(a);
}

static bool copy_file(const char *from, const char *to)
{
    FILE *in = fopen(from, "rb"), *out = fopen(to, "wb");
    bool ok = in && out;
    char buf[65536];
    size_t n;
    while (ok && (n = fread(buf, 1, sizeof buf, in)) > 0) ok = fwrite(buf, 1, n, out) == n;
    if (in) fclose(in);
    if (out && fclose(out) != 0) ok = false;
    return ok;
}

/* A source whose images live in a subdirectory ("tex/checker.png": copied to
 * the same relative place) and above it ("../mr.png": copied as
 * <stem>.image1.png, uri changed), written into another directory. */
static void test_copied_images(void)
{
    char src[4400], dst[4400], p1[4600], p2[4600];
    snprintf(src, sizeof src, "%s/src", out_dir);
    snprintf(dst, sizeof dst, "%s/dst", out_dir);
    remove_tree(src);
    remove_tree(dst);
    snprintf(p1, sizeof p1, "%s/tex", src);
    CHECK(mkdir(src, 0777) == 0 && mkdir(p1, 0777) == 0 && mkdir(dst, 0777) == 0, "mkdirs");

    /* the scene text with the image uris moved */
    FILE *f = fopen(data_path("data/gltf/basic.gltf"), "r");
    static char text[65536], edited[65600];
    size_t n = f ? fread(text, 1, sizeof text - 1, f) : 0;
    if (f) fclose(f);
    text[n] = 0;
    char *c = strstr(text, "\"checker.png\""), *m = strstr(text, "\"mr.png\"");
    CHECK(c && m && c < m, "basic.gltf image uris");
    if (!(c && m && c < m)) return;
    snprintf(edited, sizeof edited, "%.*s\"tex/checker.png\"%.*s\"../mr.png\"%s", (int)(c - text), text,
             (int)(m - c - 13), c + 13, m + 8);
    snprintf(p1, sizeof p1, "%s/moved.gltf", src);
    f = fopen(p1, "w");
    if (f) {
        fputs(edited, f);
        fclose(f);
    }
    snprintf(p2, sizeof p2, "%s/basic.bin", src);
    bool ok = copy_file(data_path("data/gltf/basic.bin"), p2);
    snprintf(p2, sizeof p2, "%s/tex/checker.png", src);
    ok = ok && copy_file(data_path("data/gltf/checker.png"), p2);
    snprintf(p2, sizeof p2, "%s/mr.png", out_dir);
    ok = ok && copy_file(data_path("data/gltf/mr.png"), p2);
    CHECK(ok, "copying the test scene");

    struct dr_scene *a = dr_scene_load(p1);
    CHECK(a != NULL, "moved.gltf: %s", dr_last_error());
    if (!a) return;
    snprintf(p2, sizeof p2, "%s/moved-out.gltf", dst);
    int rc = dr_gltf_write(a, NULL, p2);
    CHECK(rc == 0, "moved-out.gltf: %s", dr_last_error());
    struct dr_scene *b = rc == 0 ? reload(p2) : NULL;
    if (b) {
        check_same_scene(a, b, "copied images");
        for (int i = 0; i < a->n_images && i < b->n_images; i++)
            CHECK(same_pixels(&a->images[i], &b->images[i]), "copied image %d", i);
        dr_scene_destroy(b);
    }
    snprintf(p1, sizeof p1, "%s/tex/checker.png", dst);
    CHECK(exists(p1), "tex/checker.png copied into the output's tex/");
    snprintf(p1, sizeof p1, "%s/moved-out.image1.png", dst);
    CHECK(exists(p1), "../mr.png copied as moved-out.image1.png");
    CHECK(count_entries(dst) == 4, "dst holds .gltf, .bin, tex/, the renamed image: %d", count_entries(dst));
    dr_scene_destroy(a);
    remove_tree(src);
    remove_tree(dst);
    snprintf(p2, sizeof p2, "%s/mr.png", out_dir);
    unlink(p2);
}

/* ---- failures leave nothing behind ---- */

static void test_write_failures(void)
{
    struct dr_scene *s = dr_scene_load(scene_path("cornell-box.gltf"));
    CHECK(s != NULL, "cornell-box.gltf: %s", dr_last_error());
    if (!s) return;
    const char *ptrs[] = {"/images/0", "/materials/0/pbrMetallicRoughness/roughnessFactor"};
    struct dr_param_set *set = make_set(s, ptrs, 2);

    char fail_dir[4200], path[4300];
    snprintf(fail_dir, sizeof fail_dir, "%s/fail", out_dir);
    remove_tree(fail_dir);
    CHECK(mkdir(fail_dir, 0777) == 0, "mkdir %s: %s", fail_dir, strerror(errno));

    /* a directory that does not exist */
    snprintf(path, sizeof path, "%s/no-such-dir/x.gltf", fail_dir);
    int rc = dr_gltf_write(s, set, path);
    CHECK(rc == DR_ERR_IO, "nonexistent directory: rc %d", rc);
    CHECK(strstr(dr_last_error(), "x.gltf") != NULL, "the message names the file: %s", dr_last_error());
    fprintf(stderr, "expected error: %s\n", dr_last_error());
    CHECK(count_entries(fail_dir) == 0, "nothing left in %s (%d entries)", fail_dir, count_entries(fail_dir));

    /* not a glTF name */
    snprintf(path, sizeof path, "%s/x.obj", fail_dir);
    rc = dr_gltf_write(s, set, path);
    CHECK(rc == DR_ERR_ARG, "x.obj: rc %d (%s)", rc, dr_last_error());
    CHECK(count_entries(fail_dir) == 0, "nothing left after x.obj");

    /* a failure at the very end (the .bin cannot replace a non-empty directory):
     * the texture already renamed into place is removed again */
    char blocker[4400];
    snprintf(blocker, sizeof blocker, "%s/x.bin", fail_dir);
    CHECK(mkdir(blocker, 0777) == 0, "mkdir x.bin");
    snprintf(blocker, sizeof blocker, "%s/x.bin/keep", fail_dir);
    FILE *f = fopen(blocker, "w");
    if (f) fclose(f);
    snprintf(path, sizeof path, "%s/x.gltf", fail_dir);
    rc = dr_gltf_write(s, set, path);
    CHECK(rc == DR_ERR_IO, "blocked .bin: rc %d", rc);
    fprintf(stderr, "expected error: %s\n", dr_last_error());
    CHECK(count_entries(fail_dir) == 1, "only the blocker is left (%d entries)", count_entries(fail_dir));
    snprintf(path, sizeof path, "%s/x.image0.png", fail_dir);
    CHECK(!exists(path), "x.image0.png removed again");

    /* a non-finite value is refused */
    double nan_v = NAN;
    dr_param_put(s, &set->params[1], &nan_v);
    snprintf(path, sizeof path, "%s/y.gltf", fail_dir);
    rc = dr_gltf_write(s, set, path);
    CHECK(rc == DR_ERR_ARG, "NaN roughness: rc %d (%s)", rc, dr_last_error());
    CHECK(count_entries(fail_dir) == 1, "nothing left after NaN");

    remove_tree(fail_dir);
    dr_param_set_destroy(set);
    dr_scene_destroy(s);
}

int main(int argc, char **argv)
{
    dr_set_warn_handler(record_warning);
    bool keep = argc > 1;
    if (keep) {
        snprintf(out_dir, sizeof out_dir, "%s", argv[1]);
        if (mkdir(out_dir, 0777) != 0 && errno != EEXIST) {
            fprintf(stderr, "cannot create %s: %s\n", out_dir, strerror(errno));
            return 2;
        }
    } else {
        const char *tmp = getenv("TMPDIR");
        snprintf(out_dir, sizeof out_dir, "%s/drender-gltf-write-XXXXXX", tmp && *tmp ? tmp : "/tmp");
        if (!mkdtemp(out_dir)) {
            fprintf(stderr, "mkdtemp: %s\n", strerror(errno));
            return 2;
        }
    }
    test_cornell("cornell.gltf");
    test_cornell("cornell-binary.glb");
    test_rewrite_same_dir();
    test_basic("data/gltf/basic.gltf", "basic.gltf");
    test_basic("data/gltf/basic.glb", "basic-from-glb.glb");
    test_env_map();
    test_embedded();
    test_copied_images();
    test_write_failures();
    if (warnings[0]) fprintf(stderr, "warnings:\n%s", warnings);
    if (!keep) remove_tree(out_dir);
    else fprintf(stderr, "outputs kept in %s\n", out_dir);
    return TEST_END();
}
