/* Tests of core/bsdf.c: sampling against the pdf (chi-square), the pdf's
 * normalisation, the pdf against the Jacobian of the sampling map,
 * reciprocity, energy conservation, the Lambertian limit and hard cases.
 * Deterministic: every random number comes from fixed seeds. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bsdf.h"
#include "lights.h"
#include "simd_trig.h"
#include "sampler.h"
#include "sheen_albedo.h"
#include "test.h"

/* ---------------------------------------------------------------- helpers */

struct rng { uint64_t s; };
static double rng_next(struct rng *r)
{
    r->s += 0x9e3779b97f4a7c15ULL;
    return (double)(dr_hash64(r->s) >> 11) * (1.0 / 9007199254740992.0);
}

static struct dr_bsdf make_bsdf(double rough, double metal, double spec, dr_vec3 base)
{
    struct dr_bsdf b = {0};
    b.base_color = base;
    b.metallic = metal;
    b.roughness = rough;
    b.specular = spec;
    b.specular_color = dr_v3s(1.0);
    return b;
}

static double test_alpha(double rough)
{
    return fmax(rough * rough, DR_BSDF_MIN_ALPHA);
}

static dr_vec3 dir_from(double cos_t, double phi)
{
    double s = sqrt(fmax(0.0, 1.0 - cos_t * cos_t));
    return dr_v3(s * cos(phi), s * sin(phi), cos_t);
}

static dr_vec3 random_hemi(struct rng *r)
{
    /* cos theta uniform in (0.02, 1): avoids the grazing limit for generic checks */
    return dir_from(0.02 + 0.98 * rng_next(r), 2.0 * M_PI * rng_next(r));
}

static bool finite3(dr_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }
static bool nonneg3(dr_vec3 v) { return v.x >= 0.0 && v.y >= 0.0 && v.z >= 0.0; }

/* Test-side GGX formulas (textbook forms, independent of core/bsdf.c). */
static double ref_lambda(double a, dr_vec3 w)
{
    double tan2 = (w.x * w.x + w.y * w.y) / (w.z * w.z);
    return (-1.0 + sqrt(1.0 + a * a * tan2)) / 2.0;
}
static double ref_D(double a, dr_vec3 h)
{
    double c2 = h.z * h.z, a2 = a * a;
    double d = c2 * (a2 - 1.0) + 1.0;
    return a2 / (M_PI * d * d);
}
/* pdf of the specular lobe alone (VNDF + reflection). */
static double ref_pdf_spec(double a, dr_vec3 wo, dr_vec3 wi)
{
    dr_vec3 h = dr_normalize(dr_add(wo, wi));
    double g1 = 1.0 / (1.0 + ref_lambda(a, wo));
    double dwo = g1 * fmax(0.0, dr_dot(wo, h)) * ref_D(a, h) / wo.z;
    return dwo / (4.0 * fabs(dr_dot(wo, h)));
}

/* Regularised upper incomplete gamma Q(a, x) (Numerical Recipes gser/gcf). */
static double gamma_q(double a, double x)
{
    if (x <= 0.0)
        return 1.0;
    double gln = lgamma(a);
    if (x < a + 1.0) {
        double ap = a, sum = 1.0 / a, del = sum;
        for (int n = 0; n < 100000; n++) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if (fabs(del) < fabs(sum) * 1e-15)
                break;
        }
        return 1.0 - sum * exp(-x + a * log(x) - gln);
    }
    const double fpmin = 1e-300;
    double bb = x + 1.0 - a, c = 1.0 / fpmin, d = 1.0 / bb, h = d;
    for (int i = 1; i < 100000; i++) {
        double an = -i * (i - a);
        bb += 2.0;
        d = an * d + bb;
        if (fabs(d) < fpmin) d = fpmin;
        c = bb + an / c;
        if (fabs(c) < fpmin) c = fpmin;
        d = 1.0 / d;
        double del = d * c;
        h *= del;
        if (fabs(del - 1.0) < 1e-15)
            break;
    }
    return exp(-x + a * log(x) - gln) * h;
}

static const double *sort_key;
static int cmp_by_key(const void *a, const void *b)
{
    double x = sort_key[*(const int *)a], y = sort_key[*(const int *)b];
    return x < y ? -1 : (x > y ? 1 : 0);
}

/* Chi-square test. Cells expecting fewer than 5 counts are pooled into one
 * cell, which also takes the next-smallest cells until it expects >= 5; cells
 * that expect nothing are in that pool too, so an observation where nothing is
 * expected weighs heavily unless the pool is large. */
static double chi2_test(const double *obs, const double *expd, int n, int *dof_out, double *chi2_out)
{
    int *idx = malloc(sizeof(int) * (size_t)n);
    for (int i = 0; i < n; i++) idx[i] = i;
    sort_key = expd;
    qsort(idx, (size_t)n, sizeof(int), cmp_by_key);
    double chi2 = 0.0, pool_o = 0.0, pool_e = 0.0;
    int cells = 0, pooled = 0;
    for (int k = 0; k < n; k++) {
        int i = idx[k];
        if (expd[i] < 5.0 || (pooled > 0 && pool_e < 5.0)) {
            pool_o += obs[i];
            pool_e += expd[i];
            pooled++;
            continue;
        }
        chi2 += dr_sqr(obs[i] - expd[i]) / expd[i];
        cells++;
    }
    if (pooled > 0) {
        chi2 += pool_e > 0.0 ? dr_sqr(pool_o - pool_e) / pool_e : (pool_o > 0.0 ? INFINITY : 0.0);
        cells++;
    }
    free(idx);
    int dof = cells - 1;
    *dof_out = dof;
    *chi2_out = chi2;
    if (!isfinite(chi2))
        return 0.0;
    return dof > 0 ? gamma_q(0.5 * dof, 0.5 * chi2) : 1.0;
}

/* ------------------------------------------------- adaptive quadrature */

typedef double (*dens_fn)(void *ctx, double x, double y);

static long quad_evals;

static double gl3_rect(dens_fn f, void *ctx, double x0, double x1, double y0, double y1)
{
    static const double nd[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};
    static const double wt[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
    double xm = 0.5 * (x0 + x1), xr = 0.5 * (x1 - x0), ym = 0.5 * (y0 + y1), yr = 0.5 * (y1 - y0);
    double s = 0.0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            s += wt[i] * wt[j] * f(ctx, xm + xr * nd[i], ym + yr * nd[j]);
    quad_evals += 9;
    return s * xr * yr;
}

#define QUAD_MIN_DEPTH 1
#define QUAD_MAX_DEPTH 8

static double adapt_rec(dens_fn f, void *ctx, double x0, double x1, double y0, double y1, double whole,
                        double tol, int depth)
{
    double xm = 0.5 * (x0 + x1), ym = 0.5 * (y0 + y1);
    double c[4] = {gl3_rect(f, ctx, x0, xm, y0, ym), gl3_rect(f, ctx, xm, x1, y0, ym),
                   gl3_rect(f, ctx, x0, xm, ym, y1), gl3_rect(f, ctx, xm, x1, ym, y1)};
    double sum = c[0] + c[1] + c[2] + c[3];
    if (depth >= QUAD_MAX_DEPTH || (depth >= QUAD_MIN_DEPTH && fabs(sum - whole) <= tol))
        return sum;
    return adapt_rec(f, ctx, x0, xm, y0, ym, c[0], 0.5 * tol, depth + 1) +
           adapt_rec(f, ctx, xm, x1, y0, ym, c[1], 0.5 * tol, depth + 1) +
           adapt_rec(f, ctx, x0, xm, ym, y1, c[2], 0.5 * tol, depth + 1) +
           adapt_rec(f, ctx, xm, x1, ym, y1, c[3], 0.5 * tol, depth + 1);
}

/* Integral of f over [x0,x1] x [y0,y1]: adaptive 3x3 Gauss-Legendre, absolute tolerance tol. */
static double integrate2d(dens_fn f, void *ctx, double x0, double x1, double y0, double y1, double tol)
{
    return adapt_rec(f, ctx, x0, x1, y0, y1, gl3_rect(f, ctx, x0, x1, y0, y1), tol, 0);
}

/* ----------------------------------------------------- chi-square cases */

/* Two binnings of the sampled directions, each with expected counts from an
 * adaptive quadrature of dr_bsdf_pdf in the binning's own coordinates:
 *  W: wi in (cos theta, phi), 10 x 20 cells over the hemisphere; used for lobes
 *     with roughness >= 0.3 (an adaptive quadrature started on a fixed grid can
 *     step over a narrower peak, which would make the expected counts wrong);
 *  H: the half vector h = normalize(wo + wi) in (u, phi_h), 20 x 20 cells, with
 *     u = 1 - sqrt(1 - t), t = tan^2 theta_h / (alpha^2 + tan^2 theta_h) the GGX
 *     slope CDF: the specular lobe spreads over all cells however small alpha is,
 *     and the density in (u, phi_h) stays bounded. With v = 1 - u:
 *       tan theta_h = alpha sqrt(1 - v^2) / v,
 *       d omega_h / du dphi = alpha^2 / (v^2 + alpha^2 (1 - v^2))^(3/2),
 *     and d omega_wi = 4 (wo.h) d omega_h. */
#define WU 10
#define WV 20
#define HU 20
#define HV 20

static int bin_w(dr_vec3 wi)
{
    double phi = atan2(wi.y, wi.x);
    if (phi < 0.0) phi += 2.0 * M_PI;
    int iu = (int)(dr_clamp(wi.z, 0.0, 1.0) * WU), iv = (int)(phi / (2.0 * M_PI) * WV);
    if (iu >= WU) iu = WU - 1;
    if (iv >= WV) iv = WV - 1;
    return iu * WV + iv;
}

static int bin_h(dr_vec3 h, double a)
{
    double sxy = h.x * h.x + h.y * h.y;
    double v = a * h.z / sqrt(sxy + a * a * h.z * h.z);
    double phi = atan2(h.y, h.x);
    if (phi < 0.0) phi += 2.0 * M_PI;
    int iu = (int)((1.0 - v) * HU), iv = (int)(phi / (2.0 * M_PI) * HV);
    if (iu >= HU) iu = HU - 1;
    if (iu < 0) iu = 0;
    if (iv >= HV) iv = HV - 1;
    return iu * HV + iv;
}

/* h at (u, phi) of the H parametrisation; *jac = d omega_h / du dphi. */
static dr_vec3 h_of_u(double a, double u, double phi, double *jac)
{
    double v = 1.0 - u, a2 = a * a;
    double q = v * v + a2 * (1.0 - v * v);
    double sq = sqrt(q);
    *jac = a2 / (q * sq);
    double st = a * sqrt(fmax(0.0, 1.0 - v * v)) / sq, ct = v / sq;
    return dr_v3(st * cos(phi), st * sin(phi), ct);
}

struct qctx {
    const struct dr_bsdf *b;
    dr_vec3 wo;
    double a;
    int mode;   /* dens_ref_vndf: 0 everywhere, 1 only where the reflection leaves the hemisphere */
};

static double dens_w(void *vc, double c, double phi)
{
    struct qctx *q = vc;
    return dr_bsdf_pdf(q->b, q->wo, dir_from(c, phi));
}

static double dens_h(void *vc, double u, double phi)
{
    struct qctx *q = vc;
    double jac;
    dr_vec3 h = h_of_u(q->a, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), q->wo);
    if (wi.z <= 0.0)
        return 0.0;
    return dr_bsdf_pdf(q->b, q->wo, wi) * 4.0 * oh * jac;
}

/* Test-side visible-normal density D_wo(h) in (u, phi) coordinates. */
static double dens_ref_vndf(void *vc, double u, double phi)
{
    struct qctx *q = vc;
    double jac;
    dr_vec3 h = h_of_u(q->a, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    if (q->mode == 1 && 2.0 * oh * h.z - q->wo.z > 0.0)
        return 0.0;
    double g1 = 1.0 / (1.0 + ref_lambda(q->a, q->wo));
    return g1 * oh * ref_D(q->a, h) / q->wo.z * jac;
}

/* Test-side single-scattering albedo density of a white metal, D G2 (wo.h) / wo.z
 * per unit h solid angle, in (u, phi) coordinates. */
static double dens_ref_albedo(void *vc, double u, double phi)
{
    struct qctx *q = vc;
    double jac;
    dr_vec3 h = h_of_u(q->a, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), q->wo);
    if (wi.z <= 0.0)
        return 0.0;
    double g2 = 1.0 / (1.0 + ref_lambda(q->a, q->wo) + ref_lambda(q->a, wi));
    return g2 * ref_D(q->a, h) * oh / q->wo.z * jac;
}

/* Test-side f cos of a white dielectric (specular 1, f0 = 0.04) per unit h solid angle. */
static double dens_ref_dielectric_albedo(void *vc, double u, double phi)
{
    struct qctx *q = vc;
    double jac;
    dr_vec3 h = h_of_u(q->a, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), q->wo);
    if (wi.z <= 0.0)
        return 0.0;
    double F = 0.04 + 0.96 * pow(1.0 - oh, 5.0);
    double Fo = 0.04 + 0.96 * pow(1.0 - q->wo.z, 5.0), Fi = 0.04 + 0.96 * pow(1.0 - wi.z, 5.0);
    double g2 = 1.0 / (1.0 + ref_lambda(q->a, q->wo) + ref_lambda(q->a, wi));
    double f = (1.0 - Fo) * (1.0 - Fi) / M_PI + F * ref_D(q->a, h) * g2 / (4.0 * q->wo.z * wi.z);
    return f * wi.z * 4.0 * oh * jac;
}

/* Integral over the whole (u, phi) square, cell by cell (H cells). */
static double integrate_h_space(dens_fn f, void *q, double *cells, double tol)
{
    double total = 0.0;
    for (int i = 0; i < HU; i++)
        for (int j = 0; j < HV; j++) {
            double v = integrate2d(f, q, (double)i / HU, (double)(i + 1) / HU, 2.0 * M_PI * j / HV,
                                   2.0 * M_PI * (j + 1) / HV, tol);
            if (cells) cells[i * HV + j] = v;
            total += v;
        }
    return total;
}

struct combo {
    const char *name;
    double rough, metal, spec;
    dr_vec3 base;
    double coat, coat_rough;   /* a clear coat (bsdf_coat.c) where coat > 0 */
    dr_vec3 sheen;             /* a sheen (bsdf_sheen.c) where sheen_rough > 0 */
    double sheen_rough;
};

static struct dr_bsdf combo_bsdf(const struct combo *c)
{
    struct dr_bsdf b = make_bsdf(c->rough, c->metal, c->spec, c->base);
    b.coated = c->coat > 0.0;
    b.coat = c->coat;
    b.coat_roughness = c->coat_rough;
    b.sheened = c->sheen_rough > 0.0;
    b.sheen_color = c->sheen;
    b.sheen_roughness = c->sheen_rough;
    return b;
}

static const struct combo combos[] = {
    {"rough1 dielectric", 1.0, 0.0, 1.0, {0.5, 0.4, 0.3}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"rough0.5 dielectric", 0.5, 0.0, 1.0, {0.6, 0.5, 0.2}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"rough0.2 metal", 0.2, 1.0, 1.0, {0.9, 0.6, 0.3}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"rough0.05 metal", 0.05, 1.0, 1.0, {0.95, 0.9, 0.8}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"rough0.3 half-metal", 0.3, 0.5, 1.0, {0.7, 0.3, 0.5}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"rough0.05 dielectric", 0.05, 0.0, 1.0, {0.2, 0.5, 0.8}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"lambertian", 0.5, 0.0, 0.0, {0.8, 0.6, 0.4}, 0.0, 0.0, {0, 0, 0}, 0.0},
    {"coat0.5/0.4 on diel0.5", 0.5, 0.0, 1.0, {0.6, 0.5, 0.2}, 0.5, 0.4, {0, 0, 0}, 0.0},
    {"coat1/0.05 on metal0.2", 0.2, 1.0, 1.0, {0.9, 0.6, 0.3}, 1.0, 0.05, {0, 0, 0}, 0.0},
    {"coat0.8/0.1 on lambert", 0.5, 0.0, 0.0, {0.8, 0.6, 0.4}, 0.8, 0.1, {0, 0, 0}, 0.0},
    /* sheens (bsdf_sheen.c) over dielectrics, metals, under a coat */
    {"sheen w/0.07 on diel0.5", 0.5, 0.0, 1.0, {0.6, 0.5, 0.2}, 0.0, 0.0, {1, 1, 1}, 0.07},
    {"sheen c/0.3 on diel0.5", 0.5, 0.0, 1.0, {0.6, 0.5, 0.2}, 0.0, 0.0, {0.9, 0.3, 0.5}, 0.3},
    {"sheen w/0.8 on metal0.2", 0.2, 1.0, 1.0, {0.9, 0.6, 0.3}, 0.0, 0.0, {1, 1, 1}, 0.8},
    {"sheen c/1 on lambert", 0.5, 0.0, 0.0, {0.8, 0.6, 0.4}, 0.0, 0.0, {0.2, 0.7, 0.4}, 1.0},
    {"sheen 0/0.3 on metal0.05", 0.05, 1.0, 1.0, {0.95, 0.9, 0.8}, 0.0, 0.0, {0, 0, 0}, 0.3},
    {"coat+sheen w/0.3 diel", 0.5, 0.0, 1.0, {0.6, 0.5, 0.2}, 0.5, 0.4, {1, 1, 1}, 0.3},
    {"coat+sheen c/0.07 metal", 0.2, 1.0, 1.0, {0.9, 0.6, 0.3}, 1.0, 0.05, {0.5, 0.8, 0.3}, 0.07},
};
#define NCOMBOS ((int)(sizeof(combos) / sizeof(combos[0])))

static double min_pvalue = 1.0;

static void chi2_case(const struct combo *c, double cos_o, long nsamples, int seed)
{
    struct dr_bsdf b = combo_bsdf(c);
    dr_vec3 wo = dir_from(cos_o, 0.7);
    double a = test_alpha(c->rough);
    double p = dr_bsdf_specular_prob(&b, wo);
    bool use_w = c->rough >= 0.3 && (c->coat == 0.0 || c->coat_rough >= 0.3);
    static double ew[WU * WV], ow[WU * WV], eh[HU * HV], oh[HU * HV];
    memset(ow, 0, sizeof(ow));
    memset(oh, 0, sizeof(oh));
    struct qctx q = {&b, wo, a, 0};

    /* expected counts */
    double int_w = 0.0;
    if (use_w)
        for (int i = 0; i < WU; i++)
            for (int j = 0; j < WV; j++) {
                double v = integrate2d(dens_w, &q, (double)i / WU, (double)(i + 1) / WU, 2.0 * M_PI * j / WV,
                                       2.0 * M_PI * (j + 1) / WV, 1e-6);
                ew[i * WV + j] = v * (double)nsamples;
                int_w += v;
            }
    double int_h = integrate_h_space(dens_h, &q, eh, 1e-6);
    for (int i = 0; i < HU * HV; i++) eh[i] *= (double)nsamples;
    /* test-side: the visible normals integrate to 1; the part reflected below the horizon */
    double vndf_total = integrate_h_space(dens_ref_vndf, &q, NULL, 1e-6);
    q.mode = 1;
    double fail_ref = integrate_h_space(dens_ref_vndf, &q, NULL, 1e-6);

    /* samples */
    struct rng r = {(uint64_t)seed * 7919u + 17u};
    long fails = 0;
    for (long s = 0; s < nsamples; s++) {
        struct dr_bsdf_sample bs;
        double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
        if (!dr_bsdf_sample(&b, wo, ul, u1, u2, &bs)) {
            fails++;
            continue;
        }
        ow[bin_w(bs.wi)] += 1.0;
        oh[bin_h(dr_normalize(dr_add(wo, bs.wi)), a)] += 1.0;
    }

    int dof_w = 0, dof_h;
    double chi_w = 0.0, chi_h, pw = 1.0;
    if (use_w)
        pw = chi2_test(ow, ew, WU * WV, &dof_w, &chi_w);
    double ph = chi2_test(oh, eh, HU * HV, &dof_h, &chi_h);
    double expect_integral = 1.0 - p * fail_ref;
    if (c->coat > 0.0) {   /* the coat's lobe (test-side weight c Fc(wo.z)) fails where its own VNDF leaves */
        struct dr_bsdf base = b;
        base.coated = false;
        const double pc = c->coat * (0.04 + 0.96 * pow(1.0 - cos_o, 5.0));
        struct qctx qc = {&b, wo, test_alpha(c->coat_rough), 1};
        const double fail_coat = integrate_h_space(dens_ref_vndf, &qc, NULL, 1e-6);
        expect_integral = 1.0 - pc * fail_coat - (1.0 - pc) * dr_bsdf_specular_prob(&base, wo) * fail_ref;
    }
    double fail_frac = (double)fails / (double)nsamples;
    if (use_w)
        printf("  %-21s wo.z=%.1f p_spec=%.4f | W: chi2=%6.1f dof=%3d p=%.4f | H: chi2=%6.1f dof=%3d p=%.4f"
               " | int pdf: W %.5f H %.5f ref %.5f | fail %.5f\n",
               c->name, cos_o, p, chi_w, dof_w, pw, chi_h, dof_h, ph, int_w, int_h, expect_integral, fail_frac);
    else
        printf("  %-21s wo.z=%.1f p_spec=%.4f | W: (lobe too narrow)        | H: chi2=%6.1f dof=%3d p=%.4f"
               " | int pdf: W    -    H %.5f ref %.5f | fail %.5f\n",
               c->name, cos_o, p, chi_h, dof_h, ph, int_h, expect_integral, fail_frac);
    min_pvalue = fmin(min_pvalue, fmin(pw, ph));
    CHECK(pw > 0.001, "%s wo.z=%g: chi-square (wi cells) p-value %g", c->name, cos_o, pw);
    CHECK(ph > 0.001, "%s wo.z=%g: chi-square (half-vector cells) p-value %g", c->name, cos_o, ph);
    /* normalisation: the pdf integrates to 1 minus the probability that a
     * specular sample leaves the hemisphere (test-side VNDF quadrature) */
    CHECK(fabs(int_h - expect_integral) < 2e-3, "%s wo.z=%g: integral of pdf over h %.6f, expected %.6f",
          c->name, cos_o, int_h, expect_integral);
    if (use_w)
        CHECK(fabs(int_w - expect_integral) < 2e-3, "%s wo.z=%g: integral of pdf over wi %.6f, expected %.6f",
              c->name, cos_o, int_w, expect_integral);
    CHECK(int_h <= 1.0 + 1e-3, "%s wo.z=%g: integral of pdf %.6f > 1", c->name, cos_o, int_h);
    CHECK(fabs(vndf_total - 1.0) < 1e-3, "%s wo.z=%g: VNDF integral %.6f", c->name, cos_o, vndf_total);
    double pf = 1.0 - int_h;
    double sd = sqrt(fmax(pf * (1.0 - pf), 1e-12) / (double)nsamples);
    CHECK(fabs(fail_frac - pf) < 5.0 * sd + 1e-4, "%s wo.z=%g: failed samples %.5f, expected %.5f", c->name,
          cos_o, fail_frac, pf);
}

static void test_chi2(void)
{
    printf("chi-square goodness of fit (dr_bsdf_sample vs dr_bsdf_pdf), 400k samples per case:\n");
    const double coss[] = {0.9, 0.5, 0.1};
    int seed = 1;
    quad_evals = 0;
    for (int c = 0; c < NCOMBOS; c++)
        for (int k = 0; k < 3; k++)
            chi2_case(&combos[c], coss[k], 400000, seed++);
    printf("  smallest p-value %.4f; quadrature evaluations %ld\n", min_pvalue, quad_evals);
}

/* --------------------------------------------------------- Jacobian test */

static dr_vec3 sample_map(const struct dr_bsdf *b, dr_vec3 wo, double ul, double u1, double u2, bool *ok)
{
    struct dr_bsdf_sample s;
    *ok = dr_bsdf_sample(b, wo, ul, u1, u2, &s) && *ok;
    return s.wi;
}

/* 1 / |d wi/du1 x d wi/du2|: the solid-angle density of the map (u1, u2) -> wi. */
static double map_density(const struct dr_bsdf *b, dr_vec3 wo, double ul, double u1, double u2, bool *ok)
{
    const double e = 1e-6;
    dr_vec3 a1 = sample_map(b, wo, ul, u1 + e, u2, ok), b1 = sample_map(b, wo, ul, u1 - e, u2, ok);
    dr_vec3 a2 = sample_map(b, wo, ul, u1, u2 + e, ok), b2 = sample_map(b, wo, ul, u1, u2 - e, ok);
    dr_vec3 d1 = dr_scale(dr_sub(a1, b1), 0.5 / e), d2 = dr_scale(dr_sub(a2, b2), 0.5 / e);
    return 1.0 / dr_length(dr_cross(d1, d2));
}

static void test_jacobian(void)
{
    const double us[][2] = {{0.13, 0.37}, {0.5, 0.71}, {0.82, 0.23}, {0.31, 0.9}, {0.66, 0.05}, {0.05, 0.55}};
    const double coss[] = {0.95, 0.6, 0.2};
    const double roughs[] = {1.0, 0.5, 0.2, 0.05};
    int checked = 0;
    double worst = 0.0;
    for (int k = 0; k < 3; k++) {
        dr_vec3 wo = dir_from(coss[k], 2.1);
        /* specular lobe alone: metallic 1 gives p = 1, so dr_bsdf_pdf is the lobe pdf */
        for (int r = 0; r < 4; r++) {
            struct dr_bsdf b = make_bsdf(roughs[r], 1.0, 1.0, dr_v3(0.8, 0.7, 0.6));
            CHECK(dr_bsdf_specular_prob(&b, wo) == 1.0, "metal: specular prob must be 1");
            for (int i = 0; i < 6; i++) {
                bool ok = true;
                double dens = map_density(&b, wo, 0.5, us[i][0], us[i][1], &ok);
                if (!ok)
                    continue;   /* the sample (or a neighbour) left the hemisphere */
                struct dr_bsdf_sample s;
                dr_bsdf_sample(&b, wo, 0.5, us[i][0], us[i][1], &s);
                double pdf = dr_bsdf_pdf(&b, wo, s.wi);
                double rel = fabs(dens / pdf - 1.0);
                worst = fmax(worst, rel);
                checked++;
                CHECK(rel < 1e-4, "specular Jacobian: rough %g wo.z %g u (%g,%g): map %.9g pdf %.9g",
                      roughs[r], coss[k], us[i][0], us[i][1], dens, pdf);
                CHECK(s.pdf == pdf, "sample pdf %.17g != dr_bsdf_pdf %.17g", s.pdf, pdf);
            }
        }
        /* diffuse lobe alone: Lambertian, p = 0 */
        struct dr_bsdf lam = make_bsdf(0.5, 0.0, 0.0, dr_v3(0.8, 0.7, 0.6));
        for (int i = 0; i < 6; i++) {
            bool ok = true;
            double dens = map_density(&lam, wo, 0.5, us[i][0], us[i][1], &ok);
            struct dr_bsdf_sample s;
            dr_bsdf_sample(&lam, wo, 0.5, us[i][0], us[i][1], &s);
            double pdf = dr_bsdf_pdf(&lam, wo, s.wi);
            double rel = fabs(dens / pdf - 1.0);
            worst = fmax(worst, rel);
            checked++;
            CHECK(ok && rel < 1e-4, "diffuse Jacobian: wo.z %g u (%g,%g): map %.9g pdf %.9g", coss[k],
                  us[i][0], us[i][1], dens, pdf);
        }
        /* mixture: each lobe's map against the test-side component formula,
         * and dr_bsdf_pdf against (1-p) cos/pi + p pdf_spec */
        for (int r = 0; r < 4; r++) {
            struct dr_bsdf b = make_bsdf(roughs[r], 0.4, 0.8, dr_v3(0.5, 0.6, 0.7));
            double p = dr_bsdf_specular_prob(&b, wo), a = test_alpha(roughs[r]);
            CHECK(p > 0.0 && p < 1.0, "mixture: specular prob %g", p);
            for (int i = 0; i < 6; i++) {
                bool ok = true;
                double dens_s = map_density(&b, wo, 0.0, us[i][0], us[i][1], &ok);
                if (ok) {
                    struct dr_bsdf_sample s;
                    dr_bsdf_sample(&b, wo, 0.0, us[i][0], us[i][1], &s);
                    double ps = ref_pdf_spec(a, wo, s.wi);
                    double rel = fabs(dens_s / ps - 1.0);
                    worst = fmax(worst, rel);
                    checked++;
                    CHECK(rel < 1e-4, "mixture specular map: rough %g: %.9g vs %.9g", roughs[r], dens_s, ps);
                    double mix = (1.0 - p) * s.wi.z / M_PI + p * ps;
                    CHECK(fabs(s.pdf / mix - 1.0) < 1e-9, "mixture pdf %.12g vs %.12g", s.pdf, mix);
                }
                ok = true;
                double dens_d = map_density(&b, wo, 1.0 - 1e-12, us[i][0], us[i][1], &ok);
                struct dr_bsdf_sample s;
                dr_bsdf_sample(&b, wo, 1.0 - 1e-12, us[i][0], us[i][1], &s);
                double rel = fabs(dens_d / (s.wi.z / M_PI) - 1.0);
                worst = fmax(worst, rel);
                checked++;
                CHECK(ok && rel < 1e-4, "mixture diffuse map: %.9g vs %.9g", dens_d, s.wi.z / M_PI);
                double mix = (1.0 - p) * s.wi.z / M_PI + p * ref_pdf_spec(a, wo, s.wi);
                CHECK(fabs(s.pdf / mix - 1.0) < 1e-9, "mixture pdf (diffuse sample) %.12g vs %.12g", s.pdf, mix);
            }
        }
    }
    printf("Jacobian of the sampling map vs pdf: %d points, worst relative error %.2e\n", checked, worst);
}

/* ------------------------------------------------------------ reciprocity */

static void test_reciprocity(void)
{
    struct rng r = {12345};
    double worst = 0.0;
    for (int c = 0; c < NCOMBOS; c++) {
        struct dr_bsdf b = combo_bsdf(&combos[c]);
        for (int i = 0; i < 2000; i++) {
            dr_vec3 wo = random_hemi(&r), wi = random_hemi(&r);
            dr_vec3 f1 = dr_bsdf_eval(&b, wo, wi), f2 = dr_bsdf_eval(&b, wi, wo);
            double scale = fmax(dr_max3(f1), 1e-300);
            double rel = fmax(fabs(f1.x - f2.x), fmax(fabs(f1.y - f2.y), fabs(f1.z - f2.z))) / scale;
            worst = fmax(worst, rel);
            CHECK(rel <= 1e-12, "reciprocity %s: rel %g", combos[c].name, rel);
        }
    }
    printf("reciprocity: worst relative difference %.2e\n", worst);
}

/* ------------------------------------------------------------ energy */


static void test_energy(void)
{
    const double roughs[] = {0.05, 0.2, 0.5, 1.0};
    const double coss[] = {0.9, 0.5, 0.1};
    printf("white metal directional albedo (importance sampled, 200k samples):\n");
    for (int ri = 0; ri < 4; ri++) {
        struct dr_bsdf b = make_bsdf(roughs[ri], 1.0, 1.0, dr_v3s(1.0));
        printf("  rough %.2f:", roughs[ri]);
        for (int k = 0; k < 3; k++) {
            dr_vec3 wo = dir_from(coss[k], 0.3);
            struct rng r = {(uint64_t)(1000 + 10 * ri + k)};
            const long n = 200000;
            double sum = 0.0, sum2 = 0.0;
            for (long s = 0; s < n; s++) {
                struct dr_bsdf_sample bs;
                double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
                double w = 0.0;
                if (dr_bsdf_sample(&b, wo, ul, u1, u2, &bs))
                    w = bs.f.x * bs.wi.z / bs.pdf;
                sum += w;
                sum2 += w * w;
            }
            double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
            printf("  wo.z=%.1f: %.4f +- %.4f", coss[k], mean, se);
            CHECK(mean <= 1.0 + 3.0 * se, "white metal rough %g wo.z %g: albedo %.5f +- %.5f", roughs[ri],
                  coss[k], mean, se);
            /* independent value: test-side quadrature of D G2 (wo.h) / wo.z over the half vectors */
            struct qctx q = {&b, wo, test_alpha(roughs[ri]), 0};
            double ref = integrate_h_space(dens_ref_albedo, &q, NULL, 1e-7);
            printf(" (quad %.4f)", ref);
            CHECK(fabs(mean - ref) < 4.0 * se + 1e-3, "white metal rough %g wo.z %g: albedo %.5f +- %.5f, quadrature %.5f",
                  roughs[ri], coss[k], mean, se, ref);
        }
        printf("\n");
    }
    /* White dielectric (specular 1, specular colour 1): the estimate matches an
     * independent quadrature of the model and never exceeds 1 (glTF's reference
     * 1 - F(wo.h) diffuse weight reached 1.5 at wo.z = 0.1, roughness 0.05). */
    printf("white dielectric directional albedo (importance sampled, 200k samples):\n");
    for (int ri = 0; ri < 4; ri++) {
        struct dr_bsdf b = make_bsdf(roughs[ri], 0.0, 1.0, dr_v3s(1.0));
        printf("  rough %.2f:", roughs[ri]);
        for (int k = 0; k < 3; k++) {
            dr_vec3 wo = dir_from(coss[k], 0.3);
            struct rng r = {(uint64_t)(2000 + 10 * ri + k)};
            const long n = 200000;
            double sum = 0.0, sum2 = 0.0;
            for (long s = 0; s < n; s++) {
                struct dr_bsdf_sample bs;
                double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
                double w = 0.0;
                if (dr_bsdf_sample(&b, wo, ul, u1, u2, &bs))
                    w = bs.f.x * bs.wi.z / bs.pdf;
                sum += w;
                sum2 += w * w;
            }
            double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
            struct qctx q = {&b, wo, test_alpha(roughs[ri]), 0};
            double ref = integrate_h_space(dens_ref_dielectric_albedo, &q, NULL, 1e-7);
            printf("  wo.z=%.1f: %.4f +- %.4f (quad %.4f)", coss[k], mean, se, ref);
            CHECK(fabs(mean - ref) < 4.0 * se + 1e-3, "white dielectric rough %g wo.z %g: albedo %.5f +- %.5f, quadrature %.5f",
                  roughs[ri], coss[k], mean, se, ref);
            CHECK(ref <= 1.0 && mean <= 1.0 + 4.0 * se, "white dielectric rough %g wo.z %g creates energy: albedo %.5f, quadrature %.5f",
                  roughs[ri], coss[k], mean, ref);
        }
        printf("\n");
    }
    /* A white dielectric under a full clear coat keeps its albedo <= 1 (the
     * coat lets through what it does not reflect, on the way in and out) */
    printf("white dielectric under a clear coat, directional albedo (200k samples):\n");
    for (int ri = 0; ri < 4; ri++)
        for (int cr = 0; cr < 2; cr++) {
            struct dr_bsdf b = make_bsdf(roughs[ri], 0.0, 1.0, dr_v3s(1.0));
            b.coated = true;
            b.coat = 1.0;
            b.coat_roughness = cr ? 0.3 : 0.05;
            printf("  rough %.2f coat %.2f:", roughs[ri], b.coat_roughness);
            for (int k = 0; k < 3; k++) {
                dr_vec3 wo = dir_from(coss[k], 0.3);
                struct rng r = {(uint64_t)(3000 + 10 * ri + 5 * cr + k)};
                const long n = 200000;
                double sum = 0.0, sum2 = 0.0;
                for (long s = 0; s < n; s++) {
                    struct dr_bsdf_sample bs;
                    double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
                    double w = dr_bsdf_sample(&b, wo, ul, u1, u2, &bs) ? bs.f.x * bs.wi.z / bs.pdf : 0.0;
                    CHECK(isfinite(w) && w >= 0.0, "coated sample weight %g", w);
                    sum += w;
                    sum2 += w * w;
                }
                double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
                printf("  wo.z=%.1f: %.4f +- %.4f", coss[k], mean, se);
                CHECK(mean <= 1.0 + 4.0 * se, "coated white dielectric rough %g coat %g wo.z %g creates energy: %.5f +- %.5f",
                      roughs[ri], b.coat_roughness, coss[k], mean, se);
            }
            printf("\n");
        }
    /* white Lambertian: every sample weight is exactly 1 */
    struct dr_bsdf lam = make_bsdf(0.5, 0.0, 0.0, dr_v3s(1.0));
    struct rng r = {99};
    double worst = 0.0;
    for (int s = 0; s < 100000; s++) {
        dr_vec3 wo = random_hemi(&r);
        struct dr_bsdf_sample bs;
        double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
        if (!dr_bsdf_sample(&lam, wo, ul, u1, u2, &bs))
            continue;   /* only wi.z <= 1e-12, probability ~1e-24 */
        worst = fmax(worst, fabs(bs.f.x * bs.wi.z / bs.pdf - 1.0));
    }
    printf("white Lambertian: worst |weight - 1| = %.2e\n", worst);
    CHECK(worst <= 1e-12, "white Lambertian sample weight off by %g", worst);
}

/* ------------------------------------------------------------ Lambertian */

static void test_lambertian(void)
{
    dr_vec3 base = dr_v3(0.8, 0.35, 0.05);
    const double roughs[] = {0.0, 0.001, 0.5, 1.0};
    struct rng r = {4242};
    for (int ri = 0; ri < 4; ri++) {
        struct dr_bsdf b = make_bsdf(roughs[ri], 0.0, 0.0, base);
        b.specular_color = dr_v3(3.0, 2.0, 1.0);   /* irrelevant when specular = 0 */
        for (int i = 0; i < 2000; i++) {
            dr_vec3 wo = random_hemi(&r), wi = random_hemi(&r);
            dr_vec3 f = dr_bsdf_eval(&b, wo, wi);
            CHECK(f.x == base.x * DR_INV_PI && f.y == base.y * DR_INV_PI && f.z == base.z * DR_INV_PI,
                  "Lambertian eval (%.17g %.17g %.17g) != base/pi", f.x, f.y, f.z);
            double pdf;
            dr_vec3 f2 = dr_bsdf_eval_pdf(&b, wo, wi, &pdf);
            CHECK(f2.x == f.x && f2.y == f.y && f2.z == f.z, "eval_pdf f differs from eval");
            CHECK(fabs(pdf - wi.z / M_PI) <= 1e-15 * pdf, "Lambertian pdf %.17g vs cos/pi %.17g", pdf, wi.z / M_PI);
            CHECK(dr_bsdf_specular_prob(&b, wo) == 0.0, "Lambertian specular prob must be exactly 0");
            struct dr_bsdf_sample s;
            /* u_lobe close to 1 must still pick the diffuse lobe */
            double ul = (i & 1) ? 1.0 - 1e-16 : rng_next(&r);
            bool ok = dr_bsdf_sample(&b, wo, ul, rng_next(&r), rng_next(&r), &s);
            CHECK(ok, "Lambertian sample failed");
            if (ok) {
                CHECK(fabs(s.f.x * s.wi.z / s.pdf - base.x) <= 1e-12 * base.x &&
                      fabs(s.f.y * s.wi.z / s.pdf - base.y) <= 1e-12 * base.y &&
                      fabs(s.f.z * s.wi.z / s.pdf - base.z) <= 1e-12 * base.z,
                      "Lambertian sample weight != base");
                CHECK(fabs(dr_length(s.wi) - 1.0) < 1e-12, "cosine sample not unit: %.17g", dr_length(s.wi));
            }
        }
    }
}

/* The cosine sampler's direction against the concentric map written out
 * with libm's cos and sin (bsdf.c evaluates the disk angle's sine and cosine
 * by a series of its own): within a few ulps everywhere, including both of
 * the map's halves, their shared diagonals and the disk's edge. A chi-square
 * test cannot see this: swapping x and y, or a small error in the series,
 * still gives a cosine distribution. */
static dr_vec3 concentric_reference(double u1, double u2)
{
    double a = 2.0 * u1 - 1.0, c = 2.0 * u2 - 1.0, r, phi;
    if (a == 0.0 && c == 0.0)
        return dr_v3(0.0, 0.0, 1.0);
    if (fabs(a) > fabs(c)) {
        r = a;
        phi = (M_PI / 4.0) * (c / a);
    } else {
        r = c;
        phi = (M_PI / 2.0) - (M_PI / 4.0) * (a / c);
    }
    double x = r * cos(phi), y = r * sin(phi);
    return dr_v3(x, y, sqrt(dr_max(0.0, 1.0 - x * x - y * y)));
}

static void test_cosine_sampler_map(void)
{
    struct dr_bsdf b = make_bsdf(1.0, 0.0, 0.0, dr_v3s(0.5));
    dr_vec3 wo = dr_v3(0.0, 0.0, 1.0);
    struct rng r = {777};
    double worst = 0.0;
    const double edges[] = {0.0, 1e-9, 0.25, 0.5, 0.75, 1.0 - 1e-16, 1.0};
    for (int i = 0; i < 200049; i++) {
        double u1, u2;
        if (i < 49) {
            u1 = edges[i % 7];
            u2 = edges[i / 7];
        } else if (i % 3 == 0) {   /* on a diagonal |a| = |c|, where the halves meet */
            u1 = rng_next(&r);
            u2 = (i & 2) ? u1 : 1.0 - u1;
        } else {
            u1 = rng_next(&r);
            u2 = rng_next(&r);
        }
        dr_vec3 got = dr_bsdf_sample_dir(&b, wo, DR_BSDF_LOBE_DIFFUSE, u1, u2);
        dr_vec3 want = concentric_reference(u1, u2);
        double err = fmax(fabs(got.x - want.x), fmax(fabs(got.y - want.y), fabs(got.z - want.z)));
        worst = fmax(worst, err);
    }
    /* x, y within [-1, 1]: 1e-15 is about 4 ulps at 1; z = sqrt(1 - x^2 - y^2)
     * amplifies near the disk's edge, where x^2 + y^2 -> 1, hence the looser 1e-7
     * there (z itself is ~1e-8 at the edge samples) */
    CHECK(worst < 1e-7, "cosine sampler differs from the libm concentric map by %.3g", worst);
    int off = 0;
    for (int i = 0; i < 100000; i++) {
        double u1 = 0.05 + 0.9 * rng_next(&r), u2 = 0.05 + 0.9 * rng_next(&r);
        dr_vec3 got = dr_bsdf_sample_dir(&b, wo, DR_BSDF_LOBE_DIFFUSE, u1, u2);
        dr_vec3 want = concentric_reference(u1, u2);
        off += fabs(got.x - want.x) > 1e-15 || fabs(got.y - want.y) > 1e-15 || fabs(got.z - want.z) > 1e-14;
    }
    CHECK(off == 0, "%d of 100000 interior cosine samples differ from the libm map by more than a few ulps", off);
}

/* dr_sincos_turn, the azimuth of the GGX and environment samplers, against
 * sin and cos of 2 pi u in long double (x87: 64-bit significands, so the
 * reference's own error is far below a double's ulp) and against libm of
 * the double angle, which the samplers used before. */
static void test_sincos_turn(void)
{
    struct rng r = {4242};
    double worst = 0.0, worst_libm = 0.0, worst_unit = 0.0;
    for (int i = 0; i < 1000000; i++) {
        double u = i < 4096 ? i / 4096.0 : rng_next(&r);
        if (i % 7 == 3)
            u -= 0.5;   /* half a turn either way (the environment's azimuth) */
        if (i % 5 == 1)
            u = nextafter(u, 2.0);   /* just past a grid point */
        double s, c;
        dr_sincos_turn(u, &s, &c);
        long double a = 2.0L * 3.14159265358979323846264338327950288L * (long double)u;
        worst = fmax(worst, fmax(fabs((double)((long double)s - sinl(a))), fabs((double)((long double)c - cosl(a)))));
        double phi = 2.0 * M_PI * u;
        worst_libm = fmax(worst_libm, fmax(fabs(s - sin(phi)), fabs(c - cos(phi))));
        worst_unit = fmax(worst_unit, fabs(s * s + c * c - 1.0));
    }
    /* 2.3e-16 is about two ulps of a value near 1 */
    CHECK(worst <= 2.3e-16, "dr_sincos_turn is %.3g from sin, cos of 2 pi u", worst);
    /* libm's error is the rounding of phi = 2 pi u, up to 2 pi u ulps */
    CHECK(worst_libm <= 1e-15, "dr_sincos_turn is %.3g from libm's sin, cos of the double angle", worst_libm);
    CHECK(worst_unit <= 4.5e-16, "s^2 + c^2 - 1 up to %.3g", worst_unit);
    /* the quarter turns exactly, their signs by quadrant */
    const double qu[] = {0.0, 0.25, 0.5, 0.75, 1.0}, qs[] = {0.0, 1.0, 0.0, -1.0, 0.0}, qc[] = {1.0, 0.0, -1.0, 0.0, 1.0};
    for (int k = 0; k < 5; k++) {
        double s, c;
        dr_sincos_turn(qu[k], &s, &c);
        CHECK(s == qs[k] && c == qc[k], "u = %g: sin %.17g cos %.17g", qu[k], s, c);
    }
    const double eighth[] = {0.125, 0.375, 0.625, 0.875};   /* the quadrants' signs, the values equal */
    for (int k = 0; k < 4; k++) {
        double s, c;
        dr_sincos_turn(eighth[k], &s, &c);
        CHECK(fabs(fabs(s) - M_SQRT1_2) <= 2.3e-16 && fabs(fabs(c) - M_SQRT1_2) <= 2.3e-16 && (s > 0) == (k < 2) &&
                  (c > 0) == (k == 0 || k == 3),
              "u = %g: sin %.17g cos %.17g", eighth[k], s, c);
    }
    double s, c;
    dr_sincos_turn(NAN, &s, &c);
    CHECK(isnan(s) && isnan(c), "NaN turns give NaN: %g %g", s, c);
}

/* dr_f8_atan2 and dr_f8_acos (simd_trig.h), the environment map's
 * coordinates in both walkers, against their scalar twins (bit for bit)
 * and long double: 10^6 pairs of every
 * octant and scale, plus the axes, the diagonals, zeros and NaN. The error
 * bound is in ulps of the result (a few, against libm's one). */
static double ulps_off(double got, long double want)
{
    double w = (double)want;
    double ulp = nextafter(fabs(w), INFINITY) - fabs(w);
    return w == 0.0 ? (got == 0.0 ? 0.0 : INFINITY) : (double)fabsl((long double)got - want) / ulp;
}

static void test_atan2_acos(void)
{
    struct rng r = {777};
    double worst_atan2 = 0.0, worst_acos = 0.0;
    long twins_differ = 0;
    enum { N = 1000000 };
    for (int i = 0; i < N; i += DR_SIMD_W) {
        dr_f8 y, x, c;
        for (int l = 0; l < DR_SIMD_W; l++) {
            double scale = ldexp(1.0, (int)(rng_next(&r) * 40.0) - 20);
            y[l] = (2.0 * rng_next(&r) - 1.0) * scale;
            x[l] = (2.0 * rng_next(&r) - 1.0) * (i % 3 ? 1.0 : scale);
            if (i % 11 == 0)
                x[l] = y[l] * (1.0 + ldexp(rng_next(&r) - 0.5, -(int)(rng_next(&r) * 50.0)));   /* near the diagonal */
            c[l] = 2.0 * rng_next(&r) - 1.0;
            if (i % 5 == 0)
                c[l] = copysign(1.0 - ldexp(rng_next(&r), -(int)(rng_next(&r) * 52.0)), c[l]);   /* near the poles */
        }
        dr_f8 a = dr_f8_atan2(y, x), ac = dr_f8_acos(c);
        for (int l = 0; l < DR_SIMD_W; l++) {
            /* the scalar twins: the same bits */
            double as = dr_atan2(y[l], x[l]), acs = dr_acos(c[l]);
            const double al = a[l], acl = ac[l];   /* (clang takes no address of a vector's element) */
            twins_differ += memcmp(&as, &al, sizeof as) != 0 || memcmp(&acs, &acl, sizeof acs) != 0;
            worst_atan2 = fmax(worst_atan2, ulps_off(a[l], atan2l(y[l], x[l])));
            worst_acos = fmax(worst_acos, ulps_off(ac[l], acosl(c[l])));
        }
    }
    printf("dr_f8_atan2: worst %.3g ulp, dr_f8_acos %.3g ulp\n", worst_atan2, worst_acos);
    CHECK(twins_differ == 0, "dr_atan2/dr_acos differ from their eight-lane twins in %ld of %d values",
          twins_differ, N);
    CHECK(worst_atan2 <= 3.0, "dr_f8_atan2 is %.3g ulp from atan2", worst_atan2);
    CHECK(worst_acos <= 4.0, "dr_f8_acos is %.3g ulp from acos", worst_acos);
    /* the axes and diagonals exactly where libm is exact or correctly rounded */
    const dr_f8 ys = {0.0, 1.0, 0.0, -1.0, 1.0, 1.0, -1.0, -1.0}, xs = {1.0, 0.0, -1.0, 0.0, 1.0, -1.0, -1.0, 1.0};
    dr_f8 a = dr_f8_atan2(ys, xs);
    for (int l = 0; l < DR_SIMD_W; l++)
        CHECK(a[l] == atan2(ys[l], xs[l]), "atan2(%g, %g) = %.17g, libm %.17g", ys[l], xs[l], a[l],
              atan2(ys[l], xs[l]));
    const dr_f8 cs = {1.0, -1.0, 0.0, 0.5, -0.5, 1.0, 1.0, 1.0};
    dr_f8 ac = dr_f8_acos(cs);
    CHECK(ac[0] == 0.0 && ac[1] == M_PI && ac[2] == M_PI / 2.0, "acos(1, -1, 0) = %.17g %.17g %.17g", ac[0], ac[1],
          ac[2]);
    /* zeros give 0 (no division by zero), NaN gives NaN */
    a = dr_f8_atan2((dr_f8){0.0, -0.0, NAN, 1.0, NAN, 0, 0, 0}, (dr_f8){0.0, 0.0, 1.0, NAN, NAN, 0, 0, 0});
    CHECK(a[0] == 0.0 && a[1] == 0.0 && isnan(a[2]) && isnan(a[3]) && isnan(a[4]),
          "atan2 of zeros and NaN: %g %g %g %g %g", a[0], a[1], a[2], a[3], a[4]);
    CHECK(dr_atan2(0.0, 0.0) == 0.0 && dr_atan2(-0.0, -0.0) == 0.0 && isnan(dr_atan2(NAN, 1.0)) &&
              isnan(dr_acos(NAN)),
          "the scalar twin on zeros and NaN");
    /* the map's coordinates: lane 0 of the eight-lane mapping, within 1e-15 of libm's */
    double worst_uv = 0.0;
    for (int i = 0; i < 100000; i++) {
        double z = 2.0 * rng_next(&r) - 1.0, ph = 2.0 * M_PI * rng_next(&r), rr = sqrt(1.0 - z * z);
        dr_vec3 d = dr_v3(rr * cos(ph), z, rr * sin(ph));
        double u, v;
        dr_env_dir_to_uv(d, &u, &v);
        double ul = 0.5 + atan2(d.x, -d.z) * (0.5 / M_PI), vl = acos(d.y) / M_PI;
        worst_uv = fmax(worst_uv, fmax(fabs(u - ul), fabs(v - vl)));
    }
    CHECK(worst_uv <= 1e-15, "dr_env_dir_to_uv is %.3g from libm's coordinates", worst_uv);
}

/* ------------------------------------------------------------ hard cases */

static void check_pair(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, const char *what)
{
    double pdf = -1.0;
    dr_vec3 f = dr_bsdf_eval_pdf(b, wo, wi, &pdf);
    dr_vec3 fe = dr_bsdf_eval(b, wo, wi);
    double pp = dr_bsdf_pdf(b, wo, wi);
    double ps = dr_bsdf_specular_prob(b, wo);
    CHECK(finite3(f) && nonneg3(f) && isfinite(pdf) && pdf >= 0.0, "%s: f (%g %g %g) pdf %g", what, f.x, f.y,
          f.z, pdf);
    CHECK(fe.x == f.x && fe.y == f.y && fe.z == f.z, "%s: eval differs from eval_pdf", what);
    CHECK(pp == pdf, "%s: pdf %.17g differs from eval_pdf %.17g", what, pp, pdf);
    CHECK(isfinite(ps) && ps >= 0.0 && ps <= 1.0, "%s: specular prob %g", what, ps);
    if (wo.z <= 0.0 || wi.z <= 0.0)
        CHECK(dr_is_black(f) && pdf == 0.0 && pp == 0.0, "%s: below the surface must give zero", what);
}

static void test_hard_cases(void)
{
    const double roughs[] = {0.0, 0.001, 0.01, 0.5, 1.0};
    const double metals[] = {0.0, 0.5, 1.0};
    const double specs[] = {0.0, 0.5, 1.0};
    const dr_vec3 bases[] = {{0, 0, 0}, {1, 1, 1}, {0.5, 0.2, 0.0}};
    const double zs[] = {1.0, 0.5, 1e-4, 1e-8, 1e-12, 1e-13, 1e-300, 0.0, -0.0, -1e-8, -0.5};
    const int nz = (int)(sizeof(zs) / sizeof(zs[0]));
    struct rng r = {777};
    for (int ri = 0; ri < 5; ri++)
        for (int mi = 0; mi < 3; mi++)
            for (int si = 0; si < 3; si++)
                for (int bi = 0; bi < 3; bi++) {
                    struct dr_bsdf b = make_bsdf(roughs[ri], metals[mi], specs[si], bases[bi]);
                    char what[160];
                    snprintf(what, sizeof what, "rough %g metal %g spec %g base %d", roughs[ri], metals[mi],
                             specs[si], bi);
                    for (int i = 0; i < nz; i++)
                        for (int j = 0; j < nz; j++) {
                            double so = sqrt(fmax(0.0, 1.0 - zs[i] * zs[i]));
                            double si2 = sqrt(fmax(0.0, 1.0 - zs[j] * zs[j]));
                            dr_vec3 wo = dr_v3(so, 0.0, zs[i]);
                            check_pair(&b, wo, dr_v3(-si2, 0.0, zs[j]), what);   /* mirror plane */
                            check_pair(&b, wo, dr_v3(si2, 0.0, zs[j]), what);    /* retro plane */
                            check_pair(&b, wo, dr_v3(0.0, si2, zs[j]), what);    /* side */
                            check_pair(&b, wo, dr_neg(wo), what);                /* wo == -wi: h undefined */
                            check_pair(&b, wo, wo, what);                        /* wo == wi */
                        }
                    /* mirror direction exactly: the peak of a near-specular lobe */
                    dr_vec3 wo = dir_from(0.3, 1.0), wm = dr_v3(-wo.x, -wo.y, wo.z);
                    check_pair(&b, wo, wm, what);
                    /* samples: finite, consistent with eval/pdf, zero when rejected */
                    for (int k = 0; k < nz; k++) {
                        dr_vec3 w = dr_v3(sqrt(fmax(0.0, 1.0 - zs[k] * zs[k])), 0.0, zs[k]);
                        const double edge[] = {0.0, 0.5, 1.0 - 1e-16};
                        for (int e = 0; e < 3 * 3 * 3 + 30; e++) {
                            double ul, u1, u2;
                            if (e < 27) {
                                ul = edge[e % 3]; u1 = edge[(e / 3) % 3]; u2 = edge[e / 9];
                            } else {
                                ul = rng_next(&r); u1 = rng_next(&r); u2 = rng_next(&r);
                            }
                            struct dr_bsdf_sample s;
                            bool ok = dr_bsdf_sample(&b, w, ul, u1, u2, &s);
                            CHECK(finite3(s.f) && isfinite(s.pdf) && finite3(s.wi), "%s: sample not finite", what);
                            if (!ok) {
                                CHECK(dr_is_black(s.f) && s.pdf == 0.0, "%s: rejected sample not zero", what);
                                continue;
                            }
                            CHECK(w.z > 0.0 && s.wi.z > 0.0 && s.pdf > 0.0 && nonneg3(s.f),
                                  "%s: accepted sample invalid (wo.z %g wi.z %g pdf %g)", what, w.z, s.wi.z, s.pdf);
                            double pdf;
                            dr_vec3 f = dr_bsdf_eval_pdf(&b, w, s.wi, &pdf);
                            CHECK(pdf == s.pdf && f.x == s.f.x && f.y == s.f.y && f.z == s.f.z,
                                  "%s: sample (f, pdf) differ from eval_pdf: pdf %.17g vs %.17g", what, s.pdf, pdf);
                        }
                    }
                }
    /* specular prob: exact 0 without a specular lobe, exact 1 without a diffuse one */
    dr_vec3 wo = dir_from(0.7, 0.0);
    struct dr_bsdf b0 = make_bsdf(0.3, 0.0, 0.0, dr_v3(0.0, 0.0, 0.0));
    CHECK(dr_bsdf_specular_prob(&b0, wo) == 0.0, "black Lambertian: p must be 0");
    struct dr_bsdf b1 = make_bsdf(0.3, 1.0, 0.0, dr_v3(0.0, 0.0, 0.0));
    CHECK(dr_bsdf_specular_prob(&b1, wo) == 1.0, "black metal: p must be 1");
    struct dr_bsdf b2 = make_bsdf(0.3, 0.0, 1.0, dr_v3(0.0, 0.0, 0.0));
    CHECK(dr_bsdf_specular_prob(&b2, wo) == 1.0, "black dielectric: p must be 1");
    /* grazing wo: the specular value stays finite and positive at 1e-8 */
    struct dr_bsdf g = make_bsdf(0.001, 1.0, 1.0, dr_v3s(1.0));
    dr_vec3 wg = dr_v3(sqrt(1.0 - 1e-16), 0.0, 1e-6);
    dr_vec3 fg = dr_bsdf_eval(&g, wg, dr_v3(-wg.x, 0.0, wg.z));
    CHECK(finite3(fg) && fg.x > 0.0, "grazing mirror value %g", fg.x);
}

/* ------------------------------------------------------------ anisotropy */

/* KHR_materials_anisotropy (bsdf.h): the base's GGX lobe with alpha_x =
 * alpha + (1 - alpha) s^2 along +x, alpha_y = alpha. Test-side textbook forms
 * (Heitz 2014), independent of core/bsdf.c. */
static void aniso_alphas(double rough, double s, double *ax, double *ay)
{
    *ay = test_alpha(rough);
    *ax = *ay + (1.0 - *ay) * s * s;
}
static double ref_D_aniso(double ax, double ay, dr_vec3 h)
{
    double k = h.x * h.x / (ax * ax) + h.y * h.y / (ay * ay) + h.z * h.z;
    return 1.0 / (M_PI * ax * ay * k * k);
}
static double ref_lambda_aniso(double ax, double ay, dr_vec3 w)
{
    double x = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / (w.z * w.z);
    return (-1.0 + sqrt(1.0 + x)) / 2.0;
}

static struct dr_bsdf make_aniso(double rough, double metal, double spec, dr_vec3 base, double s)
{
    struct dr_bsdf b = make_bsdf(rough, metal, spec, base);
    b.anisotropy = s;
    return b;
}

/* Half-vector cells of the stretched lobe: the H parametrisation above in the
 * slopes divided by (ax, ay), where the anisotropic lobe is the isotropic one
 * of alpha 1. With v = 1 - u, c = cos phi, s = sin phi,
 *   h ~ (ax sqrt(1 - v^2) c, ay sqrt(1 - v^2) s, v),
 *   Q = v^2 + (1 - v^2)(ax^2 c^2 + ay^2 s^2),  d omega_h / du dphi = ax ay / Q^(3/2)
 * (d omega = d slope^2 cos^3 theta_h, d slope^2 = ax ay t dt dphi, t = sqrt(1 - v^2) / v;
 * at ax = ay = a it is h_of_u's a^2 / q^(3/2)). */
struct actx {
    const struct dr_bsdf *b;
    dr_vec3 wo;
    double ax, ay;      /* the cells' alphas */
    double rax, ray;    /* dens_ref_vndf_aniso's lobe */
    int mode;           /* as qctx's */
};

static dr_vec3 h_of_u_aniso(double ax, double ay, double u, double phi, double *jac)
{
    double v = 1.0 - u, sv = sqrt(fmax(0.0, 1.0 - v * v)), c = cos(phi), s = sin(phi);
    double Q = v * v + (1.0 - v * v) * (ax * ax * c * c + ay * ay * s * s), sq = sqrt(Q);
    *jac = ax * ay / (Q * sq);
    return dr_v3(ax * sv * c / sq, ay * sv * s / sq, v / sq);
}

static int bin_h_aniso(dr_vec3 h, double ax, double ay)
{
    double sx = h.x / ax, sy = h.y / ay;
    double v = h.z / sqrt(sx * sx + sy * sy + h.z * h.z);
    double phi = atan2(sy, sx);
    if (phi < 0.0) phi += 2.0 * M_PI;
    int iu = (int)((1.0 - v) * HU), iv = (int)(phi / (2.0 * M_PI) * HV);
    iu = iu < 0 ? 0 : iu >= HU ? HU - 1 : iu;
    iv = iv < 0 ? 0 : iv >= HV ? HV - 1 : iv;
    return iu * HV + iv;
}

static double dens_h_aniso(void *vc, double u, double phi)
{
    struct actx *q = vc;
    double jac;
    dr_vec3 h = h_of_u_aniso(q->ax, q->ay, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), q->wo);
    if (wi.z <= 0.0)
        return 0.0;
    return dr_bsdf_pdf(q->b, q->wo, wi) * 4.0 * oh * jac;
}

/* Test-side visible normals of the lobe (rax, ray), G1(wo) (wo.h) D(h) / wo.z;
 * mode 1: only where the reflection leaves the hemisphere. */
static double dens_ref_vndf_aniso(void *vc, double u, double phi)
{
    struct actx *q = vc;
    double jac;
    dr_vec3 h = h_of_u_aniso(q->ax, q->ay, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    if (q->mode == 1 && 2.0 * oh * h.z - q->wo.z > 0.0)
        return 0.0;
    double g1 = 1.0 / (1.0 + ref_lambda_aniso(q->rax, q->ray, q->wo));
    return g1 * oh * ref_D_aniso(q->rax, q->ray, h) / q->wo.z * jac;
}

struct acombo {
    const char *name;
    double rough, metal, s;
    double coat, coat_rough;
};

static const struct acombo acombos[] = {
    {"metal r0.05 s1", 0.05, 1.0, 1.0, 0.0, 0.0},
    {"metal r0.3 s0.8", 0.3, 1.0, 0.8, 0.0, 0.0},
    {"metal r0.7 s0.3", 0.7, 1.0, 0.3, 0.0, 0.0},
    {"diel r0.05 s0.8", 0.05, 0.0, 0.8, 0.0, 0.0},
    {"diel r0.3 s1", 0.3, 0.0, 1.0, 0.0, 0.0},
    {"diel r0.7 s0.3", 0.7, 0.0, 0.3, 0.0, 0.0},
    {"coat0.7/0.3 metal r0.3 s0.8", 0.3, 1.0, 0.8, 0.7, 0.3},
};
#define NACOMBOS ((int)(sizeof(acombos) / sizeof(acombos[0])))

static struct dr_bsdf acombo_bsdf(const struct acombo *c)
{
    struct dr_bsdf b = make_aniso(c->rough, c->metal, 1.0, dr_v3(0.9, 0.6, 0.3), c->s);
    b.coated = c->coat > 0.0;
    b.coat = c->coat;
    b.coat_roughness = c->coat_rough;
    return b;
}

/* dr_bsdf_sample against dr_bsdf_pdf on the stretched half-vector cells; the
 * pdf's integral against 1 - (the test-side probability that a specular sample
 * leaves the hemisphere); every accepted sample's (f, pdf) are eval's and pdf's. */
static void aniso_chi2_case(const struct acombo *c, double cos_o, double phi_o, long nsamples, int seed)
{
    struct dr_bsdf b = acombo_bsdf(c);
    dr_vec3 wo = dir_from(cos_o, phi_o);
    double ax, ay;
    aniso_alphas(c->rough, c->s, &ax, &ay);
    double p = dr_bsdf_specular_prob(&b, wo);
    static double eh[HU * HV], oh[HU * HV];
    memset(oh, 0, sizeof(oh));
    struct actx q = {&b, wo, ax, ay, ax, ay, 0};
    double int_h;
    if (p == 1.0 || c->coat > 0.0) {
        int_h = integrate_h_space(dens_h_aniso, &q, eh, 1e-6);
    } else {
        /* A diffuse lobe seen in the cells of a strongly stretched lobe lies in
         * thin strips (1 - u ~ alpha_y, phi ~ +-pi/2) that an adaptive
         * quadrature steps over. So the expected counts are taken lobe by
         * lobe, (1 - p) E_cos + p E_spec: E_spec integrates dr_bsdf_pdf of
         * the white metal of the same lobe (p = 1), E_cos bins the cosine
         * lobe, uniform on the unit disk of (wi.x, wi.y), by the midpoint
         * rule on a grid 10x finer in y within 0.1 of -wo.y (where those
         * strips are); and dr_bsdf_pdf is checked to be that mixture
         * pointwise. */
        static double ec[HU * HV];
        struct dr_bsdf metal = make_aniso(c->rough, 1.0, 1.0, dr_v3s(1.0), c->s);
        struct actx qm = q;
        qm.b = &metal;
        int_h = p * integrate_h_space(dens_h_aniso, &qm, eh, 1e-6);
        memset(ec, 0, sizeof ec);
        const int NX = 2000;
        const double dx = 2.0 / NX, y0 = -wo.y;
        for (double y = -1.0; y < 1.0;) {
            double dy = fabs(y - y0) < 0.1 ? 1e-4 : 1e-3;
            double ym = fmin(y + 0.5 * dy, 1.0 - 1e-12), yw = fmin(dy, 1.0 - y);
            for (int i = 0; i < NX; i++) {
                double x = -1.0 + (i + 0.5) * dx, z2 = 1.0 - x * x - ym * ym;
                if (z2 <= 0.0)
                    continue;
                dr_vec3 wi = dr_v3(x, ym, sqrt(z2));
                ec[bin_h_aniso(dr_normalize(dr_add(wo, wi)), ax, ay)] += dx * yw / M_PI;
            }
            y += dy;
        }
        for (int i = 0; i < HU * HV; i++) {
            eh[i] = p * eh[i] + (1.0 - p) * ec[i];
            int_h += (1.0 - p) * ec[i];
        }
        struct rng rp = {(uint64_t)seed};
        double worst = 0.0;
        for (int k = 0; k < 2000; k++) {
            dr_vec3 wi = random_hemi(&rp);
            double want = (1.0 - p) * wi.z / M_PI + p * dr_bsdf_pdf(&metal, wo, wi);
            worst = fmax(worst, fabs(dr_bsdf_pdf(&b, wo, wi) / want - 1.0));
        }
        CHECK(worst < 1e-12, "aniso %s: pdf is not (1-p) cos/pi + p pdf_spec: rel %g", c->name, worst);
    }
    for (int i = 0; i < HU * HV; i++) eh[i] *= (double)nsamples;
    double vndf_total = integrate_h_space(dens_ref_vndf_aniso, &q, NULL, 1e-6);
    q.mode = 1;
    double fail_ref = integrate_h_space(dens_ref_vndf_aniso, &q, NULL, 1e-6);
    double expect = 1.0 - p * fail_ref;
    if (c->coat > 0.0) {   /* the coat's isotropic lobe, on its own cells */
        struct dr_bsdf base = b;
        base.coated = false;
        double ac = test_alpha(c->coat_rough), pc = c->coat * (0.04 + 0.96 * pow(1.0 - cos_o, 5.0));
        struct actx qc = {&b, wo, ac, ac, ac, ac, 1};
        double fail_coat = integrate_h_space(dens_ref_vndf_aniso, &qc, NULL, 1e-6);
        expect = 1.0 - pc * fail_coat - (1.0 - pc) * dr_bsdf_specular_prob(&base, wo) * fail_ref;
    }
    struct rng r = {(uint64_t)seed * 7919u + 17u};
    long fails = 0, mismatched = 0;
    for (long k = 0; k < nsamples; k++) {
        struct dr_bsdf_sample bs;
        double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
        if (!dr_bsdf_sample(&b, wo, ul, u1, u2, &bs)) {
            fails++;
            continue;
        }
        oh[bin_h_aniso(dr_normalize(dr_add(wo, bs.wi)), ax, ay)] += 1.0;
        double pdf;
        dr_vec3 f = dr_bsdf_eval_pdf(&b, wo, bs.wi, &pdf);
        dr_vec3 fe = dr_bsdf_eval(&b, wo, bs.wi);
        if (!(pdf == bs.pdf && dr_bsdf_pdf(&b, wo, bs.wi) == bs.pdf && f.x == bs.f.x && f.y == bs.f.y &&
              f.z == bs.f.z && fe.x == f.x && fe.y == f.y && fe.z == f.z))
            mismatched++;
    }
    int dof;
    double chi;
    double ph = chi2_test(oh, eh, HU * HV, &dof, &chi);
    double fail_frac = (double)fails / (double)nsamples;
    printf("  %-28s wo.z=%.1f phi=%.2f p_spec=%.4f | chi2=%6.1f dof=%3d p=%.4f | int pdf %.5f ref %.5f | vndf %.5f"
           " | fail %.5f\n", c->name, cos_o, phi_o, p, chi, dof, ph, int_h, expect, vndf_total, fail_frac);
    min_pvalue = fmin(min_pvalue, ph);
    CHECK(ph > 0.001, "aniso %s wo.z=%g: chi-square p-value %g", c->name, cos_o, ph);
    CHECK(mismatched == 0, "aniso %s wo.z=%g: %ld samples' (f, pdf) differ from eval/pdf", c->name, cos_o, mismatched);
    CHECK(fabs(int_h - expect) < 2e-3, "aniso %s wo.z=%g: integral of pdf %.6f, expected %.6f", c->name, cos_o,
          int_h, expect);
    CHECK(int_h <= 1.0 + 1e-3, "aniso %s wo.z=%g: integral of pdf %.6f > 1", c->name, cos_o, int_h);
    if (fail_ref < 1e-9 && c->coat == 0.0)   /* nothing rejected: the pdf integrates to 1 */
        CHECK(fabs(int_h - 1.0) < 2e-3, "aniso %s wo.z=%g: integral %.6f with no rejection", c->name, cos_o, int_h);
    CHECK(fabs(vndf_total - 1.0) < 1e-3, "aniso %s wo.z=%g: test-side VNDF integral %.6f", c->name, cos_o, vndf_total);
    double pf = 1.0 - int_h, sd = sqrt(fmax(pf * (1.0 - pf), 1e-12) / (double)nsamples);
    CHECK(fabs(fail_frac - pf) < 5.0 * sd + 1e-4, "aniso %s wo.z=%g: failed samples %.5f, expected %.5f", c->name,
          cos_o, fail_frac, pf);
}

static void test_aniso_chi2(void)
{
    printf("anisotropic: chi-square (dr_bsdf_sample vs dr_bsdf_pdf), 300k samples per case:\n");
    const double coss[] = {0.9, 0.5, 0.1}, phis[] = {0.7, 0.0, 1.9};
    int seed = 5000;
    for (int c = 0; c < NACOMBOS; c++)
        for (int k = 0; k < 3; k++)
            aniso_chi2_case(&acombos[c], coss[k], phis[(c + k) % 3], getenv("ANISO_N") ? atol(getenv("ANISO_N")) : 300000, seed++);
}

/* f and the specular pdf against the textbook anisotropic GGX (white metal:
 * F = 1, f = D G2 / (4 wo.z wi.z), p = 1), reciprocity, the sampling map's
 * Jacobian against the pdf, the highlight's orientation, the limit s -> 0 of
 * the anisotropic path, and s = 0 bit for bit the isotropic BSDF. */
static void test_aniso_values(void)
{
    struct rng r = {4242};
    const double roughs[] = {0.05, 0.3, 0.7}, ss[] = {0.3, 0.8, 1.0};
    double worst_f = 0.0, worst_p = 0.0, worst_rec = 0.0;
    for (int ri = 0; ri < 3; ri++)
        for (int si = 0; si < 3; si++) {
            double ax, ay;
            aniso_alphas(roughs[ri], ss[si], &ax, &ay);
            struct dr_bsdf m = make_aniso(roughs[ri], 1.0, 1.0, dr_v3s(1.0), ss[si]);
            struct dr_bsdf d = make_aniso(roughs[ri], 0.0, 1.0, dr_v3(0.5, 0.4, 0.3), ss[si]);
            for (int i = 0; i < 500; i++) {
                dr_vec3 wo = random_hemi(&r), wi = random_hemi(&r);
                dr_vec3 h = dr_normalize(dr_add(wo, wi));
                double g2 = 1.0 / (1.0 + ref_lambda_aniso(ax, ay, wo) + ref_lambda_aniso(ax, ay, wi));
                double want = ref_D_aniso(ax, ay, h) * g2 / (4.0 * wo.z * wi.z);
                double wantp = ref_D_aniso(ax, ay, h) / (1.0 + ref_lambda_aniso(ax, ay, wo)) / (4.0 * wo.z);
                double pdf;
                dr_vec3 f = dr_bsdf_eval_pdf(&m, wo, wi, &pdf);
                double ef = fabs(f.x / want - 1.0), ep = fabs(pdf / wantp - 1.0);
                worst_f = fmax(worst_f, ef);
                worst_p = fmax(worst_p, ep);
                CHECK(ef < 1e-10 && f.y == f.x && f.z == f.x, "aniso white metal f %.15g vs %.15g", f.x, want);
                CHECK(ep < 1e-10, "aniso metal pdf %.15g vs %.15g", pdf, wantp);
                for (int k = 0; k < 2; k++) {
                    const struct dr_bsdf *b = k ? &d : &m;
                    dr_vec3 f1 = dr_bsdf_eval(b, wo, wi), f2 = dr_bsdf_eval(b, wi, wo);
                    double rel = fmax(fabs(f1.x - f2.x), fmax(fabs(f1.y - f2.y), fabs(f1.z - f2.z))) /
                                 fmax(dr_max3(f1), 1e-300);
                    worst_rec = fmax(worst_rec, rel);
                    CHECK(rel <= 1e-12, "aniso reciprocity rough %g s %g: rel %g", roughs[ri], ss[si], rel);
                }
            }
            /* the map's Jacobian (finite differences) against the pdf, at wo of several azimuths */
            const double us[][2] = {{0.13, 0.37}, {0.5, 0.71}, {0.82, 0.23}, {0.31, 0.9}, {0.05, 0.55}};
            for (int k = 0; k < 3; k++) {
                dr_vec3 wo = dir_from(k == 0 ? 0.95 : k == 1 ? 0.6 : 0.3, 0.4 + 1.3 * k);
                for (int i = 0; i < 5; i++) {
                    bool ok = true;
                    double dens = map_density(&m, wo, 0.5, us[i][0], us[i][1], &ok);
                    if (!ok)
                        continue;
                    struct dr_bsdf_sample s;
                    dr_bsdf_sample(&m, wo, 0.5, us[i][0], us[i][1], &s);
                    double rel = fabs(dens / dr_bsdf_pdf(&m, wo, s.wi) - 1.0);
                    CHECK(rel < 1e-4, "aniso Jacobian rough %g s %g wo.z %g: map %.9g pdf %.9g", roughs[ri], ss[si],
                          wo.z, dens, dr_bsdf_pdf(&m, wo, s.wi));
                }
            }
        }
    printf("anisotropic: f vs textbook GGX worst rel %.2e, pdf %.2e, reciprocity %.2e\n", worst_f, worst_p, worst_rec);

    /* the highlight stretches along x: a half vector tilted by t along x
     * reflects more than the same tilt along y (s = 1, roughness 0.1: ax = 1,
     * ay = 0.01), and by the ratio of the textbook D's */
    struct dr_bsdf m = make_aniso(0.1, 1.0, 1.0, dr_v3s(1.0), 1.0);
    dr_vec3 wo = dr_v3(0.0, 0.0, 1.0);
    for (double t = 0.05; t < 0.6; t += 0.1) {
        dr_vec3 hx = dr_v3(sin(t), 0.0, cos(t)), hy = dr_v3(0.0, sin(t), cos(t));
        dr_vec3 wx = dr_sub(dr_scale(hx, 2.0 * hx.z), wo), wy = dr_sub(dr_scale(hy, 2.0 * hy.z), wo);
        double fx = dr_bsdf_eval(&m, wo, wx).x, fy = dr_bsdf_eval(&m, wo, wy).x;
        CHECK(fx > 100.0 * fy, "highlight not stretched along x: tilt %g: f_x %g f_y %g", t, fx, fy);
        struct dr_bsdf rot = m;   /* roughness along y instead: the same f swapped */
        rot.anisotropy = 0.0;
        CHECK(dr_bsdf_eval(&rot, wo, wx).x < fx, "anisotropy did not widen the lobe along x at tilt %g", t);
    }
    /* s -> 0 on the anisotropic path (s^2 underflows: ax == ay) is the
     * isotropic model to rounding; s = 0 is the isotropic BSDF bit for bit */
    double worst_lim = 0.0;
    for (int i = 0; i < 3000; i++) {
        double rough = i % 3 == 0 ? 0.05 : (i % 3 == 1 ? 0.4 : 0.9);
        struct dr_bsdf iso = make_bsdf(rough, (i % 4) / 3.0, 1.0, dr_v3(0.7, 0.5, 0.2));
        if (i % 5 == 0)
            iso.coated = true, iso.coat = 0.6, iso.coat_roughness = 0.2;
        struct dr_bsdf zero = iso, tiny = iso;
        zero.anisotropy = 0.0;
        tiny.anisotropy = 1e-200;
        dr_vec3 o = random_hemi(&r), w = random_hemi(&r);
        double pi_, pz, pt;
        dr_vec3 fi = dr_bsdf_eval_pdf(&iso, o, w, &pi_), fz = dr_bsdf_eval_pdf(&zero, o, w, &pz),
                ft = dr_bsdf_eval_pdf(&tiny, o, w, &pt);
        CHECK(fi.x == fz.x && fi.y == fz.y && fi.z == fz.z && pi_ == pz, "s = 0 is not the isotropic BSDF bit for bit");
        double rel = fmax(fabs(ft.x / fi.x - 1.0), fabs(pt / pi_ - 1.0));
        worst_lim = fmax(worst_lim, rel);
        CHECK(rel < 1e-12, "s = 1e-200 vs isotropic: f %.17g vs %.17g, pdf %.17g vs %.17g", ft.x, fi.x, pt, pi_);
        double u1 = rng_next(&r), u2 = rng_next(&r), ul = rng_next(&r);
        struct dr_bsdf_sample si, sz, st;
        bool oki = dr_bsdf_sample(&iso, o, ul, u1, u2, &si), okz = dr_bsdf_sample(&zero, o, ul, u1, u2, &sz);
        dr_bsdf_sample(&tiny, o, ul, u1, u2, &st);
        CHECK(oki == okz && si.wi.x == sz.wi.x && si.wi.y == sz.wi.y && si.wi.z == sz.wi.z && si.pdf == sz.pdf,
              "s = 0 sample differs from the isotropic one");
        CHECK(dr_length(dr_sub(st.wi, si.wi)) < 1e-12, "s = 1e-200 sample direction differs");
        CHECK(dr_bsdf_sky_share(&iso, o) == dr_bsdf_sky_share(&zero, o) &&
                  fabs(dr_bsdf_sky_share(&tiny, o) - dr_bsdf_sky_share(&iso, o)) < 1e-14,
              "sky share at s = 0 / 1e-200");
    }
    printf("anisotropic path at s = 1e-200 vs isotropic: worst rel %.2e\n", worst_lim);
    /* the sky share uses the geometric mean of the alphas: a sharp lobe
     * stretched to ax = 1 gets no share any more */
    struct dr_bsdf sharp = make_aniso(0.5, 1.0, 1.0, dr_v3s(1.0), 0.0), wide = sharp;
    wide.anisotropy = 1.0;
    dr_vec3 o = dir_from(0.7, 0.3);
    CHECK(dr_bsdf_sky_share(&sharp, o) == 1.0 && dr_bsdf_sky_share(&wide, o) == 0.0,
          "sky share: isotropic %g (want 1), stretched %g (want 0)", dr_bsdf_sky_share(&sharp, o),
          dr_bsdf_sky_share(&wide, o));
}

/* White-furnace: a white anisotropic metal's sample weights are G2/G1 <= 1, so
 * its albedo is <= 1; and it matches a test-side quadrature of D G2 (wo.h)/wo.z. */
static double dens_ref_albedo_aniso(void *vc, double u, double phi)
{
    struct actx *q = vc;
    double jac;
    dr_vec3 h = h_of_u_aniso(q->ax, q->ay, u, phi, &jac);
    double oh = dr_dot(q->wo, h);
    if (oh <= 0.0)
        return 0.0;
    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), q->wo);
    if (wi.z <= 0.0)
        return 0.0;
    double g2 = 1.0 / (1.0 + ref_lambda_aniso(q->rax, q->ray, q->wo) + ref_lambda_aniso(q->rax, q->ray, wi));
    return g2 * ref_D_aniso(q->rax, q->ray, h) * oh / q->wo.z * jac;
}

static void test_aniso_energy(void)
{
    const double roughs[] = {0.05, 0.3, 0.7}, ss[] = {0.3, 0.8, 1.0}, coss[] = {0.9, 0.5, 0.1};
    printf("white anisotropic metal directional albedo (100k samples):\n");
    for (int ri = 0; ri < 3; ri++)
        for (int si = 0; si < 3; si++) {
            struct dr_bsdf b = make_aniso(roughs[ri], 1.0, 1.0, dr_v3s(1.0), ss[si]);
            double ax, ay;
            aniso_alphas(roughs[ri], ss[si], &ax, &ay);
            printf("  rough %.2f s %.1f:", roughs[ri], ss[si]);
            for (int k = 0; k < 3; k++) {
                dr_vec3 wo = dir_from(coss[k], 0.3 + k);
                struct rng r = {(uint64_t)(7000 + 10 * ri + 3 * si + k)};
                const long n = 100000;
                double sum = 0.0, sum2 = 0.0, wmax = 0.0;
                for (long s = 0; s < n; s++) {
                    struct dr_bsdf_sample bs;
                    double ul = rng_next(&r), u1 = rng_next(&r), u2 = rng_next(&r);
                    double w = dr_bsdf_sample(&b, wo, ul, u1, u2, &bs) ? bs.f.x * bs.wi.z / bs.pdf : 0.0;
                    wmax = fmax(wmax, w);
                    sum += w;
                    sum2 += w * w;
                }
                double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
                struct actx q = {&b, wo, ax, ay, ax, ay, 0};
                double ref = integrate_h_space(dens_ref_albedo_aniso, &q, NULL, 1e-7);
                printf("  wo.z=%.1f: %.4f +- %.4f (quad %.4f)", coss[k], mean, se, ref);
                CHECK(wmax <= 1.0 + 1e-9 && mean <= 1.0, "white aniso metal: weight up to %.17g, albedo %.6f", wmax, mean);
                CHECK(fabs(mean - ref) < 4.0 * se + 1e-3, "white aniso metal rough %g s %g wo.z %g: %.5f +- %.5f vs %.5f",
                      roughs[ri], ss[si], coss[k], mean, se, ref);
            }
            printf("\n");
        }
}


/* ------------------------------------------------------------ the sheen */

/* Test-side sheen lobe (Estevez & Kulla 2017 as written in their paper and
 * the glTF KHR_materials_sheen spec, independent of core/bsdf_sheen.c):
 * D G / (4 wo.z wi.z) for a white colour at roughness r (floored). */
static double ref_sheen_L(double r, double x)
{
    static const double p0[5] = {25.3245, 3.32435, 0.16801, -1.27393, -4.85967};
    static const double p1[5] = {21.5473, 3.82987, 0.19823, -1.97760, -4.32054};
    double a = r * r, t = (1.0 - a) * (1.0 - a), p[5];
    for (int i = 0; i < 5; i++)
        p[i] = (1.0 - t) * p1[i] + t * p0[i];
    return p[0] / (1.0 + p[1] * pow(x, p[2])) + p[3] * x + p[4];
}
static double ref_sheen_lambda(double r, double x)
{
    x = fmin(x, 1.0);
    return x < 0.5 ? exp(ref_sheen_L(r, x)) : exp(2.0 * ref_sheen_L(r, 0.5) - ref_sheen_L(r, 1.0 - x));
}
static double ref_sheen(double r, dr_vec3 wo, dr_vec3 wi)
{
    r = fmax(r, DR_SHEEN_MIN_ROUGHNESS);
    double a = r * r;
    dr_vec3 h = dr_normalize(dr_add(wo, wi));
    double sin_h = sqrt(fmax(0.0, 1.0 - h.z * h.z));
    double D = (2.0 + 1.0 / a) * pow(sin_h, 1.0 / a) / (2.0 * M_PI);
    double G = 1.0 / (1.0 + ref_sheen_lambda(r, wo.z) + ref_sheen_lambda(r, wi.z));
    return D * G / (4.0 * wo.z * wi.z);
}

/* E(mu, r) by a quadrature of the test's own: composite Gauss-Legendre (16
 * points a panel) over t = cos(theta_h) on panels graded towards t = 0
 * (where the lobe is), and over phi_h in the range where wi.z > 0,
 * |phi| < acos(mu (1 - 2t^2) / (2 t sin_o sin_h)), with the substitution
 * phi = lim (1 - (1 - v)^3), which clusters nodes at the range's end (wi.z
 * -> 0, where Lambda's x^c makes the integrand steep). f: the lobe (ref_sheen
 * if b is NULL, else dr_bsdf_eval(b).x). */
static double sheen_quad(const struct dr_bsdf *b, double mu, double r)
{
    static const double gx[8] = {0.0950125098376374, 0.2816035507792589, 0.4580167776572274, 0.6178762444026438,
                                 0.7554044083550030, 0.8656312023878318, 0.9445750230732326, 0.9894009349916499};
    static const double gw[8] = {0.1894506104550685, 0.1826034150449236, 0.1691565193950025, 0.1495959888165767,
                                 0.1246289712555339, 0.0951585116824928, 0.0622535239386479, 0.0271524594117541};
    static const double cut[] = {0.0, 0.004, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.14, 0.2, 0.3, 0.45, 0.65, 1.0};
    const double so = sqrt(fmax(0.0, 1.0 - mu * mu));
    const dr_vec3 wo = dr_v3(so, 0.0, mu);
    /* the smallest t with directions above the surface (mu (1 - 2t^2) <
     * 2 t so sin_h), by bisection; the phi range opens like sqrt(t - tmin),
     * so the panel holding tmin is integrated in u, t = tmin + (t1 - tmin) u^2 */
    double lo = 0.0, hi = 1.0;
    for (int it = 0; it < 100; it++) {
        const double t = 0.5 * (lo + hi);
        if (mu * (1.0 - 2.0 * t * t) < 2.0 * t * so * sqrt(1.0 - t * t))
            hi = t;
        else
            lo = t;
    }
    const double tmin = hi;
    double sum = 0.0;
    for (size_t k = 0; k + 1 < sizeof cut / sizeof *cut; k++) {
        if (cut[k + 1] <= tmin)
            continue;
        const bool first = cut[k] < tmin;
        const double t0 = first ? 0.0 : cut[k], t1 = first ? 1.0 : cut[k + 1], tm = 0.5 * (t0 + t1),
                     tr = 0.5 * (t1 - t0);
        for (int i = 0; i < 16; i++) {
            double t = tm + tr * (i < 8 ? -gx[i] : gx[i - 8]), wt = tr * gw[i % 8];
            if (first) {   /* (t0, t1) = (0, 1) is u's range */
                const double u = t, span = cut[k + 1] - tmin;
                t = tmin + span * u * u;
                wt *= 2.0 * span * u;
            }
            const double sh = sqrt(fmax(0.0, 1.0 - t * t)), den = 2.0 * t * so * sh, num = mu * (1.0 - 2.0 * t * t);
            if (!(num < den))
                continue;
            const double lim = num <= -den ? M_PI : acos(num / den);
            double inner = 0.0;
            for (int j = 0; j < 16; j++) {
                const double v = 0.5 + 0.5 * (j < 8 ? -gx[j] : gx[j - 8]), wv = 0.5 * gw[j % 8];
                const double q = 1.0 - v, phi = lim * (1.0 - q * q * q), dphi = lim * 3.0 * q * q;
                const dr_vec3 h = dr_v3(sh * cos(phi), sh * sin(phi), t);
                const double oh = dr_dot(wo, h);
                const dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), wo);
                if (!(wi.z > 0.0) || !(oh > 0.0))
                    continue;
                const double f = b ? dr_bsdf_eval(b, wo, wi).x : ref_sheen(r, wo, wi);
                inner += wv * dphi * f * wi.z * 4.0 * oh;
            }
            sum += wt * 2.0 * inner;
        }
    }
    return sum;
}

/* The table (core/sheen_albedo.c) against the test's quadrature at every
 * node (1e-4; node mu = 0 holds E(DR_SHEEN_MU_LO)), the interpolant at
 * off-grid points (2e-3), and the BSDF's own lobe (a white sheen over a
 * black Lambertian: f = f_sheen) against the table at off-grid points. */
static void test_sheen_table(void)
{
    double worst_node = 0.0, worst_off = 0.0, worst_lobe = 0.0, emax = 0.0;
    for (int j = 0; j < DR_SHEEN_NR; j++)
        for (int i = 0; i < DR_SHEEN_NMU; i++) {
            const double mu = fmax(dr_sheen_grid_mu(i), DR_SHEEN_MU_LO), r = dr_sheen_grid_r(j);
            const double q = sheen_quad(NULL, mu, r), e = DR_SHEEN_ALBEDO[j][i];
            worst_node = fmax(worst_node, fabs(q - e));
            emax = fmax(emax, e);
            CHECK(fabs(q - e) < 1e-4, "sheen table node mu %g r %g: %.7f, quadrature %.7f", mu, r, e, q);
        }
    struct rng g = {4242};
    struct dr_bsdf b = make_bsdf(0.5, 0.0, 0.0, dr_v3s(0.0));
    b.sheened = true;
    b.sheen_color = dr_v3s(1.0);
    for (int n = 0; n < 300; n++) {
        const double mu = n < 20 ? 0.002 + 0.002 * n : 0.001 + 0.999 * rng_next(&g);
        const double r = DR_SHEEN_MIN_ROUGHNESS + (1.0 - DR_SHEEN_MIN_ROUGHNESS) * rng_next(&g);
        const double e = dr_sheen_albedo(mu, r, NULL, NULL), q = sheen_quad(NULL, mu, r);
        worst_off = fmax(worst_off, fabs(e - q));
        if (fabs(e - q) > 5e-4) printf("  off-grid mu %g r %g: %.6f vs %.6f\n", mu, r, e, q);
        CHECK(fabs(e - q) < 2e-3, "sheen albedo interpolant mu %g r %g: %.6f, quadrature %.6f", mu, r, e, q);
        if (n % 3 == 0) {
            b.sheen_roughness = r;
            const double ql = sheen_quad(&b, mu, r);
            worst_lobe = fmax(worst_lobe, fabs(ql - e));
            CHECK(fabs(ql - e) < 2e-3, "sheen lobe's albedo mu %g r %g: %.6f, table %.6f", mu, r, ql, e);
        }
    }
    printf("sheen albedo table: %d nodes, worst node error %.2e, worst off-grid error %.2e, lobe vs table %.2e;"
           " max E %.4f\n", DR_SHEEN_NR * DR_SHEEN_NMU, worst_node, worst_off, worst_lobe, emax);
}

/* f and pdf of sheened BSDFs against the test-side formulas:
 *   f = T(wo) T(wi) f_base + C f_lobe, T = max(0, 1 - m E), m = max(C),
 *   pdf = P wi.z / pi + (1 - P) pdf_base, P = min(1, m E(wo.z)),
 * (E the table's: checked above); reciprocity; the sheened = false bits. */
static void test_sheen_values(void)
{
    struct rng g = {99};
    double worst = 0.0;
    for (int n = 0; n < 4000; n++) {
        struct dr_bsdf b = make_bsdf(0.05 + 0.95 * rng_next(&g), n % 3 == 0 ? 1.0 : 0.3 * rng_next(&g), n % 4 ? 1.0 : 0.0,
                                     dr_v3(rng_next(&g), rng_next(&g), rng_next(&g)));
        b.coated = n % 5 == 0, b.coat = 0.6, b.coat_roughness = 0.3;
        b.anisotropy = n % 7 == 0 ? 0.5 : 0.0;
        b.sheened = true;
        b.sheen_roughness = n % 6 == 0 ? 0.03 : rng_next(&g);
        b.sheen_color = n % 8 == 0 ? dr_v3s(0.0) : n % 8 == 1 ? dr_v3s(1.0) : dr_v3(rng_next(&g), rng_next(&g), rng_next(&g));
        dr_vec3 wo = random_hemi(&g), wi = random_hemi(&g);
        if (n % 9 == 0)
            wo = dir_from(1e-3 + 0.02 * rng_next(&g), 1.0);
        struct dr_bsdf base = b;
        base.coated = false, base.sheened = false;
        const double r = fmax(b.sheen_roughness, DR_SHEEN_MIN_ROUGHNESS);
        const double m = dr_max3(b.sheen_color);
        const double eo = dr_sheen_albedo(wo.z, r, NULL, NULL), ei = dr_sheen_albedo(wi.z, r, NULL, NULL);
        const double tt = fmax(0.0, 1.0 - m * eo) * fmax(0.0, 1.0 - m * ei);
        dr_vec3 want = dr_add(dr_scale(dr_bsdf_eval(&base, wo, wi), tt), dr_scale(b.sheen_color, ref_sheen(r, wo, wi)));
        const double P = fmin(1.0, m * eo);
        double want_pdf = P * wi.z / M_PI + (1.0 - P) * dr_bsdf_pdf(&base, wo, wi);
        if (b.coated) {   /* bsdf.h: the coat over the sheened BSDF */
            const double fo = 0.04 + 0.96 * pow(1.0 - wo.z, 5.0), fi = 0.04 + 0.96 * pow(1.0 - wi.z, 5.0);
            struct dr_bsdf cl = make_bsdf(0.3, 0.0, 1.0, dr_v3s(0.0));
            want = dr_add(dr_scale(want, (1.0 - 0.6 * fo) * (1.0 - 0.6 * fi)), dr_scale(dr_bsdf_eval(&cl, wo, wi), 0.6));
            want_pdf = 0.6 * fo * dr_bsdf_pdf(&cl, wo, wi) + (1.0 - 0.6 * fo) * want_pdf;
        }
        double pdf;
        const dr_vec3 f = dr_bsdf_eval_pdf(&b, wo, wi, &pdf);
        const double rel = fmax(fabs(f.x - want.x), fmax(fabs(f.y - want.y), fabs(f.z - want.z))) / fmax(dr_max3(want), 1e-300);
        worst = fmax(worst, rel);
        CHECK(rel < 1e-9, "sheen f vs test-side formula: rel %g (n %d)", rel, n);
        CHECK(fabs(pdf - want_pdf) <= 1e-12 * want_pdf, "sheen pdf %.15g vs test-side %.15g (n %d)", pdf, want_pdf, n);
        CHECK(pdf == dr_bsdf_pdf(&b, wo, wi), "sheen: dr_bsdf_eval_pdf and dr_bsdf_pdf disagree");
        /* a sheened = false BSDF ignores its sheen fields, bit for bit */
        struct dr_bsdf off = b, clean = b;
        off.sheened = false;
        clean.sheened = false, clean.sheen_color = dr_v3s(0.0), clean.sheen_roughness = 0.0;
        const dr_vec3 f1 = dr_bsdf_eval(&off, wo, wi), f2 = dr_bsdf_eval(&clean, wo, wi);
        CHECK(f1.x == f2.x && f1.y == f2.y && f1.z == f2.z && dr_bsdf_pdf(&off, wo, wi) == dr_bsdf_pdf(&clean, wo, wi) &&
                  dr_bsdf_specular_prob(&off, wo) == dr_bsdf_specular_prob(&clean, wo),
              "sheened = false: the sheen's fields changed a result");
        /* the sheen lobe's map is the cosine map, bit for bit */
        const double u1 = rng_next(&g), u2 = rng_next(&g);
        const dr_vec3 ws = dr_bsdf_sample_dir(&b, wo, DR_BSDF_LOBE_SHEEN, u1, u2), wc = dr_bsdf_cosine_dir(u1, u2);
        CHECK(ws.x == wc.x && ws.y == wc.y && ws.z == wc.z, "sheen map is not the cosine map");
        /* specular_prob: the GGX maps' share (1 - P) p_base (under a coat, the coat's too) */
        if (!b.coated)
            CHECK(fabs(dr_bsdf_specular_prob(&b, wo) - (1.0 - P) * dr_bsdf_specular_prob(&base, wo)) < 1e-15,
                  "sheen specular_prob");
    }
    printf("sheen values vs test-side formulas: worst relative difference %.2e\n", worst);
}

/* bsdf_sheen.c memoises per thread what depends on (roughness, wo.z) only
 * (eight wo entries, four roughnesses, replaced round-robin). A hit must
 * give the bits a miss gives: cycling through nine wo directions and five
 * roughnesses misses every time (each entry is replaced before its turn
 * comes round again), then each (BSDF, wo) is evaluated again at once,
 * which hits, and also interleaved with a second wo, as the eight-lane
 * stages interleave lanes. f, pdf, a sample (its lobe, direction, f and
 * pdf), the sky's share and the GGX maps' share are compared. */
static void test_sheen_memo(void)
{
    enum { NWO = 9, NR = 5, NWI = 4 };
    const double rough[NR] = {0.07, 0.2, 0.5, 0.81, 1.0};
    struct rng g = {4242};
    dr_vec3 wo[NWO], wi[NWI];
    for (int k = 0; k < NWO; k++)
        wo[k] = k == 0 ? dir_from(1e-3, 0.3) : random_hemi(&g);
    for (int k = 0; k < NWI; k++)
        wi[k] = random_hemi(&g);
    struct dr_bsdf b[NR];
    for (int j = 0; j < NR; j++) {
        b[j] = make_bsdf(0.4, 0.0, 1.0, dr_v3(0.3, 0.2, 0.1));
        b[j].sheened = true, b[j].sheen_roughness = rough[j], b[j].sheen_color = dr_v3(0.9, 0.5, 0.7);
        b[j].coated = j == 3, b[j].coat = 0.5, b[j].coat_roughness = 0.2;
    }
    /* first pass: (j, k) in an order that never repeats a key within 9 calls */
    double f[NR][NWO][NWI][4], share[NR][NWO][2];
    struct dr_bsdf_sample smp[NR][NWO];
    for (int k = 0; k < NWO; k++)
        for (int j = 0; j < NR; j++)
            for (int i = 0; i < NWI; i++) {
                double pdf;
                const dr_vec3 v = dr_bsdf_eval_pdf(&b[(j + i) % NR], wo[(k + 2 * i) % NWO], wi[i], &pdf);
                f[(j + i) % NR][(k + 2 * i) % NWO][i][0] = v.x, f[(j + i) % NR][(k + 2 * i) % NWO][i][1] = v.y;
                f[(j + i) % NR][(k + 2 * i) % NWO][i][2] = v.z, f[(j + i) % NR][(k + 2 * i) % NWO][i][3] = pdf;
            }
    for (int k = 0; k < NWO; k++)
        for (int j = 0; j < NR; j++) {
            share[j][k][0] = dr_bsdf_sky_share(&b[j], wo[k]);
            share[j][k][1] = dr_bsdf_specular_prob(&b[j], wo[k]);
            dr_bsdf_sample(&b[j], wo[k], 0.37, 0.61, 0.29, &smp[j][k]);
        }
    /* second pass: each key asked for repeatedly, interleaved with another */
    int bad = 0;
    for (int j = 0; j < NR; j++)
        for (int k = 0; k < NWO; k++)
            for (int rep = 0; rep < 2; rep++) {
                const int k2 = (k + 4) % NWO;
                for (int i = 0; i < NWI; i++) {
                    double pdf;
                    const dr_vec3 v = dr_bsdf_eval_pdf(&b[j], wo[k], wi[i], &pdf);
                    bad += v.x != f[j][k][i][0] || v.y != f[j][k][i][1] || v.z != f[j][k][i][2] || pdf != f[j][k][i][3];
                    (void)dr_bsdf_eval(&b[j], wo[k2], wi[i]);
                }
                bad += dr_bsdf_sky_share(&b[j], wo[k]) != share[j][k][0];
                bad += dr_bsdf_specular_prob(&b[j], wo[k]) != share[j][k][1];
                struct dr_bsdf_sample o;
                dr_bsdf_sample(&b[j], wo[k], 0.37, 0.61, 0.29, &o);
                bad += o.lobe != smp[j][k].lobe || o.pdf != smp[j][k].pdf || o.f.x != smp[j][k].f.x || o.wi.z != smp[j][k].wi.z;
            }
    CHECK(bad == 0, "sheen memo: %d results differ between a memo hit and a miss", bad);
}

/* bsdf.h's sheen layer (path_simd.c composes it over its eight-wide base):
 * over the base's f and density (the record without sheen and coat) it
 * gives dr_bsdf_eval_pdf's bits, and P(wo) gives the sky share's and the
 * specular probability's (1 - P) factor and dr_bsdf_sample's lobe choice. */
static void test_sheen_layer(void)
{
    const double rough[] = {0.07, 0.3, 0.5, 1.0}, aniso[] = {0.0, 0.0, 0.6, 0.0};
    struct rng g = {777};
    int bad_f = 0, bad_p = 0, bad_lobe = 0, n = 0;
    for (int j = 0; j < 4; j++) {
        struct dr_bsdf b = make_bsdf(0.3 * j, 0.4 * (j & 1), 0.2 + 0.25 * j, dr_v3(0.6, 0.3, 0.2));
        b.anisotropy = aniso[j];
        b.sheened = true, b.sheen_roughness = rough[j], b.sheen_color = dr_v3(0.9, 0.5 * j, 0.7);
        struct dr_bsdf base = b;
        base.sheened = false;
        for (int k = 0; k < 200; k++, n++) {
            const dr_vec3 wo = k == 0 ? dir_from(2e-3, 0.3) : random_hemi(&g), wi = random_hemi(&g);
            double pdf, pb;
            const dr_vec3 f = dr_bsdf_eval_pdf(&b, wo, wi, &pdf), fb = dr_bsdf_eval_pdf(&base, wo, wi, &pb);
            const struct dr_sheen_layer l = dr_sheen_layer_at(&b, wo, wi);
            const dr_vec3 fl = dr_sheen_layer_f(&l, fb);
            bad_f += fl.x != f.x || fl.y != f.y || fl.z != f.z || dr_sheen_layer_pdf(&l, wi, pb) != pdf;
            const double p = dr_sheen_lobe_prob(&b, wo);
            bad_p += p != l.p || dr_bsdf_sky_share(&b, wo) != (1.0 - p) * dr_bsdf_sky_share(&base, wo) ||
                     dr_bsdf_specular_prob(&b, wo) != (1.0 - p) * dr_bsdf_specular_prob(&base, wo);
            const double u = rng_next(&g);
            struct dr_bsdf_sample smp;
            dr_bsdf_sample(&b, wo, u, 0.3, 0.7, &smp);
            bad_lobe += (u < p) != (smp.lobe == DR_BSDF_LOBE_SHEEN);
        }
    }
    CHECK(bad_f == 0, "sheen layer over the base: %d of %d f or pdf differ from dr_bsdf_eval_pdf's", bad_f, n);
    CHECK(bad_p == 0, "sheen lobe probability: %d of %d disagree with the sky share or specular probability", bad_p, n);
    CHECK(bad_lobe == 0, "sheen lobe probability: %d of %d samples chose otherwise", bad_lobe, n);
}

/* White furnace: a white sheen over a white Lambertian, importance sampled:
 * albedo = E(wo) + T(wo) 2 int T(mu) mu dmu (<= 1 where m E <= 1; above 1
 * where the model's E is, T = 0 there), checked against that. */
static void test_sheen_furnace(void)
{
    const double rs[] = {0.07, 0.2, 0.3, 0.5, 0.8, 1.0};
    const double coss[] = {0.02, 0.05, 0.1, 0.3, 0.6, 0.9, 1.0};
    printf("white sheen over white Lambertian, directional albedo (200k samples):\n");
    for (size_t ri = 0; ri < sizeof rs / sizeof *rs; ri++) {
        struct dr_bsdf b = make_bsdf(0.5, 0.0, 0.0, dr_v3s(1.0));
        b.sheened = true, b.sheen_color = dr_v3s(1.0), b.sheen_roughness = rs[ri];
        double avg_t = 0.0;   /* 2 int T mu dmu, midpoint rule */
        for (int k = 0; k < 4000; k++) {
            const double mu = (k + 0.5) / 4000.0;
            avg_t += 2.0 * mu * fmax(0.0, 1.0 - dr_sheen_albedo(mu, rs[ri], NULL, NULL)) / 4000.0;
        }
        printf("  r %.2f:", rs[ri]);
        for (size_t k = 0; k < sizeof coss / sizeof *coss; k++) {
            struct rng g = {1000u + 17u * ri + k};
            const dr_vec3 wo = dir_from(coss[k], 0.4);
            double sum = 0.0, sum2 = 0.0;
            const long ns = 200000;
            for (long s = 0; s < ns; s++) {
                struct dr_bsdf_sample bs;
                double w = 0.0;
                if (dr_bsdf_sample(&b, wo, rng_next(&g), rng_next(&g), rng_next(&g), &bs))
                    w = bs.f.x * bs.wi.z / bs.pdf;
                sum += w, sum2 += w * w;
            }
            const double mean = sum / ns, se = sqrt(fmax(0.0, sum2 / ns - mean * mean) / ns);
            const double e = dr_sheen_albedo(coss[k], rs[ri], NULL, NULL);
            const double want = e + fmax(0.0, 1.0 - e) * avg_t;
            printf(" %.3f", mean);
            CHECK(fabs(mean - want) < 4.0 * se + 3e-3, "sheen furnace r %g wo.z %g: %.5f +- %.5f, expected %.5f", rs[ri],
                  coss[k], mean, se, want);
            if (e <= 1.0)
                CHECK(mean <= 1.0 + 4.0 * se, "sheen furnace r %g wo.z %g creates energy: %.5f +- %.5f", rs[ri], coss[k],
                      mean, se);
        }
        printf("\n");
    }
}

int main(void)
{
    setvbuf(stdout, NULL, _IOLBF, 0);
    clock_t t0 = clock();
    test_lambertian();
    test_cosine_sampler_map();
    test_sincos_turn();
    test_atan2_acos();
    test_reciprocity();
    test_hard_cases();
    test_jacobian();
    clock_t t1 = clock();
    test_energy();
    clock_t t2 = clock();
    test_chi2();
    test_aniso_values();
    test_aniso_energy();
    test_aniso_chi2();
    clock_t t3 = clock();
    test_sheen_values();
    test_sheen_memo();
    test_sheen_layer();
    test_sheen_furnace();
    test_sheen_table();
    clock_t t4 = clock();
    printf("times: basic %.2fs, energy %.2fs, chi-square + pdf integrals %.2fs, sheen %.2fs\n",
           (double)(t1 - t0) / CLOCKS_PER_SEC, (double)(t2 - t1) / CLOCKS_PER_SEC,
           (double)(t3 - t2) / CLOCKS_PER_SEC, (double)(t4 - t3) / CLOCKS_PER_SEC);
    return TEST_END();
}
