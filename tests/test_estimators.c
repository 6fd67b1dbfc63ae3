/* tape and prb: with the same random numbers they compute the same gradient
 * (to rounding: 1e-9 relative), in reverse and forward mode and with the
 * cross primal (the adjoint from the paths themselves), on the bundled
 * Cornell box (area light, textures, rough metal, shading normals) and on a
 * glossy scene; and both agree with the plain renderer's primal. */
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include "camera.h"
#include "common.h"
#include "error.h"
#include "exact_sum.h"
#include "loss.h"
#include "normal_map.h"
#include "path_deriv.h"
#include "estimator.h"
#include "render.h"
#include "reverse.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"
#include "wave_soa.h"
#include "wavefront.h"

static const int W = 24, H = 20;

static double rel_err(double a, double b)
{
    double m = fmax(fabs(a), fabs(b));
    return m > 0 ? fabs(a - b) / m : 0.0;
}

#define MAX_EST 8

/* max over parameters of (max |a - b| over its scalars / max |gradient|):
 * for a scalar parameter the plain relative error; for a texture relative to
 * its largest texel gradient, since PRB's subtraction leaves ~1e-20 where the
 * tape has exact zeros. Checks no parameter's gradient is identically zero. */
static double reverse_difference(const char *what, const struct dr_param_set *ps, const double *a, const double *b)
{
    double worst = 0;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *pp = &ps->params[k];
        double diff = 0, scale = 0;
        for (int64_t i = pp->offset; i < pp->offset + pp->size; i++) {
            diff = fmax(diff, fabs(a[i] - b[i]));
            scale = fmax(scale, fmax(fabs(a[i]), fabs(b[i])));
        }
        CHECK(scale > 0, "%s: %s: gradient identically zero", what, pp->name);
        worst = fmax(worst, scale > 0 ? diff / scale : 0.0);
    }
    return worst;
}

/* Every registered estimator on the same problem and random numbers; every
 * pair must agree to rounding, in both modes, and each must be bit-identical
 * when repeated (resumable optimisation relies on it). */
/* Which estimators shade vertices eight lanes at a time (path_simd.h):
 * prb's primal walks and replays wherever no light is dark (also with light
 * and BSDF parameters: the stages mark those vertices and fill what their
 * adjoints read, so replays group even where every material has a BSDF
 * parameter, as in the glossy scene), the tape's compact steps only where
 * no light has a parameter; in prb's one-path modes (attached, derivative
 * sampling) its primal walks only, not its replays (GROUPED_WALKS). Under
 * attached sampling the tape's record too, up to each path's first moving
 * vertex (whole vertices from there on: next_whole); under derivative
 * sampling its record but for the vertices on materials with a BSDF
 * parameter and the ones right after them, and its new directions'
 * radiance walks, walked ahead of the sweep (walk_ahead), beyond their
 * first vertex: so even where every material has a BSDF parameter, as in
 * the glossy scene. */
enum grouping { GROUPED_WALKS, GROUPED_BOTH };

/* dr_estimator_forward_groups: the parameters in up to three groups, one
 * pass; each group's image is, to the bit, the one pass's image along dir
 * with every other group's entries 0 (grad -o's several parameters). Under
 * mis sampling only one group is allowed. */
static void forward_groups_match(const char *what, const struct dr_estimator_ops *est, const struct dr_grad_problem *p,
                                 const double *dir)
{
    const struct dr_param_set *ps = p->params;
    const int n_groups = ps->n < 3 ? ps->n : 3;
    int64_t group_end[3];
    for (int g = 0; g < n_groups; g++) {   /* (parameters 0 .. n-1 split as evenly as they go) */
        const struct dr_param *last = &ps->params[(g + 1) * ps->n / n_groups - 1];
        group_end[g] = last->offset + last->size;
    }
    double *img[3], *one = malloc(sizeof(double) * 3 * W * H), *masked = malloc(sizeof(double) * (size_t)ps->total);
    for (int g = 0; g < n_groups; g++)
        img[g] = malloc(sizeof(double) * 3 * W * H);
    CHECK(dr_estimator_forward_groups(est, p, dir, n_groups, group_end, img, NULL) == 0, "%s: %s forward groups: %s",
          what, est->name, dr_last_error());
    int64_t differ = 0, nonzero = 0;
    for (int g = 0; g < n_groups; g++) {
        const int64_t begin = g ? group_end[g - 1] : 0;
        for (int64_t i = 0; i < ps->total; i++)
            masked[i] = i >= begin && i < group_end[g] ? dir[i] : 0.0;
        CHECK(dr_estimator_forward(est, p, masked, one, NULL) == 0, "%s: %s forward: %s", what, est->name,
              dr_last_error());
        for (int i = 0; i < 3 * W * H; i++) {
            differ += memcmp(&one[i], &img[g][i], sizeof(double)) != 0;
            nonzero += img[g][i] != 0.0;
        }
    }
    CHECK(differ == 0 && nonzero > 0, "%s: %s: %lld values of %d groups' images differ from one pass per group "
          "(%lld non-zero)", what, est->name, (long long)differ, n_groups, (long long)nonzero);
    struct dr_grad_problem mis = *p;
    mis.sampling = DR_SAMPLING_MIS;
    if (n_groups > 1 && dr_est_sampling_run(&mis) == DR_SAMPLING_MIS)
        CHECK(dr_estimator_forward_groups(est, &mis, dir, n_groups, group_end, img, NULL) != 0,
              "%s: %s: forward groups under mis sampling accepted", what, est->name);
    for (int g = 0; g < n_groups; g++)
        free(img[g]);
    free(one);
    free(masked);
}


static void compare(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n,
                    int depth, enum dr_sampling sampling, enum grouping grouping)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    /* past the wavefront's replay log (DR_WAVE_REPLAY_DEPTH vertices), no
     * roulette: every path is that long, so prb's replay traces its tail again */
    const int rr_depth = depth > DR_WAVE_REPLAY_DEPTH ? depth : DR_RR_DEPTH_DEFAULT;
    struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 3,
                                .max_depth = depth, .rr_depth = rr_depth, .seed = 11, .threads = 2,
                                .sampling = sampling, .regularize = DR_PRB_REGULARIZE_DEFAULT};   /* (attached) */
    int ne = 0;
    while (dr_estimators[ne] && ne < MAX_EST)
        ne++;
    CHECK(ne >= 2, "%s: fewer than two estimators registered (%d)", what, ne);
    float *adj = malloc(sizeof(float) * 3 * W * H);
    struct dr_sampler r;
    dr_sampler_init(&r, 5, 6, 7);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(dr_sampler_next(&r) - 0.3);
    double *dir = malloc(sizeof(double) * (size_t)ps->total);
    for (int64_t i = 0; i < ps->total; i++)
        dir[i] = dr_sampler_next(&r) - 0.5;
    double *g[MAX_EST], *f[MAX_EST];
    double *again = calloc((size_t)ps->total, sizeof(double));
    for (int e = 0; e < ne; e++) {
        const struct dr_estimator_ops *est = dr_estimators[e];
        g[e] = calloc((size_t)ps->total, sizeof(double));
        f[e] = calloc(3 * W * H, sizeof(double));
        struct dr_grad_stats st = {0};
        p.batch = e % 2 ? 97 : 0;   /* tape: several record/sweep batches */
        CHECK(dr_estimator_backward(est, &p, adj, g[e], &st) == 0, "%s: %s backward: %s", what, est->name,
              dr_last_error());
        CHECK(st.memory_bytes > 0, "%s: %s reports no memory", what, est->name);
        CHECK(st.memory_bytes >= st.record_bytes, "%s: %s: record bytes exceed its memory", what, est->name);
        /* prb's walks and the tape's compact steps (detached sampling) shade
         * the vertices eight lanes at a time (path_simd.h; in the tape's
         * since 2026-12-06 those with a light's or a BSDF parameter's term
         * too, handed to its record whole: wave_soa.c's steps) */
        const bool is_prb = strcmp(est->name, "prb") == 0;
        CHECK(st.rays.simd_vertices > 0, "%s: %s shaded no vertex eight lanes at a time", what, est->name);
        if (is_prb && grouping == GROUPED_BOTH)
            CHECK(st.rays.simd_replayed > 0 && st.rays.simd_replayed < st.rays.simd_vertices,
                  "%s: prb's replays shaded %llu of its %llu eight-wide vertices (expected some, not all)", what,
                  (unsigned long long)st.rays.simd_replayed, (unsigned long long)st.rays.simd_vertices);
        else
            CHECK(st.rays.simd_replayed == 0, "%s: %s: %llu replayed vertices eight-wide (expected none)", what,
                  est->name, (unsigned long long)st.rays.simd_replayed);
        dr_estimator_backward(est, &p, adj, again, NULL);
        CHECK(memcmp(g[e], again, sizeof(double) * (size_t)ps->total) == 0, "%s: %s not bit-identical when repeated",
              what, est->name);
        CHECK(dr_estimator_forward(est, &p, dir, f[e], &st) == 0, "%s: %s forward: %s", what, est->name,
              dr_last_error());
        /* forward and reverse are transposes: adj . (J dir) == (adj^T J) . dir */
        double dot = 0, rdot = 0, fnorm = 0;
        for (int i = 0; i < 3 * W * H; i++) {
            dot += adj[i] * f[e][i];
            fnorm = fmax(fnorm, fabs(f[e][i]));
        }
        for (int64_t i = 0; i < ps->total; i++)
            rdot += g[e][i] * dir[i];
        CHECK(fnorm > 0, "%s: %s: forward derivative image is zero", what, est->name);
        CHECK(rel_err(dot, rdot) <= 1e-9, "%s: %s: forward . adjoint %.12g != reverse . dir %.12g", what, est->name,
              dot, rdot);
        forward_groups_match(what, est, &p, dir);
        printf("%s: %s: %lld scalars, adjoint identity %.3g, memory %llu bytes (records %llu), %llu vertices "
               "eight-wide (%llu replayed)\n", what, est->name, (long long)ps->total, rel_err(dot, rdot),
               (unsigned long long)st.memory_bytes, (unsigned long long)st.record_bytes,
               (unsigned long long)st.rays.simd_vertices, (unsigned long long)st.rays.simd_replayed);
    }
    /* the cross primal (estimator.h): the adjoint from the paths themselves */
    double *cg[MAX_EST], *cimg[MAX_EST];
    float *target = malloc(sizeof(float) * 3 * W * H);
    for (int i = 0; i < 3 * W * H; i++)
        target[i] = (float)(0.5 * dr_sampler_next(&r));
    for (int e = 0; e < ne; e++) {
        const struct dr_estimator_ops *est = dr_estimators[e];
        cg[e] = calloc((size_t)ps->total, sizeof(double));
        cimg[e] = calloc(3 * W * H, sizeof(double));
        struct dr_cross_loss cross = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = cimg[e]};
        struct dr_grad_problem cp = p;
        cp.cross = &cross;
        cp.batch = e % 2 ? 97 : 0;
        CHECK(dr_estimator_backward(est, &cp, NULL, cg[e], NULL) == 0, "%s: %s cross: %s", what, est->name,
              dr_last_error());
        dr_estimator_backward(est, &cp, NULL, again, NULL);
        CHECK(memcmp(cg[e], again, sizeof(double) * (size_t)ps->total) == 0,
              "%s: %s cross not bit-identical when repeated", what, est->name);
        double inorm = 0;
        for (int i = 0; i < 3 * W * H; i++)
            inorm = fmax(inorm, fabs(cimg[e][i]));
        CHECK(inorm > 0 && isfinite(inorm), "%s: %s cross: primal image empty (%g)", what, est->name, inorm);
    }
    for (int a = 0; a < ne; a++)
        for (int b = a + 1; b < ne; b++) {
            double worst = reverse_difference(what, ps, cg[a], cg[b]), iworst = 0;
            for (int i = 0; i < 3 * W * H; i++)
                iworst = fmax(iworst, rel_err(cimg[a][i], cimg[b][i]));
            CHECK(worst <= 1e-9, "%s: cross %s vs %s differ by %.3g relative", what, dr_estimators[a]->name,
                  dr_estimators[b]->name, worst);
            CHECK(iworst <= 1e-9, "%s: cross primal images %s vs %s differ by %.3g relative", what,
                  dr_estimators[a]->name, dr_estimators[b]->name, iworst);
            printf("%s: cross %s vs %s: worst relative difference %.3g, images %.3g\n", what, dr_estimators[a]->name,
                   dr_estimators[b]->name, worst, iworst);
        }
    for (int e = 0; e < ne; e++) {
        free(cg[e]);
        free(cimg[e]);
    }
    free(target);
    for (int a = 0; a < ne; a++)
        for (int b = a + 1; b < ne; b++) {
            double worst = reverse_difference(what, ps, g[a], g[b]), fworst = 0;
            for (int i = 0; i < 3 * W * H; i++)
                fworst = fmax(fworst, rel_err(f[a][i], f[b][i]) * (fabs(f[a][i]) > 1e-12));
            CHECK(worst <= 1e-9, "%s: reverse mode %s vs %s differ by %.3g relative", what, dr_estimators[a]->name,
                  dr_estimators[b]->name, worst);
            CHECK(fworst <= 1e-9, "%s: forward mode %s vs %s differ by %.3g relative", what, dr_estimators[a]->name,
                  dr_estimators[b]->name, fworst);
            printf("%s: %s vs %s: worst relative difference reverse %.3g, forward %.3g\n", what,
                   dr_estimators[a]->name, dr_estimators[b]->name, worst, fworst);
        }
    for (int e = 0; e < ne; e++) {
        free(g[e]);
        free(f[e]);
    }
    free(again);
    free(adj);
    free(dir);
    dr_param_set_destroy(ps);
}

/* prb's wavefront (detached sampling: the eight-lane stages, which keep the
 * map lookups they made for the adjoints) against its one-path walk
 * (derivative sampling, which with no BSDF parameter runs detached
 * sampling's terms one path at a time and looks everything up again): the
 * same gradient to rounding. */
static void wave_against_one_path(const char *what, struct dr_scene *s, const struct dr_camera *cam,
                                  const char *const *ptrs, int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    const struct dr_estimator_ops *prb = dr_estimator_find("prb");
    float *adj = malloc(sizeof(float) * 3 * W * H);
    struct dr_sampler r;
    dr_sampler_init(&r, 8, 9, 10);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(dr_sampler_next(&r) - 0.3);
    /* 0: the wavefront; 1: the one-path walk (the test knob); 2: --sampling
     * derivative, which without a BSDF parameter runs detached and must take
     * the wavefront too (it walked one path at a time, 1.2x the time, until
     * the knob replaced it) */
    double *g[3];
    for (int k = 0; k < 3; k++) {
        g[k] = calloc((size_t)ps->total, sizeof(double));
        struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 3,
                                    .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 11, .threads = 2,
                                    .one_path_walks = k == 1,
                                    .sampling = k == 2 ? DR_SAMPLING_DERIVATIVE : DR_SAMPLING_DETACHED};
        struct dr_grad_stats st = {0};
        CHECK(dr_estimator_backward(prb, &p, adj, g[k], &st) == 0, "%s: prb: %s", what, dr_last_error());
        CHECK(k == 1 ? st.rays.simd_replayed == 0 : st.rays.simd_replayed > 0,
              "%s: %s walk shaded %llu vertices eight-wide (%llu replayed)", what, k == 1 ? "one-path" : "wavefront",
              (unsigned long long)st.rays.simd_vertices, (unsigned long long)st.rays.simd_replayed);
    }
    double worst = reverse_difference(what, ps, g[0], g[1]), norm = 0;
    for (int64_t i = 0; i < ps->total; i++)
        norm = fmax(norm, fabs(g[0][i]));
    CHECK(norm > 0 && worst <= 1e-9, "%s: prb's wavefront vs its one-path walk differ by %.3g relative (norm %g)",
          what, worst, norm);
    CHECK(memcmp(g[0], g[2], sizeof(double) * (size_t)ps->total) == 0,
          "%s: --sampling derivative without a BSDF parameter differs from detached", what);
    printf("%s: prb wavefront vs one-path walk: worst relative difference %.3g\n", what, worst);
    for (int k = 0; k < 3; k++)
        free(g[k]);
    free(adj);
    dr_param_set_destroy(ps);
}

/* The cross primal with more samples per pixel than prb parks ray logs for
 * (its replays then trace again): prb and tape still agree to rounding. */
static void cross_many_samples(struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "cross, many samples: %s", dr_last_error());
    if (!ps)
        return;
    float target[6] = {0.1f, 0.2f, 0.3f, 0.0f, 0.5f, 0.0f};
    double img[2][6], *g[2];
    const struct dr_estimator_ops *est[2] = {dr_estimator_find("prb"), dr_estimator_find("tape")};
    for (int e = 0; e < 2; e++) {
        struct dr_cross_loss cross = {.loss = DR_LOSS_L1, .target = target, .scale = 1.0, .image = img[e]};
        struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = 2, .height = 1, .spp = 5000,
                                    .max_depth = 4, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 3, .threads = 2,
                                    .cross = &cross};
        g[e] = calloc((size_t)ps->total, sizeof(double));
        CHECK(dr_estimator_backward(est[e], &p, NULL, g[e], NULL) == 0, "cross, many samples: %s: %s", est[e]->name,
              dr_last_error());
    }
    double worst = reverse_difference("cross, many samples", ps, g[0], g[1]);
    CHECK(worst <= 1e-9, "cross, 5000 spp: prb vs tape differ by %.3g relative", worst);
    CHECK(memcmp(img[0], img[1], sizeof img[0]) == 0, "cross, 5000 spp: primal images differ");
    printf("cross, 5000 spp (replays trace again): prb vs tape %.3g\n", worst);
    free(g[0]);
    free(g[1]);
    dr_param_set_destroy(ps);
}

/* Path i of a run seeded `seed` started through pixel i of the W x H view
 * (wrapping), with its sampler. */
static void camera_path(const struct dr_camera_view *view, uint64_t seed, int i, struct dr_sampler *smp,
                        struct dr_path_state *st)
{
    dr_sampler_init(smp, seed, (uint64_t)i, 0);
    double u, v;
    dr_sampler_next2(smp, &u, &v);
    dr_vec3 o, d;
    dr_camera_ray(view, (i % W) + u, ((i / W) % H) + v, &o, &d);
    dr_path_start(st, o, d);
}

/* dr_path_vertex_has_derivative's contract, checked against the adjoints
 * themselves: a vertex it calls derivative-free gets nothing from
 * d_path_vertex_term (nor d_path_continuation, which only differentiated
 * materials reach). prb's shortened replays and tape's steps both rest on
 * it, so their agreement above could not catch a predicate that forgot a
 * kind of term: this can. */
static void derivative_predicate(struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "predicate: %s", dr_last_error());
    if (!ps)
        return;
    const struct dr_path_opts opts = {.max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT,
                                      .stages = dr_path_plan(s, ps), .params = ps};
    struct dr_camera_view view = dr_camera_view(cam, W, H);
    double *g = calloc((size_t)ps->total, sizeof(double));
    struct dr_ray_counts rays = {0};
    int with = 0, without = 0, leaks = 0;
    for (int i = 0; i < 4000; i++) {
        struct dr_sampler smp;
        struct dr_path_state st;
        struct dr_path_vertex vx;
        camera_path(&view, 21, i, &smp, &st);
        for (bool more = true; more;) {
            more = dr_path_step(s, &opts, &st, &smp, &vx, &rays);
            if (dr_path_vertex_has_derivative(s, ps, &vx)) {
                with++;
                continue;
            }
            without++;
            struct dr_grad_sink sink = dr_sink_reverse(g);
            d_path_vertex_term(s, ps, &vx, dr_v3s(1.0), &sink);
            if (vx.cont && vx.diff_bsdf)
                d_path_continuation(s, ps, &vx, dr_v3s(1.0), &sink);
            for (int64_t k = 0; k < ps->total; k++)
                if (g[k] != 0.0) {
                    leaks++;
                    g[k] = 0.0;
                }
        }
    }
    CHECK(with > 0 && without > 0, "predicate: vertices with %d, without %d (both kinds needed)", with, without);
    CHECK(leaks == 0, "predicate: %d derivative terms at vertices it calls derivative-free", leaks);
    printf("derivative predicate: %d vertices with a term, %d without, %d leaks\n", with, without, leaks);
    free(g);
    dr_param_set_destroy(ps);
}

/* d_path_vertex, which prb and the tape call at every differentiated vertex,
 * sums its two BSDF values' adjoints before the material's (one texture
 * lookup, one texel scatter): it must give what d_path_vertex_term and
 * d_path_continuation give apart, to rounding, in reverse and forward mode,
 * on vertices that have both parts (a dropped part, or one part's adjoint
 * given to the other, fails). */
static void joint_vertex_adjoint(struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "joint adjoint: %s", dr_last_error());
    if (!ps)
        return;
    const struct dr_path_opts opts = {.max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT,
                                      .stages = dr_path_plan(s, ps), .params = ps};
    struct dr_camera_view view = dr_camera_view(cam, W, H);
    double *joint = calloc((size_t)ps->total, sizeof(double)), *apart = calloc((size_t)ps->total, sizeof(double)),
           *dir = calloc((size_t)ps->total, sizeof(double));
    for (int64_t k = 0; k < ps->total; k++)
        dir[k] = 0.5 + 0.01 * (double)(k % 37);
    struct dr_ray_counts rays = {0};
    int both = 0;
    double worst = 0.0, worst_fwd = 0.0;
    for (int i = 0; i < 3000; i++) {
        struct dr_sampler smp;
        struct dr_path_state st;
        struct dr_path_vertex vx;
        camera_path(&view, 23, i, &smp, &st);
        for (bool more = true; more;) {
            more = dr_path_step(s, &opts, &st, &smp, &vx, &rays);
            if (!(vx.nee && vx.cont && vx.diff_bsdf))
                continue;
            both++;
            const dr_vec3 d_e = dr_v3(0.3, -0.7, 1.1), d_f = dr_v3(-0.9, 0.4, 0.6);
            struct dr_grad_sink a = dr_sink_reverse(joint), b = dr_sink_reverse(apart);
            d_path_vertex(s, ps, &vx, d_e, d_f, &a);
            d_path_vertex_term(s, ps, &vx, d_e, &b);
            d_path_continuation(s, ps, &vx, d_f, &b);
            double scale = 0.0, diff = 0.0;
            for (int64_t k = 0; k < ps->total; k++) {
                scale = fmax(scale, fabs(apart[k]));
                diff = fmax(diff, fabs(joint[k] - apart[k]));
                joint[k] = apart[k] = 0.0;
            }
            worst = fmax(worst, scale > 0.0 ? diff / scale : diff);
            /* (relative to the parts' sizes: their sum may cancel) */
            struct dr_grad_sink fa = dr_sink_forward(dir), ft = dr_sink_forward(dir), fc = dr_sink_forward(dir);
            d_path_vertex(s, ps, &vx, d_e, d_f, &fa);
            d_path_vertex_term(s, ps, &vx, d_e, &ft);
            d_path_continuation(s, ps, &vx, d_f, &fc);
            for (int c = 0; c < 3; c++) {
                const double size = fabs(ft.forward[c]) + fabs(fc.forward[c]);
                const double diff = fabs(fa.forward[c] - (ft.forward[c] + fc.forward[c]));
                worst_fwd = fmax(worst_fwd, size > 0.0 ? diff / size : diff);
            }
        }
    }
    CHECK(both > 100, "joint adjoint: only %d vertices with both parts", both);
    CHECK(worst <= 1e-12, "joint adjoint: reverse mode differs from the parts by %.3g relative", worst);
    CHECK(worst_fwd <= 1e-12, "joint adjoint: forward mode differs from the parts by %.3g relative", worst_fwd);
    printf("joint vertex adjoint: %d vertices, reverse %.3g, forward %.3g\n", both, worst, worst_fwd);
    free(joint);
    free(apart);
    free(dir);
    dr_param_set_destroy(ps);
}

/* tape keeps each worker's tape mappings from one run to the next (tape.c):
 * a run after runs of other depths, batch sizes and thread counts gives bit
 * for bit what it gave before them. */
static void tape_reuse(struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs, int n)
{
    const struct dr_estimator_ops *tape = dr_estimator_find("tape");
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(tape && ps, "tape reuse: set-up: %s", dr_last_error());
    if (!tape || !ps)
        return;
    float *adj = malloc(sizeof(float) * 3 * W * H);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(0.01 * ((i * 7) % 13 - 6));
    double *first = calloc((size_t)ps->total, sizeof(double)), *other = calloc((size_t)ps->total, sizeof(double)),
           *again = calloc((size_t)ps->total, sizeof(double));
    struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 2,
                                .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 3, .threads = 1};
    CHECK(dr_estimator_backward(tape, &p, adj, first, NULL) == 0, "tape reuse: %s", dr_last_error());
    struct dr_grad_problem deep = p, small = p;
    deep.threads = 2;
    deep.max_depth = deep.rr_depth = 40;   /* longer tapes than the first run's */
    deep.spp = 3;
    small.threads = 3;
    small.batch = 7;                       /* shorter ones, on more workers */
    CHECK(dr_estimator_backward(tape, &deep, adj, other, NULL) == 0, "tape reuse (deep): %s", dr_last_error());
    CHECK(dr_estimator_backward(tape, &small, adj, other, NULL) == 0, "tape reuse (small): %s", dr_last_error());
    CHECK(dr_estimator_backward(tape, &p, adj, again, NULL) == 0, "tape reuse (again): %s", dr_last_error());
    CHECK(memcmp(first, again, sizeof(double) * (size_t)ps->total) == 0,
          "tape: a run after runs of other sizes differs from the same run before them");
    printf("tape reuse: %lld scalars bit-identical after deeper and smaller runs\n", (long long)ps->total);
    free(first);
    free(other);
    free(again);
    free(adj);
    dr_param_set_destroy(ps);
}

/* The cross primal's adjoint of one sample (common.h), computed by hand for
 * a pixel of spp samples: with independent numbers at the mean of all the
 * other samples; under sobol at the mean of the other half (samples of the
 * other parity), each half over its own count (odd spp: unequal halves). */
/* prb replays a gradient whose environment has a parameter in its arrays
 * (wave_soa.h: the escaped vertices made there), as any other eight-lane
 * run; the comparisons with the tape then check those replays. */
static void environment_replays_in_arrays(const char *what, struct dr_scene *s, const char *const *ptrs, int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    const struct dr_path_opts po = {.max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, ps),
                                    .params = ps};
    CHECK(ps->env_active && dr_wave_soa_replays_apply(s, &po), "%s: prb's replays run in the arrays", what);
    dr_param_set_destroy(ps);
}

static void cross_adjoint_by_hand(void)
{
    static struct dr_est_base b;
    const float target[3] = {0.3f, 0.2f, 0.1f};
    double image[3];
    struct dr_cross_loss x = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = image};
    for (int sobol = 0; sobol <= 1; sobol++)
        for (int spp = 2; spp <= 5; spp++) {
            struct dr_grad_problem p = {.width = 1, .height = 1, .spp = spp, .cross = &x,
                                        .sampler = sobol ? DR_SAMPLER_SOBOL : DR_SAMPLER_INDEPENDENT};
            b.p = &p;
            dr_vec3 L[5];
            struct dr_cross_sum sum = {0};
            for (int t = 0; t < spp; t++) {
                L[t] = dr_v3(0.1 * t + 0.05, 0.2 + 0.01 * t * t, 0.3 - 0.02 * t);
                dr_cross_sum_add(&sum, t, L[t]);
            }
            dr_est_cross_pixel(&b, 0, &sum);
            for (int s = 0; s < spp; s++) {
                dr_vec3 adj = dr_est_cross_adjoint(&b, 0, &sum, s, L[s]);
                for (int c = 0; c < 3; c++) {
                    double others = 0.0;
                    int n = 0;
                    for (int t = 0; t < spp; t++)
                        if (sobol ? (t & 1) != (s & 1) : t != s)
                            others += dr_v3_get(L[t], c), n++;
                    double want = d_loss_value(DR_LOSS_L2, others / n, target[c], 3, 1.0) / spp;
                    CHECK(fabs(dr_v3_get(adj, c) - want) <= 1e-12 * fabs(want),
                          "cross adjoint (%s, spp %d, sample %d, channel %d): %.17g, by hand %.17g",
                          sobol ? "sobol" : "independent", spp, s, c, dr_v3_get(adj, c), want);
                }
            }
            for (int c = 0; c < 3; c++) {   /* the pixel's mean over all its samples */
                double all = 0.0;
                for (int t = 0; t < spp; t++)
                    all += dr_v3_get(L[t], c);
                CHECK(fabs(image[c] - all / spp) <= 1e-12 * all, "cross image (spp %d): %.17g vs %.17g", spp,
                      image[c], all / spp);
            }
        }
}

/* dr_est_camera_rays8 against eight calls of dr_est_camera_ray: every
 * lane's sampler, ray origin and direction to the bit, for each sampler
 * kind, with and without the cross primal (sobol's halves), for each
 * filter, on a cropped frame, with lanes of one pixel, of neighbouring
 * pixels and of pixels in no order (the replays' lanes). */
static void camera_rays8_match(const struct dr_camera *cam)
{
    static struct dr_est_base b;   /* (static: its thread states are large) */
    static const enum dr_sampler_kind kinds[] = {DR_SAMPLER_INDEPENDENT, DR_SAMPLER_SOBOL, DR_SAMPLER_STRATIFIED};
    static const struct dr_filter filters[] = {{DR_FILTER_BOX, 0.0}, {DR_FILTER_TENT, 0.0}, {DR_FILTER_GAUSSIAN, 0.7}};
    static const int64_t lanes_px[3][8] = {{5, 5, 5, 5, 5, 5, 5, 5}, {3, 3, 3, 4, 4, 4, 4, 5}, {9, 2, 9, 0, 11, 2, 7, 7}};
    static const int lanes_sample[3][8] = {{0, 1, 2, 3, 4, 5, 6, 7}, {5, 6, 7, 0, 1, 2, 3, 0}, {3, 0, 7, 6, 1, 2, 4, 5}};
    const float target[3] = {0};
    double image[3];
    struct dr_cross_loss x = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = image};
    int lanes = 0, differ = 0;
    for (size_t k = 0; k < sizeof kinds / sizeof *kinds; k++)
        for (int cross = 0; cross <= 1; cross++)
            for (size_t f = 0; f < sizeof filters / sizeof *filters; f++)
                for (int set = 0; set < 3; set++) {
                    struct dr_grad_problem p = {.width = 4, .height = 3, .spp = 8, .seed = 11, .sampler = kinds[k],
                                                .cross = cross ? &x : NULL};
                    p.film = (struct dr_film){filters[f], 9, 7, 2, 3};   /* (a 4 x 3 crop of a 9 x 7 frame) */
                    memset(&b, 0, sizeof b);
                    b.p = &p;
                    b.view = dr_camera_view(cam, 9, 7);
                    struct dr_sampler smp8[8], smp1;
                    dr_vec3 o8[8], d8[8], o1, d1;
                    dr_est_camera_rays8(&b, 1, lanes_px[set], lanes_sample[set], smp8, o8, d8);
                    for (int l = 0; l < 8; l++, lanes++) {
                        dr_est_camera_ray(&b, 0, lanes_px[set][l], lanes_sample[set][l], &smp1, &o1, &d1);
                        const bool same = memcmp(&o1, &o8[l], sizeof o1) == 0 && memcmp(&d1, &d8[l], sizeof d1) == 0 &&
                                          smp1.key == smp8[l].key && smp1.dim == smp8[l].dim &&
                                          smp1.kind == smp8[l].kind && smp1.pkey == smp8[l].pkey &&
                                          smp1.index == smp8[l].index && smp1.count == smp8[l].count &&
                                          smp1.grid_m == smp8[l].grid_m && smp1.grid_n == smp8[l].grid_n;
                        differ += !same;
                        CHECK(same, "camera rays8 (sampler %d, cross %d, filter %zu, lanes %d, lane %d): "
                              "d %.17g %.17g %.17g vs %.17g %.17g %.17g, key %llx vs %llx", (int)kinds[k], cross, f, set,
                              l, d8[l].x, d8[l].y, d8[l].z, d1.x, d1.y, d1.z, (unsigned long long)smp8[l].key,
                              (unsigned long long)smp1.key);
                    }
                }
    CHECK(lanes == 3 * 2 * 3 * 3 * 8 && differ == 0, "camera rays8: %d lanes, %d differ", lanes, differ);
}

/* estimator.h's dr_grad_consumer: the gradient handed over in pieces is
 * the vector a run writes, to the bit, every entry exactly once (where a
 * piece comes with a block mask, its unmarked blocks +0: a block with a
 * non-zero entry left unmarked fails the comparison); pieces begin at
 * multiples of 1024; the scratch's vectors and masks are left cleared (not
 * dirty), so a second run with them gives it again; dr_estimator_consumes
 * says no where the run cannot (mis sampling; the shared exact sum from
 * four threads on a big vector, `consumes` false). */
struct taken {
    double *g;
    int *count;
    int64_t marked, unmarked, misaligned;   /* blocks of masked pieces; pieces not at a multiple of 1024 */
};
static void take_piece(void *ctx, int64_t begin, int64_t end, const double *g, const uint64_t *mask)
{
    struct taken *t = ctx;
    if (begin % 1024 != 0)
        __atomic_fetch_add(&t->misaligned, 1, __ATOMIC_RELAXED);
    for (int64_t i = begin; i < end; i++) {
        const bool marked = !mask || (mask[(i - begin) / 512] >> ((i - begin) / 8 % 64) & 1);
        t->g[i] = marked ? g[i - begin] : 0.0;
        __atomic_fetch_add(&t->count[i], 1, __ATOMIC_RELAXED);   /* (pieces come from several threads) */
        if (mask && (i - begin) % 8 == 0)
            __atomic_fetch_add(marked ? &t->marked : &t->unmarked, 1, __ATOMIC_RELAXED);
    }
}

static void consumer_matches(const char *what, struct dr_scene *s, const struct dr_camera *cam,
                             const char *const *ptrs, int n, int threads, bool consumes)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    const struct dr_estimator_ops *prb = dr_estimator_find("prb");
    const size_t T = (size_t)ps->total;
    float *adj = malloc(sizeof(float) * 3 * W * H);
    struct dr_sampler r;
    dr_sampler_init(&r, 7, 8, 9);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(dr_sampler_next(&r) - 0.4);
    double *own = calloc(T, sizeof(double));
    struct taken got = {calloc(T, sizeof(double)), calloc(T, sizeof(int)), 0, 0, 0};
    const struct dr_grad_consumer consumer = {take_piece, &got};
    struct dr_est_scratch sc = {0};
    struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 2,
                                .max_depth = 4, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 9, .threads = threads};
    CHECK(dr_estimator_backward(prb, &p, adj, own, NULL) == 0, "%s: %s", what, dr_last_error());
    p.scratch = &sc;
    p.consumer = &consumer;
    CHECK(dr_estimator_consumes(&p) == consumes, "%s, %d threads: dr_estimator_consumes says %d", what, threads,
          !consumes);
    for (int run = 0; consumes && run < 2; run++) {
        memset(got.count, 0, sizeof(int) * T);
        CHECK(dr_estimator_backward(prb, &p, adj, NULL, NULL) == 0, "%s: %s", what, dr_last_error());
        int64_t not_once = 0, zeros = 0;
        for (size_t i = 0; i < T; i++)
            not_once += got.count[i] != 1, zeros += own[i] == 0.0;
        CHECK(not_once == 0, "%s, run %d: %lld entries not taken exactly once", what, run, (long long)not_once);
        CHECK(memcmp(own, got.g, sizeof(double) * T) == 0 && zeros < (int64_t)T,
              "%s, %d threads, run %d: the consumer's gradient differs from the vector's", what, threads, run);
        const bool exact = dr_estimator_shared_sums(threads, (int64_t)T);
        for (int t = 0; t < threads; t++) {
            int64_t left = 0, bits = 0;
            for (size_t i = 0; sc.grad[t] && i <= T; i++)
                left += sc.grad[t][i] != 0.0;
            for (int64_t w = 0; sc.touched[t] && w < (int64_t)(T + 1 + 511) / 512; w++)
                bits += sc.touched[t][w] != 0;
            const bool kept = exact ? sc.exact != NULL : sc.grad[t] != NULL, dirty = exact ? sc.exact_dirty : sc.dirty[t];
            CHECK(kept && !dirty && left == 0 && bits == 0, "%s, run %d: thread %d's vector %s", what, run, t,
                  !kept ? "missing" : dirty ? "left dirty" : bits ? "with its mask set" : "not cleared");
        }
        /* the shared exact sum (four threads): left all zero, as created */
        int64_t exact_left = 0;
        for (size_t i = 0; exact && sc.exact && i < T; i++)
            exact_left += sc.exact->w[i].lo != 0 || sc.exact->w[i].hi != 0 || sc.exact->bad[i] != 0;
        CHECK(exact_left == 0, "%s, run %d: %lld entries of the exact sum not cleared", what, run,
              (long long)exact_left);
        /* masks where the vectors are too big for the estimator's chunks (4096 entries) */
        CHECK(got.misaligned == 0 && (T > 4096) == (got.marked > 0),
              "%s, run %d: %lld pieces not at multiples of 1024, %lld blocks marked, %lld not", what, run,
              (long long)got.misaligned, (long long)got.marked, (long long)got.unmarked);
        if (T > 4096)
            printf("%s, %d threads, run %d: %lld blocks marked, %lld not\n", what, threads, run, (long long)got.marked,
                   (long long)got.unmarked);
        got.marked = got.unmarked = got.misaligned = 0;
    }
    struct dr_grad_problem mis = p;
    mis.sampling = DR_SAMPLING_MIS;
    mis.params = ps;
    CHECK(!dr_estimator_consumes(&mis) || dr_est_sampling_run(&mis) != DR_SAMPLING_MIS,
          "%s: a mis run would hand its gradient to a consumer", what);
    dr_est_scratch_free(&sc);
    free(own);
    free(got.g);
    free(got.count);
    free(adj);
    dr_param_set_destroy(ps);
    if (consumes)
        printf("%s: a consumer's pieces are the gradient vector, %d threads\n", what, threads);
}

/* The batches' fold (reverse.c) on a sparse texture gradient, whose
 * untouched blocks it leaves alone: with two batches, an entry's mean is
 * (g0 + g1) / 2 and its standard error |g0 - g1| / 2, so an entry with a
 * mean and no standard error had the same non-zero value in both batches,
 * which independent samples never give. A fold that skipped a block a
 * batch did not touch but the other did would leave such entries (its
 * mean one batch's value, its error 0). */
static void fold_sparse(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs,
                        int n)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    const size_t T = (size_t)ps->total;
    double *g = calloc(T, sizeof(double)), *se = calloc(T, sizeof(double));
    float *target = calloc((size_t)3 * W * H, sizeof(float));
    struct dr_reverse_scratch rs = {0};
    for (int cross = 0; cross <= 1; cross++) {
        struct dr_reverse_options o = {
            .estimator = dr_estimator_find("prb"), .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = 2,
            .primal = cross ? DR_PRIMAL_CROSS : DR_PRIMAL_PER_BATCH, .scratch = &rs,
            .problem = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 4, .max_depth = 3,
                        .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 21, .threads = 2}};
        struct dr_reverse_result res = {.grad = g, .se = se};
        for (int run = 0; run < 2; run++)   /* (the second with the vectors the first left) */
            CHECK(dr_reverse_gradient(&o, target, &res) == 0, "%s: %s", what, dr_last_error());
        int64_t touched = 0, alike = 0;
        for (size_t i = 0; i < T; i++) {
            touched += g[i] != 0.0;
            alike += g[i] != 0.0 && se[i] == 0.0;
        }
        CHECK(touched > 0 && touched < (int64_t)T / 2, "%s: %lld of %zu entries touched: not a sparse gradient", what,
              (long long)touched, T);
        CHECK(alike == 0, "%s (%s primal): %lld entries with a mean and no standard error", what,
              cross ? "cross" : "per-batch", (long long)alike);
        if (!cross)
            continue;
        /* the cross primal's batches one by one (reverse.c's seeds: hash(hash(seed ^ "GRAD") + 2b)), and
         * Welford's formulas on them entry by entry: r's mean and error to the bit */
        double *gb[2] = {calloc(T, sizeof(double)), calloc(T, sizeof(double))};
        double *img = calloc((size_t)3 * W * H, sizeof(double));
        const uint64_t base = dr_hash64(o.problem.seed ^ 0x47524144ULL);
        for (int b = 0; b < 2; b++) {
            const struct dr_cross_loss x = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = img};
            struct dr_grad_problem p = o.problem;
            p.spp = 2, p.seed = dr_hash64(base + 2 * (uint64_t)b), p.cross = &x;
            CHECK(dr_estimator_backward(o.estimator, &p, NULL, gb[b], NULL) == 0, "%s: %s", what, dr_last_error());
        }
        int64_t differ = 0;
        for (size_t i = 0; i < T; i++) {
            const double mean0 = 0.0 + (gb[0][i] - 0.0) / 1, m20 = 0.0 + (gb[0][i] - 0.0) * (gb[0][i] - mean0);
            const double d = gb[1][i] - mean0, mean = mean0 + d / 2, m2 = m20 + d * (gb[1][i] - mean);
            differ += memcmp(&mean, &g[i], sizeof mean) != 0 || sqrt(m2 / 1 / 2) != se[i];
        }
        CHECK(differ == 0, "%s: %lld entries of the fold differ from Welford's formulas on the batches", what,
              (long long)differ);
        free(gb[0]);
        free(gb[1]);
        free(img);
    }
    dr_reverse_scratch_free(&rs);
    free(g);
    free(se);
    free(target);
    dr_param_set_destroy(ps);
}

/* reverse.h's result mask (dr_reverse_result.nonzero), as optimize keeps
 * it from iteration to iteration: runs with other seeds on the same
 * vectors (the blocks the last run left non-zero are not this one's) give
 * the bits of runs on fresh vectors without a mask, the mask is true after
 * each (every block with a non-zero mean or error marked) and sparse; where
 * the run cannot keep it (per-batch halves with the parts asked for) it
 * comes back all marked, the result still exact. */
static void result_mask(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs,
                        int n, int threads)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: param set: %s", what, dr_last_error());
    if (!ps)
        return;
    const size_t T = (size_t)ps->total, words = (T + 511) / 512;
    double *g = calloc(T, sizeof(double)), *se = calloc(T, sizeof(double));
    double *g1 = malloc(sizeof(double) * T), *se1 = malloc(sizeof(double) * T);
    double *sg = malloc(sizeof(double) * T), *sp = malloc(sizeof(double) * T);
    uint64_t *mask = calloc(words, sizeof(uint64_t));
    float *target = calloc((size_t)3 * W * H, sizeof(float));
    struct dr_reverse_scratch rs = {0};
    /* se wanted in every third block only (reverse.h's se_blocks, optimize's
     * pattern): se is left alone elsewhere (a sentinel stays), the rest is
     * the same to the bit, with the result's mask kept from run to run
     * (g2, se2, mask2) and without one (g3, se3) */
    uint64_t *wanted = calloc(words, sizeof(uint64_t)), *mask2 = calloc(words, sizeof(uint64_t));
    double *g2 = calloc(T, sizeof(double)), *se2 = malloc(sizeof(double) * T);
    double *g3 = malloc(sizeof(double) * T), *se3 = malloc(sizeof(double) * T);
    const double sentinel = 12345.0;
    for (size_t i = 0; i < T; i += 24)
        wanted[i / 512] |= UINT64_C(1) << (i / 8 % 64);
    for (size_t i = 0; i < T; i++)
        se2[i] = wanted[i / 512] >> (i / 8 % 64) & 1 ? 0.0 : sentinel;
    for (int run = 0; run < 4; run++) {
        const bool parts = run == 3;   /* (per-batch primals, two halves, se_gradient asked for) */
        struct dr_reverse_options o = {
            .estimator = dr_estimator_find("prb"), .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = 2 + run % 2,
            .primal = parts ? DR_PRIMAL_PER_BATCH : DR_PRIMAL_CROSS, .scratch = &rs,
            .problem = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = run == 1 ? 6 : 4,
                        .max_depth = 3, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 31 + (uint64_t)run,
                        .threads = threads}};
        struct dr_reverse_result fresh = {.grad = g1, .se = se1, .se_gradient = parts ? sg : NULL,
                                          .se_primal = parts ? sp : NULL};
        CHECK(dr_reverse_gradient(&o, target, &fresh) == 0, "%s: %s", what, dr_last_error());
        struct dr_reverse_result kept = {.grad = g, .se = se, .se_gradient = parts ? sg : NULL,
                                         .se_primal = parts ? sp : NULL, .nonzero = mask};
        CHECK(dr_reverse_gradient(&o, target, &kept) == 0, "%s: %s", what, dr_last_error());
        CHECK(memcmp(g, g1, sizeof(double) * T) == 0 && memcmp(se, se1, sizeof(double) * T) == 0,
              "%s, run %d: with the mask the result differs from a run without", what, run);
        for (size_t i = 0; i < T; i++)
            se3[i] = sentinel;
        struct dr_reverse_result sel = {.grad = g2, .se = se2, .nonzero = mask2, .se_blocks = wanted},
                                 sel_dense = {.grad = g3, .se = se3, .se_blocks = wanted};
        if (!parts) {   /* (se_blocks is ignored where the parts are asked for: reverse.h) */
            CHECK(dr_reverse_gradient(&o, target, &sel) == 0 && dr_reverse_gradient(&o, target, &sel_dense) == 0,
                  "%s: %s", what, dr_last_error());
            int64_t wrong = 0, touched = 0;
            for (size_t i = 0; i < T; i++) {
                const bool want = wanted[i / 512] >> (i / 8 % 64) & 1;
                wrong += memcmp(&g2[i], &g1[i], 8) != 0 || memcmp(&g3[i], &g1[i], 8) != 0 ||
                         (want && (memcmp(&se2[i], &se1[i], 8) != 0 || memcmp(&se3[i], &se1[i], 8) != 0));
                touched += !want && (se2[i] != sentinel || se3[i] != sentinel);
            }
            CHECK(wrong == 0 && touched == 0,
                  "%s, run %d, se in every third block: %lld entries differ from the full run, %lld se written "
                  "outside",
                  what, run, (long long)wrong, (long long)touched);
        }
        int64_t untrue = 0, marked = 0;
        for (size_t i = 0; i < T; i += 8) {
            const bool m = mask[i / 512] >> (i / 8 % 64) & 1;
            marked += m;
            for (size_t k = i; k < i + 8 && k < T; k++)
                untrue += !m && (g[k] != 0.0 || se[k] != 0.0 || signbit(g[k]) || signbit(se[k]));
        }
        const int64_t blocks = (int64_t)(T + 7) / 8;
        CHECK(untrue == 0, "%s, run %d: %lld entries non-zero in unmarked blocks", what, run, (long long)untrue);
        CHECK(parts ? marked == blocks : marked > 0 && marked < blocks / 2,
              "%s, run %d: %lld of %lld blocks marked", what, run, (long long)marked, (long long)blocks);
        if (parts)   /* (the dense run left every block marked: start the next from a true mask again) */
            continue;
        printf("%s, %d threads, run %d: the result's mask marks %lld of %lld blocks\n", what, threads, run,
               (long long)marked, (long long)blocks);
    }
    dr_reverse_scratch_free(&rs);
    free(wanted);
    free(mask2);
    free(g2);
    free(se2);
    free(g3);
    free(se3);
    free(g);
    free(se);
    free(g1);
    free(se1);
    free(sg);
    free(sp);
    free(mask);
    free(target);
    dr_param_set_destroy(ps);
}

/* estimator.h's dr_est_scratch and reverse.h's dr_reverse_scratch: runs
 * that reuse the caller's vectors (cleared, not fresh) give the same
 * gradient to the bit as runs with their own, again and again; a problem of
 * another size replaces them. threads 2: thread 1's vector is kept; 4 with a
 * texture of at least DR_SHARED_SUMS_MIN entries: the shared exact sum. */
static void scratch_reuse(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *const *ptrs,
                          int n, int threads)
{
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n), *small = dr_param_set_create(s, ptrs + n - 1, 1);
    CHECK(ps && small && small->total < ps->total, "%s: param sets: %s", what, dr_last_error());
    if (!ps || !small)
        return;
    const bool exact = dr_estimator_shared_sums(threads, ps->total);
    const struct dr_estimator_ops *prb = dr_estimator_find("prb");
    float *adj = malloc(sizeof(float) * 3 * W * H);
    struct dr_sampler r;
    dr_sampler_init(&r, 3, 4, 5);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(dr_sampler_next(&r) - 0.4);
    double *own = calloc((size_t)ps->total, sizeof(double)), *kept = calloc((size_t)ps->total, sizeof(double));
    struct dr_est_scratch sc = {0};
    struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = H, .spp = 2,
                                .max_depth = 4, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 5, .threads = threads};
    CHECK(dr_estimator_backward(prb, &p, adj, own, NULL) == 0, "%s: %s", what, dr_last_error());
    p.scratch = &sc;
    const void *first = NULL;
    for (int run = 0; run < 3; run++) {
        CHECK(dr_estimator_backward(prb, &p, adj, kept, NULL) == 0, "%s: %s", what, dr_last_error());
        CHECK(memcmp(own, kept, sizeof(double) * (size_t)ps->total) == 0,
              "%s: run %d with the scratch differs from a run with its own vectors", what, run);
        const void *held = exact ? (const void *)sc.exact : (const void *)sc.grad[1];
        CHECK(held && (run == 0 || held == first), "%s: run %d did not keep (or reuse) the scratch's %s", what,
              run, exact ? "exact sum" : "thread 1 vector");
        first = run == 0 ? held : first;
    }
    CHECK(exact ? sc.exact_len == ps->total && !sc.grad[1] : sc.len[1] == ps->total + 1 && !sc.exact,
          "%s: the scratch holds %s of the wrong size", what, exact ? "an exact sum" : "a vector");
    /* another problem's size: replaced, and still the run's own result */
    p.params = small;
    p.scratch = NULL;
    CHECK(dr_estimator_backward(prb, &p, adj, own, NULL) == 0, "%s: %s", what, dr_last_error());
    p.scratch = &sc;
    CHECK(dr_estimator_backward(prb, &p, adj, kept, NULL) == 0, "%s: %s", what, dr_last_error());
    CHECK(memcmp(own, kept, sizeof(double) * (size_t)small->total) == 0, "%s: a smaller problem with the scratch",
          what);
    dr_est_scratch_free(&sc);
    CHECK(!sc.grad[1] && !sc.exact && sc.len[1] == 0, "%s: dr_est_scratch_free left something", what);

    /* the batches' driver: twice with one dr_reverse_scratch, as optimize's
     * iterations, against a run with its own */
    float *target = calloc((size_t)3 * W * H, sizeof(float));
    double *g[2], *se[2];
    struct dr_reverse_scratch rs = {0};
    for (int k = 0; k < 2; k++) {
        g[k] = calloc((size_t)ps->total, sizeof(double));
        se[k] = calloc((size_t)ps->total, sizeof(double));
    }
    /* per-batch primals (two halves a batch: the first kept in half[0], the
     * second folded in as it is summed, also from the shared exact sum) and
     * the cross primal (each batch folded in as it is summed: no batch
     * vector) */
    for (int cross = 0; cross <= 1; cross++) {
        for (int run = 0; run < 3; run++) {
            struct dr_reverse_options o = {.estimator = prb, .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = 2,
                                           .primal = cross ? DR_PRIMAL_CROSS : DR_PRIMAL_PER_BATCH, .problem = p};
            o.problem.params = ps;
            o.problem.scratch = NULL;
            o.problem.spp = 4;
            o.scratch = run ? &rs : NULL;
            struct dr_reverse_result res = {.grad = g[run > 0], .se = se[run > 0]};
            CHECK(dr_reverse_gradient(&o, target, &res) == 0, "%s: reverse run %d: %s", what, run, dr_last_error());
            if (run > 0)
                CHECK(memcmp(g[0], g[1], sizeof(double) * (size_t)ps->total) == 0 &&
                          memcmp(se[0], se[1], sizeof(double) * (size_t)ps->total) == 0,
                      "%s: dr_reverse_gradient (%s primal) with a kept scratch (run %d) differs from one with its own",
                      what, cross ? "cross" : "per-batch", run);
        }
        CHECK((cross ? !rs.half[0] : rs.half[0] && rs.half_len[0] == ps->total) && !rs.half[1],
              "%s (%s primal): the reverse scratch kept the wrong batch vectors (%p, %p)", what,
              cross ? "cross" : "per-batch", (void *)rs.half[0], (void *)rs.half[1]);
        dr_reverse_scratch_free(&rs);
    }
    CHECK(!rs.half[0] && !rs.est.grad[1] && !rs.est.exact, "%s: dr_reverse_scratch_free left something", what);
    for (int k = 0; k < 2; k++) {
        free(g[k]);
        free(se[k]);
    }
    free(target);
    free(own);
    free(kept);
    free(adj);
    dr_param_set_destroy(small);
    dr_param_set_destroy(ps);
    printf("%s: runs with a kept scratch (%d threads, %s) match runs with their own\n", what, threads,
           exact ? "shared exact sum" : "per-thread vectors");
}

/* A texture parameter is read in its eight-bit storage (image.h) until a
 * writer asks for its floats (dr_param_set_writable): `grad` never makes
 * the 50 MB of floats a 2k colour texture would take. The values read are
 * the same either way, and a put after the call writes them. */
static long minor_faults(void)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
}

/* The fold's first writes into a kept result's fresh pages (reverse.c's
 * `fresh` blocks): with the result's mask, a block a later batch reaches
 * first is +0 and is written without being read, so a fresh page of grad
 * and se faults once. Read first, each such page faulted twice (the
 * kernel's zero page, then its copy). A 2k texture seen in 480 pixels:
 * its gradient reaches a few thousand pages, most of them first in batches
 * after the first. A warm-up run with the same seed faults in the
 * estimator's own vectors, so that the counted run's faults are the
 * result's pages and a few others (images, thread stacks). */
static void fold_fresh_pages(void)
{
    const char *path = shared_sample("NormalTangentTest/glTF/NormalTangentTest.gltf");
    if (!path) {
        printf("fold_fresh_pages: NormalTangentTest not found beside the checkout: skipped\n");
        return;
    }
    struct dr_scene *s = dr_scene_load(path);
    const char *ptr = "/images/0";
    /* (lit as the command line lights a scene without lights) */
    struct dr_param_set *ps = s && dr_scene_set_environment(s, dr_v3s(1.0), 1.0, NULL, true) == 0
                                  ? dr_param_set_create(s, &ptr, 1)
                                  : NULL;
    CHECK(ps != NULL, "fold_fresh_pages: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const size_t T = (size_t)ps->total, words = (size_t)dr_mask_words((int64_t)T), bytes = T * sizeof(double);
    float *target = calloc((size_t)3 * W * H, sizeof(float));
    double *warm_g = calloc(T, sizeof(double)), *warm_se = calloc(T, sizeof(double));
    uint64_t *warm_mask = calloc(words, sizeof(uint64_t)), *mask = calloc(words, sizeof(uint64_t));
    double *g = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    double *se = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    CHECK(g != MAP_FAILED && se != MAP_FAILED, "fold_fresh_pages: mmap");
    madvise(g, bytes, MADV_NOHUGEPAGE);   /* (4 KiB pages: one mask word each) */
    madvise(se, bytes, MADV_NOHUGEPAGE);
    struct dr_reverse_scratch rs = {0};
    const struct dr_camera cam = dr_camera_default(s);   /* (the file has none) */
    struct dr_reverse_options o = {
        .estimator = dr_estimator_find("prb"), .loss = DR_LOSS_L2, .loss_scale = 1.0, .batches = 4,
        .primal = DR_PRIMAL_CROSS, .scratch = &rs,
        .problem = {.scene = s, .camera = &cam, .params = ps, .width = W, .height = H, .spp = 8,
                    .max_depth = 3, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 5, .threads = 2}};
    struct dr_reverse_result warm = {.grad = warm_g, .se = warm_se, .nonzero = warm_mask},
                             res = {.grad = g, .se = se, .nonzero = mask};
    CHECK(dr_reverse_gradient(&o, target, &warm) == 0, "fold_fresh_pages: %s", dr_last_error());
    const long before = minor_faults();
    CHECK(dr_reverse_gradient(&o, target, &res) == 0, "fold_fresh_pages: %s", dr_last_error());
    const long faults = minor_faults() - before;
    long pages = 0;   /* (grad's and se's pages written: the mask words marking a block, twice) */
    for (size_t i = 0; i < words; i++)
        pages += 2 * (mask[i] != 0);
    CHECK(memcmp(g, warm_g, bytes) == 0 && memcmp(se, warm_se, bytes) == 0,
          "fold_fresh_pages: the same run on fresh vectors gave another result");
#if defined(__SANITIZE_ADDRESS__)
    /* (AddressSanitizer's quarantine hands every run fresh memory for its
     * own buffers, and its shadow pages fault too: the count is not the
     * result's; the bound is checked without it) */
    CHECK(pages >= 2000, "fold_fresh_pages: %ld fresh pages written", pages);
#else
    CHECK(pages >= 2000 && faults >= pages / 2 && faults < pages + pages / 4 + 200,
          "fold_fresh_pages: %ld page faults for %ld fresh pages written (at most %ld)", faults, pages,
          pages + pages / 4 + 200);
#endif
    printf("fold_fresh_pages: %ld page faults for %ld fresh result pages\n", faults, pages);
    dr_reverse_scratch_free(&rs);
    munmap(g, bytes);
    munmap(se, bytes);
    free(warm_g);
    free(warm_se);
    free(warm_mask);
    free(mask);
    free(target);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

static void texture_storage(const char *path)
{
    struct dr_scene *s = dr_scene_load(path);
    const char *ptr = "/images/0";
    struct dr_param_set *ps = s ? dr_param_set_create(s, &ptr, 1) : NULL;
    CHECK(ps != NULL, "texture storage: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    struct dr_image *img = &s->images[ps->params[0].target];
    const size_t n = (size_t)ps->total;
    double *eight = malloc(sizeof(double) * n), *floats = malloc(sizeof(double) * n);
    CHECK(img->bytes != NULL && img->data == NULL, "texture storage: the parameter set made floats of the texture");
    dr_param_set_get(s, ps, eight);
    CHECK(dr_param_set_writable(s, ps) == 0, "writable: %s", dr_last_error());
    CHECK(img->bytes == NULL && img->data != NULL, "texture storage: dr_param_set_writable left eight bits");
    dr_param_set_get(s, ps, floats);
    CHECK(memcmp(eight, floats, sizeof(double) * n) == 0, "texture storage: the values differ between storages");
    floats[5] = 0.25;
    dr_param_set_put(s, ps, floats);
    dr_param_set_get(s, ps, eight);
    CHECK(eight[5] == 0.25, "texture storage: a put after dr_param_set_writable did not write (%g)", eight[5]);
    free(eight);
    free(floats);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

int main(void)
{
    cross_adjoint_by_hand();
    fold_fresh_pages();
    const char *path = scene_path("cornell-box.gltf");
    texture_storage(path);
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
    camera_rays8_match(&s->cameras[0]);
    compare("cornell box", s, &s->cameras[0], ptrs, 7, 8, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    scratch_reuse("cornell box", s, &s->cameras[0], ptrs, 7, 2);
    consumer_matches("cornell box", s, &s->cameras[0], ptrs, 7, 2, true);
    consumer_matches("cornell box", s, &s->cameras[0], ptrs, 7, 3, true);
    /* the light's parameters alone: the vertices that see it or sample it
     * are the only ones with a term (prb's walks mark them in the arrays) */
    compare("cornell box, the light only", s, &s->cameras[0], ptrs + 4, 2, 8, DR_SAMPLING_DETACHED,
            GROUPED_BOTH);
    /* BSDF parameters only: prb's walks and the tape's steps shade the
     * vertices on other materials eight lanes at a time; the estimators must
     * still agree (a wrong continuation factor in the tape's steps, or a
     * wrong radiance in prb's, would show) */
    const char *bsdf_ptrs[] = {ptrs[0], ptrs[2], ptrs[3], ptrs[6]};
    compare("cornell box, BSDF parameters only", s, &s->cameras[0], bsdf_ptrs, 4, 8, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* one parameter at a time: most vertices then have no term */
    for (int k = 0; k < 7; k++)
        derivative_predicate(s, &s->cameras[0], &ptrs[k], 1);
    joint_vertex_adjoint(s, &s->cameras[0], ptrs, 7);
    /* attached sampling (the gold roughness moves its sampling map): prb
     * with the default regularisation recomputes ill-conditioned Jacobians
     * exactly, so it matches the tape on a whole image, with an adjoint of
     * mixed signs (a sign lost in an adjoint fails the forward-reverse
     * identity); with the cross primal its walks run in the arrays. (mis is
     * left out: its weights are estimated from the gradients themselves, so
     * its forward and reverse modes are not transposes.) */
    compare("cornell box, attached sampling", s, &s->cameras[0], ptrs, 7, 8, DR_SAMPLING_ATTACHED, GROUPED_WALKS);
    /* derivative sampling: the same sub-streams, the same terms in another order */
    compare("cornell box, derivative sampling", s, &s->cameras[0], ptrs, 7, 8, DR_SAMPLING_DERIVATIVE, GROUPED_WALKS);
    compare("cornell box, paths longer than the replay log", s, &s->cameras[0], ptrs, 7, DR_WAVE_REPLAY_DEPTH + 12,
            DR_SAMPLING_DETACHED, GROUPED_BOTH);
    compare("cornell box, BSDF parameters only, paths longer than the replay log", s, &s->cameras[0], bsdf_ptrs, 4,
            DR_WAVE_REPLAY_DEPTH + 12, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* zero BSDF channels at differentiated vertices (path.h's substitutes):
     * the red wall reflects no green or blue, the white walls nothing (no
     * specular lobe either: its 4 % would make no channel 0). prb's
     * walks shade these vertices eight lanes at a time (a shadow ray cast
     * where the BSDF towards the light is 0, the zero channels substituted),
     * the tape's steps keep them whole and take the scalar stages: the two
     * must still agree */
    int zeroed = 0;
    for (int m = 0; m < s->n_materials; m++) {
        struct dr_material *mat = &s->materials[m];
        if (strcmp(mat->name, "red") == 0)
            mat->base_color = dr_v3(0.8, 0.0, 0.0), mat->specular = 0.0, zeroed++;
        if (strcmp(mat->name, "white") == 0)
            mat->base_color = dr_v3(0.0, 0.0, 0.0), mat->specular = 0.0, zeroed++;
    }
    CHECK(zeroed == 2, "cornell box: the red and white materials (found %d)", zeroed);
    const char *zero_ptrs[] = {ptrs[0], ptrs[1], ptrs[2]};
    compare("cornell box, zero BSDF channels", s, &s->cameras[0], zero_ptrs, 3, 8, DR_SAMPLING_DETACHED, GROUPED_BOTH);
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
    compare("glossy scene", s, &cam, gptrs, 8, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    compare("glossy scene, derivative sampling", s, &cam, gptrs, 8, 6, DR_SAMPLING_DERIVATIVE, GROUPED_WALKS);
    compare("glossy scene, derivative-roughness sampling", s, &cam, gptrs, 8, 6, DR_SAMPLING_DERIVATIVE_ROUGHNESS,
            GROUPED_WALKS);
    compare("glossy scene, the floor's BSDF only", s, &cam, gptrs, 2, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* one kind of light at a time: where the point light alone has a
     * parameter, a vertex's term is its light sample's when that picked the
     * point light, never an escaped ray's; with the environment's alone,
     * the other way round */
    compare("glossy scene, the point light only", s, &cam, gptrs + 4, 2, 6, DR_SAMPLING_DETACHED,
            GROUPED_BOTH);
    compare("glossy scene, the environment only", s, &cam, gptrs + 6, 2, 6, DR_SAMPLING_DETACHED,
            GROUPED_BOTH);
    environment_replays_in_arrays("glossy scene, the environment only", s, gptrs + 6, 2);
    tape_reuse(s, &cam, gptrs, 8);
    cross_many_samples(s, &cam, gptrs, 8);
    for (int k = 0; k < 8; k++)
        derivative_predicate(s, &cam, &gptrs[k], 1);
    /* a floor that reflects no green (Lambertian, a zero channel): paths
     * bounced off it carry on with a substitute in green (path.h), whose
     * true throughput (ratio 0) must stay out of the sky's share of the
     * escaped rays (prb's walks sum those eight at a time, the tape one by one) */
    s->materials[0].base_color = dr_v3(0.6, 0.0, 0.4);
    s->materials[0].specular = 0.0;
    const char *sky_ptrs[] = {gptrs[1], gptrs[6]};
    compare("glossy scene, a floor without green under the sky", s, &cam, sky_ptrs, 2, 6, DR_SAMPLING_DETACHED,
            GROUPED_BOTH);
    /* both surfaces under a clear coat (bsdf_coat.c): the coat's factors
     * and the bases' parameters, detached (eight lanes wide: path_simd.c
     * composes the coat) and attached (the coat's roughness moves its
     * lobe's map) */
    s->materials[0].specular = 1.0;   /* (the floor glossy again) */
    for (int m = 0; m < 2; m++) {
        s->materials[m].coated = true;
        s->materials[m].coat = m ? 0.4 : 0.7;
        s->materials[m].coat_roughness = m ? 0.3 : 0.1;
    }
    CHECK(dr_scene_refresh(s) == 0 && (s->effects & DR_FX_CLEARCOAT), "coated glossy scene: %s", dr_last_error());
    const char *cptrs[] = {
        "/materials/0/extensions/KHR_materials_clearcoat/clearcoatFactor",
        "/materials/0/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor",
        "/materials/1/extensions/KHR_materials_clearcoat/clearcoatFactor",
        "/materials/1/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor",
        gptrs[0], gptrs[1], gptrs[2], gptrs[4],
    };
    compare("coated glossy scene", s, &cam, cptrs, 8, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* (attached: the floor's parameters and the light's, so that the tape's
     * vertices on the coated metal, which has none, run eight-wide) */
    const char *aptrs[] = {cptrs[0], cptrs[1], gptrs[0], gptrs[1], gptrs[4]};
    compare("coated glossy scene, attached sampling", s, &cam, aptrs, 5, 6, DR_SAMPLING_ATTACHED, GROUPED_WALKS);
    /* derivative sampling: the floor's base colour and roughness under its
     * coat, and the coat's roughness with its own antithetic pair */
    compare("coated glossy scene, derivative sampling", s, &cam, aptrs, 5, 6, DR_SAMPLING_DERIVATIVE, GROUPED_WALKS);
    /* ... and anisotropic under the coats (KHR_materials_anisotropy: the
     * frames from the generated tangents, eight lanes wide): the strengths
     * and the bases' parameters, detached and derivative (attached is
     * refused on anisotropic scenes) */
    for (int m = 0; m < 2; m++) {
        s->materials[m].anisotropic = true;
        s->materials[m].anisotropy_strength = m ? 0.5 : 0.8;
        s->materials[m].anisotropy_rotation = m ? -0.7 : 0.3;
    }
    CHECK(dr_mesh_prepare_tangents(s) == 0 && s->mesh.tangents && dr_scene_refresh(s) == 0 &&
              (s->effects & DR_FX_ANISOTROPY),
          "anisotropic coated scene: %s", dr_last_error());
    const char *nptrs[] = {"/materials/0/extensions/KHR_materials_anisotropy/anisotropyStrength",
                           "/materials/1/extensions/KHR_materials_anisotropy/anisotropyStrength",
                           gptrs[0], gptrs[1], gptrs[2], gptrs[4]};
    compare("anisotropic coated scene", s, &cam, nptrs, 6, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* (the floor's and the light's: the tape's vertices on the metal, which has none, run eight-wide) */
    const char *ndptrs[] = {nptrs[0], gptrs[0], gptrs[1], gptrs[4]};
    compare("anisotropic coated scene, derivative sampling", s, &cam, ndptrs, 4, 6, DR_SAMPLING_DERIVATIVE,
            GROUPED_WALKS);
    /* attached: the stretched lobe's map moves with the strength and the
     * roughness, and the frame with the moving hit point (d_anisotropy_frame) */
    compare("anisotropic coated scene, attached sampling", s, &cam, ndptrs, 4, 6, DR_SAMPLING_ATTACHED, GROUPED_WALKS);
    /* mildly anisotropic (strengths within DR_DERIV_MAX_STRENGTH): both
     * roughnesses get the stretched lobe's antithetic pair under derivative
     * sampling (the stronger anisotropy above leaves them to the forward
     * strategies) */
    s->materials[0].anisotropy_strength = 0.15, s->materials[1].anisotropy_strength = 0.1;
    CHECK(dr_path_deriv_aniso_pair_ok(&s->materials[0]) && dr_path_deriv_aniso_pair_ok(&s->materials[1]) &&
              dr_scene_refresh(s) == 0,
          "mildly anisotropic scene: %s", dr_last_error());
    const char *mptrs[] = {gptrs[0], gptrs[2], gptrs[1], gptrs[4]};
    compare("mildly anisotropic coated scene, derivative sampling", s, &cam, mptrs, 4, 6, DR_SAMPLING_DERIVATIVE,
            GROUPED_WALKS);
    /* ... and sheened under the coats instead (KHR_materials_sheen: the
     * sheened lanes by bsdf.c lane by lane inside the eight-lane stages):
     * the sheens' colours and roughnesses and the bases' parameters,
     * detached, attached (the sheen's lobe is the cosine map's; its
     * probability moves with wo) and derivative (the sheen's own
     * parameters with the forward strategies) */
    for (int m = 0; m < 2; m++) {
        s->materials[m].anisotropic = false;
        s->materials[m].sheened = true;
        s->materials[m].sheen_color = m ? dr_v3(0.3, 0.6, 0.9) : dr_v3(0.8, 0.8, 0.7);
        s->materials[m].sheen_roughness = m ? 0.3 : 0.6;
    }
    CHECK(dr_scene_refresh(s) == 0 && (s->effects & DR_FX_SHEEN) && !(s->effects & DR_FX_ANISOTROPY),
          "sheened coated scene: %s", dr_last_error());
    const char *sptrs[] = {"/materials/0/extensions/KHR_materials_sheen/sheenColorFactor",
                           "/materials/0/extensions/KHR_materials_sheen/sheenRoughnessFactor",
                           "/materials/1/extensions/KHR_materials_sheen/sheenColorFactor",
                           "/materials/1/extensions/KHR_materials_sheen/sheenRoughnessFactor",
                           gptrs[0], gptrs[1], gptrs[2], gptrs[4]};
    compare("sheened coated scene", s, &cam, sptrs, 8, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    const char *saptrs[] = {sptrs[0], sptrs[1], gptrs[0], gptrs[1], gptrs[4]};
    compare("sheened coated scene, attached sampling", s, &cam, saptrs, 5, 6, DR_SAMPLING_ATTACHED, GROUPED_WALKS);
    compare("sheened coated scene, derivative sampling", s, &cam, saptrs, 5, 6, DR_SAMPLING_DERIVATIVE,
            GROUPED_WALKS);
    dr_scene_destroy(s);

    /* a closed box lit from inside: no path escapes, and without roulette
     * every one is as long as the limit, most vertices differentiated (the
     * walls; the lid's material has no parameter): most replays (in prb's
     * arrays or lanes) trace their vertices past the log again. (In the
     * open Cornell box above, few replays got that far.) */
    sb_init(&b);
    int wall = sb_material(&b, sb_diffuse(dr_v3(0.7, 0.6, 0.5)));
    sb_open_box(&b, 2.0, wall);
    sb_quad(&b, dr_v3(-1, 2, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.6, 0.6))));
    l.position = dr_v3(0.2, 1.6, 0.1);
    l.intensity = 3;
    sb_light(&b, l);
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    cam = sb_camera(dr_v3(0.5, 1.0, 0.9), dr_v3(-0.3, 0.8, -1), 60);
    const char *box_ptrs[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor"};
    compare("closed box, paths longer than the replay log", s, &cam, box_ptrs, 1, DR_WAVE_REPLAY_DEPTH + 12,
            DR_SAMPLING_DETACHED, GROUPED_BOTH);
    /* one path at a time: with the cross primal the replays take the arrays'
     * logged ray answers (dr_wave_log_step) and trace past the log */
    compare("closed box, derivative sampling, paths longer than the replay log", s, &cam, box_ptrs, 1,
            DR_WAVE_REPLAY_DEPTH + 12, DR_SAMPLING_DERIVATIVE, GROUPED_WALKS);
    dr_scene_destroy(s);

    /* the closed box with a stochastically transparent pane (BLEND, alpha
     * 0.5) across it and a lamp tile under the lid that is half pane too:
     * which surfaces a ray passes depends on its coverage key (coverage.h),
     * which prb's replays past the log must make again as its walks made
     * them (path_simd.c and wave_soa.c make the keys for the eight-lane
     * stages) */
    sb_init(&b);
    wall = sb_material(&b, sb_diffuse(dr_v3(0.7, 0.6, 0.5)));
    sb_open_box(&b, 2.0, wall);
    sb_quad(&b, dr_v3(-1, 2, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.6, 0.6))));
    struct dr_material pane = sb_diffuse(dr_v3(0.3, 0.5, 0.8));
    pane.alpha_mode = DR_ALPHA_BLEND;
    pane.alpha = 0.5;
    sb_quad(&b, dr_v3(-1, 0, -0.2), dr_v3(2, 0, 0), dr_v3(0, 2, 0.3), sb_material(&b, pane));
    struct dr_material tile = sb_diffuse(dr_v3s(0.0));
    tile.emissive_factor = dr_v3(3.0, 2.5, 2.0);
    tile.alpha_mode = DR_ALPHA_BLEND;
    tile.alpha = 0.5;
    sb_quad(&b, dr_v3(-0.3, 1.95, 0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, -0.6), sb_material(&b, tile));   /* faces down */
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    CHECK((s->effects & DR_FX_ALPHA_BLEND) != 0, "closed box with a pane: alpha BLEND");
    compare("closed box with a BLEND pane and lamp, paths longer than the replay log", s, &cam, box_ptrs, 1,
            DR_WAVE_REPLAY_DEPTH + 12, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    dr_scene_destroy(s);

    /* a panel with an emissive texture lighting an open box, the texels the
     * parameter: hits on the panel read them at the hit's coordinates, light
     * samples at the sampled point's (its barycentrics), and prb's replays
     * hand both to the adjoints from the eight-lane stages (path_simd.h) */
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.7, 0.6, 0.5))));
    float texels[4 * 4 * 3];
    for (int i = 0; i < 4 * 4 * 3; i++)
        texels[i] = 0.2f + 0.8f * (float)((i * 7) % 11) / 10.0f;
    struct dr_material panel = sb_diffuse(dr_v3(0.3, 0.3, 0.3));
    panel.emissive_factor = dr_v3(4.0, 3.5, 3.0);
    panel.emissive_tex.texture = sb_texture(&b, sb_image(4, 4, 3, texels, 0.0f, true));
    sb_quad(&b, dr_v3(-0.6, 1.8, -0.6), dr_v3(1.2, 0, 0), dr_v3(0, 0, 1.2), sb_material(&b, panel));
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *panel_ptrs[] = {"/images/0"};
    compare("open box, an emissive texture's texels", s, &cam, panel_ptrs, 1, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    dr_scene_destroy(s);

    /* an open box under an environment map alone, its colour and texels the
     * parameters: light samples of the map and rays that leave, whose
     * lookups the eight-lane stages keep for the adjoints (lights.h's
     * dr_env_lookup) in prb's replays; the tape's samples look the map up
     * again */
    sb_init(&b);
    sb_open_box(&b, 1.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, sb_diffuse(dr_v3(0.3, 0.5, 0.7))));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    float sky[16 * 8 * 3];
    for (int i = 0; i < 16 * 8 * 3; i++)
        sky[i] = i % 37 == 5 ? 30.0f : 0.05f + 0.9f * (float)((i * 5) % 13) / 12.0f;   /* (a few suns) */
    b.s->env.map = sb_image(16, 8, 3, sky, 0.0f, false);
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const struct dr_camera above = sb_camera(dr_v3(0.3, 2.2, 1.6), dr_v3(0, 0.2, 0), 50);
    const char *sky_map_ptrs[] = {"/extensions/DR_environment/color", "/extensions/DR_environment/uri"};
    compare("open box under a map", s, &above, sky_map_ptrs, 2, 6, DR_SAMPLING_DETACHED, GROUPED_BOTH);
    environment_replays_in_arrays("open box under a map", s, sky_map_ptrs, 2);
    wave_against_one_path("open box under a map", s, &above, sky_map_ptrs, 2);
    dr_scene_destroy(s);

    /* a 160 x 160 texture with four threads: the runs share one exact sum
     * (dr_estimator_shared_sums), which the scratch keeps */
    sb_init(&b);
    struct dr_material textured = sb_diffuse(dr_v3s(1.0));
    textured.base_color_tex.texture = sb_texture(&b, sb_varied_image(160, 160, 3, 1));
    sb_quad(&b, dr_v3(-1, 0, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, textured));
    sb_environment(&b, dr_v3(1.0, 0.9, 0.8));
    s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *tex_ptrs[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor", "/images/0"};
    const struct dr_camera top = sb_camera(dr_v3(0, 1.2, 0.8), dr_v3(0, 0, 0), 60);
    scratch_reuse("a 160x160 texture", s, &top, tex_ptrs, 2, 4);
    consumer_matches("a 160x160 texture", s, &top, tex_ptrs, 2, 2, true);
    consumer_matches("a 160x160 texture", s, &top, tex_ptrs, 2, 4, true);   /* (the shared exact sum) */
    fold_sparse("a 160x160 texture", s, &top, tex_ptrs, 2);
    result_mask("a 160x160 texture", s, &top, tex_ptrs, 2, 2);
    result_mask("a 160x160 texture", s, &top, tex_ptrs, 2, 4);   /* (the shared exact sum) */
    dr_scene_destroy(s);
    return TEST_END();
}
