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
 *    which keeps every intermediate finite (z^2 never underflows). */
#include "bsdf.h"

#define COS_EPS 1e-12

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

/* cos_o = wo.z > COS_EPS. */
static double specular_prob(const struct dr_bsdf *b, double cos_o)
{
    if (no_specular_lobe(b))
        return 0.0;
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

/* f and pdf for wo.z, wi.z > COS_EPS, given p = specular_prob(b, wo.z).
 * The single place where the pdf is computed, so dr_bsdf_pdf, dr_bsdf_eval_pdf
 * and dr_bsdf_sample agree bit for bit. */
static inline dr_vec3 eval_pdf_above(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double p,
                                     double *pdf)
{
    double cos_pdf = wi.z * DR_INV_PI;
    if (no_specular_lobe(b)) {
        *pdf = cos_pdf;
        return dr_scale(b->base_color, DR_INV_PI);
    }
    double a = bsdf_alpha(b), a2 = a * a;
    dr_vec3 H = dr_add(wo, wi);
    double hxy2 = H.x * H.x + H.y * H.y;
    double H2 = hxy2 + H.z * H.z;
    double q = hxy2 + a2 * H.z * H.z;   /* > 0: H.z > 0 */
    double r = H2 / q;
    double D = a2 * r * r * DR_INV_PI;
    double lo = smith_lambda(a2, wo), li = smith_lambda(a2, wi);
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

dr_vec3 dr_bsdf_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS)) {
        *pdf = 0.0;
        return dr_v3s(0.0);
    }
    return eval_pdf_above(b, wo, wi, specular_prob(b, wo.z), pdf);
}

dr_vec3 dr_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi)
{
    double pdf;
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return dr_v3s(0.0);
    /* p = 0: the pdf is not needed, the compiler drops its arithmetic. */
    return eval_pdf_above(b, wo, wi, 0.0, &pdf);
}

double dr_bsdf_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi)
{
    double pdf = 0.0;
    dr_bsdf_eval_pdf(b, wo, wi, &pdf);
    return pdf;
}

double dr_bsdf_specular_prob(const struct dr_bsdf *b, dr_vec3 wo)
{
    if (!(wo.z > COS_EPS))
        return no_specular_lobe(b) ? 0.0 : specular_prob(b, 0.0);
    return specular_prob(b, wo.z);
}

/* Cosine-weighted hemisphere: Shirley-Chiu concentric disk, lifted (Malley). */
static inline dr_vec3 sample_cosine(double u1, double u2)
{
    double a = 2.0 * u1 - 1.0, c = 2.0 * u2 - 1.0;
    double r, phi;
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

/* GGX visible normals (Heitz 2018, JCGT 7(4)), wo.z > 0. Returns h. */
static inline dr_vec3 sample_vndf(dr_vec3 wo, double a, double u1, double u2)
{
    dr_vec3 vh = dr_normalize(dr_v3(a * wo.x, a * wo.y, wo.z));
    double lensq = vh.x * vh.x + vh.y * vh.y;
    dr_vec3 t1 = lensq > 0.0 ? dr_scale(dr_v3(-vh.y, vh.x, 0.0), 1.0 / sqrt(lensq)) : dr_v3(1.0, 0.0, 0.0);
    dr_vec3 t2 = dr_cross(vh, t1);
    double r = sqrt(u1), phi = 2.0 * M_PI * u2;
    double p1 = r * cos(phi), p2 = r * sin(phi);
    double s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(dr_max(0.0, 1.0 - p1 * p1)) + s * p2;
    dr_vec3 nh = dr_add(dr_add(dr_scale(t1, p1), dr_scale(t2, p2)),
                        dr_scale(vh, sqrt(dr_max(0.0, 1.0 - p1 * p1 - p2 * p2))));
    return dr_normalize(dr_v3(a * nh.x, a * nh.y, dr_max(0.0, nh.z)));
}

bool dr_bsdf_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                    struct dr_bsdf_sample *out)
{
    out->wi = dr_v3(0.0, 0.0, 1.0);
    out->f = dr_v3s(0.0);
    out->pdf = 0.0;
    if (!(wo.z > COS_EPS))
        return false;
    double p = specular_prob(b, wo.z);
    dr_vec3 wi;
    if (u_lobe < p) {
        dr_vec3 h = sample_vndf(wo, bsdf_alpha(b), u1, u2);
        wi = dr_sub(dr_scale(h, 2.0 * dr_dot(wo, h)), wo);
    } else {
        wi = sample_cosine(u1, u2);
    }
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

/* Reverse mode of dr_bsdf_eval (directions are constants). With
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
void d_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const bool lambert = no_specular_lobe(b);
    const double m = b->metallic;
    const dr_vec3 base = b->base_color;

    /* Microfacet term spec = D G2 / (4 wo.z wi.z), shared by both lobes. */
    double a = bsdf_alpha(b), a2 = a * a;
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
    double s5 = pow5(1.0 - dr_clamp(c, 0.0, 1.0));
    dr_vec3 fm = dr_v3(base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5,
                       base.z + (1.0 - base.z) * s5);
    double d_km = dr_dot(d_out, fm);      /* d loss / d (m spec)       */
    double d_kd = dr_dot(d_out, base);    /* d loss / d ((1-m) kd0)    */

    if (lambert) {
        /* m = 0, F_d = 0, kd0 = 1/pi: the roughness derivative is exactly 0. */
        d->base_color = dr_madd(d->base_color, d_out, DR_INV_PI);
        d->metallic += spec * d_km - DR_INV_PI * d_kd;
        return;
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

    double rough = b->roughness;
    double d_spec = (1.0 - m) * d_ks + m * d_km;
    if (d_spec == 0.0 || !(rough * rough > DR_BSDF_MIN_ALPHA))
        return;
    double dlnD = (2.0 / a) * ((hxy2 - a2 * hz2) / q);
    double dlo = 0.5 * a * tan2o / so, dli = 0.5 * a * tan2i / si;
    double dspec_da = spec * (dlnD - (dlo + dli) / g);
    d->roughness += d_spec * dspec_da * (2.0 * rough);
}
