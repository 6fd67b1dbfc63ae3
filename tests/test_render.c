/* Analytic scenes with known radiance, rendered through dr_render, checked
 * within statistical tolerances (pixels are independent estimates, so their
 * spread gives the standard error of the image mean). */
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "error.h"
#include "film.h"
#include "lights.h"
#include "render.h"
#include "sampler.h"
#include "params.h"
#include "path_simd.h"
#include "media_builder.h"
#include "scene_builder.h"
#include "wave_soa.h"
#include "wavefront.h"
#include "test.h"

struct stats {
    dr_vec3 mean, stderr_;
    double min, max;
};

static struct stats render_stats(struct dr_scene *s, struct dr_camera cam, int res, int spp, int depth)
{
    float *rgb = malloc(sizeof(float) * 3 * res * res);
    struct dr_render_opts o = {.width = res, .height = res, .spp = spp, .max_depth = depth,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 7, .threads = 2};
    struct dr_render_stats st;
    /* (the cameras here are not the scene's: backface.h) */
    CHECK(dr_scene_add_viewpoint(s, &cam) == 0, "add_viewpoint: %s", dr_last_error());
    int rc = dr_render(s, &cam, &o, rgb, &st);
    CHECK(rc == 0, "dr_render failed: %s", dr_last_error());
    CHECK(st.invalid_samples == 0, "%llu non-finite samples", (unsigned long long)st.invalid_samples);
    double sum[3] = {0}, sq[3] = {0};
    struct stats r = {dr_v3s(0), dr_v3s(0), INFINITY, -INFINITY};
    int n = res * res;
    for (int i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double v = rgb[3 * i + c];
            sum[c] += v;
            sq[c] += v * v;
            r.min = fmin(r.min, v);
            r.max = fmax(r.max, v);
        }
    double m[3], se[3];
    for (int c = 0; c < 3; c++) {
        m[c] = sum[c] / n;
        se[c] = sqrt(fmax(0.0, sq[c] / n - m[c] * m[c]) / (n - 1));
    }
    r.mean = dr_v3(m[0], m[1], m[2]);
    r.stderr_ = dr_v3(se[0], se[1], se[2]);
    free(rgb);
    return r;
}

/* mean within k standard errors (plus a relative slack for tiny errors) */
static void check_mean(const char *what, struct stats st, dr_vec3 expect, double rel_slack)
{
    double m[3] = {st.mean.x, st.mean.y, st.mean.z}, e[3] = {expect.x, expect.y, expect.z},
           se[3] = {st.stderr_.x, st.stderr_.y, st.stderr_.z};
    for (int c = 0; c < 3; c++) {
        double tol = 4.0 * se[c] + rel_slack * fabs(e[c]);
        CHECK(fabs(m[c] - e[c]) <= tol, "%s channel %d: mean %.6f, expected %.6f (tol %.2g, stderr %.2g)", what, c,
              m[c], e[c], tol, se[c]);
    }
}

static void test_emitter_seen_directly(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = dr_v3(2, 3, 4);
    sb_quad(&b, dr_v3(-50, -50, -1), dr_v3(100, 0, 0), dr_v3(0, 100, 0), sb_material(&b, m));
    struct dr_scene *s = sb_finish(&b);
    struct stats st = render_stats(s, sb_camera(dr_v3(0, 0, 0), dr_v3(0, 0, -1), 40), 16, 4, 8);
    CHECK_NEAR(st.mean.x, 2.0, 1e-6, "emitter red");
    CHECK_NEAR(st.mean.y, 3.0, 1e-6, "emitter green");
    CHECK_NEAR(st.mean.z, 4.0, 1e-6, "emitter blue");
    /* seen from behind, a single-sided emitter is black */
    st = render_stats(s, sb_camera(dr_v3(0, 0, -2), dr_v3(0, 0, -1), 40), 8, 2, 8);
    CHECK(st.max == 0.0, "back of single-sided emitter: max %g", st.max);
    dr_scene_destroy(s);
}

static void test_diffuse_plane_constant_env(void)
{
    for (int depth = 2; depth <= 6; depth += 4) {
        struct sb b;
        sb_init(&b);
        dr_vec3 albedo = dr_v3(0.8, 0.5, 0.2), E = dr_v3(0.5, 1.0, 2.0);
        sb_quad(&b, dr_v3(-100, 0, 100), dr_v3(200, 0, 0), dr_v3(0, 0, -200), sb_material(&b, sb_diffuse(albedo)));
        sb_environment(&b, E);
        struct dr_scene *s = sb_finish(&b);
        struct stats st = render_stats(s, sb_camera(dr_v3(0, 1, 0), dr_v3(0, 0, 0), 20), 32, 16, depth);
        /* (the pixels are floats: 2^-24 of the value) */
        check_mean("diffuse plane under constant environment", st, dr_mul(albedo, E), 1e-7);
        /* next-event estimation samples the sky by the cosine about the
         * normal, the BSDF by the cosine too: on a surface open to the sky
         * both samples are exact, so no pixel differs from albedo E (over
         * the whole sphere the pixels' spread was 2e-3 of their mean) */
        const double se[3] = {st.stderr_.x, st.stderr_.y, st.stderr_.z}, m[3] = {st.mean.x, st.mean.y, st.mean.z};
        for (int c = 0; c < 3; c++)
            CHECK(se[c] <= 1e-8 * m[c], "diffuse plane under constant environment, depth %d: channel %d's pixels "
                  "spread by %.3g of their mean (exact samples: none)", depth, c, se[c] / m[c]);
        dr_scene_destroy(s);
    }
}

/* The sky sampled by dr_sky_pdf's mixture of the cosine about the normal
 * and the BSDF against over the whole sphere (dr_path_opts' sky_uniform),
 * where neither is exact: a dielectric floor with a GGX lobe (both halves
 * of the mixture), a tilted panel whose smooth shading normals lean away
 * from its geometric one, and a glossy metal box (the BSDF's half alone)
 * that hides part of the sky from both. The same 400 camera rays, 500
 * paths each: the two strategies are independent estimates of the same
 * radiance, so their means must agree; the mixture's spread about each
 * ray's mean must be smaller. */
static void test_sky_mixture_matches_sphere(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material floor = sb_diffuse(dr_v3(0.7, 0.6, 0.5));
    floor.roughness = 0.35;
    floor.specular = 0.5;   /* a dielectric GGX lobe over the diffuse one */
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, floor));
    sb_quad(&b, dr_v3(-1.5, 0.2, -1.0), dr_v3(3, 0, 0), dr_v3(0, 2, -0.6), sb_material(&b, sb_diffuse(dr_v3s(0.8))));
    struct dr_material metal = sb_diffuse(dr_v3(0.3, 0.5, 0.7));
    metal.metallic = 1.0;
    metal.roughness = 0.3;
    metal.specular = 1.0;
    sb_box(&b, dr_v3(0.4, 0, 0.2), dr_v3(1.2, 0.9, 1.0), sb_material(&b, metal));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.2));
    struct dr_scene *s = b.s;
    for (uint32_t v = 4; v < 8; v++) {   /* the panel's vertices: normals tilted apart */
        dr_vec3 n = dr_normalize(dr_v3(0.5 * ((v & 1) ? 1 : -1), 0.2, 1.0 + 0.3 * (v & 2)));
        s->mesh.normals[3 * v] = (float)n.x, s->mesh.normals[3 * v + 1] = (float)n.y;
        s->mesh.normals[3 * v + 2] = (float)n.z;
    }
    s->mesh.flags[2] |= DR_TRI_HAS_NORMALS;
    s->mesh.flags[3] |= DR_TRI_HAS_NORMALS;
    sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0, 1.4, 3.0), dr_v3(0, 0.4, -0.5), 55);
    CHECK(dr_scene_add_viewpoint(s, &cam) == 0, "add_viewpoint: %s", dr_last_error());
    struct dr_camera_view view = dr_camera_view(&cam, 1, 1);
    enum { RAYS = 400, PATHS = 500 };
    double mean[2], se[2];
    for (int uniform = 0; uniform < 2; uniform++) {
        struct dr_path_opts po = {.max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, NULL),
                                  .sky_uniform = uniform};
        struct dr_ray_counts rays = {0};
        double sum = 0.0, spread = 0.0;   /* spread: sum over rays of their paths' squared deviations */
        int invalid = 0;
        for (int r = 0; r < RAYS; r++) {
            struct dr_sampler pixel;
            dr_sampler_init(&pixel, 5, (uint64_t)r, 0);   /* (the same rays for both) */
            double jx = dr_sampler_next(&pixel), jy = dr_sampler_next(&pixel), ray_sum = 0.0, ray_sum2 = 0.0;
            dr_vec3 o, d;
            dr_camera_ray(&view, jx, jy, &o, &d);
            for (int i = 0; i < PATHS; i++) {
                struct dr_sampler smp;
                dr_sampler_init(&smp, 11 + (uint64_t)uniform, (uint64_t)r, (uint64_t)i);
                dr_vec3 L = dr_path_radiance(s, &po, o, d, &smp, &rays);
                invalid += !dr_v3_finite(L);
                double y = L.x + L.y + L.z;
                ray_sum += y, ray_sum2 += y * y;
            }
            sum += ray_sum;
            spread += fmax(0.0, ray_sum2 - ray_sum * ray_sum / PATHS);
        }
        CHECK(invalid == 0, "sky %s: %d paths not finite", uniform ? "over the sphere" : "by the mixture", invalid);
        mean[uniform] = sum / (RAYS * PATHS);
        se[uniform] = sqrt(spread / (RAYS * (PATHS - 1.0)) / (RAYS * PATHS));   /* (the rays fixed: their paths' spread) */
    }
    const double z = (mean[0] - mean[1]) / hypot(se[0], se[1]);
    CHECK(fabs(z) <= 4.0, "sky by the mixture %.5f +- %.5f against over the sphere %.5f +- %.5f (z %.2f)", mean[0],
          se[0], mean[1], se[1], z);
    CHECK(se[0] < 0.9 * se[1], "sky by the mixture: standard error %.3g, not below over the sphere's %.3g", se[0], se[1]);
    printf("    | sky by the mixture %.5f +- %.5f, over the sphere %.5f +- %.5f (z %.2f)\n", mean[0], se[0], mean[1],
           se[1], z);
    dr_scene_destroy(s);
}

/* A white open box (fronts inside, open at the top) under uniform radiance 1:
 * every interreflection bounce matters, and a white Lambertian must render
 * exactly the environment (the furnace test). */
static struct dr_scene *furnace_scene(struct dr_material mat)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, mat));
    sb_environment(&b, dr_v3s(1.0));
    return sb_finish(&b);
}

static void test_furnace(void)
{
    struct dr_scene *s = furnace_scene(sb_diffuse(dr_v3s(1.0)));
    struct dr_camera cam = sb_camera(dr_v3(0.1, 4, 0.2), dr_v3(0, 0, 0), 35);
    struct stats st = render_stats(s, cam, 32, 32, 1000);
    check_mean("white Lambertian furnace", st, dr_v3s(1.0), 0.0);
    CHECK(fabs(st.mean.x - 1.0) < 0.01, "furnace mean %.5f off by more than 1%%", st.mean.x);
    dr_scene_destroy(s);

    /* A rough white metal loses energy (single-scattering microfacets), never
     * gains it, and loses more the rougher it is. */
    double prev = 2.0;
    for (double rough = 0.2; rough <= 1.0; rough += 0.4) {
        struct dr_material m = sb_diffuse(dr_v3s(1.0));
        m.metallic = 1.0;
        m.roughness = rough;
        m.specular = 1.0;
        s = furnace_scene(m);
        st = render_stats(s, cam, 32, 32, 1000);
        CHECK(st.mean.x <= 1.0 + 4.0 * st.stderr_.x, "rough metal %.1f furnace %.5f > 1", rough, st.mean.x);
        CHECK(st.mean.x < prev - 4.0 * st.stderr_.x, "rough metal %.1f furnace %.5f not darker than %.5f", rough,
              st.mean.x, prev);
        prev = st.mean.x;
        dr_scene_destroy(s);
    }
}

static struct dr_punctual light(enum dr_light_type type, dr_vec3 pos, dr_vec3 dir, double intensity)
{
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = type;
    l.color = dr_v3(1.0, 0.5, 0.25);
    l.intensity = intensity;
    l.position = pos;
    l.direction = dir;
    l.cos_inner = cos(10 * M_PI / 180);
    l.cos_outer = cos(20 * M_PI / 180);
    return l;
}

static void test_punctual(void)
{
    dr_vec3 albedo = dr_v3(0.6, 0.6, 0.6);
    double h = 2.0, I = 5.0;
    for (int t = 0; t < 4; t++) {
        struct sb b;
        sb_init(&b);
        sb_quad(&b, dr_v3(-100, 0, 100), dr_v3(200, 0, 0), dr_v3(0, 0, -200), sb_material(&b, sb_diffuse(albedo)));
        struct dr_punctual l;
        double expect;
        const char *what;
        if (t == 0) {
            l = light(DR_LIGHT_POINT, dr_v3(0, h, 0), dr_v3(0, -1, 0), I);
            expect = I / (h * h);
            what = "point light";
        } else if (t == 1) {
            l = light(DR_LIGHT_SPOT, dr_v3(0, h, 0), dr_v3(0, -1, 0), I);
            expect = I / (h * h);
            what = "spot light, inside the cone";
        } else if (t == 2) {
            l = light(DR_LIGHT_SPOT, dr_v3(0, h, 0), dr_normalize(dr_v3(1, -0.3, 0)), I);
            expect = 0.0;
            what = "spot light, outside the cone";
        } else {
            l = light(DR_LIGHT_DIRECTIONAL, dr_v3(0, 0, 0), dr_v3(0, -1, 0), I);
            expect = I;
            what = "directional light";
        }
        sb_light(&b, l);
        struct dr_scene *s = sb_finish(&b);
        /* camera just beside the light looking straight down, a 1 degree view */
        struct stats st = render_stats(s, sb_camera(dr_v3(0, h - 1e-3, 0), dr_v3(0, 0, 0), 1.0), 8, 2, 4);
        dr_vec3 e = dr_scale(dr_mul(albedo, l.color), expect * DR_INV_PI);
        check_mean(what, st, e, 1e-3);
        dr_scene_destroy(s);
    }
}

/* A ceiling that emits everywhere above a diffuse floor: the floor's direct
 * lighting is albedo * Le, which needs both MIS strategies summed right. */
static void test_area_light_mis(void)
{
    struct sb b;
    sb_init(&b);
    dr_vec3 albedo = dr_v3(0.7, 0.4, 0.9), Le = dr_v3(1.5, 2.0, 0.5);
    sb_quad(&b, dr_v3(-500, 0, 500), dr_v3(1000, 0, 0), dr_v3(0, 0, -1000), sb_material(&b, sb_diffuse(albedo)));
    struct dr_material em = sb_diffuse(dr_v3s(0.0));
    em.emissive_factor = Le;
    sb_quad(&b, dr_v3(-500, 1, 500), dr_v3(0, 0, -1000), dr_v3(1000, 0, 0), sb_material(&b, em)); /* faces -y */
    struct dr_scene *s = sb_finish(&b);
    struct stats st = render_stats(s, sb_camera(dr_v3(0, 0.5, 0), dr_v3(0, 0, 0), 30), 32, 16, 2);
    check_mean("floor under an emitting ceiling", st, dr_mul(albedo, Le), 1e-4);
    dr_scene_destroy(s);

    /* a small emitter far away: the inverse-square law with both cosines */
    sb_init(&b);
    sb_quad(&b, dr_v3(-100, 0, 100), dr_v3(200, 0, 0), dr_v3(0, 0, -200), sb_material(&b, sb_diffuse(albedo)));
    double side = 0.02, hgt = 2.0;
    sb_quad(&b, dr_v3(-side / 2, hgt, side / 2), dr_v3(0, 0, -side), dr_v3(side, 0, 0), sb_material(&b, em));
    s = sb_finish(&b);
    st = render_stats(s, sb_camera(dr_v3(0, 0.5, 0), dr_v3(0, 0, 0), 0.5), 16, 16, 2);
    double E = side * side / (hgt * hgt);   /* irradiance / Le for a small source overhead */
    check_mean("small area light", st, dr_scale(dr_mul(albedo, Le), E * DR_INV_PI), 2e-3);
    dr_scene_destroy(s);
}

/* Environment-map importance sampling: the density dr_light_sample reports is
 * the one dr_light_pdf_env gives back, and it integrates the map correctly. */
static void test_env_map_sampling(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-1, 0, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, sb_diffuse(dr_v3s(0.5))));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_image *map = &b.s->env.map;
    map->width = 16;
    map->height = 8;
    map->channels = 3;
    map->data = malloc(sizeof(float) * 16 * 8 * 3);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++)
            for (int c = 0; c < 3; c++)
                map->data[(y * 16 + x) * 3 + c] = (float)(0.1 + ((x * 7 + y * 3 + c) % 11) + (x == 5 && y == 2 ? 200 : 0));
    struct dr_scene *s = sb_finish(&b);
    struct dr_sampler smp;
    dr_sampler_init(&smp, 1, 2, 3);
    int n = 200000, mismatch = 0;
    double sum_is = 0, sum_is2 = 0, sum_u = 0, sum_u2 = 0;
    for (int i = 0; i < n; i++) {
        struct dr_light_sample ls;
        double a = dr_sampler_next(&smp), u1 = dr_sampler_next(&smp), u2 = dr_sampler_next(&smp);
        /* (a map's sampling does not look at the point's BSDF) */
        if (dr_light_sample(s, s->light_sampler, dr_v3(0, 1, 0), NULL, a, u1, u2, &ls)) {
            double p = dr_light_pdf_env(s, s->light_sampler, ls.wi, DR_SKY_SPHERE);
            if (fabs(p - ls.pdf) > 1e-6 * ls.pdf)
                mismatch++;
            double v = ls.radiance.x / ls.pdf;
            sum_is += v;
            sum_is2 += v * v;
        }
        /* the same integral by uniform sphere sampling */
        double z = 1 - 2 * u1, r = sqrt(fmax(0, 1 - z * z)), ph = 2 * M_PI * u2;
        double v = dr_env_radiance(s, dr_v3(r * cos(ph), r * sin(ph), z)).x * 4 * M_PI;
        sum_u += v;
        sum_u2 += v * v;
    }
    CHECK(mismatch == 0, "%d samples whose pdf differs from dr_light_pdf_env", mismatch);
    /* what a ray leaving the scene reads, the map coordinates computed once:
     * exactly dr_env_radiance and dr_light_pdf_env (a mutation that swaps
     * the coordinates of the density fails here and nowhere else) */
    int differ = 0;
    for (int i = 0; i < 20000; i++) {
        double z = 1 - 2 * dr_sampler_next(&smp), r = sqrt(fmax(0, 1 - z * z)), ph = 2 * M_PI * dr_sampler_next(&smp);
        dr_vec3 dir = dr_v3(r * cos(ph), r * sin(ph), z);
        double pdf = -1.0;
        dr_vec3 L = dr_env_radiance_pdf(s, s->light_sampler, dir, DR_SKY_SPHERE, &pdf), L0 = dr_env_radiance(s, dir);
        dr_vec3 L1 = dr_env_radiance_pdf(s, s->light_sampler, dir, DR_SKY_SPHERE, NULL);
        differ += pdf != dr_light_pdf_env(s, s->light_sampler, dir, DR_SKY_SPHERE) || L.x != L0.x || L.y != L0.y || L.z != L0.z ||
                  L1.x != L0.x || L1.y != L0.y || L1.z != L0.z;
    }
    CHECK(differ == 0, "dr_env_radiance_pdf differs from dr_env_radiance, dr_light_pdf_env in %d of 20000 directions",
          differ);
    /* the lookup the eight-lane radiance keeps for the adjoint
     * (d_env_radiance_at): the coordinates and texel blend d_env_radiance
     * computes again, to the bit */
    struct dr_env_tables et;
    CHECK(dr_light_env_tables(s->light_sampler, &et), "the map's light tables");
    int lookups_differ = 0;
    for (int i = 0; i < 20000; i += DR_SIMD_W) {
        dr_v3x8 d8;
        dr_m8 all = {-1, -1, -1, -1, -1, -1, -1, -1};
        for (int l = 0; l < DR_SIMD_W; l++) {
            double z = 1 - 2 * dr_sampler_next(&smp), r = sqrt(fmax(0, 1 - z * z)), ph = 2 * M_PI * dr_sampler_next(&smp);
            d8.x[l] = r * cos(ph), d8.y[l] = r * sin(ph), d8.z[l] = z;
        }
        struct dr_env8_lookup at;
        dr_env8_radiance_pdf(s, &et, all, d8, NULL, &at);
        for (int l = 0; l < DR_SIMD_W; l++) {
            double u, v, px[4];
            dr_env_dir_to_uv(dr_v3x8_get(&d8, l), &u, &v);
            dr_texture_eval(&dr_env_texture, &s->env.map, u, v, true, px);
            lookups_differ += u != at.u[l] || v != at.v[l] || px[0] != at.map.x[l] || px[1] != at.map.y[l] ||
                              px[2] != at.map.z[l];
        }
    }
    CHECK(lookups_differ == 0, "the eight-lane map lookup differs from d_env_radiance's in %d of 20000 directions",
          lookups_differ);
    double m_is = sum_is / n, m_u = sum_u / n;
    double se = sqrt((sum_is2 / n - m_is * m_is) / n + (sum_u2 / n - m_u * m_u) / n);
    CHECK(fabs(m_is - m_u) < 4 * se, "env integral: importance %.4f vs uniform %.4f (se %.3g)", m_is, m_u, se);
    /* importance sampling must have far less variance on a peaked map */
    CHECK(sum_is2 / n - m_is * m_is < sum_u2 / n - m_u * m_u, "importance sampling is not better than uniform");
    dr_scene_destroy(s);
}

/* The packet renderer (wavefront.c, which render uses) against the one-path
 * walker, pixel by pixel: the same sampler, film, camera ray and
 * dr_path_radiance per sample, summed in sample order. Bit for bit equal. */
static uint64_t wavefront_matches_one_path(struct dr_scene *s, struct dr_camera cam, const char *name)
{
    const int w = 12, h = 10, spp = 5, depth = 8;
    float *rgb = malloc(sizeof(float) * 3 * w * h);
    struct dr_render_opts o = {.width = w, .height = h, .spp = spp, .max_depth = depth,
                              .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 3, .threads = 2};
    struct dr_render_stats st;
    CHECK(dr_render(s, &cam, &o, rgb, &st) == 0, "dr_render: %s", dr_last_error());
    struct dr_camera_view view = dr_camera_view(&cam, w, h);
    struct dr_path_opts po = {.max_depth = depth, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, NULL)};
    struct dr_ray_counts rays = {0};
    int differ = 0;
    double total = 0.0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            dr_vec3 sum = dr_v3s(0.0);
            for (int k = 0; k < spp; k++) {
                struct dr_sampler smp;
                dr_sampler_init_kind(&smp, DR_SAMPLER_INDEPENDENT, o.seed, (uint64_t)(y * w + x), (uint64_t)k, spp);
                double u, v, px, py;
                dr_vec3 ro, rd;
                dr_sampler_next2(&smp, &u, &v);
                dr_film_sample(&o.film.filter, x, y, u, v, &px, &py);
                dr_camera_ray(&view, px, py, &ro, &rd);
                sum = dr_add(sum, dr_path_radiance(s, &po, ro, rd, &smp, &rays));
            }
            const float *got = rgb + 3 * (y * w + x);
            total += got[0] + got[1] + got[2];
            differ += got[0] != (float)(sum.x / spp) || got[1] != (float)(sum.y / spp) || got[2] != (float)(sum.z / spp);
        }
    CHECK(total > 0.0, "%s: the image is black", name);
    CHECK(differ == 0, "%s: %d of %d pixels differ between the packet renderer and the one-path walker", name, differ,
          w * h);
    CHECK(rays.camera == st.rays.camera && rays.extension == st.rays.extension && rays.shadow == st.rays.shadow,
          "%s: ray counts: packets %llu/%llu/%llu, one path %llu/%llu/%llu", name, (unsigned long long)st.rays.camera,
          (unsigned long long)st.rays.extension, (unsigned long long)st.rays.shadow, (unsigned long long)rays.camera,
          (unsigned long long)rays.extension, (unsigned long long)rays.shadow);
    free(rgb);
    return st.rays.simd_vertices;
}

/* A box whose surfaces take both of the packet renderer's ways: Lambertian
 * walls with interpolated normals, a single-sided Lambertian panel, a glossy
 * dielectric block and a near-specular metal block (shaded eight lanes at a
 * time, path_simd.h) next to a textured floor tile (one lane at a time), lit
 * by two lamps of different size and colour, one double-sided. */
static struct dr_scene *mixed_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.7, 0.5, 0.3))));
    struct dr_mesh *m = &b.s->mesh;
    for (uint32_t v = 0; v < m->n_vertices; v++) {   /* normals leaning inwards, towards the box's axis */
        dr_vec3 p = dr_v3(m->positions[3 * v], m->positions[3 * v + 1], m->positions[3 * v + 2]);
        dr_vec3 n = dr_normalize(dr_sub(dr_v3(0.0, 1.0, 0.0), dr_scale(p, 0.6)));
        m->normals[3 * v] = (float)n.x, m->normals[3 * v + 1] = (float)n.y, m->normals[3 * v + 2] = (float)n.z;
    }
    for (uint32_t t = 0; t < m->n_triangles; t++)
        m->flags[t] |= DR_TRI_HAS_NORMALS;
    struct dr_material glossy = sb_diffuse(dr_v3(0.2, 0.4, 0.8));
    glossy.specular = 1.0;
    glossy.roughness = 0.3;
    sb_box(&b, dr_v3(-0.6, 0.0, -0.5), dr_v3(-0.1, 0.9, 0.0), sb_material(&b, glossy));
    struct dr_material metal = sb_diffuse(dr_v3(0.9, 0.6, 0.3));
    metal.metallic = 1.0;
    metal.roughness = 0.05;   /* near-specular */
    sb_box(&b, dr_v3(0.3, 0.0, 0.1), dr_v3(0.7, 0.3, 0.5), sb_material(&b, metal));
    struct dr_image checker = sb_image(2, 2, 3, (const float[]){1, 1, 1, 0.1f, 0.1f, 0.1f, 0.1f, 0.1f, 0.1f, 1, 1, 1},
                                       0.0f, true);
    struct dr_material textured = sb_diffuse(dr_v3s(0.8));
    textured.base_color_tex.texture = sb_texture(&b, checker);
    sb_quad(&b, dr_v3(-0.9, 0.01, 0.2), dr_v3(0.8, 0, 0), dr_v3(0, 0, -0.8), sb_material(&b, textured));
    struct dr_material panel = sb_diffuse(dr_v3(0.3, 0.8, 0.3));
    panel.double_sided = false;
    sb_quad(&b, dr_v3(0.2, 0.2, -0.6), dr_v3(0.6, 0, 0), dr_v3(0, 0.8, 0.3), sb_material(&b, panel));
    struct dr_material lamp = sb_diffuse(dr_v3s(0.0));
    lamp.emissive_factor = dr_v3(4.0, 3.0, 2.0);
    sb_quad(&b, dr_v3(-0.3, 1.9, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, lamp));   /* faces down */
    struct dr_material lamp2 = sb_diffuse(dr_v3s(0.0));
    lamp2.emissive_factor = dr_v3(0.5, 2.0, 6.0);
    lamp2.emissive_strength = 3.0;
    lamp2.double_sided = true;
    sb_quad(&b, dr_v3(0.5, 0.6, 0.4), dr_v3(0.2, 0, 0), dr_v3(0, 0.2, 0.1), sb_material(&b, lamp2));
    return sb_finish(&b);
}

/* Paths from random points of a camera's view, for the exact comparison below. */
struct random_paths {
    struct dr_camera_view view;
    enum dr_sampler_kind kind;   /* structured: 16 samples of a pixel */
};
static void random_path_start(void *ctx, int64_t i, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct random_paths *r = ctx;
    if (r->kind == DR_SAMPLER_INDEPENDENT)
        dr_sampler_init(smp, 11, (uint64_t)i, 0);
    else
        dr_sampler_init_kind(smp, r->kind, 11, (uint64_t)i / 16, (uint64_t)i % 16, 16);
    double u, v;
    dr_sampler_next2(smp, &u, &v);
    dr_camera_ray(&r->view, u * 64.0, v * 48.0, o, d);
}

/* The packet tracer's radiance against dr_path_radiance, path by path in
 * double precision: equal to the last bit, both as dr_wave_radiance gives it
 * (in arrays, wave_soa.c, where it can) and through the lanes
 * (dr_wave_radiance_lanes, as the gradients' walks use them). Deep paths with Russian roulette from the
 * second segment, so every stage is crossed many times (an image's float
 * pixels would hide a last-bit difference). Returns how many vertices were
 * shaded eight lanes at a time, the fewer of the two ways' counts. */
static uint64_t radiance_matches_exactly(const struct dr_scene *s, struct dr_camera cam, const char *scene,
                                         enum dr_sampler_kind kind)
{
    enum { N = 6000 };
    struct random_paths r = {dr_camera_view(&cam, 64, 48), kind};
    char name[160];
    snprintf(name, sizeof name, "%s, %s sampler", scene, dr_sampler_kind_name(kind));
    struct dr_path_opts po = {.max_depth = 16, .rr_depth = 2, .stages = dr_path_plan(s, NULL)};
    dr_vec3 *L = malloc(sizeof(dr_vec3) * N), *Llanes = malloc(sizeof(dr_vec3) * N);
    struct dr_wave *w = dr_wave_create();
    struct dr_ray_counts packets = {0}, lanes = {0}, one = {0};
    dr_wave_radiance(w, s, &po, N, random_path_start, NULL, &r, L, &packets);
    dr_wave_radiance_lanes(w, s, &po, N, random_path_start, &r, Llanes, &lanes);
    int differ = 0, differ_lanes = 0, lit = 0;
    for (int i = 0; i < N; i++) {
        struct dr_sampler smp;
        dr_vec3 o, d;
        random_path_start(&r, i, &smp, &o, &d);
        dr_vec3 ref = dr_path_radiance(s, &po, o, d, &smp, &one);
        differ += memcmp(&ref, &L[i], sizeof ref) != 0;
        differ_lanes += memcmp(&ref, &Llanes[i], sizeof ref) != 0;
        lit += !dr_is_black(ref);
    }
    CHECK(lit > N / 4, "%s: only %d of %d paths carry light", name, lit, N);
    CHECK(differ == 0, "%s: %d of %d paths' radiance differs (in double) between the packet tracer and the one-path "
          "walker", name, differ, N);
    CHECK(differ_lanes == 0, "%s: %d of %d paths' radiance differs (in double) between the packet tracer's lanes and "
          "the one-path walker", name, differ_lanes, N);
    CHECK(packets.extension == one.extension && packets.shadow == one.shadow, "%s: rays %llu/%llu vs %llu/%llu",
          name, (unsigned long long)packets.extension, (unsigned long long)packets.shadow,
          (unsigned long long)one.extension, (unsigned long long)one.shadow);
    CHECK(lanes.extension == one.extension && lanes.shadow == one.shadow, "%s: lanes' rays %llu/%llu vs %llu/%llu",
          name, (unsigned long long)lanes.extension, (unsigned long long)lanes.shadow,
          (unsigned long long)one.extension, (unsigned long long)one.shadow);
    dr_wave_destroy(w);
    free(L);
    free(Llanes);
    return packets.simd_vertices < lanes.simd_vertices ? packets.simd_vertices : lanes.simd_vertices;
}

/* The packet renderer against the one-path walker: the bundled Cornell box
 * (a textured floor, shaded one lane at a time with its hits located and
 * texels prefetched first; glossy dielectric walls and a rough metal, eight
 * lanes at a time), a small Lambertian box (no prefetching), and a box that
 * mixes them with shading normals and a second, double-sided lamp. */
/* Materials and a lamp the test scenes share. */
static struct dr_material glossy_blue(void)
{
    struct dr_material m = sb_diffuse(dr_v3(0.2, 0.4, 0.8));
    m.specular = 1.0;
    m.roughness = 0.25;
    return m;
}
static struct dr_material warm_lamp(void)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = dr_v3(4.0, 3.0, 2.0);
    return m;
}

/* Every kind of light at once: an area lamp, point, spot and directional
 * lights, and an environment map seen through the open top. The point
 * light has a range that leaves part of the box out (range_window's 0),
 * the spot's cone another part (spot_falloff's). */
static struct dr_scene *lit_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    sb_quad(&b, dr_v3(0.4, 1.5, 0.4), dr_v3(0.3, 0, 0), dr_v3(0, 0, -0.3), sb_material(&b, warm_lamp()));
    struct dr_punctual point = light(DR_LIGHT_POINT, dr_v3(0.5, 1.2, 0.5), dr_v3(0, -1, 0), 2.0);
    point.range = 1.6;
    sb_light(&b, point);
    sb_light(&b, light(DR_LIGHT_SPOT, dr_v3(-0.5, 1.6, 0.3), dr_normalize(dr_v3(0.2, -1, -0.1)), 4.0));
    sb_light(&b, light(DR_LIGHT_DIRECTIONAL, dr_v3(0, 0, 0), dr_normalize(dr_v3(0.3, -1, 0.2)), 1.5));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_image *map = &b.s->env.map;
    map->width = 16, map->height = 8, map->channels = 3;
    map->data = malloc(sizeof(float) * 16 * 8 * 3);
    for (int k = 0; k < 16 * 8 * 3; k++)
        map->data[k] = (float)(0.2 + (k * 37 % 17) / 4.0);
    return sb_finish(&b);
}

/* A constant environment alone (what a glTF file without lights gets).
 * Next-event estimation draws it by dr_sky_pdf's mixture: the Lambertian box by the cosine alone, the glossy dielectric
 * block by both halves, a sharp metal block by the BSDF alone, a broad
 * metal one (roughness 0.6) by both. */
static struct dr_scene *sky_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 1.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    struct dr_material metal = glossy_blue();
    metal.metallic = 1.0;
    sb_box(&b, dr_v3(0.2, 0.0, -0.6), dr_v3(0.6, 0.4, -0.2), sb_material(&b, metal));
    metal.roughness = 0.6;
    sb_box(&b, dr_v3(0.1, 0.0, 0.2), dr_v3(0.5, 0.5, 0.6), sb_material(&b, metal));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    return sb_finish(&b);
}

/* An open box under an environment map alone, seen from above so that many
 * rays leave: a 32 x 16 map with a black top row and black texels (cells
 * never sampled), a bright patch (a sun) and a coloured rest; RGB, or grey
 * (one channel, with a decoded copy beside it). A half-metal glossy block.
 * The packet renderer samples and looks it up eight lanes at a time
 * (env8.h). (Maps are read in float storage only.) */
static struct dr_scene *map_box(bool grey)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 1.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    struct dr_material block = glossy_blue();
    block.metallic = 0.5;
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, block));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    b.s->env.strength = 1.5;
    enum { W = 32, H = 16 };
    const int c = grey ? 1 : 3;
    float px[W * H * 3];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int k = 0; k < c; k++) {
                float v = (float)(0.05 + 0.4 * ((x * 7 + y * 13 + k * 5) % 11) / 10.0);
                if (y == 0 || (x + y) % 9 == 0)
                    v = 0.0f;                    /* black: never sampled */
                else if (y >= 4 && y <= 5 && x >= 20 && x <= 22)
                    v = 40.0f;   /* the sun */
                px[(y * W + x) * c + k] = v;
            }
    b.s->env.map = sb_image(W, H, c, px, 0.0f, grey);
    return sb_finish(&b);
}

/* Normal-mapped walls (tangents generated), a lamp and a glossy block.
 * eight_bit: the map in eight-bit storage, which the packet tracer applies
 * eight lanes at a time (path_simd.c's normal_map8), at scale 0.7 through a
 * texture transform, on walls whose vertex normals lean in at some corners
 * and out at others (the authored side), with some tangent frames'
 * handedness flipped and some missing, and a tile on the back wall whose
 * tangents lie along its normal but for 1e-9 (a degenerate frame: no
 * mapping); else a float map on walls with a base colour texture of five
 * channels (an EXR's), which only the scalar lookups read: such lanes build
 * a scalar hit, to which dr_normal_map_apply applies the map lane by lane. */
static struct dr_scene *bumpy_box(bool eight_bit)
{
    struct sb b;
    sb_init(&b);
    static const float bump_px[4 * 4 * 3] = {
        0.5f, 0.5f, 1,    0.9f, 0.5f, 0.8f, 0.2f, 0.6f, 0.9f, 0.5f, 0.1f, 0.9f, 0.7f, 0.7f, 0.7f, 0.3f,
        0.3f, 0.9f, 0.5f, 0.5f, 1,    0.8f, 0.2f, 0.7f, 0.1f, 0.5f, 0.8f, 0.5f, 0.9f, 0.8f, 0.6f, 0.4f,
        0.9f, 0.5f, 0.5f, 1,    0.4f, 0.8f, 0.8f, 0.9f, 0.9f, 0.6f, 0.5f, 0.5f, 1,    0.2f, 0.3f, 0.9f};
    struct dr_material bumpy = sb_diffuse(dr_v3(0.7, 0.6, 0.5));
    bumpy.normal_tex.texture = sb_texture(&b, eight_bit ? sb_image8(4, 4, 3, bump_px) : sb_image(4, 4, 3, bump_px, 0.0f, false));
    if (!eight_bit) {
        static const float five[2 * 2 * 5] = {0.9f, 0.4f, 0.6f, 1.0f, 0.5f, 0.3f, 0.8f, 0.7f, 1.0f, 0.2f,
                                              0.6f, 0.6f, 0.2f, 1.0f, 0.9f, 1.0f, 0.7f, 0.4f, 1.0f, 0.1f};
        bumpy.base_color_tex.texture = sb_texture(&b, sb_image(2, 2, 5, five, 0.0f, true));
    }
    if (eight_bit) {
        bumpy.normal_scale = 0.7;
        bumpy.normal_tex.transformed = true;
        const double xf[6] = {1.5, 0.2, 0.1, -0.3, 1.2, 0.4};
        memcpy(bumpy.normal_tex.xf, xf, sizeof xf);
    }
    const int bumpy_id = sb_material(&b, bumpy);
    sb_open_box(&b, 2.0, bumpy_id);
    struct dr_mesh *m = &b.s->mesh;
    for (uint32_t v = 0; eight_bit && v < m->n_vertices; v++) {   /* leaning in (v even) or out */
        dr_vec3 p = dr_v3(m->positions[3 * v], m->positions[3 * v + 1], m->positions[3 * v + 2]);
        dr_vec3 n = dr_normalize(dr_scale(dr_sub(dr_v3(0.0, 1.0, 0.0), p), v % 2 ? -1.0 : 1.0));
        m->normals[3 * v] = (float)n.x, m->normals[3 * v + 1] = (float)n.y, m->normals[3 * v + 2] = (float)n.z;
    }
    for (uint32_t t = 0; eight_bit && t < m->n_triangles; t++)
        m->flags[t] |= DR_TRI_HAS_NORMALS;
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    sb_quad(&b, dr_v3(-0.3, 1.9, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));
    const uint32_t tile = m->n_vertices;
    if (eight_bit)   /* facing +z */
        sb_quad(&b, dr_v3(0.2, 0.8, -0.9), dr_v3(0.5, 0, 0), dr_v3(0, 0.5, 0), bumpy_id);
    struct dr_scene *s = sb_finish(&b);
    CHECK(s->mesh.tangents != NULL, "the bumpy box has tangent frames");
    for (uint32_t v = tile; eight_bit && s->mesh.tangents && v < tile + 4; v++)
        memcpy(s->mesh.tangents + 4 * (size_t)v, (const float[]){1e-9f, 0, 1, 1}, 4 * sizeof(float));
    for (uint32_t v = 0; eight_bit && s->mesh.tangents && v < s->mesh.n_vertices; v++) {
        float *t = s->mesh.tangents + 4 * (size_t)v;
        if (v % 5 == 1)
            t[3] = -t[3];   /* the other handedness */
        else if (v % 7 == 3)
            t[3] = 0.0f;    /* no frame: the interpolated normal stays */
    }
    return s;
}

/* Cut-outs (alphaMode MASK) and stochastic transparency (BLEND), which the
 * queries' filters apply (BLEND by each ray's coverage key, which the
 * packet tracer makes for its traces and shadow rays) and the eight-lane
 * stages see only at light points (path_simd.c's light_sample): a wall
 * panel whose RGBA base colour texture's alpha is a checker with holes, a
 * lamp cut the same way (about half its light points are holes, which emit
 * nothing), a BLEND pane of alpha 0.6 across the room and a small BLEND
 * lamp of alpha 0.5, above a glossy block; the open top lets some rays out
 * to a constant sky. */
static struct dr_scene *cutout_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    float px[4 * 4 * 4];
    for (int k = 0; k < 16; k++) {   /* colours, and alpha 1 or 0.1 in a checker */
        px[4 * k] = 0.9f, px[4 * k + 1] = (float)(0.3 + 0.04 * k), px[4 * k + 2] = 0.5f;
        px[4 * k + 3] = ((k % 4) + (k / 4)) % 2 ? 0.1f : 1.0f;
    }
    struct dr_material panel = sb_diffuse(dr_v3(0.9, 0.9, 0.9));
    panel.alpha_mode = DR_ALPHA_MASK;
    panel.alpha_cutoff = 0.5;
    panel.base_color_tex.texture = sb_texture(&b, sb_image8(4, 4, 4, px));
    sb_quad(&b, dr_v3(-0.8, 0.2, 0.3), dr_v3(1.4, 0, 0), dr_v3(0, 1.2, 0.2), sb_material(&b, panel));
    struct dr_material lamp = warm_lamp();
    lamp.alpha_mode = DR_ALPHA_MASK;
    lamp.alpha_cutoff = 0.5;
    lamp.base_color_tex.texture = panel.base_color_tex.texture;
    sb_quad(&b, dr_v3(-0.4, 1.9, -0.4), dr_v3(0.8, 0, 0), dr_v3(0, 0, 0.8), sb_material(&b, lamp));   /* faces down */
    struct dr_material pane = sb_diffuse(dr_v3(0.2, 0.5, 0.9));
    pane.alpha_mode = DR_ALPHA_BLEND;
    pane.alpha = 0.6;
    sb_quad(&b, dr_v3(-0.9, 0.1, 0.6), dr_v3(1.8, 0, 0), dr_v3(0, 1.0, -0.3), sb_material(&b, pane));
    struct dr_material veil = warm_lamp();
    veil.alpha_mode = DR_ALPHA_BLEND;
    veil.alpha = 0.5;
    sb_quad(&b, dr_v3(0.5, 1.7, 0.5), dr_v3(0.3, 0, 0), dr_v3(0, 0, -0.3), sb_material(&b, veil));   /* faces down */
    sb_environment(&b, dr_v3(0.3, 0.35, 0.4));
    return sb_finish(&b);
}

/* Vertex colours without textures: no prefetching, and the eight-lane
 * stages interpolate the colours themselves (no scalar material lookups). */
static struct dr_scene *coloured_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.9, 0.9, 0.9))));
    sb_quad(&b, dr_v3(-0.3, 1.9, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));
    struct dr_mesh *m = &b.s->mesh;
    m->colors = malloc(sizeof(float) * 3 * m->n_vertices);
    for (uint32_t k = 0; k < 3 * m->n_vertices; k++)
        m->colors[k] = (float)(0.2 + 0.7 * ((k * 7919u) % 13u) / 12.0);
    return sb_finish(&b);
}

/* A ceiling lamp of 6 x 6 tiles (72 emitting triangles: the light table is
 * searched through its guide and the lanes' reads of it are prefetched,
 * path_simd.c) and a point light, so that some lanes pick a light that is
 * not a triangle of that table. */
static struct dr_scene *tiled_lamp_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    int lamp = sb_material(&b, warm_lamp());
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++)   /* faces down */
            sb_quad(&b, dr_v3(-0.3 + 0.1 * i, 1.9, -0.3 + 0.1 * j), dr_v3(0.1, 0, 0), dr_v3(0, 0, 0.1), lamp);
    sb_light(&b, light(DR_LIGHT_POINT, dr_v3(0.5, 1.2, 0.5), dr_v3(0, -1, 0), 2.0));
    struct dr_scene *s = sb_finish(&b);
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt) && lt.n_emitters == 72, "the tiled lamp is 72 emitters");
    return s;
}

/* The tiled lamp with an emissive texture (each tile's light point reads
 * its texels) and textured walls: the packet tracer locates the textured
 * hits before shading and keeps the groups' hit points for the shading
 * (dr_path8_located), and takes the random numbers and light picks ahead,
 * stage by stage over the wave (dr_path8_ahead), as on a textured asset
 * with thousands of emitting triangles. The textures are looked up eight
 * lanes at a time (texture8.h: base colour at the hits, emission at hits
 * and at light points). eight_bit: in eight-bit storage, the walls' base
 * colour and the lamp's emission read through TEXCOORD_1 (a set of its own,
 * made from the positions), the block's metallic-roughness through
 * TEXCOORD_0; else float images through TEXCOORD_0. */
static void uv1_from_positions(struct dr_mesh *m)
{
    m->uvs1 = malloc(sizeof(float) * 2 * m->n_vertices);
    CHECK(m->uvs1 != NULL, "TEXCOORD_1 array");
    for (uint32_t v = 0; m->uvs1 && v < m->n_vertices; v++) {
        const float *p = m->positions + 3 * (size_t)v;
        m->uvs1[2 * v] = 0.8f * p[0] - 0.3f * p[2] + 0.2f * p[1] + 0.15f;
        m->uvs1[2 * v + 1] = 0.5f * p[1] + 0.6f * p[2] - 0.7f * p[0] - 0.25f;
    }
}

static struct dr_scene *textured_lamp_box(bool eight_bit)
{
    struct sb b;
    sb_init(&b);
    static const float wall_px[3 * 3 * 3] = {0.9f, 0.8f, 0.7f, 0.3f, 0.6f, 0.9f, 0.8f, 0.8f, 0.2f,
                                             0.5f, 0.9f, 0.4f, 0.7f, 0.2f, 0.3f, 0.6f, 0.6f, 0.6f,
                                             0.2f, 0.4f, 0.8f, 0.9f, 0.9f, 0.9f, 0.4f, 0.7f, 0.5f};
    static const float glow_px[2 * 2 * 3] = {1.0f, 0.9f, 0.6f, 0.2f, 0.5f, 1.0f, 0.8f, 0.1f, 0.3f, 0.0f, 0.0f, 0.0f};
    struct dr_material wall = sb_diffuse(dr_v3s(0.8));
    wall.base_color_tex.texture =
        sb_texture(&b, eight_bit ? sb_image8(3, 3, 3, wall_px) : sb_image(3, 3, 3, wall_px, 0.0f, true));
    wall.base_color_tex.texcoord = eight_bit;
    sb_open_box(&b, 2.0, sb_material(&b, wall));
    struct dr_material block = glossy_blue();
    if (eight_bit) {   /* half metal, with roughness and metalness from an RGBA metallic-roughness texture */
        static const float mr_px[2 * 2 * 4] = {0.0f, 0.9f, 0.1f, 1.0f, 0.0f, 0.3f, 0.8f, 0.5f,
                                               0.0f, 0.6f, 1.0f, 1.0f, 0.0f, 0.1f, 0.4f, 0.2f};
        block.metallic = 0.5;
        block.metallic_roughness_tex.texture = sb_texture(&b, sb_image8(2, 2, 4, mr_px));
    }
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, block));
    struct dr_material glow = warm_lamp();
    glow.emissive_tex.texture =
        sb_texture(&b, eight_bit ? sb_image8(2, 2, 3, glow_px) : sb_image(2, 2, 3, glow_px, 0.0f, true));
    glow.emissive_tex.texcoord = eight_bit;
    int lamp = sb_material(&b, glow);
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++)   /* faces down */
            sb_quad(&b, dr_v3(-0.3 + 0.1 * i, 1.9, -0.3 + 0.1 * j), dr_v3(0.1, 0, 0), dr_v3(0, 0, 0.1), lamp);
    sb_light(&b, light(DR_LIGHT_POINT, dr_v3(0.5, 1.2, 0.5), dr_v3(0, -1, 0), 2.0));
    if (eight_bit)
        uv1_from_positions(&b.s->mesh);
    struct dr_scene *s = sb_finish(&b);
    CHECK(dr_wave_prefetches(s) && dr_path8_picks_ahead(s),
          "the textured lamp box is located before shading, its light picks taken ahead");
    bool storage = s->n_images == (eight_bit ? 3 : 2);
    for (int i = 0; storage && i < s->n_images; i++)
        storage = (s->images[i].bytes != NULL) == eight_bit;
    CHECK(storage, "the lamp box's textures are in %s storage", eight_bit ? "eight-bit" : "float");
    return s;
}

/* Clear coats (bsdf_coat.c), which the packet tracer composes eight lanes at
 * a time: over the glossy dielectric block (smooth coat), over a Lambertian
 * panel (a full, rougher coat), over a metal block with the coat and its
 * roughness from an eight-bit RGBA texture (R and G), a floor tile whose
 * coat textures are five-channel float images (read lane by lane through
 * dr_material_eval), and a coat of factor 0 (coated all the same); uncoated
 * walls beside them. Lit by a lamp and a constant sky (whose next-event
 * samples take the coated BSDF's sampling, dr_sky_pdf) through the open top. */
static struct dr_scene *coated_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 1.6, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    struct dr_material block = glossy_blue();
    block.coated = true, block.coat = 0.8, block.coat_roughness = 0.1;
    sb_box(&b, dr_v3(-0.6, 0.0, -0.6), dr_v3(-0.1, 0.7, -0.1), sb_material(&b, block));
    struct dr_material panel = sb_diffuse(dr_v3(0.7, 0.2, 0.2));
    panel.coated = true, panel.coat = 1.0, panel.coat_roughness = 0.35;
    sb_quad(&b, dr_v3(0.2, 0.1, -0.8), dr_v3(0.6, 0, 0), dr_v3(0, 0.9, 0.2), sb_material(&b, panel));
    static const float coat_px[2 * 2 * 4] = {1.0f, 0.2f, 0.0f, 1.0f, 0.5f, 0.9f, 0.3f, 1.0f,
                                             0.0f, 0.5f, 0.7f, 1.0f, 0.8f, 0.05f, 0.1f, 1.0f};
    struct dr_material metal = sb_diffuse(dr_v3(0.9, 0.6, 0.3));
    metal.metallic = 1.0, metal.roughness = 0.5;
    metal.coated = true, metal.coat = 0.9, metal.coat_roughness = 0.8;
    metal.coat_tex.texture = metal.coat_roughness_tex.texture = sb_texture(&b, sb_image8(2, 2, 4, coat_px));
    sb_box(&b, dr_v3(0.2, 0.0, 0.1), dr_v3(0.6, 0.4, 0.5), sb_material(&b, metal));
    static const float five[2 * 2 * 5] = {0.9f, 0.4f, 0.6f, 1.0f, 0.5f, 0.3f, 0.8f, 0.7f, 1.0f, 0.2f,
                                          0.6f, 0.1f, 0.2f, 1.0f, 0.9f, 1.0f, 0.6f, 0.5f, 1.0f, 0.4f};
    struct dr_material tile = glossy_blue();
    tile.coated = true, tile.coat = 0.7, tile.coat_roughness = 0.6;
    tile.coat_tex.texture = sb_texture(&b, sb_image(2, 2, 5, five, 0.0f, false));
    tile.coat_roughness_tex.texture = tile.coat_tex.texture;
    sb_quad(&b, dr_v3(-0.9, 0.01, 0.9), dr_v3(0.8, 0, 0), dr_v3(0, 0, -0.7), sb_material(&b, tile));
    struct dr_material bare = sb_diffuse(dr_v3(0.3, 0.8, 0.3));
    bare.coated = true, bare.coat = 0.0, bare.coat_roughness = 0.2;   /* a coat of factor 0 */
    sb_quad(&b, dr_v3(-0.95, 0.2, -0.4), dr_v3(0, 0, 0.6), dr_v3(0, 0.6, 0), sb_material(&b, bare));
    sb_quad(&b, dr_v3(-0.3, 1.5, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    struct dr_scene *s = sb_finish(&b);
    CHECK(dr_path8_reads_textures(s, s->mesh.n_triangles - 6) && !dr_path8_reads_textures(s, 0),
          "the tile's coat textures are read, the walls read none");
    return s;
}

/* Anisotropic surfaces (KHR_materials_anisotropy) of every kind the
 * stages meet: a rough metal floor turned by its rotation, a glossy
 * dielectric block stretched along its tangents, a tile whose direction and
 * strength come from a texture (one texel of no direction: the isotropic
 * fallback), a coat over an anisotropic metal, an anisotropic Lambertian
 * (nothing to stretch), and a panel without UVs (no tangent frame:
 * isotropic), under a lamp and a constant sky. The block also has
 * KHR_materials_specular's textures (read lane by lane). The tile's texture is
 * eight-bit RGB (read eight lanes at a time: anisotropy8), or five-channel
 * float (lane by lane, with dr_material_eval and dr_anisotropy_frame). */
static struct dr_scene *anisotropic_box(bool scalar_tile)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 1.6, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    struct dr_material floor = sb_diffuse(dr_v3(0.9, 0.8, 0.7));
    floor.metallic = 1.0, floor.roughness = 0.25;
    floor.anisotropic = true, floor.anisotropy_strength = 0.8, floor.anisotropy_rotation = 0.6;
    sb_quad(&b, dr_v3(-0.95, 0.005, 0.95), dr_v3(1.9, 0, 0), dr_v3(0, 0, -1.9), sb_material(&b, floor));
    struct dr_material block = glossy_blue();
    block.anisotropic = true, block.anisotropy_strength = 1.0;
    /* (and KHR_materials_specular's textures: A scales the specular, RGB its colour; lane by lane) */
    static const float spec_px[2 * 2 * 4] = {0.2f, 0.4f, 0.6f, 1.0f, 1.0f, 0.5f, 0.3f, 0.25f,
                                             0.7f, 0.9f, 0.1f, 0.0f, 0.4f, 0.4f, 0.8f, 0.6f};
    block.specular_tex.texture = block.specular_color_tex.texture = sb_texture(&b, sb_image8(2, 2, 4, spec_px));
    sb_box(&b, dr_v3(-0.6, 0.0, -0.6), dr_v3(-0.1, 0.7, -0.1), sb_material(&b, block));
    static const float dir_px[2 * 2 * 3] = {1.0f, 0.5f, 1.0f, 0.5f, 0.5f, 0.9f,   /* (0.5, 0.5): no direction */
                                            0.2f, 0.9f, 0.6f, 0.8f, 0.1f, 0.3f};
    struct dr_material tile = sb_diffuse(dr_v3(0.7, 0.8, 0.9));
    tile.metallic = 1.0, tile.roughness = 0.15;
    tile.anisotropic = true, tile.anisotropy_strength = 0.9, tile.anisotropy_rotation = -1.1;
    static const float five[2 * 2 * 5] = {1.0f, 0.5f, 1.0f, 0.3f, 0.2f, 0.5f, 0.5f, 0.9f, 1.0f, 0.7f,
                                          0.2f, 0.9f, 0.6f, 0.5f, 0.5f, 0.8f, 0.1f, 0.3f, 0.4f, 0.9f};
    tile.anisotropy_tex.texture =
        sb_texture(&b, scalar_tile ? sb_image(2, 2, 5, five, 0.0f, false) : sb_image8(2, 2, 3, dir_px));
    sb_quad(&b, dr_v3(0.2, 0.1, -0.8), dr_v3(0.6, 0, 0), dr_v3(0, 0.9, 0.2), sb_material(&b, tile));
    struct dr_material coated = sb_diffuse(dr_v3(0.9, 0.6, 0.3));
    coated.metallic = 1.0, coated.roughness = 0.4;
    coated.coated = true, coated.coat = 0.6, coated.coat_roughness = 0.1;
    coated.anisotropic = true, coated.anisotropy_strength = 0.7, coated.anisotropy_rotation = 2.0;
    sb_box(&b, dr_v3(0.2, 0.0, 0.1), dr_v3(0.6, 0.4, 0.5), sb_material(&b, coated));
    struct dr_material plain = sb_diffuse(dr_v3(0.3, 0.8, 0.3));
    plain.anisotropic = true, plain.anisotropy_strength = 0.5;   /* Lambertian: nothing to stretch */
    sb_quad(&b, dr_v3(-0.95, 0.2, -0.4), dr_v3(0, 0, 0.6), dr_v3(0, 0.6, 0), sb_material(&b, plain));
    struct dr_material bare = glossy_blue();
    bare.anisotropic = true, bare.anisotropy_strength = 1.0;
    sb_quad(&b, dr_v3(0.95, 0.2, 0.4), dr_v3(0, 0, -0.6), dr_v3(0, 0.6, 0), sb_material(&b, bare));
    struct dr_mesh *m = &b.s->mesh;
    m->flags[m->n_triangles - 1] &= (uint8_t)~DR_TRI_HAS_UVS;   /* (no UVs: no tangent frame) */
    m->flags[m->n_triangles - 2] &= (uint8_t)~DR_TRI_HAS_UVS;
    sb_quad(&b, dr_v3(-0.3, 1.5, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    return sb_finish(&b);
}

/* KHR_materials_sheen's lanes (shaded lane by lane by the scalar BSDF on
 * dr_material_eval's record, path_simd.h's sheen_bsdf) among the others:
 * a velvet floor over a Lambertian, a rough metal block with a coloured
 * sheen under a coat, a tile whose sheen colour and roughness come from
 * textures (eight-bit RGB, float RGBA: A the roughness), an anisotropic
 * sheened panel, and a sheen of colour 0 (still sheened: a fit's start),
 * under a lamp and a constant sky; the walls are not sheened. */
static struct dr_scene *sheened_box(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 1.6, sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    struct dr_material floor = sb_diffuse(dr_v3(0.3, 0.1, 0.2));
    floor.sheened = true, floor.sheen_color = dr_v3(0.9, 0.8, 0.9), floor.sheen_roughness = 0.5;
    sb_quad(&b, dr_v3(-0.95, 0.005, 0.95), dr_v3(1.9, 0, 0), dr_v3(0, 0, -1.9), sb_material(&b, floor));
    struct dr_material block = sb_diffuse(dr_v3(0.9, 0.6, 0.3));
    block.metallic = 1.0, block.roughness = 0.35;
    block.sheened = true, block.sheen_color = dr_v3(0.2, 0.5, 0.9), block.sheen_roughness = 0.3;
    block.coated = true, block.coat = 0.5, block.coat_roughness = 0.1;
    sb_box(&b, dr_v3(-0.6, 0.0, -0.6), dr_v3(-0.1, 0.7, -0.1), sb_material(&b, block));
    static const float col_px[2 * 2 * 3] = {1.0f, 0.5f, 0.2f, 0.1f, 0.9f, 0.4f, 0.6f, 0.6f, 0.6f, 0.0f, 0.3f, 1.0f};
    static const float rough_px[2 * 2 * 4] = {0.2f, 0.4f, 0.6f, 1.0f, 1.0f, 0.5f, 0.3f, 0.25f,
                                              0.7f, 0.9f, 0.1f, 0.0f, 0.4f, 0.4f, 0.8f, 0.6f};
    struct dr_material tile = glossy_blue();
    tile.sheened = true, tile.sheen_color = dr_v3(1.0, 1.0, 0.8), tile.sheen_roughness = 0.9;
    tile.sheen_color_tex.texture = sb_texture(&b, sb_image8(2, 2, 3, col_px));
    tile.sheen_roughness_tex.texture = sb_texture(&b, sb_image(2, 2, 4, rough_px, 0.0f, false));
    sb_quad(&b, dr_v3(0.2, 0.1, -0.8), dr_v3(0.6, 0, 0), dr_v3(0, 0.9, 0.2), sb_material(&b, tile));
    struct dr_material stretched = sb_diffuse(dr_v3(0.7, 0.8, 0.9));
    stretched.metallic = 1.0, stretched.roughness = 0.2;
    stretched.anisotropic = true, stretched.anisotropy_strength = 0.8, stretched.anisotropy_rotation = 0.4;
    stretched.sheened = true, stretched.sheen_color = dr_v3(0.5, 0.5, 0.5), stretched.sheen_roughness = 0.2;
    sb_box(&b, dr_v3(0.2, 0.0, 0.1), dr_v3(0.6, 0.4, 0.5), sb_material(&b, stretched));
    struct dr_material black = sb_diffuse(dr_v3(0.3, 0.8, 0.3));
    black.sheened = true, black.sheen_color = dr_v3s(0.0), black.sheen_roughness = 0.4;
    sb_quad(&b, dr_v3(-0.95, 0.2, -0.4), dr_v3(0, 0, 0.6), dr_v3(0, 0.6, 0), sb_material(&b, black));
    sb_quad(&b, dr_v3(-0.3, 1.5, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.1));
    return sb_finish(&b);
}

/* A lamp of two large triangles whose emissive texture is black but for
 * two spots (the way assets paint their glowing parts): the light table
 * samples its triangles part by part (lights.h, dr_light_part_point), the
 * packet tracer maps its lanes' light points into their parts and looks up
 * the density of the part a hit is in. eight_bit as textured_lamp_box. */
static float spot_px[64 * 64 * 3];
static struct dr_scene *spotted_lamp_box(bool eight_bit)
{
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++) {
            float *p = spot_px + 3 * (64 * y + x);
            const bool a = x >= 8 && x < 12 && y >= 10 && y < 14, c = x >= 40 && x < 48 && y >= 30 && y < 34;
            p[0] = a ? 1.0f : c ? 0.3f : 0.0f;
            p[1] = a ? 0.8f : c ? 0.6f : 0.0f;
            p[2] = a ? 0.5f : c ? 1.0f : 0.0f;
        }
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.7, 0.6, 0.5))));
    sb_box(&b, dr_v3(-0.5, 0.0, -0.5), dr_v3(0.0, 0.7, 0.0), sb_material(&b, glossy_blue()));
    struct dr_material glow = warm_lamp();
    glow.emissive_factor = dr_v3(40.0, 30.0, 20.0);
    glow.emissive_tex.texture =
        sb_texture(&b, eight_bit ? sb_image8(64, 64, 3, spot_px) : sb_image(64, 64, 3, spot_px, 0.0f, true));
    sb_quad(&b, dr_v3(-0.6, 1.9, -0.6), dr_v3(1.2, 0, 0), dr_v3(0, 0, 1.2), sb_material(&b, glow));   /* faces down */
    struct dr_scene *s = sb_finish(&b);
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt) && lt.any_parts && lt.n_emitters > 2 && lt.n_emitters < 200,
          "the spotted lamp's triangles are sampled part by part, the black parts left out (%lld entries)",
          (long long)lt.n_emitters);
    return s;
}

/* ---- differentiated vertices from the eight-lane stages (prb's walks and
 * replays, dr_wave_ops.bsdf_terms) against the one-path walker's */

/* What the adjoints of a BSDF parameter read of a vertex (path_simd.h's
 * dr_path8_shade lists it), kept by item and depth. */
struct diff_vertex {
    bool seen, diff, nee, cont;
    struct dr_wave_arrival arrival;
    struct dr_hit hit;
    dr_vec3 ng, wo, nee_wi, nee_f, wi, f, s;
    dr_frame frame;
    struct dr_bsdf bsdf;
    double nee_scale, nee_bsdf_pdf, pdf, cos_pdf_q;
    bool sub[3];
    struct dr_light_sample ls;
};
enum { DIFF_PATHS = 3000, DIFF_DEPTH = 8 };
struct diff_run {
    struct random_paths r;
    struct diff_vertex *rec;   /* [item * DIFF_DEPTH + depth - 1] */
};
static void diff_start(void *ctx, int64_t i, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    *(int64_t *)user = i;
    random_path_start(&((struct diff_run *)ctx)->r, i, smp, o, d);
}
static bool diff_vertex(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                        struct dr_sampler *smp, bool more)
{
    (void)smp, (void)more;
    struct diff_vertex *k = &((struct diff_run *)ctx)->rec[*(int64_t *)user * DIFF_DEPTH + v->depth - 1];
    *k = (struct diff_vertex){.seen = true, .diff = v->diff_bsdf, .arrival = *a};
    if (!v->diff_bsdf)
        return true;
    k->nee = v->nee, k->cont = v->cont;
    k->hit = v->hit, k->ng = v->ng, k->wo = v->wo, k->frame = v->frame, k->bsdf = v->bsdf;
    if (v->nee)
        k->nee_wi = v->nee_wi, k->nee_f = v->nee_f, k->nee_scale = v->nee_scale, k->nee_bsdf_pdf = v->nee_bsdf_pdf,
        k->ls = v->ls;
    if (v->cont)
        k->wi = v->wi, k->f = v->f, k->s = v->s, k->pdf = v->pdf, k->cos_pdf_q = v->cos_pdf_q,
        memcpy(k->sub, v->sub, sizeof k->sub);
    return true;
}
static enum dr_wave_next diff_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)ctx, (void)user, (void)smp, (void)o, (void)d;
    return DR_WAVE_DONE;
}

#define SAME(a, b) (memcmp(&(a), &(b), sizeof(a)) == 0)

/* Does kept vertex k hold the one-path walker's v to the bit, in every
 * field the adjoints read (the light sample's record as d_light_radiance
 * reads it for the light's kind; of the hit all but t, which nothing reads
 * and the stages set to the distance to p, path_simd.c's hit_of_lane)? */
static bool same_diff_vertex(const struct diff_vertex *k, const struct dr_path_vertex *v, dr_vec3 beta,
                             dr_vec3 ratio)
{
    const struct dr_hit *h = &k->hit, *g = &v->hit;
    bool same = k->diff && k->nee == v->nee && k->cont == v->cont && SAME(k->arrival.beta, beta) &&
                SAME(k->arrival.ratio, ratio) && h->tri == g->tri && SAME(h->p, g->p) &&
                SAME(h->ng, g->ng) && SAME(h->ns, g->ns) && SAME(h->uv, g->uv) && SAME(h->b1, g->b1) &&
                SAME(h->b2, g->b2) && h->front == g->front && h->material == g->material && SAME(h->eps, g->eps) &&
                SAME(k->ng, v->ng) && SAME(k->wo, v->wo) && SAME(k->frame, v->frame) &&
                SAME(k->bsdf.base_color, v->bsdf.base_color) && SAME(k->bsdf.metallic, v->bsdf.metallic) &&
                SAME(k->bsdf.roughness, v->bsdf.roughness) && SAME(k->bsdf.specular, v->bsdf.specular) &&
                SAME(k->bsdf.specular_color, v->bsdf.specular_color) && k->bsdf.coated == v->bsdf.coated &&
                SAME(k->bsdf.coat, v->bsdf.coat) && SAME(k->bsdf.coat_roughness, v->bsdf.coat_roughness);
    if (same && v->nee) {
        const struct dr_light_sample *a = &k->ls, *b = &v->ls;
        same = SAME(k->nee_wi, v->nee_wi) && SAME(k->nee_f, v->nee_f) && SAME(k->nee_scale, v->nee_scale) &&
               SAME(k->nee_bsdf_pdf, v->nee_bsdf_pdf) && a->type == b->type && SAME(a->wi, b->wi) &&
               SAME(a->radiance, b->radiance);
        if (b->type == DR_LS_AREA)
            same = same && a->index == b->index && SAME(a->b1, b->b1) && SAME(a->b2, b->b2);
        if (b->type == DR_LS_PUNCTUAL)
            same = same && a->index == b->index && SAME(a->atten, b->atten);
    }
    if (same && v->cont)
        same = SAME(k->wi, v->wi) && SAME(k->f, v->f) && SAME(k->s, v->s) && SAME(k->pdf, v->pdf) &&
               SAME(k->cos_pdf_q, v->cos_pdf_q) && SAME(k->sub, v->sub);
    return same;
}

/* With every other material's BSDF differentiated (the lamps' too, whose
 * black base colour makes zero channels to substitute), the lanes with
 * bsdf_terms shade those vertices eight at a time and hand them over as
 * the one-path walker makes them: compared field by field, path by path.
 * The same run without bsdf_terms must group fewer vertices (so the first
 * did take differentiated ones). */
static void differentiated_vertices_match(struct dr_scene *s, struct dr_camera cam, const char *name)
{
    char ptr_store[64][80];
    const char *ptrs[64];
    int n = 0;
    if (s->n_file_materials == 0)
        s->n_file_materials = s->n_materials;
    static const char *const what[] = {"baseColorFactor", "roughnessFactor", "metallicFactor"};
    for (int m = 0; m < s->n_file_materials && n + 3 <= 64; m += 2)
        for (int k = 0; k < 3; k++) {
            snprintf(ptr_store[n], sizeof ptr_store[n], "/materials/%d/pbrMetallicRoughness/%s", m, what[k]);
            ptrs[n] = ptr_store[n];
            n++;
        }
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: BSDF parameters: %s", name, dr_last_error());
    if (!ps)
        return;
    struct dr_path_opts po = {.max_depth = DIFF_DEPTH, .rr_depth = 3, .stages = dr_path_plan(s, ps), .params = ps};
    struct diff_run run = {{dr_camera_view(&cam, 64, 48), DR_SAMPLER_INDEPENDENT},
                           calloc((size_t)DIFF_PATHS * DIFF_DEPTH, sizeof(struct diff_vertex))};
    struct dr_wave *w = dr_wave_create();
    struct dr_wave_ops ops = {.start = diff_start, .vertex = diff_vertex, .walk_end = diff_end,
                              .partial_vertices = true, .bsdf_terms = true};
    struct dr_ray_counts with = {0}, without = {0};
    dr_wave_run(w, s, &po, DIFF_PATHS, &ops, &run, &with);
    int compared = 0, differ = 0, missing = 0;
    for (int64_t i = 0; i < DIFF_PATHS; i++) {
        struct dr_sampler smp;
        struct dr_path_state st;
        struct dr_path_vertex v = {0};
        dr_vec3 o, d;
        struct dr_ray_counts one = {0};
        random_path_start(&run.r, i, &smp, &o, &d);
        dr_path_start(&st, o, d);
        for (bool more = true; more;) {
            dr_vec3 beta = st.beta, ratio = st.ratio;
            more = dr_path_step(s, &po, &st, &smp, &v, &one);
            const struct diff_vertex *k = &run.rec[i * DIFF_DEPTH + v.depth - 1];
            missing += !k->seen || k->diff != v.diff_bsdf;
            if (k->seen && v.diff_bsdf) {
                compared++;
                differ += !same_diff_vertex(k, &v, beta, ratio);
            }
        }
    }
    ops.bsdf_terms = false;
    dr_wave_run(w, s, &po, DIFF_PATHS, &ops, &run, &without);
    CHECK(compared > 1000, "%s: only %d differentiated vertices", name, compared);
    CHECK(missing == 0 && differ == 0, "%s: of %d differentiated vertices from the lanes, %d differ from the one-path "
          "walker's, %d paths' vertices disagree on being differentiated", name, compared, differ, missing);
    CHECK(with.simd_vertices > without.simd_vertices, "%s: bsdf_terms grouped %llu vertices, without it %llu", name,
          (unsigned long long)with.simd_vertices, (unsigned long long)without.simd_vertices);
    printf("%s: %d differentiated vertices equal to the one-path walker's; %llu vertices eight-wide (%llu without "
           "bsdf_terms)\n", name, compared, (unsigned long long)with.simd_vertices,
           (unsigned long long)without.simd_vertices);
    dr_wave_destroy(w);
    free(run.rec);
    dr_param_set_destroy(ps);
}

/* radiance_matches_exactly on scene s (destroyed after), which must have
 * the effects named and qualify for the eight-lane stages, most of whose
 * hits they must take. */
static void exact_with_groups(struct dr_scene *s, unsigned effects, struct dr_camera cam, const char *name)
{
    struct dr_path_opts po = {.max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, NULL)};
    CHECK(dr_path8_applies(s, &po), "%s qualifies for the eight-lane stages", name);
    CHECK((s->effects & effects) == effects, "%s: effects %#x, expected %#x among them", name, s->effects, effects);
    /* (the structured samplers' numbers are drawn lane by lane inside the kernels) */
    const enum dr_sampler_kind kinds[] = {DR_SAMPLER_INDEPENDENT, DR_SAMPLER_SOBOL, DR_SAMPLER_STRATIFIED};
    for (int k = 0; k < 3; k++) {
        uint64_t simd = radiance_matches_exactly(s, cam, name, kinds[k]);
        CHECK(simd > 1000, "%s, %s sampler: only %llu vertices shaded eight lanes at a time", name,
              dr_sampler_kind_name(kinds[k]), (unsigned long long)simd);
    }
    differentiated_vertices_match(s, cam, name);
    dr_scene_destroy(s);
}

static void test_wavefront_matches_one_path(void)
{
    struct dr_scene *s = dr_scene_load(scene_path("cornell-box.gltf"));
    CHECK(s != NULL, "load the bundled scene: %s", dr_last_error());
    if (s) {
        CHECK(dr_wave_prefetches(s), "the textured box is shaded with prefetching");
        CHECK(wavefront_matches_one_path(s, s->cameras[0], "bundled Cornell box") > 0,
              "the bundled box's hits are shaded eight lanes at a time");
        exact_with_groups(s, DR_FX_TEXTURES | DR_FX_SPECULAR, s->cameras[0], "bundled Cornell box");
    }
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3(0.7, 0.5, 0.3))));
    sb_quad(&b, dr_v3(-0.3, 1.9, -0.3), dr_v3(0.6, 0, 0), dr_v3(0, 0, 0.6), sb_material(&b, warm_lamp()));   /* faces down */
    s = sb_finish(&b);
    CHECK(!dr_wave_prefetches(s), "a small untextured box is shaded in one pass");
    uint64_t simd = wavefront_matches_one_path(s, sb_camera(dr_v3(0, 1, 3.5), dr_v3(0, 1, 0), 45.0), "untextured box");
    CHECK(simd > 0, "the Lambertian box is shaded eight lanes at a time");
    dr_scene_destroy(s);
    s = mixed_box();
    CHECK(wavefront_matches_one_path(s, sb_camera(dr_v3(0, 1, 3.5), dr_v3(0, 0.8, 0), 50.0), "mixed box") > 0,
          "the mixed box's hits are shaded eight lanes at a time");
    struct dr_camera inside = sb_camera(dr_v3(0, 1, 2.5), dr_v3(0, 0.8, 0), 60.0);
    exact_with_groups(s, DR_FX_SHADING_NORMALS | DR_FX_SPECULAR | DR_FX_SINGLE_SIDED | DR_FX_TEXTURES, inside,
                      "mixed box");
    exact_with_groups(lit_box(), DR_FX_PUNCTUAL_LIGHTS | DR_FX_ENV_MAP | DR_FX_AREA_LIGHTS, inside, "lit box");
    exact_with_groups(sky_box(), DR_FX_ENV_CONSTANT, sb_camera(dr_v3(0, 2.5, 2.0), dr_v3(0, 0.3, 0), 60.0),
                      "sky-lit box");
    const struct dr_camera above = sb_camera(dr_v3(0.3, 2.5, 1.8), dr_v3(0, 0.3, 0), 70.0);
    exact_with_groups(map_box(false), DR_FX_ENV_MAP, above, "map-lit box");
    exact_with_groups(map_box(true), DR_FX_ENV_MAP, above, "map-lit box, grey map");
    exact_with_groups(bumpy_box(false), DR_FX_NORMAL_MAPS, inside, "bumpy box");
    exact_with_groups(bumpy_box(true), DR_FX_NORMAL_MAPS | DR_FX_SHADING_NORMALS, inside, "bumpy box, eight-bit map");
    exact_with_groups(cutout_box(), DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND | DR_FX_AREA_LIGHTS | DR_FX_TEXTURES, inside,
                      "cut-out box");
    exact_with_groups(tiled_lamp_box(), DR_FX_AREA_LIGHTS | DR_FX_PUNCTUAL_LIGHTS, inside, "tiled lamp box");
    exact_with_groups(textured_lamp_box(false), DR_FX_AREA_LIGHTS | DR_FX_PUNCTUAL_LIGHTS | DR_FX_TEXTURES, inside,
                      "textured lamp box");
    exact_with_groups(textured_lamp_box(true), DR_FX_AREA_LIGHTS | DR_FX_PUNCTUAL_LIGHTS | DR_FX_TEXTURES, inside,
                      "textured lamp box, eight-bit textures, TEXCOORD_1");
    exact_with_groups(spotted_lamp_box(false), DR_FX_AREA_LIGHTS | DR_FX_TEXTURES, inside, "spotted lamp box");
    exact_with_groups(spotted_lamp_box(true), DR_FX_AREA_LIGHTS | DR_FX_TEXTURES, inside,
                      "spotted lamp box, eight-bit texture");
    exact_with_groups(coated_box(), DR_FX_CLEARCOAT | DR_FX_TEXTURES | DR_FX_ENV_CONSTANT | DR_FX_AREA_LIGHTS,
                      sb_camera(dr_v3(0.2, 2.2, 2.0), dr_v3(0, 0.3, 0), 70.0), "coated box");
    exact_with_groups(anisotropic_box(false), DR_FX_ANISOTROPY | DR_FX_CLEARCOAT | DR_FX_TEXTURES | DR_FX_ENV_CONSTANT,
                      sb_camera(dr_v3(0.2, 2.2, 2.0), dr_v3(0, 0.3, 0), 70.0), "anisotropic box");
    exact_with_groups(anisotropic_box(true), DR_FX_ANISOTROPY | DR_FX_CLEARCOAT | DR_FX_TEXTURES | DR_FX_ENV_CONSTANT,
                      sb_camera(dr_v3(0.2, 2.2, 2.0), dr_v3(0, 0.3, 0), 70.0), "anisotropic box, float direction texture");
    exact_with_groups(sheened_box(), DR_FX_SHEEN | DR_FX_ANISOTROPY | DR_FX_CLEARCOAT | DR_FX_TEXTURES | DR_FX_ENV_CONSTANT,
                      sb_camera(dr_v3(0.2, 2.2, 2.0), dr_v3(0, 0.3, 0), 70.0), "sheened box");
    s = coloured_box();
    CHECK(!dr_wave_prefetches(s), "the coloured box is shaded without prefetching");
    exact_with_groups(s, DR_FX_VERTEX_COLORS, inside, "coloured box");
}

/* Scenes whose media are bounded by meshes: the packet renderer keeps the
 * paths that have entered no medium on the eight-lane stages (their shadow
 * rays through a medium's box take the one-path walker's transmittance) and
 * hands the others to the one-path walker at the start of the step where
 * they could enter one (wave_soa.c's finish_in_media) with the step's ray
 * query answered. The image and the ray counts must be the one-path
 * walker's, bit for bit: a homogeneous KHR volume, a density grid,
 * a medium behind a dielectric boundary; and a camera inside the fog, whose
 * every path starts in it. */
static void test_media_outside_paths(void)
{
    const char *dir = getenv("DR_TESTDIR") ? getenv("DR_TESTDIR") : "tests";
    const char *names[] = {"fog-khr", "smoke", "glass-fog"};
    for (int i = 0; i < 3; i++) {
        char path[4096];
        snprintf(path, sizeof path, "%s/data/media/%s.gltf", dir, names[i]);
        struct dr_scene *s = dr_scene_load(path);
        CHECK(s != NULL, "load %s: %s", path, dr_last_error());
        if (!s)
            continue;
        const struct dr_path_opts po = {.max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, NULL)};
        CHECK(dr_wave_soa_applies(s, &po), "%s: the packet tracer renders a scene whose media are bounded", names[i]);
        const uint64_t simd = wavefront_matches_one_path(s, s->cameras[0], names[i]);
        CHECK(simd > 0, "%s: %llu vertices shaded eight lanes at a time", names[i], (unsigned long long)simd);
        if (i == 0) {   /* the camera in the fog cube ([-1, 1]^3): every path starts in it */
            const uint64_t in_fog = wavefront_matches_one_path(
                s, sb_camera(dr_v3(0.2, 0.1, 0.5), dr_v3(0, -1, -3), 60.0), "fog-khr, camera inside");
            CHECK(in_fog == 0, "camera in the fog: %llu vertices eight lanes at a time (none: every path starts in "
                  "it)", (unsigned long long)in_fog);
        }
        dr_scene_destroy(s);
    }
}

/* A fog octahedron (|x| + |y| + |z| <= 1) over a floor: a camera inside its
 * box [-1, 1]^3 but outside the octahedron starts no path in the fog, and
 * the packet renderer keeps its paths (wave_soa.c's meets_medium asks the
 * one-path walker's dr_medium_at where a camera is inside a medium's box);
 * the image is still the one-path walker's. */
static void test_media_camera_in_box(void)
{
    struct sb b;
    sb_init(&b);
    const int fog = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    const dr_vec3 axis[3] = {dr_v3(1, 0, 0), dr_v3(0, 1, 0), dr_v3(0, 0, 1)};
    for (int f = 0; f < 8; f++) {   /* face (sx, sy, sz), wound to face outwards */
        const double sx = f & 1 ? -1 : 1, sy = f & 2 ? -1 : 1, sz = f & 4 ? -1 : 1;
        uint32_t a = sb_vertex(&b, dr_scale(axis[0], sx), 0, 0), c = sb_vertex(&b, dr_scale(axis[1], sy), 0, 0),
                 d = sb_vertex(&b, dr_scale(axis[2], sz), 0, 0);
        if (sx * sy * sz > 0)
            sb_triangle(&b, a, c, d, fog);
        else
            sb_triangle(&b, a, d, c, fog);
    }
    sb_medium(&b, fog, medium(dr_v3(1.5, 2.0, 2.5), dr_v3(0.8, 0.8, 0.7), 0.2));
    sb_quad(&b, dr_v3(-4, -1.2, -4), dr_v3(0, 0, 8), dr_v3(8, 0, 0), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_environment(&b, dr_v3(0.6, 0.7, 0.9));
    struct dr_scene *s = sb_finish(&b);
    const dr_vec3 corner = dr_v3(0.7, 0.6, 0.8);   /* in the box, |x| + |y| + |z| = 2.1: outside */
    CHECK(dr_medium_at(s, corner, dr_v3(0, 0, 1)) == -1 && dr_medium_at(s, dr_v3(0.1, 0.1, 0.1), dr_v3(0, 0, 1)) == 0,
          "octahedron: the corner of its box is outside it, its centre inside");
    const uint64_t simd = wavefront_matches_one_path(s, sb_camera(corner, dr_v3(-0.5, -1.2, -0.5), 70.0),
                                                     "camera in the octahedron's box, outside it");
    CHECK(simd > 0, "camera outside the fog but in its box: %llu vertices eight lanes at a time",
          (unsigned long long)simd);
    dr_scene_destroy(s);
}

int main(void)
{
    test_wavefront_matches_one_path();
    test_media_camera_in_box();
    test_media_outside_paths();
    test_emitter_seen_directly();
    test_diffuse_plane_constant_env();
    test_sky_mixture_matches_sphere();
    test_furnace();
    test_punctual();
    test_area_light_mis();
    test_env_map_sampling();
    return TEST_END();
}
