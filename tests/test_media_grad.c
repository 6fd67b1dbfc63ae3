/* Gradients of media parameters against finite differences: a heterogeneous
 * cube whose left part is empty (a whole majorant cell of zero density),
 * lit by the environment and, in turn, by a point light and by an area light
 * (an emissive quad above the cube). Objective J = image mean.
 * For each checked scalar, B batches give the estimator's dJ/dtheta (prb and
 * tape, reverse mode, DRT and the baseline) and a central (or, at 0,
 * one-sided second-order) difference of two renders with common random
 * numbers; agreement is |z| <= 3.5 on the batch means.
 *
 * Expected: DRT agrees everywhere, including empty voxels; the baseline
 * differentiates the sampled null collisions, of which an empty cell has
 * none: its gradient there misses what the empty cell would add.
 * And a homogeneous chromatic cube (no null collisions there), where all
 * three agree. */
#include <stdlib.h>

#include "camera.h"
#include "error.h"
#include "estimator.h"
#include "media_builder.h"
#include "medium_grad.h"
#include "render.h"
#include "test.h"

#define RES 12
#define BATCHES 32
#define SPP 16

static double grid_density(int x, int y, int z)
{
    if (x <= 4)
        return 0.0;   /* voxels 0..4: majorant cell 0 is empty */
    return 0.5 + 0.4 * sin(1.3 * x + 0.7 * y) * cos(0.9 * z);
}

/* lamp: an emissive quad (area light) instead of the point light */
static struct dr_scene *cube_scene(bool lamp)
{
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), mat);
    struct dr_medium m = medium(dr_v3(2.0, 3.0, 4.0), dr_v3(0.8, 0.7, 0.9), 0.3);
    set_grid(&m, 12, 8, 8, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), grid_density);
    sb_medium(&b, mat, m);
    int floor = sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4)));
    sb_quad(&b, dr_v3(-4, -1.5, -4), dr_v3(0, 0, 8), dr_v3(8, 0, 0), floor);
    sb_environment(&b, dr_v3(0.6, 0.7, 0.9));
    if (lamp) {
        struct dr_material e = sb_diffuse(dr_v3s(0.0));
        e.emissive_factor = dr_v3(4.0, 3.5, 3.0);
        sb_quad(&b, dr_v3(-1, 2.5, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), sb_material(&b, e));   /* faces down */
        b.s->n_file_materials = b.s->n_materials;
        return sb_finish(&b);
    }
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3s(1.0);
    l.intensity = 8.0;
    l.position = dr_v3(1.5, 3.0, 2.0);
    sb_light(&b, l);
    b.s->n_file_materials = b.s->n_materials;   /* parameters name file materials */
    return sb_finish(&b);
}

static double render_mean(struct dr_scene *s, const struct dr_camera *cam, uint64_t seed)
{
    static float rgb[RES * RES * 3];
    struct dr_render_opts o = {.width = RES, .height = RES, .spp = SPP, .max_depth = 6,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = seed, .threads = 2};
    if (dr_render(s, cam, &o, rgb, NULL) != 0)
        return NAN;
    double sum = 0.0;
    for (int i = 0; i < RES * RES * 3; i++)
        sum += rgb[i];
    return sum / (RES * RES * 3);
}

struct check {
    int64_t slot;        /* scalar in the set's gradient vector */
    const char *what;
    bool empty_region;   /* instead: every voxel of the empty region at once */
};

static int64_t voxel_base;   /* the density grid's first slot */

/* Slots the check moves together (direction: +1 on each). */
static int check_slots(const struct check *c, int64_t *slots)
{
    if (!c->empty_region) {
        slots[0] = c->slot;
        return 1;
    }
    int n = 0;
    for (int z = 0; z < 8; z++)
        for (int y = 0; y < 8; y++)
            for (int x = 0; x <= 4; x++)
                slots[n++] = voxel_base + ((int64_t)z * 8 + y) * 12 + x;
    return n;
}

static double dot_slots(const double *g, const int64_t *slots, int n)
{
    double sum = 0.0;
    for (int i = 0; i < n; i++)
        sum += g[slots[i]];
    return sum;
}

/* Where the last DRT run of estimator_grad took the first medium's gain (medium_grad.h). */
static struct dr_medium_gain_choice last_gain;

/* Estimator gradients (all slots) for batch b. */
static void estimator_grad(const struct dr_estimator_ops *e, enum dr_medium_grad mode, struct dr_scene *s,
                           const struct dr_camera *cam, const struct dr_param_set *ps, uint64_t seed, double *grad)
{
    static float adj[RES * RES * 3];
    for (int i = 0; i < RES * RES * 3; i++)
        adj[i] = 1.0f / (RES * RES * 3);
    struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = RES, .height = RES, .spp = SPP,
                                .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = seed, .threads = 2,
                                .sampling = DR_SAMPLING_DETACHED, .medium_grad = mode};
    struct dr_grad_stats st = {0};
    int rc = dr_estimator_backward(e, &p, adj, grad, &st);
    CHECK(rc == 0, "%s: %s", e->name, dr_last_error());
    CHECK(mode == DR_MEDIUM_GRAD_DRT ? st.n_media_gain == 1 : st.n_media_gain == 0, "%s: %d gain choices reported",
          dr_medium_grad_name(mode), st.n_media_gain);
    if (mode == DR_MEDIUM_GRAD_DRT && st.n_media_gain == 1)
        last_gain = st.media_gain[0];
}

/* Finite difference of J along one scalar (common random numbers). */
static double finite_difference(struct dr_scene *s, const struct dr_camera *cam, const struct dr_param_set *ps,
                                const int64_t *slots, int n, double eps, uint64_t seed)
{
    double *v = malloc(sizeof(double) * (size_t)ps->total), *v0 = malloc(sizeof(double) * (size_t)ps->total);
    dr_param_set_get(s, ps, v0);
    double J[3];
    bool one_sided = v0[slots[0]] - eps < 0.0;
    double steps[3] = {one_sided ? 0.0 : -eps, eps, one_sided ? 2 * eps : 0.0};
    for (int k = 0; k < (one_sided ? 3 : 2); k++) {
        memcpy(v, v0, sizeof(double) * (size_t)ps->total);
        for (int i = 0; i < n; i++)
            v[slots[i]] += steps[k];
        dr_param_set_put(s, ps, v);
        dr_scene_refresh(s);
        J[k] = render_mean(s, cam, seed);
    }
    double fd = one_sided ? (-3.0 * J[0] + 4.0 * J[1] - J[2]) / (2.0 * eps) : (J[1] - J[0]) / (2.0 * eps);
    dr_param_set_put(s, ps, v0);
    dr_scene_refresh(s);
    free(v);
    free(v0);
    return fd;
}

struct moments {
    double sum, sq;
};
static void add(struct moments *m, double x) { m->sum += x, m->sq += x * x; }
static double mean(struct moments m) { return m.sum / BATCHES; }
static double se(struct moments m)
{
    double mu = mean(m);
    return sqrt(fmax(0.0, m.sq / BATCHES - mu * mu) / (BATCHES - 1));
}

/* Each estimator's z against the finite difference (printed). */
static void z_scores(const char *what, struct moments fd, struct moments prb, struct moments tape, struct moments base,
                     double *zp, double *zt, double *zb)
{
    const double f = mean(fd), fs = se(fd);
    *zp = (mean(prb) - f) / sqrt(fs * fs + se(prb) * se(prb) + 1e-30);
    *zt = (mean(tape) - f) / sqrt(fs * fs + se(tape) * se(tape) + 1e-30);
    *zb = (mean(base) - f) / sqrt(fs * fs + se(base) * se(base) + 1e-30);
    fprintf(stderr, "%-22s fd %+.5f (%.5f)  drt prb %+.5f (%.5f) z %+.2f  tape %+.5f z %+.2f  baseline %+.5f z %+.2f\n",
            what, f, fs, mean(prb), se(prb), *zp, mean(tape), *zt, mean(base), *zb);
}


/* The cross primal (estimator.h): prb's replays one path at a time take
 * each path's sums and vertex count from the walk that made its pixel's
 * adjoints (prb.c's pixel_replays) instead of walking it again. Paths longer
 * than medium_grad.c's GAIN_PATHS (no roulette) make the count matter: prb
 * must still give the tape's gradient, to rounding. */
static void cross_primal_long_paths(struct dr_scene *s, const struct dr_camera *cam, const struct dr_param_set *ps)
{
    enum { W = 6 };
    /* a dense, bright medium: many collisions per path */
    double *v0 = malloc(sizeof(double) * (size_t)ps->total), *v = malloc(sizeof(double) * (size_t)ps->total);
    dr_param_set_get(s, ps, v0);
    memcpy(v, v0, sizeof(double) * (size_t)ps->total);
    v[ps->params[4].offset] *= 8.0;   /* density_scale */
    for (int c = 0; c < 3; c++)
        v[ps->params[1].offset + c] = 0.98;   /* albedo */
    dr_param_set_put(s, ps, v);
    dr_scene_refresh(s);
    float target[W * W * 3];
    for (int i = 0; i < W * W * 3; i++)
        target[i] = (float)(0.02 * (i % 7));
    double *g[2], img[2][W * W * 3];
    for (int e = 0; e < 2; e++) {
        g[e] = calloc((size_t)ps->total, sizeof(double));
        struct dr_cross_loss cross = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = img[e]};
        struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = W, .height = W, .spp = 3,
                                    .max_depth = 14, .rr_depth = 14, .seed = 9, .threads = 2,
                                    .sampling = DR_SAMPLING_DETACHED, .medium_grad = DR_MEDIUM_GRAD_DRT,
                                    .cross = &cross};
        struct dr_grad_stats st = {0};
        CHECK(dr_estimator_backward(dr_estimator_find(e ? "prb" : "tape"), &p, NULL, g[e], &st) == 0,
              "cross primal: %s", dr_last_error());
        /* prb walks the paths that meet no medium in the arrays (prb.c's
         * arrays_pixels: the medium is bounded by a mesh), the others one
         * path at a time; the tape walks every path one at a time */
        if (e)
            CHECK(st.rays.simd_vertices > 0, "cross primal: prb shaded no vertex eight lanes at a time");
        fprintf(stderr, "cross primal: %s shaded %llu vertices eight lanes at a time\n", e ? "prb" : "tape",
                (unsigned long long)st.rays.simd_vertices);
    }
    double worst = 0.0, scale = 0.0;
    for (int64_t i = 0; i < ps->total; i++) {
        worst = fmax(worst, fabs(g[0][i] - g[1][i]));
        scale = fmax(scale, fabs(g[0][i]));
    }
    fprintf(stderr, "cross primal, paths of up to 14 vertices: prb vs tape %.3g relative\n", worst / scale);
    CHECK(scale > 0.0 && worst <= 1e-9 * scale, "cross primal: prb and tape differ by %.3g relative", worst / scale);
    free(g[0]);
    free(g[1]);
    dr_param_set_put(s, ps, v0);
    dr_scene_refresh(s);
    free(v0);
    free(v);
}

/* prb's primal walks in the arrays beside a medium (prb.c's arrays_pixels):
 * seen from afar, the cube of smoke is a small part of the picture, so most
 * paths meet no medium and are walked eight lanes at a time, the others
 * handed back and walked one path at a time, and only the paths with a
 * derivative term replayed. prb must still give the tape's gradient (one
 * path at a time throughout) to rounding, for the media's parameters and a
 * surface's and a light's, with the cross primal and with a given adjoint. */
static void arrays_beside_media(void)
{
    enum { W = 24 };
    struct dr_scene *s = cube_scene(true);
    struct dr_camera cam = sb_camera(dr_v3(4.5, 1.0, 7.0), dr_v3(2.5, -1.5, 2.5), 50);
    const char *ptrs[] = {"/materials/0/extensions/DR_medium/density", "/materials/0/extensions/DR_medium/albedo",
                          "/materials/0/extensions/DR_medium/density_scale", "/materials/2/emissiveFactor",
                          "/materials/1/pbrMetallicRoughness/baseColorFactor"};
    /* by case: every parameter; the media's; the media's and the lamp's */
    static const int n_params[] = {5, 3, 4};
    static const char *const names[] = {"media, surface and light parameters", "media parameters",
                                        "media and light parameters"};
    uint64_t shaded8[3] = {0, 0, 0};   /* (by case: prb's last run's vertices eight lanes at a time) */
    for (int c = 0; c < 3; c++) {
        struct dr_param_set *ps = dr_param_set_create(s, ptrs, n_params[c]);
        CHECK(ps != NULL, "beside media: %s", dr_last_error());
        if (!ps)
            continue;
        float target[W * W * 3], adj[W * W * 3];
        for (int i = 0; i < W * W * 3; i++) {
            target[i] = (float)(0.02 * (i % 7));
            adj[i] = (float)(0.01 * ((i * 5) % 11) - 0.05);
        }
        for (int cross_mode = 0; cross_mode < 2; cross_mode++) {
            double *g[2], img[2][W * W * 3];
            struct dr_grad_stats st[2] = {{0}};
            for (int e = 0; e < 2; e++) {
                g[e] = calloc((size_t)ps->total, sizeof(double));
                struct dr_cross_loss cross = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = img[e]};
                struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = W, .height = W,
                                            .spp = 4, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 4,
                                            .threads = 2, .sampling = DR_SAMPLING_DETACHED,
                                            .medium_grad = DR_MEDIUM_GRAD_DRT, .cross = cross_mode ? &cross : NULL};
                CHECK(dr_estimator_backward(dr_estimator_find(e ? "prb" : "tape"), &p, cross_mode ? NULL : adj, g[e],
                                            &st[e]) == 0,
                      "beside media: %s", dr_last_error());
            }
            double worst = 0.0, scale = 0.0, media_scale = 0.0;
            for (int64_t i = 0; i < ps->total; i++) {
                worst = fmax(worst, fabs(g[0][i] - g[1][i]));
                scale = fmax(scale, fabs(g[0][i]));
                if (i < ps->params[2].offset + 1)   /* (the media's scalars come first) */
                    media_scale = fmax(media_scale, fabs(g[0][i]));
            }
            fprintf(stderr, "beside media (%s, %s): prb vs tape %.3g relative; prb shaded %llu vertices eight "
                            "lanes at a time, the tape %llu, of %llu camera rays\n",
                    names[c], cross_mode ? "cross primal" : "given adjoint", worst / scale,
                    (unsigned long long)st[1].rays.simd_vertices, (unsigned long long)st[0].rays.simd_vertices,
                    (unsigned long long)st[1].rays.camera);
            CHECK(media_scale > 0.0 && worst <= 1e-9 * scale, "beside media: prb and tape differ by %.3g relative",
                  worst / scale);
            CHECK(st[1].rays.simd_vertices > (uint64_t)W * W,   /* (821 here; 0 one path at a time) */
                  "beside media: prb shaded only %llu vertices eight lanes at a time",
                  (unsigned long long)st[1].rays.simd_vertices);
            /* the tape records the paths that meet no medium in the arrays
             * too (tape.c's record_soa), and the others again from their
             * start one path at a time */
            CHECK(st[0].rays.simd_vertices > (uint64_t)W * W,
                  "beside media: the tape shaded only %llu vertices eight lanes at a time",
                  (unsigned long long)st[0].rays.simd_vertices);
            shaded8[c] = st[1].rays.simd_vertices;
            free(g[0]);
            free(g[1]);
        }
        dr_param_set_destroy(ps);
    }
    /* with a surface's and a light's parameters, the paths that met no
     * medium and have a term replay in the arrays too (prb.c's media_replays) */
    CHECK(shaded8[0] > shaded8[1], "beside media: %llu vertices eight lanes at a time with surface parameters, %llu "
                                   "without (their replays took the one-path walker)",
          (unsigned long long)shaded8[0], (unsigned long long)shaded8[1]);
    dr_scene_destroy(s);
}

static void check_scene(bool lamp)
{
    fprintf(stderr, "-- lit by the environment and %s\n", lamp ? "an area light" : "a point light");
    struct dr_scene *s = cube_scene(lamp);
    struct dr_camera cam = sb_camera(dr_v3(0.4, 0.8, 4.0), dr_v3(0, 0, 0), 40);
    const char *ptrs[] = {"/materials/0/extensions/DR_medium/density", "/materials/0/extensions/DR_medium/albedo",
                          "/materials/0/extensions/DR_medium/g", "/materials/0/extensions/DR_medium/extinction",
                          "/materials/0/extensions/DR_medium/density_scale",
                          /* surfaces and lights seen and lit through the medium */
                          "/materials/1/pbrMetallicRoughness/baseColorFactor",
                          lamp ? "/materials/2/emissiveFactor" : "/extensions/KHR_lights_punctual/lights/0/intensity"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 7);
    CHECK(ps != NULL, "param set: %s", dr_last_error());
    if (!ps)
        return;
    const int64_t vox = ps->params[0].offset;
    voxel_base = vox;
#define VOXEL(x, y, z) (vox + ((int64_t)(z) * 8 + (y)) * 12 + (x))
    const struct check checks[] = {
        {0, "empty region (x <= 4)", true},   /* a whole empty majorant cell and more */
        {VOXEL(7, 4, 5), "voxel (7,4,5)", false},
        {ps->params[1].offset + 1, "albedo g", false},
        {ps->params[2].offset, "g", false},
        {ps->params[3].offset + 0, "extinction r", false},
        {ps->params[4].offset, "density_scale", false},
        {ps->params[5].offset, "floor base colour r", false},
        {ps->params[6].offset, lamp ? "area light emission r" : "light intensity", false},
    };
    const double eps[] = {0.1, 0.2, 0.02, 0.05, 0.1, 0.05, 0.05, 0.5};
    int64_t *slots = malloc(sizeof(int64_t) * 12 * 8 * 8);
    enum { N = sizeof checks / sizeof checks[0] };
    struct moments fd[N] = {{0}}, drt_prb[N] = {{0}}, drt_tape[N] = {{0}}, base[N] = {{0}};
    double *g = malloc(sizeof(double) * (size_t)ps->total);
    const struct dr_estimator_ops *prb = dr_estimator_find("prb"), *tape = dr_estimator_find("tape");
    for (int b = 0; b < BATCHES; b++) {
        uint64_t seed = 100 + (uint64_t)b;
        estimator_grad(prb, DR_MEDIUM_GRAD_DRT, s, &cam, ps, seed, g);
        for (int i = 0; i < N; i++)
            add(&drt_prb[i], dot_slots(g, slots, check_slots(&checks[i], slots)));
        estimator_grad(tape, DR_MEDIUM_GRAD_DRT, s, &cam, ps, seed, g);
        for (int i = 0; i < N; i++)
            add(&drt_tape[i], dot_slots(g, slots, check_slots(&checks[i], slots)));
        estimator_grad(prb, DR_MEDIUM_GRAD_BASELINE, s, &cam, ps, seed, g);
        for (int i = 0; i < N; i++)
            add(&base[i], dot_slots(g, slots, check_slots(&checks[i], slots)));
        for (int i = 0; i < N; i++) {
            int n = check_slots(&checks[i], slots);
            add(&fd[i], finite_difference(s, &cam, ps, slots, n, eps[i], 5000 + (uint64_t)b));
        }
    }
    for (int i = 0; i < N; i++) {
        double zp, zt, zb;
        z_scores(checks[i].what, fd[i], drt_prb[i], drt_tape[i], base[i], &zp, &zt, &zb);
        CHECK(fabs(zp) <= 3.5, "%s: DRT (prb) disagrees with finite differences: z = %.2f", checks[i].what, zp);
        CHECK(fabs(zt) <= 3.5, "%s: DRT (tape) disagrees with finite differences: z = %.2f", checks[i].what, zt);
    }
    /* the empty voxel: the true derivative is clearly not 0, the baseline's is exactly 0 */
    CHECK(fabs(mean(fd[0])) > 4.0 * se(fd[0]), "empty region: finite difference %.5f not significant (se %.5f)",
          mean(fd[0]), se(fd[0]));
    double zb0 = (mean(base[0]) - mean(fd[0])) / sqrt(se(base[0]) * se(base[0]) + se(fd[0]) * se(fd[0]));
    CHECK(fabs(zb0) > 4.0, "baseline in the empty region: expected to fail, z = %.2f", zb0);
    /* where the majorant is not 0 the baseline is unbiased too (null collisions see the voxel) */
    double zb1 = (mean(base[1]) - mean(fd[1])) / sqrt(se(base[1]) * se(base[1]) + se(fd[1]) * se(fd[1]));
    CHECK(fabs(zb1) <= 3.5, "baseline at a non-empty voxel: z = %.2f", zb1);
    /* forward mode, same random numbers: the same directional derivatives */
    for (int mode = 0; mode < 2; mode++)
        for (int i = 0; i < N; i += 5) {   /* the empty region, density_scale */
            int n = check_slots(&checks[i], slots);
            double *dir = calloc((size_t)ps->total, sizeof(double)), *dimg = malloc(sizeof(double) * RES * RES * 3);
            for (int k = 0; k < n; k++)
                dir[slots[k]] = 1.0;
            struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = RES, .height = RES,
                                        .spp = SPP, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 100,
                                        .threads = 2, .sampling = DR_SAMPLING_DETACHED,
                                        .medium_grad = mode ? DR_MEDIUM_GRAD_BASELINE : DR_MEDIUM_GRAD_DRT};
            CHECK(dr_estimator_forward(prb, &p, dir, dimg, NULL) == 0, "forward: %s", dr_last_error());
            double fwd = 0.0;
            for (int k = 0; k < RES * RES * 3; k++)
                fwd += dimg[k] / (RES * RES * 3);
            estimator_grad(prb, p.medium_grad, s, &cam, ps, 100, g);
            double rev = dot_slots(g, slots, n);
            CHECK(fabs(fwd - rev) <= 1e-9 + 1e-6 * fabs(rev), "%s %s: forward %.9g vs reverse %.9g", checks[i].what,
                  mode ? "baseline" : "drt", fwd, rev);
            free(dir);
            free(dimg);
        }
    /* a grid: extinction's and density scale's gain at the collisions, the
     * voxels' from gain paths (medium_grad.c's gain_from_collisions) */
    CHECK(last_gain.collisions && last_gain.grid && last_gain.why == DR_GAIN_GRID && last_gain.stretches == 0,
          "the grid's gain: %s (%s)", last_gain.collisions ? "collisions" : "gain paths",
          dr_gain_reason_name(last_gain.why));
    cross_primal_long_paths(s, &cam, ps);
    free(g);
    free(slots);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Where DRT takes a homogeneous medium's sigma_t gain (medium_grad.c's
 * gain_at_collisions), and so whether its numbers are the baseline's. */
enum gain_source {
    GAIN_PATHS,         /* thin, and few of the pilot's stretches collide: gain paths, numbers differ */
    PILOT_COLLISIONS,   /* thin, but most stretches collide: the pilot picks the collisions */
    THICK_COLLISIONS,   /* thickness >= 1: the collisions, no pilot */
};

/* A homogeneous cube of strongly chromatic extinction, whose free flight
 * is the hero channel's own (medium.c's homogeneous_sample: no null
 * collisions, so the baseline takes each segment's exact transmittance
 * derivative, as DRT does): prb and tape with DRT and prb with the
 * baseline against finite differences. Where DRT takes the gain at the
 * path's collisions, as the baseline does, its numbers are the baseline's
 * to the bit; where it takes gain paths, they differ. */
static void check_homogeneous(dr_vec3 extinction, enum gain_source expect)
{
    fprintf(stderr, "-- a homogeneous chromatic cube, extinction %g / %g / %g\n", extinction.x, extinction.y,
            extinction.z);
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), mat);
    sb_medium(&b, mat, medium(extinction, dr_v3(0.8, 0.7, 0.9), 0.3));
    int floor = sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4)));
    sb_quad(&b, dr_v3(-4, -1.5, -4), dr_v3(0, 0, 8), dr_v3(8, 0, 0), floor);
    sb_environment(&b, dr_v3(0.6, 0.7, 0.9));
    b.s->n_file_materials = b.s->n_materials;
    struct dr_scene *s = sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0.4, 0.8, 4.0), dr_v3(0, 0, 0), 40);
    const char *ptrs[] = {"/materials/0/extensions/DR_medium/extinction", "/materials/0/extensions/DR_medium/albedo",
                          "/materials/0/extensions/DR_medium/density_scale"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 3);
    CHECK(ps != NULL, "param set: %s", dr_last_error());
    if (!ps)
        return;
    const struct check checks[] = {
        {ps->params[0].offset + 0, "extinction r", false}, {ps->params[0].offset + 1, "extinction g", false},
        {ps->params[0].offset + 2, "extinction b", false}, {ps->params[1].offset + 1, "albedo g", false},
        {ps->params[2].offset, "density_scale", false},
    };
    const double eps[] = {0.05, 0.1, 0.2, 0.02, 0.05};
    enum { N = sizeof checks / sizeof checks[0] };
    struct moments fd[N] = {{0}}, drt_prb[N] = {{0}}, drt_tape[N] = {{0}}, base[N] = {{0}};
    double *g = malloc(sizeof(double) * (size_t)ps->total), *g_drt = malloc(sizeof(double) * (size_t)ps->total);
    const struct dr_estimator_ops *prb = dr_estimator_find("prb"), *tape = dr_estimator_find("tape");
    int64_t slot;
    int same_as_baseline = 0;   /* (batch, sigma_t entry) pairs where DRT's number is the baseline's */
    for (int bt = 0; bt < BATCHES; bt++) {
        uint64_t seed = 300 + (uint64_t)bt;
        estimator_grad(prb, DR_MEDIUM_GRAD_DRT, s, &cam, ps, seed, g_drt);
        for (int i = 0; i < N; i++)
            add(&drt_prb[i], g_drt[checks[i].slot]);
        estimator_grad(tape, DR_MEDIUM_GRAD_DRT, s, &cam, ps, seed, g);
        for (int i = 0; i < N; i++)
            add(&drt_tape[i], g[checks[i].slot]);
        estimator_grad(prb, DR_MEDIUM_GRAD_BASELINE, s, &cam, ps, seed, g);
        for (int i = 0; i < N; i++) {
            add(&base[i], g[checks[i].slot]);
            same_as_baseline += i != 3 && g[checks[i].slot] == g_drt[checks[i].slot];   /* (3: albedo) */
        }
        for (int i = 0; i < N; i++) {
            slot = checks[i].slot;
            add(&fd[i], finite_difference(s, &cam, ps, &slot, 1, eps[i], 7000 + (uint64_t)bt));
        }
    }
    for (int i = 0; i < N; i++) {
        double zp, zt, zb;
        z_scores(checks[i].what, fd[i], drt_prb[i], drt_tape[i], base[i], &zp, &zt, &zb);
        const double f = mean(fd[i]), fs = se(fd[i]);
        CHECK(fabs(f) > 3.0 * fs, "%s: the finite difference is not significant (%.5f, se %.5f)", checks[i].what, f,
              fs);
        CHECK(fabs(zp) <= 3.5, "%s: DRT (prb) disagrees with finite differences: z = %.2f", checks[i].what, zp);
        CHECK(fabs(zt) <= 3.5, "%s: DRT (tape) disagrees with finite differences: z = %.2f", checks[i].what, zt);
        CHECK(fabs(zb) <= 3.5, "%s: the baseline disagrees with finite differences: z = %.2f", checks[i].what, zb);
    }
    struct dr_path_opts drt = {.medium_grad = DR_MEDIUM_GRAD_DRT, .params = ps};
    CHECK(last_gain.collisions == (expect != GAIN_PATHS) &&
              last_gain.why == (expect == THICK_COLLISIONS ? DR_GAIN_THICK : DR_GAIN_PILOT),
          "reported: %s (%s)", last_gain.collisions ? "collisions" : "gain paths", dr_gain_reason_name(last_gain.why));
    CHECK(dr_medium_gain_pilot_wanted(s, &drt) == (expect != THICK_COLLISIONS), "the pilot is%s wanted",
          expect != THICK_COLLISIONS ? " not" : "");
    if (expect == GAIN_PATHS)
        CHECK(same_as_baseline < BATCHES, "DRT should take gain paths, yet %d of %d numbers are the baseline's",
              same_as_baseline, 4 * BATCHES);
    else
        CHECK(same_as_baseline == 4 * BATCHES, "DRT took the gain at the collisions, as the baseline, in %d of %d",
              same_as_baseline, 4 * BATCHES);
    free(g_drt);
    free(g);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* The pilot's tally and choice (medium_grad.h) on records made by hand: a
 * crossing of several media counts a segment in each, a collision only in
 * the vertex's medium; the choice takes collisions from 0.4 of the stretches
 * on, given 64 of them; and who asks for a pilot (DRT, a sigma_t
 * parameter, every channel scattering, homogeneous and not thick). */
static void check_pilot_rule(void)
{
    fprintf(stderr, "-- the media pilot's tally and choice\n");
    struct sb b;
    sb_init(&b);
    int thin = sb_material(&b, sb_diffuse(dr_v3s(0.5))), grid = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(0, 1, 1), thin);
    sb_box(&b, dr_v3(0.5, -1, -1), dr_v3(1.5, 1, 1), grid);
    sb_medium(&b, thin, medium(dr_v3(0.2, 0.3, 0.4), dr_v3(0.8, 0.7, 0.9), 0.0));
    struct dr_medium gm = medium(dr_v3(0.2, 0.3, 0.4), dr_v3(0.8, 0.7, 0.9), 0.0);
    set_grid(&gm, 12, 8, 8, dr_v3(0.5, -1, -1), dr_v3(1.5, 1, 1), grid_density);
    sb_medium(&b, grid, gm);
    sb_environment(&b, dr_v3s(1.0));
    b.s->n_file_materials = b.s->n_materials;
    struct dr_scene *s = sb_finish(&b);
    struct dr_medium_tally t[2] = {{0}};
    struct dr_medium_record rec = {.seg = {.n = 2, .p = {{.medium = 0}, {.medium = 1}}}};
    struct dr_path_vertex v = {.kind = DR_VERTEX_MEDIUM, .medium = 1, .mrec = &rec};
    dr_medium_tally_vertex(&v, t);
    v.kind = DR_VERTEX_SURFACE, v.medium = -1;
    dr_medium_tally_vertex(&v, t);
    CHECK(t[0].stretches == 2 && t[0].collisions == 0 && t[1].stretches == 2 && t[1].collisions == 1,
          "tally: %d %d / %d %d (expected 2 0 / 2 1)", (int)t[0].stretches, (int)t[0].collisions, (int)t[1].stretches,
          (int)t[1].collisions);
    v.mrec = NULL;   /* (nothing recorded: nothing counted) */
    dr_medium_tally_vertex(&v, t);
    CHECK(t[0].stretches == 2, "a vertex without a record counted");
    const struct {
        uint64_t stretches, collisions;
        unsigned char expect;
    } cases[] = {{100, 40, 1}, {100, 39, 0}, {64, 64, 1}, {63, 63, 0}, {0, 0, 0}, {1000, 999, 1}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        struct dr_medium_tally ti[2] = {{cases[i].stretches, cases[i].collisions}, {0, 0}};
        unsigned char choice[2] = {9, 9};
        dr_medium_gain_decide(s, ti, choice);
        CHECK(choice[0] == cases[i].expect && choice[1] == 0, "%d of %d stretches collide: chose %d, expected %d",
              (int)cases[i].collisions, (int)cases[i].stretches, choice[0], cases[i].expect);
    }
    const char *thin_ext[] = {"/materials/0/extensions/DR_medium/extinction"},
               *thin_albedo[] = {"/materials/0/extensions/DR_medium/albedo"},
               *grid_ext[] = {"/materials/1/extensions/DR_medium/extinction"};
    const struct {
        const char *const *param;
        enum dr_medium_grad mode;
        dr_vec3 thin_extinction, grid_albedo;
        bool wanted;
    } asks[] = {
        {thin_ext, DR_MEDIUM_GRAD_DRT, {0.2, 0.3, 0.4}, {0.8, 0.7, 0.9}, true},
        {thin_ext, DR_MEDIUM_GRAD_BASELINE, {0.2, 0.3, 0.4}, {0.8, 0.7, 0.9}, false},   /* (collisions everywhere) */
        {thin_albedo, DR_MEDIUM_GRAD_DRT, {0.2, 0.3, 0.4}, {0.8, 0.7, 0.9}, false},     /* (no sigma_t derivative) */
        {thin_ext, DR_MEDIUM_GRAD_DRT, {0.2, 0.3, 0.0}, {0.8, 0.7, 0.9}, false},   /* (a clear channel: gain paths) */
        {grid_ext, DR_MEDIUM_GRAD_DRT, {0.2, 0.3, 0.4}, {0.8, 0.7, 0.9}, false},   /* (a grid: the collisions) */
        {grid_ext, DR_MEDIUM_GRAD_DRT, {0.2, 0.3, 0.4}, {0.8, 0.0, 0.9}, false},   /* (a channel without albedo) */
    };
    for (size_t i = 0; i < sizeof asks / sizeof asks[0]; i++) {
        s->media[0].extinction = asks[i].thin_extinction;
        s->media[1].albedo = asks[i].grid_albedo;
        struct dr_param_set *ps = dr_param_set_create(s, asks[i].param, 1);
        CHECK(ps != NULL, "param set: %s", dr_last_error());
        if (!ps)
            continue;
        struct dr_path_opts o = {.medium_grad = asks[i].mode, .params = ps};
        CHECK(dr_medium_gain_pilot_wanted(s, &o) == asks[i].wanted, "case %zu: %s, %s: the pilot is%s wanted", i,
              asks[i].param[0], dr_medium_grad_name(asks[i].mode), asks[i].wanted ? "" : " not");
        dr_param_set_destroy(ps);
    }
    dr_scene_destroy(s);
}

/* The caller's media plan (medium_grad.h): a second run of the same problem
 * reuses the pilot's choice (the same gradient to the bit, the pilot's rays
 * not traced again), a run without a plan pilots every time, and a run after
 * a medium's values changed pilots again. */
static void check_plan_reuse(void)
{
    fprintf(stderr, "-- the media plan kept between runs\n");
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), mat);
    sb_medium(&b, mat, medium(dr_v3(0.5, 3.0, 9.0), dr_v3(0.8, 0.7, 0.9), 0.3));
    sb_environment(&b, dr_v3(0.6, 0.7, 0.9));
    b.s->n_file_materials = b.s->n_materials;
    struct dr_scene *s = sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0.4, 0.8, 4.0), dr_v3(0, 0, 0), 40);
    const char *ptrs[] = {"/materials/0/extensions/DR_medium/extinction"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 1);
    CHECK(ps != NULL, "param set: %s", dr_last_error());
    if (!ps)
        return;
    static float adj[RES * RES * 3];
    for (int i = 0; i < RES * RES * 3; i++)
        adj[i] = 1.0f / (RES * RES * 3);
    struct dr_media_plan plan = {0};
    struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = RES, .height = RES, .spp = 4,
                                .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 5, .threads = 2,
                                .sampling = DR_SAMPLING_DETACHED, .media_plan = &plan};
    const struct dr_estimator_ops *prb = dr_estimator_find("prb");
    double g[4][3];
    uint64_t rays[4];
    for (int run = 0; run < 4; run++) {
        if (run == 2)
            p.media_plan = NULL;
        if (run == 3) {
            p.media_plan = &plan;
            s->media[0].extinction.x = 0.6;   /* (a new key) */
        }
        const uint64_t key = plan.key;
        struct dr_grad_stats st = {0};
        CHECK(dr_estimator_backward(prb, &p, adj, g[run], &st) == 0, "run %d: %s", run, dr_last_error());
        rays[run] = st.rays.camera + st.rays.extension + st.rays.shadow;
        CHECK(st.n_media_gain == 1 && st.media_gain[0].why == DR_GAIN_PILOT && st.media_gain[0].stretches >= 64,
              "run %d: the choice and the pilot's tally reported", run);
        if (run == 3)
            CHECK(plan.valid && plan.key != key, "run 3: the plan was made again for the new values");
    }
    CHECK(plan.valid && memcmp(g[0], g[1], sizeof g[0]) == 0 && memcmp(g[0], g[2], sizeof g[0]) == 0,
          "the same gradient with the plan kept, and without a plan");
    CHECK(rays[1] < rays[0] && rays[2] == rays[0] && rays[3] > rays[1],
          "rays: %llu first, %llu reusing the plan, %llu without one, %llu after a change",
          (unsigned long long)rays[0], (unsigned long long)rays[1], (unsigned long long)rays[2],
          (unsigned long long)rays[3]);
    dr_media_plan_free(&plan);
    CHECK(!plan.valid && !plan.tally && !plan.collision_gain, "dr_media_plan_free empties the plan");
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* dr_medium_vertex_has_derivative's contract, against d_medium_vertex
 * itself: a vertex of the medium walker it calls free of media terms (its
 * rays stayed out of the cube: the floor seen beside it, the sky) gets
 * nothing from it, with unit adjoints everywhere and DRT's gain paths on
 * every vertex. prb ends its replays at the last vertex with a term by this
 * predicate (estimators/prb.c's walk_vertex). */
static void check_media_predicate(void)
{
    struct dr_scene *s = cube_scene(false);
    struct dr_camera cam = sb_camera(dr_v3(0.4, 0.8, 4.0), dr_v3(0, -0.5, 0), 70);
    const char *ptrs[] = {"/materials/0/extensions/DR_medium/density", "/materials/0/extensions/DR_medium/albedo",
                          "/materials/0/extensions/DR_medium/g", "/materials/0/extensions/DR_medium/extinction",
                          "/materials/0/extensions/DR_medium/density_scale"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 5);
    CHECK(ps != NULL, "predicate: %s", dr_last_error());
    if (!ps)
        return;
    const struct dr_path_opts opts = {.max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, ps),
                                      .params = ps, .medium_grad = DR_MEDIUM_GRAD_DRT};
    struct dr_camera_view view = dr_camera_view(&cam, 32, 32);
    double *g = calloc((size_t)ps->total, sizeof(double));
    struct dr_medium_record rec;
    struct dr_ray_counts rays = {0};
    int with = 0, without = 0, leaks = 0;
    for (int i = 0; i < 3000; i++) {
        struct dr_sampler smp;
        dr_sampler_init(&smp, 5, (uint64_t)i, 0);
        double u, v;
        dr_sampler_next2(&smp, &u, &v);
        dr_vec3 o, d;
        dr_camera_ray(&view, (i % 32) + u, ((i / 32) % 32) + v, &o, &d);
        struct dr_path_state st;
        struct dr_path_vertex vx;
        vx.mrec = &rec;
        dr_path_start(&st, o, d);
        for (bool more = true; more;) {
            more = dr_path_step(s, &opts, &st, &smp, &vx, &rays);
            if (dr_medium_vertex_has_derivative(ps, &vx)) {
                with++;
                continue;
            }
            without++;
            struct dr_grad_sink sink = dr_sink_reverse(g);
            d_medium_vertex(s, &opts, &vx, &rec, 1, dr_v3s(1.0), dr_v3s(1.0), dr_v3s(1.0), dr_v3s(1.0), &sink);
            for (int64_t k = 0; k < ps->total; k++)
                if (g[k] != 0.0) {
                    leaks++;
                    g[k] = 0.0;
                }
        }
    }
    CHECK(with > 100 && without > 100, "media predicate: vertices with %d, without %d (both kinds needed)", with,
          without);
    CHECK(leaks == 0, "media predicate: %d media terms at vertices it calls free of them", leaks);
    fprintf(stderr, "media predicate: %d vertices with a media term, %d without, %d leaks\n", with, without, leaks);
    free(g);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

int main(void)
{
    arrays_beside_media();
    check_media_predicate();
    check_pilot_rule();
    check_plan_reuse();
    /* least extinction x the cube's mean chord of 4/3: thickness 0.13, 0.67, 2.7 */
    check_homogeneous(dr_v3(0.1, 0.2, 0.4), GAIN_PATHS);         /* about a fifth of the stretches collide */
    check_homogeneous(dr_v3(0.5, 3.0, 9.0), PILOT_COLLISIONS);   /* about four fifths */
    check_homogeneous(dr_v3(2.0, 3.0, 9.0), THICK_COLLISIONS);
    check_scene(false);
    check_scene(true);
    return TEST_END();
}
