/* The film (issue 14): pixel filters by filter importance sampling and crop
 * windows.
 *   - step edge: an emitter's vertical edge at a known film position; each
 *     column's value must be the filter's integral over the lit side
 *     (box: the covered fraction, tent: its quadratic CDF, gaussian: Phi);
 *   - gaussian vs brute force: a gaussian-filtered render equals the
 *     numerical convolution of a high-resolution box render;
 *   - crop: a cropped render, a cropped forward derivative and a cropped
 *     reverse-mode gradient equal the same rectangle of the full frame, bit
 *     for bit;
 *   - filter names: parse and format. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "film.h"
#include "camera.h"
#include "path.h"
#include "sampler.h"
#include "render.h"
#include "scene_builder.h"
#include "test.h"

static struct dr_material emitter(dr_vec3 Le)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = Le;
    m.double_sided = true;
    return m;
}

/* ---- step edge ---- */

/* Fraction of the filter (in x) left of offset t from the pixel centre. */
static double filter_cdf(const struct dr_filter *f, double t)
{
    switch (f->kind) {
    case DR_FILTER_TENT:
        if (t <= -1.0) return 0.0;
        if (t >= 1.0) return 1.0;
        return t < 0.0 ? 0.5 * (1.0 + t) * (1.0 + t) : 1.0 - 0.5 * (1.0 - t) * (1.0 - t);
    case DR_FILTER_GAUSSIAN: return 0.5 * erfc(-t / (f->stddev * sqrt(2.0)));
    case DR_FILTER_BOX:
    default: return t <= -0.5 ? 0.0 : t >= 0.5 ? 1.0 : t + 0.5;
    }
}

/* An 8x2 film looking at the plane z = -1, which spans x in [-1, 1]: film x
 * = 4 (1 + world x). Emitter (radiance 1) left of world x = 0.075, i.e. film
 * x = 4.3; nothing else. */
static void step_edge(void)
{
    const int W = 8, H = 2, spp = 65536;
    const double edge = 4.3;
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-50, -50, -1), dr_v3(50 + (edge / 4.0 - 1.0), 0, 0), dr_v3(0, 100, 0),
            sb_material(&b, emitter(dr_v3s(1.0))));
    struct dr_scene *s = sb_finish(&b);
    struct dr_camera cam = sb_camera(dr_v3(0, 0, 0), dr_v3(0, 0, -1), 2.0 * atan(0.25) * 180.0 / M_PI);
    const struct dr_filter filters[] = {{DR_FILTER_BOX, 0}, {DR_FILTER_TENT, 0}, {DR_FILTER_GAUSSIAN, 0.5},
                                        {DR_FILTER_GAUSSIAN, 1.3}};
    float rgb[8 * 2 * 3];
    for (size_t k = 0; k < sizeof filters / sizeof filters[0]; k++) {
        struct dr_render_opts ro = {.width = W, .height = H, .spp = spp, .max_depth = 1, .rr_depth = 5, .seed = 3,
                                    .threads = 2, .film = {.filter = filters[k]}};
        CHECK(dr_render(s, &cam, &ro, rgb, NULL) == 0, "render: %s", dr_last_error());
        char name[32];
        dr_filter_format(&filters[k], name, sizeof name);
        for (int x = 0; x < W; x++) {
            double want = filter_cdf(&filters[k], edge - (x + 0.5));
            double got = 0.5 * (rgb[3 * x] + rgb[3 * (W + x)]);
            double sd = sqrt(want * (1.0 - want) / (2.0 * spp));
            printf("%-12s column %d: %.5f (filter integral %.5f)\n", name, x, got, want);
            CHECK(fabs(got - want) <= 5.0 * sd + 1e-4, "%s: column %d is %.5f, the filter's integral %.5f", name, x,
                  got, want);
        }
    }
    dr_scene_destroy(s);
}

/* ---- gaussian vs brute-force convolution ---- */

/* Emissive shapes with slanted edges on black: a piecewise-constant image,
 * sharp at every scale. The film spans [-1, 1]^2 of the plane z = -1. */
static struct dr_scene *shapes_scene(void)
{
    struct sb b;
    sb_init(&b);
    int m0 = sb_material(&b, emitter(dr_v3(1.0, 0.5, 0.25))), m1 = sb_material(&b, emitter(dr_v3(0.2, 0.9, 0.4)));
    uint32_t a = sb_vertex(&b, dr_v3(-0.6, -0.7, -1), 0, 0), c = sb_vertex(&b, dr_v3(0.7, -0.3, -1), 0, 0),
             d = sb_vertex(&b, dr_v3(-0.2, 0.8, -1), 0, 0);
    sb_triangle(&b, a, c, d, m0);
    sb_quad(&b, dr_v3(0.1, 0.15, -0.99), dr_v3(0.6, 0.1, 0), dr_v3(-0.15, 0.5, 0), m1);
    return sb_finish(&b);
}

static void gaussian_vs_convolution(void)
{
    const int N = 16, S = 8, HN = N * S;
    const double sigma = 0.7;
    struct dr_scene *s = shapes_scene();
    struct dr_camera cam = sb_camera(dr_v3(0, 0, 0), dr_v3(0, 0, -1), 90.0);
    float *lo = malloc(sizeof(float) * 3 * N * N), *hi = malloc(sizeof(float) * 3 * HN * HN);
    struct dr_render_opts ro = {.width = N, .height = N, .spp = 16384, .max_depth = 1, .rr_depth = 5, .seed = 5,
                                .threads = 2, .film = {.filter = {DR_FILTER_GAUSSIAN, sigma}}};
    CHECK(dr_render(s, &cam, &ro, lo, NULL) == 0, "render: %s", dr_last_error());
    struct dr_render_opts rh = {.width = HN, .height = HN, .spp = 64, .max_depth = 1, .rr_depth = 5, .seed = 6,
                                .threads = 2};
    CHECK(dr_render(s, &cam, &rh, hi, NULL) == 0, "render: %s", dr_last_error());
    /* pixels whose filter reaches past the frame by less than 3 sigma */
    const int border = (int)ceil(3.0 * sigma);
    double worst = 0.0, rms = 0.0, box_gap = 0.0;
    int n = 0;
    for (int y = border; y < N - border; y++)
        for (int x = border; x < N - border; x++)
            for (int ch = 0; ch < 3; ch++) {
                double conv = 0.0, wsum = 0.0, box = 0.0;
                for (int j = 0; j < HN; j++)
                    for (int i = 0; i < HN; i++) {
                        double dx = (i + 0.5) / S - (x + 0.5), dy = (j + 0.5) / S - (y + 0.5);
                        double w = exp(-(dx * dx + dy * dy) / (2 * sigma * sigma)) / (2 * M_PI * sigma * sigma * S * S);
                        conv += w * hi[3 * (j * HN + i) + ch];
                        wsum += w;
                        if (i / S == x && j / S == y)
                            box += hi[3 * (j * HN + i) + ch] / (S * S);
                    }
                double got = lo[3 * (y * N + x) + ch], d = fabs(got - conv);
                CHECK(fabs(wsum - 1.0) < 2e-3, "the convolution's weights sum to %.5f", wsum);
                CHECK(d < 0.02, "pixel (%d, %d) channel %d: gaussian render %.4f vs convolution %.4f", x, y, ch, got,
                      conv);
                worst = fmax(worst, d);
                rms += d * d;
                box_gap = fmax(box_gap, fabs(box - conv));
                n++;
            }
    rms = sqrt(rms / n);
    printf("gaussian %.2f px vs brute-force convolution of a %dx box render: max |diff| %.4f, rms %.4f "
           "(box-filtered pixels differ from it by up to %.3f)\n", sigma, S, worst, rms, box_gap);
    CHECK(rms < 0.004, "rms difference %.4f", rms);
    /* the comparison can tell filters apart: a box render would fail it */
    CHECK(box_gap > 0.1, "box and gaussian pixels should differ on this image (%.3f)", box_gap);
    free(lo);
    free(hi);
    dr_scene_destroy(s);
}

/* ---- crop ---- */

/* The rectangle (x0, y0, w, h) of a W-wide image of doubles or floats. */
static bool same_rect_f(const float *full, int W, const float *crop, int x0, int y0, int w, int h)
{
    for (int y = 0; y < h; y++)
        if (memcmp(full + 3 * ((size_t)(y0 + y) * W + x0), crop + 3 * (size_t)y * w, sizeof(float) * 3 * w) != 0)
            return false;
    return true;
}

static bool same_rect_d(const double *full, int W, const double *crop, int x0, int y0, int w, int h)
{
    for (int y = 0; y < h; y++)
        if (memcmp(full + 3 * ((size_t)(y0 + y) * W + x0), crop + 3 * (size_t)y * w, sizeof(double) * 3 * w) != 0)
            return false;
    return true;
}

static void crop_bit_identical(void)
{
    const int W = 23, H = 17, x0 = 5, y0 = 3, w = 11, h = 9;
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, emitter(dr_v3(3, 2, 1))));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50);
    float full[23 * 17 * 3], crop[11 * 9 * 3];
    const struct dr_filter filters[] = {{DR_FILTER_BOX, 0}, {DR_FILTER_GAUSSIAN, 0.5}};
    for (int k = 0; k < 2; k++) {
        struct dr_film film = {.filter = filters[k], .frame_w = W, .frame_h = H, .x0 = x0, .y0 = y0};
        struct dr_render_opts ro = {.width = W, .height = H, .spp = 8, .max_depth = 4, .rr_depth = 3, .seed = 9,
                                    .threads = 2, .film = {.filter = filters[k]}};
        CHECK(dr_render(s, &cam, &ro, full, NULL) == 0, "%s", dr_last_error());
        ro.width = w;
        ro.height = h;
        ro.threads = 1;   /* another thread count too: nothing may depend on it */
        ro.film = film;
        CHECK(dr_render(s, &cam, &ro, crop, NULL) == 0, "%s", dr_last_error());
        CHECK(same_rect_f(full, W, crop, x0, y0, w, h), "cropped render differs from the full render's rectangle");
        /* estimators: forward d image and reverse gradient with a crop-sized adjoint */
        const char *ptr = "/materials/0/pbrMetallicRoughness/baseColorFactor";
        struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
        double dir[3] = {1, 1, 1}, dfull[23 * 17 * 3], dcrop[11 * 9 * 3];
        for (int e = 0; dr_estimators[e]; e++) {
            struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = W, .height = H, .spp = 4,
                                        .max_depth = 4, .rr_depth = 3, .seed = 2, .threads = 2,
                                        .film = {.filter = filters[k]}};
            CHECK(dr_estimator_forward(dr_estimators[e], &p, dir, dfull, NULL) == 0, "%s", dr_last_error());
            struct dr_grad_problem pc = p;
            pc.width = w;
            pc.height = h;
            pc.film = film;
            CHECK(dr_estimator_forward(dr_estimators[e], &pc, dir, dcrop, NULL) == 0, "%s", dr_last_error());
            CHECK(same_rect_d(dfull, W, dcrop, x0, y0, w, h), "%s: cropped d image differs", dr_estimators[e]->name);
            /* reverse: an adjoint that is zero outside the rectangle gives the crop's gradient */
            float afull[23 * 17 * 3] = {0}, acrop[11 * 9 * 3];
            for (int i = 0; i < w * h * 3; i++) {
                acrop[i] = (float)(0.01 * ((i * 7) % 13 - 6));
                int px = i / 3 % w, py = i / 3 / w;
                afull[3 * ((y0 + py) * W + x0 + px) + i % 3] = acrop[i];
            }
            double gfull[3], gcrop[3];
            p.threads = pc.threads = 1;   /* the same summation order */
            CHECK(dr_estimator_backward(dr_estimators[e], &p, afull, gfull, NULL) == 0, "%s", dr_last_error());
            CHECK(dr_estimator_backward(dr_estimators[e], &pc, acrop, gcrop, NULL) == 0, "%s", dr_last_error());
            for (int c = 0; c < 3; c++)
                CHECK_NEAR(gcrop[c], gfull[c], 1e-12 * fabs(gfull[c]) + 1e-300, "cropped reverse gradient");
            CHECK(gfull[0] != 0.0, "the reverse gradient should not be zero");
        }
        dr_param_set_destroy(ps);
    }
    /* a rectangle outside the frame is refused, not rendered */
    struct dr_render_opts bad = {.width = w, .height = h, .spp = 1, .max_depth = 1, .rr_depth = 1, .seed = 0,
                                 .threads = 1, .film = {.frame_w = W, .frame_h = H, .x0 = W - w + 1, .y0 = 0}};
    CHECK(dr_render(s, &cam, &bad, crop, NULL) == DR_ERR_ARG, "a crop past the frame's edge must be refused");
    dr_scene_destroy(s);
}

/* ---- render's starts against the one-path walker's ---- */

/* Pixel `local` of a render as the one-path walker makes it: each sample's
 * sampler, camera draw, film position and ray from the scalar functions
 * (start_sample's), its radiance from dr_path_radiance, the mean in sample
 * order (store_pixel's). */
static void one_path_pixel(const struct dr_scene *s, const struct dr_camera *cam, const struct dr_render_opts *ro,
                           int64_t local, float out[3])
{
    const struct dr_camera_view view =
        dr_camera_view(cam, dr_film_frame_w(&ro->film, ro->width), dr_film_frame_h(&ro->film, ro->height));
    const struct dr_path_opts po = {.max_depth = ro->max_depth, .rr_depth = ro->rr_depth,
                                    .stages = dr_path_plan(s, NULL)};
    int fx, fy;
    const uint64_t pixel = dr_film_pixel(&ro->film, ro->width, local, &fx, &fy);
    dr_vec3 sum = dr_v3s(0.0);
    for (int k = 0; k < ro->spp; k++) {
        struct dr_sampler smp;
        dr_sampler_init_kind(&smp, ro->sampler, ro->seed, pixel, (uint64_t)k, ro->spp);
        double u, v, px, py;
        dr_sampler_next2(&smp, &u, &v);
        dr_film_sample(&ro->film.filter, fx, fy, u, v, &px, &py);
        dr_vec3 o, d;
        dr_camera_ray(&view, px, py, &o, &d);
        struct dr_ray_counts counts = {0};
        dr_vec3 L = dr_path_radiance(s, &po, o, d, &smp, &counts);
        if (dr_v3_finite(L))
            sum = dr_add(sum, L);
    }
    out[0] = (float)(sum.x / ro->spp), out[1] = (float)(sum.y / ro->spp), out[2] = (float)(sum.z / ro->spp);
}

/* render starts its paths eight at a time in vector form (the packet
 * renderer's samplers, camera draws, film positions and rays): every pixel
 * must be the one-path walker's from the scalar start, for each sampler and
 * filter, a perspective and an orthographic camera, a crop, and spp that
 * make groups of eight straddle pixels. */
static void render_equals_one_path(void)
{
    const int W = 13, H = 9;
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_quad(&b, dr_v3(-0.5, 1.5, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, emitter(dr_v3(3, 2, 1))));
    sb_quad(&b, dr_v3(-0.4, 0, -0.4), dr_v3(0.8, 0, 0), dr_v3(0, 0.7, 0), sb_material(&b, sb_diffuse(dr_v3s(0.7))));
    struct dr_scene *s = sb_finish(&b);
    struct dr_camera persp = sb_camera(dr_v3(0, 1, 2), dr_v3(0, 0, 0), 50), ortho = persp;
    ortho.orthographic = true;
    ortho.ymag = 1.5;
    const struct dr_camera *cams[] = {&persp, &ortho};
    CHECK(dr_scene_add_viewpoint(s, &persp) == 0 && dr_scene_add_viewpoint(s, &ortho) == 0, "viewpoints: %s",
          dr_last_error());
    const enum dr_sampler_kind kinds[] = {DR_SAMPLER_INDEPENDENT, DR_SAMPLER_SOBOL, DR_SAMPLER_STRATIFIED};
    const struct dr_filter filters[] = {{DR_FILTER_BOX, 0}, {DR_FILTER_TENT, 0}, {DR_FILTER_GAUSSIAN, 0.7}};
    const int spps[] = {5, 16};
    float rgb[13 * 9 * 3], want[3];
    int bad = 0, pixels = 0;
    for (int c = 0; c < 2; c++)
        for (int k = 0; k < 3; k++)
            for (int f = 0; f < 3; f++)
                for (int n = 0; n < 2; n++) {
                    struct dr_render_opts ro = {.width = W, .height = H, .spp = spps[n], .max_depth = 4,
                                                .rr_depth = 3, .seed = 11, .threads = 2, .sampler = kinds[k],
                                                .film = {.filter = filters[f]}};
                    if (n == 1)   /* a crop of a larger frame: frame pixels key the numbers */
                        ro.film.frame_w = 29, ro.film.frame_h = 21, ro.film.x0 = 7, ro.film.y0 = 5;
                    CHECK(dr_render(s, cams[c], &ro, rgb, NULL) == 0, "render: %s", dr_last_error());
                    for (int64_t i = 0; i < (int64_t)W * H; i++, pixels++) {
                        one_path_pixel(s, cams[c], &ro, i, want);
                        bad += memcmp(want, rgb + 3 * i, sizeof want) != 0;
                    }
                }
    CHECK(bad == 0, "%d of %d rendered pixels differ from the one-path walker's", bad, pixels);
    CHECK(pixels == 36 * W * H, "pixels compared: %d", pixels);
    dr_scene_destroy(s);
}

static void filter_names(void)
{
    struct dr_filter f;
    char buf[32];
    CHECK(dr_filter_parse("box", &f) == 0 && f.kind == DR_FILTER_BOX, "box");
    CHECK(dr_filter_parse("tent", &f) == 0 && f.kind == DR_FILTER_TENT, "tent");
    CHECK(dr_filter_parse("gaussian", &f) == 0 && f.kind == DR_FILTER_GAUSSIAN && f.stddev == 0.5, "gaussian");
    CHECK(dr_filter_parse("gaussian:1.25", &f) == 0 && f.stddev == 1.25, "gaussian:1.25");
    dr_filter_format(&f, buf, sizeof buf);
    CHECK(strcmp(buf, "gaussian:1.25") == 0, "format: %s", buf);
    const char *bad[] = {"gauss", "gaussian:", "gaussian:0", "gaussian:-1", "gaussian:x", "gaussian:1e9", "tent:1",
                         "", "Box"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        CHECK(dr_filter_parse(bad[i], &f) == DR_ERR_ARG, "'%s' should be refused", bad[i]);
}

int main(void)
{
    filter_names();
    step_edge();
    gaussian_vs_convolution();
    crop_bit_identical();
    render_equals_one_path();
    return TEST_END();
}
