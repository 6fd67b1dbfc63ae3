/* Tests of the derivative-sampling densities (core/bsdf.c, --sampling
 * derivative): each lobe and each parameter mixture's samples against its
 * pdf (chi-square over half-vector cells whose expected counts integrate the
 * pdf), the pdf's normalisation, and the roughness lobes against a central
 * difference of GGX D in alpha (p+-(h) = 2 alpha |dD/dalpha| cos(theta_h)).
 * Deterministic: every random number comes from fixed seeds. */
#include <stdint.h>
#include <stdlib.h>

#include "bsdf.h"
#include "sampler.h"
#include "sheen_albedo.h"
#include "test.h"

struct rng { uint64_t s; };
static double rng_next(struct rng *r)
{
    r->s += 0x9e3779b97f4a7c15ULL;
    return (double)(dr_hash64(r->s) >> 11) * (1.0 / 9007199254740992.0);
}

static struct dr_bsdf make_bsdf(double rough, double metal, dr_vec3 base)
{
    struct dr_bsdf b = {.base_color = base, .metallic = metal, .roughness = rough, .specular = 1.0,
                        .specular_color = dr_v3s(1.0)};
    return b;
}

/* Chi-square p-value by the Wilson-Hilferty approximation (dof >= 10 here). */
static double chi2_pvalue(double chi2, int dof)
{
    double k = dof, z = (cbrt(chi2 / k) - (1.0 - 2.0 / (9.0 * k))) / sqrt(2.0 / (9.0 * k));
    return 0.5 * erfc(z / sqrt(2.0));
}

/* Half-vector cells: v = (2/pi) atan(tan(theta_h) / alpha) in [0, 1) (so GGX's
 * bulk, tan(theta_h) ~ alpha, sits mid-range whatever alpha) times phi_h. */
#define NV 32
#define NP 12
#define SUBV 96
#define SUBP 24

static dr_vec3 h_of(double a, double v, double phi, double *domega_dvdphi)
{
    double tv = tan(0.5 * M_PI * v);           /* tan(theta_h) / alpha = sqrt(u) */
    double t = a * tv, c = 1.0 / sqrt(1.0 + t * t);
    double du_dv = 2.0 * tv * (1.0 + tv * tv) * 0.5 * M_PI;
    *domega_dvdphi = a * a * c * c * c * 0.5 * du_dv;   /* dw_h = a^2 cos^3 / 2 du dphi */
    return dr_v3(t * c * cos(phi), t * c * sin(phi), c);
}

static int cell_of(double a, dr_vec3 h)
{
    double t = sqrt(h.x * h.x + h.y * h.y) / h.z;
    double v = atan(t / a) / (0.5 * M_PI);
    double phi = atan2(h.y, h.x);
    if (phi < 0.0)
        phi += 2.0 * M_PI;
    int iv = (int)(v * NV), ip = (int)(phi / (2.0 * M_PI) * NP);
    iv = iv < 0 ? 0 : (iv >= NV ? NV - 1 : iv);
    ip = ip < 0 ? 0 : (ip >= NP ? NP - 1 : ip);
    return iv * NP + ip;
}

/* Density of the mixture (params != 0) or of one lobe (params == 0) */
static double pdf_of(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, unsigned params, int lobe)
{
    return params ? dr_bsdf_deriv_pdf(b, wo, wi, params) : dr_bsdf_deriv_lobe_pdf(b, wo, wi, (enum dr_bsdf_dlobe)lobe);
}

/* Expected fraction of samples per cell: the wi density carried to h space
 * (times 4 wo.h), integrated by the midpoint rule on a fine sub-grid. */
static double expected_cells(const struct dr_bsdf *b, double a, dr_vec3 wo, unsigned params, int lobe, double *e)
{
    double total = 0.0;
    for (int iv = 0; iv < NV; iv++)
        for (int ip = 0; ip < NP; ip++) {
            double s = 0.0;
            for (int sv = 0; sv < SUBV; sv++)
                for (int sp = 0; sp < SUBP; sp++) {
                    double v = (iv + (sv + 0.5) / SUBV) / NV, phi = 2.0 * M_PI * (ip + (sp + 0.5) / SUBP) / NP, jac;
                    dr_vec3 h = h_of(a, v, phi, &jac);
                    double oh = dr_dot(wo, h);
                    if (!(oh > 0.0))
                        continue;
                    dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), wo);
                    s += pdf_of(b, wo, wi, params, lobe) * 4.0 * oh * jac;
                }
            e[iv * NP + ip] = s / (SUBV * SUBP) / NV * (2.0 * M_PI / NP);
            total += e[iv * NP + ip];
        }
    return total;
}

static double worst_p = 1.0;
static double cells_alpha;   /* > 0: the cells' alpha (a stretched lobe's), else the lobe's roughness^2 */

/* One direction of the mixture for params (dr_bsdf_deriv_sample) or, params
 * 0, of one lobe's map with its density; false: none (rejected). */
static bool draw(const struct dr_bsdf *b, dr_vec3 wo, unsigned params, int lobe, struct rng *r, dr_vec3 *wi,
                 double *pdf)
{
    double ul = rng_next(r), u1 = rng_next(r), u2 = rng_next(r);
    *pdf = 0.0;
    if (params)
        return dr_bsdf_deriv_sample(b, wo, params, ul, u1, u2, wi, pdf);
    *wi = dr_bsdf_deriv_sample_dir(b, wo, (enum dr_bsdf_dlobe)lobe, u1, u2);
    *pdf = dr_bsdf_deriv_lobe_pdf(b, wo, *wi, (enum dr_bsdf_dlobe)lobe);
    return wi->z > 1e-12 && *pdf > 0.0;
}

/* The verdict on ncells observed / expected (a fraction of n) counts: the
 * chi-square's p-value (cells expecting < 5 pooled), and the density's
 * integral total against the valid fraction of the n draws. */
static void chi2_verdict(const char *what, double cos_o, const double *obs, const double *expd, int ncells, long n,
                         long valid, double total)
{
    double chi2 = 0.0, po = 0.0, pe = 0.0;
    int cells = 0;
    for (int i = 0; i < ncells; i++) {
        double ei = expd[i] * n;
        if (ei < 5.0) {
            po += obs[i];
            pe += ei;
            continue;
        }
        chi2 += dr_sqr(obs[i] - ei) / ei;
        cells++;
    }
    if (pe > 0.0 || po > 0.0) {
        chi2 += pe > 1.0 ? dr_sqr(po - pe) / pe : dr_sqr(po - pe);
        cells++;
    }
    double p = chi2_pvalue(chi2, cells - 1);
    double frac = (double)valid / n, se = sqrt(frac * (1.0 - frac) / n) + 1e-4;
    printf("  %-34s wo.z=%.2f valid=%.4f integral=%.4f chi2=%7.1f dof=%3d p=%.4f\n", what, cos_o, frac, total, chi2,
           cells - 1, p);
    if (p < worst_p)
        worst_p = p;
    CHECK(p > 1e-4, "%s wo.z=%g: chi-square p-value %g", what, cos_o, p);
    CHECK(fabs(total - frac) < 4.0 * se + 2e-3, "%s wo.z=%g: pdf integrates to %g, valid fraction %g", what, cos_o,
          total, frac);
}

/* Samples n directions (mixture: dr_bsdf_deriv_sample; one lobe: its map)
 * and compares the cell counts with the integrated pdf; the pdf's total must
 * equal the fraction of valid samples (normalisation). */
static void chi2_case(const char *what, const struct dr_bsdf *b, double cos_o, unsigned params, int lobe, long n,
                      uint64_t seed)
{
    /* (cells at the lobe's alpha: a coat lobe's is the coat's) */
    const bool coat_lobe = !params && (lobe == DR_BSDF_DLOBE_COAT_POS || lobe == DR_BSDF_DLOBE_COAT_NEG);
    const double r_cells = coat_lobe ? b->coat_roughness : b->roughness;
    double a = cells_alpha > 0.0 ? cells_alpha : fmax(r_cells * r_cells, DR_BSDF_MIN_ALPHA);
    dr_vec3 wo = dr_v3(sqrt(1.0 - cos_o * cos_o), 0.0, cos_o);
    static double obs[NV * NP], expd[NV * NP];
    for (int i = 0; i < NV * NP; i++)
        obs[i] = 0.0;
    double total = expected_cells(b, a, wo, params, lobe, expd);
    struct rng r = {seed};
    long valid = 0;
    for (long k = 0; k < n; k++) {
        dr_vec3 wi;
        double pdf;
        if (!draw(b, wo, params, lobe, &r, &wi, &pdf))
            continue;
        CHECK(isfinite(pdf) && pdf > 0.0, "%s: sampled pdf %g", what, pdf);
        valid++;
        obs[cell_of(a, dr_normalize(dr_add(wo, wi)))] += 1.0;
    }
    chi2_verdict(what, cos_o, obs, expd, NV * NP, n, valid, total);
}

/* A BSDF under a clear coat of factor 0.7 and roughness coat_rough. */
static struct dr_bsdf make_coated(double rough, double coat_rough)
{
    struct dr_bsdf b = make_bsdf(rough, 0.3, dr_v3(0.8, 0.4, 0.2));
    b.coated = true, b.coat = 0.7, b.coat_roughness = coat_rough;
    return b;
}

static void test_lobes(void)
{
    static const char *names[DR_BSDF_DLOBE_COUNT] = {"cosine", "vndf", "rough+", "rough-", "coat+", "coat-"};
    const double roughs[] = {0.1, 0.5, 0.9}, coss[] = {0.95, 0.4};
    uint64_t seed = 1;
    printf("single lobes (map vs pdf):\n");
    for (int l = 0; l < DR_BSDF_DLOBE_COUNT; l++)
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 2; k++) {
                /* (the coat's lobes on a coated BSDF whose base is rougher or smoother than its coat) */
                const bool coat = l == DR_BSDF_DLOBE_COAT_POS || l == DR_BSDF_DLOBE_COAT_NEG;
                struct dr_bsdf b = coat ? make_coated(1.0 - 0.8 * roughs[i], roughs[i])
                                        : make_bsdf(roughs[i], 1.0, dr_v3(1.0, 0.8, 0.3));
                char what[64];
                snprintf(what, sizeof what, "%s rough=%.1f", names[l], roughs[i]);
                chi2_case(what, &b, coss[k], 0, l, 200000, seed++);
            }
    /* without a coat, the coat's lobes have no density and map below the surface */
    struct dr_bsdf b = make_bsdf(0.3, 0.0, dr_v3s(0.5));
    dr_vec3 wo = dr_normalize(dr_v3(0.3, 0.1, 1.0)), wi = dr_normalize(dr_v3(-0.2, 0.1, 1.0));
    CHECK(dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_COAT_POS) == 0.0 &&
              dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_COAT_NEG) == 0.0 &&
              !(dr_bsdf_deriv_sample_dir(&b, wo, DR_BSDF_DLOBE_COAT_POS, 0.3, 0.6).z > 0.0),
          "an uncoated BSDF's coat lobes: density 0, nothing sampled");
}

static void test_mixtures(void)
{
    static const struct { const char *name; unsigned params; } masks[] = {
        {"base", DR_BSDF_D_BASE}, {"metallic", DR_BSDF_D_METALLIC}, {"roughness", DR_BSDF_D_ROUGHNESS},
        {"all", DR_BSDF_D_BASE | DR_BSDF_D_METALLIC | DR_BSDF_D_ROUGHNESS},
        {"coat roughness", DR_BSDF_D_COAT_ROUGHNESS},
        {"all, coated", DR_BSDF_D_BASE | DR_BSDF_D_METALLIC | DR_BSDF_D_ROUGHNESS | DR_BSDF_D_COAT_ROUGHNESS}};
    const double metals[] = {0.0, 0.5, 1.0};
    uint64_t seed = 1000;
    printf("mixtures (dr_bsdf_deriv_sample vs dr_bsdf_deriv_pdf):\n");
    for (int m = 0; m < 6; m++)
        for (int i = 0; i < 3; i++) {
            struct dr_bsdf b = make_bsdf(i == 0 ? 0.1 : 0.5, metals[i], dr_v3(0.9, 0.1, 0.1));
            if (masks[m].params & DR_BSDF_D_COAT_ROUGHNESS)   /* under a coat smoother than the base */
                b.coated = true, b.coat = 0.6, b.coat_roughness = 0.2;
            char what[64];
            snprintf(what, sizeof what, "%s metallic=%.1f rough=%.1f", masks[m].name, metals[i], b.roughness);
            chi2_case(what, &b, 0.7, masks[m].params, 0, 200000, seed++);
        }
    /* weights sum to 1 for any request, and to 0 for none */
    struct dr_bsdf b = make_bsdf(0.3, 0.25, dr_v3s(0.5));
    for (unsigned mask = 0; mask < 16; mask++) {
        double w[DR_BSDF_DLOBE_COUNT], s = 0.0;
        dr_bsdf_deriv_weights(&b, mask, w);
        for (int l = 0; l < DR_BSDF_DLOBE_COUNT; l++) {
            CHECK(w[l] >= 0.0, "mask %u: weight %d is %g", mask, l, w[l]);
            s += w[l];
        }
        CHECK_NEAR(s, mask ? 1.0 : 0.0, 1e-15, "sum of the mixture weights");
    }
}

/* Test-side GGX D (textbook form). */
static double ref_D(double a, dr_vec3 h)
{
    double c2 = h.z * h.z, a2 = a * a;
    double d = c2 * (a2 - 1.0) + 1.0;
    return a2 / (M_PI * d * d);
}

/* The roughness lobes are |d D / d alpha| made a density: their h-space
 * density 4 wo.h p(wi), summed over both signs, must equal
 * 2 alpha |dD/dalpha| cos(theta_h), dD/dalpha by central differences; and
 * each sign's lobe lives on its own side of tan(theta_h) = alpha. */
static void test_rough_vs_fd(void)
{
    struct rng r = {77};
    double worst = 0.0;
    for (int k = 0; k < 2000; k++) {
        double rough = 0.05 + 0.9 * rng_next(&r), a = rough * rough;
        struct dr_bsdf b = make_bsdf(rough, 1.0, dr_v3s(1.0));
        double ct = 0.2 + 0.8 * rng_next(&r), po = 2.0 * M_PI * rng_next(&r);
        dr_vec3 wo = dr_v3(sqrt(1 - ct * ct) * cos(po), sqrt(1 - ct * ct) * sin(po), ct);
        double th = atan(a * tan(0.5 * M_PI * 0.98 * rng_next(&r))), ph = 2.0 * M_PI * rng_next(&r);
        dr_vec3 h = dr_v3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th));
        double oh = dr_dot(wo, h);
        dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), wo);
        if (!(oh > 0.0) || !(wi.z > 1e-3))
            continue;
        double eps = 1e-4 * a;
        double dD = (ref_D(a + eps, h) - ref_D(a - eps, h)) / (2.0 * eps);
        double want = 2.0 * a * fabs(dD) * h.z;
        double pp = dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_ROUGH_POS) * 4.0 * oh;
        double pn = dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_ROUGH_NEG) * 4.0 * oh;
        double rel = fabs(pp + pn - want) / fmax(want, 1e-300);
        if (want > 1e-3 * ref_D(a, dr_v3(0, 0, 1)) && rel > worst)
            worst = rel;
        bool wide = tan(th) > a;
        CHECK(wide ? pn == 0.0 : pp == 0.0, "roughness lobe on the wrong side: tan %g alpha %g (+ %g, - %g)",
              tan(th), a, pp, pn);
    }
    printf("roughness lobes vs 2 alpha |dD/dalpha| cos (central differences): worst relative error %.3g\n", worst);
    CHECK(worst < 1e-4, "roughness lobe density vs finite differences of D: relative error %g", worst);
}

/* Test-side Smith G2 (height-correlated) and the specular lobe with D
 * evaluated at its own alpha, so D alone can be varied. */
static double ref_lambda(double a, dr_vec3 w)
{
    double tan2 = (w.x * w.x + w.y * w.y) / (w.z * w.z);
    return (-1.0 + sqrt(1.0 + a * a * tan2)) / 2.0;
}

/* The NDF part of a GGX lobe's value at (wo, wi) by central differences
 * in roughness with only D moving (G2 at the fixed roughness), per unit
 * Fresnel: G2 dD/drough / (4 wo.z wi.z). */
static double ref_ndf_part(double rough, dr_vec3 wo, dr_vec3 wi)
{
    double a = rough * rough, h = 1e-5;
    dr_vec3 hv = dr_normalize(dr_add(wo, wi));
    double g2 = 1.0 / (1.0 + ref_lambda(a, wo) + ref_lambda(a, wi));
    double dD = (ref_D((rough + h) * (rough + h), hv) - ref_D((rough - h) * (rough - h), hv)) / (2.0 * h);
    return g2 * dD / (4.0 * wo.z * wi.z);
}

/* The clear coat's Fresnel (Schlick, f0 0.04) */
static double ref_coat_fresnel(double x) { return 0.04 + 0.96 * pow(1.0 - x, 5.0); }

/* d_bsdf_eval_rough_ndf against central differences in roughness of the
 * specular lobe with only D moving (G2 and Fresnel at the fixed roughness),
 * channel by channel: the part of d f / d rough that the antithetic pair
 * estimates. Every other BSDF under a clear coat: the base's part times
 * the coat's transmission (1 - c Fc(wo.z)) (1 - c Fc(wi.z)), and the coat
 * lobe's part c Fc(wo.h) G2 dD/drough_c / (4 wo.z wi.z), each asked alone.
 * Also: zero for a Lambertian and below the alpha floor. */
static void test_rough_ndf_vs_fd(void)
{
    struct rng r = {91};
    double worst = 0.0, worst_coat = 0.0;
    for (int k = 0; k < 1000; k++) {
        double rough = 0.1 + 0.85 * rng_next(&r), m = rng_next(&r);
        dr_vec3 base = dr_v3(rng_next(&r), rng_next(&r), rng_next(&r));
        struct dr_bsdf b = make_bsdf(rough, m, base);
        b.specular = 0.5 + 0.5 * rng_next(&r);
        const bool coated = k % 2;
        if (coated)
            b.coated = true, b.coat = rng_next(&r), b.coat_roughness = 0.05 + 0.9 * rng_next(&r);
        double co = 0.2 + 0.8 * rng_next(&r), ci = 0.2 + 0.8 * rng_next(&r), pi_ = 2.0 * M_PI * rng_next(&r);
        dr_vec3 wo = dr_v3(sqrt(1 - co * co), 0.0, co), wi = dr_v3(sqrt(1 - ci * ci) * cos(pi_), sqrt(1 - ci * ci) * sin(pi_), ci);
        /* the lobe with D at roughness t: f(t) = f_rest + f_spec(rough) * D(t) / D(rough) */
        const double ndf = ref_ndf_part(rough, wo, wi);
        const double s5 = pow(1.0 - 0.5 * dr_length(dr_add(wo, wi)), 5.0);
        const double f0 = fmin(0.04, 1.0) * b.specular;
        const double tt = coated ? (1.0 - b.coat * ref_coat_fresnel(co)) * (1.0 - b.coat * ref_coat_fresnel(ci)) : 1.0;
        for (int c = 0; c < 3; c++) {
            double bc = dr_v3_get(base, c);
            double fd = f0 + (b.specular - f0) * s5, fm = bc + (1.0 - bc) * s5;
            double want = tt * ((1.0 - m) * fd + m * fm) * ndf;
            struct dr_d_bsdf d = {0};
            dr_vec3 d_out = dr_v3s(0.0);
            dr_v3_set(&d_out, c, 1.0);
            d_bsdf_eval_rough_ndf(&b, wo, wi, d_out, DR_BSDF_D_ROUGHNESS, &d);
            double err = fabs(d.roughness - want) / (fabs(want) + 1e-3);
            if (err > worst)
                worst = err;
            CHECK(d.metallic == 0.0 && dr_is_black(d.base_color) && d.coat == 0.0 && d.coat_roughness == 0.0,
                  "rough_ndf touched other adjoints");
            if (!coated)
                continue;
            /* the coat's part: a white lobe of f0 0.04 and f90 1, times c */
            const double want_c = b.coat * (0.04 + 0.96 * s5) * ref_ndf_part(b.coat_roughness, wo, wi);
            struct dr_d_bsdf dc = {0};
            d_bsdf_eval_rough_ndf(&b, wo, wi, d_out, DR_BSDF_D_COAT_ROUGHNESS, &dc);
            err = fabs(dc.coat_roughness - want_c) / (fabs(want_c) + 1e-3);
            if (err > worst_coat)
                worst_coat = err;
            CHECK(dc.roughness == 0.0 && dc.coat == 0.0 && dc.metallic == 0.0,
                  "the coat's NDF part touched other adjoints");
        }
    }
    printf("NDF part of d f / d roughness vs central differences: worst relative error %.3g (the coat's %.3g)\n",
           worst, worst_coat);
    CHECK(worst < 1e-5, "d_bsdf_eval_rough_ndf vs finite differences: relative error %g", worst);
    CHECK(worst_coat < 1e-5, "d_bsdf_eval_rough_ndf (coat) vs finite differences: relative error %g", worst_coat);
    struct dr_bsdf plain = make_bsdf(0.4, 0.5, dr_v3s(0.5));
    struct dr_d_bsdf dp = {0};
    const dr_vec3 wa = dr_normalize(dr_v3(0.3, 0.2, 1.0)), wb = dr_normalize(dr_v3(-0.1, 0.4, 1.0));
    d_bsdf_eval_rough_ndf(&plain, wa, wb, dr_v3s(1.0), DR_BSDF_D_COAT_ROUGHNESS, &dp);
    CHECK(dp.roughness == 0.0 && dp.coat_roughness == 0.0, "an uncoated BSDF's coat part is not 0");
    struct dr_bsdf lam = make_bsdf(0.5, 0.0, dr_v3s(0.5));
    lam.specular = 0.0;
    struct dr_bsdf flo = make_bsdf(1e-4, 1.0, dr_v3s(0.5));
    struct dr_d_bsdf d = {0};
    dr_vec3 w = dr_normalize(dr_v3(0.1, 0.2, 1.0));
    d_bsdf_eval_rough_ndf(&lam, w, w, dr_v3s(1.0), DR_BSDF_D_ROUGHNESS, &d);
    d_bsdf_eval_rough_ndf(&flo, w, w, dr_v3s(1.0), DR_BSDF_D_ROUGHNESS, &d);
    CHECK(d.roughness == 0.0, "NDF part not 0 for a Lambertian or below the alpha floor: %g", d.roughness);
}

/* Chi-square of a lobe (or mixture) on bins of a stretched lobe's own
 * coordinates: F = u / (1 + u) and phi of its stretched slopes t = H.xy /
 * (Hz alpha), 8 x 16 bins, where both the stretched lobe and the pair's
 * boundaries (curves u = u*(phi)) stay resolved at any aspect ratio
 * (chi2_case's isotropic cells do not). A bin's expected count integrates
 * the density dr_bsdf_deriv_lobe_pdf / dr_bsdf_deriv_pdf gives over it by
 * the change of variables d omega_i = 4 (wo.h) d omega_h, d omega_h =
 * 2 dF dphi / (2 pi 2 D(h) cos(theta_h)) with D the test's own stretched
 * GGX (D cos d omega_h = du dphi / (2 pi (1 + u)^2), du = (1 + u)^2 dF). */
static void chi2_stretched(const char *what, const struct dr_bsdf *b, double cos_o, unsigned params, int lobe, long n,
                           uint64_t seed)
{
    enum { NF = 8, NPH = 16, SF = 48, SPH = 24 };
    const double a = fmax(b->roughness * b->roughness, DR_BSDF_MIN_ALPHA), s = b->anisotropy;
    const double ax = a + (1.0 - a) * s * s;
    const dr_vec3 wo = dr_v3(sqrt(1.0 - cos_o * cos_o), 0.0, cos_o);
    static double obs[NF * NPH], expd[NF * NPH];
    double total = 0.0;
    for (int i = 0; i < NF * NPH; i++) {
        obs[i] = 0.0;
        double e = 0.0;
        for (int jf = 0; jf < SF; jf++)
            for (int jp = 0; jp < SPH; jp++) {
                const double F = ((i / NPH) + (jf + 0.5) / SF) / NF, ph = 2.0 * M_PI * ((i % NPH) + (jp + 0.5) / SPH) / NPH;
                const double u = F / (1.0 - F), rr = sqrt(u);
                const dr_vec3 h = dr_normalize(dr_v3(ax * rr * cos(ph), a * rr * sin(ph), 1.0));
                const double oh = dr_dot(wo, h);
                const dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), wo);
                if (!(oh > 0.0) || !(wi.z > 1e-12))
                    continue;
                const double q = h.x * h.x / (ax * ax) + h.y * h.y / (a * a) + h.z * h.z;
                const double D = 1.0 / (M_PI * ax * a * q * q);
                const double pdf = params ? dr_bsdf_deriv_pdf(b, wo, wi, params)
                                          : dr_bsdf_deriv_lobe_pdf(b, wo, wi, (enum dr_bsdf_dlobe)lobe);
                e += pdf * 4.0 * oh / (2.0 * M_PI * D * h.z) * (1.0 / (NF * SF)) * (2.0 * M_PI / (NPH * SPH));
            }
        expd[i] = e;
        total += e;
    }
    struct rng r = {seed};
    long valid = 0;
    for (long k = 0; k < n; k++) {
        dr_vec3 wi;
        double pdf;
        if (!draw(b, wo, params, lobe, &r, &wi, &pdf))
            continue;
        valid++;
        const dr_vec3 H = dr_add(wo, wi);
        const double tx = H.x / (H.z * ax), ty = H.y / (H.z * a), u = tx * tx + ty * ty;
        double ph = atan2(ty, tx);
        if (ph < 0.0)
            ph += 2.0 * M_PI;
        int fi = (int)(u / (1.0 + u) * NF), pi_ = (int)(ph / (2.0 * M_PI) * NPH);
        fi = fi < NF ? fi : NF - 1, pi_ = pi_ < NPH ? pi_ : NPH - 1;
        obs[fi * NPH + pi_] += 1.0;
    }
    chi2_verdict(what, cos_o, obs, expd, NF * NPH, n, valid, total);
}

/* KHR_materials_anisotropy (bsdf.h): the VNDF lobe is the forward sampler's
 * specular map, stretched with the base's lobe (alpha_x = alpha + (1 -
 * alpha) s^2): its density is dr_bsdf_pdf's for a metal (p = 1), its samples
 * follow it (chi-square on cells at the geometric mean of the alphas), and a
 * base-colour and metallic mixture (cosine + VNDF) still matches its pdf.
 * The roughness pair of a stretched lobe is the lobe itself on either side
 * of the stretched u = 1: their densities sum to 2 D cos(theta_h) (h-space),
 * each lives on its own side, and their samples follow them; the base's NDF
 * part is the lobe times the roughness's share of d ln D (central
 * differences of a test-side stretched D), and a coat's is that of the same
 * BSDF without anisotropy. */
static void test_aniso(void)
{
    struct rng r = {4711};
    double worst = 0.0;
    const double ss[] = {0.3, 0.8, 1.0}, roughs[] = {0.05, 0.3, 0.7};
    for (int k = 0; k < 3000; k++) {
        struct dr_bsdf b = make_bsdf(roughs[k % 3], 1.0, dr_v3(0.9, 0.7, 0.4));
        b.anisotropy = ss[(k / 3) % 3];
        double co = 0.05 + 0.95 * rng_next(&r), ci = 0.05 + 0.95 * rng_next(&r);
        double po = 2.0 * M_PI * rng_next(&r), pi_ = 2.0 * M_PI * rng_next(&r);
        dr_vec3 wo = dr_v3(sqrt(1 - co * co) * cos(po), sqrt(1 - co * co) * sin(po), co);
        dr_vec3 wi = dr_v3(sqrt(1 - ci * ci) * cos(pi_), sqrt(1 - ci * ci) * sin(pi_), ci);
        double pv = dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_VNDF), pf = dr_bsdf_pdf(&b, wo, wi);
        double rel = fabs(pv - pf) / pf;
        if (rel > worst)
            worst = rel;
        CHECK(rel <= 1e-15, "anisotropic VNDF lobe density %.17g vs dr_bsdf_pdf %.17g (s %g)", pv, pf, b.anisotropy);
        struct dr_bsdf iso = b;
        iso.anisotropy = 0.0;
        if (k < 300)   /* the stretched lobe's density is not the isotropic one */
            CHECK(pv != dr_bsdf_deriv_lobe_pdf(&iso, wo, wi, DR_BSDF_DLOBE_VNDF), "VNDF lobe density ignores anisotropy");
    }
    printf("anisotropic VNDF lobe density vs dr_bsdf_pdf (metal, p = 1): worst relative difference %.2g\n", worst);
    printf("anisotropic VNDF lobe and mixtures (cells at sqrt(ax ay)):\n");
    uint64_t seed = 9000;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 2; j++) {
            /* (the isotropic cells here resolve a lobe up to ax/ay ~ 40: rough 0.05
             * only at s = 0.3; test_bsdf's chi-square on stretched cells covers the
             * same map up to ax/ay = 400) */
            const double rough = roughs[i], s = i == 0 ? 0.3 : ss[(i + j) % 3], a = rough * rough;
            const double ax = a + (1.0 - a) * s * s;
            struct dr_bsdf b = make_bsdf(rough, 1.0, dr_v3(1.0, 0.8, 0.3));
            b.anisotropy = s;
            cells_alpha = sqrt(ax * a);
            char what[64];
            snprintf(what, sizeof what, "vndf rough=%.2f s=%.1f", rough, s);
            chi2_case(what, &b, j ? 0.4 : 0.95, 0, DR_BSDF_DLOBE_VNDF, 200000, seed++);
            b.metallic = 0.5;
            snprintf(what, sizeof what, "base+metallic m=0.5 rough=%.2f s=%.1f", rough, s);
            chi2_case(what, &b, 0.7, DR_BSDF_D_BASE | DR_BSDF_D_METALLIC, 0, 200000, seed++);
        }
    /* the roughness pair's maps and densities, alone and in the roughness
     * mixture, on bins of the stretched lobe's own coordinates (chi2_stretched) */
    printf("anisotropic roughness pair (bins in the stretched (u / (1 + u), phi)):\n");
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 2; j++) {
            const double rough = roughs[i], s = i == 0 ? 0.3 : ss[(i + j) % 3];
            struct dr_bsdf b = make_bsdf(rough, 1.0, dr_v3(1.0, 0.8, 0.3));
            b.anisotropy = s;
            char what[64];
            for (int l = DR_BSDF_DLOBE_ROUGH_POS; l <= DR_BSDF_DLOBE_ROUGH_NEG; l++) {
                snprintf(what, sizeof what, "rough%c rough=%.2f s=%.1f", l == DR_BSDF_DLOBE_ROUGH_POS ? '+' : '-',
                         rough, s);
                chi2_stretched(what, &b, j ? 0.4 : 0.95, 0, l, 400000, seed++);
            }
            /* (at rough 0.05 the pair alone: the base colour's cosine lobe
             * lies in the last bin's far end, beyond these bins' quadrature) */
            b.metallic = 0.5;
            snprintf(what, sizeof what, "rough mixture m=0.5 rough=%.2f s=%.1f", rough, s);
            chi2_stretched(what, &b, 0.7, DR_BSDF_D_ROUGHNESS | (i ? DR_BSDF_D_BASE : 0u), 0, 400000, seed++);
        }
    /* h-space densities: each side's is |d D / d alpha| cos(theta_h) / M,
     * d D / d alpha by central differences of a test-side D and M the side's
     * mass (bsdf.c's rough_split: with cx = (1 - s^2) / ax, cy = 1 / ay,
     * c = cx + cy, k = c + 2 (cx - cy) cos(2 phi), M+ = k^2 / (2 (k + c)),
     * M- = c^2 / (2 (k + c)), or (c - k) / 2 where k <= 0); and p+'s side is
     * d D / d alpha > 0's */
    double worst_d = 0.0;
    int sign_ok = 0, sign_n = 0;
    for (int k = 0; k < 3000; k++) {
        const double rough = 0.05 + 0.9 * rng_next(&r), a = rough * rough, s = 0.1 + 0.9 * rng_next(&r);
        const double ax = a + (1.0 - a) * s * s;
        struct dr_bsdf b = make_bsdf(rough, 1.0, dr_v3s(1.0));
        b.anisotropy = s;
        dr_vec3 wo = dr_normalize(dr_v3(rng_next(&r) - 0.5, rng_next(&r) - 0.5, 0.6 + rng_next(&r)));
        dr_vec3 h = dr_normalize(dr_v3(ax * (2.0 * rng_next(&r) - 1.0) * 2.0, a * (2.0 * rng_next(&r) - 1.0) * 2.0, 1.0));
        const double oh = dr_dot(wo, h);
        const dr_vec3 wi = dr_sub(dr_scale(h, 2.0 * oh), wo);
        if (!(oh > 0.0) || !(wi.z > 1e-3))
            continue;
        const double tx = h.x / (h.z * ax), ty = h.y / (h.z * a), u = tx * tx + ty * ty;
        const double cx = (1.0 - s * s) / ax, cy = 1.0 / a, c = cx + cy;
        const double kk = c + 2.0 * (cx - cy) * (tx * tx - ty * ty) / u;
        const bool pos = u * kk > c;
        const double M = pos ? kk * kk / (2.0 * (kk + c)) : kk > 0.0 ? c * c / (2.0 * (kk + c)) : 0.5 * (c - kk);
        double Dm[2];
        for (int sg = 0; sg < 2; sg++) {
            const double al = a * (1.0 + (sg ? 1e-6 : -1e-6)), axl = al + (1.0 - al) * s * s;
            const double ql = h.x * h.x / (axl * axl) + h.y * h.y / (al * al) + h.z * h.z;
            Dm[sg] = 1.0 / (M_PI * axl * al * ql * ql);
        }
        const double q = h.x * h.x / (ax * ax) + h.y * h.y / (a * a) + h.z * h.z;
        const double D = 1.0 / (M_PI * ax * a * q * q);
        const double want = fabs(Dm[1] - Dm[0]) / (2e-6 * a) * h.z / M;
        const double pp = dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_ROUGH_POS) * 4.0 * oh;
        const double pn = dr_bsdf_deriv_lobe_pdf(&b, wo, wi, DR_BSDF_DLOBE_ROUGH_NEG) * 4.0 * oh;
        if (fabs(u * kk - c) > 1e-3 * c) {
            worst_d = fmax(worst_d, fabs((pos ? pp : pn) - want) / want);
            CHECK(pos ? pn == 0.0 : pp == 0.0, "stretched roughness pair on the wrong side: u %g k %g (+ %g, - %g)",
                  u, kk, pp, pn);
            if (fabs(Dm[1] - Dm[0]) > 1e-7 * D) {
                sign_n++;
                sign_ok += (Dm[1] > Dm[0]) == pos;
            }
        }
    }
    printf("anisotropic roughness pair vs |d D / d alpha| cos / M: worst relative error %.3g; p+'s side is d D / d alpha > 0's at %d "
           "of %d\n", worst_d, sign_ok, sign_n);
    CHECK(worst_d < 1e-5, "anisotropic roughness pair's density: relative error %g", worst_d);
    CHECK(sign_ok == sign_n && sign_n > 1000, "the pair's sides are d D / d alpha's signs: %d of %d", sign_ok, sign_n);
    /* the NDF part: the lobe times the roughness's share of d ln D (central
     * differences in the roughness of a test-side stretched D, s held); a
     * coat's part unchanged */
    double worst_n = 0.0;
    for (int k = 0; k < 400; k++) {
        struct dr_bsdf b = make_bsdf(0.2 + 0.7 * rng_next(&r), 1.0, dr_v3(0.5, 0.6, 0.7));
        b.anisotropy = 0.1 + 0.9 * rng_next(&r);
        dr_vec3 wo = dr_normalize(dr_v3(rng_next(&r) - 0.5, rng_next(&r) - 0.5, 1.0));
        dr_vec3 wi = dr_normalize(dr_v3(rng_next(&r) - 0.5, rng_next(&r) - 0.5, 1.0));
        struct dr_d_bsdf d = {0};
        d_bsdf_eval_rough_ndf(&b, wo, wi, dr_v3s(1.0), DR_BSDF_D_ROUGHNESS, &d);
        const dr_vec3 h = dr_normalize(dr_add(wo, wi)), f = dr_bsdf_eval(&b, wo, wi);   /* (a metal: f is the lobe) */
        double lnD[2];
        for (int sgn = 0; sgn < 2; sgn++) {
            const double rr = b.roughness + (sgn ? 1e-5 : -1e-5), a = rr * rr, ax = a + (1.0 - a) * b.anisotropy * b.anisotropy;
            const double q = h.x * h.x / (ax * ax) + h.y * h.y / (a * a) + h.z * h.z;
            lnD[sgn] = -log(M_PI * ax * a * q * q);
        }
        const double want = (f.x + f.y + f.z) * (lnD[1] - lnD[0]) / 2e-5;
        const double rel = fabs(d.roughness - want) / fmax(fabs(want), 1e-3 * (f.x + f.y + f.z));
        worst_n = fmax(worst_n, rel);
        CHECK(rel < 1e-6 && d.anisotropy == 0.0, "stretched base: NDF part %.10g, want %.10g (anisotropy part %g)",
              d.roughness, want, d.anisotropy);
        b.coated = true, b.coat = 0.6, b.coat_roughness = 0.1 + 0.8 * rng_next(&r);
        struct dr_bsdf iso = b;
        iso.anisotropy = 0.0;
        struct dr_d_bsdf dc = {0}, di = {0};
        d_bsdf_eval_rough_ndf(&b, wo, wi, dr_v3s(1.0), DR_BSDF_D_COAT_ROUGHNESS, &dc);
        d_bsdf_eval_rough_ndf(&iso, wo, wi, dr_v3s(1.0), DR_BSDF_D_COAT_ROUGHNESS, &di);
        CHECK(dc.roughness == 0.0 && dc.coat_roughness == di.coat_roughness && dc.coat_roughness != 0.0,
              "coated stretched base: base part %g, coat part %g vs %g", dc.roughness, dc.coat_roughness,
              di.coat_roughness);
    }
    printf("anisotropic NDF part vs central differences of ln D: worst relative error %.3g\n", worst_n);
}


/* The sheen (bsdf_sheen.c): on a sheened BSDF the derivative mixture's
 * lobes are the base's (T(wo) T(wi) is a smooth factor), so every mixture
 * is still a consistent density whose samples follow it, with a coat over
 * the sheen too; and d_bsdf_eval_rough_ndf's part is T(wo) T(wi) times the
 * unsheened BSDF's (under a coat: the coat's factor as well, the coat's own
 * part unchanged), T = max(0, 1 - m E(cos, r)) from the table. */
static void test_sheen(void)
{
    static const struct { const char *name; unsigned params; } masks[] = {
        {"sheened base", DR_BSDF_D_BASE}, {"sheened metallic", DR_BSDF_D_METALLIC},
        {"sheened roughness", DR_BSDF_D_ROUGHNESS},
        {"sheened all, coated", DR_BSDF_D_BASE | DR_BSDF_D_METALLIC | DR_BSDF_D_ROUGHNESS | DR_BSDF_D_COAT_ROUGHNESS}};
    uint64_t seed = 5000;
    printf("sheened mixtures (dr_bsdf_deriv_sample vs dr_bsdf_deriv_pdf):\n");
    for (int m = 0; m < 4; m++)
        for (int i = 0; i < 2; i++) {
            struct dr_bsdf b = make_bsdf(i == 0 ? 0.2 : 0.5, i == 0 ? 1.0 : 0.3, dr_v3(0.9, 0.1, 0.1));
            b.sheened = true, b.sheen_color = dr_v3(1.0, 0.5, 0.5), b.sheen_roughness = i == 0 ? 0.3 : 0.07;
            if (masks[m].params & DR_BSDF_D_COAT_ROUGHNESS)
                b.coated = true, b.coat = 0.6, b.coat_roughness = 0.3;
            char what[64];
            snprintf(what, sizeof what, "%s m=%.1f r=%.1f", masks[m].name, b.metallic, b.roughness);
            chi2_case(what, &b, i == 0 ? 0.7 : 0.2, masks[m].params, 0, 200000, seed++);
        }
    struct rng r = {1234};
    double worst = 0.0;
    int nonzero = 0;
    for (int k = 0; k < 1000; k++) {
        struct dr_bsdf b = make_bsdf(0.1 + 0.85 * rng_next(&r), rng_next(&r), dr_v3(rng_next(&r), rng_next(&r), rng_next(&r)));
        b.sheened = true;
        b.sheen_roughness = k % 4 == 0 ? 0.07 : rng_next(&r);
        b.sheen_color = k % 5 == 0 ? dr_v3s(1.0) : dr_v3(rng_next(&r), rng_next(&r), rng_next(&r));
        const bool coated = k % 3 == 0;
        if (coated)
            b.coated = true, b.coat = rng_next(&r), b.coat_roughness = 0.05 + 0.9 * rng_next(&r);
        const double co = (k % 7 == 0 ? 0.01 : 0.2) + 0.8 * rng_next(&r), ci = 0.05 + 0.95 * rng_next(&r);
        const double ph = 2.0 * M_PI * rng_next(&r);
        const dr_vec3 wo = dr_v3(sqrt(1 - co * co), 0.0, co);
        const dr_vec3 wi = dr_v3(sqrt(1 - ci * ci) * cos(ph), sqrt(1 - ci * ci) * sin(ph), ci);
        const double sr = fmax(b.sheen_roughness, DR_SHEEN_MIN_ROUGHNESS), m = dr_max3(b.sheen_color);
        const double tt = fmax(0.0, 1.0 - m * dr_sheen_albedo(co, sr, NULL, NULL)) *
                          fmax(0.0, 1.0 - m * dr_sheen_albedo(ci, sr, NULL, NULL));
        struct dr_bsdf plain = b;
        plain.sheened = false;
        const dr_vec3 d_out = dr_v3(rng_next(&r), rng_next(&r), rng_next(&r));
        struct dr_d_bsdf ds = {0}, dp = {0}, dsc = {0}, dpc = {0};
        d_bsdf_eval_rough_ndf(&b, wo, wi, d_out, DR_BSDF_D_ROUGHNESS, &ds);
        d_bsdf_eval_rough_ndf(&plain, wo, wi, d_out, DR_BSDF_D_ROUGHNESS, &dp);
        const double want = tt * dp.roughness, err = fabs(ds.roughness - want) / (fabs(want) + 1e-300);
        if (want != 0.0)
            worst = fmax(worst, err), nonzero++;
        CHECK(want == 0.0 ? ds.roughness == 0.0 : err < 1e-12, "sheened NDF part %g vs T T x unsheened %g", ds.roughness,
              want);
        CHECK(ds.metallic == 0.0 && dr_is_black(ds.base_color) && dr_is_black(ds.sheen_color) && ds.sheen_roughness == 0.0,
              "sheened NDF part touched other adjoints");
        if (coated) {
            d_bsdf_eval_rough_ndf(&b, wo, wi, d_out, DR_BSDF_D_COAT_ROUGHNESS, &dsc);
            d_bsdf_eval_rough_ndf(&plain, wo, wi, d_out, DR_BSDF_D_COAT_ROUGHNESS, &dpc);
            CHECK(dsc.coat_roughness == dpc.coat_roughness, "the coat's NDF part changed under a sheen");
        }
    }
    printf("sheened NDF part vs T T x the unsheened one: %d nonzero, worst relative error %.2e\n", nonzero, worst);
    CHECK(nonzero > 500, "too few nonzero sheened NDF parts (%d)", nonzero);
}

int main(void)
{
    test_rough_ndf_vs_fd();
    test_rough_vs_fd();
    test_lobes();
    test_mixtures();
    test_aniso();
    test_sheen();
    printf("worst chi-square p-value: %.4g\n", worst_p);
    return TEST_END();
}
