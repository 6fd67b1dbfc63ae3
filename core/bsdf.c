/* The glTF metallic-roughness BSDF: see bsdf.h for the model.
 *
 * Everything is in the local shading frame (normal = +z). Notes on numerics:
 *  - GGX D is evaluated from the unnormalised half vector H = wo + wi as
 *      D = alpha^2 |H|^4 / (pi (Hx^2 + Hy^2 + alpha^2 Hz^2)^2),
 *    which is exact for tiny alpha (no 1 - cos^2 cancellation).
 *  - Smith Lambda is written as x / (2 (1 + sqrt(1 + x))), x = alpha^2 tan^2,
 *    the cancellation-free form of (-1 + sqrt(1 + x)) / 2.
 *  - wo.h = wi.h = |wo + wi| / 2 for unit wo, wi: symmetric in (wo, wi), so
 *    f(wo, wi) == f(wi, wo) bit for bit, and no dot product is needed.
 *  - Cosines at or below COS_EPS count as below the surface (f = pdf = 0),
 *    which keeps every intermediate finite (z^2 never underflows).
 *  - Anisotropy (b->anisotropy != 0, KHR_materials_anisotropy) takes separate
 *    paths (the *_aniso functions, "anisotropic GGX" below) so that the
 *    isotropic arithmetic, which the eight-lane copy in path_simd.c and the
 *    estimators' tests compare bit for bit, is untouched. */
#include "bsdf.h"

#include <stddef.h>

#include "bsdf_coat.h"   /* a coated BSDF (b->coated) is handed there */
#include "bsdf_sheen.h"  /* then a sheened one (b->sheened): coat over sheen over base */

#define COS_EPS DR_BSDF_COS_EPS

static inline double pow5(double s)
{
    double s2 = s * s;
    return s2 * s2 * s;
}

static inline double bsdf_alpha(const struct dr_bsdf *b)
{
    double a = b->roughness * b->roughness;
    return a > DR_BSDF_MIN_ALPHA ? a : DR_BSDF_MIN_ALPHA;
}

/* Smith Lambda for GGX; w.z > COS_EPS. */
static inline double smith_lambda(double a2, dr_vec3 w)
{
    double x = a2 * (w.x * w.x + w.y * w.y) / (w.z * w.z);
    return 0.5 * x / (1.0 + sqrt(1.0 + x));
}

/* ------------------------------------------------------- anisotropic GGX
 *
 * KHR_materials_anisotropy stretches the base's lobe along the local +x axis:
 * alpha_x = alpha + (1 - alpha) s^2, alpha_y = alpha (s = b->anisotropy), so
 * alpha_x >= alpha_y. Heitz 2014 ("Understanding the masking-shadowing
 * function"), with H = wo + wi unnormalised, h = H / |H|:
 *   D(h) = 1 / (pi ax ay (hx^2/ax^2 + hy^2/ay^2 + hz^2)^2)
 *        = ax ay |H|^4 / (pi q^2),  q = Hx^2 (ay/ax) + Hy^2 (ax/ay) + ax ay Hz^2
 * (multiply the bracket by ax ay |H|^2); at ax = ay = a, q = Hxy^2 + a^2 Hz^2
 * and D = a^2 (|H|^2/q)^2 / pi, the isotropic form. Like it, exact for tiny
 * alphas (no 1 - cos^2 cancellation). Smith Lambda keeps its form with
 *   x = (ax^2 wx^2 + ay^2 wy^2) / wz^2. */

/* alpha_x of the stretched lobe, a = bsdf_alpha(b) = alpha_y. */
static inline double alpha_x_of(const struct dr_bsdf *b, double a)
{
    const double s = b->anisotropy;
    return a + (1.0 - a) * (s * s);
}

/* The anisotropic half-vector terms (as struct ggx_half, below, for one alpha). */
struct ggx_aniso {
    dr_vec3 H;
    double hx2, hy2, hz2, H2, q, D;
};

static inline struct ggx_aniso ggx_aniso(double ax, double ay, dr_vec3 wo, dr_vec3 wi)
{
    struct ggx_aniso g;
    g.H = dr_add(wo, wi);
    g.hx2 = g.H.x * g.H.x;
    g.hy2 = g.H.y * g.H.y;
    g.hz2 = g.H.z * g.H.z;
    g.H2 = g.hx2 + g.hy2 + g.hz2;
    g.q = g.hx2 * (ay / ax) + g.hy2 * (ax / ay) + ax * ay * g.hz2;   /* > 0: H.z > 0 */
    double r = g.H2 / g.q;
    g.D = ax * ay * r * r * DR_INV_PI;
    return g;
}

/* Smith Lambda of the anisotropic lobe (w.z > COS_EPS); with dax, day not
 * NULL also dLambda/dax = ax tx / (2 sqrt(1 + x)) (tx = wx^2 / wz^2; from
 * dLambda/dx = 1 / (4 sqrt(1 + x))) and alike in ay. */
static inline double smith_lambda_aniso(double ax, double ay, dr_vec3 w, double *dax, double *day)
{
    double iz2 = 1.0 / (w.z * w.z);
    double tx = w.x * w.x * iz2, ty = w.y * w.y * iz2;
    double x = ax * ax * tx + ay * ay * ty, sq = sqrt(1.0 + x);
    if (dax) {
        *dax = 0.5 * ax * tx / sq;
        *day = 0.5 * ay * ty / sq;
    }
    return 0.5 * x / (1.0 + sq);
}

static inline bool no_specular_lobe(const struct dr_bsdf *b)
{
    return b->metallic == 0.0 && b->specular == 0.0;
}

/* Dielectric f0 per KHR_materials_specular. */
static inline dr_vec3 dielectric_f0(const struct dr_bsdf *b)
{
    dr_vec3 sc = b->specular_color;
    return dr_v3(dr_min(0.04 * sc.x, 1.0) * b->specular, dr_min(0.04 * sc.y, 1.0) * b->specular,
                 dr_min(0.04 * sc.z, 1.0) * b->specular);
}

/* specular_prob of a BSDF with a specular lobe. */
static double __attribute__((noinline)) specular_prob_glossy(const struct dr_bsdf *b, double cos_o)
{
    double m = b->metallic;
    double s5 = pow5(1.0 - dr_clamp(cos_o, 0.0, 1.0));
    double f0max = dr_max3(dielectric_f0(b));
    double fd = f0max + (b->specular - f0max) * s5;  /* max channel of F_d at wo.z */
    dr_vec3 base = b->base_color;
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    double w_spec = (1.0 - m) * fd + m * dr_luminance(fm);
    double w_diff = (1.0 - m) * (1.0 - fd) * dr_luminance(base);
    if (!(w_diff > 0.0))
        return 1.0;
    if (!(w_spec > 0.0))
        return 0.0;
    return w_spec / (w_spec + w_diff);
}

/* The probability of sampling the specular lobe; cos_o = wo.z > COS_EPS.
 * The Lambertian case inline (it is on every bounce of a diffuse scene; a
 * call passes and returns its vectors through memory), the rest out of line. */
static inline __attribute__((always_inline)) double specular_prob(const struct dr_bsdf *b, double cos_o)
{
    return no_specular_lobe(b) ? 0.0 : specular_prob_glossy(b, cos_o);
}

/* f and pdf for wo.z, wi.z > COS_EPS, given p = specular_prob(b, wo.z).
 * The single place where the pdf is computed, so dr_bsdf_pdf, dr_bsdf_eval_pdf
 * and dr_bsdf_sample agree bit for bit. */
static dr_vec3 __attribute__((noinline)) eval_pdf_glossy(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double p,
                                                          double *pdf)
{
    double cos_pdf = wi.z * DR_INV_PI;
    double a = bsdf_alpha(b), D, H2, lo, li;
    if (b->anisotropy == 0.0) {
        double a2 = a * a;
        dr_vec3 H = dr_add(wo, wi);
        double hxy2 = H.x * H.x + H.y * H.y;
        H2 = hxy2 + H.z * H.z;
        double q = hxy2 + a2 * H.z * H.z;   /* > 0: H.z > 0 */
        double r = H2 / q;
        D = a2 * r * r * DR_INV_PI;
        lo = smith_lambda(a2, wo), li = smith_lambda(a2, wi);
    } else {
        double ax = alpha_x_of(b, a);
        struct ggx_aniso g = ggx_aniso(ax, a, wo, wi);
        D = g.D, H2 = g.H2;
        lo = smith_lambda_aniso(ax, a, wo, NULL, NULL), li = smith_lambda_aniso(ax, a, wi, NULL, NULL);
    }
    double dq = D / (4.0 * wo.z);
    double pdf_spec = dq / (1.0 + lo);               /* G1(wo) D / (4 wo.z) = D_wo(h) / (4 wo.h) */
    double spec = dq / ((1.0 + lo + li) * wi.z);     /* D G2 / (4 wo.z wi.z) */
    *pdf = (1.0 - p) * cos_pdf + p * pdf_spec;

    double c = 0.5 * sqrt(H2);                       /* wo.h = wi.h */
    double s5 = pow5(1.0 - dr_clamp(c, 0.0, 1.0));
    double m = b->metallic;
    dr_vec3 f0 = dielectric_f0(b);
    double f90 = b->specular;
    dr_vec3 fd = dr_v3(f0.x + (f90 - f0.x) * s5, f0.y + (f90 - f0.y) * s5, f0.z + (f90 - f0.z) * s5);
    dr_vec3 base = b->base_color;
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    /* Diffuse weight: what the dielectric layer's Fresnel lets through on the
     * way in and on the way out, (1 - F(n.wo)) (1 - F(n.wi)), max over channels.
     * glTF's reference 1 - F(wo.h) is not reciprocal in effect and creates
     * energy at grazing angles (albedo ~1.5); this form never does. */
    double f0max = dr_max3(f0);
    double fo = f0max + (f90 - f0max) * pow5(1.0 - wo.z), fi = f0max + (f90 - f0max) * pow5(1.0 - wi.z);
    double kd = (1.0 - m) * dr_max(0.0, 1.0 - fo) * dr_max(0.0, 1.0 - fi) * DR_INV_PI;
    double ks = (1.0 - m) * spec, km = m * spec;
    return dr_v3(base.x * kd + fd.x * ks + fm.x * km, base.y * kd + fd.y * ks + fm.y * km,
                 base.z * kd + fd.z * ks + fm.z * km);
}

/* (The Lambertian case inline, as in specular_prob.) */
static inline __attribute__((always_inline)) dr_vec3 eval_pdf_above(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi,
                                                                    double p, double *pdf)
{
    if (no_specular_lobe(b)) {
        *pdf = wi.z * DR_INV_PI;
        return dr_scale(b->base_color, DR_INV_PI);
    }
    return eval_pdf_glossy(b, wo, wi, p, pdf);
}

dr_vec3 dr_bsdf_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS)) {
        *pdf = 0.0;
        return dr_v3s(0.0);
    }
    if (b->coated)
        return dr_coat_eval_pdf(b, wo, wi, pdf);
    if (b->sheened)
        return dr_sheen_eval_pdf(b, wo, wi, pdf);
    return eval_pdf_above(b, wo, wi, specular_prob(b, wo.z), pdf);
}

dr_vec3 dr_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi)
{
    double pdf;
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return dr_v3s(0.0);
    if (b->coated)
        return dr_coat_eval_pdf(b, wo, wi, NULL);
    if (b->sheened)
        return dr_sheen_eval_pdf(b, wo, wi, NULL);
    /* p = 0: the pdf is not needed, the compiler drops its arithmetic. */
    return eval_pdf_above(b, wo, wi, 0.0, &pdf);
}

double dr_bsdf_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi)
{
    double pdf = 0.0;
    dr_bsdf_eval_pdf(b, wo, wi, &pdf);
    return pdf;
}

double dr_bsdf_sky_share(const struct dr_bsdf *b, dr_vec3 wo)
{
    if (b->coated)
        return dr_coat_sky_share(b, wo);
    if (b->sheened)
        return dr_sheen_sky_share(b, wo);
    if (!(wo.z > COS_EPS))
        return 0.0;
    double a = bsdf_alpha(b);
    if (b->anisotropy != 0.0)   /* a stretched lobe's sharpness: the geometric mean of its alphas */
        a = sqrt(alpha_x_of(b, a) * a);
    double sharp = (0.45 - a) * (1.0 / 0.15);   /* (path_simd.c's sky_share: the same operations) */
    return specular_prob(b, wo.z) * (sharp < 0.0 ? 0.0 : sharp > 1.0 ? 1.0 : sharp);
}

double dr_bsdf_specular_prob(const struct dr_bsdf *b, dr_vec3 wo)
{
    if (b->coated)
        return dr_coat_specular_prob(b, wo);
    if (b->sheened)
        return dr_sheen_specular_prob(b, wo);
    if (!(wo.z > COS_EPS))
        return no_specular_lobe(b) ? 0.0 : specular_prob(b, 0.0);
    return specular_prob(b, wo.z);
}

/* sin t and cos t for |t| <= pi/4, by their Taylor series to t^17 and t^18:
 * the first omitted terms are below 1e-19 there, so both are as accurate as
 * libm's (within an ulp), without its range reduction. The cosine sampler
 * needs no more, and it is on every diffuse bounce. The series run in t^2 by
 * Horner's rule from the highest term: sin t = t + t^3 P(t^2), cos t = 1 -
 * t^2 Q(t^2). */
const double DR_SIN_SERIES[8] = {1.0 / 355687428096000.0, -1.0 / 1307674368000.0, 1.0 / 6227020800.0,
                                    -1.0 / 39916800.0,       1.0 / 362880.0,         -1.0 / 5040.0,
                                    1.0 / 120.0,             -1.0 / 6.0};   /* 1/17!, -1/15!, ..., -1/3! */
const double DR_COS_SERIES[9] = {1.0 / 6402373705728000.0, -1.0 / 20922789888000.0, 1.0 / 87178291200.0,
                                    -1.0 / 479001600.0,       1.0 / 3628800.0,         -1.0 / 40320.0,
                                    1.0 / 720.0,              -1.0 / 24.0,             0.5};   /* 1/18!, ..., 1/2! */

static inline void sincos_quarter(double t, double *s, double *c)
{
    double t2 = t * t;
    *s = t + t * t2 * dr_horner(t2, DR_SIN_SERIES, 8);
    *c = 1.0 - t2 * dr_horner(t2, DR_COS_SERIES, 9);
}

void dr_sincos_turn(double u, double *s, double *c)
{
    const double m = floor(4.0 * u + 0.5);       /* the nearest quarter turn */
    const double r = (2.0 * M_PI) * (u - 0.25 * m);   /* |r| <= pi/4; the difference is exact */
    const double q = m - 4.0 * floor(0.25 * m);  /* m mod 4 (NaN: none of 1, 2, 3) */
    double sr, cr;
    sincos_quarter(r, &sr, &cr);
    if (q == 1.0)
        *s = cr, *c = -sr;
    else if (q == 2.0)
        *s = -sr, *c = -cr;
    else if (q == 3.0)
        *s = -cr, *c = sr;
    else
        *s = sr, *c = cr;
}

/* Cosine-weighted hemisphere: Shirley-Chiu concentric disk, lifted (Malley).
 * The disk angle is pi/4 (c/a), or pi/2 - pi/4 (a/c), whose cosine and sine
 * are the sine and cosine of pi/4 (a/c): one small angle either way. */
static inline dr_vec3 sample_cosine(double u1, double u2)
{
    double a = 2.0 * u1 - 1.0, c = 2.0 * u2 - 1.0;
    if (a == 0.0 && c == 0.0)
        return dr_v3(0.0, 0.0, 1.0);
    double r, x, y;
    if (fabs(a) > fabs(c)) {
        r = a;
        sincos_quarter((M_PI / 4.0) * (c / a), &y, &x);
    } else {
        r = c;
        sincos_quarter((M_PI / 4.0) * (a / c), &x, &y);
    }
    x *= r;
    y *= r;
    return dr_v3(x, y, sqrt(dr_max(0.0, 1.0 - x * x - y * y)));
}

/* Intermediates of sample_vndf, kept for its adjoint (d_sample_vndf). */
struct vndf_tape {
    dr_vec3 v, vh;        /* stretched wo and its normalisation */
    double lensq;         /* vh.x^2 + vh.y^2 */
    dr_vec3 t1, t2;       /* frame around vh */
    double p1, p2, c;     /* disk point (constants of u) and c = sqrt(1 - p1^2) */
    double s, p2s, n3;    /* warp weight, warped p2, lift onto the hemisphere */
    dr_vec3 nh, m, h;     /* hemisphere normal, unstretched, normalised */
};

/* GGX visible normals (Heitz 2018, JCGT 7(4)), wo.z > 0, of the lobe with
 * alphas (ax, ay): wo is stretched to the lobe of alpha 1, a visible normal of
 * that hemisphere is drawn and unstretched. Returns h; fills *t (the primal's
 * callers let the compiler drop those stores). With ax == ay the arithmetic
 * is exactly the pre-adjoint isotropic map's, so dr_bsdf_sample's samples did
 * not change. */
static inline dr_vec3 sample_vndf(dr_vec3 wo, double ax, double ay, double u1, double u2, struct vndf_tape *t)
{
    t->v = dr_v3(ax * wo.x, ay * wo.y, wo.z);
    dr_vec3 vh = dr_normalize(t->v);
    double lensq = vh.x * vh.x + vh.y * vh.y;
    dr_vec3 t1 = lensq > 0.0 ? dr_scale(dr_v3(-vh.y, vh.x, 0.0), 1.0 / sqrt(lensq)) : dr_v3(1.0, 0.0, 0.0);
    dr_vec3 t2 = dr_cross(vh, t1);
    double r = sqrt(u1), cos_phi, sin_phi;
    dr_sincos_turn(u2, &sin_phi, &cos_phi);   /* phi = 2 pi u2 */
    double p1 = r * cos_phi, p2 = r * sin_phi;
    double s = 0.5 * (1.0 + vh.z);
    double c = sqrt(dr_max(0.0, 1.0 - p1 * p1));
    double p2s = (1.0 - s) * c + s * p2;
    double n3 = sqrt(dr_max(0.0, 1.0 - p1 * p1 - p2s * p2s));
    dr_vec3 nh = dr_add(dr_add(dr_scale(t1, p1), dr_scale(t2, p2s)), dr_scale(vh, n3));
    t->m = dr_v3(ax * nh.x, ay * nh.y, dr_max(0.0, nh.z));
    t->h = dr_normalize(t->m);
    t->vh = vh;
    t->lensq = lensq;
    t->t1 = t1;
    t->t2 = t2;
    t->p1 = p1;
    t->p2 = p2;
    t->c = c;
    t->s = s;
    t->p2s = p2s;
    t->n3 = n3;
    t->nh = nh;
    return t->h;
}

static dr_vec3 __attribute__((noinline)) sample_specular_dir(const struct dr_bsdf *b, dr_vec3 wo, double u1, double u2)
{
    struct vndf_tape t;
    const double a = bsdf_alpha(b);
    dr_vec3 h = sample_vndf(wo, b->anisotropy == 0.0 ? a : alpha_x_of(b, a), a, u1, u2, &t);
    return dr_sub(dr_scale(h, 2.0 * dr_dot(wo, h)), wo);
}

dr_vec3 dr_bsdf_cosine_dir(double u1, double u2) { return sample_cosine(u1, u2); }

/* dr_bsdf_sample_dir, with the diffuse lobe inline for dr_bsdf_sample. */
static inline __attribute__((always_inline)) dr_vec3 sample_dir(const struct dr_bsdf *b, dr_vec3 wo,
                                                                enum dr_bsdf_lobe lobe, double u1, double u2)
{
    return lobe != DR_BSDF_LOBE_SPECULAR ? sample_cosine(u1, u2) : sample_specular_dir(b, wo, u1, u2);
}

dr_vec3 dr_bsdf_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2)
{
    if (b->coated)
        return dr_coat_sample_dir(b, wo, lobe, u1, u2);
    if (b->sheened)
        return dr_sheen_sample_dir(b, wo, lobe, u1, u2);
    return sample_dir(b, wo, lobe, u1, u2);
}

bool dr_bsdf_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                    struct dr_bsdf_sample *out)
{
    if (b->coated)
        return dr_coat_sample(b, wo, u_lobe, u1, u2, out);
    if (b->sheened)
        return dr_sheen_sample(b, wo, u_lobe, u1, u2, out);
    out->wi = dr_v3(0.0, 0.0, 1.0);
    out->f = dr_v3s(0.0);
    out->pdf = 0.0;
    out->lobe = DR_BSDF_LOBE_DIFFUSE;
    if (!(wo.z > COS_EPS))
        return false;
    double p = specular_prob(b, wo.z);
    out->lobe = u_lobe < p ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
    dr_vec3 wi = sample_dir(b, wo, out->lobe, u1, u2);
    out->wi = wi;
    if (!(wi.z > COS_EPS))
        return false;
    double pdf;
    dr_vec3 f = eval_pdf_above(b, wo, wi, p, &pdf);
    if (!(pdf > 0.0) || !isfinite(pdf))
        return false;
    out->f = f;
    out->pdf = pdf;
    return true;
}

/* ------------------------------------------------------------ derivatives */

/* The GGX half-vector terms every microfacet evaluation shares: H = wo + wi
 * (not normalised), its squared components and length, q = Hxy^2 + a2 Hz^2
 * and D = a2 (H^2 / q)^2 / pi, the normal distribution at H/|H|. */
struct ggx_half {
    dr_vec3 H;
    double hxy2, hz2, H2, q, D;
};

static inline struct ggx_half ggx_half(double a2, dr_vec3 wo, dr_vec3 wi)
{
    struct ggx_half g;
    g.H = dr_add(wo, wi);
    g.hxy2 = g.H.x * g.H.x + g.H.y * g.H.y;
    g.hz2 = g.H.z * g.H.z;
    g.H2 = g.hxy2 + g.hz2;
    g.q = g.hxy2 + a2 * g.hz2;
    double r = g.H2 / g.q;
    g.D = a2 * r * r * DR_INV_PI;
    return g;
}

/* d ln D / d alpha = (2/alpha) (Hxy^2 - alpha^2 Hz^2) / q. */
static inline double ggx_dlnD_dalpha(double a, double a2, const struct ggx_half *g)
{
    return (2.0 / a) * ((g->hxy2 - a2 * g->hz2) / g->q);
}

/* The Schlick-weighted Fresnel of the two specular lobes at weight s5 =
 * (1 - |H|/2)^5: dielectric F_d = f0 + (f90 - f0) s5 and metal F_m = base +
 * (1 - base) s5, per channel. */
static inline void fresnel_lobes(const struct dr_bsdf *b, double s5, dr_vec3 *fd, dr_vec3 *fm)
{
    const dr_vec3 f0 = dielectric_f0(b), base = b->base_color;
    const double f90 = b->specular;
    *fd = dr_v3(f0.x + (f90 - f0.x) * s5, f0.y + (f90 - f0.y) * s5, f0.z + (f90 - f0.z) * s5);
    *fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5, base.z + (1.0 - base.z) * s5);
}

/* Parameter part of d_bsdf_eval (wo.z, wi.z > COS_EPS). With
 *   kd0 = max(0, 1 - F_o) max(0, 1 - F_i) / pi,   spec = D G2 / (4 wo.z wi.z),
 *   f_c = (1-m) kd0 base_c + (1-m) spec F_d,c + m spec F_m,c,
 *   F_m,c = base_c + (1 - base_c) s5:
 *   df_c/dbase_c = (1-m) kd0 + m spec (1 - s5)
 *   df_c/dm      = -kd0 base_c - spec F_d,c + spec F_m,c
 *   df_c/dalpha  = ((1-m) F_d,c + m F_m,c) dspec/dalpha
 * F_o, F_i, F_d and s5 depend only on specular, specular_color and the
 * directions (so the maxima over channels carry no derivative).
 *
 * dspec/dalpha = spec (dlnD/dalpha - (dL_o/dalpha + dL_i/dalpha) / (1 + L_o + L_i)), where
 *   D = a^2 |H|^4 / (pi q^2), q = Hxy^2 + a^2 Hz^2:
 *     dlnD/da = 2/a - 4 a Hz^2 / q = (2/a) (Hxy^2 - a^2 Hz^2) / q   (the ratio is in [-1, 1])
 *   L = x / (2 (1 + sqrt(1 + x))), x = a^2 tan^2:  dL/dx = 1 / (4 sqrt(1 + x)), dx/da = 2 a tan^2:
 *     dL/da = a tan^2 / (2 sqrt(1 + x))
 * No cancellation and no division by anything that can vanish (a >= 1e-6,
 * q >= a^2 Hz^2 > 0, w.z > COS_EPS), so the result is finite wherever f is.
 * dalpha/droughness = 2 roughness above the floor, 0 at or below it.
 *
 * The pure-Lambertian fast path (metallic == 0, specular == 0) evaluates the
 * general formula exactly (F_d = F_o = F_i = 0, kd0 = 1/pi); its metallic
 * derivative is the general one, -base/pi + spec F_m, which needs spec. */

/* The base colour and metallic parts of d_eval_params, given the microfacet
 * term spec and |H|^2 (isotropic or not, the rest of f is the same): adds
 * them to *d and returns d loss / d spec, 0 for the Lambertian (whose
 * roughness derivative is exactly 0). */
static inline double d_eval_colour_metal(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out,
                                         double spec, double H2, struct dr_d_bsdf *d)
{
    const bool lambert = no_specular_lobe(b);
    const double m = b->metallic;
    const dr_vec3 base = b->base_color;

    double c = 0.5 * sqrt(H2);
    double s5 = pow5(1.0 - dr_clamp(c, 0.0, 1.0));
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    double d_km = dr_dot(d_out, fm);      /* d loss / d (m spec)       */
    double d_kd = dr_dot(d_out, base);    /* d loss / d ((1-m) kd0)    */

    if (lambert) {
        /* m = 0, F_d = 0, kd0 = 1/pi: the roughness derivative is exactly 0. */
        d->base_color = dr_madd(d->base_color, d_out, DR_INV_PI);
        d->metallic += spec * d_km - DR_INV_PI * d_kd;
        return 0.0;
    }

    dr_vec3 f0 = dielectric_f0(b);
    double f90 = b->specular;
    dr_vec3 fd = dr_v3(f0.x + (f90 - f0.x) * s5, f0.y + (f90 - f0.y) * s5, f0.z + (f90 - f0.z) * s5);
    double f0max = dr_max3(f0);
    double fo = f0max + (f90 - f0max) * pow5(1.0 - wo.z), fi = f0max + (f90 - f0max) * pow5(1.0 - wi.z);
    double kd0 = dr_max(0.0, 1.0 - fo) * dr_max(0.0, 1.0 - fi) * DR_INV_PI;
    double d_ks = dr_dot(d_out, fd);      /* d loss / d ((1-m) spec)   */

    d->base_color = dr_madd(d->base_color, d_out, (1.0 - m) * kd0 + m * spec * (1.0 - s5));
    d->metallic += spec * (d_km - d_ks) - kd0 * d_kd;
    return (1.0 - m) * d_ks + m * d_km;
}

/* d loss / d alpha_x and d alpha_y of the stretched lobe into roughness and
 * anisotropy: alpha_x = alpha + (1 - alpha) s^2, alpha_y = alpha, alpha =
 * rough^2 above the floor, so
 *   d ax / d rough = (1 - s^2) 2 rough, d ay / d rough = 2 rough (0 at or below the floor),
 *   d ax / d s = 2 s (1 - alpha), d ay / d s = 0 (the floored alpha's: alpha_x moves with s there too). */
static inline void d_alphas(const struct dr_bsdf *b, double d_ax, double d_ay, struct dr_d_bsdf *d)
{
    const double rough = b->roughness, s = b->anisotropy;
    if (rough * rough > DR_BSDF_MIN_ALPHA)
        d->roughness += (d_ax * (1.0 - s * s) + d_ay) * (2.0 * rough);
    d->anisotropy += d_ax * (2.0 * s * (1.0 - bsdf_alpha(b)));
}

/* d ln D / d ax and d ay of the stretched lobe: ln D = ln ax + ln ay + 4 ln|H|
 * - 2 ln q, d q / d ax = -Hx^2 ay/ax^2 + Hy^2/ay + ay Hz^2, so over one
 * denominator
 *   d lnD/d ax = (3 Hx^2 ay/ax - Hy^2 ax/ay - ax ay Hz^2) / (ax q),
 *   d lnD/d ay = (3 Hy^2 ax/ay - Hx^2 ay/ax - ax ay Hz^2) / (ay q)
 * (each ratio in [-1, 3]; their sum at ax = ay = a is the isotropic
 * (2/a) (Hxy^2 - a^2 Hz^2) / q). */
static inline void ggx_aniso_dlnD(double ax, double ay, const struct ggx_aniso *g, double *dax, double *day)
{
    const double tx = g->hx2 * (ay / ax), ty = g->hy2 * (ax / ay), tz = ax * ay * g->hz2;
    *dax = (3.0 * tx - ty - tz) / g->q / ax;
    *day = (3.0 * ty - tx - tz) / g->q / ay;
}

/* d_eval_params of the stretched lobe: as the isotropic one below with
 *   dspec/dax = spec (dlnD/dax - (dL_o/dax + dL_i/dax) / (1 + L_o + L_i)),
 * alike in ay (ggx_aniso_dlnD, smith_lambda_aniso), then d_alphas. */
static void d_eval_params_aniso(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out,
                                struct dr_d_bsdf *d)
{
    const double ay = bsdf_alpha(b), ax = alpha_x_of(b, ay);
    const struct ggx_aniso g_h = ggx_aniso(ax, ay, wo, wi);
    double dlo_x, dlo_y, dli_x, dli_y;
    double lo = smith_lambda_aniso(ax, ay, wo, &dlo_x, &dlo_y), li = smith_lambda_aniso(ax, ay, wi, &dli_x, &dli_y);
    double g = 1.0 + lo + li;
    double spec = g_h.D / (4.0 * wo.z * g * wi.z);
    double d_spec = d_eval_colour_metal(b, wo, wi, d_out, spec, g_h.H2, d);
    if (d_spec == 0.0)
        return;
    double dlnD_x, dlnD_y;
    ggx_aniso_dlnD(ax, ay, &g_h, &dlnD_x, &dlnD_y);
    double k = d_spec * spec;
    d_alphas(b, k * (dlnD_x - (dlo_x + dli_x) / g), k * (dlnD_y - (dlo_y + dli_y) / g), d);
}

static void d_eval_params(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out,
                          struct dr_d_bsdf *d)
{
    if (b->anisotropy != 0.0) {
        d_eval_params_aniso(b, wo, wi, d_out, d);
        return;
    }
    /* Microfacet term spec = D G2 / (4 wo.z wi.z), shared by both lobes. */
    double a = bsdf_alpha(b), a2 = a * a;
    const struct ggx_half g_h = ggx_half(a2, wo, wi);
    double tan2o = (wo.x * wo.x + wo.y * wo.y) / (wo.z * wo.z);
    double tan2i = (wi.x * wi.x + wi.y * wi.y) / (wi.z * wi.z);
    double xo = a2 * tan2o, xi = a2 * tan2i;
    double so = sqrt(1.0 + xo), si = sqrt(1.0 + xi);
    double lo = 0.5 * xo / (1.0 + so), li = 0.5 * xi / (1.0 + si);
    double g = 1.0 + lo + li;
    double spec = g_h.D / (4.0 * wo.z * g * wi.z);

    double d_spec = d_eval_colour_metal(b, wo, wi, d_out, spec, g_h.H2, d);
    double rough = b->roughness;
    if (d_spec == 0.0 || !(rough * rough > DR_BSDF_MIN_ALPHA))
        return;
    double dlnD = ggx_dlnD_dalpha(a, a2, &g_h);
    double dlo = 0.5 * a * tan2o / so, dli = 0.5 * a * tan2i / si;
    double dspec_da = spec * (dlnD - (dlo + dli) / g);
    d->roughness += d_spec * dspec_da * (2.0 * rough);
}

/* ---------------------------------------------- direction adjoints: pieces */

static inline double pow4(double s)
{
    double s2 = s * s;
    return s2 * s2;
}

/* Gradient of ln D with respect to the unnormalised half vector H, for
 * D = a^2 |H|^4 / (pi q^2), q = Hxy^2 + a^2 Hz^2:
 *   d lnD/dH = 4 H / |H|^2 - 4 (Hx, Hy, a^2 Hz) / q.
 * The two terms cancel in z where H is near the normal (the peak of a narrow
 * lobe, where accuracy matters most) and in x, y where roughness is near 1 or
 * H is far from the normal, so they are combined over |H|^2 q first
 * (q - |H|^2 = -(1 - a^2) Hz^2, q - a^2 |H|^2 = (1 - a^2) Hxy^2):
 *   d lnD/dHxy = -4 (1 - a^2) Hxy (Hz^2 / |H|^2) / q,   d lnD/dHz = 4 (1 - a^2) Hz (Hxy^2 / |H|^2) / q.
 * Bounded: |Hxy| / q <= 1 / (2 a |Hz|) and Hxy^2 / q <= 1, so the only large
 * values are the genuine ones of a narrow lobe (no overflow for a >= 1e-7,
 * Hz > 2e-12). Exactly zero in x, y for H along the normal. */
static inline dr_vec3 grad_ln_D(double a2, dr_vec3 H, double hxy2, double hz2, double H2, double q)
{
    double k = 4.0 * (1.0 - a2);
    double kxy = -k * (hz2 / H2) / q, kz = k * (hxy2 / H2) / q;
    return dr_v3(kxy * H.x, kxy * H.y, kz * H.z);
}

/* Gradient of smith_lambda(a2, w) with respect to w (w.z > COS_EPS). With
 * x = a^2 (wx^2 + wy^2) / wz^2: dLambda/dx = 1 / (4 sqrt(1 + x)) (from
 * Lambda = (-1 + sqrt(1 + x)) / 2), dx/dwxy = 2 a^2 wxy / wz^2, dx/dwz = -2 x / wz.
 * At wz = 1e-12 the pieces stay below ~1e36: finite. */
static inline dr_vec3 grad_lambda(double a2, dr_vec3 w)
{
    double iz2 = 1.0 / (w.z * w.z);
    double x = a2 * (w.x * w.x + w.y * w.y) * iz2;
    double k = 0.25 / sqrt(1.0 + x);
    double kxy = k * (2.0 * a2 * iz2);
    return dr_v3(kxy * w.x, kxy * w.y, -k * (2.0 * x / w.z));
}

/* Gradient of ln D of the stretched lobe with respect to H: ln D = 4 ln|H| -
 * 2 ln q + const, q = Hx^2 ay/ax + Hy^2 ax/ay + ax ay Hz^2, so
 *   d lnD/dH = 4 H / |H|^2 - 4 (Hx ay/ax, Hy ax/ay, Hz ax ay) / q,
 * combined over |H|^2 q as grad_ln_D does (component c: 4 H_c (q - |H|^2 k_c)
 * / (|H|^2 q), k the factors above), where the differences are, with
 * sxy = ax/ay - ay/ax = (ax - ay)(ax + ay) / (ax ay) >= 0:
 *   q - |H|^2 ay/ax = Hy^2 sxy - Hz^2 ay (1 - ax^2) / ax,
 *   q - |H|^2 ax/ay = -Hx^2 sxy - Hz^2 ax (1 - ay^2) / ay,
 *   q - |H|^2 ax ay = Hx^2 ay (1 - ax^2) / ax + Hy^2 ax (1 - ay^2) / ay:
 * no cancellation between large terms, and at ax = ay = a exactly the
 * isotropic expressions. Each bracket over q is bounded as there
 * (Hy^2 sxy <= Hy^2 ax/ay <= q, ...). */
static inline dr_vec3 grad_ln_D_aniso(double ax, double ay, const struct ggx_aniso *g)
{
    const double sxy = (ax - ay) * (ax + ay) / (ax * ay);
    const double zx = ay * (1.0 - ax * ax) / ax, zy = ax * (1.0 - ay * ay) / ay;
    const double k = 4.0 / g->H2;
    return dr_v3(k * g->H.x * ((g->hy2 * sxy - g->hz2 * zx) / g->q),
                 k * g->H.y * ((-g->hx2 * sxy - g->hz2 * zy) / g->q),
                 k * g->H.z * ((g->hx2 * zx + g->hy2 * zy) / g->q));
}

/* Gradient of smith_lambda_aniso in w, as grad_lambda with
 * x = (ax^2 wx^2 + ay^2 wy^2) / wz^2: dx/dwx = 2 ax^2 wx / wz^2, alike in y,
 * dx/dwz = -2 x / wz. */
static inline dr_vec3 grad_lambda_aniso(double ax, double ay, dr_vec3 w)
{
    double iz2 = 1.0 / (w.z * w.z);
    double ax2 = ax * ax, ay2 = ay * ay;
    double x = (ax2 * w.x * w.x + ay2 * w.y * w.y) * iz2;
    double k = 0.25 / sqrt(1.0 + x);
    return dr_v3(k * (2.0 * ax2 * iz2) * w.x, k * (2.0 * ay2 * iz2) * w.y, -k * (2.0 * x / w.z));
}

/* The GGX terms the direction adjoints share, for the base's lobe whether
 * isotropic (the very operations the isotropic code always did) or
 * stretched: D, |H|^2, Lambda both ways and the gradients of ln D in H and
 * of Lambda in wo (and in wi when with_wi). g_h: the isotropic terms (not
 * filled when stretched). */
struct ggx_dirs {
    dr_vec3 H, dlnD_dH, dlo, dli;
    double H2, D, lo, li;
    struct ggx_half g_h;
};

static inline void ggx_dir_terms(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, bool with_wi, struct ggx_dirs *t)
{
    const double a = bsdf_alpha(b);
    if (b->anisotropy == 0.0) {
        const double a2 = a * a;
        t->g_h = ggx_half(a2, wo, wi);
        t->H = t->g_h.H, t->H2 = t->g_h.H2, t->D = t->g_h.D;
        t->lo = smith_lambda(a2, wo), t->li = smith_lambda(a2, wi);
        t->dlnD_dH = grad_ln_D(a2, t->g_h.H, t->g_h.hxy2, t->g_h.hz2, t->g_h.H2, t->g_h.q);
        t->dlo = grad_lambda(a2, wo);
        t->dli = with_wi ? grad_lambda(a2, wi) : dr_v3s(0.0);
        return;
    }
    const double ax = alpha_x_of(b, a);
    const struct ggx_aniso g = ggx_aniso(ax, a, wo, wi);
    t->H = g.H, t->H2 = g.H2, t->D = g.D;
    t->lo = smith_lambda_aniso(ax, a, wo, NULL, NULL), t->li = smith_lambda_aniso(ax, a, wi, NULL, NULL);
    t->dlnD_dH = grad_ln_D_aniso(ax, a, &g);
    t->dlo = grad_lambda_aniso(ax, a, wo);
    t->dli = with_wi ? grad_lambda_aniso(ax, a, wi) : dr_v3s(0.0);
}

/* d s5 / d c for s5 = (1 - clamp(c, 0, 1))^5: the clamp is flat outside (0, 1). */
static inline double ds5_dc(double c)
{
    return c > 0.0 && c < 1.0 ? -5.0 * pow4(1.0 - c) : 0.0;
}

/* ---------------------------------------------------- d_bsdf_eval: directions */

/* Direction part of d_bsdf_eval on the general path (wo.z, wi.z > COS_EPS).
 * f_c = base_c kd + F_d,c (1-m) spec + F_m,c m spec, and the directions enter
 * through four quantities only:
 *   spec = D(H) / (4 wo.z (1 + L_o + L_i) wi.z), H = wo + wi: differentiated in
 *     log form, d spec = spec (d lnD - dwo.z/wo.z - dwi.z/wi.z - (dL_o + dL_i) / g),
 *     because spec spans ~50 orders of magnitude while its log-derivative stays
 *     moderate (see grad_ln_D, grad_lambda);
 *   s5 = (1 - c)^5, c = |H| / 2 (the Fresnel cosine; the primal never forms
 *     wo.h): dc/dH = H / (4 c);
 *   F_o, F_i = f0max + (f90 - f0max)(1 - z)^5 of wo.z, wi.z, inside
 *     kd = (1-m) max(0, 1 - F_o) max(0, 1 - F_i) / pi (zero slope where a max clamps).
 * H feeds both directions equally, which is why d_H is added to both. */
static void d_eval_dirs(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, dr_vec3 *d_wo,
                        dr_vec3 *d_wi)
{
    const double m = b->metallic;
    const dr_vec3 base = b->base_color;
    struct ggx_dirs t;
    ggx_dir_terms(b, wo, wi, true, &t);
    double g = 1.0 + t.lo + t.li;
    double spec = t.D / (4.0 * wo.z * g * wi.z);

    double c = 0.5 * sqrt(t.H2);
    double s5 = pow5(1.0 - dr_clamp(c, 0.0, 1.0));
    dr_vec3 f0 = dielectric_f0(b);
    double f90 = b->specular;
    dr_vec3 fd, fm;
    fresnel_lobes(b, s5, &fd, &fm);
    double gs = ((1.0 - m) * dr_dot(d_out, fd) + m * dr_dot(d_out, fm)) * spec;  /* d loss / d ln spec */
    /* d loss / d s5: F_d,c has slope f90 - f0_c, F_m,c has slope 1 - base_c */
    double d_s5 = spec * ((1.0 - m) * dr_dot(d_out, dr_sub(dr_v3s(f90), f0)) +
                          m * dr_dot(d_out, dr_sub(dr_v3s(1.0), base)));
    double d_c = d_s5 * ds5_dc(c);
    dr_vec3 d_H = dr_scale(t.dlnD_dH, gs);
    if (d_c != 0.0)
        d_H = dr_madd(d_H, t.H, d_c * 0.25 / c);

    dr_vec3 go = dr_madd(d_H, t.dlo, -gs / g);
    dr_vec3 gi = dr_madd(d_H, t.dli, -gs / g);
    go.z -= gs / wo.z;
    gi.z -= gs / wi.z;

    double f0max = dr_max3(f0);
    double fo = f0max + (f90 - f0max) * pow5(1.0 - wo.z), fi = f0max + (f90 - f0max) * pow5(1.0 - wi.z);
    double d_kk = dr_dot(d_out, base) * (1.0 - m) * DR_INV_PI;  /* d loss / d [max(0,1-F_o) max(0,1-F_i)] */
    double dF = -5.0 * (f90 - f0max);                            /* dF/dz = dF (1 - z)^4 */
    if (1.0 - fo > 0.0)
        go.z -= d_kk * dr_max(0.0, 1.0 - fi) * dF * pow4(1.0 - wo.z);
    if (1.0 - fi > 0.0)
        gi.z -= d_kk * dr_max(0.0, 1.0 - fo) * dF * pow4(1.0 - wi.z);
    if (d_wo)
        *d_wo = dr_add(*d_wo, go);
    if (d_wi)
        *d_wi = dr_add(*d_wi, gi);
}

/* Reverse mode of dr_bsdf_eval. The parameter part is d_eval_params, whose
 * arithmetic is kept exactly as it was when the directions were constants:
 * the estimators compare their gradients bit for bit. */
void d_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    if (b->coated) {
        d_coat_eval(b, wo, wi, d_out, d, d_wo, d_wi);
        return;
    }
    if (b->sheened) {
        d_sheen_eval(b, wo, wi, d_out, d, d_wo, d_wi);
        return;
    }
    if (d)
        d_eval_params(b, wo, wi, d_out, d);
    /* The Lambertian fast path, f = base / pi, does not depend on the directions. */
    if ((d_wo || d_wi) && !no_specular_lobe(b))
        d_eval_dirs(b, wo, wi, d_out, d_wo, d_wi);
}

/* ------------------------------------------------------ d_bsdf_pdf and p */

/* Adjoint of specular_prob(b, cos_o) for d_p = d loss / d p: adds the
 * parameter part to *d (if not NULL) and returns d loss / d cos_o.
 *   p = ws / (ws + wd),  ws = (1-m) F + m lum(F_m),  wd = (1-m) (1 - F) lum(base),
 *   F = f0max + (specular - f0max) s5,  F_m,c = base_c + (1 - base_c) s5,
 *   s5 = (1 - clamp(cos_o, 0, 1))^5,
 * so dp = (wd dws - ws dwd) / (ws + wd)^2. The primal's shortcuts p = 1
 * (wd = 0) and p = 0 (ws = 0, which includes the Lambertian early return) are
 * the ratio's own values, so the ratio's derivative applies there as well: at
 * the domain's edges (metallic 1, base 0) it is the one-sided derivative from
 * inside, and for a Lambertian it is the general formula's metallic
 * derivative, as in d_bsdf_eval. Only ws = wd = 0 (black Lambertian; black
 * metal at exactly normal incidence) is a jump of p: zero there. */
static double d_specular_prob(const struct dr_bsdf *b, double cos_o, double d_p, struct dr_d_bsdf *d)
{
    const double m = b->metallic;
    const dr_vec3 base = b->base_color;
    double t = 1.0 - dr_clamp(cos_o, 0.0, 1.0);
    double s5 = pow5(t);
    double f0max = dr_max3(dielectric_f0(b));
    double fd = f0max + (b->specular - f0max) * s5;
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    double lb = dr_luminance(base), lfm = dr_luminance(fm);
    double ws = (1.0 - m) * fd + m * lfm, wd = (1.0 - m) * (1.0 - fd) * lb;
    double sum = ws + wd;
    if (!(sum > 0.0) || d_p == 0.0)
        return 0.0;
    double k = d_p / sum;
    double d_ws = k * (wd / sum), d_wd = -k * (ws / sum);
    if (d) {
        d->metallic += d_ws * (lfm - fd) - d_wd * (1.0 - fd) * lb;
        /* lum is linear: d lum(v) / dv_c is the luminance of the c-th unit vector */
        double kb = d_ws * m * (1.0 - s5) + d_wd * (1.0 - m) * (1.0 - fd);
        d->base_color = dr_add(d->base_color, dr_v3(dr_luminance(dr_v3(kb, 0.0, 0.0)),
                                                     dr_luminance(dr_v3(0.0, kb, 0.0)),
                                                     dr_luminance(dr_v3(0.0, 0.0, kb))));
    }
    double dfd = b->specular - f0max;   /* dF/ds5 */
    double d_s5 = d_ws * ((1.0 - m) * dfd + m * dr_luminance(dr_sub(dr_v3s(1.0), base))) -
                  d_wd * (1.0 - m) * dfd * lb;
    return cos_o > 0.0 && cos_o < 1.0 ? -5.0 * pow4(t) * d_s5 : 0.0;
}

void d_bsdf_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    if (b->coated) {
        d_coat_specular_prob(b, wo, d_p, d, d_wo);
        return;
    }
    if (b->sheened) {
        d_sheen_specular_prob(b, wo, d_p, d, d_wo);
        return;
    }
    /* Below the surface dr_bsdf_specular_prob is p at cos_o = 0, a constant in wo. */
    bool above = wo.z > COS_EPS;
    double d_cos = d_specular_prob(b, above ? wo.z : 0.0, d_p, d);
    if (above && d_wo)
        d_wo->z += d_cos;
}

/* Reverse mode of dr_bsdf_pdf: pdf = (1-p) wi.z / pi + p P_s with
 *   P_s = D / (4 wo.z (1 + L_o)) = G1(wo) D / (4 wo.z), the visible-normal
 *   density D_wo(h) = G1(wo) max(0, wo.h) D / wo.z times the reflection's
 *   Jacobian 1 / (4 wo.h) (the wo.h cancel, so the primal never forms it);
 *   p = specular_prob(wo.z), whose adjoint is d_specular_prob.
 * d pdf = (P_s - wi.z/pi) dp + (1-p) dwi.z / pi + p P_s d ln P_s,
 *   d ln P_s = d lnD - dwo.z / wo.z - dL_o / (1 + L_o)   (log form as in d_eval_dirs),
 *   d lnD/da = (2/a) (Hxy^2 - a^2 Hz^2) / q, dL/da = a tan^2 / (2 sqrt(1 + x)) (see d_eval_params).
 * The Lambertian fast path returns wi.z / pi, the general formula at p = 0;
 * its metallic derivative is the general one, (P_s - wi.z/pi) dp/dm, so P_s
 * is computed there too. */
static void d_pdf_impl(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, bool prob_moves,
                  struct dr_d_bsdf *d, dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const double rough = b->roughness;
    double p = specular_prob(b, wo.z);
    double cos_pdf = wi.z * DR_INV_PI;
    double a = bsdf_alpha(b), a2 = a * a;
    struct ggx_dirs t;
    ggx_dir_terms(b, wo, wi, false, &t);
    double lo = t.lo;
    double ps = t.D / (4.0 * wo.z) / (1.0 + lo);
    double d_cos_o = prob_moves ? d_specular_prob(b, wo.z, d_pdf * (ps - cos_pdf), d) : 0.0;
    double gs = d_pdf * p * ps;   /* d loss / d ln P_s */
    if (d && gs != 0.0 && b->anisotropy != 0.0) {
        /* stretched: d ln P_s / d ax = dlnD/dax - dL_o/dax / (1 + L_o), alike in ay */
        const double ax = alpha_x_of(b, a);
        const struct ggx_aniso g = ggx_aniso(ax, a, wo, wi);
        double dlo_x, dlo_y, dlnD_x, dlnD_y;
        smith_lambda_aniso(ax, a, wo, &dlo_x, &dlo_y);
        ggx_aniso_dlnD(ax, a, &g, &dlnD_x, &dlnD_y);
        d_alphas(b, gs * (dlnD_x - dlo_x / (1.0 + lo)), gs * (dlnD_y - dlo_y / (1.0 + lo)), d);
    } else if (d && gs != 0.0 && rough * rough > DR_BSDF_MIN_ALPHA) {
        double dlnD = ggx_dlnD_dalpha(a, a2, &t.g_h);
        double tan2o = (wo.x * wo.x + wo.y * wo.y) / (wo.z * wo.z);
        double dlo = 0.5 * a * tan2o / sqrt(1.0 + a2 * tan2o);
        d->roughness += gs * (dlnD - dlo / (1.0 + lo)) * (2.0 * rough);
    }
    dr_vec3 d_H = dr_scale(t.dlnD_dH, gs);
    if (d_wo) {
        dr_vec3 go = dr_madd(d_H, t.dlo, -gs / (1.0 + lo));
        go.z += d_cos_o - gs / wo.z;
        *d_wo = dr_add(*d_wo, go);
    }
    if (d_wi) {
        d_H.z += d_pdf * (1.0 - p) * DR_INV_PI;
        *d_wi = dr_add(*d_wi, d_H);
    }
}

void d_bsdf_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, struct dr_d_bsdf *d,
                dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (b->coated)
        d_coat_pdf(b, wo, wi, d_pdf, true, d, d_wo, d_wi);
    else if (b->sheened)
        d_sheen_pdf(b, wo, wi, d_pdf, true, d, d_wo, d_wi);
    else
        d_pdf_impl(b, wo, wi, d_pdf, true, d, d_wo, d_wi);
}

void d_bsdf_pdf_fixed_prob(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, struct dr_d_bsdf *d,
                           dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (b->coated)
        d_coat_pdf(b, wo, wi, d_pdf, false, d, d_wo, d_wi);
    else if (b->sheened)
        d_sheen_pdf(b, wo, wi, d_pdf, false, d, d_wo, d_wi);
    else
        d_pdf_impl(b, wo, wi, d_pdf, false, d, d_wo, d_wi);
}

/* --------------------------------------------------- sampling map adjoints */

/* Adjoint of sample_vndf: given d_h = d loss / d h, adds d loss / d wo to
 * *d_wo and d loss / d a to *d_a, walking the forward steps backwards with the
 * intermediates in *t (p1, p2 and c depend on u only):
 *   h = m / |m|, m = (a nh.x, a nh.y, max(0, nh.z))   d_m = (d_h - h (h.d_h)) / |m|
 *   nh = p1 t1 + p2s t2 + n3 vh, n3 = sqrt(1 - p1^2 - p2s^2)
 *   p2s = (1 - s) c + s p2, s = (1 + vh.z) / 2
 *   t2 = vh x t1                                     d_vh += t1 x d_t2, d_t1 += d_t2 x vh
 *   t1 = e / |e|, e = (-vh.y, vh.x, 0)
 *   vh = v / |v|, v = (a wo.x, a wo.y, wo.z)
 * Where the map is not differentiable the adjoint is that of the branch taken:
 *  - t1 is the azimuthal frame around vh; at vh = n (wo along the normal) it
 *    jumps to (1, 0, 0) and the sampled direction turns with wo's azimuth, so
 *    the map itself is discontinuous there. Its derivative grows like
 *    1 / sin(theta_v) towards that point (a property of Heitz's map, not of
 *    the adjoint); exactly at it, the constant branch's zero.
 *  - n3 has slope -p2s / n3, unbounded at the disk's rim (u1 -> 1) where
 *    n3 -> 0; at n3 == 0 (u1 = 1, or rounding) the clamp's zero slope.
 *  - max(0, nh.z) clamps only when h ends up horizontal, and then the
 *    reflection lies below the surface and the sample is rejected.
 * The stretched lobe's map has ax in x and ay in y where a stands above
 * (v = (ax wo.x, ay wo.y, wo.z), m = (ax nh.x, ay nh.y, ...)); its alpha
 * adjoints go to *d_a (ax) and *d_ay. d_ay NULL: the isotropic map of
 * a = ax = ay, its adjoint summed into *d_a in the very order the
 * isotropic code always did. */
static void d_sample_vndf(dr_vec3 wo, double a, double ay, const struct vndf_tape *t, dr_vec3 d_h, dr_vec3 *d_wo,
                          double *d_a, double *d_ay)
{
    double lm = dr_length(t->m);
    if (!(lm > 0.0))
        return;
    dr_vec3 d_m = dr_scale(dr_sub(d_h, dr_scale(t->h, dr_dot(t->h, d_h))), 1.0 / lm);
    if (d_ay)
        *d_a += t->nh.x * d_m.x, *d_ay += t->nh.y * d_m.y;
    else
        *d_a += t->nh.x * d_m.x + t->nh.y * d_m.y;
    dr_vec3 d_nh = dr_v3(a * d_m.x, ay * d_m.y, t->nh.z > 0.0 ? d_m.z : 0.0);
    dr_vec3 d_t1 = dr_scale(d_nh, t->p1), d_t2 = dr_scale(d_nh, t->p2s), d_vh = dr_scale(d_nh, t->n3);
    double d_p2s = dr_dot(t->t2, d_nh);
    if (t->n3 > 0.0)
        d_p2s -= dr_dot(t->vh, d_nh) * (t->p2s / t->n3);
    d_vh.z += 0.5 * d_p2s * (t->p2 - t->c);
    d_vh = dr_add(d_vh, dr_cross(t->t1, d_t2));
    d_t1 = dr_add(d_t1, dr_cross(d_t2, t->vh));
    if (t->lensq > 0.0) {
        dr_vec3 d_e = dr_scale(dr_sub(d_t1, dr_scale(t->t1, dr_dot(t->t1, d_t1))), 1.0 / sqrt(t->lensq));
        d_vh.x += d_e.y;
        d_vh.y -= d_e.x;
    }
    dr_vec3 d_v = dr_scale(dr_sub(d_vh, dr_scale(t->vh, dr_dot(t->vh, d_vh))), 1.0 / dr_length(t->v));
    if (d_ay)
        *d_a += wo.x * d_v.x, *d_ay += wo.y * d_v.y;
    else
        *d_a += wo.x * d_v.x + wo.y * d_v.y;
    *d_wo = dr_add(*d_wo, dr_v3(a * d_v.x, ay * d_v.y, d_v.z));
}

/* Reverse mode of dr_bsdf_sample_dir. The cosine map (u1, u2) -> wi involves
 * neither the parameters nor wo: it contributes nothing. The specular map is
 * wi = 2 (wo.h) h - wo with h = sample_vndf(wo, alpha): the reflection gives
 *   d_h = 2 (wo.h) d_wi + 2 (h.d_wi) wo,   d_wo (direct) = 2 (h.d_wi) h - d_wi,
 * then d_sample_vndf; d alpha / d roughness = 2 roughness above the floor.
 * A stretched lobe's map (alpha_x, alpha_y) takes its two alpha adjoints to
 * roughness and anisotropy by d_alphas (the anisotropy's also below the
 * roughness floor). */
void d_bsdf_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                       dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    if (b->coated) {
        d_coat_sample_dir(b, wo, lobe, u1, u2, d_wi, d, d_wo);
        return;
    }
    if (b->sheened) {
        d_sheen_sample_dir(b, wo, lobe, u1, u2, d_wi, d, d_wo);
        return;
    }
    if (lobe != DR_BSDF_LOBE_SPECULAR || !(wo.z > COS_EPS))
        return;
    const double rough = b->roughness;
    const bool aniso = b->anisotropy != 0.0;
    const bool at_floor = !(rough * rough > DR_BSDF_MIN_ALPHA);
    if (!d_wo && (!d || (at_floor && !aniso)))
        return;
    double a = bsdf_alpha(b), ax = aniso ? alpha_x_of(b, a) : a;
    struct vndf_tape t;
    dr_vec3 h = sample_vndf(wo, ax, a, u1, u2, &t);
    double oh = dr_dot(wo, h), hd = dr_dot(h, d_wi);
    dr_vec3 d_h = dr_add(dr_scale(d_wi, 2.0 * oh), dr_scale(wo, 2.0 * hd));
    dr_vec3 g_wo = dr_sub(dr_scale(h, 2.0 * hd), d_wi);
    double d_a = 0.0, d_ay = 0.0;
    d_sample_vndf(wo, ax, a, &t, d_h, &g_wo, &d_a, aniso ? &d_ay : NULL);
    if (d_wo)
        *d_wo = dr_add(*d_wo, g_wo);
    if (d && aniso)
        d_alphas(b, d_a, d_ay, d);
    else if (d && !at_floor)
        d->roughness += d_a * (2.0 * rough);
}

/* ------------------------------------------- derivative sampling densities */

/* --sampling derivative (path_deriv.c) samples the derivative integrand
 * d f / d theta (wo, wi) L_in(wi) cos with a density made for d f / d theta,
 * a mixture of lobes (bsdf.h: enum dr_bsdf_dlobe):
 *
 *   cosine    wi.z / pi: the derivative of f in base colour, for the diffuse
 *             lobe, is the diffuse lobe itself (1-m)(1-F_o)(1-F_i) / pi
 *             (times no colour: the colour is the parameter);
 *   vndf      the forward specular map's density (Heitz 2018): the base
 *             colour derivative of a metal, m (1 - s5) D G / (4 cos cos),
 *             and the positive part of the metallic derivative
 *             spec (F_m - F_d) are the specular lobe with a different
 *             Fresnel factor;
 *   rough+/-  the positivized roughness derivative of GGX D (Zeltner et al.
 *             2021; Belhe et al. 2024 sample the positive and negative
 *             parts of d D / d alpha separately). In slope space,
 *             u = tan^2(theta_h) / alpha^2, GGX is D cos(theta_h) dw_h =
 *             du / (1+u)^2 dphi / (2 pi), and
 *               d lnD / d alpha = 2 (u - 1) / (alpha (1 + u)),
 *             so d/dalpha [D cos dw_h] = (2/alpha) (u-1) / (1+u)^3 du dphi/2pi,
 *             positive for u > 1 (wide half vectors), negative for u < 1,
 *             each part of mass 1 / (2 alpha) (they cancel: D stays
 *             normalised). Normalised, in u:
 *               p+(u) = 4 (u-1) / (1+u)^3 (u > 1),  CDF ((u-1)/(u+1))^2,
 *                       inverse u = (1+s)/(1-s), s = sqrt(xi);
 *               p-(u) = 4 (1-u) / (1+u)^3 (u < 1),  CDF 4u / (1+u)^2,
 *                       inverse u = (1-t)/(1+t), t = sqrt(1-xi);
 *             as densities of h: p+-(h) = 2 alpha |d D / d alpha| cos(theta_h)
 *             on its side (= 4 |u-1| / (1+u) D cos(theta_h)), and of wi by
 *             the reflection's Jacobian 1 / (4 wo.h);
 *   coat+/-   the same pair at the clear coat's alpha, for its roughness
 *             (a coated BSDF's c f_coat is the coat lobe's GGX times c).
 *
 * Under a coat, the base's integrands are the base's times the coat's
 * transmission to ti (bsdf_coat.c), a smooth factor <= 1: the base's lobes
 * serve them unchanged.
 *
 * The metallic derivative is a signed mixture: spec (F_m - F_d) (positive
 * where the metal reflects more than the dielectric, i.e. almost always)
 * minus the diffuse lobe (negative): positivized, each sign with its own
 * lobe, vndf and cosine. The G and Fresnel parts of the roughness derivative
 * (D dG/dalpha) are left to the forward sampler, with which the estimator
 * combines these densities by the balance heuristic (path_deriv.c); that is
 * also why a lobe need not cover the whole integrand, only its bulk.
 *
 * Anisotropy (KHR_materials_anisotropy): the vndf lobe is the forward map,
 * so it follows the stretched lobe; the roughness pair splits the stretched
 * lobe where d D / d alpha changes sign, azimuth by azimuth (rough_split),
 * and the NDF part is the roughness's share of the stretched D's
 * derivative (d_eval_rough_ndf_aniso).
 *
 * Every lobe density is of wi, zero below the surface; samples a lobe maps
 * below the surface (or, for the microfacet lobes, with wo.h <= 0) are
 * rejected, so a lobe's density of valid directions integrates to at most 1
 * (the rest is the rejection probability). */

void dr_bsdf_deriv_weights(const struct dr_bsdf *b, unsigned params, double w[DR_BSDF_DLOBE_COUNT])
{
    for (int l = 0; l < DR_BSDF_DLOBE_COUNT; l++)
        w[l] = 0.0;
    int kinds = ((params & DR_BSDF_D_BASE) != 0) + ((params & DR_BSDF_D_METALLIC) != 0) +
                ((params & DR_BSDF_D_ROUGHNESS) != 0) + ((params & DR_BSDF_D_COAT_ROUGHNESS) != 0);
    if (kinds == 0)
        return;
    double k = 1.0 / kinds;   /* each requested parameter gets an equal share */
    if (params & DR_BSDF_D_BASE) {
        double m = dr_clamp(b->metallic, 0.0, 1.0);
        w[DR_BSDF_DLOBE_COSINE] += k * (1.0 - m);
        w[DR_BSDF_DLOBE_VNDF] += k * m;
    }
    if (params & DR_BSDF_D_METALLIC) {
        w[DR_BSDF_DLOBE_COSINE] += 0.5 * k;
        w[DR_BSDF_DLOBE_VNDF] += 0.5 * k;
    }
    if (params & DR_BSDF_D_ROUGHNESS) {
        w[DR_BSDF_DLOBE_ROUGH_POS] += 0.5 * k;
        w[DR_BSDF_DLOBE_ROUGH_NEG] += 0.5 * k;
    }
    if (params & DR_BSDF_D_COAT_ROUGHNESS) {
        w[DR_BSDF_DLOBE_COAT_POS] += 0.5 * k;
        w[DR_BSDF_DLOBE_COAT_NEG] += 0.5 * k;
    }
}

/* A coat lobe as the same lobe of the coat's own BSDF (bsdf_coat.c's
 * coat_lobe: alpha its roughness's). */
static inline enum dr_bsdf_dlobe coat_as_rough(enum dr_bsdf_dlobe lobe)
{
    return lobe == DR_BSDF_DLOBE_COAT_POS ? DR_BSDF_DLOBE_ROUGH_POS : DR_BSDF_DLOBE_ROUGH_NEG;
}

/* The stretched lobe's pair (anisotropic roughness). In the stretched
 * slopes t = (sx / alpha_x, sy / alpha_y), u = |t|^2 and their azimuth phi,
 * the lobe is du / (1 + u)^2 dphi / (2 pi) whatever the alphas, and
 *   d ln D / d alpha = cx (4 tx^2 / (1 + u) - 1) + cy (4 ty^2 / (1 + u) - 1)
 *                    = (u k - c) / (1 + u),
 * cx = (1 - s^2) / alpha_x, cy = 1 / alpha_y (d alpha_x / d alpha = 1 -
 * s^2), c = cx + cy, k(phi) = c + 2 (cx - cy) cos(2 phi): positive beyond
 * u* = c / k, and nowhere at an azimuth where k <= 0. The pair is its
 * positive and negative parts azimuth by azimuth: phi uniform, then u with
 * radial density |u k - c| / ((1 + u)^3 M) on its side, M the side's mass
 *   M+ = k^2 / (2 (k + c)),  M- = c^2 / (2 (k + c)) (k > 0), (c - k) / 2 (k <= 0),
 * so that A / p is M times smooth factors, as for the isotropic pair (which
 * is this with cx = cy: u* = 1, M = c / 4). In w = 1 / (1 + u) the CDFs
 * invert in closed form, started at u* as the isotropic pair's (xi = u1
 * for p+, 1 - u1 for p-, whose caller passes 1 - u1):
 *   w+ = w* (1 - sqrt(xi)), w* = k / (k + c);
 *   w- = (k + c sqrt(xi)) / (k + c) (k > 0),
 *        (k + sqrt(k^2 + (c^2 - k^2) xi)) / (k + c) (k <= 0);
 * in h, p+-(h) = D cos(theta_h) |u k - c| / ((1 + u) M). */
struct rough_split { double c, k; };

static inline struct rough_split rough_split(const struct dr_bsdf *b, double a, double ax, double cos2phi)
{
    const double s = b->anisotropy, cx = (1.0 - s * s) / ax, cy = 1.0 / a;
    return (struct rough_split){cx + cy, cx + cy + 2.0 * (cx - cy) * cos2phi};
}

static inline double rough_split_mass(struct rough_split sp, bool positive)
{
    return positive ? sp.k * sp.k / (2.0 * (sp.k + sp.c))
                    : sp.k > 0.0 ? sp.c * sp.c / (2.0 * (sp.k + sp.c)) : 0.5 * (sp.c - sp.k);
}

double dr_bsdf_deriv_lobe_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, enum dr_bsdf_dlobe lobe)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return 0.0;
    if (lobe == DR_BSDF_DLOBE_COAT_POS || lobe == DR_BSDF_DLOBE_COAT_NEG) {
        if (!b->coated)
            return 0.0;
        const struct dr_bsdf l = dr_coat_lobe(b);
        return dr_bsdf_deriv_lobe_pdf(&l, wo, wi, coat_as_rough(lobe));
    }
    if (lobe == DR_BSDF_DLOBE_COSINE)
        return wi.z * DR_INV_PI;
    double a = bsdf_alpha(b), a2 = a * a;
    if (lobe == DR_BSDF_DLOBE_VNDF && b->anisotropy != 0.0) {   /* the stretched lobe's map (sample_vndf) */
        const double ax = alpha_x_of(b, a);
        const struct ggx_aniso g = ggx_aniso(ax, a, wo, wi);
        return g.D / (4.0 * wo.z) / (1.0 + smith_lambda_aniso(ax, a, wo, NULL, NULL));
    }
    if (b->anisotropy != 0.0) {   /* the stretched lobe's pair (sample_rough_h_aniso) */
        const double ax = alpha_x_of(b, a);
        const struct ggx_aniso g = ggx_aniso(ax, a, wo, wi);
        /* the stretched slopes' squares over Hz^2 (t = H.xy / (Hz alpha)) */
        const double tx2 = g.hx2 / (ax * ax), ty2 = g.hy2 / (a * a), u = (tx2 + ty2) / g.hz2;
        const struct rough_split sp = rough_split(b, a, ax, u > 0.0 ? (tx2 - ty2) / (tx2 + ty2) : 1.0);
        const bool positive = u * sp.k > sp.c;
        if (positive != (lobe == DR_BSDF_DLOBE_ROUGH_POS))
            return 0.0;
        /* p(h) / (4 wo.h), p(h) = D cos(theta_h) |u k - c| / ((1 + u) M), wo.h = |H| / 2 */
        return 0.5 * fabs(u * sp.k - sp.c) / ((1.0 + u) * rough_split_mass(sp, positive)) * g.D * g.H.z / g.H2;
    }
    const struct ggx_half g_h = ggx_half(a2, wo, wi);
    if (lobe == DR_BSDF_DLOBE_VNDF)
        return g_h.D / (4.0 * wo.z) / (1.0 + smith_lambda(a2, wo));   /* as eval_pdf_above's pdf_spec */
    /* u - 1 = (hxy2 - a2 hz2) / (a2 hz2), u + 1 = q / (a2 hz2): their ratio
     * without forming u (which overflows for tiny alpha). */
    double num = g_h.hxy2 - a2 * g_h.hz2;
    if (lobe == DR_BSDF_DLOBE_ROUGH_POS ? !(num > 0.0) : !(num < 0.0))
        return 0.0;
    /* p(h) / (4 wo.h), with p(h) = 4 |u-1|/(u+1) D cos(theta_h), cos(theta_h) = Hz/|H|, wo.h = |H|/2 */
    return 2.0 * (fabs(num) / g_h.q) * g_h.D * g_h.H.z / g_h.H2;
}

double dr_bsdf_deriv_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, unsigned params)
{
    double w[DR_BSDF_DLOBE_COUNT], pdf = 0.0;
    dr_bsdf_deriv_weights(b, params, w);
    for (int l = 0; l < DR_BSDF_DLOBE_COUNT; l++)
        if (w[l] > 0.0)
            pdf += w[l] * dr_bsdf_deriv_lobe_pdf(b, wo, wi, (enum dr_bsdf_dlobe)l);
    return pdf;
}

/* The half vector of a roughness lobe for (u1, u2): tan(theta_h) = alpha sqrt(u),
 * written as h ~ (alpha sqrt(1 +- s) (cos phi, sin phi), sqrt(1 -+ s)) so
 * that u = (1 +- s) / (1 -+ s) is never formed (it is infinite at xi = 1). */
static dr_vec3 sample_rough_h(double a, bool positive, double u1, double u2)
{
    double s = positive ? sqrt(u1) : sqrt(dr_max(0.0, 1.0 - u1));
    double xy = positive ? a * sqrt(1.0 + s) : a * sqrt(dr_max(0.0, 1.0 - s));
    double z = positive ? sqrt(dr_max(0.0, 1.0 - s)) : sqrt(1.0 + s);
    double phi = 2.0 * M_PI * u2;
    return dr_normalize(dr_v3(xy * cos(phi), xy * sin(phi), z));
}

/* A half vector of the pair's lobe (rough_split); (0, 0, -1), rejected,
 * where the lobe has no support. */
static dr_vec3 sample_rough_h_aniso(const struct dr_bsdf *b, double a, bool positive, double u1, double u2)
{
    const double ax = alpha_x_of(b, a), phi = 2.0 * M_PI * u2, cp = cos(phi), sn = sin(phi);
    const struct rough_split sp = rough_split(b, a, ax, cp * cp - sn * sn);
    /* (the pair's caller hands the negative lobe 1 - u1, path_deriv.c: it
     * inverts with 1 - u1 too, so that both start at u* from the same u1,
     * as sample_rough_h's pair does) */
    const double xi = positive ? u1 : 1.0 - u1;
    double w;
    if (positive)
        w = sp.k > 0.0 ? sp.k / (sp.k + sp.c) * (1.0 - sqrt(xi)) : 0.0;
    else if (sp.k > 0.0)
        w = (sp.k + sp.c * sqrt(xi)) / (sp.k + sp.c);
    else
        w = (sp.k + sqrt(sp.k * sp.k + (sp.c * sp.c - sp.k * sp.k) * xi)) / (sp.k + sp.c);
    if (!(w > 0.0))
        return dr_v3(0.0, 0.0, -1.0);
    const double r = sqrt(dr_max(0.0, 1.0 / w - 1.0));
    return dr_normalize(dr_v3(ax * r * cp, a * r * sn, 1.0));
}

dr_vec3 dr_bsdf_deriv_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_dlobe lobe, double u1, double u2)
{
    switch (lobe) {
    case DR_BSDF_DLOBE_COSINE:
        return sample_cosine(u1, u2);
    case DR_BSDF_DLOBE_VNDF:
        return dr_bsdf_sample_dir(b, wo, DR_BSDF_LOBE_SPECULAR, u1, u2);
    case DR_BSDF_DLOBE_COAT_POS:
    case DR_BSDF_DLOBE_COAT_NEG: {
        if (!b->coated)
            return dr_v3(0.0, 0.0, -1.0);   /* (no coat: density 0, rejected) */
        const struct dr_bsdf l = dr_coat_lobe(b);
        return dr_bsdf_deriv_sample_dir(&l, wo, coat_as_rough(lobe), u1, u2);
    }
    default: {
        const double a = bsdf_alpha(b);
        const bool positive = lobe == DR_BSDF_DLOBE_ROUGH_POS;
        dr_vec3 h = b->anisotropy != 0.0 ? sample_rough_h_aniso(b, a, positive, u1, u2)
                                         : sample_rough_h(a, positive, u1, u2);
        double oh = dr_dot(wo, h);
        if (!(oh > 0.0))
            return dr_v3(0.0, 0.0, -1.0);   /* the back of the microfacet: rejected */
        return dr_sub(dr_scale(h, 2.0 * oh), wo);
    }
    }
}

bool dr_bsdf_deriv_sample(const struct dr_bsdf *b, dr_vec3 wo, unsigned params, double u_lobe, double u1, double u2,
                          dr_vec3 *wi, double *pdf)
{
    double w[DR_BSDF_DLOBE_COUNT], acc = 0.0;
    *pdf = 0.0;
    *wi = dr_v3(0.0, 0.0, 1.0);
    dr_bsdf_deriv_weights(b, params, w);
    if (!(wo.z > COS_EPS))
        return false;
    int lobe = -1;
    for (int l = 0; l < DR_BSDF_DLOBE_COUNT; l++) {
        if (!(w[l] > 0.0))
            continue;
        acc += w[l];
        lobe = l;   /* the last lobe with weight also catches rounding (acc may end below 1) */
        if (u_lobe < acc)
            break;
    }
    if (lobe < 0)
        return false;
    *wi = dr_bsdf_deriv_sample_dir(b, wo, (enum dr_bsdf_dlobe)lobe, u1, u2);
    if (!(wi->z > COS_EPS))
        return false;
    *pdf = dr_bsdf_deriv_pdf(b, wo, *wi, params);
    return *pdf > 0.0 && isfinite(*pdf);
}

/* The stretched lobe's NDF part: spec (d lnD/d ax (1 - s^2) + d lnD/d ay)
 * 2 rough, the roughness's share of d_eval_params_aniso's D terms (the
 * anisotropy's strength moves alpha_x too: its share is B's, as G's is). */
static void d_eval_rough_ndf_aniso(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out,
                                   struct dr_d_bsdf *d)
{
    const double ay = bsdf_alpha(b), ax = alpha_x_of(b, ay), s = b->anisotropy, m = b->metallic;
    const struct ggx_aniso g_h = ggx_aniso(ax, ay, wo, wi);
    const double spec = g_h.D / (4.0 * wo.z * (1.0 + smith_lambda_aniso(ax, ay, wo, NULL, NULL) +
                                               smith_lambda_aniso(ax, ay, wi, NULL, NULL)) * wi.z);
    const double s5 = pow5(1.0 - dr_clamp(0.5 * sqrt(g_h.H2), 0.0, 1.0));
    dr_vec3 fd, fm;
    fresnel_lobes(b, s5, &fd, &fm);
    const double d_spec = (1.0 - m) * dr_dot(d_out, fd) + m * dr_dot(d_out, fm);
    double dlnD_x, dlnD_y;
    ggx_aniso_dlnD(ax, ay, &g_h, &dlnD_x, &dlnD_y);
    d->roughness += d_spec * spec * (dlnD_x * (1.0 - s * s) + dlnD_y) * (2.0 * b->roughness);
}

/* The NDF part of the roughness derivative (see bsdf.h; for a stretched
 * base lobe d_eval_rough_ndf_aniso): with
 * f_spec,c = [(1-m) F_d,c + m F_m,c] D G2 / (4 wo.z wi.z) = K_c spec,
 *   d f_c / d rough |_D = K_c spec d lnD/d alpha * 2 rough,
 *   d lnD / d alpha = (2/alpha) (Hxy^2 - alpha^2 Hz^2) / q   (as d_eval_params).
 * Zero for a Lambertian (no specular lobe) and below the alpha floor, as
 * d_eval_params' roughness adjoint. */
void d_bsdf_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                           struct dr_d_bsdf *d)
{
    if (b->coated) {
        d_coat_eval_rough_ndf(b, wo, wi, d_out, parts, d);
        return;
    }
    if (b->sheened) {
        d_sheen_eval_rough_ndf(b, wo, wi, d_out, parts, d);
        return;
    }
    const double rough = b->roughness, m = b->metallic;
    if (!(parts & DR_BSDF_D_ROUGHNESS) || !(wo.z > COS_EPS) || !(wi.z > COS_EPS) || no_specular_lobe(b) ||
        !(rough * rough > DR_BSDF_MIN_ALPHA))
        return;
    if (b->anisotropy != 0.0) {
        d_eval_rough_ndf_aniso(b, wo, wi, d_out, d);
        return;
    }
    double a = bsdf_alpha(b), a2 = a * a;
    const struct ggx_half g_h = ggx_half(a2, wo, wi);
    double spec = g_h.D / (4.0 * wo.z * (1.0 + smith_lambda(a2, wo) + smith_lambda(a2, wi)) * wi.z);
    double s5 = pow5(1.0 - dr_clamp(0.5 * sqrt(g_h.H2), 0.0, 1.0));
    dr_vec3 fd, fm;
    fresnel_lobes(b, s5, &fd, &fm);
    double d_spec = (1.0 - m) * dr_dot(d_out, fd) + m * dr_dot(d_out, fm);
    double dlnD = ggx_dlnD_dalpha(a, a2, &g_h);
    d->roughness += d_spec * spec * dlnD * (2.0 * rough);
}
