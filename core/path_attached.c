/* Attached sampling: the reverse mode of one vertex of the staged walker
 * (path.h), stage by stage in reverse order, carrying the adjoint of the
 * walker's state (arriving ray, previous pdf, previous point) as redner's
 * backward pass carries d_next_rays / d_next_points.
 *
 * Forward order at a surface vertex, and what each stage's adjoint gets:
 *   hit      p, ns, uv = hit(o, d)                  d_hit_compute -> d_o, d_d
 *   emission Le(uv) * mis(prev_pdf, pdf_A(prev_p, p)) -> d_prev_pdf, d_prev_p, d_p, d_uv
 *   material frame(ns), wo = frame^T (-d), bsdf(uv)  -> d_ns, d_d, d_uv
 *   nee      light sample at p; f(wo, wi_l), |cos| mis / pdf  -> d_p, d_wo, d_frame (a sky: d_bsdf)
 *   continue wi = T(u, bsdf, wo); t = f |cos| / pdf / q; next ray (p, frame wi)
 * An escaped vertex has only Le(d) * mis(prev_pdf, pdf_env(d, prev_sky)): a
 * map's pdf_env is piecewise constant in d; a constant sky's is pick
 * prev_sky, prev_sky = (1 - c) cos / pi + c pdf (lights.h's dr_sky_pdf: cos
 * = d . ng of the point d left, pdf its BSDF's, the share c held at its
 * primal value as the lobe probability is): the continuation takes its
 * adjoint into its pdf and, along the constant ng, its direction. A
 * next-event sample of a constant sky drawn by the BSDF moves as the
 * continuation's does (its lobe fixed, its direction T(u, bsdf, wo)); one
 * drawn by the cosine about ng stays. */
#include "path.h"

#include <string.h>

#include "anisotropy.h"
#include "material.h"

bool dr_path_material_sampling_moves(const struct dr_scene *s, const struct dr_param_set *ps, int m)
{
    if (!ps || m < 0 || m >= ps->n_materials)
        return false;
    if (ps->mat_roughness[m] >= 0 || ps->mat_coat_roughness[m] >= 0)   /* (the coat's lobe map) */
        return true;
    const struct dr_texref *cr = dr_material_coat_tex(&s->materials[m], 1);
    if (cr && ps->image[s->textures[cr->texture].image] >= 0)
        return true;
    int t = s->materials[m].metallic_roughness_tex.texture;
    return t >= 0 && ps->image[s->textures[t].image] >= 0;
}

bool dr_path_params_enter_sampling(const struct dr_scene *s, const struct dr_param_set *ps)
{
    for (int m = 0; ps && m < ps->n_materials; m++)
        if (dr_path_material_sampling_moves(s, ps, m))
            return true;
    return false;
}

bool dr_path_vertex_sampling_moves(const struct dr_scene *s, const struct dr_param_set *ps,
                                   const struct dr_path_vertex *v)
{
    return v->shaded && dr_path_material_sampling_moves(s, ps, v->hit.material);
}

/* Adjoints gathered at one vertex before they flow into the hit and the material. */
struct vertex_adjoint {
    dr_vec3 p, ns, wo;
    struct dr_d_hit attr;   /* uv sets and vertex colour (p and ns are the fields above) */
    dr_frame frame;
    struct dr_d_bsdf bsdf;
};

/* Emission (surface) or environment radiance (escaped), times its MIS weight. */
static void emission_adjoint(const struct dr_scene *s, const struct dr_path_opts *opts,
                             const struct dr_path_vertex *v, dr_vec3 d_e, struct vertex_adjoint *a,
                             struct dr_d_path_state *d_this, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    if (!v->emits || dr_is_black(d_e))
        return;
    dr_vec3 d_Le = dr_scale(d_e, v->emit_w);
    double d_w = dr_dot(d_e, v->Le);
    if (v->kind == DR_VERTEX_ESCAPED) {
        if (sink)
            d_env_radiance(s, ps, v->d, d_Le, sink);
        d_env_radiance_dir(s, v->d, d_Le, &d_this->d);
        if (v->depth > 1) {   /* a map's pdf_env is constant within a cell; a sky's is pick prev_sky */
            const struct dr_light_sampler *ls = s->light_sampler;
            double d_pdf_env = 0.0;
            d_mis_power(v->prev_pdf, dr_light_pdf_env(s, ls, v->d, v->prev_sky), d_w, &d_this->prev_pdf, &d_pdf_env);
            if (!opts->sky_uniform)   /* (over the sphere prev_sky is a constant) */
                d_this->prev_sky = d_pdf_env * dr_light_pdf_env_dsky(ls);
        }
        return;
    }
    if (sink)
        d_emission(s, ps, &v->hit, d_Le, sink);
    d_emission_uv(s, &v->hit, d_Le, &a->attr);
    if (v->depth > 1) {
        double pdf_a = dr_light_pdf_area(s, s->light_sampler, v->prev_p, &v->hit), d_pdf_a = 0.0;
        d_mis_power(v->prev_pdf, pdf_a, d_w, &d_this->prev_pdf, &d_pdf_a);
        d_light_pdf_area_points(s, s->light_sampler, v->prev_p, &v->hit, d_pdf_a, &d_this->prev_p, &a->p);
    }
}

/* Next-event estimation: e_nee = f(wo, wi_l) L_l |wi_l.z| w / pdf_l, with
 * wi_l = frame^T ls.wi(p), w = mis(pdf_l(p), pdf_bsdf(wo, wi_l)). A
 * constant sky's pdf_l = pick ((1 - c) cos_g / pi + c pdf_bsdf(wo, wi_l))
 * (dr_sky_pdf, c held); drawn by the cosine, ls.wi and cos_g stay; drawn by
 * the BSDF, wi_l = T(u_l, bsdf, wo) and cos_g = (frame wi_l) . ng move. */
static void nee_adjoint(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                        dr_vec3 d_e, struct vertex_adjoint *a, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    if (!v->nee || dr_is_black(d_e))
        return;
    const struct dr_light_sample *ls = &v->ls;
    dr_vec3 d_f = dr_scale(dr_mul(d_e, ls->radiance), v->nee_scale);
    dr_vec3 d_rad = dr_scale(dr_mul(d_e, v->nee_f), v->nee_scale);
    double d_scale = dr_dot(d_e, dr_mul(v->nee_f, ls->radiance));
    double c = fabs(v->nee_wi.z), pdf_b = dr_bsdf_pdf(&v->bsdf, v->wo, v->nee_wi);
    double w = ls->delta ? 1.0 : dr_mis_power(ls->pdf, pdf_b);
    double d_pdf_l = -d_scale * v->nee_scale / ls->pdf, d_pdf_b = 0.0;
    if (!ls->delta)
        d_mis_power(ls->pdf, pdf_b, d_scale * c / ls->pdf, &d_pdf_l, &d_pdf_b);
    /* d |wi.z| / d wi.z = sign(wi.z); the adjoint keeps its own sign (copysign of
     * the product would drop it: a negative loss adjoint turned this term around) */
    dr_vec3 d_wi = dr_v3(0.0, 0.0, d_scale * w / ls->pdf * copysign(1.0, v->nee_wi.z));
    d_bsdf_eval(&v->bsdf, v->wo, v->nee_wi, d_f, &a->bsdf, &a->wo, &d_wi);
    /* a constant sky's density pick ((1 - c) cos_g / pi + c pdf_b) (dr_sky_pdf) */
    const double sky_pick =
        ls->type == DR_LS_ENV && !opts->sky_uniform ? dr_light_pdf_env_dsky(s->light_sampler) : 0.0;
    const double c_sky = sky_pick > 0.0 ? dr_bsdf_sky_share(&v->bsdf, v->wo) : 0.0;
    d_pdf_b += sky_pick * c_sky * d_pdf_l;
    if (d_pdf_b != 0.0)
        d_bsdf_pdf_fixed_prob(&v->bsdf, v->wo, v->nee_wi, d_pdf_b, &a->bsdf, &a->wo, &d_wi);
    if (ls->lobe >= 0) {   /* drawn by the BSDF: cos_g = (frame wi) . ng moves with it */
        const double d_cos = dr_dot(ls->wi, v->ng) > 0.0 ? sky_pick * (1.0 - c_sky) * DR_INV_PI * d_pdf_l : 0.0;
        d_frame_to_world(&v->frame, v->nee_wi, dr_scale(v->ng, d_cos), &d_wi, &a->frame);
        if (sink)
            d_light_radiance(s, ps, ls, d_rad, sink);
        d_bsdf_sample_dir(&v->bsdf, v->wo, ls->lobe, v->u.light_u1, v->u.light_u2, d_wi, &a->bsdf, &a->wo);
        return;
    }
    dr_vec3 d_ls_wi = dr_v3s(0.0);
    d_frame_to_local(&v->frame, ls->wi, d_wi, &d_ls_wi, &a->frame);
    if (sink)
        d_light_radiance(s, ps, ls, d_rad, sink);
    d_light_sample_point(s, v->hit.p, ls, d_ls_wi, d_pdf_l, d_rad, &a->p);
}

/* Continuation: t = f(wo, wi) |wi.z| / pdf(wo, wi) / q (q constant), the next
 * ray leaves p (offset along the constant ng) along frame wi, wi = T(u, bsdf, wo),
 * and hands on pdf and prev_sky = (1 - c) cos / pi + c pdf, cos = (frame wi) . ng
 * (dr_path_leaving_sky; a walk that samples the sky uniformly hands on a
 * constant, and the escaped vertex gives it no adjoint). */
static void continuation_adjoint(const struct dr_path_vertex *v, dr_vec3 d_t, const struct dr_d_path_state *d_next,
                                 struct vertex_adjoint *a)
{
    if (!v->cont)
        return;
    dr_vec3 d_f = dr_scale(d_t, v->cos_pdf_q);
    double d_tt = dr_dot(d_f, v->f);   /* sum_c d_t,c t_c */
    const double c_sky = d_next->prev_sky != 0.0 ? dr_bsdf_sky_share(&v->bsdf, v->wo) : 0.0;
    double d_pdf = -d_tt / v->pdf + d_next->prev_pdf + c_sky * d_next->prev_sky;
    dr_vec3 d_wi = dr_v3(0.0, 0.0, d_tt / v->wi.z);
    /* (each adjoint is linear in its seed: a zero seed adds nothing, and prb's
     * Jacobian rows seed one coordinate at a time, most of them zero here) */
    if (!dr_is_black(d_f))
        d_bsdf_eval(&v->bsdf, v->wo, v->wi, d_f, &a->bsdf, &a->wo, &d_wi);
    if (d_pdf != 0.0)
        d_bsdf_pdf_fixed_prob(&v->bsdf, v->wo, v->wi, d_pdf, &a->bsdf, &a->wo, &d_wi);
    const dr_vec3 d_cos = dr_scale(v->ng, (1.0 - c_sky) * DR_INV_PI * d_next->prev_sky);
    const dr_vec3 d_dir = dr_add(d_next->d, d_cos);
    if (!dr_is_black(d_dir))
        d_frame_to_world(&v->frame, v->wi, d_dir, &d_wi, &a->frame);
    a->p = dr_add(a->p, dr_add(d_next->o, d_next->prev_p));
    if (!dr_is_black(d_wi))
        d_bsdf_sample_dir(&v->bsdf, v->wo, v->lobe, v->u.bsdf_u1, v->u.bsdf_u2, d_wi, &a->bsdf, &a->wo);
}

/* Material inputs (the BSDF at uv, the frame of the oriented shading normal,
 * wo) and then the hit point itself, back to the arriving ray. */
static void surface_adjoint(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                            struct vertex_adjoint *a, struct dr_d_path_state *d_this, struct dr_grad_sink *sink)
{
    const struct dr_hit *hit = &v->hit;
    if (v->shaded) {
        if (v->diff_bsdf && sink)
            d_material_eval(s, ps, hit, &a->bsdf, sink);
        d_material_eval_uv(s, hit, &a->bsdf, &a->attr);
        dr_vec3 d_wo_world = dr_v3s(0.0);
        d_frame_to_local(&v->frame, dr_neg(v->d), a->wo, &d_wo_world, &a->frame);
        d_this->d = dr_sub(d_this->d, d_wo_world);
        dr_vec3 n = hit->front ? hit->ns : dr_neg(hit->ns), d_n = dr_v3s(0.0);
        /* an anisotropic frame turns with the tangent, the normal and the
         * direction texture (anisotropy.h); the rest is the normal's */
        if (!s->materials[hit->material].anisotropic || !d_anisotropy_frame(s, hit, n, &a->frame, &d_n, &a->attr))
            d_frame_from_normal(n, &a->frame, &d_n);
        else
            d_n = dr_add(d_n, a->frame.n);
        a->ns = hit->front ? dr_add(a->ns, d_n) : dr_sub(a->ns, d_n);
    }
    struct dr_d_hit dh = a->attr;
    dh.p = a->p;
    dh.ns = dr_add(a->ns, a->attr.ns);   /* (a->attr.ns: the tangent frame's, hit->ns unoriented) */
    d_hit_compute(&s->mesh, hit, v->o, v->d, &dh, &d_this->o, &d_this->d);
}

void d_path_vertex_attached(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                            dr_vec3 d_e, dr_vec3 d_t, const struct dr_d_path_state *d_next,
                            struct dr_d_path_state *d_this, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    struct vertex_adjoint a;
    memset(&a, 0, sizeof a);
    memset(d_this, 0, sizeof *d_this);
    emission_adjoint(s, opts, v, d_e, &a, d_this, sink);
    if (v->kind != DR_VERTEX_SURFACE)
        return;
    nee_adjoint(s, opts, v, d_e, &a, sink);
    continuation_adjoint(v, d_t, d_next, &a);
    surface_adjoint(s, ps, v, &a, d_this, sink);
}
