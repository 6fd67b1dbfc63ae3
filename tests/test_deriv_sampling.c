/* --sampling derivative (core/path_deriv.c) on the bundled Cornell box:
 * agreement with finite differences within 3 standard errors for the red
 * wall's albedo, the gold sphere's roughness at 0.1 and 0.5 and its metallic
 * factor, and (--sampling derivative-roughness) its roughness and metallic
 * together, in reverse and forward mode, under a clear coat (the gold's
 * roughness and the coat's), and in two scenes with media; forward and reverse see the same
 * numbers (equal to rounding); and the gradient's standard error against
 * detached sampling's with the same seeds where the forward sampler is known
 * to be poor: a near-specular roughness (0.1), whose derivative lobe is
 * signed with parts ~1/alpha that the antithetic pair cancels. The other
 * fdcheck cases (glossy, near-specular, environment maps, ...) run every
 * sampling mode in test_fdcheck.c. */
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "fdcheck.h"
#include "scene_builder.h"
#include "test.h"

static struct dr_scene *load_cornell(void)
{
    const char *path = scene_path("cornell-box.gltf");
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "load: %s", dr_last_error());
    return s;
}

static int set_value(struct dr_scene *s, const char *ptr, double v)
{
    struct dr_param p;
    if (dr_param_resolve(s, ptr, &p) != 0)
        return -1;
    double vals[3] = {v, v, v};
    dr_param_put(s, &p, vals);
    return dr_scene_refresh(s);
}

/* The objective: the mean of the 24x24 frame, or of the 9x9 crop around the
 * gold sphere (whose parameters barely move the whole frame's mean). */
enum region { FRAME, SPHERE };

/* Runs fdcheck for one parameter; returns the worst |z| and the mean
 * gradient standard error over the components (for the variance comparison).
 * resolve: the finite difference must be resolved (|fd| > 3 se), so that
 * agreement means something. */
static double fd_case_n(struct dr_scene *s, const char *name, const char *const *ptrs, int n, enum dr_sampling smp,
                        double eps, enum region region, bool resolve, double *mean_se)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: %s", name, dr_last_error());
    if (!ps)
        return INFINITY;
    struct dr_fd_options o = {.estimator = dr_estimator_find("prb"), .sampling = smp, .width = 24, .height = 24,
                              .spp = 64, .batches = 16, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT,
                              .seed = 4321, .threads = 2, .eps = eps, .z_max = 3.0};
    if (region == SPHERE) {
        o.width = o.height = 9;
        o.film.frame_w = o.film.frame_h = 24;
        o.film.x0 = 9;
        o.film.y0 = 12;
    }
    struct dr_fd_entry *en = NULL;
    int count = 0;
    int rc = dr_fdcheck(s, &s->cameras[0], ps, &o, &en, &count);
    CHECK(rc == 0 && count > 0, "%s: fdcheck failed: %s", name, dr_last_error());
    double worst = 0.0, se = 0.0;
    for (int i = 0; i < count; i++) {
        printf("%-14s %-10s %-56s rev %.5g +- %.2g  fwd %.5g +- %.2g  fd %.5g +- %.2g  z %.2f %.2f\n", name,
               dr_sampling_name(smp), en[i].label, en[i].reverse, en[i].reverse_se, en[i].forward, en[i].forward_se,
               en[i].fd, en[i].fd_se, en[i].z_reverse, en[i].z_forward);
        CHECK(isfinite(en[i].reverse) && isfinite(en[i].forward), "%s: %s not finite", name, en[i].label);
        CHECK(en[i].agree, "%s (%s): %s: gradient %.6g/%.6g vs finite differences %.6g +- %.2g (z %.2f, %.2f > 3)",
              name, dr_sampling_name(smp), en[i].label, en[i].reverse, en[i].forward, en[i].fd, en[i].fd_se,
              en[i].z_reverse, en[i].z_forward);
        /* a check that cannot fail is no check: the derivative must be resolved */
        CHECK(!resolve || fabs(en[i].fd) > 3.0 * en[i].fd_se,
              "%s: %s: finite differences too noisy to judge (%.3g +- %.3g)", name, en[i].label, en[i].fd, en[i].fd_se);
        /* forward and reverse mode walk the same paths with the same numbers */
        CHECK(fabs(en[i].reverse - en[i].forward) <= 1e-6 * (fabs(en[i].reverse) + 1e-12),
              "%s: %s: reverse %.17g vs forward %.17g", name, en[i].label, en[i].reverse, en[i].forward);
        worst = fmax(worst, fmax(fabs(en[i].z_reverse), fabs(en[i].z_forward)));
        se += en[i].reverse_se / count;
    }
    free(en);
    dr_param_set_destroy(ps);
    if (mean_se)
        *mean_se = se;
    return worst;
}

/* One parameter. */
static double fd_case(struct dr_scene *s, const char *name, const char *ptr, enum dr_sampling smp, double eps,
                      enum region region, bool resolve, double *mean_se)
{
    return fd_case_n(s, name, &ptr, 1, smp, eps, region, resolve, mean_se);
}

/* test_fdcheck.c's occluder edge: a rough metal floor reflecting a dark
 * plate's edge, where attached sampling misses the boundary term (64% bias).
 * Derivative sampling differentiates no visibility either, but moves no
 * sample: it must agree. */
static void occluder_edge(void)
{
    struct dr_camera cam;
    struct dr_scene *s = sb_occluder_edge(&cam);
    const char *p = "/materials/0/pbrMetallicRoughness/roughnessFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &p, 1);
    struct dr_fd_options o = {.estimator = dr_estimator_find("prb"), .sampling = DR_SAMPLING_DERIVATIVE,
                              .width = 16, .height = 16, .spp = 32, .batches = 8, .max_depth = 2,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 7, .threads = 2, .eps = 1e-2, .z_max = 3.0};
    struct dr_fd_entry *en = NULL;
    int count = 0;
    CHECK(ps && dr_fdcheck(s, &cam, ps, &o, &en, &count) == 0 && count == 1, "occluder edge: %s", dr_last_error());
    if (en && count == 1) {
        printf("occluder-edge derivative %.5g +- %.2g vs fd %.5g +- %.2g (z %.2f %.2f)\n", en->reverse, en->reverse_se,
               en->fd, en->fd_se, en->z_reverse, en->z_forward);
        CHECK(en->agree, "occluder edge: derivative sampling disagrees (z %.2f)", en->z_reverse);
        CHECK(fabs(en->fd) > 3.0 * en->fd_se, "occluder edge: finite differences unresolved");
    }
    free(en);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* In scenes with media the radiance walks are the medium walker's
 * (path_deriv.h). On the bounded fog (a dielectric-bounded cube, a point
 * light and the sky) with the floor made a metal of roughness 0.2, its
 * colour under derivative sampling (the third strategy's emission weights
 * read the vertex's arrival state, prev_p and prev_sky, which the medium
 * walker did not keep: 12 % too large, z ~6) and, on the smoke grid, the
 * floor's roughness at 0.3 under derivative-roughness (resolved). Smaller
 * runs than fd_case's: the medium walker walks one path at a time. */
static double media_case(const char *file, const char *name, const char *const *ptrs, int n, enum dr_sampling smp,
                         double roughness)
{
    struct dr_scene *s = dr_scene_load(path_in("DR_TESTDIR", "tests", file));
    CHECK(s != NULL, "%s: load: %s", name, dr_last_error());
    if (!s)
        return INFINITY;
    const char *metal = "/materials/1/pbrMetallicRoughness/metallicFactor";
    const char *rough = "/materials/1/pbrMetallicRoughness/roughnessFactor";
    CHECK(set_value(s, metal, 1.0) == 0 && set_value(s, rough, roughness) == 0, "%s: --set: %s", name, dr_last_error());
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: %s", name, dr_last_error());
    struct dr_fd_options o = {.estimator = dr_estimator_find("prb"), .sampling = smp, .width = 16, .height = 16,
                              .spp = 16, .batches = 8, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 4321,
                              .threads = 2, .eps = 1e-2, .z_max = 3.0};
    struct dr_fd_entry *en = NULL;
    int count = 0;
    double worst = 0.0;
    CHECK(ps && dr_fdcheck(s, &s->cameras[0], ps, &o, &en, &count) == 0 && count > 0, "%s: fdcheck: %s", name,
          dr_last_error());
    for (int i = 0; i < count; i++) {
        printf("%-14s %-20s %-52s rev %.5g +- %.2g  fd %.5g +- %.2g  z %.2f %.2f\n", name, dr_sampling_name(smp),
               en[i].label, en[i].reverse, en[i].reverse_se, en[i].fd, en[i].fd_se, en[i].z_reverse, en[i].z_forward);
        CHECK(en[i].agree, "%s (%s): %s: gradient %.6g vs finite differences %.6g +- %.2g (z %.2f, %.2f > 3)", name,
              dr_sampling_name(smp), en[i].label, en[i].reverse, en[i].fd, en[i].fd_se, en[i].z_reverse,
              en[i].z_forward);
        CHECK(fabs(en[i].fd) > 3.0 * en[i].fd_se, "%s: %s: finite differences too noisy to judge (%.3g +- %.3g)", name,
              en[i].label, en[i].fd, en[i].fd_se);
        worst = fmax(worst, fmax(fabs(en[i].z_reverse), fabs(en[i].z_forward)));
    }
    free(en);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
    return worst;
}

int main(void)
{
    occluder_edge();
    static const char *red = "/materials/red/pbrMetallicRoughness/baseColorFactor";
    static const char *rough = "/materials/rough-gold/pbrMetallicRoughness/roughnessFactor";
    static const char *metal = "/materials/rough-gold/pbrMetallicRoughness/metallicFactor";
    struct dr_scene *s = load_cornell();
    if (!s)
        return TEST_END();
    double worst = 0.0;
    worst = fmax(worst, fd_case(s, "red-albedo", red, DR_SAMPLING_DERIVATIVE, 1e-2, FRAME, true, NULL));
    worst = fmax(worst, fd_case(s, "gold-metallic", metal, DR_SAMPLING_DERIVATIVE, 1e-2, SPHERE, true, NULL));
    /* At roughness 0.1 the sphere's mean hardly moves with roughness (the
     * highlights sharpen, the energy stays): agreement is checked, resolution
     * is not (it would take ~100x the samples); the standard error against
     * detached sampling's is what the pair is for. */
    CHECK(set_value(s, rough, 0.1) == 0, "--set roughness 0.1: %s", dr_last_error());
    double se_d = 0.0, se_det = 0.0;
    worst = fmax(worst, fd_case(s, "gold-rough-0.1", rough, DR_SAMPLING_DERIVATIVE, 1e-2, SPHERE, false, &se_d));
    fd_case(s, "gold-rough-0.1", rough, DR_SAMPLING_DETACHED, 1e-2, SPHERE, false, &se_det);
    printf("gold roughness 0.1: gradient standard error %.3g (derivative) vs %.3g (detached)\n", se_d, se_det);
    CHECK(se_d < 0.75 * se_det, "gold roughness 0.1: derivative sampling's standard error %g is not clearly below "
          "detached's %g", se_d, se_det);
    CHECK(set_value(s, rough, 0.5) == 0, "--set roughness 0.5: %s", dr_last_error());
    worst = fmax(worst, fd_case(s, "gold-rough-0.5", rough, DR_SAMPLING_DERIVATIVE, 1e-2, SPHERE, true, NULL));
    /* derivative-roughness: the roughness's directions beside a metallic left
     * to detached sampling's strategies (path_deriv.c's vertex_dparams) */
    const char *rough_metal[] = {rough, metal};
    worst = fmax(worst, fd_case_n(s, "gold-rough+metal", rough_metal, 2, DR_SAMPLING_DERIVATIVE_ROUGHNESS, 1e-2, SPHERE,
                                  true, NULL));
    /* under a clear coat (bsdf_coat.c): the base's roughness (its pair, the
     * integrand times the coat's transmission) and the coat's own roughness
     * at 0.1 (a pair of its own at the coat's alpha), whose standard error
     * must again beat detached sampling's */
    static const char *coat_rough = "/materials/rough-gold/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor";
    struct dr_material *gold = NULL;
    for (int m = 0; m < s->n_materials; m++)
        if (strcmp(s->materials[m].name, "rough-gold") == 0)
            gold = &s->materials[m];
    CHECK(gold != NULL, "the bundled box has its rough-gold material");
    if (gold) {
        gold->coated = true, gold->coat = 0.8, gold->coat_roughness = 0.1;
        CHECK(dr_scene_refresh(s) == 0 && (s->effects & DR_FX_CLEARCOAT), "coat the gold sphere: %s", dr_last_error());
        worst = fmax(worst, fd_case(s, "coated-gold-rough", rough, DR_SAMPLING_DERIVATIVE, 1e-2, SPHERE, true, NULL));
        worst = fmax(worst, fd_case(s, "coat-rough-0.1", coat_rough, DR_SAMPLING_DERIVATIVE, 1e-2, SPHERE, false, &se_d));
        fd_case(s, "coat-rough-0.1", coat_rough, DR_SAMPLING_DETACHED, 1e-2, SPHERE, false, &se_det);
        printf("coat roughness 0.1: gradient standard error %.3g (derivative) vs %.3g (detached)\n", se_d, se_det);
        CHECK(se_d < 0.75 * se_det, "coat roughness 0.1: derivative sampling's standard error %g is not clearly below "
              "detached's %g", se_d, se_det);
    }
    const char *floor_colour[] = {"/materials/1/pbrMetallicRoughness/baseColorFactor"};
    const char *floor_rough[] = {"/materials/1/pbrMetallicRoughness/roughnessFactor"};
    worst = fmax(worst, media_case("data/media/fog-khr.gltf", "fog-floor", floor_colour, 1, DR_SAMPLING_DERIVATIVE, 0.2));
    worst = fmax(worst, media_case("data/media/smoke-vdb.gltf", "smoke-floor", floor_rough, 1,
                                   DR_SAMPLING_DERIVATIVE_ROUGHNESS, 0.3));
    printf("worst |z| of derivative sampling: %.2f\n", worst);
    dr_scene_destroy(s);
    return TEST_END();
}
