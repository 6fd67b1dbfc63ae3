/* What the honest reverse-mode standard error (drivers/reverse.h) costs:
 * times one L2 reverse-mode gradient on a scene with the estimator drender
 * used before (one primal at the full spp shared by all batches) and with
 * per-batch primals (K renders of spp/K, two estimator runs per batch), and
 * prints their seconds, primal shares and reported standard errors as JSON.
 * Then the cross primal (no render: the gradient's samples are their own
 * primal) against per-batch primals over RUNS seeds each: mean seconds, the
 * runs' spread of the first gradient entry, and the efficiency ratio
 * (variance x time of per-batch / of cross; > 1: cross is cheaper for the
 * same accuracy); then the cross primal with sobol numbers (each sample
 * weighted at the other half of its pixel's samples) against it with
 * independent ones, the same way.
 *
 * usage: reverse_stderr SCENE PARAM [WxH] [SPP] [K] [THREADS]
 * The target is the scene rendered at 4 x SPP with PARAM's values scaled by 0.8. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "clock.h"
#include "error.h"
#include "reverse.h"

struct timing {
    double seconds, primal, gradient, se, g0;
};

static int time_mode(const struct dr_reverse_options *base, enum dr_primal_mode mode, const float *target,
                     int64_t T, struct timing *out)
{
    double *buf = calloc(4 * (size_t)T, sizeof(double));
    if (!buf)
        return DR_ERR_NOMEM;
    struct dr_reverse_options o = *base;
    o.primal = mode;
    struct dr_reverse_result r = {.grad = buf, .se = buf + T, .se_gradient = buf + 2 * T, .se_primal = buf + 3 * T};
    double t0 = dr_clock_seconds();
    int rc = dr_reverse_gradient(&o, target, &r);
    *out = (struct timing){dr_clock_seconds() - t0, r.t_primal, r.t_gradient, buf[T], buf[0]};
    free(buf);
    return rc;
}

#define RUNS 8

/* RUNS runs of mode with seeds 100..: mean seconds and the spread (sample
 * standard deviation) of the first gradient entry. */
static int spread(const struct dr_reverse_options *base, enum dr_primal_mode mode, enum dr_sampler_kind sampler,
                  const float *target, int64_t T, double *seconds, double *sd)
{
    double g[RUNS], mean = 0.0, var = 0.0;
    *seconds = 0.0;
    for (int r = 0; r < RUNS; r++) {
        struct dr_reverse_options o = *base;
        o.problem.seed = 100 + (uint64_t)r;
        o.problem.sampler = sampler;
        struct timing t;
        int rc = time_mode(&o, mode, target, T, &t);
        if (rc != 0)
            return rc;
        *seconds += t.seconds / RUNS;
        g[r] = t.g0;
        mean += g[r] / RUNS;
    }
    for (int r = 0; r < RUNS; r++)
        var += (g[r] - mean) * (g[r] - mean) / (RUNS - 1);
    *sd = sqrt(var);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: reverse_stderr SCENE PARAM [WxH] [SPP] [K] [THREADS]\n");
        return 2;
    }
    int w = 128, h = 128, spp = argc > 4 ? atoi(argv[4]) : 32, K = argc > 5 ? atoi(argv[5]) : 4;
    int threads = argc > 6 ? atoi(argv[6]) : 2;
    if (argc > 3 && sscanf(argv[3], "%dx%d", &w, &h) != 2)
        return 2;
    struct dr_scene *s = dr_scene_load(argv[1]);
    if (!s) {
        fprintf(stderr, "%s\n", dr_last_error());
        return 3;
    }
    struct dr_camera cam = s->n_cameras > 0 ? s->cameras[0] : dr_camera_default(s);
    const char *ptr = argv[2];
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    float *target = malloc(sizeof(float) * 3 * (size_t)w * h);
    double *theta = ps ? malloc(sizeof(double) * (size_t)ps->total) : NULL;
    if (!ps || !target || !theta) {
        fprintf(stderr, "%s\n", dr_last_error());
        return 2;
    }
    dr_param_set_get(s, ps, theta);
    for (int64_t i = 0; i < ps->total; i++)
        theta[i] *= 0.8;
    dr_param_set_put(s, ps, theta);
    dr_scene_refresh(s);
    struct dr_render_opts ro = {.width = w, .height = h, .spp = 4 * spp, .max_depth = 8,
                                .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 99, .threads = threads};
    dr_render(s, &cam, &ro, target, NULL);
    for (int64_t i = 0; i < ps->total; i++)
        theta[i] /= 0.8;
    dr_param_set_put(s, ps, theta);
    dr_scene_refresh(s);
    struct dr_reverse_options o = {
        .estimator = dr_estimator_find("prb"), .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = K,
        .problem = {.scene = s, .camera = &cam, .params = ps, .width = w, .height = h, .spp = spp, .max_depth = 8,
                    .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 1, .threads = threads}};
    struct timing old, now;
    time_mode(&o, DR_PRIMAL_SHARED, target, ps->total, &old);   /* warm-up */
    if (time_mode(&o, DR_PRIMAL_SHARED, target, ps->total, &old) != 0 ||
        time_mode(&o, DR_PRIMAL_PER_BATCH, target, ps->total, &now) != 0) {
        fprintf(stderr, "%s\n", dr_last_error());
        return 1;
    }
    double t_sep, sd_sep, t_cross, sd_cross, t_sobol, sd_sobol;
    if (spread(&o, DR_PRIMAL_PER_BATCH, DR_SAMPLER_INDEPENDENT, target, ps->total, &t_sep, &sd_sep) != 0 ||
        spread(&o, DR_PRIMAL_CROSS, DR_SAMPLER_INDEPENDENT, target, ps->total, &t_cross, &sd_cross) != 0 ||
        spread(&o, DR_PRIMAL_CROSS, DR_SAMPLER_SOBOL, target, ps->total, &t_sobol, &sd_sobol) != 0) {
        fprintf(stderr, "%s\n", dr_last_error());
        return 1;
    }
    printf("{\"shared_primal\": {\"seconds\": %.4f, \"primal_share\": %.3f, \"stderr0\": %.4g}, "
           "\"per_batch_primal\": {\"seconds\": %.4f, \"primal_share\": %.3f, \"stderr0\": %.4g}, "
           "\"time_ratio\": %.3f, \"runs\": %d, \"per_batch_runs\": {\"seconds\": %.4f, \"sd0\": %.4g}, "
           "\"cross_runs\": {\"seconds\": %.4f, \"sd0\": %.4g}, \"cross_time_ratio\": %.3f, "
           "\"cross_efficiency\": %.3f, \"sobol_cross_runs\": {\"seconds\": %.4f, \"sd0\": %.4g}, "
           "\"sobol_cross_efficiency\": %.3f}\n",
           old.seconds, old.primal / old.seconds, old.se, now.seconds, now.primal / now.seconds, now.se,
           now.seconds / old.seconds, RUNS, t_sep, sd_sep, t_cross, sd_cross, t_cross / t_sep,
           sd_sep * sd_sep * t_sep / (sd_cross * sd_cross * t_cross), t_sobol, sd_sobol,
           sd_cross * sd_cross * t_cross / (sd_sobol * sd_sobol * t_sobol));
    free(theta);
    free(target);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
    return 0;
}
