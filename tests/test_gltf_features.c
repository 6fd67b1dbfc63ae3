/* glTF features of real users' files (issue 13) in the loader and the
 * lookups built on it: COLOR_0 (float, normalized byte and short; absent ->
 * no array), TEXCOORD_1 (loaded only when a texture reads it),
 * KHR_texture_transform, sparse accessors (and every way their indices and
 * byte ranges can be wrong), orthographic cameras and their rays, KTX2
 * images (refused, or skipped under ignore_unsupported), and Draco (the
 * shared Box sample decodes to the plain Box's triangles).
 *
 * Scenes are written into a temporary directory as .gltf with base64
 * buffers; the expected numbers follow from the bytes written here. */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "anisotropy.h"
#include "camera.h"
#include "error.h"
#include "geometry.h"
#include "image_io.h"
#include "material.h"
#include "params.h"
#include "render.h"
#include "scene.h"
#include "test.h"

static char dir[256];
static char warnings[16384];

static void record_warning(const char *msg)
{
    size_t n = strlen(warnings);
    snprintf(warnings + n, sizeof warnings - n, "%s\n", msg);
}

static const char *tmp_path(const char *name)
{
    static char buf[2][512];
    static int k;
    k ^= 1;
    snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
    return buf[k];
}

static void write_file(const char *name, const void *data, size_t n)
{
    FILE *f = fopen(tmp_path(name), "wb");
    CHECK(f != NULL, "cannot write %s", name);
    if (!f) return;
    fwrite(data, 1, n, f);
    fclose(f);
}

/* name's contents, or NULL (size in *n) */
static unsigned char *read_file(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc((size_t)len + 1);
    *n = fread(b, 1, (size_t)len, f);
    fclose(f);
    return b;
}

/* "data:application/octet-stream;base64,..." of bytes (static buffer) */
static const char *data_uri(const void *bytes, size_t n)
{
    static char out[8192];
    static const char tbl[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const unsigned char *b = bytes;
    size_t o = (size_t)snprintf(out, sizeof out, "data:application/octet-stream;base64,");
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)b[i] << 16 | (i + 1 < n ? (uint32_t)b[i + 1] << 8 : 0) | (i + 2 < n ? b[i + 2] : 0);
        out[o++] = tbl[v >> 18 & 63];
        out[o++] = tbl[v >> 12 & 63];
        out[o++] = i + 1 < n ? tbl[v >> 6 & 63] : '=';
        out[o++] = i + 2 < n ? tbl[v & 63] : '=';
    }
    out[o] = '\0';
    return out;
}

/* Writes name with the printf-formatted JSON, loads it (opts may be NULL):
 * the scene (release with dr_scene_destroy) and the return code. */
static struct dr_scene *load_json(const char *name, const struct dr_load_opts *opts, int *rc, const char *fmt, ...)
{
    static char json[65536];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(json, sizeof json, fmt, ap);
    va_end(ap);
    write_file(name, json, strlen(json));
    warnings[0] = '\0';
    struct dr_scene *s = calloc(1, sizeof *s);
    s->path = strdup(tmp_path(name));
    *rc = dr_gltf_load_opts(tmp_path(name), opts, s);
    return s;
}

/* The load failed with an error naming the file and every needle. */
static void check_error(int rc, const char *what, const char *file, const char *n1, const char *n2)
{
    const char *e = dr_last_error();
    CHECK(rc == DR_ERR_FORMAT, "%s: rc %d (%s)", what, rc, e);
    CHECK(strstr(e, file) != NULL, "%s: the message names the file: %s", what, e);
    CHECK(strstr(e, n1) != NULL, "%s: the message names '%s': %s", what, n1, e);
    CHECK(!n2 || strstr(e, n2) != NULL, "%s: the message names '%s': %s", what, n2 ? n2 : "", e);
    printf("  %-28s -> %s\n", what, e);
}

static void put_f32(unsigned char *b, size_t *o, int n, ...)
{
    va_list ap;
    va_start(ap, n);
    for (int i = 0; i < n; i++) {
        float f = (float)va_arg(ap, double);
        memcpy(b + *o, &f, 4);
        *o += 4;
    }
    va_end(ap);
}

/* ---- COLOR_0 ---- */

static void test_colors(void)
{
    /* 0..35: 3 positions; 36..47: rgba ubyte (3 x 4); 48..65: rgb ushort (3 x 6) */
    unsigned char b[72] = {0};
    size_t o = 0;
    put_f32(b, &o, 9, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    const unsigned char rgba[12] = {255, 0, 0, 255, 0, 128, 0, 255, 0, 0, 255, 0};
    memcpy(b + 36, rgba, 12);
    const uint16_t rgb16[9] = {65535, 0, 32768, 0, 65535, 0, 13107, 13107, 13107};
    memcpy(b + 48, rgb16, 18);
    int rc;
    struct dr_scene *s = load_json("colors.gltf", NULL, &rc,
        "{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}},"
        "{\"attributes\":{\"POSITION\":0,\"COLOR_0\":1}},{\"attributes\":{\"POSITION\":0,\"COLOR_0\":2}}]}],"
        "\"buffers\":[{\"byteLength\":66,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":12},"
        "{\"buffer\":0,\"byteOffset\":48,\"byteLength\":18}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":1,\"componentType\":5121,\"normalized\":true,\"count\":3,\"type\":\"VEC4\"},"
        "{\"bufferView\":2,\"componentType\":5123,\"normalized\":true,\"count\":3,\"type\":\"VEC3\"}]}",
        data_uri(b, 66));
    CHECK(rc == 0, "colors.gltf: %s", dr_last_error());
    const struct dr_mesh *m = &s->mesh;
    CHECK(m->colors != NULL && m->n_vertices == 9, "colours loaded (%p), %u vertices", (void *)m->colors,
          m->n_vertices);
    if (rc == 0 && m->colors && m->n_vertices == 9) {
        /* primitive 0 has none: white; 1: ubyte/255 (alpha dropped); 2: ushort/65535 */
        const double want[27] = {1, 1, 1, 1, 1, 1, 1, 1, 1,
                                 1, 0, 0, 0, 128 / 255.0, 0, 0, 0, 1,
                                 1, 0, 32768 / 65535.0, 0, 1, 0, 0.2, 0.2, 0.2};
        double worst = 0;
        for (int i = 0; i < 27; i++) worst = fmax(worst, fabs(m->colors[i] - want[i]));
        CHECK(worst < 1e-6, "COLOR_0 values differ by %g", worst);
        /* dr_hit_color interpolates them at the barycentrics */
        struct dr_hit h = {0};
        h.tri = 1;
        h.b1 = 0.25;
        h.b2 = 0.5;
        dr_vec3 c = dr_hit_color(m, &h);
        CHECK(fabs(c.x - 0.25) < 1e-6 && fabs(c.y - 0.25 * 128 / 255.0) < 1e-6 && fabs(c.z - 0.5) < 1e-6,
              "interpolated colour (%g, %g, %g)", c.x, c.y, c.z);
    }
    dr_scene_destroy(s);

    /* integer colours must be normalized */
    s = load_json("colors_raw.gltf", NULL, &rc,
        "{\"asset\":{\"version\":\"2.0\"},\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"COLOR_0\":1}}]}],"
        "\"buffers\":[{\"byteLength\":66,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":12}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":1,\"componentType\":5121,\"count\":3,\"type\":\"VEC4\"}]}",
        data_uri(b, 66));
    check_error(rc, "COLOR_0 not normalized", "colors_raw.gltf", "/accessors/1", "COLOR_0");
    dr_scene_destroy(s);
}

/* ---- sparse accessors ---- */

/* A triangle mesh whose POSITION is accessor 0 = "accessor", with a buffer of
 * 4 base positions (0..47), sparse indices u16 {1, 3} (48..51) and values
 * (52..75); extra_views appended to the three views. */
static struct dr_scene *sparse_scene(const char *name, int *rc, const char *accessor)
{
    unsigned char b[76] = {0};
    size_t o = 0;
    put_f32(b, &o, 12, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0);
    const uint16_t ix[2] = {1, 3};
    memcpy(b + 48, ix, 4);
    o = 52;
    put_f32(b, &o, 6, 5.0, 0.0, 0.0, 5.0, 6.0, 7.0);
    return load_json(name, NULL, rc,
        "{\"asset\":{\"version\":\"2.0\"},\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"mode\":5}]}],"
        "\"buffers\":[{\"byteLength\":76,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":4},"
        "{\"buffer\":0,\"byteOffset\":52,\"byteLength\":24}],"
        "\"accessors\":[%s]}",
        data_uri(b, 76), accessor);
}

#define SPARSE(count, ixview, ixoff, ixtype, valview, valoff)                                               \
    "{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"sparse\":{\"count\":" #count \
    ",\"indices\":{\"bufferView\":" #ixview ",\"byteOffset\":" #ixoff ",\"componentType\":" #ixtype "},"   \
    "\"values\":{\"bufferView\":" #valview ",\"byteOffset\":" #valoff "}}}"

static void test_sparse(void)
{
    int rc;
    struct dr_scene *s = sparse_scene("sparse.gltf", &rc, SPARSE(2, 1, 0, 5123, 2, 0));
    CHECK(rc == 0, "sparse.gltf: %s", dr_last_error());
    if (rc == 0 && s->mesh.n_vertices == 4) {
        const float want[12] = {0, 0, 0, 5, 0, 0, 0, 1, 0, 5, 6, 7};   /* elements 1 and 3 replaced */
        int bad = 0;
        for (int i = 0; i < 12; i++) bad += s->mesh.positions[i] != want[i];
        CHECK(bad == 0, "%d sparse-substituted coordinates differ", bad);
    } else {
        CHECK(0, "sparse.gltf has %u vertices", s->mesh.n_vertices);
    }
    dr_scene_destroy(s);

    /* no bufferView: zeros, then the substitution */
    s = sparse_scene("sparse_zero.gltf", &rc,
                     "{\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"sparse\":{\"count\":2,"
                     "\"indices\":{\"bufferView\":1,\"componentType\":5123},\"values\":{\"bufferView\":2}}}");
    CHECK(rc == 0, "sparse_zero.gltf: %s", dr_last_error());
    if (rc == 0 && s->mesh.n_vertices == 4) {
        const float want[12] = {0, 0, 0, 5, 0, 0, 0, 0, 0, 5, 6, 7};
        int bad = 0;
        for (int i = 0; i < 12; i++) bad += s->mesh.positions[i] != want[i];
        CHECK(bad == 0, "%d coordinates of a sparse accessor without bufferView differ", bad);
    }
    dr_scene_destroy(s);

    /* every way the substitution can point outside what the file holds */
    struct { const char *name, *acc, *n1, *n2; } bad[] = {
        {"sp_range.gltf", SPARSE(2, 2, 0, 5123, 2, 0), "/accessors/0/sparse/indices", "out of range"},   /* 5.0f bits */
        {"sp_count.gltf", SPARSE(5, 1, 0, 5123, 2, 0), "/accessors/0/sparse/count", "5"},
        {"sp_zero.gltf", SPARSE(0, 1, 0, 5123, 2, 0), "/accessors/0/sparse/count", "0"},
        {"sp_ixview.gltf", SPARSE(2, 9, 0, 5123, 2, 0), "/accessors/0/sparse/indices/bufferView", "9"},
        {"sp_ixlen.gltf", SPARSE(2, 1, 2, 5123, 2, 0), "/accessors/0/sparse/indices", "exceeds bufferView 1"},
        {"sp_ixtype.gltf", SPARSE(2, 1, 0, 5126, 2, 0), "/accessors/0/sparse/indices/componentType", "5126"},
        {"sp_neg.gltf", SPARSE(2, 1, -4, 5123, 2, 0), "/accessors/0/sparse/indices/byteOffset", "-4"},
        {"sp_vallen.gltf", SPARSE(2, 1, 0, 5123, 2, 4), "/accessors/0/sparse/values", "exceeds bufferView 2"},
        {"sp_valview.gltf", SPARSE(2, 1, 0, 5123, -1, 0), "/accessors/0/sparse/values/bufferView", "-1"},
        {"sp_order.gltf", SPARSE(2, 1, 0, 5121, 2, 0), "/accessors/0/sparse/indices", "strictly"},   /* u8 1, 0 */
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        s = sparse_scene(bad[i].name, &rc, bad[i].acc);
        check_error(rc, bad[i].name, bad[i].name, bad[i].n1, bad[i].n2);
        dr_scene_destroy(s);
    }
}

/* ---- TEXCOORD_1 and KHR_texture_transform ---- */

static void test_texcoords(void)
{
    size_t n = 0;
    const char *td = getenv("DR_TESTDIR");
    char src[512];
    snprintf(src, sizeof src, "%s/data/gltf/checker.png", td && *td ? td : "tests");
    unsigned char *png = read_file(src, &n);
    CHECK(png != NULL, "cannot read %s", src);
    if (!png) return;
    write_file("checker.png", png, n);
    free(png);
    /* positions (0..35), TEXCOORD_0 (36..59), TEXCOORD_1 (60..83) */
    unsigned char b[84];
    size_t o = 0;
    put_f32(b, &o, 9, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    put_f32(b, &o, 6, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0);
    put_f32(b, &o, 6, 0.25, 0.5, 0.75, 0.5, 0.25, 1.0);
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_texture_transform\"],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1,\"TEXCOORD_1\":2},"
        "\"material\":0}]}],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0,\"extensions\":"
        "{\"KHR_texture_transform\":{\"offset\":[0.5,0.25],\"rotation\":1.5707963267948966,\"scale\":[2,3],"
        "\"texCoord\":1}}},\"metallicRoughnessTexture\":{\"index\":0%s}},"
        "\"emissiveTexture\":{\"index\":0,\"texCoord\":2}}],"
        "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"checker.png\"}],"
        "\"buffers\":[{\"byteLength\":84,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":48}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":1,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
        "{\"bufferView\":1,\"byteOffset\":24,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"}]}";
    int rc;
    struct dr_scene *s = load_json("uv.gltf", NULL, &rc, fmt, "", data_uri(b, 84));
    CHECK(rc == 0, "uv.gltf: %s", dr_last_error());
    if (rc == 0) {
        const struct dr_texref *t = &s->materials[0].base_color_tex;
        /* T(0.5, 0.25) R(90 deg) S(2, 3): [c sx, s sy, ox; -s sx, c sy, oy] */
        const double want[6] = {0, 3, 0.5, -2, 0, 0.25};
        double worst = 0;
        for (int i = 0; i < 6; i++) worst = fmax(worst, fabs(t->xf[i] - want[i]));
        CHECK(t->texture == 0 && t->texcoord == 1 && t->transformed && worst < 1e-12,
              "base colour texref: texture %d, texCoord %d (override), transformed %d, matrix off by %g", t->texture,
              t->texcoord, t->transformed, worst);
        CHECK(!s->materials[0].metallic_roughness_tex.transformed, "no transform on metallicRoughness");
        CHECK(s->materials[0].emissive_tex.texture == -1, "TEXCOORD_2 texture ignored");
        CHECK(strstr(warnings, "TEXCOORD_2") && !strstr(warnings, "KHR_texture_transform"),
              "a TEXCOORD_2 warning and none about the transform:\n%s", warnings);
        CHECK(s->mesh.uvs1 != NULL, "TEXCOORD_1 loaded: a texture reads it");
        if (s->mesh.uvs1) {
            /* at barycentrics (0.5, 0.25): uv1 = 0.25 (0.25, 0.5) + 0.5 (0.75, 0.5) + 0.25 (0.25, 1) */
            struct dr_hit h = {0};
            h.tri = 0;
            h.b1 = 0.5;
            h.b2 = 0.25;
            h.uv[0] = 0.5;   /* TEXCOORD_0 there, which the lookup must not use */
            h.uv[1] = 0.25;
            double uv[2];
            dr_texref_uv(&s->mesh, t, &h, uv);
            double u1 = 0.5, v1 = 0.625;
            CHECK(fabs(uv[0] - (3 * v1 + 0.5)) < 1e-7 && fabs(uv[1] - (-2 * u1 + 0.25)) < 1e-7,
                  "looked-up uv (%g, %g), want (%g, %g)", uv[0], uv[1], 3 * v1 + 0.5, -2 * u1 + 0.25);
        }
    }
    dr_scene_destroy(s);
    /* without a texture on set 1 the second set is not loaded */
    s = load_json("uv0.gltf", NULL, &rc,
                  "{\"asset\":{\"version\":\"2.0\"},\"nodes\":[{\"mesh\":0}],"
                  "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1,\"TEXCOORD_1\":2}}]}],"
                  "\"buffers\":[{\"byteLength\":84,\"uri\":\"%s\"}],"
                  "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":48}],"
                  "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
                  "{\"bufferView\":1,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
                  "{\"bufferView\":1,\"byteOffset\":24,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"}]}",
                  data_uri(b, 84));
    CHECK(rc == 0 && s->mesh.uvs1 == NULL && s->mesh.colors == NULL, "uv0.gltf: rc %d, uvs1 %p, colors %p", rc,
          (void *)s->mesh.uvs1, (void *)s->mesh.colors);
    dr_scene_destroy(s);
    /* a malformed transform names its JSON path */
    s = load_json("uv_bad.gltf", NULL, &rc, fmt,
                  ",\"extensions\":{\"KHR_texture_transform\":{\"scale\":[1]}}", data_uri(b, 84));
    check_error(rc, "bad KHR_texture_transform", "uv_bad.gltf",
                "/materials/0/pbrMetallicRoughness/metallicRoughnessTexture/extensions/KHR_texture_transform/scale",
                NULL);
    dr_scene_destroy(s);
}

/* ---- orthographic cameras ---- */

static void test_ortho(void)
{
    unsigned char b[36];
    size_t o = 0;
    put_f32(b, &o, 9, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"nodes\":[{\"mesh\":0},{\"camera\":1,\"translation\":[0,0,5]},"
        "{\"camera\":0,\"translation\":[0,0,9]}],\"scenes\":[{\"nodes\":[0,1,2]}],"
        "\"cameras\":[{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.5,\"znear\":0.1}},"
        "{\"type\":\"orthographic\",\"orthographic\":{\"xmag\":%s,\"ymag\":1,\"znear\":0.1,\"zfar\":10}},"
        "{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.7,\"znear\":0.1}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}]}";
    int rc;
    struct dr_scene *s = load_json("ortho.gltf", NULL, &rc, fmt, "2", data_uri(b, 36));
    CHECK(rc == 0, "ortho.gltf: %s", dr_last_error());
    CHECK(s->n_cameras == 2 && s->n_unplaced_cameras == 1, "2 cameras placed (%d), 1 unplaced (%d)", s->n_cameras,
          s->n_unplaced_cameras);
    if (rc == 0 && s->n_cameras == 2) {
        const struct dr_camera *c = &s->cameras[0];
        CHECK(c->orthographic && c->gltf_index == 1 && c->ymag == 1.0 && c->aspect == 2.0,
              "camera 0 (node order) is /cameras/1, orthographic %d, ymag %g, aspect %g", c->orthographic, c->ymag,
              c->aspect);
        /* a 200 x 100 film: 4 x 2 units, rays parallel along -z from z = 5 */
        struct dr_camera_view v = dr_camera_view(c, 200, 100);
        dr_vec3 o0, d0, o1, d1;
        dr_camera_ray(&v, 0, 0, &o0, &d0);
        dr_camera_ray(&v, 200, 100, &o1, &d1);
        CHECK(fabs(o0.x + 2) < 1e-12 && fabs(o0.y - 1) < 1e-12 && fabs(o0.z - 5) < 1e-12, "top-left origin (%g %g %g)",
              o0.x, o0.y, o0.z);
        CHECK(fabs(o1.x - 2) < 1e-12 && fabs(o1.y + 1) < 1e-12 && fabs(o1.z - 5) < 1e-12,
              "bottom-right origin (%g %g %g)", o1.x, o1.y, o1.z);
        CHECK(d0.x == 0 && d0.y == 0 && d0.z == -1 && d1.x == 0 && d1.y == 0 && d1.z == -1, "parallel rays along -z");
        /* the perspective camera still has one origin and diverging rays */
        v = dr_camera_view(&s->cameras[1], 200, 100);
        dr_camera_ray(&v, 0, 0, &o0, &d0);
        dr_camera_ray(&v, 200, 100, &o1, &d1);
        CHECK(o0.z == 9 && o1.z == 9 && o0.x == o1.x && d0.x < 0 && d1.x > 0, "perspective rays");
    }
    dr_scene_destroy(s);
    s = load_json("ortho_bad.gltf", NULL, &rc, fmt, "0", data_uri(b, 36));
    check_error(rc, "xmag 0", "ortho_bad.gltf", "/cameras/1/orthographic/xmag", NULL);
    dr_scene_destroy(s);
}

/* ---- KTX2 ---- */

/* exactly one warning line about KTX2, naming /images/0 */
static int count_ktx2_warnings(void)
{
    int n = 0;
    for (const char *p = strstr(warnings, "KTX2"); p; p = strstr(p + 1, "KTX2")) n++;
    return n == 1 && strstr(warnings, "/images/0") != NULL;
}

/* The header of a KTX2 file: 12-byte identifier, then vkFormat, typeSize,
 * width, height, depth, layers, faces, levels, supercompression (from byte
 * 12), then the index; level 0's offset, length and uncompressed length at
 * byte 80. */
static void ktx2_header(unsigned char *b, unsigned vk, unsigned w, unsigned h, unsigned scheme, unsigned level_len)
{
    static const unsigned char magic[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
    memcpy(b, magic, 12);
    const unsigned f[] = {vk, 1, w, h, 0, 0, 1, 1, scheme};
    for (int i = 0; i < 9; i++)
        for (int k = 0; k < 4; k++)
            b[12 + 4 * i + k] = (unsigned char)(f[i] >> (8 * k));
    const unsigned level[3] = {104, level_len, level_len};   /* (64-bit fields, high words 0) */
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 4; k++)
            b[80 + 8 * i + k] = (unsigned char)(level[i] >> (8 * k));
}

static void test_ktx2(void)
{
    /* Basis Universal ETC1S (vkFormat 0, BasisLZ): not decodable */
    unsigned char ktx2[120] = {0};
    ktx2_header(ktx2, 0, 4, 4, 1, 16);
    write_file("tex.ktx2", ktx2, sizeof ktx2);
    unsigned char b[36];
    size_t o = 0;
    put_f32(b, &o, 9, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_texture_basisu\"],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"material\":0}]}],"
        "\"materials\":[{%s}],"
        "\"textures\":[{\"extensions\":{\"KHR_texture_basisu\":{\"source\":0}}}],"
        "\"images\":[{\"uri\":\"tex.ktx2\",\"mimeType\":\"image/ktx2\"}],"
        "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}]}";
    const char *normal = "\"normalTexture\":{\"index\":0},\"occlusionTexture\":{\"index\":0}";
    int rc;
    struct dr_scene *s = load_json("ktx_normal.gltf", NULL, &rc, fmt, normal, data_uri(b, 36));
    check_error(rc, "KTX2 normal map", "ktx_normal.gltf", "Basis Universal ETC1S", "--ignore-unsupported");
    CHECK(strstr(dr_last_error(), "/images/0") != NULL, "names the image: %s", dr_last_error());
    dr_scene_destroy(s);
    struct dr_load_opts skip = {.ignore_unsupported = true};
    s = load_json("ktx_normal.gltf", &skip, &rc, fmt, normal, data_uri(b, 36));
    CHECK(rc == 0, "KTX2 normal map under ignore_unsupported: %s", dr_last_error());
    CHECK(count_ktx2_warnings(), "one KTX2 warning naming /images/0:\n%s", warnings);
    CHECK(s->n_images == 1 && s->images[0].data == NULL, "the KTX2 image stays undecoded");
    dr_scene_destroy(s);
    /* a base colour changes the image: refused even under ignore_unsupported */
    s = load_json("ktx_color.gltf", &skip, &rc, fmt, "\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0}}",
                  data_uri(b, 36));
    check_error(rc, "KTX2 base colour", "ktx_color.gltf", "/materials/0/pbrMetallicRoughness/baseColorTexture",
                "Basis Universal ETC1S");
    dr_scene_destroy(s);
    /* plain 8-bit texels (R8G8B8_SRGB, no supercompression): read (core/ktx2.c; test_ktx2 covers the
     * formats), as the base colour, sRGB-decoded */
    unsigned char rgb[104 + 12];
    memset(rgb, 0, sizeof rgb);
    ktx2_header(rgb, 29, 2, 2, 0, 12);
    const unsigned char texels[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 128, 128, 128};
    memcpy(rgb + 104, texels, 12);
    write_file("tex.ktx2", rgb, sizeof rgb);
    s = load_json("ktx_color.gltf", NULL, &rc, fmt, "\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0}}",
                  data_uri(b, 36));
    CHECK(rc == 0 && s, "an 8-bit KTX2 base colour loads: %s", dr_last_error());
    if (s) {
        const struct dr_image *im = &s->images[0];
        CHECK(im->width == 2 && im->height == 2 && im->channels == 3 && im->file_is_srgb, "2x2 sRGB RGB");
        double px[4];
        const struct dr_texture tex = {.image = 0, .wrap_s = DR_WRAP_CLAMP, .wrap_t = DR_WRAP_CLAMP};
        dr_texture_eval(&tex, im, 0.75, 0.75, dr_image_has_linear(im), px);   /* the grey texel's centre */
        CHECK_NEAR(px[0], dr_srgb_to_linear(128.0 / 255.0), 1e-6, "bottom-right texel, decoded");
        dr_texture_eval(&tex, im, 0.25, 0.25, dr_image_has_linear(im), px);
        CHECK(px[0] > 0.99 && px[1] < 1e-6 && px[2] < 1e-6, "top-left texel red: %g %g %g", px[0], px[1], px[2]);
    }
    dr_scene_destroy(s);
}

/* ---- KHR_materials_anisotropy ---- */

/* A quad facing +z whose u runs along +x and v down +y (so the generated
 * tangent is +x and the bitangent +y), with the material's anisotropy
 * extension `ext`, extra primitive attributes `attrs` and node fields
 * `node`; the anisotropy texture is a 1x1 R8G8B8 KTX2 texel `texel`. Loaded
 * whole (tangents prepared); NULL when it fails (rc, the error kept). */
static struct dr_scene *aniso_scene(const char *ext, const char *attrs, const char *node, const unsigned char texel[3],
                                    int *rc)
{
    unsigned char ktx[104 + 4] = {0};
    ktx2_header(ktx, 23, 1, 1, 0, 3);   /* R8G8B8_UNORM: linear data */
    memcpy(ktx + 104, texel, 3);
    write_file("aniso.ktx2", ktx, sizeof ktx);
    unsigned char b[156];
    size_t o = 0;
    put_f32(b, &o, 12, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0);   /* 0: positions */
    put_f32(b, &o, 8, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0);                          /* 48: uvs */
    for (int v = 0; v < 4; v++)
        put_f32(b, &o, 4, 0.0, 1.0, 0.0, 1.0);                                          /* 80: tangents, +y */
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};                                         /* 144: indices */
    memcpy(b + o, idx, sizeof idx);
    char uri[512];
    snprintf(uri, sizeof uri, "%s", data_uri(b, sizeof b));
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_anisotropy\"],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"metallicFactor\":1,\"roughnessFactor\":0.3},"
        "\"extensions\":{\"KHR_materials_anisotropy\":%s}},{}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0%s},\"indices\":3,\"material\":0}]}],"
        "\"nodes\":[{\"mesh\":0%s}],\"scenes\":[{\"nodes\":[0]}],"
        "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"aniso.ktx2\",\"mimeType\":\"image/ktx2\"}],"
        "\"buffers\":[{\"byteLength\":156,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":156}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"max\":[1,1,0],"
        "\"min\":[-1,0,0]},{\"bufferView\":0,\"byteOffset\":48,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},"
        "{\"bufferView\":0,\"byteOffset\":80,\"componentType\":5126,\"count\":4,\"type\":\"VEC4\"},"
        "{\"bufferView\":0,\"byteOffset\":144,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}";
    struct dr_scene *s = load_json("aniso.gltf", NULL, rc, fmt, ext, attrs, node, uri);
    dr_scene_destroy(s);
    if (*rc != 0)
        return NULL;
    s = dr_scene_load(tmp_path("aniso.gltf"));
    *rc = s ? 0 : -1;
    return s;
}

/* The anisotropy's world direction at the quad's point (x, y), seen from +z
 * (false: none); *strength: the BSDF's anisotropy there. */
static bool aniso_at(const struct dr_scene *s, double x, double y, dr_vec3 *dir, double *strength)
{
    struct dr_hit hit;
    const dr_vec3 o = dr_v3(x, y, 3.0);
    for (int64_t tri = 0; tri < (int64_t)s->mesh.n_triangles; tri++) {
        dr_hit_compute(&s->mesh, tri, o, dr_v3(0.0, 0.0, -1.0), &hit);
        if (hit.b1 >= 0.0 && hit.b2 >= 0.0 && hit.b1 + hit.b2 <= 1.0)
            break;
    }
    struct dr_bsdf b;
    dr_material_eval(s, &hit, &b);
    *strength = b.anisotropy;
    return dr_anisotropy_direction(s, &hit, dir);
}

static void test_anisotropy(void)
{
    const unsigned char grey[3] = {128, 128, 128}, up[3] = {128, 255, 128};
    const struct {
        const char *what, *ext, *attrs, *node;
        const unsigned char *texel;
        dr_vec3 want;       /* the direction, up to its sign */
        double strength;
    } cases[] = {
        {"the tangent", "{\"anisotropyStrength\":0.6}", ",\"TEXCOORD_0\":1", "", grey, {1, 0, 0}, 0.6},
        {"turned a quarter", "{\"anisotropyStrength\":0.6,\"anisotropyRotation\":1.5707963267948966}",
         ",\"TEXCOORD_0\":1", "", grey, {0, 1, 0}, 0.6},
        {"the texel's (0, 1)", "{\"anisotropyStrength\":0.6,\"anisotropyTexture\":{\"index\":0}}",
         ",\"TEXCOORD_0\":1", "", up, {0, 1, 0}, 0.6 * 128.0 / 255.0},
        {"the texel's, turned", "{\"anisotropyStrength\":0.6,\"anisotropyRotation\":1.5707963267948966,"
         "\"anisotropyTexture\":{\"index\":0}}", ",\"TEXCOORD_0\":1", "", up, {1, 0, 0}, 0.6 * 128.0 / 255.0},
        /* an eighth of a turn tells the bitangent's sign: T + B, which a mirror turns into -x + y */
        {"turned an eighth", "{\"anisotropyStrength\":1,\"anisotropyRotation\":0.78539816339744828}",
         ",\"TEXCOORD_0\":1", "", grey, {M_SQRT1_2, M_SQRT1_2, 0}, 1.0},
        {"mirrored, turned an eighth", "{\"anisotropyStrength\":1,\"anisotropyRotation\":0.78539816339744828}",
         ",\"TEXCOORD_0\":1", ",\"scale\":[-1,1,1]", grey, {-M_SQRT1_2, M_SQRT1_2, 0}, 1.0},
        {"TANGENT", "{\"anisotropyStrength\":0.5}", ",\"TEXCOORD_0\":1,\"TANGENT\":2", "", grey, {0, 1, 0}, 0.5},
        {"TANGENT, turned", "{\"anisotropyStrength\":0.5,\"anisotropyRotation\":1.5707963267948966}",
         ",\"TEXCOORD_0\":1,\"TANGENT\":2", "", grey, {1, 0, 0}, 0.5},
        {"TANGENT without UVs", "{\"anisotropyStrength\":0.5}", ",\"TANGENT\":2", "", grey, {1, 0, 0}, 0.5},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc;
        struct dr_scene *s = aniso_scene(cases[i].ext, cases[i].attrs, cases[i].node, cases[i].texel, &rc);
        CHECK(s != NULL, "%s: %s", cases[i].what, dr_last_error());
        if (!s)
            continue;
        CHECK(!strstr(warnings, "KHR_materials_anisotropy"), "%s: no warning about the extension:\n%s", cases[i].what,
              warnings);
        CHECK(s->materials[0].anisotropic && (s->effects & DR_FX_ANISOTROPY) && s->mesh.tangents,
              "%s: anisotropic, the effect named, tangents prepared", cases[i].what);
        dr_vec3 d;
        double strength;
        bool has = aniso_at(s, 0.3, 0.6, &d, &strength);
        const bool uvs = strstr(cases[i].attrs, "TEXCOORD_0") != NULL;
        if (!uvs) {   /* a supplied tangent is applied where the triangle has UVs only (normal_map.h) */
            CHECK(!has, "%s: no direction without UVs", cases[i].what);
        } else {
            CHECK(has && fabs(fabs(dr_dot(d, cases[i].want)) - 1.0) < 1e-4, "%s: direction (%g, %g, %g), want +-(%g, %g, %g)",
                  cases[i].what, d.x, d.y, d.z, cases[i].want.x, cases[i].want.y, cases[i].want.z);
        }
        CHECK(fabs(strength - cases[i].strength) < 1e-7,   /* (the texel in float) */
              "%s: the BSDF's strength %g, want %g", cases[i].what, strength,
              cases[i].strength);
        dr_scene_destroy(s);
    }
    int rc;
    /* neither TANGENT nor UVs: said once, and no direction */
    struct dr_scene *s = aniso_scene("{\"anisotropyStrength\":0.5}", "", "", grey, &rc);
    CHECK(s && strstr(warnings, "neither TANGENT nor TEXCOORD_0"), "a primitive without a frame is warned about:\n%s",
          warnings);
    dr_scene_destroy(s);
    /* strength 0: not anisotropic, nothing of it computed */
    s = aniso_scene("{\"anisotropyStrength\":0,\"anisotropyRotation\":1}", ",\"TEXCOORD_0\":1", "", grey, &rc);
    CHECK(s && !s->materials[0].anisotropic && !(s->effects & DR_FX_ANISOTROPY) && !s->mesh.tangents,
          "strength 0 is not anisotropic (no effect, no tangents)");
    dr_scene_destroy(s);
    /* its strength is a parameter of anisotropic materials only */
    s = aniso_scene("{\"anisotropyStrength\":0.5}", ",\"TEXCOORD_0\":1", "", grey, &rc);
    if (s) {
        struct dr_param p;
        CHECK(dr_param_resolve(s, "/materials/0/extensions/KHR_materials_anisotropy/anisotropyStrength", &p) == 0 &&
                  p.kind == DR_PARAM_ANISOTROPY_STRENGTH,
              "anisotropyStrength is a parameter: %s", dr_last_error());
        CHECK(dr_param_resolve(s, "/materials/1/extensions/KHR_materials_anisotropy/anisotropyStrength", &p) != 0,
              "an isotropic material's anisotropyStrength is not");
    }
    dr_scene_destroy(s);
    const struct { const char *ext, *what, *n1, *n2; } bad[] = {
        {"{\"anisotropyStrength\":1.5}", "strength above 1", "KHR_materials_anisotropy/anisotropyStrength", "[0, 1]"},
        {"{\"anisotropyStrength\":-0.1}", "negative strength", "KHR_materials_anisotropy/anisotropyStrength", "[0, 1]"},
        {"{\"anisotropyStrength\":0.5,\"anisotropyRotation\":\"up\"}", "a rotation not a number",
         "/materials/0/extensions/KHR_materials_anisotropy/anisotropyRotation", "a number"},
        {"{\"anisotropyStrength\":0.5,\"anisotropyTexture\":{\"index\":7}}", "a missing texture",
         "KHR_materials_anisotropy/anisotropyTexture", "does not exist"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        s = aniso_scene(bad[i].ext, ",\"TEXCOORD_0\":1", "", grey, &rc);
        check_error(rc, bad[i].what, "aniso.gltf", bad[i].n1, bad[i].n2);
        dr_scene_destroy(s);
    }
}

/* A unit quad in z = 0 (x in [-1, 1], y in [0, 1]) with uvs, drawn with
 * material 0: its buffer as a data URI (uri: 512 bytes), and the JSON that
 * uses it, QUAD_MESH_JSON (meshes, nodes, scenes) and QUAD_BUFFER_JSON
 * (buffers, views and accessors, closing the document; its %s is the URI). */
static void textured_quad_uri(char uri[512])
{
    unsigned char b[92];
    size_t o = 0;
    put_f32(b, &o, 12, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0);
    put_f32(b, &o, 8, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0);
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
    memcpy(b + o, idx, sizeof idx);
    snprintf(uri, 512, "%s", data_uri(b, sizeof b));
}
#define QUAD_MESH_JSON                                                                                            \
    "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":2,\"material\":0}]}]," \
    "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}],"
#define QUAD_BUFFER_JSON                                                                                          \
    "\"buffers\":[{\"byteLength\":92,\"uri\":\"%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":92}],"        \
    "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"max\":[1,1,0],"      \
    "\"min\":[-1,0,0]},{\"bufferView\":0,\"byteOffset\":48,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"}," \
    "{\"bufferView\":0,\"byteOffset\":80,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}"

/* ---- KHR_materials_specular's textures ---- */

/* A quad whose material's specular factor and colour are scaled by a 1x1
 * RGBA KTX2 specularTexture (A, linear) and an sRGB specularColorTexture
 * (RGB, decoded): the BSDF at a hit carries the products; no warning. */
static void test_specular_textures(void)
{
    unsigned char spec[104 + 4] = {0}, col[104 + 3] = {0};
    ktx2_header(spec, 37, 1, 1, 0, 4);   /* R8G8B8A8_UNORM */
    memcpy(spec + 104, (const unsigned char[]){10, 20, 30, 128}, 4);
    ktx2_header(col, 29, 1, 1, 0, 3);    /* R8G8B8_SRGB */
    memcpy(col + 104, (const unsigned char[]){255, 128, 64}, 3);
    write_file("spec.ktx2", spec, sizeof spec);
    write_file("col.ktx2", col, sizeof col);
    char uri[512];
    textured_quad_uri(uri);
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_specular\"],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"metallicFactor\":0,\"roughnessFactor\":0.4},"
        "\"extensions\":{\"KHR_materials_specular\":{\"specularFactor\":0.8,\"specularColorFactor\":[1,0.5,0.25]%s}}}],"
        QUAD_MESH_JSON
        "\"textures\":[{\"source\":0},{\"source\":1}],"
        "\"images\":[{\"uri\":\"spec.ktx2\",\"mimeType\":\"image/ktx2\"},{\"uri\":\"col.ktx2\",\"mimeType\":\"image/ktx2\"}],"
        QUAD_BUFFER_JSON;
    int rc;
    struct dr_scene *s = load_json("spec.gltf", NULL, &rc, fmt,
                                   ",\"specularTexture\":{\"index\":0},\"specularColorTexture\":{\"index\":1}", uri);
    CHECK(rc == 0, "specular textures: %s", dr_last_error());
    CHECK(!strstr(warnings, "specular"), "no warning about the specular textures:\n%s", warnings);
    dr_scene_destroy(s);
    s = dr_scene_load(tmp_path("spec.gltf"));
    CHECK(s != NULL, "specular textures, whole: %s", dr_last_error());
    if (s) {
        struct dr_hit hit;
        dr_hit_compute(&s->mesh, 0, dr_v3(0.5, 0.2, 3.0), dr_v3(0.0, 0.0, -1.0), &hit);
        struct dr_bsdf bs;
        dr_material_eval(s, &hit, &bs);
        CHECK(fabs(bs.specular - 0.8 * 128.0 / 255.0) < 1e-6, "specular = factor x A: %g", bs.specular);
        const dr_vec3 want = dr_v3(1.0, 0.5 * dr_srgb_to_linear(128.0 / 255.0), 0.25 * dr_srgb_to_linear(64.0 / 255.0));
        CHECK(fabs(bs.specular_color.x - want.x) < 1e-6 && fabs(bs.specular_color.y - want.y) < 1e-6 &&
                  fabs(bs.specular_color.z - want.z) < 1e-6,
              "specular colour = factor x decoded RGB: (%g, %g, %g), want (%g, %g, %g)", bs.specular_color.x,
              bs.specular_color.y, bs.specular_color.z, want.x, want.y, want.z);
        CHECK(s->effects & DR_FX_TEXTURES, "the specular textures count as textures");
    }
    dr_scene_destroy(s);
    s = load_json("spec_bad.gltf", NULL, &rc, fmt, ",\"specularTexture\":{\"index\":5}", uri);
    check_error(rc, "a missing specular texture", "spec_bad.gltf", "KHR_materials_specular/specularTexture",
                "does not exist");
    dr_scene_destroy(s);
}

/* ---- KHR_materials_anisotropy: the frame's adjoint (attached sampling) ---- */

/* F(o, d) = ws . s + wt . t + wa strength at the hit of the ray (o, d) on a
 * triangle whose normals, tangents and uvs vary over it and whose direction
 * texture (bilinear) turns the direction: anisotropy.h's frame and
 * material.h's strength. */
static const dr_vec3 FRAME_WS = {0.3, -0.7, 0.45}, FRAME_WT = {-0.5, 0.2, 0.6};
static const double FRAME_WA = 0.8;
static double frame_objective(const struct dr_scene *s, dr_vec3 o, dr_vec3 d, struct dr_hit *hit, bool *ok)
{
    dr_hit_compute(&s->mesh, 0, o, d, hit);
    const dr_vec3 n = hit->front ? hit->ns : dr_neg(hit->ns);
    dr_frame f;
    struct dr_bsdf b;
    *ok = dr_anisotropy_frame(s, hit, n, &f);
    dr_material_eval(s, hit, &b);
    return dr_dot(FRAME_WS, f.s) + dr_dot(FRAME_WT, f.t) + FRAME_WA * b.anisotropy;
}

static void test_anisotropy_frame_adjoint(void)
{
    unsigned char tex[104 + 16] = {0};
    ktx2_header(tex, 37, 2, 2, 0, 16);   /* R8G8B8A8_UNORM, 2 x 2 */
    memcpy(tex + 104, (const unsigned char[]){250, 140, 200, 255, 90, 230, 60, 255, 180, 30, 255, 255, 20, 160, 120, 255},
           16);
    write_file("aniso_adj.ktx2", tex, sizeof tex);
    unsigned char b[144];
    size_t o = 0;
    put_f32(b, &o, 9, -1.0, -0.5, 0.0, 1.2, -0.4, 0.2, 0.1, 1.3, -0.3);
    put_f32(b, &o, 9, 0.15, 0.0, 1.0, -0.2, 0.1, 1.0, 0.0, -0.25, 1.0);
    put_f32(b, &o, 6, 0.05, 0.1, 0.95, 0.2, 0.35, 0.9);
    put_f32(b, &o, 12, 1.0, 0.1, 0.0, 1.0, 0.9, -0.3, 0.1, 1.0, 1.0, 0.35, -0.1, 1.0);
    char uri[512];
    snprintf(uri, sizeof uri, "%s", data_uri(b, sizeof b));
    int rc;
    struct dr_scene *s = load_json(
        "aniso_adj.gltf", NULL, &rc,
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_anisotropy\"],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"metallicFactor\":1,\"roughnessFactor\":0.3},"
        "\"extensions\":{\"KHR_materials_anisotropy\":{\"anisotropyStrength\":0.7,\"anisotropyRotation\":0.4,"
        "\"anisotropyTexture\":{\"index\":0}}}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1,\"TEXCOORD_0\":2,\"TANGENT\":3},"
        "\"material\":0}]}],\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}],"
        "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"aniso_adj.ktx2\",\"mimeType\":\"image/ktx2\"}],"
        "\"buffers\":[{\"byteLength\":144,\"uri\":\"%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":144}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"max\":[1.2,1.3,0.2],"
        "\"min\":[-1,-0.5,-0.3]},{\"bufferView\":0,\"byteOffset\":36,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":0,\"byteOffset\":72,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
        "{\"bufferView\":0,\"byteOffset\":96,\"componentType\":5126,\"count\":3,\"type\":\"VEC4\"}]}",
        uri);
    CHECK(rc == 0, "the frame's scene: %s", dr_last_error());
    dr_scene_destroy(s);
    s = dr_scene_load(tmp_path("aniso_adj.gltf"));   /* (whole: the triangles' normals and tangents) */
    CHECK(s != NULL, "the frame's scene, whole: %s", dr_last_error());
    if (!s)
        return;
    const dr_vec3 origins[3] = {{0.1, 0.2, 3.0}, {-0.3, 0.1, 2.5}, {0.4, 0.5, -2.0}};
    const dr_vec3 dirs[3] = {{-0.02, 0.03, -1.0}, {0.05, -0.04, -1.0}, {-0.1, 0.0, 1.0}};   /* (the last: the back) */
    double worst = 0.0;
    int tested = 0;
    for (int k = 0; k < 3; k++) {
        struct dr_hit hit;
        bool ok;
        frame_objective(s, origins[k], dirs[k], &hit, &ok);
        CHECK(ok, "ray %d: an anisotropic frame", k);
        if (!ok)
            continue;
        const dr_vec3 n = hit.front ? hit.ns : dr_neg(hit.ns);
        const dr_frame d_f = {FRAME_WS, FRAME_WT, dr_v3s(0.0)};
        dr_vec3 d_n = dr_v3s(0.0), d_o = dr_v3s(0.0), d_d = dr_v3s(0.0);
        struct dr_d_hit attr;
        memset(&attr, 0, sizeof attr);
        CHECK(d_anisotropy_frame(s, &hit, n, &d_f, &d_n, &attr), "ray %d: the frame's adjoint applies", k);
        struct dr_d_bsdf db;
        memset(&db, 0, sizeof db);
        db.anisotropy = FRAME_WA;
        d_material_eval_uv(s, &hit, &db, &attr);
        struct dr_d_hit dh = attr;
        dh.ns = dr_add(hit.front ? d_n : dr_neg(d_n), attr.ns);
        d_hit_compute(&s->mesh, &hit, origins[k], dirs[k], &dh, &d_o, &d_d);
        const double got[6] = {d_o.x, d_o.y, d_o.z, d_d.x, d_d.y, d_d.z};
        for (int c = 0; c < 6; c++) {
            const double h = 1e-6;
            dr_vec3 o1 = origins[k], o2 = origins[k], d1 = dirs[k], d2 = dirs[k];
            double *p1 = c < 3 ? &o1.x : &d1.x, *p2 = c < 3 ? &o2.x : &d2.x;
            p1[c % 3] += h, p2[c % 3] -= h;
            struct dr_hit h1, h2;
            bool ok1, ok2;
            const double fd = (frame_objective(s, o1, d1, &h1, &ok1) - frame_objective(s, o2, d2, &h2, &ok2)) / (2 * h);
            const double err = fabs(fd - got[c]) / (fabs(fd) + 1e-3);
            worst = err > worst ? err : worst;
            tested++;
            CHECK(ok1 && ok2 && err < 1e-5, "ray %d, d/d %s[%d]: adjoint %.9g, central differences %.9g", k,
                  c < 3 ? "o" : "d", c % 3, got[c], fd);
        }
    }
    printf("  the anisotropic frame's adjoint against central differences: %d derivatives, worst relative error %.2g\n",
           tested, worst);
    dr_scene_destroy(s);
}

/* ---- KHR_materials_sheen: factors, textures, parameters, refusals ---- */

static void test_sheen(void)
{
    unsigned char rough[104 + 4] = {0}, col[104 + 3] = {0};
    ktx2_header(rough, 37, 1, 1, 0, 4);   /* R8G8B8A8_UNORM: A is the roughness */
    memcpy(rough + 104, (const unsigned char[]){10, 20, 30, 128}, 4);
    ktx2_header(col, 29, 1, 1, 0, 3);     /* R8G8B8_SRGB */
    memcpy(col + 104, (const unsigned char[]){255, 128, 64}, 3);
    write_file("sheen_r.ktx2", rough, sizeof rough);
    write_file("sheen_c.ktx2", col, sizeof col);
    char uri[512];
    textured_quad_uri(uri);
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_sheen\"],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"metallicFactor\":0,\"roughnessFactor\":0.4},"
        "\"extensions\":{\"KHR_materials_sheen\":{%s}}}],"
        QUAD_MESH_JSON
        "\"textures\":[{\"source\":0},{\"source\":1}],"
        "\"images\":[{\"uri\":\"sheen_c.ktx2\",\"mimeType\":\"image/ktx2\"},{\"uri\":\"sheen_r.ktx2\",\"mimeType\":\"image/ktx2\"}],"
        QUAD_BUFFER_JSON;
    int rc;
    struct dr_scene *s = load_json("sheen.gltf", NULL, &rc, fmt,
                                   "\"sheenColorFactor\":[1,0.5,0.25],\"sheenRoughnessFactor\":0.6,"
                                   "\"sheenColorTexture\":{\"index\":0},\"sheenRoughnessTexture\":{\"index\":1}",
                                   uri);
    CHECK(rc == 0, "sheen: %s", dr_last_error());
    CHECK(!strstr(warnings, "sheen"), "no warning about the sheen:\n%s", warnings);
    dr_scene_destroy(s);
    s = dr_scene_load(tmp_path("sheen.gltf"));
    CHECK(s != NULL, "sheen, whole: %s", dr_last_error());
    if (s) {
        CHECK(s->materials[0].sheened, "a coloured sheen is there");
        CHECK((s->effects & DR_FX_SHEEN) && (s->effects & DR_FX_TEXTURES), "effects sheen and textures: %x",
              s->effects);
        struct dr_hit hit;
        dr_hit_compute(&s->mesh, 0, dr_v3(0.5, 0.2, 3.0), dr_v3(0.0, 0.0, -1.0), &hit);
        struct dr_bsdf bs;
        dr_material_eval(s, &hit, &bs);
        CHECK(bs.sheened, "the BSDF has the sheen");
        CHECK(fabs(bs.sheen_roughness - 0.6 * 128.0 / 255.0) < 1e-6, "sheen roughness = factor x A: %g",
              bs.sheen_roughness);
        const dr_vec3 want = dr_v3(1.0, 0.5 * dr_srgb_to_linear(128.0 / 255.0), 0.25 * dr_srgb_to_linear(64.0 / 255.0));
        CHECK(fabs(bs.sheen_color.x - want.x) < 1e-6 && fabs(bs.sheen_color.y - want.y) < 1e-6 &&
                  fabs(bs.sheen_color.z - want.z) < 1e-6,
              "sheen colour = factor x decoded RGB: (%g, %g, %g), want (%g, %g, %g)", bs.sheen_color.x,
              bs.sheen_color.y, bs.sheen_color.z, want.x, want.y, want.z);
        struct dr_param *list;
        int n;
        CHECK(dr_params_list(s, &list, &n) == 0, "params: %s", dr_last_error());
        int colour = -1, rough_p = -1;
        for (int i = 0; i < n; i++) {
            if (strcmp(list[i].name, "/materials/0/extensions/KHR_materials_sheen/sheenColorFactor") == 0)
                colour = i;
            if (strcmp(list[i].name, "/materials/0/extensions/KHR_materials_sheen/sheenRoughnessFactor") == 0)
                rough_p = i;
        }
        CHECK(colour >= 0 && list[colour].size == 3 && list[colour].kind == DR_PARAM_SHEEN_COLOR,
              "sheenColorFactor is a colour parameter");
        CHECK(rough_p >= 0 && list[rough_p].size == 1 && list[rough_p].kind == DR_PARAM_SHEEN_ROUGHNESS,
              "sheenRoughnessFactor is a parameter");
        free(list);
    }
    dr_scene_destroy(s);
    /* glTF's default colour, black, is no sheen: nothing of it is read or listed */
    s = load_json("sheen_black.gltf", NULL, &rc, fmt, "\"sheenRoughnessFactor\":0.6,\"sheenColorTexture\":{\"index\":0}",
                  uri);
    CHECK(rc == 0 && s && !s->materials[0].sheened && !(s->effects & (DR_FX_SHEEN | DR_FX_TEXTURES)),
          "a black sheen is none (rc %d)", rc);
    if (s) {
        struct dr_param *list;
        int n;
        CHECK(dr_params_list(s, &list, &n) == 0, "params: %s", dr_last_error());
        for (int i = 0; i < n; i++)
            CHECK(!strstr(list[i].name, "sheen"), "no sheen parameter without a sheen: %s", list[i].name);
        free(list);
    }
    dr_scene_destroy(s);
    static const struct { const char *ext, *what, *where, *says; } bad[] = {
        {"\"sheenColorFactor\":[1,1.5,0]", "a sheen colour above 1", "KHR_materials_sheen/sheenColorFactor/1",
         "[0, 1]"},
        {"\"sheenColorFactor\":[1,1,1],\"sheenRoughnessFactor\":-0.1", "a negative sheen roughness",
         "KHR_materials_sheen/sheenRoughnessFactor", "[0, 1]"},
        {"\"sheenColorFactor\":[1,1,1],\"sheenRoughnessTexture\":{\"index\":5}", "a missing sheen texture",
         "KHR_materials_sheen/sheenRoughnessTexture", "does not exist"},
        {"\"sheenColorFactor\":[1,1]", "a sheen colour of two numbers", "KHR_materials_sheen/sheenColorFactor", ""},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        s = load_json("sheen_bad.gltf", NULL, &rc, fmt, bad[i].ext, uri);
        check_error(rc, bad[i].what, "sheen_bad.gltf", bad[i].where, bad[i].says);
        dr_scene_destroy(s);
    }
}

/* ---- Draco: the shared sample against the plain Box ---- */

static int cmp_tri(const void *a, const void *b)
{
    const float *x = a, *y = b;
    for (int i = 0; i < 9; i++)
        if (x[i] != y[i]) return x[i] < y[i] ? -1 : 1;
    return 0;
}

/* The triangles as sorted 9-float records, each starting at its smallest
 * vertex (so an index permutation that keeps the winding compares equal),
 * positions rounded to 1e-4 (Draco quantises them). */
static float *triangles(const struct dr_scene *s)
{
    uint32_t n = s->mesh.n_triangles;
    float *t = malloc(sizeof(float) * 9 * (n ? n : 1));
    for (uint32_t i = 0; i < n; i++) {
        float v[3][3];
        for (int k = 0; k < 3; k++)
            for (int c = 0; c < 3; c++)
                v[k][c] = roundf(s->mesh.positions[3 * s->mesh.indices[3 * i + (uint32_t)k] + (uint32_t)c] * 1e4f) / 1e4f;
        int first = 0;
        for (int k = 1; k < 3; k++)
            if (memcmp(v[k], v[first], sizeof v[0]) != 0 &&
                (v[k][0] < v[first][0] || (v[k][0] == v[first][0] && (v[k][1] < v[first][1] ||
                                           (v[k][1] == v[first][1] && v[k][2] < v[first][2])))))
                first = k;
        for (int k = 0; k < 3; k++) memcpy(t + 9 * i + 3 * k, v[(first + k) % 3], sizeof v[0]);
    }
    qsort(t, n, sizeof(float) * 9, cmp_tri);
    return t;
}

/* The path of a shared sample (../shared/gltf-samples beside the checkout)
 * into buf; false (and a failed check) if it is not there. */
static bool shared_sample_in(const char *rel, char *buf, size_t size)
{
    const char *p = shared_sample(rel);
    CHECK(p != NULL, "the shared sample %s was not found beside the checkout", rel);
    snprintf(buf, size, "%s", p ? p : "");
    return p != NULL;
}

static void test_draco(void)
{
    char plain[512], draco[512];
    if (!shared_sample_in("Box/glTF/Box.gltf", plain, sizeof plain)) return;
    snprintf(draco, sizeof draco, "%.*s/glTF-Draco/Box.gltf", (int)(strstr(plain, "/glTF/Box.gltf") - plain), plain);
    struct dr_scene *a = calloc(1, sizeof *a), *d = calloc(1, sizeof *d);
    int ra = dr_gltf_load(plain, a), rd = dr_gltf_load(draco, d);
    CHECK(ra == 0 && rd == 0, "Box %d, Box Draco %d: %s", ra, rd, dr_last_error());
    CHECK(!strstr(warnings, "KHR_draco_mesh_compression"), "no warning about the Draco extension:\n%s", warnings);
    if (ra == 0 && rd == 0) {
        CHECK(a->mesh.n_triangles == 12 && d->mesh.n_triangles == 12, "12 triangles each (%u, %u)",
              a->mesh.n_triangles, d->mesh.n_triangles);
        CHECK(d->mesh.flags[0] & DR_TRI_HAS_NORMALS, "the decoded NORMAL attribute is used");
        if (a->mesh.n_triangles == d->mesh.n_triangles) {
            float *ta = triangles(a), *tb = triangles(d);
            int same = memcmp(ta, tb, sizeof(float) * 9 * a->mesh.n_triangles) == 0;
            CHECK(same, "the Draco Box's triangles are the plain Box's");
            free(ta);
            free(tb);
        }
    }
    dr_scene_destroy(a);
    dr_scene_destroy(d);

    /* corrupt bytes and an attribute id the stream does not have: errors with the JSON path */
    const unsigned char junk[24] = "DRACO\x02\x02\x01\x01\x00\x00\x00junkjunkjunk";
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],"
        "\"extensionsUsed\":[\"KHR_draco_mesh_compression\"],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"extensions\":"
        "{\"KHR_draco_mesh_compression\":{\"bufferView\":0,\"attributes\":{\"POSITION\":0}}}}]}],"
        "\"buffers\":[{\"byteLength\":24,\"uri\":\"%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":24}],"
        "\"accessors\":[{\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"componentType\":5123,\"count\":3,\"type\":\"SCALAR\"}]}";
    int rc;
    struct dr_scene *s = load_json("draco_bad.gltf", NULL, &rc, fmt, data_uri(junk, 24));
    check_error(rc, "corrupt Draco stream", "draco_bad.gltf", "/meshes/0/primitives/0/extensions/KHR_draco_mesh_compression",
                "Draco");
    dr_scene_destroy(s);
}

/* ---- EXT_meshopt_compression and KHR_mesh_quantization: gltfpack's outputs ---- */

static struct dr_scene *load_meshopt_file(const char *name, int *rc)
{
    char path[512];
    snprintf(path, sizeof path, "%s/data/gltf/meshopt/%s", getenv("DR_TESTDIR") ? getenv("DR_TESTDIR") : "tests",
             name);
    struct dr_scene *s = calloc(1, sizeof *s);
    *rc = dr_gltf_load(path, s);
    CHECK(*rc == 0, "%s: %s", name, dr_last_error());
    return s;
}

/* Every vertex normal within `cos` of its triangle's geometric normal (the
 * Box's faces are flat: a normal decoded wrong points elsewhere). */
static bool normals_follow_faces(const struct dr_scene *s, double cos_min)
{
    const struct dr_mesh *m = &s->mesh;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        dr_vec3 p[3];
        for (int k = 0; k < 3; k++) {
            const float *q = m->positions + 3 * m->indices[3 * t + (uint32_t)k];
            p[k] = dr_v3(q[0], q[1], q[2]);
        }
        dr_vec3 ng = dr_normalize(dr_cross(dr_sub(p[1], p[0]), dr_sub(p[2], p[0])));
        for (int k = 0; k < 3; k++) {
            const float *n = m->normals + 3 * m->indices[3 * t + (uint32_t)k];
            dr_vec3 v = dr_normalize(dr_v3(n[0], n[1], n[2]));
            if (!(dr_dot(v, ng) >= cos_min)) return false;
        }
    }
    return true;
}

static void test_meshopt(void)
{
    int rc;
    warnings[0] = '\0';
    struct dr_scene *f = load_meshopt_file("box_float.gltf", &rc);
    struct dr_scene *q = load_meshopt_file("box_q.gltf", &rc);
    const char *compressed[] = {"box_c.gltf", "box_cc.glb", "box_vpf.gltf"};
    float *tq = triangles(q), *tf = triangles(f);
    CHECK(q->mesh.n_triangles == 12 && f->mesh.n_triangles == 12, "12 triangles (%u, %u)", q->mesh.n_triangles,
          f->mesh.n_triangles);
    /* quantized positions dequantized by the node's transform: the float Box's */
    CHECK(memcmp(tq, tf, sizeof(float) * 9 * 12) == 0, "the quantized Box's triangles are the float Box's");
    CHECK(normals_follow_faces(q, 0.9999), "the quantized Box's normals are its faces'");
    for (int i = 0; i < 3; i++) {
        struct dr_scene *c = load_meshopt_file(compressed[i], &rc);
        if (rc == 0 && c->mesh.n_triangles == 12) {
            float *tc = triangles(c);
            CHECK(memcmp(tc, tq, sizeof(float) * 9 * 12) == 0, "%s: the triangles are the uncompressed Box's",
                  compressed[i]);
            free(tc);
            /* (box_cc's normals went through the octahedral filter: 8 bits) */
            CHECK(normals_follow_faces(c, 0.999), "%s: the decoded normals are the faces'", compressed[i]);
        } else {
            CHECK(0, "%s: %u triangles", compressed[i], c->mesh.n_triangles);
        }
        dr_scene_destroy(c);
    }
    CHECK(!strstr(warnings, "EXT_meshopt_compression") && !strstr(warnings, "KHR_mesh_quantization"),
          "no warning about the extensions:\n%s", warnings);
    free(tq);
    free(tf);
    dr_scene_destroy(q);
    dr_scene_destroy(f);

    /* malformed compressed views: errors naming the bufferView */
    const unsigned char junk[16] = "\xa0junkjunkjunkjun";
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsRequired\":[\"EXT_meshopt_compression\"],"
        "\"extensionsUsed\":[\"EXT_meshopt_compression\"],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"buffers\":[{\"byteLength\":16,\"uri\":\"%s\"},{\"byteLength\":36,"
        "\"extensions\":{\"EXT_meshopt_compression\":{\"fallback\":true}}}],"
        "\"bufferViews\":[{\"buffer\":1,\"byteLength\":36,\"byteStride\":12,\"extensions\":{\"EXT_meshopt_compression\":"
        "{\"buffer\":0,\"byteLength\":%d,\"byteStride\":%d,\"count\":%d,\"mode\":\"%s\"%s}}}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}]}";
    struct dr_scene *s = load_json("meshopt_bad.gltf", NULL, &rc, fmt, data_uri(junk, 16), 16, 12, 3, "ATTRIBUTES", "");
    check_error(rc, "corrupt meshopt bytes", "meshopt_bad.gltf", "/bufferViews/0/extensions/EXT_meshopt_compression",
                "do not decode");
    dr_scene_destroy(s);
    s = load_json("meshopt_mode.gltf", NULL, &rc, fmt, data_uri(junk, 16), 16, 12, 3, "POINTS", "");
    check_error(rc, "unknown mode", "meshopt_mode.gltf", "/bufferViews/0/extensions/EXT_meshopt_compression/mode",
                "ATTRIBUTES");
    dr_scene_destroy(s);
    s = load_json("meshopt_past.gltf", NULL, &rc, fmt, data_uri(junk, 16), 17, 12, 3, "ATTRIBUTES", "");
    check_error(rc, "past the buffer", "meshopt_past.gltf", "/bufferViews/0/extensions/EXT_meshopt_compression/byteLength",
                "past the end");
    dr_scene_destroy(s);
    s = load_json("meshopt_huge.gltf", NULL, &rc, fmt, data_uri(junk, 16), 16, 12, 100000000, "ATTRIBUTES", "");
    check_error(rc, "a count no 16 bytes encode", "meshopt_huge.gltf",
                "/bufferViews/0/extensions/EXT_meshopt_compression/count", "more than the codec");
    dr_scene_destroy(s);
    s = load_json("meshopt_filter.gltf", NULL, &rc, fmt, data_uri(junk, 16), 16, 12, 3, "ATTRIBUTES",
                  ",\"filter\":\"OCTAHEDRAL\"");
    check_error(rc, "a filter's stride", "meshopt_filter.gltf",
                "/bufferViews/0/extensions/EXT_meshopt_compression/filter", "byteStride of 12");
    dr_scene_destroy(s);
}

/* ---- eight-bit textures: the shared NormalTangentTest's three 2k PNGs ---- */

/* Its render under a sky (it has no light), 48x48, 8 spp, into rgb. */
/* ---- EXT_mesh_gpu_instancing ---- */

/* One triangle drawn three times by a node (itself moved by 0.5 in y)
 * with TRANSLATION (float), ROTATION (normalized shorts) and SCALE (float)
 * instance attributes: the same triangles, to the bit, as a parent node
 * with three children at the instances' decoded TRS; and malformed
 * attributes refused naming their JSON path. */
static void test_instancing(void)
{
    unsigned char b[132];
    size_t o = 0;
    put_f32(b, &o, 9, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);        /* positions: 0, 36 bytes */
    put_f32(b, &o, 9, -2.0, 0.0, 0.0, 0.0, 0.0, -1.0, 2.5, 0.25, 0.0);     /* translations: 36 */
    const int16_t rot[12] = {0, 0, 0, 32767, 0, 23170, 0, 23170, 12000, -5000, 30000, 2000};   /* rotations: 72 */
    memcpy(b + o, rot, sizeof rot), o += sizeof rot;
    put_f32(b, &o, 9, 1.0, 1.0, 1.0, 2.0, 0.5, 1.0, 0.75, 0.75, 1.5);       /* scales: 96 */
    CHECK(o == sizeof b, "the buffer is filled (%zu of %zu bytes)", o, sizeof b);
    const char *head =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"EXT_mesh_gpu_instancing\"],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"buffers\":[{\"byteLength\":132,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":132}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"max\":[1,1,0],"
        "\"min\":[0,0,0]},{\"bufferView\":0,\"byteOffset\":36,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":0,\"byteOffset\":72,\"componentType\":5122,\"normalized\":true,\"count\":3,\"type\":\"VEC4\"},"
        "{\"bufferView\":0,\"byteOffset\":96,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
        "{\"bufferView\":0,\"byteOffset\":72,\"componentType\":5122,\"count\":3,\"type\":\"VEC4\"},"
        "{\"bufferView\":0,\"byteOffset\":36,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
        "{\"bufferView\":0,\"byteOffset\":96,\"componentType\":5126,\"count\":2,\"type\":\"VEC3\"},"
        "{\"componentType\":5126,\"count\":2147483648,\"type\":\"VEC3\"}],";   /* (7: zeros, no bufferView) */
    char uri[512], json[8192];
    snprintf(uri, sizeof uri, "%s", data_uri(b, sizeof b));
    int rc;
    snprintf(json, sizeof json, "%s\"nodes\":[{\"mesh\":0,\"translation\":[0,0.5,0],\"extensions\":"
             "{\"EXT_mesh_gpu_instancing\":{\"attributes\":{\"TRANSLATION\":1,\"ROTATION\":2,\"SCALE\":3,\"_ID\":1}}}}]}",
             head);
    struct dr_scene *inst = load_json("instanced.gltf", NULL, &rc, json, uri);
    CHECK(rc == 0 && inst->mesh.n_triangles == 3, "instanced: rc %d, %u triangles: %s", rc, inst->mesh.n_triangles,
          dr_last_error());
    CHECK(!strstr(warnings, "EXT_mesh_gpu_instancing"), "no warning about the extension:\n%s", warnings);
    /* the explicit twin: the decoded attributes as child nodes' TRS */
    float sc[9];
    memcpy(sc, b + 96, sizeof sc);
    char kids[3][400];
    for (int i = 0; i < 3; i++) {
        float t[3];
        memcpy(t, b + 36 + 12 * i, sizeof t);
        double q[4];
        for (int c = 0; c < 4; c++)
            q[c] = fmax(rot[4 * i + c] / 32767.0, -1.0);
        snprintf(kids[i], sizeof kids[i], "{\"mesh\":0,\"translation\":[%.17g,%.17g,%.17g],\"rotation\":[%.17g,%.17g,"
                 "%.17g,%.17g],\"scale\":[%.17g,%.17g,%.17g]}", t[0], t[1], t[2], q[0], q[1], q[2], q[3],
                 sc[3 * i], sc[3 * i + 1], sc[3 * i + 2]);
    }
    snprintf(json, sizeof json, "%s\"nodes\":[{\"translation\":[0,0.5,0],\"children\":[1,2,3]},%s,%s,%s]}", head,
             kids[0], kids[1], kids[2]);
    struct dr_scene *twin = load_json("explicit.gltf", NULL, &rc, json, uri);
    CHECK(rc == 0 && twin->mesh.n_triangles == 3, "explicit: rc %d: %s", rc, dr_last_error());
    if (inst->mesh.n_triangles == 3 && twin->mesh.n_triangles == 3)
        CHECK(inst->mesh.n_vertices == 9 && twin->mesh.n_vertices == 9 &&
              memcmp(inst->mesh.positions, twin->mesh.positions, sizeof(float) * 27) == 0 &&
              memcmp(inst->mesh.indices, twin->mesh.indices, sizeof(uint32_t) * 9) == 0 &&
              memcmp(inst->mesh.positions + 9, inst->mesh.positions, sizeof(float) * 3) != 0,
              "the instances' triangles are the explicit nodes', and they differ from one another");
    dr_scene_destroy(inst);
    dr_scene_destroy(twin);

    const struct { const char *attrs, *what, *n1, *n2; } bad[] = {
        {"\"TRANSLATION\":1,\"SCALE\":6", "a count that differs", "/nodes/0/extensions/EXT_mesh_gpu_instancing/"
         "attributes/SCALE", "TRANSLATION has 3"},
        {"\"ROTATION\":4", "integer rotations not normalized", "/accessors/4", "ROTATION must be float or normalized"},
        {"\"TRANSLATION\":5", "a VEC2 translation", "/accessors/5", "TRANSLATION must be VEC3"},
        {"\"_ID\":1", "no transform attribute", "EXT_mesh_gpu_instancing/attributes", "none of TRANSLATION"},
        {"\"TRANSLATION\":9", "a missing accessor", "attributes/TRANSLATION", "accessor 9 does not exist"},
        {"\"TRANSLATION\":7", "2^31 instances", "/nodes/0/extensions/EXT_mesh_gpu_instancing",
         "2147483648 instances of mesh 0 (3 vertices each) make more than 2^32 vertices"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(json, sizeof json, "%s\"nodes\":[{\"mesh\":0,\"extensions\":{\"EXT_mesh_gpu_instancing\":"
                 "{\"attributes\":{%s}}}}]}", head, bad[i].attrs);
        struct dr_scene *s = load_json("bad-instances.gltf", NULL, &rc, json, uri);
        check_error(rc, bad[i].what, "bad-instances.gltf", bad[i].n1, bad[i].n2);
        dr_scene_destroy(s);
    }
}

static void render_sample(struct dr_scene *s, float *rgb)
{
    struct dr_camera cam = dr_camera_default(s);
    struct dr_render_opts o = {.width = 48, .height = 48, .spp = 8, .max_depth = 4, .rr_depth = DR_RR_DEPTH_DEFAULT,
                               .seed = 5, .threads = 2};
    struct dr_render_stats st;
    CHECK(dr_render(s, &cam, &o, rgb, &st) == 0, "render: %s", dr_last_error());
}

/* ---- KHR_materials_unlit ---- */

/* An unlit wall (its base colour shown as it is) behind a white floor, no
 * light in the file: the pixels that see the wall are its colour exactly,
 * the floor is lit by it alone; no extension warning; the wall's factors are
 * no parameters (refused saying why); COLOR_0 on it is warned about. */
static void test_unlit(void)
{
    unsigned char b[96];
    size_t o = 0;
    put_f32(b, &o, 12, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0);   /* wall, facing +z */
    put_f32(b, &o, 12, -1.0, 0.0, 0.0, -1.0, 0.0, 2.0, 1.0, 0.0, 2.0, 1.0, 0.0, 0.0);   /* floor, facing +y */
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_unlit\"],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.2,0.5,0.8,1]},"
        "\"extensions\":{\"KHR_materials_unlit\":{}}},{\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,1],"
        "\"metallicFactor\":0}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0%s},\"indices\":2,\"material\":0}]},"
        "{\"primitives\":[{\"attributes\":{\"POSITION\":1},\"indices\":2,\"material\":1}]}],"
        "\"nodes\":[{\"mesh\":0},{\"mesh\":1}],\"scenes\":[{\"nodes\":[0,1]}],"
        "\"cameras\":[{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.9,\"znear\":0.01}}],"
        "\"buffers\":[{\"byteLength\":108,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":108}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"max\":[1,1,0],"
        "\"min\":[-1,0,0]},{\"bufferView\":0,\"byteOffset\":48,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\","
        "\"max\":[1,0,2],\"min\":[-1,0,0]},{\"bufferView\":0,\"byteOffset\":96,\"componentType\":5123,\"count\":6,"
        "\"type\":\"SCALAR\"},{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"}]}";
    unsigned char all[108];
    memcpy(all, b, sizeof b);
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
    memcpy(all + 96, idx, sizeof idx);
    char uri[512];
    snprintf(uri, sizeof uri, "%s", data_uri(all, sizeof all));
    int rc;
    struct dr_scene *s = load_json("unlit.gltf", NULL, &rc, fmt, "", uri);
    CHECK(rc == 0, "unlit: %s", dr_last_error());
    if (rc != 0) {
        dr_scene_destroy(s);
        return;
    }
    CHECK(!strstr(warnings, "KHR_materials_unlit"), "no warning about the extension:\n%s", warnings);
    dr_scene_destroy(s);
    s = dr_scene_load(tmp_path("unlit.gltf"));   /* (whole: lights and the tracer's geometry, for dr_render) */
    CHECK(s != NULL, "unlit: %s", dr_last_error());
    if (!s)
        return;
    CHECK(s->materials[0].unlit && !s->materials[1].unlit, "the wall's material is unlit, the floor's not");
    /* a camera on the floor's far side looking at the wall, the floor below */
    struct dr_camera cam = dr_camera_default(s);
    cam.origin = dr_v3(0.0, 0.6, 2.6);
    cam.forward = dr_normalize(dr_sub(dr_v3(0.0, 0.35, 0.0), cam.origin));
    cam.right = dr_normalize(dr_cross(cam.forward, dr_v3(0.0, 1.0, 0.0)));
    cam.up = dr_cross(cam.right, cam.forward);
    cam.yfov = 0.9, cam.orthographic = false;
    struct dr_render_opts ro = {.width = 32, .height = 32, .spp = 8, .max_depth = 4, .rr_depth = DR_RR_DEPTH_DEFAULT,
                                .seed = 5, .threads = 2};
    static float rgb[3 * 32 * 32];
    struct dr_render_stats st;
    CHECK(dr_render(s, &cam, &ro, rgb, &st) == 0, "render: %s", dr_last_error());
    int wall = 0, lit = 0, other = 0;
    for (int i = 0; i < 32 * 32; i++) {
        const float *p = rgb + 3 * i;
        if (fabsf(p[0] - 0.2f) < 1e-6f && fabsf(p[1] - 0.5f) < 1e-6f && fabsf(p[2] - 0.8f) < 1e-6f)
            wall++;   /* (whole pixels on the wall: its colour, nothing reflected) */
        else if (p[0] > 0.0f && p[0] < p[2])
            lit++;    /* the white floor in the wall's blue light */
        else
            other++;
    }
    printf("  unlit wall: %d pixels exactly its colour, %d floor pixels lit by it, %d others\n", wall, lit, other);
    CHECK(wall > 100 && lit > 100, "the unlit wall shows its colour (%d pixels) and lights the floor (%d)", wall, lit);
    struct dr_param p;
    CHECK(dr_param_resolve(s, "/materials/0/pbrMetallicRoughness/baseColorFactor", &p) != 0 &&
              strstr(dr_last_error(), "unlit (KHR_materials_unlit)"),
          "an unlit base colour is refused saying why: %s", dr_last_error());
    CHECK(dr_param_resolve(s, "/materials/1/pbrMetallicRoughness/baseColorFactor", &p) == 0,
          "the floor's base colour is a parameter: %s", dr_last_error());
    dr_scene_destroy(s);
    s = load_json("unlit_colours.gltf", NULL, &rc, fmt, ",\"COLOR_0\":3", uri);
    CHECK(rc == 0 && strstr(warnings, "vertex colours do not tint an unlit material"),
          "COLOR_0 on an unlit material is warned about: rc %d, warnings:\n%s", rc, warnings);
    dr_scene_destroy(s);
}

/* Textures from 8-bit files are kept in eight bits once decoded (image.h:
 * the same values from a table); a render of them is bit for bit the render
 * of the same scene with its textures back in float. */
static void test_eight_bit(void)
{
    char path[512];
    if (!shared_sample_in("NormalTangentTest/glTF/NormalTangentTest.gltf", path, sizeof path)) return;
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "%s: %s", path, dr_last_error());
    if (!s) return;
    CHECK(dr_scene_set_environment(s, dr_v3(1.0, 0.95, 0.9), 1.0, NULL, true) == 0, "sky: %s", dr_last_error());
    CHECK(s->n_images == 3, "three images (%d)", s->n_images);
    int eight = 0;
    size_t bytes = 0;
    for (int i = 0; i < s->n_images; i++) {
        eight += s->images[i].bytes != NULL && s->images[i].data == NULL;
        bytes += dr_image_pixel_bytes(&s->images[i]);
    }
    CHECK(eight == s->n_images, "%d of %d images in eight bits", eight, s->n_images);
    float *a = malloc(sizeof(float) * 3 * 48 * 48), *b = malloc(sizeof(float) * 3 * 48 * 48);
    render_sample(s, a);
    size_t floats = 0;
    for (int i = 0; i < s->n_images; i++) {
        CHECK(dr_image_expand(&s->images[i]) == 0, "expand image %d: %s", i, dr_last_error());
        CHECK(s->images[i].data && !s->images[i].bytes, "image %d in float after expanding", i);
        floats += dr_image_pixel_bytes(&s->images[i]);
    }
    CHECK(bytes * 3 < floats, "eight bits take %zu bytes, floats %zu", bytes, floats);
    render_sample(s, b);
    double sum = 0.0;
    for (int i = 0; i < 3 * 48 * 48; i++) sum += a[i];
    CHECK(sum > 0.0, "the render is not black (%g)", sum);
    CHECK(memcmp(a, b, sizeof(float) * 3 * 48 * 48) == 0, "eight-bit and float textures render differently");
    printf("eight-bit textures: %zu bytes against %zu as floats; renders identical\n", bytes, floats);
    free(a);
    free(b);
    dr_scene_destroy(s);
}

/* KHR_materials_pbrSpecularGlossiness, loaded onto the metallic-roughness
 * model with KHR_materials_specular (gltf_load.cpp's load_spec_gloss): the
 * BSDF at a hit, with eight-bit (KTX2) and float (EXR) textures; the
 * derived roughness texture made once per (texture, glossiness); the
 * factors are no parameters but the diffuse texture's texels are; malformed
 * files refused by JSON path. */
static void test_spec_gloss(void)
{
    unsigned char dif[104 + 3] = {0}, sg[104 + 4] = {0};
    ktx2_header(dif, 29, 1, 1, 0, 3);   /* R8G8B8_SRGB */
    memcpy(dif + 104, (const unsigned char[]){200, 100, 50}, 3);
    ktx2_header(sg, 43, 1, 1, 0, 4);    /* R8G8B8A8_SRGB: RGB the specular colour, A the glossiness */
    memcpy(sg + 104, (const unsigned char[]){255, 128, 64, 128}, 4);
    write_file("sg_d.ktx2", dif, sizeof dif);
    write_file("sg_s.ktx2", sg, sizeof sg);
    const float sg_float[4] = {0.5f, 0.25f, 1.0f, 0.25f};
    CHECK(dr_image_write(tmp_path("sg_s.exr"), 1, 1, 4, sg_float) == 0, "writing sg_s.exr: %s", dr_last_error());
    char uri[512];
    textured_quad_uri(uri);
    /* material 0: the extension (%s); 1 and 2 share its specular-glossiness
     * texture, 1 at the same glossiness (0.6), 2 at another */
    const char *fmt =
        "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_materials_pbrSpecularGlossiness\"],"
        "\"materials\":[{\"extensions\":{\"KHR_materials_pbrSpecularGlossiness\":{%s}}},"
        "{\"extensions\":{\"KHR_materials_pbrSpecularGlossiness\":{\"glossinessFactor\":0.6,"
        "\"specularGlossinessTexture\":{\"index\":1}}}},"
        "{\"extensions\":{\"KHR_materials_pbrSpecularGlossiness\":{\"glossinessFactor\":0.3,"
        "\"specularGlossinessTexture\":{\"index\":1}}}}],"
        QUAD_MESH_JSON
        "\"textures\":[{\"source\":0},{\"source\":1},{\"source\":2}],"
        "\"images\":[{\"uri\":\"sg_d.ktx2\",\"mimeType\":\"image/ktx2\"},{\"uri\":\"sg_s.ktx2\",\"mimeType\":\"image/ktx2\"},"
        "{\"uri\":\"sg_s.exr\"}],"
        QUAD_BUFFER_JSON;
    int rc;
    struct dr_scene *s = load_json("sg.gltf", NULL, &rc, fmt,
                                   "\"diffuseFactor\":[0.8,0.4,0.2,0.7],\"specularFactor\":[0.5,0.3,0.1],"
                                   "\"glossinessFactor\":0.6,\"diffuseTexture\":{\"index\":0},"
                                   "\"specularGlossinessTexture\":{\"index\":1}",
                                   uri);
    CHECK(rc == 0, "spec-gloss: %s", dr_last_error());
    CHECK(!strstr(warnings, "SpecularGlossiness"), "no warning about the extension:\n%s", warnings);
    dr_scene_destroy(s);
    s = dr_scene_load(tmp_path("sg.gltf"));
    CHECK(s != NULL, "spec-gloss, whole: %s", dr_last_error());
    if (s) {
        /* three file textures + two derived (glossiness 0.6 shared by materials 0 and 1, and 0.3) */
        CHECK(s->n_textures == 5 && s->n_images == 5, "derived roughness textures: %d textures, %d images",
              s->n_textures, s->n_images);
        CHECK(s->materials[0].spec_gloss && s->materials[0].metallic == 0.0 && s->materials[0].alpha == 0.7,
              "material 0: spec-gloss, metallic 0, alpha from diffuseFactor");
        CHECK(s->materials[0].metallic_roughness_tex.texture == s->materials[1].metallic_roughness_tex.texture &&
                  s->materials[2].metallic_roughness_tex.texture != s->materials[0].metallic_roughness_tex.texture &&
                  s->materials[0].metallic_roughness_tex.texture >= 3,
              "one derived texture per (texture, glossiness)");
        struct dr_hit hit;
        dr_hit_compute(&s->mesh, 0, dr_v3(0.5, 0.2, 3.0), dr_v3(0.0, 0.0, -1.0), &hit);
        struct dr_bsdf bs;
        dr_material_eval(s, &hit, &bs);
        const double lin_d[3] = {dr_srgb_to_linear(200.0 / 255.0), dr_srgb_to_linear(100.0 / 255.0),
                                 dr_srgb_to_linear(50.0 / 255.0)};
        CHECK(fabs(bs.base_color.x - 0.8 * lin_d[0]) < 1e-6 && fabs(bs.base_color.y - 0.4 * lin_d[1]) < 1e-6 &&
                  fabs(bs.base_color.z - 0.2 * lin_d[2]) < 1e-6,
              "base colour = diffuseFactor x diffuse texel: (%g, %g, %g)", bs.base_color.x, bs.base_color.y,
              bs.base_color.z);
        CHECK(bs.metallic == 0.0 && bs.specular == 1.0, "metallic 0, specular 1: %g, %g", bs.metallic, bs.specular);
        CHECK(fabs(bs.roughness - (1.0 - 0.6 * 128.0 / 255.0)) < 1e-6, "roughness = 1 - glossiness x A: %g",
              bs.roughness);
        /* f0 = min(0.04 specular_color, 1) is the file's F0 = specularFactor x the texel's decoded RGB */
        const double f0[3] = {0.5 * 1.0, 0.3 * dr_srgb_to_linear(128.0 / 255.0), 0.1 * dr_srgb_to_linear(64.0 / 255.0)};
        const double got[3] = {0.04 * bs.specular_color.x, 0.04 * bs.specular_color.y, 0.04 * bs.specular_color.z};
        for (int k = 0; k < 3; k++)
            CHECK(fabs(got[k] - f0[k]) < 1e-6, "f0[%d] = specularFactor x texel: %g, want %g", k, got[k], f0[k]);
        /* material 2's roughness: its own derived texture, 1 - 0.3 A */
        hit.material = 2;
        dr_material_eval(s, &hit, &bs);
        CHECK(fabs(bs.roughness - (1.0 - 0.3 * 128.0 / 255.0)) < 1e-6, "material 2's roughness: %g", bs.roughness);
        struct dr_param *list;
        int n;
        CHECK(dr_params_list(s, &list, &n) == 0, "params: %s", dr_last_error());
        bool image0 = false, emissive = false;
        for (int i = 0; i < n; i++) {
            CHECK(!strstr(list[i].name, "/pbrMetallicRoughness/"),
                  "no mapped factor of a spec-gloss material is a parameter: %s", list[i].name);
            emissive |= strcmp(list[i].name, "/materials/0/emissiveFactor") == 0;
            image0 |= strcmp(list[i].name, "/images/0") == 0;
            CHECK(strcmp(list[i].name, "/images/1") != 0 && strcmp(list[i].name, "/images/3") != 0,
                  "the specular-glossiness image and the derived one are no parameters: %s", list[i].name);
        }
        CHECK(image0, "the diffuse texture's texels are a parameter (/images/0)");
        CHECK(emissive, "a spec-gloss material's emissiveFactor is a parameter");
        free(list);
        struct dr_param p;
        CHECK(dr_param_resolve(s, "/materials/0/pbrMetallicRoughness/baseColorFactor", &p) != 0 &&
                  strstr(dr_last_error(), "pbrSpecularGlossiness"),
              "a factor refused with the reason: %s", dr_last_error());
    }
    dr_scene_destroy(s);
    /* a float image (EXR): the derived texture in floats, 1 - 0.6 x 0.25 */
    s = load_json("sg_f.gltf", NULL, &rc, fmt, "\"glossinessFactor\":0.6,\"specularGlossinessTexture\":{\"index\":2}",
                  uri);
    dr_scene_destroy(s);
    s = rc == 0 ? dr_scene_load(tmp_path("sg_f.gltf")) : NULL;
    CHECK(s != NULL, "spec-gloss with a float texture: %s", dr_last_error());
    if (s) {
        struct dr_hit hit;
        dr_hit_compute(&s->mesh, 0, dr_v3(0.5, 0.2, 3.0), dr_v3(0.0, 0.0, -1.0), &hit);
        struct dr_bsdf bs;
        dr_material_eval(s, &hit, &bs);
        CHECK(s->images[s->textures[s->materials[0].metallic_roughness_tex.texture].image].data != NULL,
              "a float image's derived texture is float");
        CHECK(fabs(bs.roughness - (1.0 - 0.6 * 0.25)) < 1e-6, "float: roughness = 1 - glossiness x A: %g", bs.roughness);
        CHECK(fabs(0.04 * bs.specular_color.y - 0.25) < 1e-6, "float: f0 = the texel's G (linear): %g",
              0.04 * bs.specular_color.y);
    }
    dr_scene_destroy(s);
    /* without a texture: roughness 1 - glossinessFactor, no texture read */
    s = load_json("sg_plain.gltf", NULL, &rc, fmt, "\"glossinessFactor\":0.25", uri);
    CHECK(rc == 0 && s->materials[0].roughness == 0.75 && s->materials[0].metallic_roughness_tex.texture < 0 &&
              s->materials[0].base_color.x == 1.0 && 0.04 * s->materials[0].specular_color.x == 1.0,
          "defaults: diffuse 1, specular 1, roughness 1 - glossiness (rc %d)", rc);
    dr_scene_destroy(s);
    static const struct { const char *ext, *what, *where, *says; } bad[] = {
        {"\"diffuseFactor\":[1,1,1]", "a diffuse factor of three numbers", "pbrSpecularGlossiness/diffuseFactor",
         "4 numbers"},
        {"\"specularFactor\":[0.5,2,0]", "a specular factor above 1", "pbrSpecularGlossiness/specularFactor/1",
         "[0, 1]"},
        {"\"glossinessFactor\":1.5", "a glossiness above 1", "pbrSpecularGlossiness/glossinessFactor", "[0, 1]"},
        {"\"specularGlossinessTexture\":{\"index\":9}", "a missing texture",
         "pbrSpecularGlossiness/specularGlossinessTexture", "does not exist"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        s = load_json("sg_bad.gltf", NULL, &rc, fmt, bad[i].ext, uri);
        check_error(rc, bad[i].what, "sg_bad.gltf", bad[i].where, bad[i].says);
        dr_scene_destroy(s);
    }
}

int main(void)
{
    snprintf(dir, sizeof dir, "%s/drender-gltf-features.XXXXXX", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    if (!mkdtemp(dir)) {
        perror("mkdtemp");
        return 1;
    }
    dr_set_warn_handler(record_warning);
    test_colors();
    test_sparse();
    test_texcoords();
    test_ortho();
    test_ktx2();
    test_draco();
    test_meshopt();
    test_instancing();
    test_unlit();
    test_anisotropy();
    test_specular_textures();
    test_sheen();
    test_spec_gloss();
    test_anisotropy_frame_adjoint();
    test_eight_bit();
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
    return TEST_END();
}
