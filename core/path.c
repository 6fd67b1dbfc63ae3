#include "path.h"

#include "accel.h"
#include "material.h"

void dr_path_start(struct dr_path_state *st, dr_vec3 o, dr_vec3 d)
{
    st->o = o;
    st->d = d;
    st->prev_pdf = 0.0;
    st->prev_p = o;
    st->depth = 0;
    st->beta = dr_v3s(1.0);
    st->ratio = dr_v3s(1.0);
}

static bool material_emits(const struct dr_scene *s, const struct dr_path_opts *o, int64_t tri, int mat)
{
    if (dr_light_pdf_area_pick(s->light_sampler, tri) > 0.0)
        return true;
    /* a dark emitter whose emission is being differentiated still counts */
    return o->params && o->params->mat_emission_active[mat];
}

bool dr_path_step(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                  struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts)
{
    const struct dr_light_sampler *ls = s->light_sampler;
    const int depth = ++st->depth;
    v->depth = depth;
    v->d = st->d;
    v->emits = v->shaded = v->nee = v->cont = v->diff_bsdf = false;

    int64_t tri = dr_accel_intersect(s->accel, st->o, st->d, 0.0, INFINITY);
    if (depth == 1)
        counts->camera++;
    else
        counts->extension++;

    if (tri < 0) {
        v->kind = DR_VERTEX_ESCAPED;
        if (s->env.present) {
            v->emits = true;
            v->Le = dr_env_radiance(s, st->d);
            v->emit_w = depth == 1 ? 1.0 : dr_mis_power(st->prev_pdf, dr_light_pdf_env(s, ls, st->d));
        }
        return false;
    }
    v->kind = DR_VERTEX_SURFACE;
    struct dr_hit *hit = &v->hit;
    dr_hit_compute(&s->mesh, tri, st->o, st->d, hit);

    if (material_emits(s, opts, tri, hit->material)) {
        v->emits = true;
        v->Le = dr_emission(s, hit);
        v->emit_w = depth == 1 ? 1.0 : dr_mis_power(st->prev_pdf, dr_light_pdf_area(s, ls, st->prev_p, hit));
    }
    if (depth >= opts->max_depth)
        return false;

    const struct dr_material *mat = &s->materials[hit->material];
    if (!hit->front && !mat->double_sided)
        return false;   /* the back of a single-sided surface reflects nothing */
    /* Orient both normals towards the side the ray arrived from. */
    dr_vec3 ng = hit->front ? hit->ng : dr_neg(hit->ng);
    dr_vec3 ns = hit->front ? hit->ns : dr_neg(hit->ns);
    v->frame = dr_frame_from_normal(ns);
    v->wo = dr_frame_to_local(&v->frame, dr_neg(st->d));
    dr_material_eval(s, hit, &v->bsdf);
    v->shaded = true;
    v->diff_bsdf = opts->params && opts->params->mat_bsdf_active[hit->material];

    sampler->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(depth - 1);
    double u_pick = dr_sampler_next(sampler), u_l1 = dr_sampler_next(sampler), u_l2 = dr_sampler_next(sampler);
    double u_lobe = dr_sampler_next(sampler), u_b1 = dr_sampler_next(sampler), u_b2 = dr_sampler_next(sampler);
    double u_rr = dr_sampler_next(sampler);

    /* Next-event estimation. */
    if (!dr_light_sampler_empty(ls) && dr_light_sample(s, ls, hit->p, u_pick, u_l1, u_l2, &v->ls) &&
        dr_dot(v->ls.wi, ng) > 0.0) {
        v->nee_wi = dr_frame_to_local(&v->frame, v->ls.wi);
        double bsdf_pdf;
        v->nee_f = dr_bsdf_eval_pdf(&v->bsdf, v->wo, v->nee_wi, &bsdf_pdf);
        /* A zero BSDF contributes nothing, but its derivative may not be zero. */
        if (!dr_is_black(v->nee_f) || v->diff_bsdf) {
            /* The shadow ray joins the two offset end points: aiming it from
             * the lifted origin along the unlifted direction would reach a
             * grazing light's plane early and shadow itself. */
            dr_vec3 so = dr_offset_origin(hit, ng, v->ls.wi), sd = v->ls.wi;
            double tmax = INFINITY;
            if (!isinf(v->ls.dist)) {
                sd = dr_sub(v->ls.target, so);
                tmax = dr_length(sd);
                sd = dr_scale(sd, 1.0 / tmax);
            }
            counts->shadow++;
            if (tmax > 0.0 && !dr_accel_occluded(s->accel, so, sd, 0.0, tmax)) {
                double w = v->ls.delta ? 1.0 : dr_mis_power(v->ls.pdf, bsdf_pdf);
                v->nee_scale = fabs(v->nee_wi.z) * w / v->ls.pdf;
                v->nee = true;
            }
        }
    }

    /* Continue the path by sampling the BSDF. */
    struct dr_bsdf_sample bs;
    if (!dr_bsdf_sample(&v->bsdf, v->wo, u_lobe, u_b1, u_b2, &bs) || !(bs.pdf > 0.0))
        return false;
    dr_vec3 wi = dr_frame_to_world(&v->frame, bs.wi);
    if (dr_dot(wi, ng) <= 0.0)
        return false;   /* shading normal points where the geometry does not */
    v->wi = bs.wi;
    v->f = bs.f;
    v->s = bs.f;
    v->sub[0] = v->sub[1] = v->sub[2] = false;
    if (v->diff_bsdf) {
        double *sc = &v->s.x, *rc = &st->ratio.x;
        for (int c = 0; c < 3; c++)
            if (sc[c] == 0.0 && rc[c] != 0.0) {
                sc[c] = DR_PATH_SUBSTITUTE;
                v->sub[c] = true;
            }
    }
    double cos_pdf = fabs(bs.wi.z) / bs.pdf;
    dr_vec3 beta = dr_mul(st->beta, dr_scale(v->s, cos_pdf));
    if (dr_is_black(beta))
        return false;
    double q = 1.0;
    if (depth >= opts->rr_depth) {
        q = dr_min(dr_max3(beta), 0.95);
        if (u_rr >= q)
            return false;
    }
    v->cos_pdf_q = cos_pdf / q;
    v->cont = true;
    st->beta = dr_scale(beta, 1.0 / q);
    for (int c = 0; c < 3; c++)
        if (v->sub[c])
            (&st->ratio.x)[c] = 0.0;
    st->prev_pdf = bs.pdf;
    st->prev_p = hit->p;
    st->o = dr_offset_origin(hit, ng, wi);
    st->d = wi;
    return true;
}
