/* Participating media against analytic answers: slab transmittance (free
 * flight through the camera ray and ratio tracking for shadow rays), the
 * furnace (albedo 1 in a white environment: radiance 1 everywhere, whatever
 * the extinction per channel, density grid or phase function), hard cases
 * (extinction 1e4, albedo 0.999 at depth 1000, sharp-edged grids);
 * dielectric boundaries: Fresnel values, the fraction of paths a flat
 * interface reflects (= Fresnel), Snell's law and the 1/eta^2 weight, total
 * internal reflection, and the furnace inside glass (still 1). */
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
    printf("%s: mean %.5f %.5f %.5f (stderr %.2g %.2g %.2g)\n", what, st.mean.x, st.mean.y, st.mean.z, st.se.x,
           st.se.y, st.se.z);
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

/* An unbounded (global) medium with a channel that does not attenuate
 * (extinction 0.4 / 0 / 1.2, absorbing only), around a camera looking at
 * the sky: green comes through whole, red and blue are absorbed on the
 * way to infinity. The hero channel green never collides; free flight took
 * a step per tentative collision against the largest extinction and never
 * got to the end of the ray (the render hung). */
static void test_clear_channel_to_infinity(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-0.1, -0.1, 30), dr_v3(0.2, 0, 0), dr_v3(0, 0.2, 0), sb_material(&b, sb_diffuse(dr_v3s(0.5))));
    sb_medium(&b, -1, medium(dr_v3(0.4, 0.0, 1.2), dr_v3s(0.0), 0.0));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_scene *s = sb_finish(&b);
    check_mean("unbounded medium, green not attenuated", render_stats(s, sb_camera(dr_v3(0, 0, 0), dr_v3(0, 0, -1), 40),
                                                                      16, 64, 8),
               dr_v3(0.0, 1.0, 0.0), 1e-9);
    /* the free flight itself: a pass to infinity, the attenuating channels'
     * probabilities 0 against green's */
    struct dr_sampler rng = {.key = 5, .dim = 0};
    struct dr_spectral_mis mis = {1, {1.0, 1.0, 1.0}};
    double t = -1.0;
    enum dr_medium_event ev = dr_medium_sample(&s->media[0], dr_v3s(0.0), dr_v3(0, 0, -1), INFINITY, &rng, &mis, &t);
    CHECK(ev == DR_MEDIUM_PASS && mis.r[0] == 0.0 && mis.r[1] > 0.0 && mis.r[2] == 0.0,
          "hero green passes to infinity: event %d, r %g %g %g", (int)ev, mis.r[0], mis.r[1], mis.r[2]);
    dr_scene_destroy(s);
}

/* dr_medium_collision_ahead against dr_medium_sample with the same numbers:
 * where it names a distance, free flight collides exactly there whatever
 * tmax lies beyond it (the walker traces its ray only that far,
 * medium_path.c), and passes for any tmax before it; where it says
 * INFINITY, free flight to infinity passes. Random rays from inside and
 * outside a bounded chromatic medium (a channel of extinction 0 among
 * them) and an unbounded one; a grid medium never names a distance. */
static void test_collision_ahead(void)
{
    struct dr_medium box = medium(dr_v3(2.0, 0.0, 40.0), dr_v3s(0.7), 0.0);
    box.bounded = true;
    box.bmin = dr_v3(-1, -1, -1);
    box.bmax = dr_v3(1, 1, 1);
    struct dr_medium open = medium(dr_v3(0.3, 1.0, 3.0), dr_v3s(0.9), 0.0);
    const struct dr_medium *ms[2] = {&box, &open};
    int bad = 0, finite = 0, infinite = 0;
    struct dr_sampler pick = {.key = 77, .dim = 0};
    for (int i = 0; i < 20000; i++) {
        const struct dr_medium *m = ms[i & 1];
        dr_vec3 o = dr_v3(4.0 * dr_sampler_next(&pick) - 2.0, 4.0 * dr_sampler_next(&pick) - 2.0,
                          4.0 * dr_sampler_next(&pick) - 2.0);
        dr_vec3 d = dr_normalize(dr_v3(dr_sampler_next(&pick) - 0.5, dr_sampler_next(&pick) - 0.5,
                                       dr_sampler_next(&pick) - 0.5));
        const int hero = (int)(dr_sampler_next(&pick) * 3.0) % 3;
        const struct dr_sampler rng = {.key = dr_hash64((uint64_t)i), .dim = 40, .kind = DR_SAMPLER_INDEPENDENT};
        const double ahead = dr_medium_collision_ahead(m, o, d, rng, hero);
        const double tmaxes[3] = {INFINITY, isinf(ahead) ? 1.0 : ahead * 1.5 + 1e-3,
                                  isinf(ahead) ? 10.0 : ahead * 0.5};
        for (int k = 0; k < 3; k++) {
            struct dr_sampler r = rng;
            struct dr_spectral_mis mis = {hero, {1.0, 1.0, 1.0}};
            double t = -1.0;
            enum dr_medium_event ev = dr_medium_sample(m, o, d, tmaxes[k], &r, &mis, &t);
            const bool collides = ev != DR_MEDIUM_PASS;
            const bool expect = !isinf(ahead) && ahead < tmaxes[k];
            bad += collides != expect || (collides && t != ahead);
            bad += k == 0 && isinf(ahead) && collides;
        }
        finite += !isinf(ahead);
        infinite += isinf(ahead);
    }
    CHECK(bad == 0, "%d free flights disagree with the collision ahead", bad);
    CHECK(finite > 5000 && infinite > 2000, "both cases drawn: %d with a collision ahead, %d without", finite, infinite);
    struct dr_medium g = medium(dr_v3s(1.0), dr_v3s(0.5), 0.0);
    set_grid(&g, 2, 2, 2, dr_v3s(-1.0), dr_v3s(1.0), constant_one);
    CHECK(isinf(dr_medium_collision_ahead(&g, dr_v3s(0.0), dr_v3(0, 0, 1), (struct dr_sampler){.key = 1}, 0)),
          "a grid medium names no distance (delta tracking needs the surface first)");
    free(g.grid.density);
}

/* Shadow rays from deep inside a thick homogeneous slab (extinction 20 /
 * 30 / 50, half-thickness 0.5: every channel below 1 % within 0.23) play
 * Russian roulette (medium_scene.c): most give 0, the rest 10 times the
 * transmittance, whose mean over many rays is the exact exp(-sigma 0.5).
 * A ray whose boundary is within that distance is exact, every time. */
static void test_shadow_roulette(void)
{
    const dr_vec3 sigma = dr_v3(20.0, 30.0, 50.0);
    struct dr_scene *s = slab_scene(medium(sigma, dr_v3s(0.5), 0.0));
    const int n = 40000;
    double sum[3] = {0}, sq[3] = {0};
    int zero = 0;
    uint64_t rays = 0;
    for (int i = 0; i < n; i++) {
        struct dr_sampler rng = {.key = dr_hash64(0x5eed + (uint64_t)i), .dim = 0};
        dr_vec3 T = dr_media_transmittance(s, dr_v3(0, 0, 0), dr_v3(0, 0, 1), INFINITY, 0, &rng, &rays, NULL);
        zero += dr_is_black(T);
        for (int c = 0; c < 3; c++) {
            sum[c] += dr_v3_get(T, c);
            sq[c] += dr_v3_get(T, c) * dr_v3_get(T, c);
        }
    }
    CHECK(zero > 0.85 * n && zero < 0.95 * n, "roulette: %d of %d shadow rays ended (expected about 90 %%)", zero, n);
    for (int c = 0; c < 3; c++) {
        const double mean = sum[c] / n, se = sqrt((sq[c] / n - mean * mean) / (n - 1));
        const double exact = exp(-dr_v3_get(sigma, c) * 0.5);
        CHECK(fabs(mean - exact) <= 4.0 * se && se > 0.0, "roulette channel %d: mean %.6g, exact %.6g (se %.2g)", c,
              mean, exact, se);
    }
    CHECK(rays < (uint64_t)n * 2, "killed rays cost one query each (%llu queries for %d rays)",
          (unsigned long long)rays, n);
    /* the boundary 0.1 away: no roulette, the exact transmittance every time */
    int inexact = 0;
    for (int i = 0; i < 1000; i++) {
        struct dr_sampler rng = {.key = dr_hash64(0xface + (uint64_t)i), .dim = 0};
        dr_vec3 T = dr_media_transmittance(s, dr_v3(0, 0, 0.4), dr_v3(0, 0, 1), INFINITY, 0, &rng, &rays, NULL);
        for (int c = 0; c < 3; c++)
            inexact += fabs(dr_v3_get(T, c) - exp(-dr_v3_get(sigma, c) * 0.1)) > 1e-3 * exp(-dr_v3_get(sigma, c) * 0.1);
    }
    CHECK(inexact == 0, "near the boundary: %d transmittances differ from the exact one", inexact);
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
    /* a channel that does not attenuate: the furnace still holds */
    s = furnace_scene(medium(dr_v3(5.0, 0.0, 50.0), dr_v3s(1.0), 0.2));
    check_mean("furnace with a clear green channel", render_stats(s, cam, 8, 64, 100000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);
    /* extinctions 10^8 apart: free flight took 10^8 tentative collisions per
     * collision of the weakest channel (a render did not finish in a minute);
     * now one step each: finite, and the red channel, whose paths stop at
     * the depth limit inside, darker than blue */
    s = furnace_scene(medium(dr_v3(1e8, 1e4, 1.0), dr_v3s(0.9), 0.0));
    st = render_stats(s, cam, 8, 4, 200);
    CHECK(st.mean.x >= 0.0 && st.mean.x < st.mean.z && st.mean.z <= 1.0, "extinction 1e8 / 1e4 / 1: mean %.4f %.4f %.4f",
          st.mean.x, st.mean.y, st.mean.z);
    dr_scene_destroy(s);
}

/* ------------------------------------------------------ dielectric boundaries */

static void test_fresnel(void)
{
    double ct;
    /* values of the s/p formulas for n = 1.5 (computed independently) */
    CHECK_NEAR(dr_fresnel_dielectric(1.0, 1.5, &ct), 0.04, 1e-12, "normal incidence ((n-1)/(n+1))^2");
    CHECK_NEAR(ct, 1.0, 1e-12, "normal incidence cos_t");
    CHECK_NEAR(dr_fresnel_dielectric(cos(M_PI / 4), 1.5, &ct), 0.05023991101223594, 1e-12, "45 degrees");
    CHECK_NEAR(dr_fresnel_dielectric(0.5, 1.5, &ct), 0.08918671280221274, 1e-12, "60 degrees");
    CHECK_NEAR(dr_fresnel_dielectric(cos(atan(1.5)), 1.5, &ct), 0.07396449704142012, 1e-12,
               "Brewster's angle: p reflects nothing");
    /* from inside: total internal reflection beyond asin(1/1.5) = 41.8 degrees */
    CHECK(dr_fresnel_dielectric(cos(0.75), 1.0 / 1.5, &ct) == 1.0 && ct == 0.0, "total internal reflection");
    /* reciprocity: the same interface seen from the other side */
    for (double ci = 0.05; ci < 1.0; ci += 0.1) {
        double f = dr_fresnel_dielectric(ci, 1.5, &ct), ct2;
        double back = dr_fresnel_dielectric(ct, 1.0 / 1.5, &ct2);
        CHECK(fabs(back - f) <= 1e-12 && fabs(ct2 - ci) <= 1e-12, "reciprocity at cos %.2f: %.15f vs %.15f", ci,
              back, f);
    }
}

/* A box [-4,4]x[-4,4]x[-1,1] bounding a clear medium behind a dielectric of
 * index 1.5 (nothing else: the vertex alone is looked at). */
static struct dr_scene *glass_slab(void)
{
    struct sb b;
    sb_init(&b);
    int mat = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_box(&b, dr_v3(-4, -4, -1), dr_v3(4, 4, 1), mat);
    struct dr_medium m = medium(dr_v3s(0.0), dr_v3s(1.0), 0.0);
    m.ior = 1.5;
    sb_medium(&b, mat, m);
    return sb_finish(&b);
}

/* One step from o along d, many times: the fraction reflected and what
 * reflection and refraction do to the ray and the throughput. */
static void interface_trials(struct dr_scene *s, dr_vec3 o, dr_vec3 d, double eta, int n, const char *what)
{
    struct dr_path_opts opts = {.max_depth = 8, .rr_depth = 5, .stages = dr_path_plan(s, NULL)};
    CHECK(opts.stages & DR_STAGE_DIELECTRIC, "%s: the plan has the dielectric stage", what);
    dr_vec3 nrm = dr_v3(0, 0, d.z < 0 ? 1 : -1);   /* the hit face's normal on the incident side */
    double cos_i = -dr_dot(d, nrm), ct;
    double F = dr_fresnel_dielectric(cos_i, eta, &ct);
    int reflected = 0, bad = 0;
    for (int i = 0; i < n; i++) {
        struct dr_sampler smp;
        dr_sampler_init(&smp, 6, (uint64_t)i, 0);
        struct dr_path_state st;
        struct dr_path_vertex v;
        struct dr_ray_counts rays = {0};
        v.mrec = NULL;
        dr_path_start(&st, o, d);
        bool more = dr_path_step(s, &opts, &st, &smp, &v, &rays);
        if (!more || v.kind != DR_VERTEX_DIELECTRIC || v.nee || v.emits) {
            bad++;
            continue;
        }
        dr_vec3 mirror = dr_v3(d.x, d.y, -d.z);
        if (dr_dot(st.d, nrm) > 0.0) {
            reflected++;
            bad += dr_length(dr_sub(st.d, mirror)) > 1e-12 || fabs(st.beta.x - 1.0) > 1e-15;
        } else {
            double sin_t = sqrt(st.d.x * st.d.x + st.d.y * st.d.y), sin_i = sqrt(d.x * d.x + d.y * d.y);
            bad += fabs(sin_t - sin_i / eta) > 1e-12 || fabs(st.beta.x - 1.0 / (eta * eta)) > 1e-12 ||
                   st.d.x * d.x < 0.0;
        }
    }
    double frac = (double)reflected / n, se = sqrt(F * (1.0 - F) / n);
    CHECK(bad == 0, "%s: %d steps with a wrong event, direction or weight", what, bad);
    CHECK(fabs(frac - F) <= 4.0 * se + 1e-12, "%s: reflected %.5f of the paths, Fresnel %.5f (se %.2g)", what, frac,
          F, se);
    printf("%s: reflected fraction %.5f, Fresnel %.5f\n", what, frac, F);
}

static void test_dielectric_interface(void)
{
    struct dr_scene *s = glass_slab();
    for (double deg = 0.0; deg < 80.0; deg += 25.0) {
        double th = deg * M_PI / 180.0;
        dr_vec3 d = dr_v3(sin(th), 0.0, -cos(th));
        char what[64];
        snprintf(what, sizeof what, "outside, %.0f degrees", deg);
        interface_trials(s, dr_sub(dr_v3(0, 0, 1), dr_scale(d, 2.0)), d, 1.5, 20000, what);
    }
    /* from inside at 35 degrees (refracts) and 50 (beyond the critical 41.8: always reflects) */
    interface_trials(s, dr_v3(0, 0, 0), dr_v3(sin(0.61), 0.0, -cos(0.61)), 1.0 / 1.5, 20000, "inside, 35 degrees");
    interface_trials(s, dr_v3(0, 0, 0), dr_v3(sin(0.87), 0.0, -cos(0.87)), 1.0 / 1.5, 2000, "inside, 50 degrees");
    /* shadow rays do not cross the interface */
    struct dr_sampler rng;
    dr_sampler_init(&rng, 1, 2, 3);
    uint64_t rays = 0;
    dr_vec3 tr = dr_media_transmittance(s, dr_v3(0, 0, 0), dr_v3(0, 0, 1), INFINITY, 0, &rng, &rays, NULL);
    CHECK(dr_is_black(tr), "a shadow ray through a dielectric boundary is blocked");
    dr_scene_destroy(s);
}

/* The furnace inside glass: albedo 1, a white sky, a box of index 1.5. A
 * path that enters and leaves carries (1/1.5^2)(1.5^2) = 1 and every path
 * leaves: the image is 1 (next-event estimation inside is blocked by the
 * interface; light comes through the specular chain with MIS weight 1). */
static void test_glass_furnace(void)
{
    struct dr_camera cam = sb_camera(dr_v3(0.3, 0.5, 4), dr_v3(0, 0, 0), 30);
    struct dr_medium m = medium(dr_v3s(0.0), dr_v3s(1.0), 0.0);
    m.ior = 1.5;
    struct dr_scene *s = furnace_scene(m);
    check_mean("clear glass furnace", render_stats(s, cam, 16, 16, 10000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);
    m = medium(dr_v3(0.5, 2.0, 8.0), dr_v3s(1.0), 0.6);
    m.ior = 1.5;
    s = furnace_scene(m);
    check_mean("RGB fog in glass furnace", render_stats(s, cam, 16, 32, 10000), dr_v3s(1.0), 1e-3);
    dr_scene_destroy(s);
    m = medium(dr_v3(1.0, 4.0, 2.0), dr_v3s(1.0), -0.3);
    m.ior = 1.33;
    set_grid(&m, 12, 10, 9, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), noise);
    s = furnace_scene(m);
    check_mean("grid in water furnace", render_stats(s, cam, 16, 32, 10000), dr_v3s(1.0), 1e-3);
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
    test_clear_channel_to_infinity();
    test_collision_ahead();
    test_shadow_roulette();
    test_furnace();
    test_fresnel();
    test_dielectric_interface();
    test_glass_furnace();
    return TEST_END();
}
