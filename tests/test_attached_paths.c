/* Attached sampling, path by path: with the random numbers fixed, one path's
 * estimate L(theta) is a smooth function of the parameter wherever no
 * discrete event flips (which light, lobe, Russian roulette, an occluder or
 * an emitter's edge crossed). So the gradient an estimator reports for a
 * 1x1 image at 1 spp must equal the central difference of that one path's
 * radiance (walked in double with the same sampler), except for the few
 * paths a flip makes non-smooth. The surfaces here are metals (lobe
 * probability 1) or Lambertian (0): elsewhere the attached estimator holds
 * the lobe probability at its primal value (path.h), an unbiased choice
 * whose single paths differ from the primal's by design (fdcheck covers
 * those materials in expectation). Scenes: a glossy floor under an area light
 * and a point light, seen directly and via a tilted, smooth-shaded,
 * textured glossy panel (so hit points, shading normals, uv, NEE geometry
 * and emission MIS all move); the same surfaces under a constant sky
 * (whose density moves with the escaping direction); and a near-specular
 * metal under an environment map. Both modes (reverse, forward) are checked, and prb with
 * the exact inverse Jacobian (--regularize 0) must give tape's number to
 * rounding on every path where the Jacobians are invertible. */
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "error.h"
#include "estimator.h"
#include "scene_builder.h"
#include "test.h"

/* The path of (seed, pixel 0, sample 0) of a 1x1 image: its radiance summed
 * over the channels (what the estimator differentiates with adjoint ones). */
static double path_value(const struct dr_scene *s, const struct dr_camera *cam, uint64_t seed, int max_depth)
{
    struct dr_camera_view view = dr_camera_view(cam, 1, 1);
    struct dr_sampler smp;
    dr_sampler_init(&smp, seed, 0, 0);
    double jx = dr_sampler_next(&smp), jy = dr_sampler_next(&smp);
    struct dr_path_opts po = {.max_depth = max_depth, .rr_depth = DR_RR_DEPTH_DEFAULT,
                              .stages = dr_path_plan(s, NULL), .params = NULL};
    struct dr_ray_counts rc = {0};
    dr_vec3 o, d;
    dr_camera_ray(&view, jx, jy, &o, &d);
    dr_vec3 L = dr_path_radiance(s, &po, o, d, &smp, &rc);
    return L.x + L.y + L.z;
}

static double fd_of_path(struct dr_scene *s, const struct dr_camera *cam, const struct dr_param_set *ps,
                         int64_t slot, uint64_t seed, int max_depth, double h)
{
    double *th = malloc(sizeof(double) * (size_t)ps->total);
    dr_param_set_get(s, ps, th);
    double t0 = th[slot];
    th[slot] = t0 + h;
    dr_param_set_put(s, ps, th);
    dr_scene_refresh(s);
    double jp = path_value(s, cam, seed, max_depth);
    th[slot] = t0 - h;
    dr_param_set_put(s, ps, th);
    dr_scene_refresh(s);
    double jm = path_value(s, cam, seed, max_depth);
    th[slot] = t0;
    dr_param_set_put(s, ps, th);
    dr_scene_refresh(s);
    free(th);
    return (jp - jm) / (2.0 * h);
}

/* Runs `paths` single-path problems; returns how many agreed (relative 1e-4). */
static void check_paths(const char *what, struct dr_scene *s, const struct dr_camera *cam, const char *ptr,
                        int paths, int max_depth, double h, double min_agree)
{
    s->n_file_materials = s->n_materials;
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "%s: %s", what, dr_last_error());
    if (!ps)
        return;
    const struct dr_estimator_ops *tape = dr_estimator_find("tape");
    float adj[3] = {1.0f, 1.0f, 1.0f};
    int agree = 0, nonzero = 0, finite = 1, prb_agree = 0, linear = 0;
    double worst_ok = 0.0;
    for (int i = 0; i < paths; i++) {
        struct dr_grad_problem p = {.scene = s, .camera = cam, .params = ps, .width = 1, .height = 1, .spp = 1,
                                    .max_depth = max_depth, .rr_depth = DR_RR_DEPTH_DEFAULT,
                                    .seed = (uint64_t)i, .threads = 1, .sampling = DR_SAMPLING_ATTACHED};
        double g = 0.0, dir = 1.0, dimg[3];
        int rc = dr_estimator_backward(tape, &p, adj, &g, NULL);
        rc |= dr_estimator_forward(tape, &p, &dir, dimg, NULL);
        CHECK(rc == 0, "%s: %s", what, dr_last_error());
        double fwd = dimg[0] + dimg[1] + dimg[2];
        /* reverse mode is linear in the adjoint, whatever its signs: an
         * adjoint of mixed signs (as an L2 loss gives, pixels above and below
         * their targets) against the forward mode's channels */
        float mixed[3] = {0.75f, -1.0f, 0.5f};   /* (exact in float) */
        double gm = 0.0;
        rc = dr_estimator_backward(tape, &p, mixed, &gm, NULL);
        double fm = 0.75 * dimg[0] - 1.0 * dimg[1] + 0.5 * dimg[2];
        linear += rc == 0 && fabs(gm - fm) <= 1e-9 * (fabs(gm) + fabs(fm) + 1e-9);
        /* prb, exact inverse (--regularize 0): the same number to rounding where M is invertible */
        double gp = 0.0, dimgp[3];
        p.regularize = 0.0;
        rc = dr_estimator_backward(dr_estimator_find("prb"), &p, adj, &gp, NULL);
        rc |= dr_estimator_forward(dr_estimator_find("prb"), &p, &dir, dimgp, NULL);
        CHECK(rc == 0, "%s: prb: %s", what, dr_last_error());
        double fwdp = dimgp[0] + dimgp[1] + dimgp[2];
        finite &= isfinite(gp) && isfinite(fwdp);
        if (fabs(gp - g) <= 1e-9 * (fabs(g) + 1e-6) && fabs(fwdp - g) <= 1e-9 * (fabs(g) + 1e-6))
            prb_agree++;
        else if (getenv("DR_TEST_VERBOSE"))
            printf("  %s seed %d: tape %.12g prb %.12g prb fwd %.12g\n", what, i, g, gp, fwdp);
        double fd = fd_of_path(s, cam, ps, 0, (uint64_t)i, max_depth, h);
        finite &= isfinite(g) && isfinite(fwd);
        double tol = 1e-4 * (fabs(fd) + fabs(g)) + 1e-9;
        if (fabs(fd) > 1e-9)
            nonzero++;
        if (fabs(g - fd) <= tol && fabs(fwd - g) <= 1e-9 * (1.0 + fabs(g))) {
            agree++;
            worst_ok = fmax(worst_ok, fabs(g - fd) / (fabs(fd) + 1e-12));
        } else if (getenv("DR_TEST_VERBOSE")) {
            printf("  %s seed %d: reverse %.9g forward %.9g fd %.9g\n", what, i, g, fwd, fd);
        }
    }
    printf("%-28s %d of %d paths agree with their finite difference (%d depend on the parameter); prb = tape on %d\n",
           what, agree, paths, nonzero, prb_agree);
    CHECK(finite, "%s: non-finite gradient", what);
    CHECK(linear == paths, "%s: reverse mode with a mixed-sign adjoint differs from forward mode on %d of %d paths",
          what, paths - linear, paths);
    CHECK(nonzero >= paths / 3, "%s: only %d of %d paths depend on the parameter", what, nonzero, paths);
    CHECK(agree >= min_agree * paths, "%s: only %d of %d paths agree", what, agree, paths);
    CHECK(prb_agree >= min_agree * paths, "%s: prb equals tape on only %d of %d paths", what, prb_agree, paths);
    dr_param_set_destroy(ps);
}

static struct dr_material glossy_material(dr_vec3 base, double metallic, double roughness)
{
    struct dr_material m = sb_diffuse(base);
    m.metallic = metallic;
    m.roughness = roughness;
    m.specular = 1.0;
    return m;
}

/* Smooth normals on the panel (the scene's second quad: vertices 4-7,
 * triangles 2 and 3), tilted apart. */
static void tilt_panel_normals(struct dr_scene *s)
{
    for (uint32_t v = 4; v < 8; v++) {
        dr_vec3 n = dr_normalize(dr_v3(0.15 * ((v & 1) ? 1 : -1), 0.3, 1.0 + 0.1 * (v & 2)));
        s->mesh.normals[3 * v] = (float)n.x;
        s->mesh.normals[3 * v + 1] = (float)n.y;
        s->mesh.normals[3 * v + 2] = (float)n.z;
    }
    s->mesh.flags[2] |= DR_TRI_HAS_NORMALS;
    s->mesh.flags[3] |= DR_TRI_HAS_NORMALS;
}

/* A metal floor, a tilted metal panel (smooth normals, base-colour texture),
 * a Lambertian wall (its diffuse samples turn with the moving frame); an
 * area light and a point light. */
static void glossy_room(void)
{
    struct sb b;
    sb_init(&b);
    int floor = sb_material(&b, glossy_material(dr_v3(0.7, 0.5, 0.3), 1.0, 0.3));
    struct dr_material pm = glossy_material(dr_v3(0.4, 0.6, 0.8), 1.0, 0.25);
    pm.base_color_tex.texture = 0;
    int panel = sb_material(&b, pm);
    struct dr_material e = sb_diffuse(dr_v3s(0.0));
    e.emissive_factor = dr_v3(6, 5, 4);
    int light = sb_material(&b, e);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), floor);
    sb_quad(&b, dr_v3(-2, 0.2, -1.5), dr_v3(4, 0, 0), dr_v3(0, 2.5, -0.8), panel);   /* tris 2, 3 */
    sb_quad(&b, dr_v3(-0.5, 2.0, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), light);
    sb_quad(&b, dr_v3(-2.5, 0, -2), dr_v3(0, 0, 4), dr_v3(0, 3, 0), sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6))));
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3(1, 0.9, 0.8);
    l.intensity = 3;
    l.position = dr_v3(1.0, 1.5, 1.0);
    sb_light(&b, l);
    struct dr_scene *s = b.s;
    tilt_panel_normals(s);
    s->n_images = 1;
    s->images = calloc(1, sizeof(struct dr_image));
    struct dr_image *im = &s->images[0];
    im->width = im->height = 4;
    im->channels = 3;
    im->data = malloc(sizeof(float) * 48);
    im->linear = malloc(sizeof(float) * 48);
    for (int i = 0; i < 48; i++)
        im->data[i] = im->linear[i] = (float)(0.2 + 0.05 * (i % 11));
    s->n_textures = 1;
    s->textures = calloc(1, sizeof(struct dr_texture));
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0, 1.2, 2.5), dr_v3(0, 0.3, -0.5), 50);
    check_paths("glossy room, floor rough.", s, &cam, "/materials/0/pbrMetallicRoughness/roughnessFactor", 200, 4,
                1e-6, 0.95);
    check_paths("glossy room, panel rough.", s, &cam, "/materials/1/pbrMetallicRoughness/roughnessFactor", 200, 4,
                1e-6, 0.95);
    dr_scene_destroy(s);
}

/* Near-specular metal under an environment map (the hard case). */
static void near_specular(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, glossy_material(dr_v3(0.9, 0.8, 0.6), 1.0, 0.05)));
    sb_environment_ramp(&b);
    struct dr_scene *s = sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 1), dr_v3(0, 0, -1), 40);
    check_paths("env metal, roughness 0.05", s, &cam, "/materials/0/pbrMetallicRoughness/roughnessFactor", 200, 3,
                1e-7, 0.9);
    dr_scene_destroy(s);
}

/* Under a constant sky, which next-event estimation samples by lights.h's
 * dr_sky_pdf (a sharp metal's by its BSDF, a broad lobe's and a Lambertian's
 * by the cosine about the geometric normal): such a light sample moves with
 * the roughness as the continuation does, and a BSDF-sampled ray that
 * escapes has the MIS weight mis(pdf, pick dr_sky_pdf), whose density and
 * cosine move with it (path_attached.c). A metal floor (sharp, roughness
 * 0.35: the BSDF's share is 1; or broad, 0.8: 0), a tilted smooth-shaded
 * sharp metal panel and a Lambertian wall. (Shares strictly between, held
 * at their primal value like the lobe probability, make single paths
 * differ from their finite differences by design: test_fdcheck.) */
static void sky_room(double floor_roughness)
{
    struct sb b;
    sb_init(&b);
    int floor = sb_material(&b, glossy_material(dr_v3(0.7, 0.5, 0.3), 1.0, floor_roughness));
    int panel = sb_material(&b, glossy_material(dr_v3(0.4, 0.6, 0.8), 1.0, 0.2));
    int wall = sb_material(&b, sb_diffuse(dr_v3(0.8, 0.7, 0.6)));
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), floor);
    sb_quad(&b, dr_v3(-2, 0.2, -1.5), dr_v3(4, 0, 0), dr_v3(0, 2.5, -0.8), panel);   /* tris 2, 3 */
    sb_quad(&b, dr_v3(-2.5, 0, -2), dr_v3(0, 0, 4), dr_v3(0, 3, 0), wall);
    sb_environment(&b, dr_v3(0.9, 1.0, 1.2));
    tilt_panel_normals(b.s);
    sb_finish(&b);
    struct dr_scene *s = b.s;
    struct dr_camera cam = sb_camera(dr_v3(0, 1.2, 2.5), dr_v3(0, 0.3, -0.5), 50);
    char what[64];
    snprintf(what, sizeof what, "sky room, floor %.2f rough.", floor_roughness);
    check_paths(what, s, &cam, "/materials/0/pbrMetallicRoughness/roughnessFactor", 200, 4, 1e-6, 0.95);
    if (floor_roughness < 0.5)
        check_paths("sky room, panel rough.", s, &cam, "/materials/1/pbrMetallicRoughness/roughnessFactor", 200, 4,
                    1e-6, 0.95);
    dr_scene_destroy(s);
}

/* The Cornell box: diffuse walls on flat triangles make the vertex
 * Jacobians singular (a diffuse direction forgets the incoming one). With
 * the default --regularize prb recomputes the state adjoint by forward mode
 * there and equals tape on every path; inverting anyway (--regularize 0)
 * loses those components: the regularisation bias, printed. */
static void cornell_singular(void)
{
    const char *path = scene_path("cornell-box.gltf");
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return;
    const char *ptr = "/materials/rough-gold/pbrMetallicRoughness/roughnessFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    float adj[3] = {1.0f, 1.0f, 1.0f};
    const int paths = 400;
    int same = 0, same0 = 0;
    double sum_tape = 0.0, sum0 = 0.0;
    for (int i = 0; i < paths; i++) {
        struct dr_grad_problem p = {.scene = s, .camera = &s->cameras[0], .params = ps, .width = 1, .height = 1,
                                    .spp = 1, .max_depth = 8, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = (uint64_t)i,
                                    .threads = 1, .sampling = DR_SAMPLING_ATTACHED,
                                    .regularize = DR_PRB_REGULARIZE_DEFAULT};
        double gt = 0.0, gp = 0.0, g0 = 0.0;
        int rc = dr_estimator_backward(dr_estimator_find("tape"), &p, adj, &gt, NULL);
        rc |= dr_estimator_backward(dr_estimator_find("prb"), &p, adj, &gp, NULL);
        p.regularize = 0.0;
        rc |= dr_estimator_backward(dr_estimator_find("prb"), &p, adj, &g0, NULL);
        CHECK(rc == 0, "cornell: %s", dr_last_error());
        same += fabs(gp - gt) <= 1e-9 * (fabs(gt) + 1e-6);
        same0 += fabs(g0 - gt) <= 1e-9 * (fabs(gt) + 1e-6);
        sum_tape += gt;
        sum0 += g0;
    }
    printf("cornell, gold roughness: prb = tape on %d of %d paths; always inverting: %d of %d, "
           "sum %.6g vs tape %.6g (bias %.2g%%)\n",
           same, paths, same0, paths, sum0, sum_tape, 100.0 * (sum0 - sum_tape) / fabs(sum_tape));
    CHECK(same == paths, "cornell: prb equals tape on only %d of %d paths", same, paths);
    CHECK(same0 < paths, "cornell: no path had a singular Jacobian: the case tests nothing");
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* The cross primal (estimator.h, the default): prb walks the primal of a
 * group of pixels' samples in its arrays (wave_soa.h) and hands their sums
 * to the attached replays (prb.c's arrays_pixels) instead of walking each
 * path once more; the gradient and the primal image must still be the
 * tape's, which records whole paths, and the arrays must have run. */
static void cross_primal(void)
{
    struct dr_scene *s = dr_scene_load(scene_path("cornell-box.gltf"));
    CHECK(s != NULL, "load: %s", dr_last_error());
    if (!s)
        return;
    const char *ptrs[] = {"/materials/rough-gold/pbrMetallicRoughness/roughnessFactor",
                          "/materials/red/pbrMetallicRoughness/baseColorFactor"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 2);
    enum { W = 12, H = 10 };
    float target[3 * W * H];
    for (int i = 0; i < 3 * W * H; i++)
        target[i] = (float)(0.05 + 0.4 * ((i * 7) % 11) / 10.0);
    const enum dr_sampling modes[] = {DR_SAMPLING_ATTACHED, DR_SAMPLING_MIS};
    for (int m = 0; m < 2; m++) {
        double g[2][4] = {{0}}, img[2][3 * W * H];
        struct dr_grad_stats st = {0};
        for (int e = 0; e < 2; e++) {
            struct dr_cross_loss cross = {.loss = DR_LOSS_L2, .target = target, .scale = 1.0, .image = img[e]};
            struct dr_grad_problem p = {.scene = s, .camera = &s->cameras[0], .params = ps, .width = W, .height = H,
                                        .spp = 4, .max_depth = 6, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 5,
                                        .threads = 2, .sampling = modes[m], .regularize = DR_PRB_REGULARIZE_DEFAULT,
                                        .cross = &cross};
            CHECK(dr_estimator_backward(dr_estimator_find(e ? "prb" : "tape"), &p, NULL, g[e], e ? &st : NULL) == 0,
                  "cross primal: %s", dr_last_error());
        }
        double worst = 0.0, scale = 0.0, iworst = 0.0;
        for (int k = 0; k < 4; k++) {
            worst = fmax(worst, fabs(g[0][k] - g[1][k]));
            scale = fmax(scale, fabs(g[0][k]));
        }
        for (int i = 0; i < 3 * W * H; i++)
            iworst = fmax(iworst, fabs(img[0][i] - img[1][i]) / (fabs(img[0][i]) + 1e-12));
        const char *name = m ? "mis" : "attached";
        printf("cross primal, %s: prb vs tape %.3g relative (gradient %.6g ...), images %.3g; %llu vertices "
               "eight-wide in prb's primal walks\n", name, worst / scale, g[0][0], iworst,
               (unsigned long long)st.rays.simd_vertices);
        CHECK(scale > 0.0, "cross primal, %s: zero gradient", name);
        CHECK(worst <= 1e-9 * scale, "cross primal, %s: prb and tape differ by %.3g relative", name, worst / scale);
        CHECK(iworst <= 1e-12, "cross primal, %s: primal images differ by %.3g relative", name, iworst);
        CHECK(st.rays.simd_vertices > 0, "cross primal, %s: prb did not walk the primal in its arrays", name);
    }
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

int main(void)
{
    glossy_room();
    near_specular();
    sky_room(0.35);
    sky_room(0.8);
    cornell_singular();
    cross_primal();
    return TEST_END();
}
