/* Normal maps, alpha modes and single-sided materials (normal_map.h, coverage.h):
 *  - generated tangents equal the TANGENT a real exporter wrote (the shared
 *    sample VertexColorTest, with a normal map added so the loader keeps
 *    them) and the analytic dP/du of a smooth UV sphere, handedness included;
 *  - the perturbed normal on a known texel, with normalTexture.scale, and the
 *    fallback to the interpolated normal on degenerate UVs;
 *  - dr_shading_normal_valid: finite, unit, wo above it, at grazing angles;
 *  - MASK: a camera ray through a hole reaches what lies behind, and a floor
 *    point lit through a hole receives the light while one under the solid
 *    part does not (shadow rays);
 *  - BLEND: the fraction of rays that stop is alpha (one layer) and the
 *    product of two layers' (independence), and a key repeats its decision;
 *  - doubleSided false: a ray from behind passes (closest hit and shadow),
 *    from the front it stops; a medium boundary is never culled;
 *  - thin-walled glass: the sheet's reflectance against Fresnel's formula,
 *    the fraction of rays (and shadow rays) it stops at two angles, and a
 *    floor lit through it receiving (1 - R) of the light. */
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "accel.h"
#include "backface.h"
#include "coverage.h"
#include "geometry.h"
#include "medium.h"
#include "normal_map.h"
#include "path.h"
#include "scene.h"
#include "scene_builder.h"
#include "media_builder.h"
#include "test.h"

/* ------------------------------------------------------------ tangents */

/* VertexColorTest ships TANGENT (Blender's MikkTSpace). A copy whose second
 * material gets a normalTexture makes the loader keep them; then each
 * vertex's tangent is regenerated and compared. */
static void test_tangents_vs_supplied(void)
{
    const char *src = shared_sample("VertexColorTest/glTF/VertexColorTest.gltf");
    CHECK(src != NULL, "the shared sample VertexColorTest was not found beside the checkout");
    if (!src)
        return;
    char dir[] = "/tmp/drender-test-surfaces.XXXXXX";
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    char srcdir[4096], path[4200], link_from[4200];
    snprintf(srcdir, sizeof srcdir, "%s", src);
    *strrchr(srcdir, '/') = '\0';
    const char *files[] = {"VertexColorTest.bin", "VertexColorTestLabels.png", "VertexColorChecks.png"};
    for (int i = 0; i < 3; i++) {
        snprintf(link_from, sizeof link_from, "%s/%s", srcdir, files[i]);
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        CHECK(symlink(link_from, path) == 0, "symlink %s", path);
    }
    FILE *f = fopen(src, "rb");
    char *text = calloc(1, 1 << 20);
    size_t n = fread(text, 1, (1 << 20) - 1, f);
    fclose(f);
    text[n] = '\0';
    const char *anchor = "\"name\" : \"VC_Checks_Mat\",";
    char *at = strstr(text, anchor);
    CHECK(at != NULL, "VertexColorTest.gltf: material VC_Checks_Mat not found");
    snprintf(path, sizeof path, "%s/t.gltf", dir);
    f = fopen(path, "wb");
    if (at) {
        at += strlen(anchor);
        fwrite(text, 1, (size_t)(at - text), f);
        fputs(" \"normalTexture\" : {\"index\" : 1},", f);
        fputs(at, f);
    }
    fclose(f);
    free(text);
    struct dr_scene *s = at ? dr_scene_load(path) : NULL;
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (s) {
        struct dr_mesh *m = &s->mesh;
        CHECK(m->tangents != NULL, "a normal-mapped primitive with TANGENT: tangents kept");
        CHECK((s->effects & DR_FX_NORMAL_MAPS) != 0, "effects name normal_maps");
        size_t nv = m->n_vertices;
        float *sup = malloc(sizeof(float) * 4 * nv);
        memcpy(sup, m->tangents, sizeof(float) * 4 * nv);
        int compared = 0;
        double worst = 1.0;
        int sign_wrong = 0;
        /* the file's tangents: the vertices of the normal-mapped material's triangles */
        uint8_t *mapped = calloc(nv, 1);
        for (uint32_t t = 0; t < m->n_triangles; t++)
            if (s->materials[m->material[t]].normal_tex.texture >= 0)
                for (int k = 0; k < 3; k++)
                    mapped[m->indices[3 * t + k]] = 1;
        /* where the UVs are degenerate (|det| <= 1e-3: the solid-colour faces,
         * some with no UV area at all) the exporter wrote a default frame;
         * generated and supplied are compared where the UVs define one */
        uint8_t *ill = calloc(nv, 1);
        for (uint32_t t = 0; t < m->n_triangles; t++) {
            const uint32_t *ix = m->indices + 3 * t;
            const float *a = m->uvs + 2 * ix[0], *b1 = m->uvs + 2 * ix[1], *c = m->uvs + 2 * ix[2];
            double det = (b1[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b1[1] - a[1]);
            if (fabs(det) <= 1e-3)
                ill[ix[0]] = ill[ix[1]] = ill[ix[2]] = 1;
        }
        for (size_t v = 0; v < nv; v++)
            if (mapped[v])
                m->tangents[4 * v + 3] = 0.0f;   /* regenerate every supplied one */
        CHECK(dr_mesh_generate_tangents(m) == 0, "generate");
        for (size_t v = 0; v < nv; v++) {
            if (!mapped[v] || ill[v] || sup[4 * v + 3] == 0.0f)
                continue;
            const float *g = m->tangents + 4 * v, *t = sup + 4 * v;
            double c = g[0] * t[0] + g[1] * t[1] + g[2] * t[2];
            worst = dr_min(worst, c);
            sign_wrong += g[3] != t[3];
            compared++;
        }
        printf("VertexColorTest: %d supplied tangents, worst cos(generated, supplied) %.6f, %d handedness "
               "mismatches\n", compared, worst, sign_wrong);
        CHECK(compared >= 20, "expected at least 20 well-conditioned vertices, got %d", compared);
        CHECK(worst > 0.999, "generated tangent differs from the supplied one: cos %.6f", worst);
        CHECK(sign_wrong == 0, "%d vertices with the wrong bitangent sign", sign_wrong);
        free(sup);
        free(mapped);
        free(ill);
        dr_scene_destroy(s);
    }
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        unlink(path);
    }
    snprintf(path, sizeof path, "%s/t.gltf", dir);
    unlink(path);
    rmdir(dir);
}

/* A smooth UV sphere (u around +y, v from the top down, as glTF's v runs down
 * the image): the generated tangent is the normalised dP/du and w is +1
 * (cross(n, dP/du) points up the image: -dP/dv). With u mirrored (u = 1 -
 * azimuth) the tangent turns around and the frame is left-handed: w = -1. */
static void sphere_tangents(bool mirrored)
{
    struct sb b;
    sb_init(&b);
    struct dr_material mat = sb_diffuse(dr_v3s(0.5));
    int mi = sb_material(&b, mat);
    enum { NU = 24, NV = 12 };
    uint32_t id[NV + 1][NU + 1];
    for (int j = 0; j <= NV; j++)
        for (int i = 0; i <= NU; i++) {
            double u = (double)i / NU, v = (double)j / NV, phi = 2 * M_PI * u, th = M_PI * v;
            dr_vec3 p = dr_v3(sin(th) * cos(phi), cos(th), -sin(th) * sin(phi));
            id[j][i] = sb_vertex(&b, p, mirrored ? 1.0 - u : u, v);
            float *n = b.s->mesh.normals + 3 * (size_t)id[j][i];
            n[0] = (float)p.x, n[1] = (float)p.y, n[2] = (float)p.z;
        }
    for (int j = 0; j < NV; j++)
        for (int i = 0; i < NU; i++) {
            /* outward-facing (counter-clockwise seen from outside) */
            sb_triangle(&b, id[j][i], id[j + 1][i], id[j + 1][i + 1], mi);
            sb_triangle(&b, id[j][i], id[j + 1][i + 1], id[j][i + 1], mi);
        }
    for (uint32_t t = 0; t < b.s->mesh.n_triangles; t++)
        b.s->mesh.flags[t] |= DR_TRI_HAS_NORMALS;
    struct dr_mesh *m = &b.s->mesh;
    m->tangents = calloc(4 * (size_t)m->n_vertices, sizeof(float));
    CHECK(dr_mesh_generate_tangents(m) == 0, "generate");
    double worst = 1.0, sgn = mirrored ? -1.0 : 1.0;
    int sign_wrong = 0, n = 0;
    for (int j = 2; j <= NV - 2; j++)   /* away from the poles */
        for (int i = 1; i < NU; i++) {  /* away from the seam (split vertices, one side each) */
            uint32_t v = id[j][i];
            double phi = 2 * M_PI * i / NU;
            dr_vec3 dpdu = dr_scale(dr_v3(-sin(phi), 0.0, -cos(phi)), sgn);   /* normalised dP/du */
            const float *t = m->tangents + 4 * (size_t)v;
            worst = dr_min(worst, t[0] * dpdu.x + t[1] * dpdu.y + t[2] * dpdu.z);
            sign_wrong += t[3] != (float)sgn;
            n++;
        }
    printf("UV sphere%s: %d vertices, worst cos(generated, dP/du) %.6f, %d wrong signs\n",
           mirrored ? " (u mirrored)" : "", n, worst, sign_wrong);
    CHECK(worst > 0.995, "sphere tangent off dP/du: cos %.6f", worst);
    CHECK(sign_wrong == 0, "sphere: %d wrong bitangent signs", sign_wrong);
    struct dr_scene *s = sb_finish(&b);
    dr_scene_destroy(s);
}

static void test_tangents_sphere(void)
{
    sphere_tangents(false);
    sphere_tangents(true);
}

/* ---------------------------------------------------- perturbed normal */

/* A quad in z = 0 facing +z with u along +x and v along -y (sb_quad), so
 * T = +x, B = +y; a 2x2 normal map of one texel value. */
static struct dr_scene *normal_quad(const dr_vec3 *enc, double scale, bool degenerate_uv)
{
    struct sb b;
    sb_init(&b);
    float px[12];
    for (int i = 0; i < 4; i++)
        px[3 * i] = (float)enc->x, px[3 * i + 1] = (float)enc->y, px[3 * i + 2] = (float)enc->z;
    struct dr_material mat = sb_diffuse(dr_v3s(0.5));
    mat.normal_tex.texture = sb_texture(&b, sb_image(2, 2, 3, px, 0.0f, false));
    mat.normal_scale = scale;
    sb_quad(&b, dr_v3(-1, -1, 0), dr_v3(2, 0, 0), dr_v3(0, 2, 0), sb_material(&b, mat));
    if (degenerate_uv)
        for (uint32_t v = 0; v < b.s->mesh.n_vertices; v++)
            b.s->mesh.uvs[2 * v] = b.s->mesh.uvs[2 * v + 1] = 0.5f;
    sb_environment(&b, dr_v3s(1.0));
    return sb_finish(&b);
}

static void test_perturbed_normal(void)
{
    dr_vec3 want = dr_normalize(dr_v3(0.5, 0.3, 0.8));
    /* 8-bit-like encoding (n + 1) / 2 */
    dr_vec3 enc = dr_v3((want.x + 1) / 2, (want.y + 1) / 2, (want.z + 1) / 2);
    const double scales[2] = {1.0, 0.5};
    for (int k = 0; k < 2; k++) {
        struct dr_scene *s = normal_quad(&enc, scales[k], false);
        CHECK((s->effects & DR_FX_NORMAL_MAPS) != 0, "normal_maps effect");
        struct dr_hit h;
        int64_t tri = dr_accel_intersect(s->accel, dr_v3(0.3, 0.2, 2), dr_v3(0, 0, -1), 0, INFINITY);
        CHECK(tri >= 0, "the quad is hit");
        if (tri >= 0) {
            dr_hit_compute(&s->mesh, tri, dr_v3(0.3, 0.2, 2), dr_v3(0, 0, -1), &h);
            CHECK_NEAR(h.ns.z, 1.0, 1e-12, "interpolated normal before the map");
            dr_normal_map_apply(s, &h);
            dr_vec3 e = dr_normalize(dr_v3(want.x * scales[k], want.y * scales[k], want.z));
            printf("scale %.1f: ns (%.6f %.6f %.6f), expected (%.6f %.6f %.6f)\n", scales[k], h.ns.x, h.ns.y, h.ns.z,
                   e.x, e.y, e.z);
            CHECK_NEAR(h.ns.x, e.x, 1e-6, "ns.x (tangent = +x)");
            CHECK_NEAR(h.ns.y, e.y, 1e-6, "ns.y (bitangent = +y: green is up the image)");
            CHECK_NEAR(h.ns.z, e.z, 1e-6, "ns.z");
        }
        dr_scene_destroy(s);
    }
    /* degenerate UVs: no tangent frame, the interpolated normal stays */
    struct dr_scene *s = normal_quad(&enc, 1.0, true);
    struct dr_hit h;
    int64_t tri = dr_accel_intersect(s->accel, dr_v3(0.3, 0.2, 2), dr_v3(0, 0, -1), 0, INFINITY);
    if (tri >= 0) {
        dr_hit_compute(&s->mesh, tri, dr_v3(0.3, 0.2, 2), dr_v3(0, 0, -1), &h);
        dr_normal_map_apply(s, &h);
        CHECK(h.ns.x == 0.0 && h.ns.y == 0.0 && h.ns.z == 1.0, "degenerate UVs: ns stays (%g %g %g)", h.ns.x,
              h.ns.y, h.ns.z);
    }
    CHECK(s->mesh.tangents[3] == 0.0f, "degenerate UVs: no tangent generated");
    dr_scene_destroy(s);
}

/* Shading normals far from ng and arriving directions down to grazing: the
 * result is finite and unit, wo lies above it, and the mirror direction
 * above the geometric surface. */
static void test_valid_normal(void)
{
    dr_vec3 ng = dr_v3(0, 0, 1);
    int bad = 0, changed = 0, total = 0;
    uint64_t x = 12345;
    for (int i = 0; i < 200000; i++) {
        double r[4];
        for (int k = 0; k < 4; k++) {
            x = x * 6364136223846793005ULL + 1442695040888963407ULL;
            r[k] = (double)(x >> 11) * 0x1.0p-53;
        }
        /* wo from grazing (cos 1e-9) to normal; n up to 89.9 degrees off ng */
        double cw = i % 4 == 0 ? 1e-9 * r[0] : r[0], sw = sqrt(1 - cw * cw), pw = 2 * M_PI * r[1];
        double tn = 1.569 * r[2], pn = 2 * M_PI * r[3];
        dr_vec3 wo = dr_v3(sw * cos(pw), sw * sin(pw), cw);
        dr_vec3 n = dr_v3(sin(tn) * cos(pn), sin(tn) * sin(pn), cos(tn));
        dr_vec3 v = dr_shading_normal_valid(ng, wo, n);
        total++;
        changed += v.x != n.x || v.y != n.y || v.z != n.z;
        double len = dr_length(v);
        dr_vec3 refl = dr_sub(dr_scale(v, 2 * dr_dot(v, wo)), wo);
        if (!isfinite(len) || fabs(len - 1) > 1e-9 || dr_dot(v, wo) < -1e-12 || dr_dot(refl, ng) < -1e-9 ||
            dr_dot(v, ng) < 0.0)
            bad++;
    }
    printf("valid normal: %d of %d bent, %d bad\n", changed, total, bad);
    CHECK(bad == 0, "%d of %d shading normals invalid (NaN, not unit, wo or its reflection below)", bad, total);
    CHECK(changed > 1000, "expected many normals to need bending, got %d", changed);
}

/* ------------------------------------------------------------------ MASK */

/* A white point light of intensity 10 at (0, 3, 0). */
static void add_overhead_light(struct sb *b)
{
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3s(1.0);
    l.intensity = 10.0;
    l.position = dr_v3(0, 3, 0);
    sb_light(b, l);
}

/* Floor y = 0 (facing up) and, at y = 1, a MASK quad (facing down, double
 * sided) whose alpha is 0 on its left texel and 1 on its right (clamped,
 * bilinear between the texel centres u = 0.25 and 0.75); a point light at
 * (0, 3, 0). */
static struct dr_scene *mask_scene(enum dr_alpha_mode mode, double alpha_factor)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3s(0.8))));
    const float px[8] = {0.2f, 0.9f, 0.2f, 0.0f, 0.2f, 0.9f, 0.2f, 1.0f};
    struct dr_material m = sb_diffuse(dr_v3s(0.5));
    m.base_color_tex.texture = sb_texture(&b, sb_image(2, 1, 4, px, 0.0f, false));
    m.alpha_mode = mode;
    m.alpha = alpha_factor;
    m.double_sided = true;
    /* x from -1 (u = 0) to 1 (u = 1), facing -y */
    sb_quad(&b, dr_v3(-1, 1, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), sb_material(&b, m));
    add_overhead_light(&b);
    struct dr_scene *s = sb_finish(&b);
    for (int i = 0; i < s->n_images; i++)
        dr_image_make_linear(&s->images[i]);
    return s;
}

/* Radiance of a floor point seen from the side, below the quad's plane. */
static double floor_radiance(const struct dr_scene *s, double x)
{
    struct dr_path_opts o = {.max_depth = 2, .rr_depth = 100, .stages = dr_path_plan(s, NULL)};
    struct dr_sampler smp;
    dr_sampler_init(&smp, 1, 0, 0);
    struct dr_ray_counts c = {0};
    dr_vec3 org = dr_v3(x, 0.5, -3), d = dr_normalize(dr_sub(dr_v3(x, 0, 0), org));
    return dr_path_radiance(s, &o, org, d, &smp, &c).x;
}

static void test_mask(void)
{
    struct dr_scene *s = mask_scene(DR_ALPHA_MASK, 1.0);
    CHECK((s->effects & DR_FX_ALPHA_MASK) != 0, "alpha_mask effect");
    /* camera rays from above: x = -0.8 (u 0.1, alpha 0) is a hole, x = 0.8 solid */
    int64_t t_hole = dr_accel_intersect(s->accel, dr_v3(-0.8, 2, 0), dr_v3(0, -1, 0), 0, INFINITY);
    int64_t t_solid = dr_accel_intersect(s->accel, dr_v3(0.8, 2, 0), dr_v3(0, -1, 0), 0, INFINITY);
    CHECK(t_hole >= 0 && s->mesh.material[t_hole] == 0, "a ray through the hole reaches the floor (tri %lld)",
          (long long)t_hole);
    CHECK(t_solid >= 0 && s->mesh.material[t_solid] == 1, "a ray at the solid part stops there (tri %lld)",
          (long long)t_solid);
    CHECK(!dr_accel_occluded(s->accel, dr_v3(-0.8, 2, 0), dr_v3(0, -1, 0), 0, 1.5), "a shadow ray through the hole");
    CHECK(dr_accel_occluded(s->accel, dr_v3(0.8, 2, 0), dr_v3(0, -1, 0), 0, 1.5), "a shadow ray at the solid part");
    /* floor x = -0.6: the shadow ray crosses y = 1 at x = -0.4 (u 0.3, alpha 0.1): lit.
     * x = 0.6: crosses at u 0.7 (alpha 0.9): shadowed. Point light: E = I cos / r^2. */
    double lit = floor_radiance(s, -0.6), dark = floor_radiance(s, 0.6);
    double r2 = 0.36 + 9.0, expect = 0.8 / M_PI * 10.0 * (3.0 / sqrt(r2)) / r2;
    printf("MASK: floor under the hole %.6f (expected %.6f), under the solid part %.6f\n", lit, expect, dark);
    CHECK_NEAR(lit, expect, 1e-6 * expect, "the light reaches the floor through the hole");
    CHECK(dark == 0.0, "the solid part shadows the floor (%g)", dark);
    /* alphaCutoff: at 0.05 the texel blend 0.1 at u = 0.3 is solid */
    s->materials[1].alpha_cutoff = 0.05;
    CHECK(floor_radiance(s, -0.6) == 0.0, "cutoff 0.05: alpha 0.1 is solid");
    dr_scene_destroy(s);
}

/* ----------------------------------------------------------------- BLEND */

static void test_blend(void)
{
    struct dr_scene *s = mask_scene(DR_ALPHA_BLEND, 0.6);   /* alpha = 0.6 x texture alpha */
    CHECK((s->effects & DR_FX_ALPHA_BLEND) != 0, "alpha_blend effect");
    const int n = 40000;
    int stop = 0, occl = 0, repeat_ok = 1;
    dr_vec3 o = dr_v3(0.8, 2, 0), d = dr_v3(0, -1, 0);   /* u = 0.9: texture alpha 1 -> alpha 0.6 */
    for (int k = 0; k < n; k++) {
        uint64_t key = dr_coverage_key(dr_hash64((uint64_t)k), 1, DR_RAY_TRACE);
        int64_t t = dr_accel_intersect_key(s->accel, o, d, 0, INFINITY, key);
        stop += t >= 0 && s->mesh.material[t] == 1;
        repeat_ok &= dr_accel_intersect_key(s->accel, o, d, 0, INFINITY, key) == t;
        occl += dr_accel_occluded_key(s->accel, o, d, 0, 1.5, dr_coverage_key(dr_hash64((uint64_t)k), 1, DR_RAY_SHADOW));
    }
    double f = (double)stop / n, fo = (double)occl / n, sd = sqrt(0.6 * 0.4 / n);
    printf("BLEND alpha 0.6: %.4f of rays stop, %.4f of shadow rays blocked (sd %.4f)\n", f, fo, sd);
    CHECK(fabs(f - 0.6) < 4 * sd, "acceptance rate %.4f, expected 0.6 +- %.4f", f, 4 * sd);
    CHECK(fabs(fo - 0.6) < 4 * sd, "shadow blocking rate %.4f, expected 0.6", fo);
    CHECK(repeat_ok, "the same key gives the same decision");
    dr_scene_destroy(s);

    /* two BLEND layers of alpha 0.5: 0.25 of rays pass both */
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3s(0.8))));
    struct dr_material m = sb_diffuse(dr_v3s(0.5));
    m.alpha_mode = DR_ALPHA_BLEND;
    m.alpha = 0.5;
    m.double_sided = true;
    int mi = sb_material(&b, m);
    sb_quad(&b, dr_v3(-1, 1, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), mi);
    sb_quad(&b, dr_v3(-1, 2, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), mi);
    s = sb_finish(&b);
    int floor_hits = 0;
    for (int k = 0; k < n; k++) {
        int64_t t = dr_accel_intersect_key(s->accel, dr_v3(0.3, 3, 0.2), d, 0, INFINITY, dr_hash64((uint64_t)k + 99));
        floor_hits += t >= 0 && s->mesh.material[t] == 0;
    }
    double fp = (double)floor_hits / n, sp = sqrt(0.25 * 0.75 / n);
    printf("two BLEND layers of 0.5: %.4f pass both (expected 0.25, sd %.4f)\n", fp, sp);
    CHECK(fabs(fp - 0.25) < 4 * sp, "two layers: %.4f pass, expected 0.25 (independent decisions)", fp);
    dr_scene_destroy(s);
}

/* ------------------------------------------------------------ thin glass */

/* The floor and light of mask_scene with a thin glass pane (ior 1.5,
 * roughness 0) at y = 1 instead of the MASK quad; with_medium: inside a
 * global medium too thin to matter (1e-9 / m), so that the medium walker
 * and its shadow transmittance see the pane. */
static struct dr_scene *glass_scene(bool with_medium)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3s(0.8))));
    struct dr_material m = sb_diffuse(dr_v3(0.2, 0.5, 0.9));
    m.roughness = 0.0;
    m.double_sided = true;
    CHECK(dr_material_make_thin(&m, 1.5) == 1, "a tinted pane reports its tint dropped");
    sb_quad(&b, dr_v3(-2, 1, -2), dr_v3(4, 0, 0), dr_v3(0, 0, 4), sb_material(&b, m));
    add_overhead_light(&b);
    if (with_medium)
        sb_medium(&b, -1, medium(dr_v3s(1e-9), dr_v3s(0.0), 0.0));
    return sb_finish(&b);
}

static void test_thin_glass(void)
{
    /* R = 2F / (1 + F): F = 0.04 at normal incidence for ior 1.5; 1 at grazing; 0 for ior 1 */
    CHECK_NEAR(dr_thin_reflectance(1.0, 1.5), 0.08 / 1.04, 1e-12, "normal incidence");
    CHECK_NEAR(dr_thin_reflectance(0.0, 1.5), 1.0, 1e-12, "grazing");
    CHECK_NEAR(dr_thin_reflectance(0.7, 1.0), 0.0, 1e-12, "index-matched");
    double ct;
    const double F60 = dr_fresnel_dielectric(0.5, 1.5, &ct);
    CHECK_NEAR(dr_thin_reflectance(0.5, 1.5), 2.0 * F60 / (1.0 + F60), 1e-12, "60 degrees");
    struct dr_scene *s = glass_scene(false);
    CHECK((s->effects & DR_FX_THIN_TRANSMISSION) != 0, "thin_transmission effect");
    CHECK(s->materials[1].metallic == 1.0 && s->materials[1].base_color.x == 1.0, "the pane shades as a white metal");
    /* the fraction of rays stopped, straight down and at 60 degrees */
    const int n = 40000;
    const dr_vec3 dirs[2] = {dr_v3(0, -1, 0), dr_normalize(dr_v3(sqrt(3.0), -1, 0))};
    for (int k = 0; k < 2; k++) {
        const dr_vec3 o = dr_sub(dr_v3(0.1, 1, 0.2), dirs[k]);   /* one unit before the pane */
        int stop = 0, occl = 0, repeat_ok = 1;
        for (int i = 0; i < n; i++) {
            uint64_t key = dr_coverage_key(dr_hash64((uint64_t)i), 1, DR_RAY_TRACE);
            int64_t t = dr_accel_intersect_key(s->accel, o, dirs[k], 0, INFINITY, key);
            stop += t >= 0 && s->mesh.material[t] == 1;
            repeat_ok &= dr_accel_intersect_key(s->accel, o, dirs[k], 0, INFINITY, key) == t;
            occl += dr_accel_occluded_key(s->accel, o, dirs[k], 0, 1.5,
                                          dr_coverage_key(dr_hash64((uint64_t)i), 1, DR_RAY_SHADOW));
        }
        const double R = dr_thin_reflectance(k == 0 ? 1.0 : 0.5, 1.5), sd = sqrt(R * (1 - R) / n);
        printf("thin glass at cos %.1f: %.4f of rays stop, %.4f of shadow rays blocked (R %.4f, sd %.4f)\n",
               k == 0 ? 1.0 : 0.5, (double)stop / n, (double)occl / n, R, sd);
        CHECK(fabs((double)stop / n - R) < 4 * sd, "stop rate %.4f, expected %.4f", (double)stop / n, R);
        CHECK(fabs((double)occl / n - R) < 4 * sd, "shadow blocking rate %.4f, expected %.4f", (double)occl / n, R);
        CHECK(repeat_ok, "the same key gives the same decision");
    }
    dr_scene_destroy(s);
    /* a floor point lit through the pane: the mean over paths is (1 - R) of the
     * unobstructed irradiance's radiance (R at the shadow ray's angle); the
     * same inside a (negligible) medium, where shadow rays estimate
     * transmittance through the medium walker's own queries */
    const double x = 1.5, r2 = x * x + 9.0, cos_l = 3.0 / sqrt(r2);
    const double clear = 0.8 / M_PI * 10.0 * cos_l / r2, want = clear * (1.0 - dr_thin_reflectance(cos_l, 1.5));
    for (int with_medium = 0; with_medium < 2; with_medium++) {
        s = glass_scene(with_medium);
        struct dr_path_opts o = {.max_depth = 2, .rr_depth = 100, .stages = dr_path_plan(s, NULL)};   /* direct */
        double sum = 0.0, sum2 = 0.0;
        for (int i = 0; i < n; i++) {
            struct dr_sampler smp;
            dr_sampler_init(&smp, (uint64_t)i + 7, 0, 0);
            struct dr_ray_counts c = {0};
            dr_vec3 org = dr_v3(x, 0.5, -3), d = dr_normalize(dr_sub(dr_v3(x, 0, 0), org));
            const double L = dr_path_radiance(s, &o, org, d, &smp, &c).x;
            sum += L;
            sum2 += L * L;
        }
        const double mean = sum / n, se = sqrt((sum2 / n - mean * mean) / n);
        printf("floor through thin glass%s: %.6f +- %.6f (expected %.6f; without the pane %.6f)\n",
               with_medium ? " in a medium" : "", mean, se, want, clear);
        CHECK(!with_medium || (o.stages & DR_STAGE_MEDIA), "the medium walker runs");
        CHECK(fabs(mean - want) < 4 * se + 1e-9, "the floor through glass%s: %.6f, expected %.6f",
              with_medium ? " in a medium" : "", mean, want);
        dr_scene_destroy(s);
    }
}

/* ------------------------------------------------------------ culling */

static void test_single_sided(void)
{
    for (int ds = 0; ds < 2; ds++) {
        struct sb b;
        sb_init(&b);
        struct dr_material m = sb_diffuse(dr_v3s(0.5));
        m.double_sided = ds;
        sb_quad(&b, dr_v3(-1, -1, 0), dr_v3(2, 0, 0), dr_v3(0, 2, 0), sb_material(&b, m));   /* faces +z */
        struct dr_scene *s = sb_finish(&b);
        CHECK(((s->effects & DR_FX_SINGLE_SIDED) != 0) == !ds, "single_sided effect iff doubleSided false");
        /* rays will come from behind the quad too: without a viewpoint
         * there, the back is proved unreachable and not tested (backface.h) */
        CHECK(dr_backface_count(s->backface) == (ds ? 0 : 2), "seen from the front only, the back is unreachable");
        struct dr_camera behind = sb_camera(dr_v3(0, 0, -2), dr_v3(0, 0, 0), 40);
        CHECK(dr_scene_add_viewpoint(s, &behind) == 0 && dr_backface_count(s->backface) == 0,
              "with a viewpoint behind it, the back is reachable");
        int64_t front = dr_accel_intersect(s->accel, dr_v3(0, 0, 2), dr_v3(0, 0, -1), 0, INFINITY);
        int64_t back = dr_accel_intersect(s->accel, dr_v3(0, 0, -2), dr_v3(0, 0, 1), 0, INFINITY);
        bool occl_back = dr_accel_occluded(s->accel, dr_v3(0, 0, -2), dr_v3(0, 0, 1), 0, 4);
        bool occl_front = dr_accel_occluded(s->accel, dr_v3(0, 0, 2), dr_v3(0, 0, -1), 0, 4);
        CHECK(front >= 0, "doubleSided %d: the front is hit", ds);
        CHECK(occl_front, "doubleSided %d: the front blocks a shadow ray", ds);
        if (ds) {
            CHECK(back >= 0 && occl_back, "double-sided: the back is hit and blocks");
        } else {
            CHECK(back < 0, "single-sided: a ray from behind passes (tri %lld)", (long long)back);
            CHECK(!occl_back, "single-sided: a shadow ray from behind passes");
            /* a medium boundary is crossed from both sides: never culled */
            int mm = 0;
            s->material_medium = &mm;
            CHECK(dr_material_coverage(s, 0) == 0, "a medium boundary is not culled");
            s->material_medium = NULL;
        }
        dr_scene_destroy(s);
    }
}

/* ------------------------------------------------------- flat faces */

/* A quad facing +z whose vertex normals are n (each vertex, both
 * triangles): after dr_scene_prepare, does it still interpolate them? And
 * the shading normal a hit gets. */
static bool keeps_normals(dr_vec3 n, dr_vec3 *ns)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3s(0.5));
    m.double_sided = true;
    sb_quad(&b, dr_v3(-1, -1, 0), dr_v3(2, 0, 0), dr_v3(0, 2, 0), sb_material(&b, m));
    struct dr_mesh *mesh = &b.s->mesh;
    for (uint32_t v = 0; v < mesh->n_vertices; v++) {
        mesh->normals[3 * v] = (float)n.x;
        mesh->normals[3 * v + 1] = (float)n.y;
        mesh->normals[3 * v + 2] = (float)n.z;
    }
    for (uint32_t t = 0; t < mesh->n_triangles; t++)
        mesh->flags[t] |= DR_TRI_HAS_NORMALS;
    struct dr_scene *s = sb_finish(&b);
    bool keeps = (s->mesh.flags[0] & DR_TRI_HAS_NORMALS) && (s->mesh.flags[1] & DR_TRI_HAS_NORMALS);
    CHECK(((s->effects & DR_FX_SHADING_NORMALS) != 0) == keeps, "the shading_normals effect follows the flags");
    struct dr_hit h;
    dr_hit_compute(&s->mesh, 0, dr_v3(0.3, -0.2, 2), dr_v3(0, 0, -1), &h);
    *ns = h.ns;
    dr_scene_destroy(s);
    return keeps;
}

static void test_flat_faces(void)
{
    dr_vec3 ns;
    CHECK(!keeps_normals(dr_v3(0, 0, 1), &ns), "vertex normals equal to the face's: shaded flat");
    CHECK(ns.x == 0 && ns.y == 0 && ns.z == 1, "... with the face normal (%g %g %g)", ns.x, ns.y, ns.z);
    /* a normal off by 1e-7 (float rounding of a normalised vector) is still the face's */
    CHECK(!keeps_normals(dr_normalize(dr_v3(1e-7, 0, 1)), &ns), "a normal within 1e-7 of the face's: flat");
    /* tilted by 1e-3 rad: a smooth surface, interpolated */
    dr_vec3 tilted = dr_normalize(dr_v3(1e-3, 0, 1));
    CHECK(keeps_normals(tilted, &ns), "a normal 1e-3 off the face's is interpolated");
    CHECK(fabs(ns.x - tilted.x) < 1e-7, "... and used (ns.x %g, expected %g)", ns.x, tilted.x);
    /* facing away from the winding: authored that way, kept (normal maps
     * read the authored side) */
    CHECK(keeps_normals(dr_v3(0, 0, -1), &ns), "normals against the winding are kept");
    CHECK(keeps_normals(dr_v3(0, 0, 0), &ns), "zero normals are left to the shading's fallback");
}

int main(void)
{
    test_tangents_vs_supplied();
    test_tangents_sphere();
    test_perturbed_normal();
    test_valid_normal();
    test_mask();
    test_blend();
    test_single_sided();
    test_thin_glass();
    test_flat_faces();
    return TEST_END();
}
