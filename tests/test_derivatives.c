/* Tests of the reverse-mode derivatives (d_ functions) against finite
 * differences of their primal functions:
 *   a. d_bsdf_eval     vs differences of dr_bsdf_eval (base colour, metallic, roughness),
 *   b. d_texture_eval  vs differences of dr_texture_eval (every texel value),
 *   c. hard cases: d_bsdf_eval stays finite (grazing, near-specular, roughness floor).
 * Deterministic: every random number comes from fixed seeds. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bsdf.h"
#include "grad_sink.h"
#include "image.h"
#include "sampler.h"
#include "test.h"

/* ---------------------------------------------------------------- helpers */

struct rng { uint64_t s; };
static double rng_next(struct rng *r)
{
    r->s += 0x9e3779b97f4a7c15ULL;
    return (double)(dr_hash64(r->s) >> 11) * (1.0 / 9007199254740992.0);
}

static struct dr_bsdf make_bsdf(double rough, double metal, double spec, dr_vec3 base, dr_vec3 spec_col)
{
    struct dr_bsdf b = {0};
    b.base_color = base;
    b.metallic = metal;
    b.roughness = rough;
    b.specular = spec;
    b.specular_color = spec_col;
    return b;
}

static dr_vec3 dir_from(double cos_t, double phi)
{
    double s = sqrt(fmax(0.0, 1.0 - cos_t * cos_t));
    return dr_v3(s * cos(phi), s * sin(phi), cos_t);
}

static dr_vec3 reflect(dr_vec3 w, dr_vec3 n) { return dr_sub(dr_scale(n, 2.0 * dr_dot(w, n)), w); }

static bool finite3(dr_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }
static bool finite_d(const struct dr_d_bsdf *d)
{
    return finite3(d->base_color) && isfinite(d->metallic) && isfinite(d->roughness);
}

/* The five differentiable inputs, by index: base_color.x/y/z, metallic, roughness. */
enum { IN_BASE_R, IN_BASE_G, IN_BASE_B, IN_METAL, IN_ROUGH, N_IN };
static const char *const in_name[N_IN] = {"base.r", "base.g", "base.b", "metallic", "roughness"};

static double *in_ptr(struct dr_bsdf *b, int k)
{
    switch (k) {
    case IN_BASE_R: return &b->base_color.x;
    case IN_BASE_G: return &b->base_color.y;
    case IN_BASE_B: return &b->base_color.z;
    case IN_METAL:  return &b->metallic;
    default:        return &b->roughness;
    }
}
static double d_in(const struct dr_d_bsdf *d, int k)
{
    switch (k) {
    case IN_BASE_R: return d->base_color.x;
    case IN_BASE_G: return d->base_color.y;
    case IN_BASE_B: return d->base_color.z;
    case IN_METAL:  return d->metallic;
    default:        return d->roughness;
    }
}

/* loss = dot(d_out, f) as a function of input k set to x. */
static double loss_at(struct dr_bsdf b, int k, double x, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out)
{
    *in_ptr(&b, k) = x;
    return dr_dot(d_out, dr_bsdf_eval(&b, wo, wi));
}

/* Worst observed |adjoint - FD| / max(|adjoint|, |FD|) per input, counted
 * where the derivative is >= 1e6 times the rounding floor of the difference
 * (below that the relative error only measures rounding), and the worst
 * |adjoint - FD| / tolerance over all checks. */
static double worst_rel[N_IN], worst_ratio[N_IN];
static long fd_checks[N_IN], fd_one_sided[N_IN];

/* Finite difference of the loss with respect to input k, second order in h.
 * Central where the (physical) domain allows, one-sided where it ends:
 *  - base colour and metallic live in [0, 1] (glTF). The primal happens to be
 *    affine in both and would accept values outside, but the test must not
 *    depend on evaluating materials that do not exist. At metallic == 0 with
 *    specular == 0 the primal takes the Lambertian fast path at x itself and
 *    the general path at x + h: the forward difference checks that the adjoint
 *    is the general formula's derivative, as documented.
 *  - roughness: alpha = max(r^2, DR_BSDF_MIN_ALPHA) has a kink at
 *    r = sqrt(DR_BSDF_MIN_ALPHA); a central difference straddling it would
 *    average the two branches, so near the floor we difference on the side of
 *    x's own branch; roughness 1 is the top of the domain (backward).
 * One-sided second-order formulas: forward  (-3 f(x) + 4 f(x+h) - f(x+2h)) / 2h,
 *                                 backward ( 3 f(x) - 4 f(x-h) + f(x-2h)) / 2h. */
static double fd_deriv(const struct dr_bsdf *b, int k, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, double *h_out)
{
    double x = *in_ptr((struct dr_bsdf *)b, k);
    double lo, hi, h;
    if (k == IN_ROUGH) {
        /* relative step: alpha's relative change stays ~2e-6 even at small roughness */
        h = 1e-6 * fmax(fabs(x), 1e-4);
        double kink = sqrt(DR_BSDF_MIN_ALPHA);
        if (x * x > DR_BSDF_MIN_ALPHA) {
            lo = kink * (1.0 + 1e-12);
            hi = 1.0;
        } else {
            lo = -kink;
            hi = kink * (1.0 - 1e-12);
        }
    } else {
        h = 1e-6 * fmax(1.0, fabs(x));
        lo = 0.0;
        hi = 1.0;
    }
    *h_out = h;
    if (x - h < lo && x + 2.0 * h <= hi) {
        fd_one_sided[k]++;
        double f0 = loss_at(*b, k, x, wo, wi, d_out);
        double f1 = loss_at(*b, k, x + h, wo, wi, d_out);
        double f2 = loss_at(*b, k, x + 2.0 * h, wo, wi, d_out);
        return (-3.0 * f0 + 4.0 * f1 - f2) / (2.0 * h);
    }
    if (x + h > hi && x - 2.0 * h >= lo) {
        fd_one_sided[k]++;
        double f0 = loss_at(*b, k, x, wo, wi, d_out);
        double f1 = loss_at(*b, k, x - h, wo, wi, d_out);
        double f2 = loss_at(*b, k, x - 2.0 * h, wo, wi, d_out);
        return (3.0 * f0 - 4.0 * f1 + f2) / (2.0 * h);
    }
    double fp = loss_at(*b, k, x + h, wo, wi, d_out);
    double fm = loss_at(*b, k, x - h, wo, wi, d_out);
    return (fp - fm) / (2.0 * h);
}

/* Compares every input's adjoint with its finite difference for one
 * (material, wo, wi, d_out). */
static void check_bsdf_point(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out)
{
    struct dr_d_bsdf d;
    memset(&d, 0, sizeof d);
    d_bsdf_eval(b, wo, wi, d_out, &d, NULL, NULL);
    CHECK(finite_d(&d), "non-finite adjoint: r %g m %g s %g", b->roughness, b->metallic, b->specular);
    dr_vec3 f = dr_bsdf_eval(b, wo, wi);
    double mag = fabs(d_out.x * f.x) + fabs(d_out.y * f.y) + fabs(d_out.z * f.z);
    for (int k = 0; k < N_IN; k++) {
        double h;
        double fd = fd_deriv(b, k, wo, wi, d_out, &h);
        double ad = d_in(&d, k);
        double scale = fmax(fabs(ad), fabs(fd));
        /* 1e-5 relative (truncation, O(h^2)) + rounding of the differences
         * (~eps |loss| / h, expressed per unit of x). */
        double floor_abs = 1e-9 * (1.0 + mag) * fmax(1.0, 1e-6 / h);
        double tol = 1e-5 * scale + floor_abs;
        fd_checks[k]++;
        if (fabs(ad - fd) / tol > worst_ratio[k])
            worst_ratio[k] = fabs(ad - fd) / tol;
        CHECK(fabs(ad - fd) <= tol,
              "d/d%s: adjoint %.12g vs FD %.12g (tol %.3g) r %g m %g s %g base (%g %g %g) "
              "wo (%g %g %g) wi (%g %g %g)",
              in_name[k], ad, fd, tol, b->roughness, b->metallic, b->specular, b->base_color.x,
              b->base_color.y, b->base_color.z, wo.x, wo.y, wo.z, wi.x, wi.y, wi.z);
        if (scale > 1e6 * floor_abs) {
            double rel = fabs(ad - fd) / scale;
            if (rel > worst_rel[k])
                worst_rel[k] = rel;
        }
    }
}

/* ------------------------------------------------------- a. d_bsdf_eval */

static dr_vec3 random_hemi(struct rng *r)
{
    /* cos theta in (0.02, 1): FD of grazing configurations is covered in c. */
    return dir_from(0.02 + 0.98 * rng_next(r), 2.0 * M_PI * rng_next(r));
}

/* A pair near the specular configuration: h within a few alpha of n. */
static bool near_specular_pair(struct rng *r, double alpha, dr_vec3 *wo, dr_vec3 *wi)
{
    *wo = random_hemi(r);
    double s = 2.0 * alpha;
    dr_vec3 h = dr_normalize(dr_v3(s * (2.0 * rng_next(r) - 1.0), s * (2.0 * rng_next(r) - 1.0), 1.0));
    *wi = reflect(*wo, h);
    return wi->z > 0.02;
}

static void test_bsdf_fd(void)
{
    static const double roughs[] = {1.0, 0.5, 0.2, 0.05, 0.01};
    static const double metals[] = {0.0, 0.3, 1.0};
    static const double specs[] = {0.0, 0.5, 1.0};
    struct rng r = {12345};
    for (size_t ir = 0; ir < sizeof roughs / sizeof *roughs; ir++)
        for (size_t im = 0; im < sizeof metals / sizeof *metals; im++)
            for (size_t is = 0; is < sizeof specs / sizeof *specs; is++)
                for (int ib = 0; ib < 5; ib++) {
                    dr_vec3 base;
                    if (ib == 0)
                        base = dr_v3s(0.0);
                    else if (ib == 1)
                        base = dr_v3s(1.0);
                    else
                        base = dr_v3(rng_next(&r), rng_next(&r), rng_next(&r));
                    dr_vec3 sc = ib == 4 ? dr_v3(0.5 + rng_next(&r), 0.5 + rng_next(&r), 0.5 + rng_next(&r))
                                         : dr_v3s(1.0);
                    struct dr_bsdf b = make_bsdf(roughs[ir], metals[im], specs[is], base, sc);
                    double alpha = fmax(roughs[ir] * roughs[ir], DR_BSDF_MIN_ALPHA);
                    for (int n = 0; n < 80; n++) {
                        dr_vec3 wo, wi;
                        if (n % 2 == 0 || !near_specular_pair(&r, alpha, &wo, &wi)) {
                            wo = random_hemi(&r);
                            wi = random_hemi(&r);
                        }
                        dr_vec3 d_out = dr_v3(2.0 * rng_next(&r) - 1.0, 2.0 * rng_next(&r) - 1.0,
                                              2.0 * rng_next(&r) - 1.0);
                        check_bsdf_point(&b, wo, wi, d_out);
                    }
                }
}

/* Roughness around the floor: just above it (one-sided forward differences,
 * the adjoint is the r^2 branch's), below it (derivative exactly 0), at 0. */
static void test_bsdf_floor(void)
{
    static const double roughs[] = {0.0011, 0.0015, 0.003, 0.0009, 0.0005, 0.0};
    struct rng r = {777};
    for (size_t ir = 0; ir < sizeof roughs / sizeof *roughs; ir++)
        for (int im = 0; im < 2; im++)
            for (int n = 0; n < 40; n++) {
                struct dr_bsdf b = make_bsdf(roughs[ir], im ? 1.0 : 0.3, 0.5,
                                             dr_v3(rng_next(&r), rng_next(&r), rng_next(&r)), dr_v3s(1.0));
                double alpha = fmax(roughs[ir] * roughs[ir], DR_BSDF_MIN_ALPHA);
                dr_vec3 wo, wi;
                if (!near_specular_pair(&r, alpha, &wo, &wi)) {
                    wo = random_hemi(&r);
                    wi = reflect(wo, dr_v3(0.0, 0.0, 1.0));
                }
                dr_vec3 d_out = dr_v3(rng_next(&r), rng_next(&r) - 0.5, rng_next(&r));
                check_bsdf_point(&b, wo, wi, d_out);
                if (roughs[ir] * roughs[ir] <= DR_BSDF_MIN_ALPHA) {
                    struct dr_d_bsdf d = {0};
                    d_bsdf_eval(&b, wo, wi, d_out, &d, NULL, NULL);
                    CHECK(d.roughness == 0.0, "below the floor: d roughness %g at r %g", d.roughness,
                          roughs[ir]);
                }
            }
}

/* The adjoint accumulates: a second call adds the same amount again. */
static void test_bsdf_accumulates(void)
{
    struct rng r = {99};
    for (int n = 0; n < 50; n++) {
        struct dr_bsdf b = make_bsdf(0.05 + rng_next(&r), n % 3 == 0 ? 0.0 : rng_next(&r), n % 5 == 0 ? 0.0 : 0.5,
                                     dr_v3(rng_next(&r), rng_next(&r), rng_next(&r)), dr_v3s(1.0));
        dr_vec3 wo = random_hemi(&r), wi = random_hemi(&r);
        dr_vec3 d_out = dr_v3(rng_next(&r), rng_next(&r), rng_next(&r));
        struct dr_d_bsdf d1 = {0}, d2 = {dr_v3(1.0, 2.0, 3.0), 4.0, 5.0, 6.0, 7.0, 0.0, dr_v3s(0.0), 0.0};
        d_bsdf_eval(&b, wo, wi, d_out, &d1, NULL, NULL);
        d_bsdf_eval(&b, wo, wi, d_out, &d2, NULL, NULL);
        d_bsdf_eval(&b, wo, wi, d_out, &d2, NULL, NULL);
        double want[N_IN] = {1.0, 2.0, 3.0, 4.0, 5.0};
        for (int k = 0; k < N_IN; k++) {
            double one = d_in(&d1, k), two = d_in(&d2, k) - want[k];
            CHECK_NEAR(two, 2.0 * one, 1e-12 * (1.0 + fabs(one)) + 1e-12 * want[k], in_name[k]);
        }
    }
    /* Below the surface: f = 0 by construction, *d is untouched. */
    struct dr_bsdf b = make_bsdf(0.5, 0.5, 0.5, dr_v3s(0.5), dr_v3s(1.0));
    struct dr_d_bsdf d = {dr_v3(1.0, 2.0, 3.0), 4.0, 5.0, 6.0, 7.0, 0.0, dr_v3s(0.0), 0.0};
    d_bsdf_eval(&b, dr_v3(0.0, 0.6, -0.8), dr_v3(0.0, 0.0, 1.0), dr_v3s(1.0), &d, NULL, NULL);
    d_bsdf_eval(&b, dr_v3(0.0, 0.0, 1.0), dr_v3(0.6, 0.0, -0.8), dr_v3s(1.0), &d, NULL, NULL);
    d_bsdf_eval(&b, dr_v3(1.0, 0.0, 0.0), dr_v3(0.0, 0.0, 1.0), dr_v3s(1.0), &d, NULL, NULL);
    CHECK(d.base_color.x == 1.0 && d.base_color.y == 2.0 && d.base_color.z == 3.0 && d.metallic == 4.0 &&
              d.roughness == 5.0,
          "below the surface the adjoint must not change");
}

/* ---------------------------------------------------- b. d_texture_eval */

static void check_texture(struct dr_image *img, enum dr_wrap ws, enum dr_wrap wt, double u, double v,
                          struct rng *r)
{
    struct dr_texture tex = {0, ws, wt};
    size_t n = (size_t)img->width * (size_t)img->height * (size_t)img->channels;
    double *dt = calloc(n, sizeof *dt);
    double d_out[4];
    for (int c = 0; c < 4; c++)
        d_out[c] = 2.0 * rng_next(r) - 1.0;
    d_texture_eval(&tex, img, u, v, d_out, 0, &(struct dr_grad_sink){.grad = dt});
    /* Texel values are multiples of 2^-8 and h = 2^-6: x +- h is exact in float,
     * and the lookup is linear in the texels, so the difference is exact up
     * to the rounding of the weighted sums. */
    const float h = 0.015625f;
    for (size_t i = 0; i < n; i++) {
        float x = img->data[i];
        double op[4], om[4];
        img->data[i] = x + h;
        dr_texture_eval(&tex, img, u, v, false, op);
        img->data[i] = x - h;
        dr_texture_eval(&tex, img, u, v, false, om);
        img->data[i] = x;
        double fd = 0.0;
        for (int c = 0; c < 4; c++)
            fd += d_out[c] * (op[c] - om[c]) / (2.0 * (double)h);
        CHECK(fabs(fd - dt[i]) <= 1e-12,
              "texture %dx%dx%d wrap %d/%d uv (%g, %g) value %zu: adjoint %.15g vs FD %.15g", img->width,
              img->height, img->channels, (int)ws, (int)wt, u, v, i, dt[i], fd);
    }
    /* accumulation */
    d_texture_eval(&tex, img, u, v, d_out, 0, &(struct dr_grad_sink){.grad = dt});
    double *d1 = calloc(n, sizeof *d1);
    d_texture_eval(&tex, img, u, v, d_out, 0, &(struct dr_grad_sink){.grad = d1});
    for (size_t i = 0; i < n; i++)
        CHECK_NEAR(dt[i], 2.0 * d1[i], 1e-14, "texture adjoint accumulates");
    free(d1);
    free(dt);
}

static void test_texture_fd(void)
{
    struct rng r = {4242};
    static const int dims[2][3] = {{3, 2, 3}, {2, 3, 4}};
    static const enum dr_wrap wraps[] = {DR_WRAP_REPEAT, DR_WRAP_CLAMP, DR_WRAP_MIRROR};
    for (int im = 0; im < 2; im++) {
        struct dr_image img;
        memset(&img, 0, sizeof img);
        img.width = dims[im][0];
        img.height = dims[im][1];
        img.channels = dims[im][2];
        size_t n = (size_t)img.width * (size_t)img.height * (size_t)img.channels;
        img.data = malloc(n * sizeof *img.data);
        for (size_t i = 0; i < n; i++)
            img.data[i] = (float)floor(rng_next(&r) * 256.0) / 256.0f;
        const double uv[][2] = {
            {0.3, 0.7},                                      /* inside */
            {0.61, 0.12},                                    /* inside, near an edge */
            {-0.4, -1.3},                                    /* negative */
            {-0.05, 0.5},                                    /* just below 0 */
            {1.7, 2.2},                                      /* > 1 */
            {3.9, 1.05},                                     /* > 1 */
            {1.5 / img.width, 0.5 / img.height},             /* texel centre */
            {0.5 / img.width, (img.height - 0.5) / img.height}, /* texel centre at the border */
            {0.0, 1.0},                                      /* the corners */
        };
        for (size_t iw = 0; iw < 3; iw++)
            for (size_t jw = 0; jw < 3; jw++)
                for (size_t k = 0; k < sizeof uv / sizeof *uv; k++)
                    check_texture(&img, wraps[iw], wraps[jw], uv[k][0], uv[k][1], &r);
        dr_image_release(&img);
    }
}

/* --------------------------------------------------------- c. hard cases */

static void test_bsdf_hard_cases(void)
{
    static const double roughs[] = {0.0, 0.0005, 0.001, 0.0011, 0.01, 0.5, 1.0};
    static const double metals[] = {0.0, 0.5, 1.0};
    static const double specs[] = {0.0, 1.0};
    static const double cosines[] = {1.0, 0.5, 1e-3, 1e-6, 1e-9, 2e-12};
    int n = 0;
    for (size_t ir = 0; ir < sizeof roughs / sizeof *roughs; ir++)
        for (size_t im = 0; im < 3; im++)
            for (size_t is = 0; is < 2; is++)
                for (int ib = 0; ib < 2; ib++) {
                    struct dr_bsdf b = make_bsdf(roughs[ir], metals[im], specs[is],
                                                 ib ? dr_v3(1.0, 0.5, 0.0) : dr_v3s(0.0), dr_v3s(1.0));
                    for (size_t ic = 0; ic < sizeof cosines / sizeof *cosines; ic++)
                        for (size_t jc = 0; jc < sizeof cosines / sizeof *cosines; jc++)
                            for (int kind = 0; kind < 3; kind++) {
                                dr_vec3 wo = dir_from(cosines[ic], 0.3);
                                dr_vec3 wi;
                                if (kind == 0)
                                    wi = reflect(wo, dr_v3(0.0, 0.0, 1.0));  /* h = n */
                                else if (kind == 1)
                                    wi = dir_from(cosines[jc], 0.3 + M_PI); /* same plane, opposite */
                                else
                                    wi = dir_from(cosines[jc], 1.9);
                                struct dr_d_bsdf d = {0};
                                d_bsdf_eval(&b, wo, wi, dr_v3(1.0, -0.5, 0.25), &d, NULL, NULL);
                                dr_vec3 f = dr_bsdf_eval(&b, wo, wi);
                                n++;
                                CHECK(finite_d(&d) && finite3(f),
                                      "hard case not finite: r %g m %g s %g wo.z %g wi.z %g kind %d: "
                                      "d (%g %g %g | %g | %g)",
                                      b.roughness, b.metallic, b.specular, wo.z, wi.z, kind, d.base_color.x,
                                      d.base_color.y, d.base_color.z, d.metallic, d.roughness);
                            }
                }
    /* Near-specular and grazing, against differences too (rel. step in r). */
    struct rng r = {31337};
    for (int k = 0; k < 200; k++) {
        double rough = k % 4 == 0 ? 0.0011 : (k % 4 == 1 ? 0.01 : (k % 4 == 2 ? 0.3 : 1.0));
        double cz = k % 2 ? 1e-6 : 1e-3;
        dr_vec3 wo = dir_from(cz, 2.0 * M_PI * rng_next(&r));
        dr_vec3 wi = k % 3 == 0 ? reflect(wo, dr_v3(0.0, 0.0, 1.0)) : random_hemi(&r);
        struct dr_bsdf b = make_bsdf(rough, k % 5 == 0 ? 1.0 : 0.4, 0.7,
                                     dr_v3(rng_next(&r), rng_next(&r), rng_next(&r)), dr_v3s(1.0));
        check_bsdf_point(&b, wo, wi, dr_v3(rng_next(&r), rng_next(&r), rng_next(&r)));
    }
    fprintf(stderr, "hard cases: %d configurations finite\n", n);
}

int main(void)
{
    test_bsdf_fd();
    test_bsdf_floor();
    test_bsdf_accumulates();
    test_texture_fd();
    test_bsdf_hard_cases();
    for (int k = 0; k < N_IN; k++)
        fprintf(stderr,
                "d_bsdf_eval d/d%-9s: %6ld FD checks (%5ld one-sided), worst rel. error %.2e, "
                "worst error/tolerance %.2f\n",
                in_name[k], fd_checks[k], fd_one_sided[k], worst_rel[k], worst_ratio[k]);
    return TEST_END();
}
