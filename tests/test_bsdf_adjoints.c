/* Tests of the BSDF adjoints that attached sampling needs (core/bsdf.c),
 * each against central differences of its primal:
 *   a. d_bsdf_eval        (parameters and both directions) vs dr_bsdf_eval,
 *   b. d_bsdf_pdf         vs dr_bsdf_pdf; d_bsdf_specular_prob vs dr_bsdf_specular_prob,
 *   c. d_bsdf_sample_dir  vs dr_bsdf_sample_dir, both lobes,
 *   d. d_mis_power        vs dr_mis_power (core/path.h),
 *   e. the forward-mode identity: <d_out, J v> from a difference of the
 *      primal along a random v equals <adjoint, v>,
 *   f. bit-identity: d_bsdf_eval's parameter part equals the frozen version
 *      from before the direction adjoints; dr_bsdf_sample's wi equals
 *      dr_bsdf_sample_dir and the frozen map,
 *   g. hard cases (no NaN/Inf from any adjoint), NULL outputs, accumulation,
 *      untouched outputs below the surface.
 * Every input is differenced with a step scaled to it; a difference that
 * would straddle a kink of the primal (a clamp or branch, known test-side as
 * a "regime") is made one-sided, or skipped when neither side fits, and
 * counted. Deterministic: fixed seeds. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bsdf.h"
#include "sheen_albedo.h"   /* test-side lobe probability of a sheen (its table) */
#include "path.h"
#include "sampler.h"
#include "test.h"

#define COS_EPS_T 1e-12   /* core/bsdf.c's COS_EPS: below it f = pdf = 0 */

/* ---------------------------------------------------------------- helpers */

struct rng { uint64_t s; };
static double rng_next(struct rng *r)
{
    r->s += 0x9e3779b97f4a7c15ULL;
    return (double)(dr_hash64(r->s) >> 11) * (1.0 / 9007199254740992.0);
}
static double rng_sym(struct rng *r) { return 2.0 * rng_next(r) - 1.0; }

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
    return finite3(d->base_color) && isfinite(d->metallic) && isfinite(d->roughness) && isfinite(d->coat) &&
           isfinite(d->coat_roughness) && isfinite(d->anisotropy) && finite3(d->sheen_color) &&
           isfinite(d->sheen_roughness);
}
static double test_alpha(double rough) { return fmax(rough * rough, DR_BSDF_MIN_ALPHA); }

/* ------------------------------------------------ inputs and configurations */

/* Every differentiable input, by index. */
/* (the sheen's last, so that the older inputs keep their indices) */
enum { X_BR, X_BG, X_BB, X_M, X_R, X_C, X_CR, X_A, X_OX, X_OY, X_OZ, X_IX, X_IY, X_IZ, X_SR, X_SG, X_SB, X_SRO, NX };
static const char *const x_name[NX] = {"base.r", "base.g", "base.b", "metallic", "roughness", "coat", "coat_roughness",
                                       "anisotropy", "wo.x",   "wo.y",   "wo.z",   "wi.x",     "wi.y",     "wi.z",
                                       "sheen.r",    "sheen.g", "sheen.b", "sheen_roughness"};

/* One point at which a function and its adjoint are compared. */
struct cfg {
    struct dr_bsdf b;
    dr_vec3 wo, wi;
    dr_vec3 d3;     /* d loss / d f (eval), d loss / d wi (sampling map) */
    double d1;      /* d loss / d pdf, d loss / d p */
    enum dr_bsdf_lobe lobe;
    double u1, u2;
    double p_fix, pc_fix, ps_fix;   /* d_bsdf_pdf_fixed_prob: the lobe probabilities held (set_fixed_probs) */
};

static double *x_ptr(struct cfg *c, int k)
{
    switch (k) {
    case X_BR: return &c->b.base_color.x;
    case X_BG: return &c->b.base_color.y;
    case X_BB: return &c->b.base_color.z;
    case X_M:  return &c->b.metallic;
    case X_R:  return &c->b.roughness;
    case X_C:  return &c->b.coat;
    case X_CR: return &c->b.coat_roughness;
    case X_A:  return &c->b.anisotropy;
    case X_OX: return &c->wo.x;
    case X_OY: return &c->wo.y;
    case X_OZ: return &c->wo.z;
    case X_IX: return &c->wi.x;
    case X_IY: return &c->wi.y;
    case X_SR: return &c->b.sheen_color.x;
    case X_SG: return &c->b.sheen_color.y;
    case X_SB: return &c->b.sheen_color.z;
    case X_SRO: return &c->b.sheen_roughness;
    default:   return &c->wi.z;
    }
}
static double x_get(const struct cfg *c, int k) { return *x_ptr((struct cfg *)c, k); }

/* Unpacks adjoint outputs into g[NX]. */
static void g_from(double g[NX], const struct dr_d_bsdf *d, dr_vec3 dwo, dr_vec3 dwi)
{
    g[X_BR] = d->base_color.x; g[X_BG] = d->base_color.y; g[X_BB] = d->base_color.z;
    g[X_M] = d->metallic; g[X_R] = d->roughness; g[X_C] = d->coat; g[X_CR] = d->coat_roughness;
    g[X_A] = d->anisotropy;
    g[X_OX] = dwo.x; g[X_OY] = dwo.y; g[X_OZ] = dwo.z;
    g[X_IX] = dwi.x; g[X_IY] = dwi.y; g[X_IZ] = dwi.z;
    g[X_SR] = d->sheen_color.x; g[X_SG] = d->sheen_color.y; g[X_SB] = d->sheen_color.z;
    g[X_SRO] = d->sheen_roughness;
}

/* Test-side lobe weights of dr_bsdf_specular_prob (textbook form of the model
 * in bsdf.h): p = ws / (ws + wd) jumps only where ws + wd = 0. */
static double ref_weight_sum(const struct dr_bsdf *b, double cos_o)
{
    double s5 = pow(1.0 - fmin(fmax(cos_o, 0.0), 1.0), 5.0);
    dr_vec3 sc = b->specular_color;
    double f0max = fmax(fmin(0.04 * sc.x, 1.0), fmax(fmin(0.04 * sc.y, 1.0), fmin(0.04 * sc.z, 1.0))) * b->specular;
    double fd = f0max + (b->specular - f0max) * s5;
    dr_vec3 bc = b->base_color;
    double lfm = dr_luminance(dr_v3(bc.x + (1 - bc.x) * s5, bc.y + (1 - bc.y) * s5, bc.z + (1 - bc.z) * s5));
    double m = b->metallic;
    return (1.0 - m) * fd + m * lfm + (1.0 - m) * (1.0 - fd) * dr_luminance(bc);
}

/* Regimes: which side of each kink of the primal a configuration is on. A
 * difference is taken only between points of the same regime. */
static int regime_coat(const struct cfg *c)
{
    return c->b.coated | (c->b.coat_roughness * c->b.coat_roughness > DR_BSDF_MIN_ALPHA) << 1;
}
/* A sheen (bsdf_sheen.c): the roughness floor, the clamps of T(wo), T(wi)
 * (and of P = 1 - T(wo)) at m E = 1, the channel of m = max(colour), and the
 * cosines' clamps at 1 (Lambda's argument, E's mu), and h along the normal. */
static double ref_sheen_mE(const struct cfg *c, double cos)
{
    const dr_vec3 s = c->b.sheen_color;
    return fmax(s.x, fmax(s.y, s.z)) * dr_sheen_albedo(cos, c->b.sheen_roughness, NULL, NULL);
}
static int regime_sheen(const struct cfg *c)
{
    if (!c->b.sheened)
        return 0;
    const dr_vec3 s = c->b.sheen_color;
    const int arg = s.y > s.x ? (s.z > s.y ? 2 : 1) : (s.z > s.x ? 2 : 0);
    return 1 | (c->b.sheen_roughness >= DR_SHEEN_MIN_ROUGHNESS) << 1 | (ref_sheen_mE(c, c->wo.z) < 1.0) << 2 |
           (ref_sheen_mE(c, c->wi.z) < 1.0) << 3 | arg << 4 | (c->wo.z < 1.0) << 6 | (c->wi.z < 1.0) << 7 |
           /* h along the normal: D ~ |Hxy|^(1/alpha) is a cone at alpha = 1 */
           (c->wo.x + c->wi.x != 0.0 || c->wo.y + c->wi.y != 0.0) << 8;
}
static int regime_common(const struct cfg *c)
{
    return (c->wo.z > COS_EPS_T) | (c->wi.z > COS_EPS_T) << 1 |
           (c->b.roughness * c->b.roughness > DR_BSDF_MIN_ALPHA) << 2 | regime_coat(c) << 4 | regime_sheen(c) << 8;
}
static int regime_eval(const struct cfg *c) { return regime_common(c); }
static int regime_pdf(const struct cfg *c)
{
    return regime_common(c) | (ref_weight_sum(&c->b, c->wo.z) > 0.0) << 3;
}
static int regime_prob(const struct cfg *c)
{
    return (c->wo.z > COS_EPS_T) | (ref_weight_sum(&c->b, c->wo.z > COS_EPS_T ? c->wo.z : 0.0) > 0.0) << 1 |
           regime_coat(c) << 2 | regime_sheen(c) << 8;
}
/* Sampling map: wo above the surface, the roughness floor, the frame branch
 * at wo along the normal (where the map is discontinuous), and whether the
 * sample is accepted (a rejected sample has no derivative to check; the
 * max(0, nh.z) clamp only acts on rejected samples). */
static int regime_sample(const struct cfg *c)
{
    int r = (c->wo.z > COS_EPS_T) | (c->b.roughness * c->b.roughness > DR_BSDF_MIN_ALPHA) << 1 |
            (c->wo.x != 0.0 || c->wo.y != 0.0) << 2 | regime_coat(c) << 4 | regime_sheen(c) << 8;
    if (c->wo.z > COS_EPS_T) {
        dr_vec3 wi = dr_bsdf_sample_dir(&c->b, c->wo, c->lobe, c->u1, c->u2);
        r |= (wi.z > COS_EPS_T) << 3;
    }
    return r;
}

/* Lengths over which the primals change in the directions: the lobe width
 * alpha |H.z| in the half vector, the cosines (Smith Lambda, 1/cos), and for
 * the sampling map the distance of wo from the normal (the frame's azimuth). */
static double feature_eval(const struct cfg *c)
{
    double hz = c->wo.z + c->wi.z;
    double a = c->b.coated ? fmin(test_alpha(c->b.roughness), test_alpha(c->b.coat_roughness)) : test_alpha(c->b.roughness);
    /* and the Schlick weight's (1 - |H|/2)^5, which can carry all of f (a
     * black metal): its scale 1 - |H|/2, above 1e-4 */
    double oc = 1.0 - 0.5 * dr_length(dr_add(c->wo, c->wi));
    double f = 1.0;
    if (c->b.sheened) {   /* the sheen lobe's width sqrt(alpha) |H| in the half vector, at its floor, */
        a = fmin(a, fmax(c->b.sheen_roughness, DR_SHEEN_MIN_ROUGHNESS));
        /* and its Lambda's (1 - cos)^c near normal incidence (cos = 1 itself is flat) */
        if (c->wo.z < 1.0)
            f = fmin(f, 1.0 - c->wo.z);
        if (c->wi.z < 1.0)
            f = fmin(f, 1.0 - c->wi.z);
    }
    return fmin(f, fmin(fmin(1.0, fmax(oc, 1e-4)), fmin(a * hz, fmin(c->wo.z, c->wi.z))));
}
static double feature_prob(const struct cfg *c) { return fmin(1.0, fmax(c->wo.z, 1e-6)); }
static double feature_sample(const struct cfg *c)
{
    double sxy = hypot(c->wo.x, c->wo.y);   /* 0: on the frame's branch point, x and y are skipped */
    return fmin(1.0, fmin(c->wo.z, sxy > 0.0 ? sxy : 1.0));
}

/* ---------------------------------------------- functions under test */

static double loss_eval(const struct cfg *c) { return dr_dot(c->d3, dr_bsdf_eval(&c->b, c->wo, c->wi)); }
static double mag_eval(const struct cfg *c)
{
    dr_vec3 f = dr_bsdf_eval(&c->b, c->wo, c->wi);
    return fabs(c->d3.x * f.x) + fabs(c->d3.y * f.y) + fabs(c->d3.z * f.z);
}
static void adj_eval(const struct cfg *c, double g[NX])
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
    d_bsdf_eval(&c->b, c->wo, c->wi, c->d3, &d, &dwo, &dwi);
    g_from(g, &d, dwo, dwi);
}

static double loss_pdf(const struct cfg *c) { return c->d1 * dr_bsdf_pdf(&c->b, c->wo, c->wi); }
/* The pdf is (1-p) wi.z/pi + p P_s: each term is rounded on its own scale,
 * which can exceed the pdf by far when p is close to 1 (P_s <= pdf / p). */
static double mag_pdf(const struct cfg *c)
{
    double pdf = dr_bsdf_pdf(&c->b, c->wo, c->wi), p = dr_bsdf_specular_prob(&c->b, c->wo);
    return fabs(c->d1) * (pdf + fabs(c->wi.z) * DR_INV_PI + (p > 0.0 ? pdf / p : 0.0));
}
static void adj_pdf(const struct cfg *c, double g[NX])
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
    d_bsdf_pdf(&c->b, c->wo, c->wi, c->d1, &d, &dwo, &dwi);
    g_from(g, &d, dwo, dwi);
}

static double loss_prob(const struct cfg *c) { return c->d1 * dr_bsdf_specular_prob(&c->b, c->wo); }
static double mag_prob(const struct cfg *c) { return fabs(c->d1); }
static void adj_prob(const struct cfg *c, double g[NX])
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0);
    d_bsdf_specular_prob(&c->b, c->wo, c->d1, &d, &dwo);
    g_from(g, &d, dwo, dr_v3s(0.0));
}

static double loss_sample(const struct cfg *c)
{
    return dr_dot(c->d3, dr_bsdf_sample_dir(&c->b, c->wo, c->lobe, c->u1, c->u2));
}
static double mag_sample(const struct cfg *c) { return fabs(c->d3.x) + fabs(c->d3.y) + fabs(c->d3.z); }
static void adj_sample(const struct cfg *c, double g[NX])
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0);
    d_bsdf_sample_dir(&c->b, c->wo, c->lobe, c->u1, c->u2, c->d3, &d, &dwo);
    g_from(g, &d, dwo, dr_v3s(0.0));
}

/* d_bsdf_pdf_fixed_prob's primal: the pdf with the lobe probabilities held
 * at p_fix (the base's specular lobe) and pc_fix (a coat's lobe), test-side:
 *   pdf = pc P_s,coat + (1 - pc) ((1 - p) wi.z / pi + p P_s),
 * the specular densities P_s as dr_bsdf_pdf of a white metal of the lobe's
 * alphas (its lobe probability is 1). */
static double pdf_fixed(const struct cfg *c)
{
    if (!(c->wo.z > COS_EPS_T) || !(c->wi.z > COS_EPS_T))
        return 0.0;
    struct dr_bsdf m = make_bsdf(c->b.roughness, 1.0, 1.0, dr_v3s(1.0), dr_v3s(1.0));
    m.anisotropy = c->b.anisotropy;
    double base = (1.0 - c->p_fix) * c->wi.z * DR_INV_PI + c->p_fix * dr_bsdf_pdf(&m, c->wo, c->wi);
    if (c->b.sheened)   /* the sheen's cosine lobe held at ps_fix */
        base = c->ps_fix * c->wi.z * DR_INV_PI + (1.0 - c->ps_fix) * base;
    if (!c->b.coated)
        return base;
    struct dr_bsdf cl = make_bsdf(c->b.coat_roughness, 1.0, 1.0, dr_v3s(1.0), dr_v3s(1.0));
    return c->pc_fix * dr_bsdf_pdf(&cl, c->wo, c->wi) + (1.0 - c->pc_fix) * base;
}
static void set_fixed_probs(struct cfg *c)
{
    struct dr_bsdf u = c->b;
    u.coated = false;
    u.sheened = false;
    c->p_fix = dr_bsdf_specular_prob(&u, c->wo);
    c->ps_fix = c->b.sheened ? fmin(1.0, ref_sheen_mE(c, c->wo.z > COS_EPS_T ? c->wo.z : 0.0)) : 0.0;
    double x = fmin(fmax(c->wo.z, 0.0), 1.0);
    c->pc_fix = c->b.coated ? c->b.coat * (0.04 + 0.96 * pow(1.0 - x, 5.0)) : 0.0;
}
static double loss_pdf_fixed(const struct cfg *c) { return c->d1 * pdf_fixed(c); }
static double mag_pdf_fixed(const struct cfg *c) { return fabs(c->d1) * (pdf_fixed(c) + fabs(c->wi.z) * DR_INV_PI); }
static void adj_pdf_fixed(const struct cfg *c, double g[NX])
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
    d_bsdf_pdf_fixed_prob(&c->b, c->wo, c->wi, c->d1, &d, &dwo, &dwi);
    g_from(g, &d, dwo, dwi);
}

struct fn {
    const char *name;
    double (*loss)(const struct cfg *);
    double (*mag)(const struct cfg *);      /* scale of the loss's rounding error */
    void (*adjoint)(const struct cfg *, double g[NX]);
    int (*regime)(const struct cfg *);
    double (*feature)(const struct cfg *);
    /* statistics */
    long checks, one_sided, skipped, id_checks, id_skipped;
    double worst_rel, worst_ratio, id_worst_rel, id_worst_ratio;
};

static struct fn fn_eval = {"d_bsdf_eval", loss_eval, mag_eval, adj_eval, regime_eval, feature_eval, 0, 0, 0, 0, 0, 0, 0, 0, 0};
static struct fn fn_pdf = {"d_bsdf_pdf", loss_pdf, mag_pdf, adj_pdf, regime_pdf, feature_eval, 0, 0, 0, 0, 0, 0, 0, 0, 0};
static struct fn fn_prob = {"d_bsdf_specular_prob", loss_prob, mag_prob, adj_prob, regime_prob, feature_prob,
                            0, 0, 0, 0, 0, 0, 0, 0, 0};
static struct fn fn_pdf_fixed = {"d_bsdf_pdf_fixed_prob", loss_pdf_fixed, mag_pdf_fixed, adj_pdf_fixed, regime_eval,
                                 feature_eval, 0, 0, 0, 0, 0, 0, 0, 0, 0};
static struct fn fn_sample = {"d_bsdf_sample_dir", loss_sample, mag_sample, adj_sample, regime_sample,
                              feature_sample, 0, 0, 0, 0, 0, 0, 0, 0, 0};

/* ------------------------------------------------ finite differences */

#define RTOL 1e-5

/* Step for input k, scaled to the length over which the primal changes:
 *  - base colour and metallic: 1e-6, as in tests/test_derivatives.c; but the
 *    lobe probability p = ws / (ws + wd) changes over the scale of ws + wd
 *    itself (tiny for a black base at near-normal incidence), so for p and
 *    the pdf the step is 1e-6 (ws + wd);
 *  - roughness: relative, so alpha's relative change stays ~2e-6;
 *  - directions: 1e-5 of the feature length (truncation ~1e-10 relative),
 *    raised to 1e-10 where that is smaller (rounding of a difference grows
 *    as eps / step), but never above 1e-3 of the feature length. */
static double step_for(const struct fn *f, const struct cfg *c, int k)
{
    if (k == X_SR || k == X_SG || k == X_SB)
        return 1e-6;
    if (k == X_SRO)
        return 1e-6 * fmax(c->b.sheen_roughness, 1e-2);
    if (k <= X_M) {
        if (f->regime != regime_pdf && f->regime != regime_prob)
            return 1e-6;
        double ws_wd = ref_weight_sum(&c->b, c->wo.z > COS_EPS_T ? c->wo.z : 0.0);
        return ws_wd > 0.0 ? 1e-6 * fmin(1.0, ws_wd) : 1e-6;
    }
    if (k == X_R)
        return 1e-6 * fmax(c->b.roughness, 1e-4);
    if (k == X_CR)
        return 1e-6 * fmax(c->b.coat_roughness, 1e-4);
    if (k == X_C)
        return 1e-6;
    if (k == X_A) {
        /* alpha_x = alpha + (1 - alpha) s^2: relative to alpha_x (>= alpha, maybe
         * 1e-7) a step moves it by ~2 s h / alpha_x, or h^2 / alpha at s = 0,
         * where the one-sided difference of a zero derivative is all
         * truncation; sqrt(alpha_x) keeps both near 1e-6 or below */
        double a = test_alpha(c->b.roughness), s = c->b.anisotropy;
        return 1e-6 * fmin(1.0, sqrt(a + (1.0 - a) * s * s));
    }
    double ell = f->feature(c);
    return fmax(1e-5 * ell, fmin(1e-10, 1e-3 * ell));
}

static double loss_at(const struct fn *f, const struct cfg *c, int k, double x, int *reg)
{
    struct cfg t = *c;
    *x_ptr(&t, k) = x;
    *reg = f->regime(&t);
    return f->loss(&t);
}

/* Second-order difference of the loss in input k: central where the domain
 * ([0, 1] for the parameters) and the regime allow, else one-sided
 * (forward (-3 f0 + 4 f1 - f2) / 2h, backward (3 f0 - 4 f1 + f2) / 2h).
 * *kind: 0 central, 1 one-sided, -1 not possible (skipped). */
static double fd_input(const struct fn *f, const struct cfg *c, int k, double h, int *kind)
{
    double x = x_get(c, k);
    const bool param = k <= X_A || k >= X_SR;
    double lo = param ? 0.0 : -INFINITY, hi = param ? 1.0 : INFINITY;
    int r0 = f->regime(c), rm, rp, r2;
    double f0 = f->loss(c);
    double fp = x + h <= hi ? loss_at(f, c, k, x + h, &rp) : NAN;
    double fm = x - h >= lo ? loss_at(f, c, k, x - h, &rm) : NAN;
    if (x + h <= hi && x - h >= lo && rp == r0 && rm == r0) {
        *kind = 0;
        return (fp - fm) / (2.0 * h);
    }
    *kind = 1;
    if (x + 2.0 * h <= hi && rp == r0) {
        double f2 = loss_at(f, c, k, x + 2.0 * h, &r2);
        if (r2 == r0)
            return (-3.0 * f0 + 4.0 * fp - f2) / (2.0 * h);
    }
    if (x - 2.0 * h >= lo && rm == r0) {
        double f2 = loss_at(f, c, k, x - 2.0 * h, &r2);
        if (r2 == r0)
            return (3.0 * f0 - 4.0 * fm + f2) / (2.0 * h);
    }
    *kind = -1;
    return 0.0;
}

static void record(struct fn *f, double ad, double fd, double tol, double floor_abs)
{
    double scale = fmax(fabs(ad), fabs(fd));
    double ratio = fabs(ad - fd) / tol;
    if (ratio > f->worst_ratio)
        f->worst_ratio = ratio;
    if (scale > 1e3 * floor_abs && fabs(ad - fd) / scale > f->worst_rel)
        f->worst_rel = fabs(ad - fd) / scale;
}

static void print_cfg(const char *fname, const char *what, const struct cfg *c)
{
    fprintf(stderr,
            "    %s %s: r %.17g aniso %.17g m %g s %g base (%g %g %g) wo (%.17g %.17g %.17g) wi (%.17g %.17g %.17g) "
            "lobe %d u (%.17g %.17g) coat %d %.17g r %.17g sheen %d (%.17g %.17g %.17g) r %.17g\n",
            fname, what, c->b.roughness, c->b.anisotropy, c->b.metallic, c->b.specular, c->b.base_color.x, c->b.base_color.y,
            c->b.base_color.z, c->wo.x, c->wo.y, c->wo.z, c->wi.x, c->wi.y, c->wi.z, (int)c->lobe, c->u1, c->u2,
            (int)c->b.coated, c->b.coat, c->b.coat_roughness, (int)c->b.sheened, c->b.sheen_color.x, c->b.sheen_color.y,
            c->b.sheen_color.z, c->b.sheen_roughness);
}

/* Compares every input's adjoint with its difference at one configuration.
 * Tolerance: RTOL relative (truncation) plus the rounding of a difference,
 * (eps-level error of the loss) / h, with that error bounded by
 * 1e-13 |terms of the loss| + 1e-14 sum_j |dL/dx_j| |x_j| (every rounding
 * inside the primal acts like a relative perturbation of its inputs; the
 * differences themselves supply dL/dx_j, not the adjoint under test). */
static void check_fd(struct fn *f, const struct cfg *c)
{
    double g[NX], fd[NX], h[NX];
    int kind[NX];
    f->adjoint(c, g);
    double cond = 0.0;
    for (int k = 0; k < NX; k++) {
        h[k] = step_for(f, c, k);
        fd[k] = fd_input(f, c, k, h[k], &kind[k]);
        if (kind[k] >= 0)
            cond += fabs(fd[k]) * fmax(fabs(x_get(c, k)), 1e-300);
    }
    double mag = f->mag(c);
    for (int k = 0; k < NX; k++) {
        bool fin = isfinite(g[k]);
        CHECK(fin, "%s d/d%s not finite (%g)", f->name, x_name[k], g[k]);
        if (!fin)
            print_cfg(f->name, "non-finite", c);
        if (kind[k] < 0) {
            f->skipped++;
            continue;
        }
        f->checks++;
        if (kind[k] == 1)
            f->one_sided++;
        double floor_abs = (1e-13 * mag + 1e-14 * cond) / h[k];
        double tol = RTOL * fmax(fabs(g[k]), fabs(fd[k])) + floor_abs;
        record(f, g[k], fd[k], tol, floor_abs);
        bool ok = fabs(g[k] - fd[k]) <= tol;
        CHECK(ok, "%s d/d%s: adjoint %.12g vs FD %.12g (tol %.3g, h %.3g, %s)", f->name, x_name[k], g[k], fd[k],
              tol, h[k], kind[k] ? "one-sided" : "central");
        if (!ok)
            print_cfg(f->name, "at", c);
    }
}

/* ------------------------------------------------ random configurations */

static const double roughs[] = {1.0, 0.5, 0.2, 0.05, 0.01, 0.001};
#define NROUGH ((int)(sizeof roughs / sizeof *roughs))
static const double metals[] = {0.0, 0.5, 1.0};
static const double specs[] = {0.0, 1.0};

static dr_vec3 random_base(struct rng *r, int kind)
{
    if (kind == 0)
        return dr_v3s(0.0);
    if (kind == 1)
        return dr_v3s(1.0);
    return dr_v3(rng_next(r), rng_next(r), rng_next(r));
}

/* wo: generic, grazing (1e-3, 1e-6), normal-ish (1 - 1e-9) or exactly normal. */
static dr_vec3 random_wo(struct rng *r, int n)
{
    double phi = 2.0 * M_PI * rng_next(r);
    switch (n % 8) {
    case 5: return dir_from(1e-3, phi);
    case 6: return dir_from(1e-6, phi);
    case 7: return n % 16 == 7 ? dir_from(1.0 - 1e-9, phi) : dr_v3(0.0, 0.0, 1.0);
    default: return dir_from(0.02 + 0.98 * rng_next(r), phi);
    }
}

/* wi: generic, near the mirror direction (h within ~2 alpha of n), nearly along
 * the normal, or exactly mirrored (H along z). */
static dr_vec3 random_wi(struct rng *r, dr_vec3 wo, double alpha, int n)
{
    dr_vec3 wi;
    switch (n % 5) {
    case 1: {
        double s = 2.0 * alpha;
        dr_vec3 h = dr_normalize(dr_v3(s * rng_sym(r), s * rng_sym(r), 1.0));
        wi = reflect(wo, h);
        break;
    }
    case 2: wi = dir_from(1.0 - 1e-10 * rng_next(r), 2.0 * M_PI * rng_next(r)); break;
    case 3: wi = reflect(wo, dr_v3(0.0, 0.0, 1.0)); break;
    default: wi = dir_from(0.02 + 0.98 * rng_next(r), 2.0 * M_PI * rng_next(r)); break;
    }
    if (!(wi.z > 1e-6))
        wi = dir_from(0.02 + 0.98 * rng_next(r), 2.0 * M_PI * rng_next(r));
    return wi;
}

/* A clear coat (bsdf_coat.c): factor inside (0, 1), 1, or 0 with the layer
 * still there (a fit moved it to 0); roughness from smooth to rough; the
 * sampled lobe the coat's a third of the time. */
static void random_coat(struct rng *r, struct cfg *c, int n)
{
    static const double coat_roughs[] = {0.03, 0.2, 0.6, 1.0};
    c->b.coated = true;
    c->b.coat = n % 5 == 1 ? 1.0 : n % 5 == 2 ? 0.0 : 0.05 + 0.9 * rng_next(r);
    c->b.coat_roughness = n % 7 == 3 ? 0.01 + 0.98 * rng_next(r) : coat_roughs[n % 4];
    if (n % 3 == 0)
        c->lobe = DR_BSDF_LOBE_COAT;
}

static struct cfg random_cfg(struct rng *r, double rough, double metal, double spec, int n)
{
    struct cfg c;
    memset(&c, 0, sizeof c);
    dr_vec3 sc = n % 7 == 3 ? dr_v3(0.5 + rng_next(r), 0.5 + rng_next(r), 0.5 + rng_next(r)) : dr_v3s(1.0);
    c.b = make_bsdf(rough, metal, spec, random_base(r, n % 6 == 0 ? 0 : (n % 6 == 1 ? 1 : 2)), sc);
    c.wo = random_wo(r, n);
    c.wi = random_wi(r, c.wo, test_alpha(rough), n / 8);
    c.d3 = dr_v3(rng_sym(r), rng_sym(r), rng_sym(r));
    c.d1 = rng_sym(r);
    c.lobe = (n / 3) % 2 ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
    c.u1 = 0.98 * rng_next(r);   /* the rim u1 -> 1 (unbounded slope) is a hard case, g. */
    c.u2 = rng_next(r);
    if (n % 4 == 3)
        random_coat(r, &c, n / 4);
    return c;
}

/* a.-c.: every function over the grid of materials and random directions. */
static void test_fd_all(void)
{
    struct rng r = {20261123};
    for (int ir = 0; ir <= NROUGH; ir++)
        for (int im = 0; im < 3; im++)
            for (int is = 0; is < 2; is++)
                for (int n = 0; n < 120; n++) {
                    /* ir == NROUGH: log-uniform roughness in [0.001, 1] */
                    double rough = ir < NROUGH ? roughs[ir] : pow(10.0, -3.0 * rng_next(&r));
                    struct cfg c = random_cfg(&r, rough, metals[im], specs[is], n);
                    check_fd(&fn_eval, &c);
                    check_fd(&fn_pdf, &c);
                    check_fd(&fn_prob, &c);
                    check_fd(&fn_sample, &c);
                }
    /* near and at the roughness floor (sqrt(DR_BSDF_MIN_ALPHA) ~ 3.2e-4) */
    static const double floor_r[] = {0.0011, 0.0004, 0.00032, 0.0003, 0.0001, 0.0};
    for (size_t ir = 0; ir < sizeof floor_r / sizeof *floor_r; ir++)
        for (int n = 0; n < 40; n++) {
            struct cfg c = random_cfg(&r, floor_r[ir], n % 2 ? 1.0 : 0.3, 0.5, n);
            check_fd(&fn_eval, &c);
            check_fd(&fn_pdf, &c);
            check_fd(&fn_sample, &c);
            if (floor_r[ir] * floor_r[ir] <= DR_BSDF_MIN_ALPHA) {
                double g[NX];
                fn_eval.adjoint(&c, g);
                CHECK(g[X_R] == 0.0, "below the floor: eval d roughness %g", g[X_R]);
                fn_pdf.adjoint(&c, g);
                CHECK(g[X_R] == 0.0, "below the floor: pdf d roughness %g", g[X_R]);
                fn_sample.adjoint(&c, g);
                CHECK(g[X_R] == 0.0, "below the floor: sample d roughness %g", g[X_R]);
            }
        }
}

/* ------------------------------------------------------ d. d_mis_power */

static long mis_checks;
static double mis_worst_rel, mis_worst_ratio;

static void check_mis(double pa, double pb, double d_w)
{
    double ga = 0.0, gb = 0.0;
    d_mis_power(pa, pb, d_w, &ga, &gb);
    double w = dr_mis_power(pa, pb);
    const double x[2] = {pa, pb}, g[2] = {ga, gb};
    for (int k = 0; k < 2; k++) {
        double h = 1e-6 * x[k];
        double fp = d_w * (k ? dr_mis_power(pa, pb + h) : dr_mis_power(pa + h, pb));
        double fm = d_w * (k ? dr_mis_power(pa, pb - h) : dr_mis_power(pa - h, pb));
        double fd = (fp - fm) / (2.0 * h);
        double floor_abs = 1e-14 * fabs(d_w) * fmax(w, 1e-300) / h;
        double scale = fmax(fabs(g[k]), fabs(fd));
        double tol = RTOL * scale + floor_abs;
        mis_checks++;
        mis_worst_ratio = fmax(mis_worst_ratio, fabs(g[k] - fd) / tol);
        if (scale > 1e3 * floor_abs)
            mis_worst_rel = fmax(mis_worst_rel, fabs(g[k] - fd) / scale);
        CHECK(isfinite(g[k]) && fabs(g[k] - fd) <= tol, "d_mis_power d/d%s at (%g, %g): adjoint %.12g vs FD %.12g",
              k ? "pb" : "pa", pa, pb, g[k], fd);
    }
}

static void test_mis(void)
{
    struct rng r = {4711};
    for (int n = 0; n < 4000; n++) {
        double pa = pow(10.0, 12.0 * rng_next(&r) - 6.0);
        double pb = n % 4 == 0 ? pa * (1.0 + 0.1 * rng_sym(&r)) : pow(10.0, 12.0 * rng_next(&r) - 6.0);
        check_mis(pa, pb, rng_sym(&r));
    }
    /* huge and tiny densities and ratios: finite, and zero on the primal's branches */
    const double v[] = {0.0, -1.0, 1e-300, 1e-150, 1e-8, 1.0, 1e8, 1e150, 1e300, INFINITY};
    const int nv = (int)(sizeof v / sizeof *v);
    for (int i = 0; i < nv; i++)
        for (int j = 0; j < nv; j++) {
            double ga = 0.0, gb = 0.0;
            d_mis_power(v[i], v[j], 1.0, &ga, &gb);
            CHECK(isfinite(ga) && isfinite(gb), "d_mis_power(%g, %g) not finite: %g %g", v[i], v[j], ga, gb);
            if (!(v[i] > 0.0) || !(v[j] > 0.0))
                CHECK(ga == 0.0 && gb == 0.0, "d_mis_power(%g, %g) on a branch: %g %g", v[i], v[j], ga, gb);
            d_mis_power(v[i], v[j], 1.0, NULL, NULL);
        }
}

/* ------------------------------------- e. forward-mode identity <d_out, J v> */

/* For interior configurations (every parameter inside (0, 1), roughness
 * above the floor), a random direction v in all inputs at once, scaled per
 * input like the steps: the difference (L(x + t v) - L(x - t v)) / 2t of the
 * primal along v must equal <adjoint, v>. */
static void check_identity(struct fn *f, const struct cfg *c, struct rng *r)
{
    double g[NX], v[NX];
    f->adjoint(c, g);
    double ell = f->feature(c);
    for (int k = 0; k < NX; k++)
        v[k] = rng_sym(r) * (k == X_R ? c->b.roughness : k == X_CR ? c->b.coat_roughness : k == X_SRO ? c->b.sheen_roughness
                                                                                          : k <= X_A || k >= X_SR ? 1.0 : ell);
    const double t = 1e-5;
    struct cfg cp = *c, cm = *c;
    for (int k = 0; k < NX; k++) {
        *x_ptr(&cp, k) += t * v[k];
        *x_ptr(&cm, k) -= t * v[k];
    }
    int r0 = f->regime(c);
    if (f->regime(&cp) != r0 || f->regime(&cm) != r0) {
        f->id_skipped++;
        return;
    }
    double fd = (f->loss(&cp) - f->loss(&cm)) / (2.0 * t);
    double ad = 0.0, cond = 0.0;
    for (int k = 0; k < NX; k++) {
        ad += g[k] * v[k];
        cond += fabs(g[k] * v[k]);
    }
    /* truncation relative to the sum of the terms (they may cancel), rounding as in check_fd */
    double floor_abs = (1e-13 * f->mag(c) + 1e-14 * cond) / t;
    double tol = RTOL * fmax(cond, fabs(fd)) + floor_abs;
    f->id_checks++;
    f->id_worst_ratio = fmax(f->id_worst_ratio, fabs(ad - fd) / tol);
    double scale = fmax(fabs(ad), fabs(fd));
    /* DR_TEST_VERBOSE=1: show the identity checks that agree least (usually
     * a small <g, v> out of large, cancelling terms) */
    if (getenv("DR_TEST_VERBOSE") && scale > 1e3 * floor_abs && fabs(ad - fd) / scale > 5e-6) {
        fprintf(stderr, "  identity %s: rel %.2e, <g,v> %.12g, sum |g_k v_k| %.3g\n", f->name, fabs(ad - fd) / scale, ad, cond);
        print_cfg(f->name, "identity", c);
    }
    if (scale > 1e3 * floor_abs)
        f->id_worst_rel = fmax(f->id_worst_rel, fabs(ad - fd) / scale);
    bool ok = isfinite(ad) && fabs(ad - fd) <= tol;
    CHECK(ok, "%s forward-mode identity: <adjoint, v> %.12g vs FD along v %.12g (tol %.3g)", f->name, ad, fd, tol);
    if (!ok)
        print_cfg(f->name, "identity", c);
}

static void test_identity(void)
{
    struct rng r = {8675309};
    for (int n = 0; n < 3000; n++) {
        struct cfg c;
        memset(&c, 0, sizeof c);
        double rough = n % 3 == 0 ? 0.01 + 0.94 * rng_next(&r) : pow(10.0, -2.0 * rng_next(&r)) * 0.95;
        double metal = n % 3 == 0 ? 0.5 : 0.05 + 0.9 * rng_next(&r);
        c.b = make_bsdf(rough, metal, n % 2 ? 1.0 : 0.0,
                        dr_v3(0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r)),
                        dr_v3s(1.0));
        c.wo = dir_from(n % 10 == 0 ? 1e-3 : 0.02 + 0.98 * rng_next(&r), 2.0 * M_PI * rng_next(&r));
        c.wi = random_wi(&r, c.wo, test_alpha(rough), n);
        c.d3 = dr_v3(rng_sym(&r), rng_sym(&r), rng_sym(&r));
        c.d1 = rng_sym(&r);
        c.lobe = n % 4 ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
        c.u1 = 0.98 * rng_next(&r);
        c.u2 = rng_next(&r);
        if (n % 3 == 1) {   /* coated, factor inside (0, 1) */
            random_coat(&r, &c, 5 * (n / 3) + 3);
            c.b.coat = 0.05 + 0.9 * rng_next(&r);
        }
        check_identity(&fn_eval, &c, &r);
        check_identity(&fn_pdf, &c, &r);
        check_identity(&fn_prob, &c, &r);
        check_identity(&fn_sample, &c, &r);
    }
}

/* ------------------------------------------------------ f. bit-identity */

/* d_bsdf_eval as it was before the direction adjoints (commit 7692fbe), frozen
 * verbatim with its helpers: the estimators rely on its parameter part staying
 * bit for bit the same. */
static inline double old_pow5(double s)
{
    double s2 = s * s;
    return s2 * s2 * s;
}
static inline double old_alpha(const struct dr_bsdf *b)
{
    double a = b->roughness * b->roughness;
    return a > DR_BSDF_MIN_ALPHA ? a : DR_BSDF_MIN_ALPHA;
}
static inline dr_vec3 old_f0(const struct dr_bsdf *b)
{
    dr_vec3 sc = b->specular_color;
    return dr_v3(dr_min(0.04 * sc.x, 1.0) * b->specular, dr_min(0.04 * sc.y, 1.0) * b->specular,
                 dr_min(0.04 * sc.z, 1.0) * b->specular);
}
/* Verbatim body; one function as it was (~70 lines). */
static void old_d_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d)
{
    if (!(wo.z > COS_EPS_T) || !(wi.z > COS_EPS_T))
        return;
    const bool lambert = b->metallic == 0.0 && b->specular == 0.0;
    const double m = b->metallic;
    const dr_vec3 base = b->base_color;
    double a = old_alpha(b), a2 = a * a;
    dr_vec3 H = dr_add(wo, wi);
    double hxy2 = H.x * H.x + H.y * H.y;
    double hz2 = H.z * H.z;
    double H2 = hxy2 + hz2;
    double q = hxy2 + a2 * hz2;
    double r = H2 / q;
    double D = a2 * r * r * DR_INV_PI;
    double tan2o = (wo.x * wo.x + wo.y * wo.y) / (wo.z * wo.z);
    double tan2i = (wi.x * wi.x + wi.y * wi.y) / (wi.z * wi.z);
    double xo = a2 * tan2o, xi = a2 * tan2i;
    double so = sqrt(1.0 + xo), si = sqrt(1.0 + xi);
    double lo = 0.5 * xo / (1.0 + so), li = 0.5 * xi / (1.0 + si);
    double g = 1.0 + lo + li;
    double spec = D / (4.0 * wo.z * g * wi.z);
    double c = 0.5 * sqrt(H2);
    double s5 = old_pow5(1.0 - dr_clamp(c, 0.0, 1.0));
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    double d_km = dr_dot(d_out, fm);
    double d_kd = dr_dot(d_out, base);
    if (lambert) {
        d->base_color = dr_madd(d->base_color, d_out, DR_INV_PI);
        d->metallic += spec * d_km - DR_INV_PI * d_kd;
        return;
    }
    dr_vec3 f0 = old_f0(b);
    double f90 = b->specular;
    dr_vec3 fd = dr_v3(f0.x + (f90 - f0.x) * s5, f0.y + (f90 - f0.y) * s5, f0.z + (f90 - f0.z) * s5);
    double f0max = dr_max3(f0);
    double fo = f0max + (f90 - f0max) * old_pow5(1.0 - wo.z), fi = f0max + (f90 - f0max) * old_pow5(1.0 - wi.z);
    double kd0 = dr_max(0.0, 1.0 - fo) * dr_max(0.0, 1.0 - fi) * DR_INV_PI;
    double d_ks = dr_dot(d_out, fd);
    d->base_color = dr_madd(d->base_color, d_out, (1.0 - m) * kd0 + m * spec * (1.0 - s5));
    d->metallic += spec * (d_km - d_ks) - kd0 * d_kd;
    double rough = b->roughness;
    double d_spec = (1.0 - m) * d_ks + m * d_km;
    if (d_spec == 0.0 || !(rough * rough > DR_BSDF_MIN_ALPHA))
        return;
    double dlnD = (2.0 / a) * ((hxy2 - a2 * hz2) / q);
    double dlo = 0.5 * a * tan2o / so, dli = 0.5 * a * tan2i / si;
    double dspec_da = spec * (dlnD - (dlo + dli) / g);
    d->roughness += d_spec * dspec_da * (2.0 * rough);
}

/* The GGX visible-normal map as it was inside dr_bsdf_sample (frozen),
 * except for its azimuth: cos and sin of 2 pi u2 come from dr_sincos_turn
 * since the samplers stopped calling libm for them (test_bsdf's
 * test_sincos_turn holds those to libm's within 1e-15). */
static dr_vec3 old_vndf_wi(dr_vec3 wo, double a, double u1, double u2)
{
    dr_vec3 vh = dr_normalize(dr_v3(a * wo.x, a * wo.y, wo.z));
    double lensq = vh.x * vh.x + vh.y * vh.y;
    dr_vec3 t1 = lensq > 0.0 ? dr_scale(dr_v3(-vh.y, vh.x, 0.0), 1.0 / sqrt(lensq)) : dr_v3(1.0, 0.0, 0.0);
    dr_vec3 t2 = dr_cross(vh, t1);
    double r = sqrt(u1), cos_phi, sin_phi;
    dr_sincos_turn(u2, &sin_phi, &cos_phi);
    double p1 = r * cos_phi, p2 = r * sin_phi;
    double s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(dr_max(0.0, 1.0 - p1 * p1)) + s * p2;
    dr_vec3 nh = dr_add(dr_add(dr_scale(t1, p1), dr_scale(t2, p2)),
                        dr_scale(vh, sqrt(dr_max(0.0, 1.0 - p1 * p1 - p2 * p2))));
    dr_vec3 h = dr_normalize(dr_v3(a * nh.x, a * nh.y, dr_max(0.0, nh.z)));
    return dr_sub(dr_scale(h, 2.0 * dr_dot(wo, h)), wo);
}

static bool same3(dr_vec3 a, dr_vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
static bool same_d(const struct dr_d_bsdf *a, const struct dr_d_bsdf *b)
{
    return same3(a->base_color, b->base_color) && a->metallic == b->metallic && a->roughness == b->roughness &&
           a->anisotropy == b->anisotropy;
}

static void test_bit_identity(void)
{
    struct rng r = {1618};
    long n_eval = 0, n_sample = 0;
    for (int ir = 0; ir <= NROUGH; ir++)
        for (int im = 0; im < 3; im++)
            for (int is = 0; is < 2; is++)
                for (int n = 0; n < 200; n++) {
                    double rough = ir < NROUGH ? roughs[ir] : (n % 2 ? 0.0 : 0.0003);
                    struct cfg c = random_cfg(&r, rough, metals[im], specs[is], n);
                    c.b.coated = false;   /* (the frozen version knows no coat) */
                    if (c.lobe == DR_BSDF_LOBE_COAT)
                        c.lobe = DR_BSDF_LOBE_SPECULAR;
                    struct dr_d_bsdf d_old = {dr_v3(0.1, 0.2, 0.3), 0.4, 0.5, 0.6, 0.7, 0.8, dr_v3(0.9, 1.0, 1.1), 1.2}, d_new = d_old, d_new2 = d_old;
                    dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
                    old_d_bsdf_eval(&c.b, c.wo, c.wi, c.d3, &d_old);
                    d_bsdf_eval(&c.b, c.wo, c.wi, c.d3, &d_new, NULL, NULL);
                    d_bsdf_eval(&c.b, c.wo, c.wi, c.d3, &d_new2, &dwo, &dwi);
                    n_eval++;
                    CHECK(same_d(&d_old, &d_new) && same_d(&d_old, &d_new2),
                          "d_bsdf_eval parameter part differs from the frozen version (r %g m %g s %g)",
                          c.b.roughness, c.b.metallic, c.b.specular);
                    /* dr_bsdf_sample: wi from dr_bsdf_sample_dir for the lobe it reports, and the frozen map */
                    double ul = rng_next(&r);
                    struct dr_bsdf_sample s;
                    dr_bsdf_sample(&c.b, c.wo, ul, c.u1, c.u2, &s);
                    if (!(c.wo.z > COS_EPS_T))
                        continue;
                    bool spec = ul < dr_bsdf_specular_prob(&c.b, c.wo);
                    dr_vec3 w = dr_bsdf_sample_dir(&c.b, c.wo, s.lobe, c.u1, c.u2);
                    n_sample++;
                    CHECK(s.lobe == (spec ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE), "sample lobe %d", (int)s.lobe);
                    CHECK(same3(w, s.wi), "dr_bsdf_sample_dir differs from dr_bsdf_sample's wi");
                    if (spec)
                        CHECK(same3(s.wi, old_vndf_wi(c.wo, test_alpha(c.b.roughness), c.u1, c.u2)),
                              "specular map differs from the frozen map (r %g)", c.b.roughness);
                }
    fprintf(stderr, "bit-identity: %ld d_bsdf_eval parameter parts, %ld samples identical\n", n_eval, n_sample);
}

/* ------------------------------------------------------ g. hard cases */

static int hard_n;

static void all_adjoints_finite(const struct cfg *c, const char *what)
{
    struct dr_d_bsdf d = {0};
    dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
    d_bsdf_eval(&c->b, c->wo, c->wi, c->d3, &d, &dwo, &dwi);
    bool ok1 = finite_d(&d) && finite3(dwo) && finite3(dwi);
    d_bsdf_pdf(&c->b, c->wo, c->wi, c->d1, &d, &dwo, &dwi);
    bool ok2 = finite_d(&d) && finite3(dwo) && finite3(dwi);
    d_bsdf_specular_prob(&c->b, c->wo, c->d1, &d, &dwo);
    bool ok3 = finite_d(&d) && finite3(dwo);
    d_bsdf_sample_dir(&c->b, c->wo, c->lobe, c->u1, c->u2, c->d3, &d, &dwo);
    bool ok4 = finite_d(&d) && finite3(dwo);
    hard_n++;
    CHECK(ok1 && ok2 && ok3 && ok4, "%s: not finite (eval %d pdf %d prob %d sample %d)", what, ok1, ok2, ok3, ok4);
    if (!(ok1 && ok2 && ok3 && ok4))
        print_cfg("hard case", what, c);
}

static void test_hard_cases(void)
{
    static const double hr[] = {0.0, 0.0005, 0.001, 0.0011, 0.01, 0.5, 1.0};
    static const double cosines[] = {1.0, 0.5, 1e-3, 1e-6, 1e-9, 2e-12};
    static const double us[] = {0.0, 1e-12, 0.5, 1.0 - 1e-16, 1.0};
    const int nc = (int)(sizeof cosines / sizeof *cosines), nu = (int)(sizeof us / sizeof *us);
    struct rng r = {99991};
    for (size_t ir = 0; ir < sizeof hr / sizeof *hr; ir++)
        for (int im = 0; im < 3; im++)
            for (int is = 0; is < 2; is++)
                for (int ib = 0; ib < 2; ib++)
                    for (int ic = 0; ic < nc; ic++)
                        for (int jc = 0; jc < nc; jc++)
                            for (int kind = 0; kind < 7; kind++) {
                                struct cfg c;
                                memset(&c, 0, sizeof c);
                                c.b = make_bsdf(hr[ir], metals[im], specs[is], ib ? dr_v3(1.0, 0.5, 0.0) : dr_v3s(0.0),
                                                dr_v3s(1.0));
                                c.wo = kind == 4 ? dr_v3(1e-170, 0.0, 1.0) : dir_from(cosines[ic], 0.3);
                                if (kind == 0 || kind == 4)
                                    c.wi = reflect(c.wo, dr_v3(0.0, 0.0, 1.0));   /* H along z */
                                else if (kind == 1)
                                    c.wi = dir_from(cosines[jc], 0.3 + M_PI);      /* same plane, opposite */
                                else if (kind == 2)
                                    c.wi = dir_from(cosines[jc], 1.9);
                                else if (kind == 3)
                                    c.wi = dr_v3(1e-9, 0.0, 1.0);                  /* nearly the normal */
                                else if (kind == 5)                                /* H nearly along z */
                                    c.wi = reflect(c.wo, dr_normalize(dr_v3(1e-9, -1e-9, 1.0)));
                                else
                                    c.wi = c.wo;                                   /* c = |H|/2 = 1 */
                                c.d3 = dr_v3(1.0, -0.5, 0.25);
                                c.d1 = 0.7;
                                c.lobe = (ic + jc) % 2 ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
                                c.u1 = us[(jc + kind) % nu];
                                c.u2 = us[(ic + 2 * kind) % nu];
                                all_adjoints_finite(&c, "grid");
                            }
    /* the sampling map over the whole (u1, u2) edge set, wo from exactly normal to grazing */
    static const dr_vec3 wos[] = {{0.0, 0.0, 1.0}, {1e-300, 0.0, 1.0}, {1e-9, -1e-9, 1.0}, {0.6, 0.0, 0.8},
                                  {0.999999999999, 0.0, 1e-6}, {0.0, 1.0, 2e-12}};
    for (size_t iw = 0; iw < sizeof wos / sizeof *wos; iw++)
        for (size_t ir = 0; ir < sizeof hr / sizeof *hr; ir++)
            for (int i = 0; i < nu; i++)
                for (int j = 0; j < nu; j++) {
                    struct cfg c;
                    memset(&c, 0, sizeof c);
                    c.b = make_bsdf(hr[ir], 1.0, 1.0, dr_v3s(0.5), dr_v3s(1.0));
                    c.wo = wos[iw];
                    c.wi = dr_v3(0.0, 0.0, 1.0);
                    c.d3 = dr_v3(rng_sym(&r), rng_sym(&r), rng_sym(&r));
                    c.d1 = 1.0;
                    c.lobe = DR_BSDF_LOBE_SPECULAR;
                    c.u1 = us[i];
                    c.u2 = us[j];
                    all_adjoints_finite(&c, "sampling edges");
                }
    /* a clear coat of every weight and roughness over a rough metal, at
     * every pair of cosines, each lobe */
    static const double coats[] = {0.0, 0.5, 1.0};
    for (size_t ic2 = 0; ic2 < sizeof coats / sizeof *coats; ic2++)
        for (size_t ir = 0; ir < sizeof hr / sizeof *hr; ir++)
            for (int ic = 0; ic < nc; ic++)
                for (int jc = 0; jc < nc; jc++)
                    for (int lobe = 0; lobe < 3; lobe++) {
                        struct cfg c;
                        memset(&c, 0, sizeof c);
                        c.b = make_bsdf(0.4, 0.5, 1.0, dr_v3(1.0, 0.5, 0.0), dr_v3s(1.0));
                        c.b.coated = true;
                        c.b.coat = coats[ic2];
                        c.b.coat_roughness = hr[ir];
                        c.wo = dir_from(cosines[ic], 0.3);
                        c.wi = jc % 2 ? reflect(c.wo, dr_v3(0.0, 0.0, 1.0)) : dir_from(cosines[jc], 1.9);
                        c.d3 = dr_v3(1.0, -0.5, 0.25);
                        c.d1 = 0.7;
                        c.lobe = (enum dr_bsdf_lobe)lobe;
                        c.u1 = us[(ic + jc) % nu];
                        c.u2 = us[(ic + 2 * jc) % nu];
                        all_adjoints_finite(&c, "coat grid");
                    }
    fprintf(stderr, "hard cases: %d configurations, every adjoint finite\n", hard_n);
}

/* h. anisotropy (KHR_materials_anisotropy: the base's lobe stretched to
 * alpha_x = alpha + (1 - alpha) s^2): d_bsdf_eval, d_bsdf_pdf,
 * d_bsdf_pdf_fixed_prob and d_bsdf_specular_prob against differences in
 * every input, anisotropy included, over s = 0 (one-sided: d alpha_x / d s
 * = 2 s (1 - alpha) vanishes there, and the adjoint must be exactly 0),
 * 0.3, 0.8, 1 and random, roughness from rough to below the alpha floor
 * (where alpha_x still moves with s), a clear coat on every fourth; and
 * d_bsdf_sample_dir of the stretched visible-normal map (both lobes, the
 * coat's too). */
static void test_fd_aniso(void)
{
    static const double ar[] = {0.7, 0.3, 0.05, 0.01, 0.001, 0.0002};
    static const double as[] = {0.0, 0.3, 0.8, 1.0, -1.0};   /* -1: random in (0, 1) */
    const long before = fn_eval.checks + fn_pdf.checks;
    long zero_checks = 0;
    struct rng r = {5551212};
    for (size_t ir = 0; ir < sizeof ar / sizeof *ar; ir++)
        for (size_t is = 0; is < sizeof as / sizeof *as; is++)
            for (int im = 0; im < 3; im++)
                for (int n = 0; n < 48; n++) {
                    struct cfg c = random_cfg(&r, ar[ir], metals[im], n % 2 ? 1.0 : 0.0, n);
                    c.b.anisotropy = as[is] >= 0.0 ? as[is] : 0.02 + 0.96 * rng_next(&r);
                    set_fixed_probs(&c);
                    check_fd(&fn_eval, &c);
                    check_fd(&fn_pdf, &c);
                    check_fd(&fn_pdf_fixed, &c);
                    check_fd(&fn_prob, &c);
                    check_fd(&fn_sample, &c);
                    if (c.b.anisotropy == 0.0) {
                        double g[NX];
                        fn_eval.adjoint(&c, g);
                        bool z = g[X_A] == 0.0;
                        fn_pdf.adjoint(&c, g);
                        z = z && g[X_A] == 0.0;
                        fn_pdf_fixed.adjoint(&c, g);
                        z = z && g[X_A] == 0.0;
                        fn_sample.adjoint(&c, g);
                        z = z && g[X_A] == 0.0;
                        zero_checks++;
                        CHECK(z, "s = 0: the anisotropy adjoint must be exactly 0");
                    }
                }
    fprintf(stderr, "anisotropic: %ld FD checks of d_bsdf_eval and d_bsdf_pdf (d_bsdf_pdf_fixed_prob: %ld in all), "
            "%ld exact zeros at s = 0\n", fn_eval.checks + fn_pdf.checks - before, fn_pdf_fixed.checks, zero_checks);
    /* the anisotropy adjoint is not vacuous: nonzero for a generic stretched lobe */
    struct cfg c;
    memset(&c, 0, sizeof c);
    c.b = make_bsdf(0.3, 1.0, 1.0, dr_v3s(0.9), dr_v3s(1.0));
    c.b.anisotropy = 0.6;
    c.wo = dir_from(0.7, 0.2), c.wi = dir_from(0.6, 2.9), c.d3 = dr_v3s(1.0), c.d1 = 1.0;
    set_fixed_probs(&c);
    double g[NX];
    fn_eval.adjoint(&c, g);
    CHECK(fabs(g[X_A]) > 1e-3 * fabs(loss_eval(&c)), "anisotropy adjoint of f vanishes: %g", g[X_A]);
    fn_pdf.adjoint(&c, g);
    CHECK(fabs(g[X_A]) > 1e-3 * fabs(loss_pdf(&c)), "anisotropy adjoint of the pdf vanishes: %g", g[X_A]);
    c.lobe = DR_BSDF_LOBE_SPECULAR, c.u1 = 0.4, c.u2 = 0.15;
    fn_sample.adjoint(&c, g);
    CHECK(fabs(g[X_A]) > 1e-3, "anisotropy adjoint of the sampling map vanishes: %g", g[X_A]);
}

/* Hard cases of the stretched lobe: grazing, normal, tiny roughness, s up
 * to 1, H along the normal and nearly so: every adjoint finite. */
static void test_hard_aniso(void)
{
    static const double hr[] = {0.0, 0.001, 0.01, 0.5, 1.0}, hs[] = {0.3, 1.0};
    static const double cosines[] = {1.0, 0.5, 1e-3, 1e-6, 1e-9, 2e-12};
    const int nc = (int)(sizeof cosines / sizeof *cosines);
    int before = hard_n;
    for (size_t ir = 0; ir < sizeof hr / sizeof *hr; ir++)
        for (int is = 0; is < 2; is++)
            for (int im = 0; im < 3; im++)
                for (int ic = 0; ic < nc; ic++)
                    for (int jc = 0; jc < nc; jc++)
                        for (int kind = 0; kind < 5; kind++) {
                            struct cfg c;
                            memset(&c, 0, sizeof c);
                            c.b = make_bsdf(hr[ir], metals[im], 1.0, dr_v3(1.0, 0.5, 0.0), dr_v3s(1.0));
                            c.b.anisotropy = hs[is];
                            c.b.coated = kind == 4, c.b.coat = 0.5, c.b.coat_roughness = 0.2;
                            c.wo = dir_from(cosines[ic], kind == 2 ? M_PI / 2 : 0.3);
                            if (kind == 0)
                                c.wi = reflect(c.wo, dr_v3(0.0, 0.0, 1.0));
                            else if (kind == 1)
                                c.wi = reflect(c.wo, dr_normalize(dr_v3(1e-9, -1e-9, 1.0)));
                            else
                                c.wi = dir_from(cosines[jc], 1.9 + kind);
                            c.d3 = dr_v3(1.0, -0.5, 0.25);
                            c.d1 = 0.7;
                            c.lobe = DR_BSDF_LOBE_SPECULAR;
                            c.u1 = 0.3, c.u2 = 0.6;
                            all_adjoints_finite(&c, "anisotropic grid");
                            dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0);
                            struct dr_d_bsdf d = {0};
                            d_bsdf_pdf_fixed_prob(&c.b, c.wo, c.wi, 1.0, &d, &dwo, &dwi);
                            CHECK(finite_d(&d) && finite3(dwo) && finite3(dwi), "anisotropic fixed-prob pdf not finite");
                        }
    fprintf(stderr, "anisotropic hard cases: %d configurations, every adjoint finite\n", hard_n - before);
}

/* NULL outputs are accepted; a second call adds the same again; below the
 * surface nothing is touched. */
static void test_accumulate_and_null(void)
{
    struct rng r = {31415};
    for (int n = 0; n < 200; n++) {
        struct cfg c = random_cfg(&r, 0.05 + 0.9 * rng_next(&r), n % 3 ? 0.4 : 0.0, n % 5 ? 0.5 : 0.0, n % 5);
        c.lobe = n % 2 ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
        const struct fn *fs[4] = {&fn_eval, &fn_pdf, &fn_prob, &fn_sample};
        for (int i = 0; i < 4; i++) {
            double g1[NX], g2[NX];
            fs[i]->adjoint(&c, g1);
            /* twice into preset outputs */
            struct dr_d_bsdf d = {dr_v3(1.0, 2.0, 3.0), 4.0, 5.0, 6.0, 7.0, 8.0, dr_v3(15.0, 16.0, 17.0), 18.0};
            dr_vec3 dwo = dr_v3(9.0, 10.0, 11.0), dwi = dr_v3(12.0, 13.0, 14.0);
            for (int t = 0; t < 2; t++) {
                if (i == 0)
                    d_bsdf_eval(&c.b, c.wo, c.wi, c.d3, &d, &dwo, &dwi);
                else if (i == 1)
                    d_bsdf_pdf(&c.b, c.wo, c.wi, c.d1, &d, &dwo, &dwi);
                else if (i == 2)
                    d_bsdf_specular_prob(&c.b, c.wo, c.d1, &d, &dwo);
                else
                    d_bsdf_sample_dir(&c.b, c.wo, c.lobe, c.u1, c.u2, c.d3, &d, &dwo);
            }
            g_from(g2, &d, dwo, dwi);
            for (int k = 0; k < NX; k++) {
                double preset = (double)(k + 1);
                CHECK_NEAR(g2[k] - preset, 2.0 * g1[k], 1e-12 * (fabs(g1[k]) + preset), fs[i]->name);
            }
        }
        /* every NULL combination runs, and the parts requested match the full call */
        for (int mask = 0; mask < 8; mask++) {
            struct dr_d_bsdf d = {0}, *pd = mask & 1 ? &d : NULL;
            dr_vec3 dwo = dr_v3s(0.0), dwi = dr_v3s(0.0), *pwo = mask & 2 ? &dwo : NULL, *pwi = mask & 4 ? &dwi : NULL;
            double g[NX], gf[NX];
            d_bsdf_eval(&c.b, c.wo, c.wi, c.d3, pd, pwo, pwi);
            g_from(g, &d, dwo, dwi);
            fn_eval.adjoint(&c, gf);
            for (int k = 0; k < NX; k++) {
                bool requested = k <= X_A || k >= X_SR ? pd != NULL : (k <= X_OZ ? pwo != NULL : pwi != NULL);
                CHECK(g[k] == (requested ? gf[k] : 0.0), "d_bsdf_eval NULL mask %d input %s", mask, x_name[k]);
            }
            d_bsdf_pdf(&c.b, c.wo, c.wi, c.d1, pd, pwo, pwi);
            d_bsdf_specular_prob(&c.b, c.wo, c.d1, pd, pwo);
            d_bsdf_sample_dir(&c.b, c.wo, c.lobe, c.u1, c.u2, c.d3, pd, pwo);
        }
    }
    /* below the surface: untouched */
    struct dr_bsdf b = make_bsdf(0.5, 0.5, 0.5, dr_v3s(0.5), dr_v3s(1.0));
    const dr_vec3 below[][2] = {{{0.0, 0.6, -0.8}, {0.0, 0.0, 1.0}}, {{0.0, 0.0, 1.0}, {0.6, 0.0, -0.8}},
                                {{1.0, 0.0, 0.0}, {0.0, 0.0, 1.0}}};
    struct dr_d_bsdf d = {dr_v3(1.0, 2.0, 3.0), 4.0, 5.0, 6.0, 7.0, 8.0, dr_v3(15.0, 16.0, 17.0), 18.0};
    dr_vec3 dwo = dr_v3(9.0, 10.0, 11.0), dwi = dr_v3(12.0, 13.0, 14.0);
    for (int coated = 0; coated < 2; coated++) {
        b.coated = coated;
        b.coat = 0.7;
        b.coat_roughness = 0.1;
        for (int i = 0; i < 3; i++) {
            d_bsdf_eval(&b, below[i][0], below[i][1], dr_v3s(1.0), &d, &dwo, &dwi);
            d_bsdf_pdf(&b, below[i][0], below[i][1], 1.0, &d, &dwo, &dwi);
            d_bsdf_pdf_fixed_prob(&b, below[i][0], below[i][1], 1.0, &d, &dwo, &dwi);
        }
        d_bsdf_sample_dir(&b, below[0][0], DR_BSDF_LOBE_SPECULAR, 0.3, 0.3, dr_v3s(1.0), &d, &dwo);
        d_bsdf_sample_dir(&b, below[0][0], DR_BSDF_LOBE_COAT, 0.3, 0.3, dr_v3s(1.0), &d, &dwo);
    }
    double g[NX];
    g_from(g, &d, dwo, dwi);
    for (int k = 0; k < NX; k++)
        CHECK(g[k] == (double)(k + 1), "below the surface the adjoint of %s changed to %g", x_name[k], g[k]);
}


/* i. the sheen (bsdf_sheen.c): every adjoint against differences in every
 * input, the sheen's colour and roughness included, over sheen roughness
 * below, at and above its floor (0.05, 0.07, 0.071) up to 1, colours 0,
 * white (T clamps at grazing angles), grey (a tie for the max channel) and
 * random, on the bases of random_cfg (a clear coat over every fourth, a
 * stretched base lobe on some), the sheen's lobe sampled a third of the
 * time. Then: zero roughness derivative below the floor, a colour 0 keeps
 * its derivative in f, and every adjoint finite at cosines down to 1e-9. */
static void random_sheen(struct rng *r, struct cfg *c, int n)
{
    static const double sr[] = {0.05, 0.07, 0.071, 0.1, 0.3, 0.5, 0.8, 1.0, -1.0};
    const double x = sr[n % 9];
    c->b.sheened = true;
    c->b.sheen_roughness = x >= 0.0 ? x : 0.08 + 0.9 * rng_next(r);
    switch ((n / 9) % 4) {
    case 0: c->b.sheen_color = dr_v3s(0.0); break;
    case 1: c->b.sheen_color = dr_v3s(1.0); break;
    case 2: c->b.sheen_color = dr_v3(0.4, 0.4, 0.2); break;
    default: c->b.sheen_color = dr_v3(rng_next(r), rng_next(r), rng_next(r)); break;
    }
    if (n % 3 == 0)
        c->lobe = DR_BSDF_LOBE_SHEEN;
    /* Lambda's slope (1 - cos)^(c-1) is singular at normal incidence: within
     * 1e-6 of it a difference cannot follow (1 - cos has few digits there) */
    if (c->wi.z > 1.0 - 1e-6)
        c->wi = dir_from(1.0 - 1e-4 * (1.0 + rng_next(r)), 2.0 * M_PI * rng_next(r));
    if (c->wo.z > 1.0 - 1e-6 && c->wo.z < 1.0)
        c->wo = dir_from(1.0 - 1e-4 * (1.0 + rng_next(r)), 2.0 * M_PI * rng_next(r));
}

static void test_fd_sheen(void)
{
    static const double br[] = {1.0, 0.5, 0.2, 0.05, 0.001};
    const long before = fn_eval.checks + fn_pdf.checks + fn_pdf_fixed.checks + fn_prob.checks + fn_sample.checks;
    struct rng r = {777000111};
    long colour0 = 0;
    for (size_t ir = 0; ir < sizeof br / sizeof *br; ir++)
        for (int im = 0; im < 3; im++)
            for (int n = 0; n < 144; n++) {
                struct cfg c = random_cfg(&r, br[ir], metals[im], n % 2 ? 1.0 : 0.0, n);
                random_sheen(&r, &c, n / 2 + 7 * (int)ir);
                if (n % 11 == 5)
                    c.b.anisotropy = 0.6;
                set_fixed_probs(&c);
                check_fd(&fn_eval, &c);
                check_fd(&fn_pdf, &c);
                check_fd(&fn_pdf_fixed, &c);
                check_fd(&fn_prob, &c);
                check_fd(&fn_sample, &c);
                double g[NX];
                if (!(c.b.sheen_roughness >= DR_SHEEN_MIN_ROUGHNESS)) {
                    fn_eval.adjoint(&c, g);
                    bool z = g[X_SRO] == 0.0;
                    fn_pdf.adjoint(&c, g);
                    z = z && g[X_SRO] == 0.0;
                    fn_prob.adjoint(&c, g);
                    CHECK(z && g[X_SRO] == 0.0, "below the sheen roughness floor: a roughness adjoint is not 0");
                }
                if (c.b.sheen_color.x == 0.0 && c.wo.z > 0.05 && c.wi.z > 0.05 && !c.b.coated) {
                    /* f_sheen = C s: d f / d C.r = s > 0 whatever C (the base's T T is 1 at C = 0) */
                    fn_eval.adjoint(&c, g);
                    struct cfg w = c;
                    w.b.sheen_color = dr_v3(1.0, 0.0, 0.0);
                    w.b.base_color = dr_v3s(0.0);
                    w.b.metallic = 0.0;
                    w.b.specular = 0.0;
                    const double s = dr_bsdf_eval(&w.b, w.wo, w.wi).x;
                    CHECK(s > 0.0 ? fabs(g[X_SR]) > 0.0 : true, "colour 0: d f / d sheen.r vanishes (s %g)", s);
                    colour0++;
                }
            }
    fprintf(stderr, "sheen: %ld FD checks over the five adjoints, %ld colour-0 checks\n",
            fn_eval.checks + fn_pdf.checks + fn_pdf_fixed.checks + fn_prob.checks + fn_sample.checks - before,
            colour0);
    CHECK(colour0 > 10, "too few colour-0 sheen configurations (%ld)", colour0);
    /* identity along random directions of all inputs at once */
    for (int n = 0; n < 600; n++) {
        struct cfg c = random_cfg(&r, 0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r), 1.0, 8 * (n % 5) + n % 7);
        random_sheen(&r, &c, n);
        c.b.sheen_roughness = 0.08 + 0.9 * rng_next(&r);
        c.b.sheen_color = dr_v3(0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r));
        c.b.base_color = dr_v3(0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r), 0.05 + 0.9 * rng_next(&r));
        if (c.b.coated)
            c.b.coat = 0.05 + 0.9 * rng_next(&r);
        check_identity(&fn_eval, &c, &r);
        check_identity(&fn_pdf, &c, &r);
        check_identity(&fn_prob, &c, &r);
        check_identity(&fn_sample, &c, &r);
    }
    /* grazing cosines, the floor, colour 0 and 1, coated or not: finite */
    static const double zs[] = {1e-9, 1e-7, 1e-4, 0.3, 1.0};
    static const double rs[] = {0.0, 0.07, 0.3, 1.0};
    int hard = 0;
    for (size_t a = 0; a < 5; a++)
        for (size_t b = 0; b < 5; b++)
            for (size_t k = 0; k < 4; k++)
                for (int v = 0; v < 4; v++) {
                    struct cfg c = random_cfg(&r, 0.3, v % 2 ? 1.0 : 0.0, 1.0, 0);
                    c.b.coated = v >= 2, c.b.coat = 0.5, c.b.coat_roughness = 0.2;
                    c.b.sheened = true;
                    c.b.sheen_roughness = rs[k];
                    c.b.sheen_color = v % 2 ? dr_v3s(1.0) : dr_v3s(0.0);
                    c.wo = dir_from(zs[a], 0.3);
                    c.wi = dir_from(zs[b], 2.0 + 0.5 * (double)v);
                    const enum dr_bsdf_lobe lobes[] = {DR_BSDF_LOBE_DIFFUSE, DR_BSDF_LOBE_SPECULAR, DR_BSDF_LOBE_SHEEN};
                    for (int l = 0; l < 3; l++) {
                        c.lobe = lobes[l];
                        set_fixed_probs(&c);
                        const struct fn *fs[5] = {&fn_eval, &fn_pdf, &fn_pdf_fixed, &fn_prob, &fn_sample};
                        for (int i = 0; i < 5; i++) {
                            double g[NX];
                            fs[i]->adjoint(&c, g);
                            bool fin = true;
                            for (int x = 0; x < NX; x++)
                                fin = fin && isfinite(g[x]);
                            CHECK(fin, "sheen hard case: %s not finite", fs[i]->name);
                            if (!fin)
                                print_cfg(fs[i]->name, "non-finite", &c);
                        }
                        hard++;
                    }
                }
    fprintf(stderr, "sheen hard cases: %d configurations, every adjoint finite\n", hard);
}

/* ------------------------------------------------------------------- main */

static void summary(const struct fn *f)
{
    fprintf(stderr,
            "%-21s: %6ld FD checks (%5ld one-sided, %4ld skipped at kinks), worst rel. error %.2e, "
            "worst error/tolerance %.2f; identity: %5ld checks (%3ld skipped), worst rel. error %.2e, "
            "worst error/tolerance %.2f\n",
            f->name, f->checks, f->one_sided, f->skipped, f->worst_rel, f->worst_ratio, f->id_checks,
            f->id_skipped, f->id_worst_rel, f->id_worst_ratio);
}

int main(void)
{
    test_fd_all();
    test_mis();
    test_identity();
    test_bit_identity();
    test_hard_cases();
    test_accumulate_and_null();
    test_fd_aniso();
    test_hard_aniso();
    test_fd_sheen();
    summary(&fn_eval);
    summary(&fn_pdf);
    summary(&fn_pdf_fixed);
    summary(&fn_prob);
    summary(&fn_sample);
    fprintf(stderr, "%-21s: %6ld FD checks, worst rel. error %.2e, worst error/tolerance %.2f\n", "d_mis_power",
            mis_checks, mis_worst_rel, mis_worst_ratio);
    CHECK(fn_eval.checks > 0 && fn_pdf.checks > 0 && fn_prob.checks > 0 && fn_sample.checks > 0 && mis_checks > 0 &&
              fn_eval.id_checks > 0 && fn_sample.id_checks > 0,
          "some function was never checked");
    return TEST_END();
}
