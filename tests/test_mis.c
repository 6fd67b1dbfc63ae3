/* --sampling mis (estimators/mis.h): detached and attached sampling from the
 * same paths, combined per parameter with cross-fitted weights.
 *  - the combination rule itself, on numbers whose answer is known;
 *  - on the bundled Cornell box: agreement with finite differences (|z| <= 3)
 *    for the red wall's albedo, the gold sphere's roughness at 0.1 and 0.5,
 *    its metallic, and the floor's texture;
 *  - a metallic-roughness texture (a texture that moves the sampling), 4x4
 *    (per-sample statistics) and 12x12 (the groups' statistics), both estimators;
 *  - prb and tape give the same mis gradient to rounding (reverse and forward);
 *  - where no parameter moves a sampling map, mis is detached bit for bit;
 *  - the variance over independent seeds of mis is at most that of the
 *    better of detached and attached (with a statistical margin) on the
 *    roughness cases, and much lower than the worse one. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "fdcheck.h"
#include "mis.h"
#include "render.h"
#include "scene_builder.h"
#include "test.h"

static const char *const RED = "/materials/red/pbrMetallicRoughness/baseColorFactor";
static const char *const ROUGH = "/materials/rough-gold/pbrMetallicRoughness/roughnessFactor";
static const char *const METAL = "/materials/rough-gold/pbrMetallicRoughness/metallicFactor";
static const char *const TEX = "/images/0";

/* ------------------------------------------------ the combination rule */

/* Two segments (entries 0-1 and 2), one pixel per group, hand-made samples:
 * the output must be sum_g (D_g + a_g (A_g - D_g)) with a_g from the
 * statistics of mis.h: per sample, centred per pixel (two samples a pixel),
 * the median of the other groups' own clamped ratios; or (one sample a
 * pixel: nothing to centre on) the clamped leave-one-out ratio of the
 * groups' sums centred on the other groups' mean. */
static double sample_value(int g, int k, int i, bool attached)
{
    /* segment 0: attached much less noisy, its delta anti-correlated with
     * D's noise; segment 1 (entry 2): the two equal */
    double noise = ((g + k) % 2 ? 1.0 : -1.0) * (1.0 + 0.1 * g + 0.3 * k) * (i + 1) + 0.2 * g;
    if (!attached || i == 2)
        return 1.0 + noise;
    return 1.0 + 0.1 * noise - 0.05 * ((g + k) % 3 - 1);
}

typedef double (*sample_fn)(int g, int k, int i, bool attached);

/* Run B's samples: attached noisier than run A's (sample_value), so its own
 * weights differ. */
static double sample_value_b(int g, int k, int i, bool attached)
{
    double v = sample_value(g, k, i, attached);
    return attached && i < 2 ? v + 1.5 * ((g + 3 * k) % 2 ? 1.0 : -1.0) * (1.0 + 0.2 * g) : v;
}

static double clamp01(double x)
{
    return x < 0.0 ? 0.0 : x > 1.0 ? 1.0 : x;
}

/* The median of the clamped -P[h] / Q[h] over h != g (7 values: the 4th). */
static double median_of_others(const double *P, const double *Q, int g)
{
    double v[DR_MIS_GROUPS];
    int n = 0;
    for (int h = 0; h < DR_MIS_GROUPS; h++)
        if (h != g) {
            double x = clamp01(-P[h] / Q[h]);
            int j = n++;
            for (; j > 0 && v[j - 1] > x; j--)   /* insertion sort */
                v[j] = v[j - 1];
            v[j] = x;
        }
    return v[n / 2];
}

/* Group g's own statistics over segment 0 (entries 0-1), its `samples`
 * samples centred on their mean (the pixel's: one pixel a group). */
static void own_stats(sample_fn f, int g, int samples, double *P, double *Q)
{
    *P = *Q = 0.0;
    for (int i = 0; i < 2; i++) {
        double Ds = 0.0, Es = 0.0;
        for (int k = 0; k < samples; k++) {
            double dk = f(g, k, i, false), ek = f(g, k, i, true) - dk;
            *P += dk * ek;
            *Q += ek * ek;
            Ds += dk;
            Es += ek;
        }
        *P -= Ds * Es / samples;
        *Q -= Es * Es / samples;
    }
}

/* One mis run over f's samples (`samples` per group, one pixel per group,
 * sample k on thread k: the sums are what count) with history h (may be
 * NULL), combined into out and w. */
static void run_rule(sample_fn f, int samples, struct dr_mis_history *h, double out[3], double w[2])
{
    struct dr_mis_accum m;
    int64_t off[2] = {0, 2}, size[2] = {2, 1}, px[DR_MIS_GROUPS];
    for (int g = 0; g < DR_MIS_GROUPS; g++)   /* a pixel of each group */
        for (px[g] = 0; dr_mis_group(px[g]) != g; px[g]++)
            ;
    CHECK(dr_mis_init(&m, samples, 3, 2, off, size, 64, false) == 0 && m.per_sample, "init: %s", dr_last_error());
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        for (int k = 0; k < samples; k++) {
            double d[3], a[3];
            for (int i = 0; i < 3; i++) {
                d[i] = f(g, k, i, false);
                a[i] = f(g, k, i, true);
            }
            dr_mis_add(&m, k, px[g], 0, 3, d, a);
        }
    dr_mis_combine(&m, out, w, h);
    dr_mis_free(&m);
}

/* Groups' sums of f over its samples: D[g][i], A[g][i]. */
static void group_sums(sample_fn f, int samples, double D[DR_MIS_GROUPS][3], double A[DR_MIS_GROUPS][3])
{
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        for (int i = 0; i < 3; i++) {
            D[g][i] = A[g][i] = 0.0;
            for (int k = 0; k < samples; k++) {
                D[g][i] += f(g, k, i, false);
                A[g][i] += f(g, k, i, true);
            }
        }
}

static void combine_rule(int samples)
{
    double out[3], w[2];
    run_rule(sample_value, samples, NULL, out, w);
    /* each group's weight by hand, as mis.h says it is chosen */
    double D[DR_MIS_GROUPS][3], A[DR_MIS_GROUPS][3], P[DR_MIS_GROUPS] = {0}, Q[DR_MIS_GROUPS] = {0},
           ag[DR_MIS_GROUPS];
    group_sums(sample_value, samples, D, A);
    if (samples == 2) {
        for (int g = 0; g < DR_MIS_GROUPS; g++)
            own_stats(sample_value, g, samples, &P[g], &Q[g]);
        for (int g = 0; g < DR_MIS_GROUPS; g++)
            ag[g] = median_of_others(P, Q, g);
    } else {
        for (int g = 0; g < DR_MIS_GROUPS; g++)
            for (int i = 0; i < 2; i++) {
                double md = 0.0, me = 0.0;
                for (int h = 0; h < DR_MIS_GROUPS; h++)
                    if (h != g) {
                        md += D[h][i] / (DR_MIS_GROUPS - 1);
                        me += (A[h][i] - D[h][i]) / (DR_MIS_GROUPS - 1);
                    }
                for (int h = 0; h < DR_MIS_GROUPS; h++)
                    if (h != g) {
                        double e = A[h][i] - D[h][i] - me;
                        P[g] += (D[h][i] - md) * e;
                        Q[g] += e * e;
                    }
            }
        for (int g = 0; g < DR_MIS_GROUPS; g++)
            ag[g] = clamp01(-P[g] / Q[g]);
    }
    double want[2] = {0.0, 0.0}, wsum = 0.0;
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        for (int i = 0; i < 2; i++)
            want[i] += D[g][i] + ag[g] * (A[g][i] - D[g][i]);
        wsum += 1.0 - ag[g];
    }
    CHECK_NEAR(out[0], want[0], 1e-12, "combined entry 0");
    CHECK_NEAR(out[1], want[1], 1e-12, "combined entry 1");
    CHECK_NEAR(w[0], wsum / DR_MIS_GROUPS, 1e-12, "segment 0's detached weight");
    CHECK(w[0] < 0.5, "%d sample(s) a pixel: segment 0 should lean on the attached estimate (weight of detached %.3f)",
          samples, w[0]);
    double d2 = 0.0;
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        d2 += D[g][2];
    CHECK_NEAR(out[2], d2, 1e-12, "identical estimates: their common value");
    CHECK(w[1] == 1.0, "identical estimates: all weight on detached (got %.3f)", w[1]);
}

/* Run B after run A with a history: group h's statistics for B's weights
 * are A_h + B_h, the weight of g their median over h != g; and the history
 * must change B's weight (else the check above proves nothing). */
static void history_rule(void)
{
    struct dr_mis_history h;
    CHECK(dr_mis_history_init(&h, 2) == 0, "history init");
    double out_a[3], out_a0[3], w_a[2], w_a0[2], out_b0[3], w_b0[2], out[3], w[2];
    run_rule(sample_value, 2, &h, out_a, w_a);
    run_rule(sample_value, 2, NULL, out_a0, w_a0);
    CHECK(memcmp(out_a, out_a0, sizeof out_a) == 0 && w_a[0] == w_a0[0], "an empty history changes nothing");
    run_rule(sample_value_b, 2, NULL, out_b0, w_b0);
    run_rule(sample_value_b, 2, &h, out, w);
    double P[DR_MIS_GROUPS], Q[DR_MIS_GROUPS], D[DR_MIS_GROUPS][3], A[DR_MIS_GROUPS][3], want = 0.0, wsum = 0.0;
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        double pa, qa, pb, qb;
        own_stats(sample_value, g, 2, &pa, &qa);
        own_stats(sample_value_b, g, 2, &pb, &qb);
        P[g] = pa + pb;
        Q[g] = qa + qb;
    }
    group_sums(sample_value_b, 2, D, A);
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        double ag = median_of_others(P, Q, g);
        want += D[g][0] + ag * (A[g][0] - D[g][0]);
        wsum += 1.0 - ag;
    }
    CHECK_NEAR(out[0], want, 1e-12, "run B with the history: entry 0");
    CHECK_NEAR(w[0], wsum / DR_MIS_GROUPS, 1e-12, "run B with the history: the weight");
    CHECK(fabs(w[0] - w_b0[0]) > 0.05, "the history should move run B's weight (%.3f alone, %.3f with it)",
          w_b0[0], w[0]);
    dr_mis_history_free(&h);
}

/* ------------------------------------------------------ the Cornell box */

static struct dr_scene *cornell(double roughness)
{
    const char *path = scene_path("cornell-box.gltf");
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return NULL;
    for (int m = 0; m < s->n_materials; m++)
        if (strcmp(s->materials[m].name, "rough-gold") == 0)
            s->materials[m].roughness = roughness;
    CHECK(dr_scene_refresh(s) == 0, "refresh");
    return s;
}

static struct dr_grad_problem problem(const struct dr_scene *s, const struct dr_param_set *ps, int res, int spp,
                                      uint64_t seed, enum dr_sampling smp)
{
    return (struct dr_grad_problem){.scene = s, .camera = &s->cameras[0], .params = ps, .width = res,
                                    .height = res, .spp = spp, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT,
                                    .seed = seed, .threads = 2, .sampling = smp,
                                    .regularize = DR_PRB_REGULARIZE_DEFAULT};
}

/* mis against finite differences, prb, |z| <= 3. may_be_zero: the label
 * prefix of entries whose true derivative may be ~0 (not required to be
 * resolved: the mean image barely depends on roughness at 0.1, and a random
 * +-1 texel pattern's derivative is ~0 by design); NULL: all resolved. */
static void fd_case(const char *what, double roughness, const char *ptr, const char *may_be_zero)
{
    struct dr_scene *s = cornell(roughness);
    if (!s)
        return;
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "%s: %s", what, dr_last_error());
    struct dr_fd_options o = {.estimator = dr_estimator_find("prb"), .sampling = DR_SAMPLING_MIS, .width = 16,
                              .height = 16, .spp = 32, .batches = 16, .max_depth = 6,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 99, .threads = 2, .eps = 1e-2,
                              .z_max = 3.0, .regularize = DR_PRB_REGULARIZE_DEFAULT};
    struct dr_fd_entry *en = NULL;
    int count = 0;
    CHECK(ps && dr_fdcheck(s, &s->cameras[0], ps, &o, &en, &count) == 0, "%s: fdcheck: %s", what, dr_last_error());
    for (int i = 0; i < count; i++) {
        printf("fdcheck mis %-16s %-60s rev %.5g +- %.2g  fwd %.5g +- %.2g  fd %.5g +- %.2g  z %.2f %.2f\n", what,
               en[i].label, en[i].reverse, en[i].reverse_se, en[i].forward, en[i].forward_se, en[i].fd, en[i].fd_se,
               en[i].z_reverse, en[i].z_forward);
        CHECK(en[i].agree, "%s: %s: mis %.6g / %.6g vs finite differences %.6g (z %.2f, %.2f)", what, en[i].label,
              en[i].reverse, en[i].forward, en[i].fd, en[i].z_reverse, en[i].z_forward);
        bool exempt = may_be_zero && strncmp(en[i].label, may_be_zero, strlen(may_be_zero)) == 0;
        CHECK(exempt || fabs(en[i].fd) > 3.0 * en[i].fd_se,
              "%s: %s: finite differences too noisy to judge (%.3g +- %.3g)", what, en[i].label, en[i].fd,
              en[i].fd_se);
    }
    free(en);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Roughness moves where light goes more than how much of it: the mean image
 * (fdcheck's objective) barely depends on it at 0.1 (fd_case cannot resolve
 * it there). So also the highlight's contrast on the sphere (a crop of a
 * 32x32 frame): J = sum_px w_px I_px with w = a sharp reference render minus
 * its mean over the crop. The mis gradient (adjoint w) against central
 * differences of J with common random numbers, K independent seeds,
 * |z| <= 3, and the difference resolved. */
static const struct dr_film SPHERE = {.frame_w = 32, .frame_h = 32, .x0 = 18, .y0 = 20};
enum { SPHERE_W = 9, SPHERE_H = 10 };

static double weighted_J(struct dr_scene *s, int mat, double rough, const float *w, int spp, uint64_t seed,
                         float *img)
{
    s->materials[mat].roughness = rough;
    dr_scene_refresh(s);
    struct dr_render_opts ro = {.width = SPHERE_W, .height = SPHERE_H, .spp = spp, .max_depth = 6,
                                .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = seed, .threads = 2, .film = SPHERE};
    CHECK(dr_render(s, &s->cameras[0], &ro, img, NULL) == 0, "render: %s", dr_last_error());
    double J = 0.0;
    for (int i = 0; w && i < SPHERE_W * SPHERE_H * 3; i++)
        J += (double)w[i] * img[i];
    return J;
}

static void weighted_fd_case(double rough)
{
    struct dr_scene *s = cornell(rough);
    if (!s)
        return;
    int mat = 0;
    while (strcmp(s->materials[mat].name, "rough-gold") != 0)
        mat++;
    const char *ptr = ROUGH;
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    const int n = SPHERE_W * SPHERE_H * 3, K = 16;
    const double eps = 0.02;
    float *w = malloc(sizeof(float) * n), *img = malloc(sizeof(float) * n);
    weighted_J(s, mat, rough, NULL, 1024, 777, w);
    double mean = 0.0;
    for (int i = 0; i < n; i++)
        mean += w[i] / n;
    for (int i = 0; i < n; i++)
        w[i] = (float)((w[i] - mean) / n);
    double gs = 0, gq = 0, fs = 0, fq = 0;
    for (int k = 0; k < K; k++) {
        double g = 0.0;
        struct dr_grad_problem p = problem(s, ps, SPHERE_W, 64, 500 + (uint64_t)k, DR_SAMPLING_MIS);
        p.height = SPHERE_H;
        p.film = SPHERE;
        s->materials[mat].roughness = rough;
        dr_scene_refresh(s);
        CHECK(dr_estimator_backward(dr_estimator_find("prb"), &p, w, &g, NULL) == 0, "%s", dr_last_error());
        double fd = (weighted_J(s, mat, rough + eps, w, 512, 500 + (uint64_t)k, img) -
                     weighted_J(s, mat, rough - eps, w, 512, 500 + (uint64_t)k, img)) / (2.0 * eps);
        gs += g;
        gq += g * g;
        fs += fd;
        fq += fd * fd;
    }
    s->materials[mat].roughness = rough;
    double gm = gs / K, fm = fs / K;
    double gse = sqrt((gq - gs * gm) / (K - 1) / K), fse = sqrt((fq - fs * fm) / (K - 1) / K);
    double z = (gm - fm) / sqrt(gse * gse + fse * fse);
    printf("weighted J, roughness %.2f: mis %.5g +- %.2g, fd %.5g +- %.2g, z %.2f\n", rough, gm, gse, fm, fse, z);
    CHECK(fabs(z) <= 3.0, "weighted J, roughness %.2f: mis %.5g +- %.2g vs fd %.5g +- %.2g (z %.2f)", rough, gm, gse,
          fm, fse, z);
    /* at 0.1 the derivative (~ -0.02) is below what 16 seeds resolve; there
     * the error bar must at least be tight enough that an error of twice
     * the 0.5 derivative (~0.1) would fail */
    if (rough >= 0.5)
        CHECK(fabs(fm) > 3.0 * fse, "weighted J, roughness %.2f: finite differences unresolved (%.3g +- %.3g)", rough,
              fm, fse);
    else
        CHECK(3.0 * sqrt(gse * gse + fse * fse) < 0.1, "weighted J, roughness %.2f: error bars too wide to judge "
              "(%.3g, %.3g)", rough, gse, fse);
    free(w);
    free(img);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* A texture that moves the sampling: a metal floor whose metallic-roughness
 * texture (G = roughness 0.15..0.55, B = metallic 1) is the parameter, under
 * an environment map with a gradient (so roughness shows). n x n texels:
 * 4 x 4 (48 entries: per-sample statistics) and 12 x 12 (432 > 256: the
 * groups' statistics, mis.h). mis against finite differences, both
 * estimators, |z| <= 3; the weights are a real mix, reported. */
static void roughness_texture(int n)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.9, 0.8, 0.6));
    m.metallic = 1.0;
    m.roughness = 1.0;   /* factors multiply the texture */
    m.specular = 1.0;
    m.metallic_roughness_tex.texture = 0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, m));
    sb_environment_ramp(&b);
    float *px = malloc(sizeof(float) * n * n * 3);
    for (int i = 0; i < n * n; i++) {
        px[3 * i] = 0.0f;
        px[3 * i + 1] = (float)(0.15 + 0.4 * ((i * 7) % 11) / 10.0);
        px[3 * i + 2] = 1.0f;
    }
    struct dr_scene *s = b.s;
    s->n_images = 1;
    s->images = calloc(1, sizeof(struct dr_image));
    s->images[0] = sb_image(n, n, 3, px, 0.0f, false);
    free(px);
    s->n_textures = 1;
    s->textures = calloc(1, sizeof(struct dr_texture));
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *ptr = "/images/0";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "roughness texture: %s", dr_last_error());
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 1), dr_v3(0, 0, -1), 40);
    for (int e = 0; ps && dr_estimators[e]; e++) {
        struct dr_fd_options o = {.estimator = dr_estimators[e], .sampling = DR_SAMPLING_MIS, .width = 16,
                                  .height = 16, .spp = 16, .batches = 8, .max_depth = 3,
                                  .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 21, .threads = 2, .eps = 1e-2,
                                  .z_max = 3.0, .regularize = DR_PRB_REGULARIZE_DEFAULT};
        struct dr_fd_entry *en = NULL;
        int count = 0;
        CHECK(dr_fdcheck(s, &cam, ps, &o, &en, &count) == 0 && count == 2, "roughness texture: %s", dr_last_error());
        for (int i = 0; i < count; i++) {
            printf("mis %s, %dx%d roughness texture, %-32s rev %.5g +- %.2g  fwd %.5g +- %.2g  fd %.5g +- %.2g  "
                   "z %.2f %.2f\n",
                   dr_estimators[e]->name, n, n, en[i].label, en[i].reverse, en[i].reverse_se, en[i].forward,
                   en[i].forward_se, en[i].fd, en[i].fd_se, en[i].z_reverse, en[i].z_forward);
            CHECK(en[i].agree, "%dx%d roughness texture (%s): %s: mis %.6g / %.6g vs fd %.6g (z %.2f, %.2f)", n, n,
                  dr_estimators[e]->name, en[i].label, en[i].reverse, en[i].forward, en[i].fd, en[i].z_reverse,
                  en[i].z_forward);
            CHECK(fabs(en[i].fd) > 3.0 * en[i].fd_se, "%dx%d roughness texture: %s unresolved (%.3g +- %.3g)", n, n,
                  en[i].label, en[i].fd, en[i].fd_se);
        }
        free(en);
    }
    /* the weight chosen for the texture (reverse mode, uniform adjoint) */
    float *adj = malloc(sizeof(float) * 16 * 16 * 3);
    for (int i = 0; i < 16 * 16 * 3; i++)
        adj[i] = 1.0f;
    double *g = calloc((size_t)(ps ? ps->total : 1), sizeof(double)), w = NAN;
    struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = 16, .height = 16, .spp = 16,
                                .max_depth = 3, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 3, .threads = 2,
                                .sampling = DR_SAMPLING_MIS, .regularize = DR_PRB_REGULARIZE_DEFAULT,
                                .mis_weights = &w};
    CHECK(ps && dr_estimator_backward(dr_estimator_find("prb"), &p, adj, g, NULL) == 0, "%s", dr_last_error());
    printf("%dx%d roughness texture: weight of detached %.3f\n", n, n, w);
    CHECK(w >= 0.0 && w <= 1.0, "%dx%d roughness texture: weight %.3f", n, n, w);
    free(adj);
    free(g);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* prb and tape, reverse and forward mode, same seed: equal to rounding; and
 * the weights they report equal. With roughness and albedo requested
 * together, the albedo's weight is all detached (the two estimates coincide). */
static void prb_equals_tape(void)
{
    struct dr_scene *s = cornell(0.1);
    if (!s)
        return;
    const char *ptrs[] = {ROUGH, RED};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 2);
    const int res = 12, n = res * res * 3;
    float *adj = malloc(sizeof(float) * n);
    for (int i = 0; i < n; i++)
        adj[i] = (float)(0.5 + 0.25 * ((i * 7) % 5));
    double gp[4], gt[4], wp[2], wt[2], *ip = calloc(n, sizeof(double)), *it = calloc(n, sizeof(double));
    struct dr_grad_problem p = problem(s, ps, res, 4, 5, DR_SAMPLING_MIS);
    p.mis_weights = wp;
    int rc = dr_estimator_backward(dr_estimator_find("prb"), &p, adj, gp, NULL);
    p.mis_weights = wt;
    rc |= dr_estimator_backward(dr_estimator_find("tape"), &p, adj, gt, NULL);
    CHECK(rc == 0, "reverse: %s", dr_last_error());
    for (int i = 0; i < 4; i++)
        CHECK(fabs(gp[i] - gt[i]) <= 1e-9 * (fabs(gt[i]) + 1e-12), "reverse entry %d: prb %.17g tape %.17g", i,
              gp[i], gt[i]);
    CHECK(fabs(wp[0] - wt[0]) <= 1e-9 && wp[0] < 1.0, "roughness weights: prb %.6f tape %.6f", wp[0], wt[0]);
    CHECK(wp[1] == 1.0 && wt[1] == 1.0, "albedo weights: prb %.6f tape %.6f (want 1: detached)", wp[1], wt[1]);
    printf("prb = tape (mis): roughness %.9g vs %.9g, weight of detached %.4f\n", gp[0], gt[0], wp[0]);
    double dir[4] = {1.0, 0.0, 0.0, 0.0};
    p.mis_weights = NULL;
    rc = dr_estimator_forward(dr_estimator_find("prb"), &p, dir, ip, NULL);
    rc |= dr_estimator_forward(dr_estimator_find("tape"), &p, dir, it, NULL);
    CHECK(rc == 0, "forward: %s", dr_last_error());
    int differ = 0;
    double norm = 0.0;
    for (int i = 0; i < n; i++)
        norm += fabs(it[i]);
    /* relative, plus an absolute floor far below the image's scale: where
     * tape has an exact 0, prb's Jacobian solves leave ~1e-19 */
    for (int i = 0; i < n; i++)
        differ += fabs(ip[i] - it[i]) > 1e-9 * fabs(it[i]) + 1e-12 * norm / n;
    CHECK(differ == 0 && norm > 0.0, "forward: %d of %d pixels differ (norm %.3g)", differ, n, norm);
    free(adj);
    free(ip);
    free(it);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Albedo, metallic (no sampling map moves): mis is the detached run, bit for bit. */
static void detached_when_nothing_moves(void)
{
    struct dr_scene *s = cornell(0.35);
    if (!s)
        return;
    const char *ptrs[] = {RED, METAL};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 2);
    const int n = 8 * 8 * 3;
    float adj[8 * 8 * 3];
    for (int i = 0; i < n; i++)
        adj[i] = 1.0f;
    for (int e = 0; dr_estimators[e]; e++) {
        double gd[4], gm[4], w[2] = {0.0, 0.0};
        struct dr_grad_stats st;
        struct dr_grad_problem p = problem(s, ps, 8, 4, 11, DR_SAMPLING_DETACHED);
        int rc = dr_estimator_backward(dr_estimators[e], &p, adj, gd, NULL);
        p.sampling = DR_SAMPLING_MIS;
        p.mis_weights = w;
        rc |= dr_estimator_backward(dr_estimators[e], &p, adj, gm, &st);
        CHECK(rc == 0, "%s: %s", dr_estimators[e]->name, dr_last_error());
        CHECK(memcmp(gd, gm, sizeof gd) == 0, "%s: mis differs from detached", dr_estimators[e]->name);
        CHECK(st.sampling_run == DR_SAMPLING_DETACHED && w[0] == 1.0 && w[1] == 1.0,
              "%s: ran %s, weights %.3f %.3f", dr_estimators[e]->name, dr_sampling_name(st.sampling_run), w[0], w[1]);
    }
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Variance over independent seeds, d (mean image) / d roughness. The three
 * estimates share each seed's paths, so the comparison is paired. The seeds
 * are mis's runs as grad's batches are (drivers/reverse.c): each run's
 * weights also use the earlier runs' statistics (a dr_mis_history); its own
 * 2k samples alone miss attached's tail at roughness 0.5 (without the
 * history: mis 2.1x detached's variance here). */
static void variance_case(double roughness)
{
    struct dr_scene *s = cornell(roughness);
    if (!s)
        return;
    const char *ptr = ROUGH;
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    const int res = 16, n = res * res * 3, seeds = 24;
    float *adj = malloc(sizeof(float) * n);
    for (int i = 0; i < n; i++)
        adj[i] = 1.0f / n;
    double sum[3] = {0, 0, 0}, sq[3] = {0, 0, 0}, wsum = 0.0, secs[3] = {0, 0, 0};
    struct dr_mis_history hist;
    CHECK(dr_mis_history_init(&hist, 1) == 0, "history init");
    for (int k = 0; k < seeds; k++)
        for (int m = 0; m < 3; m++) {
            double g = 0.0, w = NAN;
            struct dr_grad_stats st;
            struct dr_grad_problem p = problem(s, ps, res, 8, 1000 + (uint64_t)k, (enum dr_sampling)m);
            p.mis_weights = &w;
            p.mis_history = &hist;
            CHECK(dr_estimator_backward(dr_estimator_find("prb"), &p, adj, &g, &st) == 0, "%s",
                  dr_last_error());
            sum[m] += g;
            sq[m] += g * g;
            secs[m] += st.seconds;
            if (m == DR_SAMPLING_MIS)
                wsum += w;
        }
    double var[3];
    dr_mis_history_free(&hist);
    for (int m = 0; m < 3; m++)
        var[m] = (sq[m] - sum[m] * sum[m] / seeds) / (seeds - 1);
    double best = fmin(var[0], var[1]), worst = fmax(var[0], var[1]);
    printf("roughness %.3g: std detached %.4g attached %.4g mis %.4g (mean weight of detached %.3f); "
           "means %.4g %.4g %.4g; seconds %.2f %.2f %.2f\n",
           roughness, sqrt(var[0]), sqrt(var[1]), sqrt(var[2]), wsum / seeds, sum[0] / seeds, sum[1] / seeds,
           sum[2] / seeds, secs[0], secs[1], secs[2]);
    /* the margin: the weights are estimated from 7 groups each run, which
     * costs a little against the optimum; and 24 seeds estimate a variance
     * to about +-30% (paired: the ratio is tighter) */
    CHECK(var[2] <= 1.25 * best, "roughness %.3g: mis variance %.4g above the better one's %.4g", roughness, var[2],
          best);
    CHECK(var[2] < worst, "roughness %.3g: mis variance %.4g not below the worse one's %.4g", roughness, var[2],
          worst);
    free(adj);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

int main(void)
{
    combine_rule(2);
    combine_rule(1);
    history_rule();
    prb_equals_tape();
    detached_when_nothing_moves();
    variance_case(0.1);
    variance_case(0.5);
    fd_case("albedo", 0.35, RED, NULL);
    fd_case("roughness 0.1", 0.1, ROUGH, "/materials/4/pbrMetallicRoughness/roughnessFactor");
    weighted_fd_case(0.1);
    weighted_fd_case(0.5);
    fd_case("roughness 0.5", 0.5, ROUGH, NULL);
    fd_case("metallic", 0.35, METAL, NULL);
    fd_case("texture", 0.35, TEX, "/images/0 (random");
    roughness_texture(4);
    roughness_texture(12);
    return TEST_END();
}
