/* The glTF loader (core/gltf_load.cpp) against the scenes written by
 * tests/data/gltf/make_scenes.py: every expected number below follows from
 * the values in that script. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "image.h"
#include "scene.h"
#include "test.h"

/* ---- helpers ---- */

static char warnings[16384];

static void record_warning(const char *msg)
{
    size_t n = strlen(warnings);
    snprintf(warnings + n, sizeof warnings - n, "%s\n", msg);
}

static int count_substr(const char *s, const char *sub)
{
    int n = 0;
    for (const char *p = strstr(s, sub); p; p = strstr(p + 1, sub)) n++;
    return n;
}

static const char *data_path(const char *name)
{
    static char buf[4096];
    const char *dir = getenv("DR_TESTDIR");
    snprintf(buf, sizeof buf, "%s/data/gltf/%s", dir && *dir ? dir : "tests", name);
    return buf;
}

static void free_scene(struct dr_scene *s)
{
    if (!s) return;
    free(s->path);
    free(s->mesh.positions);
    free(s->mesh.normals);
    free(s->mesh.uvs);
    free(s->mesh.uvs1);
    free(s->mesh.colors);
    free(s->mesh.indices);
    free(s->mesh.material);
    free(s->mesh.flags);
    free(s->materials);
    free(s->textures);
    for (int i = 0; i < s->n_images; i++) dr_image_release(&s->images[i]);
    free(s->images);
    free(s->cameras);
    free(s->lights);
    dr_image_release(&s->env.map);
    free(s);
}

/* Loads data/gltf/name into a fresh scene; *rc gets the return code. */
static struct dr_scene *load(const char *name, int *rc)
{
    struct dr_scene *s = calloc(1, sizeof *s);
    warnings[0] = '\0';
    *rc = dr_gltf_load(data_path(name), s);
    return s;
}

static void check_vec(dr_vec3 got, double x, double y, double z, double tol, const char *what)
{
    CHECK(fabs(got.x - x) <= tol && fabs(got.y - y) <= tol && fabs(got.z - z) <= tol,
          "%s: (%g, %g, %g) vs (%g, %g, %g)", what, got.x, got.y, got.z, x, y, z);
}

static dr_vec3 vertex(const struct dr_scene *s, uint32_t v)
{
    const float *p = s->mesh.positions + 3 * (size_t)v;
    return dr_v3(p[0], p[1], p[2]);
}

static dr_vec3 normal_at(const struct dr_scene *s, uint32_t v)
{
    const float *n = s->mesh.normals + 3 * (size_t)v;
    return dr_v3(n[0], n[1], n[2]);
}

static dr_vec3 geometric_normal(const struct dr_scene *s, uint32_t t)
{
    const uint32_t *ix = s->mesh.indices + 3 * (size_t)t;
    dr_vec3 a = vertex(s, ix[0]), b = vertex(s, ix[1]), c = vertex(s, ix[2]);
    return dr_normalize(dr_cross(dr_sub(b, a), dr_sub(c, a)));
}

static void check_tri(const struct dr_scene *s, uint32_t t, uint32_t a, uint32_t b, uint32_t c)
{
    const uint32_t *ix = s->mesh.indices + 3 * (size_t)t;
    CHECK(ix[0] == a && ix[1] == b && ix[2] == c, "triangle %u: (%u %u %u) vs (%u %u %u)", t, ix[0], ix[1],
          ix[2], a, b, c);
}

static double srgb_decode(double v)
{
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

/* ---- the same scene as .gltf + .bin, as data: URIs, and as .glb ---- */

static void check_basic(const char *name)
{
    int rc;
    struct dr_scene *s = load(name, &rc);
    CHECK(rc == 0, "%s: %s", name, dr_last_error());
    if (rc != 0) {
        free_scene(s);
        return;
    }
    fprintf(stderr, "-- %s\n", name);
    const struct dr_mesh *m = &s->mesh;
    CHECK(s->path && strstr(s->path, name), "path %s", s->path ? s->path : "(null)");
    CHECK(m->n_vertices == 7, "n_vertices %u", m->n_vertices);
    CHECK(m->n_triangles == 3, "n_triangles %u", m->n_triangles);
    if (m->n_vertices != 7 || m->n_triangles != 3) {
        free_scene(s);
        return;
    }

    /* quad: T(1,2,3) R_y(90) S(2) T(0,0,1) maps (x, y, 0) to (3, 2+2y, 3-2x) */
    check_vec(vertex(s, 0), 3, 0, 5, 1e-5, "quad v0");
    check_vec(vertex(s, 1), 3, 0, 1, 1e-5, "quad v1");
    check_vec(vertex(s, 2), 3, 4, 1, 1e-5, "quad v2");
    check_vec(vertex(s, 3), 3, 4, 5, 1e-5, "quad v3");
    CHECK(m->positions[3 * 7] == 0.0f, "padding float");  /* ASan: the padding exists */
    for (uint32_t v = 0; v < 4; v++) check_vec(normal_at(s, v), 1, 0, 0, 1e-6, "quad normal (rotated +z)");
    const float uv[8] = {0, 1, 1, 1, 1, 0, 0, 0};
    for (int i = 0; i < 8; i++) CHECK_NEAR(m->uvs[i], uv[i], 1e-7, "quad uv");
    check_tri(s, 0, 0, 1, 2);
    check_tri(s, 1, 0, 2, 3);
    CHECK(dr_dot(geometric_normal(s, 0), normal_at(s, 0)) > 0.99, "quad winding agrees with its normal");
    CHECK(m->flags[0] == (DR_TRI_HAS_NORMALS | DR_TRI_HAS_UVS) && m->flags[1] == m->flags[0], "quad flags %d",
          m->flags[0]);
    CHECK(m->material[0] == 0 && m->material[1] == 0, "quad material");

    /* non-indexed triangle under scale(-1,1,1): no normals, no uvs, default material */
    check_vec(vertex(s, 4), 0, 0, 0, 1e-6, "mirrored v0");
    check_vec(vertex(s, 5), -1, 0, 0, 1e-6, "mirrored v1");
    check_vec(vertex(s, 6), 0, 1, 0, 1e-6, "mirrored v2");
    CHECK(m->flags[2] == 0, "triangle without normals/uvs: flags %d", m->flags[2]);
    check_vec(normal_at(s, 4), 0, 0, 0, 0, "missing normals are zero");
    /* the local front (+z, counter-clockwise) must stay +z after the mirror */
    check_vec(geometric_normal(s, 2), 0, 0, 1, 1e-6, "mirrored triangle keeps its front face");
    CHECK(m->material[2] == 1, "default material index %d", m->material[2]);

    check_vec(s->bbox_min, -1, 0, 0, 1e-5, "bbox_min");
    check_vec(s->bbox_max, 3, 4, 5, 1e-5, "bbox_max");

    /* materials */
    CHECK(s->n_materials == 2, "n_materials %d (1 + appended default)", s->n_materials);
    if (s->n_materials == 2) {
        const struct dr_material *a = &s->materials[0], *d = &s->materials[1];
        CHECK(strcmp(a->name, "textured") == 0, "name %s", a->name);
        check_vec(a->base_color, 0.8, 0.6, 0.4, 1e-12, "baseColorFactor");
        CHECK_NEAR(a->metallic, 0.25, 1e-12, "metallic");
        CHECK_NEAR(a->roughness, 0.5, 1e-12, "roughness");
        check_vec(a->emissive_factor, 1, 0.5, 0, 1e-12, "emissiveFactor");
        CHECK_NEAR(a->emissive_strength, 5, 1e-12, "emissive strength");
        CHECK(a->specular == 0.0, "specularFactor 0: %g", a->specular);
        check_vec(a->specular_color, 0.5, 0.25, 1, 1e-12, "specularColorFactor");
        CHECK(a->double_sided, "doubleSided");
        CHECK(a->base_color_tex.texture == 0 && a->base_color_tex.texcoord == 0, "baseColorTexture");
        CHECK(a->metallic_roughness_tex.texture == 1, "metallicRoughnessTexture");
        CHECK(a->emissive_tex.texture == -1, "no emissiveTexture");
        check_vec(d->base_color, 1, 1, 1, 0, "default base colour");
        CHECK(d->metallic == 1.0 && d->roughness == 1.0, "default metallic/roughness");
        CHECK(d->emissive_strength == 1.0 && d->specular == 1.0, "default strength/specular");
        check_vec(d->emissive_factor, 0, 0, 0, 0, "default emissive");
        check_vec(d->specular_color, 1, 1, 1, 0, "default specular colour");
        CHECK(!d->double_sided && d->base_color_tex.texture == -1 && d->metallic_roughness_tex.texture == -1 &&
                  d->emissive_tex.texture == -1,
              "default material has no textures");
    }

    /* textures and images */
    CHECK(s->n_textures == 2, "n_textures %d", s->n_textures);
    if (s->n_textures == 2) {
        CHECK(s->textures[0].image == 0 && s->textures[0].wrap_s == DR_WRAP_CLAMP &&
                  s->textures[0].wrap_t == DR_WRAP_MIRROR,
              "sampler 0 wrap modes");
        CHECK(s->textures[1].image == 1 && s->textures[1].wrap_s == DR_WRAP_REPEAT &&
                  s->textures[1].wrap_t == DR_WRAP_REPEAT,
              "no sampler: REPEAT");
    }
    CHECK(s->n_images == 2, "n_images %d", s->n_images);
    if (s->n_images == 2) {
        const struct dr_image *c = &s->images[0], *mr = &s->images[1];
        CHECK(c->width == 4 && c->height == 4 && c->channels == 3, "checker %dx%dx%d", c->width, c->height,
              c->channels);
        CHECK(dr_image_has_linear(c), "base colour image gets the sRGB decode");
        /* only used as colour: decoded in place, no second copy; from an
         * 8-bit PNG: kept in eight-bit storage (image.h) */
        CHECK(c->linear_in_data && c->bytes && !c->data && !c->linear, "colour-only image: eight bits, decoded in place");
        if (dr_image_has_linear(c) && c->width == 4 && c->height == 4 && c->channels == 3) {
            int bad = 0;
            for (int y = 0; y < 4; y++)
                for (int x = 0; x < 4; x++) {
                    const double want[3] = {64 * x / 255.0, 64 * y / 255.0, 128 / 255.0};
                    for (int k = 0; k < 3; k++) {
                        size_t i = (size_t)(y * 4 + x) * 3 + (size_t)k;
                        bad += fabs(dr_image_value(c, i, true) - srgb_decode(want[k])) > 1e-5;
                    }
                }
            CHECK(bad == 0, "%d checker texels differ from the file's sRGB decode", bad);
        }
        CHECK(mr->width == 2 && mr->height == 2, "mr %dx%d", mr->width, mr->height);
        CHECK(!dr_image_has_linear(mr), "metallicRoughness is linear data: no sRGB decode");
        if (dr_image_has_pixels(mr) && mr->width == 2 && mr->height == 2 && mr->channels >= 3) {
            const size_t t = (size_t)(1 * 2 + 1) * (size_t)mr->channels;  /* texel (1, 1) */
            CHECK_NEAR(dr_image_value(mr, t + 1, false), 150 / 255.0, 1e-6, "mr texel (1,1) green");
            CHECK_NEAR(dr_image_value(mr, t + 2, false), 200 / 255.0, 1e-6, "mr texel (1,1) blue");
        }
    }

    /* no vertex colours, no texture reading TEXCOORD_1: neither array exists */
    CHECK(s->mesh.colors == NULL && s->mesh.uvs1 == NULL, "no colour / uv1 arrays without COLOR_0 / texCoord 1");
    /* cameras: the perspective one, then the orthographic one (node order) */
    CHECK(s->n_cameras == 2 && s->n_unplaced_cameras == 0, "n_cameras %d, unplaced %d", s->n_cameras,
          s->n_unplaced_cameras);
    if (s->n_cameras == 2) {
        const struct dr_camera *o = &s->cameras[1];
        CHECK(o->orthographic && o->gltf_index == 1, "camera 1 orthographic (%d), /cameras/%d", o->orthographic,
              o->gltf_index);
        CHECK_NEAR(o->ymag, 1.0, 0, "ortho ymag");
        CHECK_NEAR(o->aspect, 1.0, 0, "ortho aspect = xmag / ymag");
        check_vec(o->forward, 0, 0, -1, 1e-12, "ortho forward");
        CHECK(!s->cameras[0].orthographic && s->cameras[0].gltf_index == 0, "camera 0 perspective");
    }
    if (s->n_cameras >= 1) {
        const struct dr_camera *c = &s->cameras[0];
        CHECK(strcmp(c->name, "main_cam") == 0, "camera name %s", c->name);
        check_vec(c->origin, 0, 1, 5, 1e-12, "camera origin");
        /* R_y(90) with scale 3: -z -> -x, x -> -z, unit length */
        check_vec(c->forward, -1, 0, 0, 1e-9, "camera forward");
        check_vec(c->right, 0, 0, -1, 1e-9, "camera right");
        check_vec(c->up, 0, 1, 0, 1e-9, "camera up");
        CHECK_NEAR(c->yfov, 0.8, 1e-12, "yfov");
        CHECK_NEAR(c->aspect, 1.5, 1e-12, "aspectRatio");
    }

    /* KHR_lights_punctual */
    CHECK(s->n_lights == 3, "n_lights %d", s->n_lights);
    if (s->n_lights == 3) {
        const struct dr_punctual *p = &s->lights[0], *sp = &s->lights[1], *d = &s->lights[2];
        CHECK(p->type == DR_LIGHT_POINT && strcmp(p->name, "bulb") == 0 && p->gltf_index == 0, "point light");
        check_vec(p->color, 1, 0.5, 0.25, 1e-12, "point colour");
        CHECK_NEAR(p->intensity, 10, 1e-12, "point intensity");
        /* no DR_units: glTF's photometric candela, rendered as W/sr after / 683 lm/W */
        CHECK(s->light_units == DR_LIGHT_UNITS_PHOTOMETRIC, "photometric by default");
        CHECK_NEAR(dr_punctual_radiant(p), 10.0 / 683.0, 1e-15, "point radiant intensity");
        CHECK_NEAR(p->range, 5, 1e-12, "point range");
        check_vec(p->position, 1, 2, 3, 1e-12, "point position");
        CHECK(sp->type == DR_LIGHT_SPOT && strcmp(sp->name, "spot_node") == 0 && sp->gltf_index == 1,
              "spot light named after its node: %s", sp->name);
        check_vec(sp->color, 1, 1, 1, 0, "spot default colour");
        CHECK_NEAR(sp->intensity, 20, 1e-12, "spot intensity");
        CHECK(sp->range == 0.0, "no range: 0");
        check_vec(sp->position, 0, 5, 0, 1e-12, "spot position");
        check_vec(sp->direction, 0, -1, 0, 1e-9, "spot points down (R_x(-90) applied to -z)");
        CHECK_NEAR(sp->cos_inner, cos(0.2), 1e-12, "cos inner");
        CHECK_NEAR(sp->cos_outer, cos(0.5), 1e-12, "cos outer");
        CHECK(d->type == DR_LIGHT_DIRECTIONAL && strcmp(d->name, "sun") == 0 && d->gltf_index == 2,
              "directional light");
        CHECK_NEAR(d->intensity, 1, 0, "default intensity");
        check_vec(d->direction, 0, 0, -1, 1e-12, "directional light travels along -z");
    }

    /* DR_environment, constant */
    CHECK(s->env.present, "environment present");
    check_vec(s->env.color, 0.1, 0.2, 0.3, 1e-12, "environment colour");
    CHECK_NEAR(s->env.strength, 2, 0, "environment strength");
    CHECK(s->env.map.data == NULL && s->env.uri[0] == '\0', "constant environment has no map");

    /* warnings: the unsupported extension once; orthographic cameras are supported now */
    CHECK(count_substr(warnings, "KHR_materials_iridescence") == 1, "iridescence warned once:\n%s", warnings);
    CHECK(count_substr(warnings, "KHR_materials_clearcoat") == 0, "clearcoat is supported:\n%s", warnings);
    CHECK(count_substr(warnings, "orthographic") == 0, "no orthographic camera warning:\n%s", warnings);
    CHECK(strncmp(warnings, data_path(name), strlen(data_path(name))) == 0, "warnings name the file:\n%s",
          warnings);
    fprintf(stderr, "%s", warnings);
    free_scene(s);
}

/* ---- byteStride, normalized UVs, uint8/uint32 indices, strip, fan ---- */

static void test_layout(void)
{
    int rc;
    struct dr_scene *s = load("layout.gltf", &rc);
    CHECK(rc == 0, "layout.gltf: %s", dr_last_error());
    const struct dr_mesh *m = &s->mesh;
    /* strip (2) + fan (2) + child triangle (1); the child is not visited twice
     * although the file has no "scenes" (only parentless nodes are roots) */
    CHECK(m->n_vertices == 11 && m->n_triangles == 5, "%u vertices, %u triangles", m->n_vertices,
          m->n_triangles);
    if (rc == 0 && m->n_vertices == 11 && m->n_triangles == 5) {
        check_vec(vertex(s, 1), 1, 0, 0, 1e-6, "interleaved v1");
        check_vec(vertex(s, 3), 1, 2, 0, 1e-6, "interleaved v3 under scale(1,2,1)");
        CHECK_NEAR(m->uvs[2], 1.0, 1e-7, "normalized u of v1");
        CHECK_NEAR(m->uvs[5], 32768 / 65535.0, 1e-7, "normalized v of v2");
        CHECK_NEAR(m->uvs[7], 1.0, 1e-7, "normalized v of v3");
        /* (1,1,0)/sqrt2 through the inverse transpose of diag(1,2,1) */
        check_vec(normal_at(s, 0), 2 / sqrt(5), 1 / sqrt(5), 0, 1e-6, "normal under non-uniform scale");
        check_tri(s, 0, 0, 1, 2);  /* strip: odd triangles swap their first two */
        check_tri(s, 1, 2, 1, 3);
        check_tri(s, 2, 4, 5, 6);  /* fan */
        check_tri(s, 3, 4, 6, 7);
        check_tri(s, 4, 8, 9, 10);
        CHECK(m->flags[0] == (DR_TRI_HAS_NORMALS | DR_TRI_HAS_UVS), "strip flags %d", m->flags[0]);
        CHECK(m->flags[2] == 0 && m->flags[4] == 0, "fan / TEXCOORD_1-only flags %d %d", m->flags[2],
              m->flags[4]);
        check_vec(vertex(s, 10), 10, 0, 1, 1e-6, "child node: parent scale * child translation");
    }
    CHECK(s->n_materials == 1, "no default material appended when unused: %d", s->n_materials);
    if (s->n_materials == 1) {
        CHECK(strcmp(s->materials[0].name, "material_0") == 0, "unnamed material: %s", s->materials[0].name);
        CHECK(s->materials[0].emissive_tex.texture == 0 && s->materials[0].emissive_tex.texcoord == 1,
              "texCoord 1 texture used");
    }
    /* TEXCOORD_1 is loaded because a texture reads it: zero where a primitive has none */
    CHECK(m->uvs1 != NULL, "TEXCOORD_1 loaded");
    if (m->uvs1 && m->n_vertices == 11) {
        static const float want[6] = {0, 0, 1, 0, 0, 1};
        int bad = 0;
        for (int i = 0; i < 6; i++) bad += m->uvs1[16 + i] != want[i];
        for (int i = 0; i < 16; i++) bad += m->uvs1[i] != 0.0f;
        CHECK(bad == 0, "%d TEXCOORD_1 values differ", bad);
    }
    CHECK(m->colors == NULL, "no COLOR_0: no colour array");
    CHECK(s->n_images == 1 && dr_image_has_linear(&s->images[0]), "the emissive texture is sRGB-decoded");
    CHECK(s->n_cameras == 0 && s->n_lights == 0 && !s->env.present, "no cameras, lights, environment");
    CHECK(strstr(warnings, "EXT_made_up") && strstr(warnings, "required"), "required extension:\n%s", warnings);
    CHECK(!strstr(warnings, "texCoord"), "no TEXCOORD_1 warning:\n%s", warnings);
    CHECK(!strstr(warnings, "BLEND"), "alphaMode BLEND is supported, no warning:\n%s", warnings);
    CHECK(s->n_materials >= 1 && s->materials[0].alpha_mode == DR_ALPHA_BLEND && s->materials[0].alpha == 1.0,
          "alphaMode BLEND loaded (alpha 1 without baseColorFactor)");
    fprintf(stderr, "-- layout.gltf\n%s", warnings);
    free_scene(s);
}

static void test_env_map(void)
{
    int rc;
    struct dr_scene *s = load("env_map.gltf", &rc);
    CHECK(rc == 0, "env_map.gltf: %s", dr_last_error());
    CHECK(s->env.present, "environment present");
    check_vec(s->env.color, 1, 1, 1, 0, "default colour");
    CHECK_NEAR(s->env.strength, 0.5, 0, "strength");
    CHECK(strcmp(s->env.uri, "sky.hdr") == 0, "uri %s", s->env.uri);
    const struct dr_image *im = &s->env.map;
    CHECK(im->data && im->width == 4 && im->height == 2 && im->channels >= 3, "sky %dx%dx%d", im->width,
          im->height, im->channels);
    if (im->data && im->width == 4 && im->height == 2 && im->channels >= 3) {
        int bad = 0;
        for (int y = 0; y < 2; y++)
            for (int x = 0; x < 4; x++) {
                const float *p = im->data + (size_t)(y * 4 + x) * (size_t)im->channels;
                bad += fabs(p[0] - (x + 1) / 4.0) > 0.01 || fabs(p[1] - (y + 1) / 2.0) > 0.01 ||
                       fabs(p[2] - 1.0) > 0.01;
            }
        CHECK(bad == 0, "%d sky texels differ", bad);
    }
    CHECK(s->mesh.n_triangles == 0 && s->mesh.n_vertices == 0, "no geometry");
    free_scene(s);
}

/* ---- bad inputs: the right code, the file name and the JSON path ---- */

static void check_error(const char *name, int want_rc, const char *want1, const char *want2)
{
    int rc;
    struct dr_scene *s = load(name, &rc);
    const char *msg = dr_last_error();
    const char *path = data_path(name);
    CHECK(rc == want_rc, "%s: rc %d, want %d (%s)", name, rc, want_rc, msg);
    CHECK(strncmp(msg, path, strlen(path)) == 0, "%s: message starts with the file: %s", name, msg);
    CHECK(strstr(msg, want1) != NULL, "%s: message lacks '%s': %s", name, want1, msg);
    if (want2) CHECK(strstr(msg, want2) != NULL, "%s: message lacks '%s': %s", name, want2, msg);
    fprintf(stderr, "   %s -> %s\n", name, msg);
    free_scene(s);  /* partial allocations must be freeable */
}

static void test_errors(void)
{
    check_error("does_not_exist.gltf", DR_ERR_IO, "cannot open", "No such file");
    check_error("bad_json.gltf", DR_ERR_FORMAT, "bad_json.gltf", NULL);
    check_error("accessor_range.gltf", DR_ERR_FORMAT,
                "/accessors/0: byte range 0..48 exceeds bufferView 0 (length 36)", NULL);
    check_error("missing_bin.gltf", DR_ERR_IO, "/buffers/1/uri: cannot read", "nothere.bin");
    check_error("points.gltf", DR_ERR_FORMAT, "/meshes/1/primitives/0/mode: points are not supported", NULL);
    check_error("tex_nosource.gltf", DR_ERR_FORMAT, "/textures/0", "source");
    check_error("bad_env.gltf", DR_ERR_IO, "/extensions/DR_environment/uri", "nosky.hdr");
}

/* An image that is both a colour texture and data (here the checker as base
 * colour and as metallic-roughness) keeps the file's values beside its
 * sRGB-decoded copy: in-place decoding is only for colour-only images. */
static void test_shared_image(void)
{
    struct dr_scene *s = dr_scene_load(data_path("shared_image.gltf"));
    CHECK(s != NULL, "shared_image.gltf: %s", dr_last_error());
    if (!s)
        return;
    const struct dr_image *c = &s->images[0];
    CHECK(dr_image_has_linear(c) && !c->linear_in_data, "image used as colour and data: both views");
    if (dr_image_has_linear(c) && c->width == 4 && c->channels == 3) {
        /* texel (1, 0): the file's 64/255 as stored, its decode as colour */
        CHECK_NEAR(dr_image_value(c, 3, false), 64 / 255.0, 1e-6, "data keeps the file's value");
        CHECK_NEAR(dr_image_value(c, 3, true), srgb_decode(64 / 255.0), 1e-5, "linear is decoded");
    }
    dr_scene_destroy(s);
}

/* Two loads' images agree value for value, as stored and as colour. */
static int image_differences(const struct dr_scene *a, const struct dr_scene *b)
{
    if (a->n_images != b->n_images)
        return -1;
    int bad = 0;
    for (int k = 0; k < a->n_images; k++) {
        const struct dr_image *x = &a->images[k], *y = &b->images[k];
        if (x->width != y->width || x->height != y->height || x->channels != y->channels ||
            dr_image_has_linear(x) != dr_image_has_linear(y) || x->linear_in_data != y->linear_in_data ||
            !dr_image_has_pixels(x) || !dr_image_has_pixels(y)) {
            bad++;
            continue;
        }
        const size_t n = (size_t)x->width * (size_t)x->height * (size_t)x->channels;
        for (size_t i = 0; i < n; i++)
            bad += dr_image_value(x, i, false) != dr_image_value(y, i, false) ||
                   dr_image_value(x, i, true) != dr_image_value(y, i, true);
    }
    return bad;
}

/* dr_scene_load decodes a scene's images on a thread of their own while the
 * loader and dr_scene_prepare make the geometry and the ray structure
 * (scene.h's pending_images): the same images and effects as the loader's
 * own decode; the decode is pending after the load and joined by the
 * preparation; a scene destroyed before that releases it. */
static void test_deferred_images(void)
{
    const char *names[] = {"basic.gltf", "basic.glb", "shared_image.gltf"};
    for (size_t f = 0; f < sizeof names / sizeof *names; f++) {
        struct dr_scene *a = dr_scene_load(data_path(names[f]));
        struct dr_scene *b = calloc(1, sizeof *b);
        b->path = strdup(data_path(names[f]));
        const int rb = dr_gltf_load(data_path(names[f]), b);
        CHECK(a && rb == 0 && dr_scene_prepare(b) == 0, "%s: both loads: %s", names[f], dr_last_error());
        if (a && rb == 0) {
            CHECK(a->n_images > 0 && image_differences(a, b) == 0, "%s: %d of %d images' values differ between "
                  "the deferred and the loader's own decode", names[f], image_differences(a, b), a->n_images);
            CHECK(a->effects == b->effects && !a->pending_images, "%s: effects %#x against %#x", names[f],
                  a->effects, b->effects);
        }
        dr_scene_destroy(a);
        dr_scene_destroy(b);
    }
    struct dr_scene *s = calloc(1, sizeof *s);
    s->path = strdup(data_path("basic.gltf"));
    int rc = dr_gltf_load_deferred(data_path("basic.gltf"), NULL, s);
    CHECK(rc == 0 && s->pending_images && s->n_images > 0 && !dr_image_has_pixels(&s->images[0]),
          "basic.gltf: the deferred load returns with its image pending (rc %d)", rc);
    CHECK(dr_scene_prepare(s) == 0 && !s->pending_images && dr_image_has_pixels(&s->images[0]),
          "basic.gltf: the preparation joins it: %s", dr_last_error());
    dr_scene_destroy(s);
    s = calloc(1, sizeof *s);
    s->path = strdup(data_path("basic.gltf"));
    rc = dr_gltf_load_deferred(data_path("basic.gltf"), NULL, s);
    CHECK(rc == 0 && s->pending_images, "basic.gltf: pending before the destroy (rc %d)", rc);
    dr_scene_destroy(s);   /* (joins and releases: the sanitizers' leak check) */
}

int main(void)
{
    dr_set_warn_handler(record_warning);
    check_basic("basic.gltf");
    check_basic("basic_embedded.gltf");
    check_basic("basic.glb");
    test_layout();
    test_env_map();
    test_shared_image();
    test_deferred_images();
    test_errors();
    return TEST_END();
}
