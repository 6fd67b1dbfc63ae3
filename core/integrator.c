#include "integrator.h"

#include "accel.h"
#include "bsdf.h"
#include "geometry.h"
#include "lights.h"
#include "material.h"

dr_vec3 dr_path_radiance(const struct dr_scene *s, const struct dr_trace_opts *opts, dr_vec3 o, dr_vec3 d,
                         struct dr_sampler *sampler, struct dr_ray_counts *counts)
{
    const struct dr_light_sampler *ls = s->light_sampler;
    const bool has_lights = !dr_light_sampler_empty(ls);
    const bool has_area = (s->effects & DR_FX_AREA_LIGHTS) != 0;
    dr_vec3 L = dr_v3s(0.0), beta = dr_v3s(1.0);
    double prev_pdf = 0.0;       /* BSDF density of the direction d (0 at the camera) */
    dr_vec3 prev_p = o;

    for (int depth = 1;; depth++) {
        int64_t tri = dr_accel_intersect(s->accel, o, d, 0.0, INFINITY);
        if (depth == 1)
            counts->camera++;
        else
            counts->extension++;

        if (tri < 0) {
            if (s->env.present) {
                double w = depth == 1 ? 1.0 : dr_mis_power(prev_pdf, dr_light_pdf_env(s, ls, d));
                L = dr_add(L, dr_scale(dr_mul(beta, dr_env_radiance(s, d)), w));
            }
            break;
        }
        struct dr_hit hit;
        dr_hit_compute(&s->mesh, tri, o, d, &hit);

        if (has_area && dr_light_pdf_area_pick(ls, tri) > 0.0) {
            dr_vec3 Le = dr_emission(s, &hit);
            if (!dr_is_black(Le)) {
                double w = depth == 1 ? 1.0 : dr_mis_power(prev_pdf, dr_light_pdf_area(s, ls, prev_p, &hit));
                L = dr_add(L, dr_scale(dr_mul(beta, Le), w));
            }
        }
        if (depth >= opts->max_depth)
            break;

        const struct dr_material *mat = &s->materials[hit.material];
        if (!hit.front && !mat->double_sided)
            break;   /* the back of a single-sided surface reflects nothing */
        /* Orient both normals towards the side the ray arrived from. */
        dr_vec3 ng = hit.front ? hit.ng : dr_neg(hit.ng);
        dr_vec3 ns = hit.front ? hit.ns : dr_neg(hit.ns);
        dr_frame frame = dr_frame_from_normal(ns);
        dr_vec3 wo = dr_frame_to_local(&frame, dr_neg(d));
        struct dr_bsdf bsdf;
        dr_material_eval(s, &hit, &bsdf);

        sampler->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(depth - 1);
        double u_pick = dr_sampler_next(sampler), u_l1 = dr_sampler_next(sampler), u_l2 = dr_sampler_next(sampler);
        double u_lobe = dr_sampler_next(sampler), u_b1 = dr_sampler_next(sampler), u_b2 = dr_sampler_next(sampler);
        double u_rr = dr_sampler_next(sampler);

        /* Next-event estimation. */
        struct dr_light_sample lsmp;
        if (has_lights && dr_light_sample(s, ls, hit.p, u_pick, u_l1, u_l2, &lsmp) && dr_dot(lsmp.wi, ng) > 0.0) {
            dr_vec3 wi = dr_frame_to_local(&frame, lsmp.wi);
            double bsdf_pdf;
            dr_vec3 f = dr_bsdf_eval_pdf(&bsdf, wo, wi, &bsdf_pdf);
            if (!dr_is_black(f)) {
                /* The shadow ray joins the two offset end points: aiming it
                 * from the lifted origin along the unlifted direction would
                 * reach a grazing light's plane early and shadow itself. */
                dr_vec3 so = dr_offset_origin(&hit, ng, lsmp.wi), sd = lsmp.wi;
                double tmax = INFINITY;
                if (!isinf(lsmp.dist)) {
                    sd = dr_sub(lsmp.target, so);
                    tmax = dr_length(sd);
                    sd = dr_scale(sd, 1.0 / tmax);
                }
                counts->shadow++;
                if (tmax > 0.0 && !dr_accel_occluded(s->accel, so, sd, 0.0, tmax)) {
                    double w = lsmp.delta ? 1.0 : dr_mis_power(lsmp.pdf, bsdf_pdf);
                    dr_vec3 c = dr_scale(dr_mul(f, lsmp.radiance), fabs(wi.z) * w / lsmp.pdf);
                    L = dr_add(L, dr_mul(beta, c));
                }
            }
        }

        /* Continue the path by sampling the BSDF. */
        struct dr_bsdf_sample bs;
        if (!dr_bsdf_sample(&bsdf, wo, u_lobe, u_b1, u_b2, &bs) || !(bs.pdf > 0.0))
            break;
        dr_vec3 wi = dr_frame_to_world(&frame, bs.wi);
        if (dr_dot(wi, ng) <= 0.0)
            break;   /* shading normal points where the geometry does not */
        beta = dr_mul(beta, dr_scale(bs.f, fabs(bs.wi.z) / bs.pdf));
        if (dr_is_black(beta))
            break;
        prev_pdf = bs.pdf;
        prev_p = hit.p;
        o = dr_offset_origin(&hit, ng, wi);
        d = wi;

        if (depth >= opts->rr_depth) {
            double q = dr_min(dr_max3(beta), 0.95);
            if (u_rr >= q)
                break;
            beta = dr_scale(beta, 1.0 / q);
        }
    }
    return L;
}
