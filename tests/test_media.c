/* Participating media against analytic answers: slab transmittance (free
 * flight through the camera ray and ratio tracking for shadow rays), the
 * furnace (albedo 1 in a white environment: radiance 1 everywhere, whatever
 * the extinction per channel, density grid or phase function), hard cases
 * (extinction 1e4, albedo 0.999 at depth 1000, sharp-edged grids). */
#include <stdlib.h>

#include "error.h"
#include "medium_scene.h"
#include "render.h"
#include "media_builder.h"
#include "test.h"

struct stats {
    dr_vec3 mean, se;
};

static struct stats render_stats(struct dr_scene *s, struct dr_camera cam, int res, int spp, int depth)
{
    float *rgb = malloc(sizeof(float) * 3 * res * res);
    struct dr_render_opts o = {.width = res, .height = res, .spp = spp, .max_depth = depth,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 11, .threads = 2};
    struct dr_render_stats st;
    int rc = dr_render(s, &cam, &o, rgb, &st);
    CHECK(rc == 0, "dr_render failed: %s", dr_last_error());
    CHECK(st.invalid_samples == 0, "%llu non-finite samples", (unsigned long long)st.invalid_samples);
    double sum[3] = {0}, sq[3] = {0};
    int n = res * res;
    for (int i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            sum[c] += rgb[3 * i + c];
            sq[c] += (double)rgb[3 * i + c] * rgb[3 * i + c];
        }
    struct stats r;
    double m[3], se[3];
    for (int c = 0; c < 3; c++) {
        m[c] = sum[c] / n;
        se[c] = sqrt(fmax(0.0, sq[c] / n - m[c] * m[c]) / (n - 1));
    }
    r.mean = dr_v3(m[0], m[1], m[2]);
    r.se = dr_v3(se[0], se[1], se[2]);
    free(rgb);
    return r;
}

static void check_mean(const char *what, struct stats st, dr_vec3 expect, double rel_slack)
{
    for (int c = 0; c < 3; c++) {
        double m = dr_v3_get(st.mean, c), e = dr_v3_get(expect, c), se = dr_v3_get(st.se, c);
        double tol = 4.0 * se + rel_slack * fabs(e);
        CHECK(fabs(m - e) <= tol, "%s channel %d: mean %.6f, expected %.6f (tol %.2g, stderr %.2g)", what, c, m, e,
              tol, se);
    }
}

/* ------------------------------------------------------------------ slab */

static double half_dense(int x, int y, int z)
{
    (void)x, (void)y;
    return z < 8 ? 1.0 : 0.0;   /* a sharp edge halfway along z */
}

static double constant_one(int x, int y, int z)
{
    (void)x, (void)y, (void)z;
    return 1.0;
}

/* A slab |z| < 0.5 (wide in x, y) in front of a white environment, seen
 * along -z through a 0.5 degree field of view: pixel = exp(-tau) per channel. */
static struct dr_scene *slab_scene(struct dr_medium m)
{
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-50, -50, -0.5), dr_v3(50, 50, 0.5), mat);
    sb_medium(&b, mat, m);
    sb_environment(&b, dr_v3s(1.0));
    return sb_finish(&b);
}

static void test_slab_transmittance(void)
{
    const dr_vec3 sigma = dr_v3(0.5, 1.0, 2.0);
    struct dr_camera cam = sb_camera(dr_v3(0, 0, 5), dr_v3(0, 0, 0), 0.5);
    dr_vec3 expect = dr_v3(exp(-0.5), exp(-1.0), exp(-2.0));

    struct dr_scene *s = slab_scene(medium(sigma, dr_v3s(0.0), 0.0));
    CHECK((s->effects & DR_FX_MEDIA) && !(s->effects & DR_FX_HETEROGENEOUS_MEDIA), "effects %x", s->effects);
    CHECK(dr_path_plan(s, NULL) & DR_STAGE_MEDIA, "media scene must plan the medium stage");
    check_mean("homogeneous slab, free flight", render_stats(s, cam, 16, 64, 8), expect, 1e-3);
    dr_scene_destroy(s);

    /* the same slab as a constant grid: spectral tracking with DDA majorants */
    struct dr_medium g = medium(sigma, dr_v3s(0.0), 0.0);
    set_grid(&g, 8, 8, 16, dr_v3(-50, -50, -0.5), dr_v3(50, 50, 0.5), constant_one);
    s = slab_scene(g);
    CHECK(s->effects & DR_FX_HETEROGENEOUS_MEDIA, "grid medium: heterogeneous_media effect");
    check_mean("grid slab, free flight", render_stats(s, cam, 16, 64, 8), expect, 1e-3);
    dr_scene_destroy(s);

    /* half the slab empty behind a sharp edge: the trilinear ramp integrates
     * to exactly half the optical depth */
    g = medium(sigma, dr_v3s(0.0), 0.0);
    set_grid(&g, 8, 8, 16, dr_v3(-50, -50, -0.5), dr_v3(50, 50, 0.5), half_dense);
    s = slab_scene(g);
    dr_vec3 half = dr_v3(exp(-0.25), exp(-0.5), exp(-1.0));
    check_mean("sharp-edged grid slab", render_stats(s, cam, 16, 64, 8), half, 1e-3);

    /* ratio tracking (shadow rays) through the same grid, from outside to outside */
    struct dr_sampler smp;
    dr_sampler_init(&smp, 3, 0, 0);
    dr_vec3 sum = dr_v3s(0.0);
    const int n = 20000;
    uint64_t rays = 0;
    for (int i = 0; i < n; i++) {
        dr_sampler_init(&smp, 3, (uint64_t)i, 0);
        sum = dr_add(sum, dr_media_transmittance(s, dr_v3(0.1, 0.2, 3), dr_v3(0, 0, -1), 6.0, -1, &smp, &rays, NULL));
    }
    sum = dr_scale(sum, 1.0 / n);
    for (int c = 0; c < 3; c++)
        CHECK_NEAR(dr_v3_get(sum, c), dr_v3_get(half, c), 0.02 * dr_v3_get(half, c), "ratio tracking through grid");
    CHECK(rays >= (uint64_t)n * 3, "shadow rays cross both boundaries (%llu queries)", (unsigned long long)rays);
    dr_scene_destroy(s);

    /* homogeneous transmittance is exact (up to the ray offsets at the two
     * boundaries, 1e-5 of the 50 m slab each) */
    s = slab_scene(medium(sigma, dr_v3s(0.0), 0.0));
    dr_vec3 T = dr_media_transmittance(s, dr_v3(0, 0, 3), dr_v3(0, 0, -1), 6.0, -1, &smp, &rays, NULL);
    for (int c = 0; c < 3; c++)
        CHECK_NEAR(dr_v3_get(T, c), dr_v3_get(expect, c), 3e-3 * dr_v3_get(expect, c), "homogeneous transmittance");
    CHECK(dr_medium_at(s, dr_v3(0, 0, 0), dr_v3(0, 0, 1)) == 0, "a point inside the slab is in its medium");
    CHECK(dr_medium_at(s, dr_v3(0, 0, 3), dr_v3(0, 0, -1)) == -1, "a point outside is in vacuum");
    dr_scene_destroy(s);
}

/* --------------------------------------------------------------- furnace */

static double noise(int x, int y, int z)
{
    uint64_t h = dr_hash64((uint64_t)(x * 73856093 ^ y * 19349663 ^ z * 83492791));
    return (h >> 11) * (1.0 / 9007199254740992.0) * 3.0 * (z % 3 != 0);   /* some empty slices */
}

/* A medium box with albedo 1 under a white sky (and no other surface): every
 * path carries exactly 1, so the image is 1 (energy conservation of the
 * tracking weights, NEE transmittance, phase MIS). */
static struct dr_scene *furnace_scene(struct dr_medium m)
{
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), mat);
    sb_medium(&b, mat, m);
    sb_environment(&b, dr_v3s(1.0));
    return sb_finish(&b);
}

static void test_furnace(void)
{
    struct dr_camera cam = sb_camera(dr_v3(0.3, 0.5, 4), dr_v3(0, 0, 0), 30);
    struct dr_scene *s = furnace_scene(medium(dr_v3(0.5, 2.0, 8.0), dr_v3s(1.0), 0.6));
    check_mean("homogeneous RGB furnace", render_stats(s, cam, 16, 32, 10000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);

    struct dr_medium g = medium(dr_v3(1.0, 4.0, 2.0), dr_v3s(1.0), -0.3);
    set_grid(&g, 12, 10, 9, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), noise);
    s = furnace_scene(g);
    check_mean("heterogeneous RGB furnace", render_stats(s, cam, 16, 32, 10000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);

    /* albedo 0.999 at depth 1000 in an optically thick box: finite, below 1 */
    s = furnace_scene(medium(dr_v3s(30.0), dr_v3s(0.999), 0.0));
    struct stats st = render_stats(s, cam, 8, 8, 1000);
    CHECK(st.mean.x < 1.0 && st.mean.x > 0.3, "albedo 0.999 furnace %.4f", st.mean.x);
    dr_scene_destroy(s);

    /* extinction 1e4: the box is opaque (absorbing) or a white wall (scattering) */
    s = furnace_scene(medium(dr_v3s(1e4), dr_v3s(0.0), 0.0));
    st = render_stats(s, cam, 8, 4, 100);
    CHECK(st.mean.x >= 0.0 && st.mean.x < 1.0, "extinction 1e4 absorbing mean %.4f", st.mean.x);
    dr_scene_destroy(s);
    s = furnace_scene(medium(dr_v3(1e4, 1e3, 1e2), dr_v3s(1.0), 0.0));
    check_mean("extinction 1e4 furnace", render_stats(s, cam, 8, 16, 100000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);
}

/* ------------------------------------------------------------- the phase */

static void test_hg(void)
{
    for (double g = -0.8; g <= 0.81; g += 0.4) {
        /* integrates to 1 over the sphere (midpoint rule in cos) */
        double sum = 0.0;
        const int n = 20000;
        for (int i = 0; i < n; i++)
            sum += dr_hg_eval(g, -1.0 + 2.0 * (i + 0.5) / n) * 2.0 * M_PI * 2.0 / n;
        CHECK_NEAR(sum, 1.0, 1e-3, "HG normalisation");
        /* sampling: mean cosine is g, and the returned pdf is the density */
        double mc = 0.0;
        struct dr_sampler smp;
        dr_sampler_init(&smp, 1, 2, 3);
        dr_vec3 d = dr_normalize(dr_v3(0.3, -0.5, 0.8));
        for (int i = 0; i < n; i++) {
            dr_vec3 wi;
            double pdf = dr_hg_sample(g, d, dr_sampler_next(&smp), dr_sampler_next(&smp), &wi);
            mc += dr_dot(wi, d) / n;
            CHECK(fabs(pdf - dr_hg_eval(g, dr_dot(wi, d))) <= 1e-9 * pdf, "pdf");
        }
        CHECK_NEAR(mc, g, 0.02, "HG mean cosine");
    }
    CHECK_NEAR(dr_albedo_from_multiscatter(0.0), 0.0, 1e-4, "multiscatter 0");
    CHECK_NEAR(dr_albedo_from_multiscatter(1.0), 1.0, 1e-4, "multiscatter 1");
}

int main(void)
{
    test_hg();
    test_slab_transmittance();
    test_furnace();
    return TEST_END();
}
