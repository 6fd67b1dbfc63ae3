/* Reverse mode's standard error tells the whole truth (issue 14).
 *
 * Over many independent runs of a small L2 reverse-mode gradient (its own
 * seed each), the fraction of runs whose gradient lies within +-2 reported
 * standard errors of the mean over all runs must match what K batches
 * promise: P(|t_{K-1}| <= 2), 0.914 for K = 8 (a Student t, because the
 * standard error is itself estimated from K batches).
 *
 * Case "primal": the target is the expected image itself, so I - T is pure
 * noise of the primal image and that noise dominates the gradient's spread.
 * The old estimator (one primal shared by all batches) reports the spread of
 * the gradient samples only and must fail there; the per-batch estimator
 * must pass, and attribute most of its error to the primal.
 * Case "mixed": a target at half the image (both noises matter), and case
 * "far": a target of -10 times the image, where the gradient samples' noise
 * dominates; the per-batch estimator must pass both, and attribute the error
 * of "far" mostly to the gradient samples.
 *
 * The cross primal (each pixel's samples are their own primal, half for half;
 * reverse.h) must pass all three cases too, and be unbiased: its mean over
 * the runs must agree with the per-batch estimator's within their spreads.
 * So must it under the sobol sampler (a sample weighted at the mean of the
 * other half of its pixel's samples, the halves scrambled apart), and there
 * its runs must spread less than the independent cross primal's: the point
 * of using it. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "reverse.h"
#include "scene_builder.h"
#include "test.h"

#define RUNS 200
#define K 8
#define RES 8

static struct dr_material emitter(dr_vec3 Le)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = Le;
    return m;
}

struct coverage {
    double mean[3], sd[3];   /* of the runs' gradients */
    double inside;        /* fraction of (run, channel) within +-2 se of the mean */
    double se_gradient;   /* mean reported parts */
    double se_primal;
    double se;
};

/* RUNS independent reverse-mode runs; coverage of their reported errors. */
static struct coverage run_many_with(const struct dr_scene *s, const struct dr_camera *cam,
                                     const struct dr_param_set *ps, const float *target, enum dr_primal_mode mode,
                                     enum dr_sampler_kind sampler, int spp)
{
    static double g[RUNS][3], se[RUNS][3];
    struct coverage c = {0};
    double sg[3], sp[3];
    for (int r = 0; r < RUNS; r++) {
        struct dr_reverse_options o = {
            .estimator = dr_estimator_find("prb"), .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = K,
            .primal = mode,
            .problem = {.scene = s, .camera = cam, .params = ps, .width = RES, .height = RES, .spp = spp,
                        .max_depth = 2, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 1000 + (uint64_t)r,
                        .threads = 1, .sampler = sampler}};
        struct dr_reverse_result res = {.grad = g[r], .se = se[r], .se_gradient = sg, .se_primal = sp};
        int rc = dr_reverse_gradient(&o, target, &res);
        CHECK(rc == 0, "dr_reverse_gradient: %s", dr_last_error());
        if (rc != 0)
            return c;
        for (int ch = 0; ch < 3; ch++) {
            c.se += se[r][ch] / (3.0 * RUNS);
            if (mode == DR_PRIMAL_CROSS)
                CHECK(!res.parts && res.primal_run == DR_PRIMAL_CROSS && res.t_primal == 0.0,
                      "cross: no parts, no render");
            if (mode == DR_PRIMAL_PER_BATCH) {
                CHECK(res.parts && isfinite(sg[ch]) && isfinite(sp[ch]), "parts missing");
                /* the parts add up to the total (in variance) */
                CHECK(sg[ch] * sg[ch] + sp[ch] * sp[ch] >= se[r][ch] * se[r][ch] * (1 - 1e-9) || sp[ch] == 0.0,
                      "parts do not add up");
                c.se_gradient += sg[ch] / (3.0 * RUNS);
                c.se_primal += sp[ch] / (3.0 * RUNS);
            }
        }
    }
    for (int ch = 0; ch < 3; ch++) {
        double mean = 0.0;
        for (int r = 0; r < RUNS; r++)
            mean += g[r][ch] / RUNS;
        double var = 0.0;
        for (int r = 0; r < RUNS; r++) {
            c.inside += fabs(g[r][ch] - mean) <= 2.0 * se[r][ch] ? 1.0 / (3.0 * RUNS) : 0.0;
            var += (g[r][ch] - mean) * (g[r][ch] - mean) / (RUNS - 1);
        }
        c.mean[ch] = mean;
        c.sd[ch] = sqrt(var);
    }
    return c;
}

static struct coverage run_many(const struct dr_scene *s, const struct dr_camera *cam,
                                const struct dr_param_set *ps, const float *target, enum dr_primal_mode mode)
{
    return run_many_with(s, cam, ps, target, mode, DR_SAMPLER_INDEPENDENT, 2 * K);
}

int main(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.6, 0.6))));
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, emitter(dr_v3(3, 2, 1))));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50);
    const char *ptr = "/materials/0/pbrMetallicRoughness/baseColorFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "%s", dr_last_error());
    if (!ps)
        return TEST_END();
    /* the expected image, to rounding: 8192 spp */
    float target[RES * RES * 3], dim[RES * RES * 3], neg[RES * RES * 3];
    struct dr_render_opts ro = {.width = RES, .height = RES, .spp = 8192, .max_depth = 2,
                                .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 777, .threads = 2};
    CHECK(dr_render(s, &cam, &ro, target, NULL) == 0, "%s", dr_last_error());
    for (int i = 0; i < RES * RES * 3; i++)
        dim[i] = 0.5f * target[i], neg[i] = -10.0f * target[i];

    /* P(|t_7| <= 2) = 0.9144; 200 runs x 3 channels: binomial sd ~ 0.016 (channels are correlated) */
    const double want = 0.9144, lo = want - 0.07, hi = want + 0.06;
    struct coverage old = run_many(s, &cam, ps, target, DR_PRIMAL_SHARED);
    struct coverage now = run_many(s, &cam, ps, target, DR_PRIMAL_PER_BATCH);
    struct coverage mixed = run_many(s, &cam, ps, dim, DR_PRIMAL_PER_BATCH);
    /* far from the target (I - T ~ 11 I): the gradient samples' noise dominates */
    struct coverage far = run_many(s, &cam, ps, neg, DR_PRIMAL_PER_BATCH);
    printf("primal-dominated: shared primal covers %.3f (mean se %.3g); per-batch covers %.3f (mean se %.3g = "
           "gradient %.3g + primal %.3g in quadrature)\n",
           old.inside, old.se, now.inside, now.se, now.se_gradient, now.se_primal);
    printf("mixed: per-batch covers %.3f (se %.3g: gradient %.3g, primal %.3g)\n", mixed.inside, mixed.se,
           mixed.se_gradient, mixed.se_primal);
    CHECK(old.inside < lo, "the shared-primal estimator should undercover here: %.3f", old.inside);
    CHECK(now.inside >= lo && now.inside <= hi, "per-batch coverage %.3f outside [%.3f, %.3f]", now.inside, lo, hi);
    CHECK(mixed.inside >= lo && mixed.inside <= hi, "mixed coverage %.3f outside [%.3f, %.3f]", mixed.inside, lo,
          hi);
    printf("far: per-batch covers %.3f (se %.3g: gradient %.3g, primal %.3g)\n", far.inside, far.se,
           far.se_gradient, far.se_primal);
    CHECK(far.inside >= lo && far.inside <= hi, "far coverage %.3f outside [%.3f, %.3f]", far.inside, lo, hi);
    CHECK(far.se_gradient > 2.0 * far.se_primal, "gradient part %.3g should dominate primal part %.3g",
          far.se_gradient, far.se_primal);
    CHECK(now.se_primal > 2.0 * now.se_gradient, "primal part %.3g should dominate gradient part %.3g",
          now.se_primal, now.se_gradient);

    /* the cross primal: honest errors in all three cases, and unbiased */
    const float *targets[3] = {target, dim, neg};
    const struct coverage *separate[3] = {&now, &mixed, &far};
    const char *names[3] = {"primal-dominated", "mixed", "far"};
    for (int k = 0; k < 3; k++) {
        struct coverage x = run_many(s, &cam, ps, targets[k], DR_PRIMAL_CROSS);
        printf("%s: cross covers %.3f (mean se %.3g; runs' sd %.3g %.3g %.3g, separate's %.3g %.3g %.3g)\n", names[k],
               x.inside, x.se, x.sd[0], x.sd[1], x.sd[2], separate[k]->sd[0], separate[k]->sd[1], separate[k]->sd[2]);
        CHECK(x.inside >= lo && x.inside <= hi, "%s: cross coverage %.3f outside [%.3f, %.3f]", names[k], x.inside, lo,
              hi);
        for (int ch = 0; ch < 3; ch++) {
            double tol = 4.0 * sqrt((x.sd[ch] * x.sd[ch] + separate[k]->sd[ch] * separate[k]->sd[ch]) / RUNS);
            CHECK(fabs(x.mean[ch] - separate[k]->mean[ch]) <= tol, "%s: cross mean %.6g vs separate %.6g (tol %.3g)",
                  names[k], x.mean[ch], separate[k]->mean[ch], tol);
        }
    }

    /* the cross primal under the sobol sampler (a pixel's two halves
     * scrambled apart, each sample weighted by the other half's mean): honest
     * and unbiased too, at 8 samples a batch (halves of 4), against the
     * per-batch estimator with independent numbers at the same spp; and with
     * less spread than the independent cross primal there */
    for (int k = 0; k < 3; k++) {
        struct coverage ind = run_many_with(s, &cam, ps, targets[k], DR_PRIMAL_PER_BATCH, DR_SAMPLER_INDEPENDENT, 8 * K);
        struct coverage x = run_many_with(s, &cam, ps, targets[k], DR_PRIMAL_CROSS, DR_SAMPLER_SOBOL, 8 * K);
        struct coverage xi = run_many_with(s, &cam, ps, targets[k], DR_PRIMAL_CROSS, DR_SAMPLER_INDEPENDENT, 8 * K);
        printf("%s, 8 spp a batch: sobol cross covers %.3f (mean se %.3g; runs' sd %.3g %.3g %.3g; independent "
               "cross's %.3g %.3g %.3g; separate's %.3g %.3g %.3g)\n", names[k], x.inside, x.se, x.sd[0], x.sd[1],
               x.sd[2], xi.sd[0], xi.sd[1], xi.sd[2], ind.sd[0], ind.sd[1], ind.sd[2]);
        CHECK(x.inside >= lo && x.inside <= hi, "%s: sobol cross coverage %.3f outside [%.3f, %.3f]", names[k],
              x.inside, lo, hi);
        for (int ch = 0; ch < 3; ch++) {
            double tol = 4.0 * sqrt((x.sd[ch] * x.sd[ch] + ind.sd[ch] * ind.sd[ch]) / RUNS);
            CHECK(fabs(x.mean[ch] - ind.mean[ch]) <= tol, "%s: sobol cross mean %.6g vs separate %.6g (tol %.3g)",
                  names[k], x.mean[ch], ind.mean[ch], tol);
            CHECK(x.sd[ch] < 0.85 * xi.sd[ch], "%s: sobol cross spread %.3g not below independent cross's %.3g",
                  names[k], x.sd[ch], xi.sd[ch]);
        }
    }
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
    return TEST_END();
}
