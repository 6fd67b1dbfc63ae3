/* KHR_materials_clearcoat: a clear dielectric coat (index 1.5) of weight
 * c = clearcoatFactor and GGX roughness r_c = clearcoatRoughnessFactor over
 * the metallic-roughness BSDF (bsdf.h):
 *
 *   f = T(wo) T(wi) f_base + c f_coat,   T(w) = 1 - c Fc(w.z),
 *   Fc(x) = 0.04 + 0.96 (1 - x)^5        (Schlick, f0 = ((1.5 - 1) / (1.5 + 1))^2),
 *   f_coat = Fc(wo.h) D G2 / (4 wo.z wi.z), alpha = r_c^2.
 *
 * f_coat is exactly the base BSDF with base colour 0, metallic 0, specular 1
 * and a white specular colour (its dielectric lobe: f0 = 0.04, f90 = 1, and
 * no diffuse part), so the coat is evaluated, sampled and differentiated by
 * bsdf.c's own functions on that BSDF (coat_lobe), and the base by them on a
 * copy without the coat (under). Nothing here repeats GGX.
 *
 * glTF's reference layering weighs the base by 1 - c Fc(n.wo) alone, which
 * is not reciprocal; weighing it by what the coat lets through on the way in
 * and on the way out, as bsdf.c's diffuse lobe does under the dielectric
 * layer, keeps f(wo, wi) = f(wi, wo) and a white base's albedo <= 1.
 *
 * Sampling: the coat's lobe with probability P = c Fc(wo.z) (about the
 * coat's albedo, so its samples' weights stay near G2/G1), else the base's
 * lobes with u_lobe rescaled; pdf = P p_coat + (1 - P) p_base. */
#include "bsdf_coat.h"
#include "bsdf_sheen.h"

#include <stddef.h>

#define COS_EPS DR_BSDF_COS_EPS

static inline double coat_fresnel(double x)
{
    double t = 1.0 - dr_clamp(x, 0.0, 1.0), t2 = t * t;
    return 0.04 + 0.96 * (t2 * t2 * t);
}

/* d Fc / d x: flat where the clamp is. */
static inline double d_coat_fresnel(double x)
{
    double t = 1.0 - x, t2 = t * t;
    return x > 0.0 && x < 1.0 ? -4.8 * (t2 * t2) : 0.0;
}

static inline struct dr_bsdf under(const struct dr_bsdf *b)
{
    struct dr_bsdf u = *b;
    u.coated = false;
    return u;
}

static inline struct dr_bsdf coat_lobe(const struct dr_bsdf *b)
{
    return (struct dr_bsdf){.base_color = dr_v3s(0.0), .metallic = 0.0, .roughness = b->coat_roughness,
                            .specular = 1.0, .specular_color = dr_v3s(1.0)};
}

/* The base's parameter adjoints into d (the coat's are added by the callers). */
static inline void add_base(struct dr_d_bsdf *d, const struct dr_d_bsdf *db)
{
    d->base_color = dr_add(d->base_color, db->base_color);
    d->metallic += db->metallic;
    d->roughness += db->roughness;
    d->anisotropy += db->anisotropy;   /* (the base's lobe is the stretched one) */
    d->sheen_color = dr_add(d->sheen_color, db->sheen_color);   /* (a sheen is the base's layer) */
    d->sheen_roughness += db->sheen_roughness;
}

dr_vec3 dr_coat_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf)
{
    const struct dr_bsdf base = under(b), lobe = coat_lobe(b);
    const double c = b->coat, to = 1.0 - c * coat_fresnel(wo.z), ti = 1.0 - c * coat_fresnel(wi.z);
    double pb = 0.0, pl = 0.0;
    const dr_vec3 fb = pdf ? dr_bsdf_eval_pdf(&base, wo, wi, &pb) : dr_bsdf_eval(&base, wo, wi);
    const dr_vec3 fl = pdf ? dr_bsdf_eval_pdf(&lobe, wo, wi, &pl) : dr_bsdf_eval(&lobe, wo, wi);
    if (pdf) {
        const double p = c * coat_fresnel(wo.z);
        *pdf = p * pl + (1.0 - p) * pb;
    }
    return dr_add(dr_scale(fb, to * ti), dr_scale(fl, c));
}

dr_vec3 dr_coat_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2)
{
    if (lobe == DR_BSDF_LOBE_COAT) {
        const struct dr_bsdf l = coat_lobe(b);
        return dr_bsdf_sample_dir(&l, wo, DR_BSDF_LOBE_SPECULAR, u1, u2);
    }
    const struct dr_bsdf base = under(b);
    return dr_bsdf_sample_dir(&base, wo, lobe, u1, u2);
}

bool dr_coat_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                    struct dr_bsdf_sample *out)
{
    out->wi = dr_v3(0.0, 0.0, 1.0);
    out->f = dr_v3s(0.0);
    out->pdf = 0.0;
    out->lobe = DR_BSDF_LOBE_DIFFUSE;
    if (!(wo.z > COS_EPS))
        return false;
    const double p = b->coat * coat_fresnel(wo.z);
    if (u_lobe < p) {
        out->lobe = DR_BSDF_LOBE_COAT;
    } else {   /* (p <= u_lobe < 1: 1 - p > 0) */
        const struct dr_bsdf base = under(b);
        const double u = (u_lobe - p) / (1.0 - p);
        if (base.sheened)   /* (the sheen's lobe, then the base's: bsdf_sheen.c) */
            out->lobe = dr_sheen_pick_lobe(&base, wo, u);
        else
            out->lobe = u < dr_bsdf_specular_prob(&base, wo) ? DR_BSDF_LOBE_SPECULAR : DR_BSDF_LOBE_DIFFUSE;
    }
    const dr_vec3 wi = dr_coat_sample_dir(b, wo, out->lobe, u1, u2);
    out->wi = wi;
    if (!(wi.z > COS_EPS))
        return false;
    double pdf;
    const dr_vec3 f = dr_coat_eval_pdf(b, wo, wi, &pdf);
    if (!(pdf > 0.0) || !isfinite(pdf))
        return false;
    out->f = f;
    out->pdf = pdf;
    return true;
}

double dr_coat_sky_share(const struct dr_bsdf *b, dr_vec3 wo)
{
    if (!(wo.z > COS_EPS))
        return 0.0;
    const struct dr_bsdf base = under(b), lobe = coat_lobe(b);
    const double p = b->coat * coat_fresnel(wo.z);
    return p * dr_bsdf_sky_share(&lobe, wo) + (1.0 - p) * dr_bsdf_sky_share(&base, wo);
}

double dr_coat_specular_prob(const struct dr_bsdf *b, dr_vec3 wo)
{
    const struct dr_bsdf base = under(b);
    const double p = b->coat * coat_fresnel(wo.z > COS_EPS ? wo.z : 0.0);
    return p + (1.0 - p) * dr_bsdf_specular_prob(&base, wo);
}

/* ------------------------------------------------------------ derivatives */

/* f = to ti f_base + c f_coat, to = 1 - c Fc(wo.z), ti = 1 - c Fc(wi.z):
 *   df/dc = -(Fc(wo.z) ti + to Fc(wi.z)) f_base + f_coat,
 *   d f / d wo.z = -c Fc'(wo.z) ti f_base (and alike for wi),
 * plus the base's adjoints at d_out to ti and the coat lobe's at d_out c. */
void d_coat_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    const struct dr_bsdf base = under(b), lobe = coat_lobe(b);
    const double c = b->coat, fo = coat_fresnel(wo.z), fi = coat_fresnel(wi.z);
    const double to = 1.0 - c * fo, ti = 1.0 - c * fi;
    struct dr_d_bsdf db = {0}, dl = {0};
    d_bsdf_eval(&base, wo, wi, dr_scale(d_out, to * ti), d ? &db : NULL, d_wo, d_wi);
    d_bsdf_eval(&lobe, wo, wi, dr_scale(d_out, c), d ? &dl : NULL, d_wo, d_wi);
    const double s = dr_dot(d_out, dr_bsdf_eval(&base, wo, wi));   /* d loss / d (to ti) */
    if (d) {
        add_base(d, &db);
        d->coat_roughness += dl.roughness;
        d->coat += s * -(fo * ti + to * fi) + dr_dot(d_out, dr_bsdf_eval(&lobe, wo, wi));
    }
    if (d_wo)
        d_wo->z -= s * ti * c * d_coat_fresnel(wo.z);
    if (d_wi)
        d_wi->z -= s * to * c * d_coat_fresnel(wi.z);
}

/* pdf = P p_coat + (1 - P) p_base, P = c Fc(wo.z). The coat lobe's own lobe
 * probability is 1 whatever its inputs (it has no diffuse part), so its
 * density is differentiated with that probability fixed either way; P moves
 * only when prob_moves (d_bsdf_pdf, not d_bsdf_pdf_fixed_prob). */
void d_coat_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, bool prob_moves, struct dr_d_bsdf *d,
                dr_vec3 *d_wo, dr_vec3 *d_wi)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const struct dr_bsdf base = under(b), lobe = coat_lobe(b);
    const double c = b->coat, p = c * coat_fresnel(wo.z);
    struct dr_d_bsdf db = {0}, dl = {0};
    d_bsdf_pdf_fixed_prob(&lobe, wo, wi, d_pdf * p, d ? &dl : NULL, d_wo, d_wi);
    if (prob_moves)
        d_bsdf_pdf(&base, wo, wi, d_pdf * (1.0 - p), d ? &db : NULL, d_wo, d_wi);
    else
        d_bsdf_pdf_fixed_prob(&base, wo, wi, d_pdf * (1.0 - p), d ? &db : NULL, d_wo, d_wi);
    if (d) {
        add_base(d, &db);
        d->coat_roughness += dl.roughness;
    }
    if (!prob_moves)
        return;
    const double d_p = d_pdf * (dr_bsdf_pdf(&lobe, wo, wi) - dr_bsdf_pdf(&base, wo, wi));
    if (d)
        d->coat += d_p * coat_fresnel(wo.z);
    if (d_wo)
        d_wo->z += d_p * c * d_coat_fresnel(wo.z);
}

/* p = P + (1 - P) p_base: dp/dP = 1 - p_base, dp/dp_base = 1 - P. */
void d_coat_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    const bool above = wo.z > COS_EPS;
    const double cos_o = above ? wo.z : 0.0, c = b->coat, p = c * coat_fresnel(cos_o);
    const struct dr_bsdf base = under(b);
    const double pb = dr_bsdf_specular_prob(&base, wo);
    struct dr_d_bsdf db = {0};
    d_bsdf_specular_prob(&base, wo, d_p * (1.0 - p), d ? &db : NULL, d_wo);
    if (d) {
        add_base(d, &db);
        d->coat += d_p * (1.0 - pb) * coat_fresnel(cos_o);
    }
    if (above && d_wo)
        d_wo->z += d_p * (1.0 - pb) * c * d_coat_fresnel(cos_o);
}

struct dr_bsdf dr_coat_lobe(const struct dr_bsdf *b) { return coat_lobe(b); }

/* The NDF parts of f = to ti f_base + c f_coat: the base's (its roughness's
 * D alone) times to ti, and the coat lobe's (the coat roughness's D alone)
 * times c; to, ti and c are smooth factors the roughness lobes need not
 * know. */
void d_coat_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                           struct dr_d_bsdf *d)
{
    if (!(wo.z > COS_EPS) || !(wi.z > COS_EPS))
        return;
    const double c = b->coat;
    if (parts & DR_BSDF_D_ROUGHNESS) {
        const struct dr_bsdf base = under(b);
        const double tt = (1.0 - c * coat_fresnel(wo.z)) * (1.0 - c * coat_fresnel(wi.z));
        d_bsdf_eval_rough_ndf(&base, wo, wi, dr_scale(d_out, tt), DR_BSDF_D_ROUGHNESS, d);
    }
    if (parts & DR_BSDF_D_COAT_ROUGHNESS) {
        const struct dr_bsdf lobe = coat_lobe(b);
        struct dr_d_bsdf dl = {0};
        d_bsdf_eval_rough_ndf(&lobe, wo, wi, dr_scale(d_out, c), DR_BSDF_D_ROUGHNESS, &dl);
        d->coat_roughness += dl.roughness;
    }
}

void d_coat_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                       dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo)
{
    struct dr_d_bsdf dd = {0};
    if (lobe == DR_BSDF_LOBE_COAT) {
        const struct dr_bsdf l = coat_lobe(b);
        d_bsdf_sample_dir(&l, wo, DR_BSDF_LOBE_SPECULAR, u1, u2, d_wi, d ? &dd : NULL, d_wo);
        if (d)
            d->coat_roughness += dd.roughness;
        return;
    }
    const struct dr_bsdf base = under(b);
    d_bsdf_sample_dir(&base, wo, lobe, u1, u2, d_wi, d ? &dd : NULL, d_wo);
    if (d)
        add_base(d, &dd);
}
