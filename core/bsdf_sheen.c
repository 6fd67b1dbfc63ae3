/* KHR_materials_sheen: a layer of fibres of colour C = sheen_color and
 * roughness r = max(sheen_roughness, DR_SHEEN_MIN_ROUGHNESS) over the base
 * BSDF (bsdf.h; under a clear coat, which hands its base here):
 *
 *   f = T(wo) T(wi) f_base + f_sheen,   T(w) = max(0, 1 - m E(w.z, r)),
 *   m = max(C.r, C.g, C.b),
 *   f_sheen = C D(h) G / (4 wo.z wi.z),  h = normalize(wo + wi), alpha = r^2,
 *
 * the "Charlie" lobe of Estevez & Kulla 2017 ("Production Friendly
 * Microfacet Sheen BRDF") as the glTF spec and the Khronos sample viewer use
 * it:
 *   D(h) = (2 + 1/alpha) (sin theta_h)^(1/alpha) / (2 pi),
 *          sin^2 theta_h = Hxy^2 / |H|^2 for H = wo + wi (no 1 - cos^2
 *          cancellation; >= 0 by construction),
 *   G = 1 / (1 + Lambda(wo.z) + Lambda(wi.z)),
 *   Lambda(x) = exp(L(x)) for x < 0.5, exp(2 L(0.5) - L(1 - x)) otherwise,
 *   L(x) = a / (1 + b x^c) + d x + e, (a..e) = (1 - t) p(r=1) + t p(r=0),
 *   t = (1 - alpha)^2   (the paper's fit; its G is not clamped to [0, 1]:
 *   the fit keeps it there on its own, Lambda > 0).
 * E(mu, r) is that lobe's directional albedo with C = 1, tabulated
 * (sheen_albedo.h). The fit's G lets E exceed 1 near grazing at small
 * roughness (table max 2.93 at mu = 0.0023, r = 0.07; on the table's grid
 * E <= 1 for mu > 0.05 at every r, and at every mu >= 1e-4 for r >= 0.26;
 * below mu ~ 1e-6 the fit's E grows without bound, sheen_albedo.h): there
 * a bright sheen has m E >= 1 and T clamps at 0 (zero derivative), the base
 * is hidden, and the layer's albedo is the lobe's, above 1 for a bright
 * sheen at grazing angles (the model's, not the layering's).
 * Weighing the base by T both ways, as the coat does, keeps f reciprocal.
 *
 * Sampling: the sheen lobe with probability P = clamp(m E(wo.z, r), 0, 1)
 * (its albedo: P = 1 - T(wo) where T > 0, so P = 1 exactly where the base
 * is hidden), by the cosine map (the diffuse lobe's), else the base's lobes
 * with u_lobe rescaled; pdf = P wi.z / pi + (1 - P) p_base. The base is
 * evaluated, sampled and differentiated by bsdf.c's own functions on a copy
 * without the sheen (under); nothing here repeats GGX. */
#include "bsdf_sheen.h"

#include <stddef.h>

#include "sheen_albedo.h"

#define COS_EPS DR_BSDF_COS_EPS

/* ------------------------------------------------------------ the lobe */

static const double P_R0[5] = {25.3245, 3.32435, 0.16801, -1.27393, -4.85967};
static const double P_R1[5] = {21.5473, 3.82987, 0.19823, -1.97760, -4.32054};

/* The lobe's roughness-dependent constants. */
struct sheen_lobe {
    double r, alpha, k;   /* k = 1 / (2 alpha): D ~ (sin^2)^k */
    double p[5], dp[5];   /* L's coefficients and d p / d alpha */
    double half;          /* L(0.5) (Lambda's reflection point) */
    bool live;            /* r at or above the floor: roughness derivatives flow */
};

/* L(x) = a / (1 + b x^c) + d x + e alone (sheen_L's value, the same
 * operations: the primal needs no slopes, and they cost a pow and a log). */
static inline double sheen_L_value(const struct sheen_lobe *l, double x)
{
    const double xc = x > 0.0 ? pow(x, l->p[2]) : 0.0, den = 1.0 + l->p[1] * xc;
    return l->p[0] / den + l->p[3] * x + l->p[4];
}

static struct sheen_lobe make_sheen_lobe(double roughness)
{
    struct sheen_lobe l;
    l.live = roughness >= DR_SHEEN_MIN_ROUGHNESS;   /* (at the floor: the slope from above, as a fit clamped there needs) */
    l.r = l.live ? roughness : DR_SHEEN_MIN_ROUGHNESS;
    l.alpha = l.r * l.r;
    l.k = 0.5 / l.alpha;
    const double t = (1.0 - l.alpha) * (1.0 - l.alpha), dt = -2.0 * (1.0 - l.alpha);
    for (int i = 0; i < 5; i++) {
        l.p[i] = (1.0 - t) * P_R1[i] + t * P_R0[i];
        l.dp[i] = dt * (P_R0[i] - P_R1[i]);
    }
    l.half = sheen_L_value(&l, 0.5);
    return l;
}

/* ------------------------------------------------ the per-thread memo */

/* A sheened vertex asks for the same things again and again: next-event
 * estimation, the sky's share, the lobe pick and the sample's evaluation
 * each need the lobe's constants (a pow), E(wo.z) (a table lookup) and the
 * evaluations Lambda(wo.z) (a pow and an exp), for one roughness and one wo.
 * They are memoised per thread, keyed by the exact inputs, so a hit returns
 * the bits the computation would (the one-path walker's and the eight-lane
 * stages' images are unchanged). Eight wo entries: the stages run a
 * group's sheened lanes one after another within each stage. Four lobes:
 * a scene's few sheened roughnesses (textured ones vary: they just miss).
 * The wo entries hold values only: the derivatives take their slopes
 * (and the values with them) from the functions themselves. */
enum { MEMO_LOBES = 4, MEMO_WO = 8 };
struct wo_memo { double r, woz, E, lambda; };   /* r = the lobe's (clamped) r */
static _Thread_local struct {
    double key[MEMO_LOBES];            /* the roughness asked for */
    struct sheen_lobe lobe[MEMO_LOBES];
    struct wo_memo wo[MEMO_WO];
    unsigned lobes, next_lobe, wos, next_wo;   /* entries filled; the next to replace */
} memo;

static struct sheen_lobe sheen_lobe(double roughness)
{
    for (unsigned i = 0; i < memo.lobes; i++)
        if (memo.key[i] == roughness)
            return memo.lobe[i];
    const unsigned i = memo.next_lobe;
    memo.next_lobe = (i + 1) % MEMO_LOBES;
    memo.lobes += memo.lobes < MEMO_LOBES;
    memo.key[i] = roughness;
    memo.lobe[i] = make_sheen_lobe(roughness);
    return memo.lobe[i];
}

/* L(x) for x in [0, 1]; *dx = L'(x) and *da = d L / d alpha. The slope's
 * x^(c-1) is infinite at x = 0 (c < 1): it is taken at x >= 2^-52 (only
 * 1 - x reaches 0, at normal incidence, where Lambda ~ 1e-8 scales it). */
static double sheen_L(const struct sheen_lobe *l, double x, double *dx, double *da)
{
    const double a = l->p[0], b = l->p[1], c = l->p[2];
    const double xc = x > 0.0 ? pow(x, c) : 0.0, den = 1.0 + b * xc, q = a / (den * den);
    const double xs = x > 0x1p-52 ? x : 0x1p-52, xcs = x > 0x1p-52 ? xc : pow(xs, c);
    *dx = -q * b * c * xcs / xs + l->p[3];
    const double lnx_xc = x > 0.0 ? xc * log(x) : 0.0;   /* x^c ln x -> 0 */
    *da = l->dp[0] / den - q * xc * l->dp[1] - q * b * lnx_xc * l->dp[2] + x * l->dp[3] + l->dp[4];
    return a / den + l->p[3] * x + l->p[4];
}

/* ln Lambda(x) with its slope in x and in alpha; x is clamped to [0, 1]
 * (flat outside: only unnormalised directions leave it). At x = 1 (normal
 * incidence) the fit's slope L'(1 - x) ~ (1 - x)^(c-1) is infinite: there
 * the slope is the clamp's, 0 (and E's mu slope too: sheen_albedo.h). */
static double sheen_ln_lambda(const struct sheen_lobe *l, double x, double *dx, double *da)
{
    const bool inside = x < 1.0;
    x = inside ? (x > 0.0 ? x : 0.0) : 1.0;
    double v, ddx, dda;
    if (x < 0.5) {
        v = sheen_L(l, x, &ddx, &dda);
    } else {
        double hx, ha;
        const double half = sheen_L(l, 0.5, &hx, &ha);
        v = 2.0 * half - sheen_L(l, 1.0 - x, &ddx, &dda);
        dda = 2.0 * ha - dda;   /* (d/dx of -L(1 - x) is +L'(1 - x): ddx as is) */
    }
    *dx = inside ? ddx : 0.0;
    *da = dda;
    return v;
}

/* ln Lambda(x) alone (sheen_ln_lambda's value, the same operations). */
static inline double sheen_ln_lambda_value(const struct sheen_lobe *l, double x)
{
    x = x < 1.0 ? (x > 0.0 ? x : 0.0) : 1.0;
    return x < 0.5 ? sheen_L_value(l, x) : 2.0 * l->half - sheen_L_value(l, 1.0 - x);
}

/* E(woz, l->r) and Lambda(woz), values, through the memo. */
static struct wo_memo wo_terms(const struct sheen_lobe *l, double woz)
{
    for (unsigned i = 0; i < memo.wos; i++)
        if (memo.wo[i].woz == woz && memo.wo[i].r == l->r)
            return memo.wo[i];
    const unsigned i = memo.next_wo;
    memo.next_wo = (i + 1) % MEMO_WO;
    memo.wos += memo.wos < MEMO_WO;
    memo.wo[i] = (struct wo_memo){l->r, woz, dr_sheen_albedo(woz, l->r, NULL, NULL),
                                  exp(sheen_ln_lambda_value(l, woz))};
    return memo.wo[i];
}

/* The lobe's value s = D G / (4 wo.z wi.z) (f_sheen = C s) and, with
 * slopes, what its adjoint needs (the d*_x, d*_a fields; else unset). */
struct sheen_eval {
    double s, G, lo, li;          /* G; Lambda(wo.z), Lambda(wi.z) */
    double dlo_x, dlo_a, dli_x, dli_a;   /* d ln Lambda / d x, d alpha */
    dr_vec3 H;
    double hxy2, H2, s2;          /* s2 = sin^2 theta_h */
};

static struct sheen_eval sheen_eval(const struct sheen_lobe *l, dr_vec3 wo, dr_vec3 wi, bool slopes)
{
    struct sheen_eval e;
    e.H = dr_add(wo, wi);
    e.hxy2 = e.H.x * e.H.x + e.H.y * e.H.y;
    e.H2 = e.hxy2 + e.H.z * e.H.z;
    e.s2 = e.hxy2 / e.H2;
    const double D = (2.0 + 2.0 * l->k) * pow(e.s2, l->k) * (0.5 * DR_INV_PI);
    if (slopes) {
        e.lo = exp(sheen_ln_lambda(l, wo.z, &e.dlo_x, &e.dlo_a));
        e.li = exp(sheen_ln_lambda(l, wi.z, &e.dli_x, &e.dli_a));
    } else {
        e.lo = wo_terms(l, wo.z).lambda;
        e.li = exp(sheen_ln_lambda_value(l, wi.z));
    }
    e.G = 1.0 / (1.0 + e.lo + e.li);
    e.s = D * e.G / (4.0 * wo.z * wi.z);
    return e;
}

/* Adjoint of s for gs = d loss / d s: d loss / d alpha returned, the
 * directions' added to *d_wo, *d_wi (if not NULL). Log form:
 *   d ln s = d ln D + d ln G - d wo.z / wo.z - d wi.z / wi.z,
 *   d ln D / d alpha = -(1/alpha^2) / (2 + 1/alpha) - ln(s2) / (2 alpha^2),
 *   d ln D / d H = (2k / H^2) (Hx Hz^2 / Hxy^2, Hy Hz^2 / Hxy^2, -Hz),
 *   d ln G = -G (Lambda_o d ln Lambda_o + Lambda_i d ln Lambda_i)
 * (G Lambda <= 1 keeps the products finite where Lambda is huge). Where
 * s = 0 (h along the normal, or D underflows) everything is 0: D's
 * derivatives vanish with it (k >= 1/2). */
static double d_sheen_lobe(const struct sheen_lobe *l, const struct sheen_eval *e, dr_vec3 wo, dr_vec3 wi, double gs,
                           dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (!(e->s > 0.0) || !(e->hxy2 > 0.0) || gs == 0.0)
        return 0.0;
    const double g = gs * e->s, a = l->alpha;
    const double go = e->G * e->lo, gi = e->G * e->li;
    const double d_alpha = g * (-(1.0 / (a * a)) / (2.0 + 1.0 / a) - log(e->s2) * l->k / a -
                                (go * e->dlo_a + gi * e->dli_a));
    if (d_wo || d_wi) {
        const double c = g * 2.0 * l->k / e->H2, z2 = e->H.z * e->H.z / e->hxy2;
        const dr_vec3 dH = dr_v3(c * e->H.x * z2, c * e->H.y * z2, -c * e->H.z);
        if (d_wo)
            *d_wo = dr_add(*d_wo, dr_v3(dH.x, dH.y, dH.z - g * (go * e->dlo_x + 1.0 / wo.z)));
        if (d_wi)
            *d_wi = dr_add(*d_wi, dr_v3(dH.x, dH.y, dH.z - g * (gi * e->dli_x + 1.0 / wi.z)));
    }
    return d_alpha;
}

/* ------------------------------------------------------- the layering */

static inline struct dr_bsdf under(const struct dr_bsdf *b)
{
    struct dr_bsdf u = *b;
    u.sheened = false;
    return u;
}

/* m = max over channels of the colour, and the channel (ties: the first). */
static inline double colour_max(dr_vec3 c, int *arg)
{
    int i = 0;
    double m = c.x;
    if (c.y > m)
        i = 1, m = c.y;
    if (c.z > m)
        i = 2, m = c.z;
    if (arg)
        *arg = i;
    return m;
}

static inline void add_channel(dr_vec3 *v, int i, double x)
{
    if (i == 0)
        v->x += x;
    else if (i == 1)
        v->y += x;
    else
        v->z += x;
}

/* m E(cos, r) with its partial derivatives (E's are the table
 * interpolant's; d/d rough 0 at the floor). */
struct sheen_albedo {
    double m, E, dE_mu, dE_r;
    int arg;
};

static struct sheen_albedo albedo_at(const struct dr_bsdf *b, const struct sheen_lobe *l, double cos)
{
    struct sheen_albedo s;
    s.m = colour_max(b->sheen_color, &s.arg);
    s.E = dr_sheen_albedo(cos, l->r, &s.dE_mu, &s.dE_r);
    if (!l->live)
        s.dE_r = 0.0;
    return s;
}

/* m E alone, for the primal (the same E: the lookup's value does not depend
 * on whether slopes are asked for); a wo's through the memo. */
static struct sheen_albedo albedo_value(const struct dr_bsdf *b, const struct sheen_lobe *l, double cos, bool is_wo)
{
    struct sheen_albedo s = {.dE_mu = 0.0, .dE_r = 0.0};
    s.m = colour_max(b->sheen_color, &s.arg);
    s.E = is_wo ? wo_terms(l, cos).E : dr_sheen_albedo(cos, l->r, NULL, NULL);
    return s;
}

/* T = max(0, 1 - m E) (clamped: see the top). */
static inline double transmit(const struct sheen_albedo *s)
{
    const double t = 1.0 - s->m * s->E;
    return t > 0.0 ? t : 0.0;
}

/* P = clamp(m E, 0, 1). */
static inline double sheen_prob(const struct sheen_albedo *s)
{
    const double p = s->m * s->E;
    return p > 0.0 ? (p < 1.0 ? p : 1.0) : 0.0;
}

/* Adds g d(m E) into d (colour, roughness) and the cosine's part to *d_cos,
 * where inside (the clamp of T or P not holding). */
static void d_albedo(const struct sheen_albedo *s, double g, struct dr_d_bsdf *d, double *d_cos)
{
    if (d) {
        add_channel(&d->sheen_color, s->arg, g * s->E);
        d->sheen_roughness += g * s->m * s->dE_r;
    }
    if (d_cos)
        *d_cos += g * s->m * s->dE_mu;
}

struct dr_sheen_layer dr_sheen_layer_at(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi)
{
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_value(b, &l, wo.z, true), ai = albedo_value(b, &l, wi.z, false);
    const struct sheen_eval e = sheen_eval(&l, wo, wi, false);
    return (struct dr_sheen_layer){.t = transmit(&ao) * transmit(&ai), .p = sheen_prob(&ao),
                                   .s = dr_scale(b->sheen_color, e.s)};
}

double dr_sheen_lobe_prob(const struct dr_bsdf *b, dr_vec3 wo)
{
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_value(b, &l, wo.z, true);
    return sheen_prob(&ao);
}

dr_vec3 dr_sheen_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf)
{
    const struct dr_bsdf base = under(b);
    double pb = 0.0;
    const dr_vec3 fb = pdf ? dr_bsdf_eval_pdf(&base, wo, wi, &pb) : dr_bsdf_eval(&base, wo, wi);
    const struct dr_sheen_layer layer = dr_sheen_layer_at(b, wo, wi);
    if (pdf)
        *pdf = dr_sheen_layer_pdf(&layer, wi, pb);
    return dr_sheen_layer_f(&layer, fb);
}

enum dr_bsdf_lobe dr_sheen_pick_lobe(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe)
{
    const double p = dr_sheen_lobe_prob(b, wo);
    if (u_lobe < p)
        return DR_BSDF_LOBE_SHEEN;
    const struct dr_bsdf base = under(b);   /* (p <= u_lobe < 1: 1 - p > 0) */
    const double u = (u_lobe - p) / (1.0 - p);
    return u < dr_bsdf_specular_prob(&base, wo) ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
}

dr_vec3 dr_sheen_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2)
{
    if (lobe == DR_BSDF_LOBE_SHEEN)
        return dr_bsdf_cosine_dir(u1, u2);
    const struct dr_bsdf base = under(b);
    return dr_bsdf_sample_dir(&base, wo, lobe, u1, u2);
}

bool dr_sheen_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                     struct dr_bsdf_sample *out)
{
    out->wi = dr_v3(0.0, 0.0, 1.0);
    out->f = dr_v3s(0.0);
    out->pdf = 0.0;
    out->lobe = DR_BSDF_LOBE_DIFFUSE;
    if (!(wo.z > COS_EPS))
        return false;
    out->lobe = dr_sheen_pick_lobe(b, wo, u_lobe);
    const dr_vec3 wi = dr_sheen_sample_dir(b, wo, out->lobe, u1, u2);
    out->wi = wi;
    if (!(wi.z > COS_EPS))
        return false;
    double pdf;
    const dr_vec3 f = dr_sheen_eval_pdf(b, wo, wi, &pdf);
    if (!(pdf > 0.0) || !isfinite(pdf))
        return false;
    out->f = f;
    out->pdf = pdf;
    return true;
}

/* The cosine samples of the sheen are the sky's other half: only the base's
 * share of (1 - P) counts. */
double dr_sheen_sky_share(const struct dr_bsdf *b, dr_vec3 wo)
{
    if (!(wo.z > COS_EPS))
        return 0.0;
    const struct dr_bsdf base = under(b);
    return (1.0 - dr_sheen_lobe_prob(b, wo)) * dr_bsdf_sky_share(&base, wo);
}

/* The probability of a microfacet (GGX) map: the base's, (1 - P) p_base; the
 * sheen's map is the cosine one. (Below the surface, as the base: at cos 0.) */
double dr_sheen_specular_prob(const struct dr_bsdf *b, dr_vec3 wo)
{
    const struct dr_bsdf base = under(b);
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_value(b, &l, wo.z > COS_EPS ? wo.z : 0.0, true);
    return (1.0 - sheen_prob(&ao)) * dr_bsdf_specular_prob(&base, wo);
}

/* ------------------------------------------------------------ derivatives */

/* f = To Ti f_base + C s, To = 1 - m E(wo.z, r) (where positive):
 *   d f / d C = s (per channel) - (Eo Ti + To Ei) f_base (argmax channel),
 *   d f / d wo.z = -Ti m E_mu(wo.z) f_base + C d s / d wo.z (and alike for wi),
 *   d f / d r = -(Ti m E_r(wo.z) + To m E_r(wi.z)) f_base + C ds/d alpha 2r,
 * plus the base's adjoints at d_out To Ti. */
void d_sheen_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                  dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    const struct dr_bsdf base = under(b);
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_at(b, &l, wo.z), ai = albedo_at(b, &l, wi.z);
    const double to = transmit(&ao), ti = transmit(&ai);
    d_bsdf_eval(&base, wo, wi, dr_scale(d_out, to * ti), d, d_wo, d_wi);
    const double gt = dr_dot(d_out, dr_bsdf_eval(&base, wo, wi));   /* d loss / d (To Ti) */
    double d_co = 0.0, d_ci = 0.0;
    if (to > 0.0)
        d_albedo(&ao, -gt * ti, d, &d_co);
    if (ti > 0.0)
        d_albedo(&ai, -gt * to, d, &d_ci);
    const struct sheen_eval e = sheen_eval(&l, wo, wi, true);
    const double d_alpha = d_sheen_lobe(&l, &e, wo, wi, dr_dot(d_out, b->sheen_color), d_wo, d_wi);
    if (d) {
        d->sheen_color = dr_add(d->sheen_color, dr_scale(d_out, e.s));
        if (l.live)
            d->sheen_roughness += d_alpha * 2.0 * l.r;
    }
    if (d_wo)
        d_wo->z += d_co;
    if (d_wi)
        d_wi->z += d_ci;
}

/* pdf = P wi.z / pi + (1 - P) p_base, P = clamp(m E(wo.z, r), 0, 1):
 * d pdf / d P = wi.z / pi - p_base where P moves (prob_moves, and inside
 * the clamp), plus the base's density's adjoints at d_pdf (1 - P). */
void d_sheen_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, bool prob_moves, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const struct dr_bsdf base = under(b);
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_at(b, &l, wo.z);
    const double p = sheen_prob(&ao), pm = ao.m * ao.E;
    if (prob_moves)
        d_bsdf_pdf(&base, wo, wi, d_pdf * (1.0 - p), d, d_wo, d_wi);
    else
        d_bsdf_pdf_fixed_prob(&base, wo, wi, d_pdf * (1.0 - p), d, d_wo, d_wi);
    if (d_wi)
        d_wi->z += d_pdf * p * DR_INV_PI;
    if (!prob_moves || !(pm < 1.0))   /* (m E >= 0 always: P clamps only at 1) */
        return;
    double d_co = 0.0;
    d_albedo(&ao, d_pdf * (wi.z * DR_INV_PI - dr_bsdf_pdf(&base, wo, wi)), d, &d_co);
    if (d_wo)
        d_wo->z += d_co;
}

/* p = (1 - P) p_base: dp/dP = -p_base, dp/dp_base = 1 - P. */
void d_sheen_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    const bool above = wo.z > COS_EPS;
    const struct dr_bsdf base = under(b);
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_at(b, &l, above ? wo.z : 0.0);
    const double p = sheen_prob(&ao), pm = ao.m * ao.E;
    d_bsdf_specular_prob(&base, wo, d_p * (1.0 - p), d, d_wo);
    if (!(pm < 1.0))
        return;
    double d_co = 0.0;
    d_albedo(&ao, -d_p * dr_bsdf_specular_prob(&base, wo), d, &d_co);
    if (above && d_wo)
        d_wo->z += d_co;
}

/* The sheen's cosine map depends on nothing differentiable; the base's maps
 * are the base's. */
void d_sheen_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                        dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    if (lobe == DR_BSDF_LOBE_SHEEN)
        return;
    const struct dr_bsdf base = under(b);
    d_bsdf_sample_dir(&base, wo, lobe, u1, u2, d_wi, d, d_wo);
}

/* The base's NDF part times To Ti, smooth factors the roughness lobes need
 * not know (the sheen's own parameters are left to the forward sampler). */
void d_sheen_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                            struct dr_d_bsdf *d)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const struct dr_bsdf base = under(b);
    const struct sheen_lobe l = sheen_lobe(b->sheen_roughness);
    const struct sheen_albedo ao = albedo_value(b, &l, wo.z, true), ai = albedo_value(b, &l, wi.z, false);
    d_bsdf_eval_rough_ndf(&base, wo, wi, dr_scale(d_out, transmit(&ao) * transmit(&ai)), parts, d);
}
