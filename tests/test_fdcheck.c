/* Gradients against finite differences (statistical: both sides carry a
 * standard error from independent batches, the verdict is a z-score), on the
 * cases a user relies on and on the hard ones. Each case builds a small scene
 * in code, runs dr_fdcheck with both estimators and requires agreement and
 * finite values. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "fdcheck.h"
#include "scene_builder.h"
#include "lights.h"
#include "test.h"

struct fd_case {
    const char *name;
    int spp, batches, max_depth, res;
    double eps;
    const char *may_be_zero;   /* the one parameter whose true derivative may be ~0 (no resolvability
                                  check for its entries); NULL: every entry must be resolved */
    const char *attached_biased;  /* the parameter whose attached estimate misses a boundary term here
                                     (samples cross an edge): reported, not judged (the discontinuity
                                     case measures that bias); NULL: none */
};

static void run_case(const struct fd_case *c, struct dr_scene *s, struct dr_camera cam, const char *const *ptrs,
                     int n)
{
    s->n_file_materials = s->n_materials;
    /* (the cameras here are not the scene's: backface.h) */
    CHECK(dr_scene_add_viewpoint(s, &cam) == 0, "%s: add_viewpoint: %s", c->name, dr_last_error());
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: %s", c->name, dr_last_error());
    if (!ps)
        return;
    for (int run = 0; run < 2 * DR_SAMPLING_COUNT && dr_estimators[run / DR_SAMPLING_COUNT]; run++) {
        const int e = run / DR_SAMPLING_COUNT;
        const enum dr_sampling smp = (enum dr_sampling)(run % DR_SAMPLING_COUNT);
        if (!dr_estimator_supports(dr_estimators[e], smp))
            continue;
        struct dr_fd_options o = {.estimator = dr_estimators[e], .sampling = smp, .width = c->res, .height = c->res,
                                  .spp = c->spp, .batches = c->batches, .max_depth = c->max_depth,
                                  .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 1234, .threads = 2, .eps = c->eps,
                                  .z_max = 4.0, .regularize = DR_PRB_REGULARIZE_DEFAULT};
        struct dr_fd_entry *en = NULL;
        int count = 0;
        int rc = dr_fdcheck(s, &cam, ps, &o, &en, &count);
        CHECK(rc == 0, "%s: fdcheck failed: %s", c->name, dr_last_error());
        for (int i = 0; i < count; i++) {
            printf("%-12s %-5s %-8s %-70s rev %.5g +- %.2g  fwd %.5g +- %.2g  fd %.5g +- %.2g  z %.2f %.2f\n", c->name,
                   dr_estimators[e]->name, dr_sampling_name(smp), en[i].label, en[i].reverse, en[i].reverse_se, en[i].forward,
                   en[i].forward_se, en[i].fd, en[i].fd_se, en[i].z_reverse, en[i].z_forward);
            CHECK(isfinite(en[i].reverse) && isfinite(en[i].forward) && isfinite(en[i].fd), "%s: %s not finite",
                  c->name, en[i].label);
            /* mis weighs the attached estimate in, and its bias with it */
            bool biased = smp != DR_SAMPLING_DETACHED && c->attached_biased &&
                          strncmp(en[i].label, c->attached_biased, strlen(c->attached_biased)) == 0;
            if (biased)
                continue;   /* reported, not judged (see attached_biased) */
            CHECK(en[i].agree, "%s (%s, %s): %s: gradient %.6g/%.6g vs finite differences %.6g (z %.2f, %.2f)", c->name,
                  dr_estimators[e]->name, dr_sampling_name(smp), en[i].label, en[i].reverse, en[i].forward, en[i].fd, en[i].z_reverse,
                  en[i].z_forward);
            /* a check that cannot fail is no check: the derivative must be resolved */
            bool exempt = c->may_be_zero && strncmp(en[i].label, c->may_be_zero, strlen(c->may_be_zero)) == 0;
            CHECK(exempt || fabs(en[i].fd) > 3.0 * en[i].fd_se || fabs(en[i].reverse) < 1e-12,
                  "%s: %s: finite differences too noisy to judge (%.3g +- %.3g)", c->name, en[i].label, en[i].fd,
                  en[i].fd_se);
        }
        free(en);
    }
    dr_param_set_destroy(ps);
}

static void diffuse_plane_env(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-100, 0, 100), dr_v3(200, 0, 0), dr_v3(0, 0, -200), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_environment(&b, dr_v3(0.8, 1.0, 1.2));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor", "/extensions/DR_environment/color",
                       "/extensions/DR_environment/strength"};
    struct fd_case c = {"plane-env", 4, 8, 4, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 0.5), dr_v3(0, 0, 0), 40), p, 3);
    dr_scene_destroy(s);
}


static struct dr_material emitter(dr_vec3 Le)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = Le;
    return m;
}

/* Floor, a wall behind the camera (never seen directly) and a small ceiling
 * light: with max depth 3 the wall's albedo matters only through
 * camera -> floor -> wall -> light. Geometry scaled by `scale`. */
static struct dr_scene *hidden_wall_scene(double scale, dr_vec3 wall_albedo)
{
    struct sb b;
    sb_init(&b);
    double S = scale;
    sb_quad(&b, dr_v3(-3 * S, 0, 3 * S), dr_v3(6 * S, 0, 0), dr_v3(0, 0, -6 * S), sb_material(&b, sb_diffuse(dr_v3s(0.7))));
    /* wall at z = +2, facing -z */
    sb_quad(&b, dr_v3(3 * S, 0, 2 * S), dr_v3(-6 * S, 0, 0), dr_v3(0, 3 * S, 0), sb_material(&b, sb_diffuse(wall_albedo)));
    /* light at y = 2.5 facing down, near the wall */
    sb_quad(&b, dr_v3(-0.5 * S, 2.5 * S, 1.8 * S), dr_v3(0, 0, -1 * S), dr_v3(1 * S, 0, 0), sb_material(&b, emitter(dr_v3(8, 8, 8))));
    return sb_finish(&b);
}

static void hidden_wall(void)
{
    struct dr_scene *s = hidden_wall_scene(1.0, dr_v3(0.5, 0.6, 0.7));
    const char *p[] = {"/materials/1/pbrMetallicRoughness/baseColorFactor"};
    struct fd_case c = {"hidden-wall", 16, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 1), dr_v3(0, 0, -1.5), 40), p, 1);
    dr_scene_destroy(s);
}

/* Area light over a floor: emission factor and strength. */
static void area_emission(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.6, 0.6))));
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, emitter(dr_v3(3, 2, 1))));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/1/emissiveFactor", "/materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength"};
    struct fd_case c = {"area-light", 8, 8, 4, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), p, 2);
    dr_scene_destroy(s);
}

static void point_light(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_box(&b, dr_v3(-0.3, 0, -0.3), dr_v3(0.3, 0.6, 0.3), sb_material(&b, sb_diffuse(dr_v3(0.8, 0.8, 0.8))));
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3(1, 0.8, 0.6);
    l.intensity = 4;
    l.position = dr_v3(0.5, 2, 0.5);
    sb_light(&b, l);
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/extensions/KHR_lights_punctual/lights/0/intensity", "/extensions/KHR_lights_punctual/lights/0/color"};
    struct fd_case c = {"point-light", 8, 8, 4, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(1.5, 1.5, 1.5), dr_v3(0, 0.2, 0), 50), p, 2);
    dr_scene_destroy(s);
}

/* An environment map lighting a diffuse box on a floor: every texel. */
static void env_map(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.6, 0.6))));
    sb_box(&b, dr_v3(-0.3, 0, -0.3), dr_v3(0.3, 0.6, 0.3), sb_material(&b, sb_diffuse(dr_v3(0.8, 0.5, 0.3))));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_image *map = &b.s->env.map;
    map->width = 8;
    map->height = 4;
    map->channels = 3;
    map->data = malloc(sizeof(float) * 8 * 4 * 3);
    for (int i = 0; i < 8 * 4 * 3; i++)
        map->data[i] = (float)(0.2 + 0.1 * (i % 7));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/extensions/DR_environment/uri"};
    struct fd_case c = {"env-map", 8, 8, 4, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(1.5, 1.5, 1.5), dr_v3(0, 0.2, 0), 50), p, 1);
    dr_scene_destroy(s);
}

/* A glossy floor (metallic 0.5, roughness 0.3) reflecting an area light.
 * Attached sampling moves BSDF samples across the light's edge as the
 * roughness changes: the boundary term it drops biases the roughness
 * derivative (here by about 0.012 against 0.011, z ~ -2.4 at these
 * settings: too close to the noise to judge either way; detached is unbiased). */
static void glossy(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material g = sb_diffuse(dr_v3(0.7, 0.5, 0.3));
    g.metallic = 0.5;
    g.roughness = 0.3;
    g.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, g));
    sb_quad(&b, dr_v3(-0.5, 1.5, -0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, emitter(dr_v3(4, 4, 4))));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/roughnessFactor", "/materials/0/pbrMetallicRoughness/metallicFactor"};
    struct fd_case c = {"glossy", 64, 8, 3, 16, 2e-2, NULL, "/materials/0/pbrMetallicRoughness/roughnessFactor"};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 1.5), dr_v3(0, 0, -0.6), 40), p, 2);
    dr_scene_destroy(s);
}

/* The same floor under a smooth environment map instead: nothing to cross,
 * so attached sampling agrees too (the lobe probability, which depends on
 * wo and metallic, is held fixed by the attached estimator: unbiased). */
static void glossy_env_scaled(double S, const char *name)
{
    struct sb b;
    sb_init(&b);
    struct dr_material g = sb_diffuse(dr_v3(0.7, 0.5, 0.3));
    g.metallic = 0.5;
    g.roughness = 0.3;
    g.specular = 1.0;
    sb_quad(&b, dr_v3(-3 * S, 0, 3 * S), dr_v3(6 * S, 0, 0), dr_v3(0, 0, -6 * S), sb_material(&b, g));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_image *map = &b.s->env.map;
    map->width = 16;
    map->height = 8;
    map->channels = 3;
    map->data = malloc(sizeof(float) * 16 * 8 * 3);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++)
            for (int k = 0; k < 3; k++)
                map->data[(y * 16 + x) * 3 + k] = (float)(0.2 + 0.1 * x + 0.3 * y + 0.1 * k);
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/roughnessFactor", "/materials/0/pbrMetallicRoughness/metallicFactor"};
    struct fd_case c = {name, 32, 8, 3, 16, 2e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, S, 1.5 * S), dr_v3(0, 0, -0.6 * S), 40), p, 2);
    dr_scene_destroy(s);
}

/* A half-metal floor under a constant sky, rough enough (0.6: alpha 0.36)
 * that next-event estimation draws the sky partly by the BSDF and partly by
 * the cosine (lights.h's dr_sky_pdf, the share strictly between 0 and 1):
 * the attached adjoints of both kinds of light sample and of the escaping
 * ray's density (path_attached.c), in expectation; and mis, which samples
 * the sky over the sphere, whose density then has no adjoint. */
static void glossy_sky(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material g = sb_diffuse(dr_v3(0.7, 0.5, 0.3));
    g.metallic = 0.5;
    g.roughness = 0.6;
    g.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, g));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.2));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/roughnessFactor", "/materials/0/pbrMetallicRoughness/metallicFactor"};
    struct fd_case c = {"glossy-sky", 32, 8, 3, 16, 2e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 1.5), dr_v3(0, 0, -0.6), 40), p, 2);
    dr_scene_destroy(s);
}

static void glossy_env(void)
{
    glossy_env_scaled(1.0, "glossy-env");
    glossy_env_scaled(1e-3, "glossy-1e-3");
    glossy_env_scaled(1e3, "glossy-1e3");
}

/* Inside a closed glossy box whose walls all glow: every ray hits a wall and
 * the radiance is continuous across the corners (nothing for attached
 * sampling to cross), max depth 1000 with Russian roulette: attached
 * roughness derivatives over long paths. */
static void glossy_closed_box(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material g = sb_diffuse(dr_v3(0.9, 0.85, 0.8));
    g.metallic = 0.5;
    g.roughness = 0.4;
    g.specular = 1.0;
    g.emissive_factor = dr_v3(0.3, 0.3, 0.3);
    g.double_sided = true;
    sb_box(&b, dr_v3(-1, -1, -1), dr_v3(1, 1, 1), sb_material(&b, g));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/roughnessFactor"};
    struct fd_case c = {"box-1000", 8, 8, 1000, 12, 2e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0.2, 0.1, 0.8), dr_v3(-0.3, -0.5, -1), 60), p, 1);
    dr_scene_destroy(s);
}

/* The discontinuity case (scene_builder.h, sb_occluder_edge): attached
 * sampling drops the plate silhouette's boundary term and fdcheck must flag
 * it, while detached agrees. The bias is printed (see the manual, SAMPLING). */
static void occluder_edge(void)
{
    struct dr_camera cam;
    struct dr_scene *s = sb_occluder_edge(&cam);
    const char *p = "/materials/0/pbrMetallicRoughness/roughnessFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &p, 1);
    struct dr_fd_entry *en[2] = {NULL, NULL};
    for (int k = 0; k < 2; k++) {
        struct dr_fd_options o = {.estimator = dr_estimator_find("tape"), .sampling = (enum dr_sampling)k,
                                  .width = 16, .height = 16, .spp = 32, .batches = 8, .max_depth = 2,
                                  .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 7, .threads = 2, .eps = 1e-2,
                                  .z_max = 4.0};
        int count = 0;
        CHECK(dr_fdcheck(s, &cam, ps, &o, &en[k], &count) == 0 && count == 1, "occluder edge: %s", dr_last_error());
    }
    if (en[0] && en[1]) {
        printf("occluder-edge fd %.5g +- %.2g; detached %.5g +- %.2g (z %.2f); attached %.5g +- %.2g (z %.2f), "
               "bias %.3g (%.0f%% of fd)\n",
               en[0]->fd, en[0]->fd_se, en[0]->reverse, en[0]->reverse_se, en[0]->z_reverse, en[1]->reverse,
               en[1]->reverse_se, en[1]->z_reverse, en[1]->reverse - en[1]->fd,
               100.0 * (en[1]->reverse - en[1]->fd) / fabs(en[1]->fd));
        CHECK(en[0]->agree, "occluder edge: detached disagrees (z %.2f)", en[0]->z_reverse);
        CHECK(!en[1]->agree, "occluder edge: the attached boundary-term bias went unflagged (z %.2f)",
              en[1]->z_reverse);
        CHECK(isfinite(en[1]->reverse) && isfinite(en[1]->forward), "occluder edge: not finite");
    }
    free(en[0]);
    free(en[1]);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* A floor with a 4x4 base-colour texture (already linear) under an environment. */
/* b's scene finished with one image, img, as its texture 0 (REPEAT). */
static struct dr_scene *one_texture(struct sb *b, struct dr_image img)
{
    struct dr_scene *s = b->s;
    s->n_images = 1;
    s->images = calloc(1, sizeof(struct dr_image));
    s->images[0] = img;
    s->n_textures = 1;
    s->textures = calloc(1, sizeof(struct dr_texture));
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    return sb_finish(b);
}

static void texture_texels(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3s(1.0));
    m.base_color_tex.texture = 0;
    sb_quad(&b, dr_v3(-1, 0, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, m));
    sb_environment(&b, dr_v3(1.0, 0.9, 0.8));
    float px[48];
    for (int i = 0; i < 48; i++)
        px[i] = (float)(0.2 + 0.05 * (i % 11));
    struct dr_scene *s = one_texture(&b, sb_image(4, 4, 3, px, 0.0f, true));
    const char *p[] = {"/images/0"};
    struct fd_case c = {"texture", 8, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1.2, 0.8), dr_v3(0, 0, 0), 60), p, 1);
    dr_scene_destroy(s);
}

/* ---- hard cases ---- */

/* Base colour exactly 0 inside an open box under an environment: the replay
 * divides by f = 0 nowhere, and the interreflection derivative (through the
 * substituted continuation) matches one-sided finite differences. */
static void zero_albedo(void)
{
    struct sb b;
    sb_init(&b);
    sb_open_box(&b, 2.0, sb_material(&b, sb_diffuse(dr_v3s(0.0))));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor"};
    struct fd_case c = {"zero-albedo", 8, 8, 6, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0.1, 4, 0.2), dr_v3(0, 0, 0), 30), p, 1);
    dr_scene_destroy(s);
}

/* Camera rays skimming a plane at 0.05 degrees. */
static void grazing(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-1000, 0, 1000), dr_v3(2000, 0, 0), dr_v3(0, 0, -2000), sb_material(&b, sb_diffuse(dr_v3(0.5, 0.5, 0.5))));
    sb_environment(&b, dr_v3(1, 1, 1));
    struct dr_scene *s = sb_finish(&b);
    double a = 0.05 * M_PI / 180;
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor"};
    struct fd_case c = {"grazing", 4, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 0.5, 0), dr_v3(0, 0.5 - 10 * tan(a), -10), 0.02), p, 1);
    dr_scene_destroy(s);
}

/* Near-specular metal (roughness 0.001) reflecting an environment map. */
static void near_specular(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.9, 0.8, 0.6));
    m.metallic = 1.0;
    m.roughness = 0.001;
    m.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, m));
    sb_environment_ramp(&b);
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor", "/materials/0/pbrMetallicRoughness/roughnessFactor"};
    struct fd_case c = {"rough-0.001", 16, 8, 3, 16, 2e-4, "/materials/0/pbrMetallicRoughness/roughnessFactor", NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 1), dr_v3(0, 0, -1), 40), p, 2);
    dr_scene_destroy(s);
}

/* The roughness-0.001 comparison, at the same sample count: the
 * detached roughness derivative is unbiased but useless (its 1/alpha-sized
 * terms almost cancel), the attached one agrees with finite differences and
 * its standard error is orders of magnitude smaller (measured: detached
 * -4.6 +- 11, attached 3.7e-5 +- 1.4e-5, FD 3.1e-5 +- 1.2e-5). The true
 * derivative is so small that its error bar stays near half its size at this
 * sample count, so the test compares the attached error bar with detached's.
 * mis must find that on its own (measured: 3.67e-5 +- 1.42e-5). */
static void near_specular_attached_vs_detached(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.9, 0.8, 0.6));
    m.metallic = 1.0;
    m.roughness = 0.001;
    m.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, m));
    sb_environment_ramp(&b);
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *p = "/materials/0/pbrMetallicRoughness/roughnessFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &p, 1);
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 1), dr_v3(0, 0, -1), 40);
    struct dr_fd_entry *en[3] = {NULL, NULL, NULL};
    for (int k = 0; k < 3; k++) {   /* detached, attached, mis */
        struct dr_fd_options o = {.estimator = dr_estimator_find("tape"), .sampling = (enum dr_sampling)k,
                                  .width = 16, .height = 16, .spp = 16, .batches = 8, .max_depth = 3,
                                  .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 99, .threads = 2, .eps = 2e-4,
                                  .z_max = 3.0};
        int count = 0;
        CHECK(dr_fdcheck(s, &cam, ps, &o, &en[k], &count) == 0 && count == 1, "rough-0.001: %s", dr_last_error());
    }
    if (en[0] && en[1] && en[2]) {
        printf("rough-0.001 detached %.4g +- %.3g, attached %.4g +- %.3g, mis %.4g +- %.3g, fd %.4g +- %.3g\n",
               en[0]->reverse, en[0]->reverse_se, en[1]->reverse, en[1]->reverse_se, en[2]->reverse,
               en[2]->reverse_se, en[1]->fd, en[1]->fd_se);
        CHECK(en[1]->agree, "rough-0.001 attached: %.4g vs fd %.4g (z %.2f)", en[1]->reverse, en[1]->fd,
              en[1]->z_reverse);
        CHECK(en[1]->reverse_se < 1e-3 * en[0]->reverse_se, "rough-0.001: attached stderr %.3g vs detached %.3g",
              en[1]->reverse_se, en[0]->reverse_se);
        /* mis finds the attached estimate on its own: its error bar is the
         * attached one's, not detached's (within a factor for the weights'
         * estimation) */
        CHECK(en[2]->agree, "rough-0.001 mis: %.4g vs fd %.4g (z %.2f)", en[2]->reverse, en[2]->fd,
              en[2]->z_reverse);
        CHECK(en[2]->reverse_se < 1.2 * en[1]->reverse_se, "rough-0.001: mis stderr %.3g vs attached %.3g",
              en[2]->reverse_se, en[1]->reverse_se);
    }
    for (int k = 0; k < 3; k++)
        free(en[k]);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Albedo 0.99 in the open box, max depth 1000: long paths, Russian roulette. */
static void long_paths(void)
{
    struct sb b;
    sb_init(&b);
    /* a deep box (opening 2x2 at height 6) keeps paths bouncing */
    sb_open_box(&b, 6.0, sb_material(&b, sb_diffuse(dr_v3s(0.99))));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor"};
    struct fd_case c = {"depth-1000", 8, 8, 1000, 12, 2e-3, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0.1, 9, 0.2), dr_v3(0, 0, 0), 10), p, 1);
    dr_scene_destroy(s);
}

/* A 1 mm emitter of radiance 1e6 over a floor. */
static void tiny_emitter(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_quad(&b, dr_v3(-5e-4, 1, 5e-4), dr_v3(0, 0, -1e-3), dr_v3(1e-3, 0, 0), sb_material(&b, emitter(dr_v3s(1e6))));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor",
                       "/materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength"};
    struct fd_case c = {"tiny-1e6", 8, 8, 4, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 1.5), dr_v3(0, 0, 0), 50), p, 2);
    dr_scene_destroy(s);
}

/* Lights whose radiance is black where they are sampled but has a
 * parameter: the light sample's term is 0, its derivative is not. An
 * emissive panel whose 8x8 texture is black but for one texel (raising the
 * black texels lights the panel), and a floor under a sky of strength 0 (its
 * strength raised lights it). Light samples of black radiance used to be
 * dropped with their derivative: next-event estimation's share of it was
 * missing (the panel's texels: 0.050 against 0.747, z -393; the sky's
 * strength: 0.541 against 0.621, z -36). */
/* A grey floor under a panel (material 1) whose emission reads image im. */
static struct dr_scene *glowing_panel(struct dr_image im)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3s(0.7))));
    struct dr_material glow = emitter(dr_v3s(1.0));
    glow.emissive_strength = 20.0;
    glow.emissive_tex.texture = 0;
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, glow));
    return one_texture(&b, im);
}

static void dark_texels(void)
{
    float px[8 * 8 * 3] = {0};
    for (int c = 0; c < 3; c++)
        px[3 * (2 * 8 + 5) + c] = 1.0f;
    struct dr_scene *s = glowing_panel(sb_image(8, 8, 3, px, 0.0f, true));
    const char *p[] = {"/images/0"};
    struct fd_case c = {"dark-texels", 16, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), p, 1);
    dr_scene_destroy(s);
}

/* The same panel with a 32x32 texture, black but for a 3x3 spot: its
 * triangles are sampled part by part (lights.h), the parts that can read
 * only black texels left out of the light table, so next-event estimation
 * reaches only the spot and the black texels' derivative comes from the
 * hits of BSDF-sampled rays alone (their light density there is 0). */
static void spotted_parts(void)
{
    static float px[32 * 32 * 3];
    for (int y = 20; y < 23; y++)
        for (int x = 9; x < 12; x++)
            for (int c = 0; c < 3; c++)
                px[3 * (32 * y + x) + c] = 1.0f;
    struct dr_scene *s = glowing_panel(sb_image(32, 32, 3, px, 0.0f, true));
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt) && lt.any_parts && lt.n_emitters < 16,
          "spotted panel: sampled part by part, black parts left out (%lld entries)", (long long)lt.n_emitters);
    const char *p[] = {"/images/0", "/materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength"};
    struct fd_case c = {"spot-parts", 16, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), p, 2);
    dr_scene_destroy(s);
}

/* A floor under a lamp cut out by alphaMode MASK (its RGBA base colour
 * texture's alpha: a checker of holes) and a cut-out panel beside it: light
 * points in the holes emit nothing, rays pass through them (the queries'
 * filters), so the floor's albedo and the lamp's strength are seen through
 * a lamp that is half holes. The eight-lane stages run here too
 * (path_simd.c). */
static void cutouts(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    float px[4 * 4 * 4];
    for (int k = 0; k < 16; k++) {
        px[4 * k] = px[4 * k + 1] = px[4 * k + 2] = 0.8f;
        px[4 * k + 3] = ((k % 4) + (k / 4)) % 2 ? 0.0f : 1.0f;
    }
    struct dr_material lamp = emitter(dr_v3(3, 2, 1));
    lamp.alpha_mode = DR_ALPHA_MASK;
    lamp.alpha_cutoff = 0.5;
    lamp.base_color_tex.texture = 0;
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, lamp));
    struct dr_material panel = sb_diffuse(dr_v3(0.3, 0.6, 0.3));
    panel.alpha_mode = DR_ALPHA_MASK;
    panel.alpha_cutoff = 0.5;
    panel.base_color_tex.texture = 0;
    sb_quad(&b, dr_v3(0.6, 0.0, -0.6), dr_v3(0, 0, 1.2), dr_v3(0, 1.2, 0), sb_material(&b, panel));
    struct dr_scene *s = one_texture(&b, sb_image8(4, 4, 4, px));
    CHECK(s->effects & DR_FX_ALPHA_MASK, "cut-outs: the scene has alpha MASK");
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor",
                       "/materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength"};
    struct fd_case c = {"cut-outs", 16, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), p, 2);
    dr_scene_destroy(s);
}

static void dark_sky(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3s(0.7))));
    sb_quad(&b, dr_v3(-0.5, 0.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, sb_diffuse(dr_v3s(0.3))));
    sb_environment(&b, dr_v3(0.8, 0.9, 1.0));
    b.s->env.strength = 0.0;
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/extensions/DR_environment/strength"};
    struct fd_case c = {"dark-sky", 16, 8, 3, 16, 1e-2, NULL, NULL};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), p, 1);
    dr_scene_destroy(s);
}

/* The hidden-wall scene at 1e-3 and 1e3 times its size. */
static void scales(void)
{
    for (int k = 0; k < 2; k++) {
        double S = k == 0 ? 1e-3 : 1e3;
        struct dr_scene *s = hidden_wall_scene(S, dr_v3(0.5, 0.6, 0.7));
        const char *p[] = {"/materials/1/pbrMetallicRoughness/baseColorFactor", "/materials/0/pbrMetallicRoughness/baseColorFactor"};
        struct fd_case c = {k == 0 ? "scale-1e-3" : "scale-1e3", 16, 8, 3, 16, 1e-2, NULL, NULL};
        run_case(&c, s, sb_camera(dr_v3(0, S, S), dr_v3(0, 0, -1.5 * S), 40), p, 2);
        dr_scene_destroy(s);
    }
}

int main(void)
{
    diffuse_plane_env();
    hidden_wall();
    area_emission();
    point_light();
    env_map();
    glossy();
    glossy_env();
    glossy_sky();
    occluder_edge();
    texture_texels();
    zero_albedo();
    grazing();
    near_specular();
    near_specular_attached_vs_detached();
    long_paths();
    glossy_closed_box();
    tiny_emitter();
    dark_texels();
    spotted_parts();
    cutouts();
    dark_sky();
    scales();
    return TEST_END();
}
