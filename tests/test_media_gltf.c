/* Media in glTF files: KHR_materials_volume (+ transmission, ior,
 * volume_scatter), the DR_medium extension with density grids (raw, EXR and
 * OpenVDB: tests/data/media/smoke.vdb holds smoke.raw's voxels),
 * and bad input that must be refused before any work, with a message naming
 * the file and the JSON path; thin-walled glass (transmission without a
 * volume, or glTF's volume on an open mesh). Scenes are written to a
 * temporary directory. */
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"
#include "image_io.h"
#include "medium_scene.h"
#include "params.h"
#include "path.h"
#include "test.h"

static char dir[256];

static void base64(const unsigned char *in, size_t n, char *out)
{
    static const char tab[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t o = 0;
    for (size_t i = 0; i < n; i += 3) {
        unsigned v = (unsigned)in[i] << 16 | (i + 1 < n ? (unsigned)in[i + 1] << 8 : 0) | (i + 2 < n ? in[i + 2] : 0);
        out[o++] = tab[v >> 18 & 63];
        out[o++] = tab[v >> 12 & 63];
        out[o++] = i + 1 < n ? tab[v >> 6 & 63] : '=';
        out[o++] = i + 2 < n ? tab[v & 63] : '=';
    }
    out[o] = '\0';
}

/* A unit cube [-1,1]^3 (outward CCW faces; drop_triangles > 0 leaves it
 * open) with material 0 whose "extensions" object is material_ext, plus a
 * camera; top_ext: the document's "extensions" members (may be ""). */
static const char *write_scene(const char *name, const char *material_ext, const char *top_ext, int drop_triangles)
{
    static char path[512];
    static const float p[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                  {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
    static const uint16_t idx[36] = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                     3, 7, 6, 3, 6, 2, 0, 4, 7, 0, 7, 3, 1, 2, 6, 1, 6, 5};
    int n_idx = 36 - 3 * drop_triangles;
    unsigned char buf[96 + 72];
    memcpy(buf, p, 96);
    memcpy(buf + 96, idx, 72);
    char b64[300];
    base64(buf, sizeof buf, b64);
    snprintf(path, sizeof path, "%s/%s.gltf", dir, name);
    FILE *f = fopen(path, "w");
    fprintf(f,
            "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0,1]}],"
            "\"nodes\":[{\"mesh\":0},{\"camera\":0,\"translation\":[0,0,5]}],"
            "\"cameras\":[{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.6,\"znear\":0.1}}],"
            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":0}]}],"
            "\"materials\":[{\"name\":\"fog\",\"extensions\":{%s}}],"
            "\"buffers\":[{\"byteLength\":168,\"uri\":\"data:application/octet-stream;base64,%s\"}],"
            "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":96},"
            "{\"buffer\":0,\"byteOffset\":96,\"byteLength\":%d}],"
            "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":8,\"type\":\"VEC3\","
            "\"min\":[-1,-1,-1],\"max\":[1,1,1]},"
            "{\"bufferView\":1,\"componentType\":5123,\"count\":%d,\"type\":\"SCALAR\"}],"
            "\"extensions\":{\"DR_environment\":{\"color\":[1,1,1]}%s%s}}\n",
            material_ext, b64, 2 * n_idx, n_idx, *top_ext ? "," : "", top_ext);
    fclose(f);
    return path;
}

static void write_raw(const char *name, int n, float value, int negative_at)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    for (int i = 0; i < n; i++) {
        float v = i == negative_at ? -1.0f : value * (float)(i % 3);
        fwrite(&v, sizeof v, 1, f);
    }
    fclose(f);
}

#define KHR_TRANSMISSIVE "\"KHR_materials_transmission\":{\"transmissionFactor\":1}"
#define KHR_INDEX_MATCHED KHR_TRANSMISSIVE ",\"KHR_materials_ior\":{\"ior\":1}"

static void test_khr_volume(void)
{
    const char *p = write_scene("khr",
                                "\"KHR_materials_volume\":{\"thicknessFactor\":1,\"attenuationDistance\":2,"
                                "\"attenuationColor\":[0.5,0.25,1]}," KHR_INDEX_MATCHED ","
                                "\"KHR_materials_volume_scatter\":{\"multiscatterColor\":[1,1,1],"
                                "\"scatterAnisotropy\":0.3}",
                                "", 0);
    struct dr_scene *s = dr_scene_load(p);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return;
    CHECK(s->n_media == 1 && s->material_medium[0] == 0 && s->global_medium == -1, "one mesh medium");
    const struct dr_medium *m = &s->media[0];
    CHECK_NEAR(m->extinction.x, -log(0.5) / 2, 1e-12, "sigma_t from attenuation (r)");
    CHECK_NEAR(m->extinction.y, -log(0.25) / 2, 1e-12, "sigma_t from attenuation (g)");
    CHECK_NEAR(m->extinction.z, 0.0, 1e-12, "attenuation colour 1: no extinction");
    CHECK_NEAR(m->albedo.x, 1.0, 1e-4, "multiscatter 1 -> albedo 1");
    CHECK_NEAR(m->g, 0.3, 1e-12, "scatterAnisotropy");
    CHECK((s->effects & DR_FX_MEDIA) && !(s->effects & DR_FX_HETEROGENEOUS_MEDIA), "effects");
    CHECK(dr_path_plan(s, NULL) & DR_STAGE_MEDIA, "plan has the medium stage");
    char fx[256];
    dr_effects_describe(s->effects, fx, sizeof fx);
    CHECK(strstr(fx, "media") != NULL, "effects name media: %s", fx);
    CHECK(m->ior == 0.0 && !(s->effects & DR_FX_DIELECTRIC_BOUNDARIES), "ior 1: index-matched");
    dr_scene_destroy(s);

    /* transmissive without KHR_materials_ior: glTF's default 1.5, a dielectric */
    p = write_scene("glass", "\"KHR_materials_volume\":{\"attenuationDistance\":2}," KHR_TRANSMISSIVE, "", 0);
    s = dr_scene_load(p);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return;
    CHECK(s->media[0].ior == 1.5 && (s->effects & DR_FX_DIELECTRIC_BOUNDARIES), "default ior 1.5: dielectric");
    CHECK(dr_path_plan(s, NULL) & DR_STAGE_DIELECTRIC, "plan has the dielectric stage");
    dr_scene_destroy(s);
    /* DR_medium with KHR_materials_ior 1.33 and transmission: water (alone: index-matched, below) */
    p = write_scene("water", "\"DR_medium\":{\"extinction\":1}," KHR_TRANSMISSIVE
                    ",\"KHR_materials_ior\":{\"ior\":1.33}", "", 0);
    s = dr_scene_load(p);
    CHECK(s && s->media[0].ior == 1.33, "DR_medium with KHR_materials_ior 1.33: %s", s ? "wrong ior" : dr_last_error());
    dr_scene_destroy(s);
}

static void test_dr_medium_grid(void)
{
    write_raw("grid.raw", 4 * 3 * 2, 0.5f, -1);
    const char *p = write_scene("grid",
                                "\"DR_medium\":{\"extinction\":[1,2,3],\"albedo\":[0.9,0.8,0.7],\"g\":-0.2,"
                                "\"density_scale\":4,\"density\":{\"uri\":\"grid.raw\",\"resolution\":[4,3,2]}}",
                                "\"DR_medium\":{\"extinction\":0.01,\"albedo\":[1,1,1]}", 0);
    struct dr_scene *s = dr_scene_load(p);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return;
    CHECK(s->n_media == 2 && s->global_medium == 1 && s->material_medium[0] == 0, "mesh + global medium");
    const struct dr_medium *m = &s->media[0];
    CHECK(m->has_grid && m->grid.nx == 4 && m->grid.ny == 3 && m->grid.nz == 2, "grid resolution");
    CHECK(m->grid.bmin.x == -1.0 && m->grid.bmax.z == 1.0, "grid box = the mesh's bounds");
    CHECK(m->ior == 0.0, "DR_medium alone: an index-matched boundary");
    CHECK(m->grid.majorant && m->grid.majorant[0] == 1.0f, "majorant = largest voxel (%g)",
          m->grid.majorant ? m->grid.majorant[0] : -1.0);
    CHECK(s->effects & DR_FX_HETEROGENEOUS_MEDIA, "heterogeneous_media effect");
    CHECK_NEAR(s->media[1].extinction.y, 0.01, 1e-15, "global extinction as a number");
    /* the camera (z = 5) is outside the cube: in the global medium */
    CHECK(dr_medium_at(s, dr_v3(0, 0, 5), dr_v3(0, 0, -1)) == 1, "camera in the global medium");
    CHECK(dr_medium_at(s, dr_v3(0, 0, 0), dr_v3(0, 0, -1)) == 0, "centre in the cube's medium");
    dr_scene_destroy(s);

    /* the same grid as a single-channel EXR (width nx, height ny * nz) */
    float px[24];
    for (int i = 0; i < 24; i++)
        px[i] = 0.5f * (float)(i % 3);
    char exr[512];
    snprintf(exr, sizeof exr, "%s/grid.exr", dir);
    CHECK(dr_image_write(exr, 4, 6, 1, px) == 0, "write exr: %s", dr_last_error());
    p = write_scene("grid_exr", "\"DR_medium\":{\"extinction\":1,\"density\":{\"uri\":\"grid.exr\",\"resolution\":[4,3,2]}}",
                    "", 0);
    s = dr_scene_load(p);
    CHECK(s != NULL, "load exr grid: %s", dr_last_error());
    if (s) {
        CHECK(s->media[0].grid.density[5] == 1.0f && s->media[0].grid.density[4] == 0.5f, "exr voxels");
        dr_scene_destroy(s);
    }
}

/* Loading fails with a message containing every string of want. */
static void expect_error(const char *what, const char *path, const char *want1, const char *want2)
{
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s == NULL, "%s: loaded although invalid", what);
    if (s) {
        dr_scene_destroy(s);
        return;
    }
    const char *e = dr_last_error();
    CHECK(strstr(e, path) != NULL, "%s: message does not name the file: %s", what, e);
    CHECK(strstr(e, want1) != NULL, "%s: message lacks '%s': %s", what, want1, e);
    CHECK(!want2 || strstr(e, want2) != NULL, "%s: message lacks '%s': %s", what, want2, e);
}

static void test_bad_input(void)
{
    expect_error("missing grid",
                 write_scene("missing", "\"DR_medium\":{\"density\":{\"uri\":\"nope.raw\",\"resolution\":[2,2,2]}}",
                             "", 0),
                 "/materials/0/extensions/DR_medium/density/uri", "nope.raw");
    write_raw("small.raw", 7, 1.0f, -1);
    expect_error("wrong grid size",
                 write_scene("size", "\"DR_medium\":{\"density\":{\"uri\":\"small.raw\",\"resolution\":[2,2,2]}}",
                             "", 0),
                 "/materials/0/extensions/DR_medium/density/uri", "32 bytes");
    write_raw("neg.raw", 8, 1.0f, 5);
    expect_error("negative density",
                 write_scene("neg", "\"DR_medium\":{\"density\":{\"uri\":\"neg.raw\",\"resolution\":[2,2,2]}}", "",
                             0),
                 "voxel (1, 0, 1)", ">= 0");
    expect_error("grid key on a raw file",
                 write_scene("gridkey", "\"DR_medium\":{\"density\":{\"uri\":\"grid.raw\",\"grid\":\"density\","
                             "\"resolution\":[4,3,2]}}", "", 0),
                 "/materials/0/extensions/DR_medium/density/grid", "OpenVDB");
    expect_error("raw without resolution",
                 write_scene("nores", "\"DR_medium\":{\"density\":{\"uri\":\"grid.raw\"}}", "", 0),
                 "/materials/0/extensions/DR_medium/density/resolution", NULL);
    expect_error("missing vdb",
                 write_scene("novdb", "\"DR_medium\":{\"density\":{\"uri\":\"smoke.vdb\"}}", "", 0),
                 "/materials/0/extensions/DR_medium/density/uri", "smoke.vdb");
    expect_error("bad resolution",
                 write_scene("res", "\"DR_medium\":{\"density\":{\"uri\":\"x.raw\",\"resolution\":[2,0,2]}}", "", 0),
                 "/materials/0/extensions/DR_medium/density/resolution/1", NULL);
    expect_error("open mesh", write_scene("open", "\"DR_medium\":{\"extinction\":1}", "", 2), "/materials/0",
                 "closed");
    expect_error("albedo", write_scene("albedo", "\"DR_medium\":{\"albedo\":[1.5,0,0]}", "", 0),
                 "/materials/0/extensions/DR_medium/albedo", NULL);
    expect_error("g", write_scene("g", "\"DR_medium\":{\"g\":1}", "", 0), "/materials/0/extensions/DR_medium/g",
                 NULL);
    expect_error("not transmissive",
                 write_scene("opaque", "\"KHR_materials_volume\":{\"attenuationDistance\":1}", "", 0),
                 "/materials/0/extensions/KHR_materials_volume", "transmissionFactor");
    expect_error("ior below 1",
                 write_scene("ior", "\"KHR_materials_volume\":{\"attenuationDistance\":1}," KHR_TRANSMISSIVE
                             ",\"KHR_materials_ior\":{\"ior\":0.9}", "", 0),
                 "/materials/0/extensions/KHR_materials_ior/ior", "[1, 10]");
    expect_error("ior not a number",
                 write_scene("iorstr", "\"KHR_materials_volume\":{\"attenuationDistance\":1}," KHR_TRANSMISSIVE
                             ",\"KHR_materials_ior\":{\"ior\":\"glass\"}", "", 0),
                 "/materials/0/extensions/KHR_materials_ior/ior", NULL);
    expect_error("global grid without bounds",
                 write_scene("global", "\"DR_medium\":{\"extinction\":1}",
                             "\"DR_medium\":{\"density\":{\"uri\":\"grid.raw\",\"resolution\":[4,3,2]}}", 0),
                 "/extensions/DR_medium/bounds", NULL);
}

/* smoke.vdb's grid "density" is smoke.raw's 16^3 voxels at index
 * (-8, 3, 100); it loads to the same floats, found by name although the file
 * has other grids; another float grid is picked with "grid". */
static void test_vdb(void)
{
    const char *t = getenv("DR_TESTDIR") ? getenv("DR_TESTDIR") : "tests";
    char raw[512], vdb[512], file[512];
    snprintf(raw, sizeof raw, "%s/data/media/smoke.gltf", t);
    snprintf(vdb, sizeof vdb, "%s/data/media/smoke-vdb.gltf", t);
    snprintf(file, sizeof file, "%s/data/media/smoke.vdb", t);
    struct dr_volume vol;
    CHECK(dr_volume_read(file, NULL, &vol) == 0, "read %s: %s", file, dr_last_error());
    CHECK(vol.nx == 16 && vol.ny == 16 && vol.nz == 16 && vol.x0 == -8 && vol.y0 == 3 && vol.z0 == 100 &&
          strcmp(vol.grid, "density") == 0, "the density grid's active box: %dx%dx%d at (%d, %d, %d), '%s'",
          vol.nx, vol.ny, vol.nz, vol.x0, vol.y0, vol.z0, vol.grid);
    free(vol.data);
    CHECK(dr_volume_read(file, "temperature", &vol) == 0 && vol.nx * vol.ny * vol.nz == 1 && vol.data[0] == 5.0f,
          "the grid named temperature: one voxel of 5");
    free(vol.data);
    struct dr_scene *a = dr_scene_load(raw), *b = dr_scene_load(vdb);
    CHECK(a && b, "load: %s", dr_last_error());
    if (a && b) {
        const struct dr_grid *ga = &a->media[0].grid, *gb = &b->media[0].grid;
        CHECK(gb->nx == 16 && gb->ny == 16 && gb->nz == 16, "resolution from the file");
        CHECK(memcmp(ga->density, gb->density, 16 * 16 * 16 * sizeof(float)) == 0, "the same voxels as the raw grid");
        CHECK(memcmp(&ga->bmin, &gb->bmin, sizeof ga->bmin) == 0 && memcmp(&ga->bmax, &gb->bmax, sizeof ga->bmax) == 0,
              "stretched over the same box");
    }
    dr_scene_destroy(a);
    dr_scene_destroy(b);
    /* bad files: the message names the file and says what is wrong */
    static const char *const bad[][2] = {{"not-a-vdb.vdb", "not an OpenVDB file"},
                                         {"nofloat.vdb", "no float grid"},
                                         {"vec3.vdb", "velocity (vec3)"},
                                         {"empty.vdb", "no active voxels"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char ext[700];
        snprintf(file, sizeof file, "%s/data/media/%s", t, bad[i][0]);
        snprintf(ext, sizeof ext, "\"DR_medium\":{\"density\":{\"uri\":\"%s\"}}", file);
        expect_error(bad[i][0], write_scene("badvdb", ext, "", 0), bad[i][1], file);
        CHECK(dr_volume_read(file, NULL, &vol) != 0 && vol.data == NULL, "%s: refused, nothing allocated",
              bad[i][0]);
    }
}

static char warned[4096];
static void keep_warning(const char *msg)
{
    size_t n = strlen(warned);
    snprintf(warned + n, sizeof warned - n, "%s\n", msg);
}

/* KHR_materials_transmission without a volume is thin-walled glass; with a
 * partial factor it stays opaque (a warning); glTF's volume on an open mesh
 * becomes thin glass with a warning (DR_medium's is still refused: test_bad_input);
 * a thin material's base colour and metallic are no parameters. */
static void test_thin_glass(void)
{
    dr_set_warn_handler(keep_warning);
    warned[0] = '\0';
    struct dr_scene *s = dr_scene_load(write_scene("thin", KHR_TRANSMISSIVE ",\"KHR_materials_ior\":{\"ior\":1.33}",
                                                   "", 0));
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (s) {
        CHECK(s->n_media == 0 && s->materials[0].thin_ior == 1.33, "thin glass of ior 1.33 (ior %g, %d media)",
              s->materials[0].thin_ior, s->n_media);
        CHECK((s->effects & DR_FX_THIN_TRANSMISSION) && !(s->effects & DR_FX_MEDIA), "effects");
        CHECK(warned[0] == '\0', "no warning: %s", warned);
        struct dr_param q;
        CHECK(dr_param_resolve(s, "/materials/0/pbrMetallicRoughness/baseColorFactor", &q) != 0 &&
                  strstr(dr_last_error(), "thin-walled glass"),
              "the base colour of glass is no parameter: %s", dr_last_error());
        CHECK(dr_param_resolve(s, "/materials/fog/pbrMetallicRoughness/metallicFactor", &q) != 0 &&
                  strstr(dr_last_error(), "thin-walled glass"),
              "nor its metallic: %s", dr_last_error());
        CHECK(dr_param_resolve(s, "/materials/0/pbrMetallicRoughness/roughnessFactor", &q) == 0,
              "its roughness is: %s", dr_last_error());
        dr_scene_destroy(s);
    }
    warned[0] = '\0';
    s = dr_scene_load(write_scene("partial", "\"KHR_materials_transmission\":{\"transmissionFactor\":0.5}", "", 0));
    CHECK(s && s->materials[0].thin_ior == 0.0 && !(s->effects & DR_FX_THIN_TRANSMISSION), "partial: opaque");
    CHECK(strstr(warned, "/materials/0/extensions/KHR_materials_transmission/transmissionFactor") &&
              strstr(warned, "rendered opaque"), "partial: warned: %s", warned);
    dr_scene_destroy(s);
    warned[0] = '\0';
    s = dr_scene_load(write_scene("openvol", "\"KHR_materials_volume\":{\"thicknessFactor\":0.01}," KHR_TRANSMISSIVE,
                                  "", 2));
    CHECK(s != NULL, "glTF's volume on an open mesh loads: %s", dr_last_error());
    if (s) {
        CHECK(s->n_media == 0 && !s->media && !s->material_medium && s->materials[0].thin_ior == 1.5,
              "thin glass of the volume's default ior 1.5, no medium left (%d)", s->n_media);
        CHECK((s->effects & DR_FX_THIN_TRANSMISSION) && !(s->effects & (DR_FX_MEDIA | DR_FX_DIELECTRIC_BOUNDARIES)),
              "effects: thin glass, no media");
        CHECK(strstr(warned, "/materials/0 (fog)") && strstr(warned, "open") && strstr(warned, "thin-walled glass"),
              "warned: %s", warned);
        dr_scene_destroy(s);
    }
    dr_set_warn_handler(NULL);
}

int main(void)
{
    snprintf(dir, sizeof dir, "/tmp/drender-media-XXXXXX");
    if (!mkdtemp(dir)) {
        perror("mkdtemp");
        return 2;
    }
    test_khr_volume();
    test_dr_medium_grid();
    test_vdb();
    test_bad_input();
    test_thin_glass();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0)
        fprintf(stderr, "could not remove %s\n", dir);
    return TEST_END();
}
