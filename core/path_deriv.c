/* --sampling derivative at one vertex: see path_deriv.h for the estimator. */
#include "path_deriv.h"

#include "material.h"
#include "medium_grad.h"   /* dr_path_vertex_nee */

#define BM_PARAMS (DR_BSDF_D_BASE | DR_BSDF_D_METALLIC)
#define NDF_PARAMS (DR_BSDF_D_ROUGHNESS | DR_BSDF_D_COAT_ROUGHNESS)   /* A's: each with its antithetic pair */

bool dr_path_deriv_aniso_pair_ok(const struct dr_material *mat)
{
    return !mat->anisotropic || mat->anisotropy_strength <= DR_DERIV_MAX_STRENGTH;
}

unsigned dr_path_material_dparams(const struct dr_scene *s, const struct dr_param_set *ps, int m)
{
    if (!ps || m < 0 || m >= ps->n_materials || !ps->mat_bsdf_active[m])
        return 0;
    const struct dr_material *mat = &s->materials[m];
    unsigned mask = 0;
    int bt = mat->base_color_tex.texture, mt = mat->metallic_roughness_tex.texture;
    if (ps->mat_base_color[m] >= 0 || (bt >= 0 && ps->image[s->textures[bt].image] >= 0))
        mask |= DR_BSDF_D_BASE;
    if (ps->mat_metallic[m] >= 0)
        mask |= DR_BSDF_D_METALLIC;
    if (ps->mat_roughness[m] >= 0)
        mask |= DR_BSDF_D_ROUGHNESS;
    /* one image holds both metallic (B) and roughness (G): its texels move both */
    if (mt >= 0 && ps->image[s->textures[mt].image] >= 0)
        mask |= DR_BSDF_D_METALLIC | DR_BSDF_D_ROUGHNESS;
    /* an anisotropic base's roughness has the stretched lobe's pair (bsdf.c)
     * where the strength is mild (path_deriv.h); the anisotropy's strength
     * stays with the forward strategies, B */
    if (mat->anisotropic && !dr_path_deriv_aniso_pair_ok(mat))
        mask &= ~(unsigned)DR_BSDF_D_ROUGHNESS;
    /* a clear coat's roughness: its factor, or the texture whose G it reads
     * (the coat's factor is left to the forward strategies: B) */
    const struct dr_texref *ct = dr_material_coat_tex(mat, 1);
    if (mat->coated && (ps->mat_coat_roughness[m] >= 0 || (ct && ps->image[s->textures[ct->texture].image] >= 0)))
        mask |= DR_BSDF_D_COAT_ROUGHNESS;
    return mask;
}

/* The inputs v's BSDF has requested parameters for that the mode samples
 * directions for (opts->deriv_params): under derivative-roughness a base
 * colour or metallic is left out, so B's terms keep detached sampling's
 * strategies (vf = 1, W_l = the primal's weight, no third direction). */
static unsigned vertex_dparams(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v)
{
    return dr_path_material_dparams(s, opts->params, v->hit.material) & opts->deriv_params;
}

/* p_bm at local wi: the base colour / metallic mixture (0: neither requested). */
static double bm_pdf(const struct dr_path_vertex *v, unsigned mask, dr_vec3 wi)
{
    return (mask & BM_PARAMS) ? dr_bsdf_deriv_pdf(&v->bsdf, v->wo, wi, mask & BM_PARAMS) : 0.0;
}

/* The light sampler's solid-angle density of the emission seen at w, from
 * w->prev_p (0 where next-event estimation does not run or cannot reach it):
 * the density the primal's emission MIS weight used (path.c). */
static double emitter_light_pdf(const struct dr_scene *s, const struct dr_path_opts *opts,
                                const struct dr_path_vertex *w)
{
    if (!(opts->stages & DR_STAGE_NEE) || !w->emits)
        return 0.0;
    if (w->kind == DR_VERTEX_ESCAPED)
        return dr_light_pdf_env(s, s->light_sampler, w->d, w->prev_sky);
    return dr_light_pdf_area(s, s->light_sampler, w->prev_p, &w->hit);
}

/* ------------------------------------------------ the two derivative parts */

/* A + B along local wi, for d_f = d loss / d f. d_path_continuation
 * differentiates f along v->wi: a copy of the vertex pointing at wi reuses it
 * (and its per-channel split in forward mode) rather than duplicating the
 * material adjoint's plumbing. */
static void d_full_along(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 wi, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    struct dr_path_vertex at = *v;
    at.wi = wi;
    d_path_continuation(s, ps, &at, d_f, sink);
}

/* A's parts (NDF_PARAMS bits) alone along wi; forward mode keeps the image
 * channels apart as path.c's by_channel does. */
static void d_ndf_along(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                        unsigned parts, dr_vec3 wi, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    for (int c = 0; c < 3; c++) {
        dr_vec3 part = sink->dir ? dr_v3_channel(d_f, c) : d_f;
        if (dr_is_black(part))
            continue;
        sink->channel = c;
        struct dr_d_bsdf db = {0};
        d_bsdf_eval_rough_ndf(&v->bsdf, v->wo, wi, part, parts, &db);
        d_material_eval(s, ps, &v->hit, &db, sink);
        if (!sink->dir)
            return;   /* reverse mode: all channels at once */
    }
}

/* B = (A + B) - A along wi (A is 0 unless a roughness is requested). */
static void d_rest_along(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         unsigned mask, dr_vec3 wi, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    d_full_along(s, ps, v, wi, d_f, sink);
    if (mask & NDF_PARAMS)
        d_ndf_along(s, ps, v, mask & NDF_PARAMS, wi, dr_neg(d_f), sink);
}

/* The antithetic pair of A's part `part` (a NDF_PARAMS bit): its two lobes. */
static void pair_lobes(unsigned part, enum dr_bsdf_dlobe lobe[2])
{
    const bool coat = part == DR_BSDF_D_COAT_ROUGHNESS;
    lobe[0] = coat ? DR_BSDF_DLOBE_COAT_POS : DR_BSDF_DLOBE_ROUGH_POS;
    lobe[1] = coat ? DR_BSDF_DLOBE_COAT_NEG : DR_BSDF_DLOBE_ROUGH_NEG;
}

/* ------------------------------------------- the forward path's strategies */

void d_path_deriv_continuation(const struct dr_scene *s, const struct dr_path_opts *opts,
                               const struct dr_path_vertex *v, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    unsigned mask = vertex_dparams(s, opts, v);
    double vf = v->pdf / (v->pdf + bm_pdf(v, mask, v->wi));
    d_rest_along(s, opts->params, v, mask, v->wi, dr_scale(d_f, vf), sink);
}

void d_path_deriv_nee(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                      dr_vec3 d_e, struct dr_grad_sink *sink)
{
    if (!v->nee || !v->diff_bsdf)
        return;
    unsigned mask = vertex_dparams(s, opts, v);
    double pl = v->ls.pdf, pf = dr_bsdf_pdf(&v->bsdf, v->wo, v->nee_wi);
    double wp = v->ls.delta ? 1.0 : dr_mis_power(pl, pf);   /* the primal's weight (path.c) */
    /* a delta light: only next-event estimation reaches it, weight 1 */
    double wl = v->ls.delta || !(mask & BM_PARAMS) ? wp : pl / (pl + pf + bm_pdf(v, mask, v->nee_wi));
    dr_vec3 d_f = dr_scale(dr_mul(d_e, v->ls.radiance), fabs(v->nee_wi.z) / pl);
    if (wl != wp && isfinite(wl - wp))
        d_rest_along(s, opts->params, v, mask, v->nee_wi, dr_scale(d_f, wl - wp), sink);
    for (unsigned part = DR_BSDF_D_ROUGHNESS; part <= DR_BSDF_D_COAT_ROUGHNESS; part <<= 1) {
        if (!(mask & part))   /* A's part: weight W_l against its antithetic pair's lobes */
            continue;
        enum dr_bsdf_dlobe lobe[2];
        pair_lobes(part, lobe);
        double pa = dr_bsdf_deriv_lobe_pdf(&v->bsdf, v->wo, v->nee_wi, lobe[0]) +
                    dr_bsdf_deriv_lobe_pdf(&v->bsdf, v->wo, v->nee_wi, lobe[1]);
        double wa = v->ls.delta ? 1.0 : pl / (pl + pa);
        if (wa != wp && isfinite(wa - wp))
            d_ndf_along(s, opts->params, v, part, v->nee_wi, dr_scale(d_f, wa - wp), sink);
    }
}

void d_path_deriv_emission(const struct dr_scene *s, const struct dr_path_opts *opts,
                           const struct dr_path_vertex *prev, dr_vec3 d_t, const struct dr_path_vertex *next,
                           struct dr_grad_sink *sink)
{
    unsigned mask = vertex_dparams(s, opts, prev);
    if (!(mask & BM_PARAMS) || !next->emits || dr_is_black(next->Le))
        return;
    double pf = prev->pdf, pd = bm_pdf(prev, mask, prev->wi), pl = emitter_light_pdf(s, opts, next);
    double dw = pf / (pl + pf + pd) - pf / (pf + pd) * next->emit_w;   /* W_f - V_f * primal weight */
    if (dw == 0.0 || !isfinite(dw))
        return;
    d_rest_along(s, opts->params, prev, mask, prev->wi, dr_scale(dr_mul(d_t, next->Le), dw), sink);
}

/* ------------------------------------------------------ the new directions */

/* Sub-streams of the new directions at depth `depth` (the media walker's
 * tracking streams use the same construction with other constants). */
enum { STREAM_DIRS = 1, STREAM_BM_PATH = 2, STREAM_PAIR_PATH = 3, STREAM_COAT_PAIR_PATH = 4 };
static struct dr_sampler deriv_stream(const struct dr_sampler *smp, int depth, uint64_t which)
{
    uint64_t k = smp->key ^ 0x8f1bbcdcca62c1d6ULL ^ ((uint64_t)depth * 0x9e3779b97f4a7c15ULL);
    struct dr_sampler r = {.key = dr_hash64(k ^ (which * 0x632be59bd9b4e019ULL)), .dim = 0,
                           .kind = DR_SAMPLER_INDEPENDENT};
    return r;
}

/* (path_deriv.h) The state the forward continuation would have handed on
 * had it sampled the ray's direction: same depth, prev_pdf = the forward
 * density pf (so the MIS weights beyond are the primal's), unit throughput. */
void dr_path_deriv_start(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_deriv_ray *r,
                         struct dr_path_state *st)
{
    dr_path_start(st, r->o, r->d);
    st->prev_pdf = r->pf;
    st->prev_sky = r->prev_sky;
    st->prev_p = r->prev_p;
    st->depth = r->depth;
    if (opts->stages & DR_STAGE_MEDIA) {
        dr_medium_path_resume(s, st, &r->rng);   /* (hero channel, spectral weights) */
        st->medium = r->medium;
    }
}

/* (path_deriv.h) */
void dr_path_deriv_first(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *w,
                         struct dr_deriv_light *out)
{
    out->E = w->emits ? w->Le : dr_v3s(0.0);
    out->pl = w->emits ? emitter_light_pdf(s, opts, w) : 0.0;
    out->L_ind = dr_path_vertex_nee(w);
}

/* (path_deriv.h) One path at a time: the walker with the primal's options
 * but no parameters (nothing to differentiate along it: no zero-channel
 * substitution). */
void dr_path_deriv_radiance(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_deriv_ray *r,
                            struct dr_deriv_light *out, struct dr_ray_counts *counts)
{
    struct dr_path_opts o = *opts;
    o.params = NULL;
    struct dr_path_state st;
    struct dr_path_vertex w;
    struct dr_sampler rng = r->rng;
    dr_path_deriv_start(s, opts, r, &st);
    for (bool first = true;; first = false) {
        dr_vec3 beta = st.beta;
        bool more = dr_path_step(s, &o, &st, &rng, &w, counts);
        if (first)
            dr_path_deriv_first(s, opts, &w, out);
        else
            out->L_ind = dr_add(out->L_ind, dr_mul(beta, dr_path_vertex_term(&w)));
        if (!more)
            return;
    }
}

/* World direction of local wi, or false where the forward sampler would
 * reject it too (below the geometric surface: the integrand is 0 there). */
static bool usable(const struct dr_path_vertex *v, dr_vec3 wi, dr_vec3 *wiw)
{
    *wiw = dr_frame_to_world(&v->frame, wi);
    return wi.z > 0.0 && dr_dot(*wiw, v->ng) > 0.0;
}

/* Ray r leaving v along local wi (world wiw) from stream `which`. */
static struct dr_deriv_ray deriv_ray(const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                                     const struct dr_sampler *smp, uint64_t which, int kind, dr_vec3 wi, dr_vec3 wiw,
                                     double pd)
{
    double pf = dr_bsdf_pdf(&v->bsdf, v->wo, wi);
    return (struct dr_deriv_ray){.wi = wi, .o = dr_offset_origin(&v->hit, v->ng, wiw), .d = wiw, .prev_p = v->hit.p,
                                 .pf = pf, .pd = pd, .prev_sky = dr_path_leaving_sky(opts, v, dr_dot(wiw, v->ng), pf),
                                 .rng = deriv_stream(smp, v->depth, which), .depth = v->depth, .kind = kind,
                                 .medium = v->medium};
}

int dr_path_deriv_max_rays(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    unsigned all = 0;
    for (int m = 0; opts->params && m < s->n_materials; m++)
        all |= dr_path_material_dparams(s, opts->params, m) & opts->deriv_params;
    return ((all & BM_PARAMS) ? 1 : 0) + ((all & DR_BSDF_D_ROUGHNESS) ? 2 : 0) +
           ((all & DR_BSDF_D_COAT_ROUGHNESS) ? 2 : 0);
}

/* (path_deriv.h) B's direction from p_bm, then A's antithetic pairs (the
 * base's roughness, then the coat's): the same (u1, u2) within a pair,
 * mirrored for the negative lobe so both start at the sign change, and the
 * same random numbers for both paths. The random numbers are drawn whether
 * or not a direction is usable. */
int dr_path_deriv_rays(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                       const struct dr_sampler *smp, struct dr_deriv_ray r[DR_DERIV_RAYS])
{
    unsigned mask = vertex_dparams(s, opts, v);
    if (!mask || !(v->wo.z > 0.0))
        return 0;
    struct dr_sampler dirs = deriv_stream(smp, v->depth, STREAM_DIRS);
    int n = 0;
    if (mask & BM_PARAMS) {
        double ul = dr_sampler_next(&dirs), u1, u2, pd;
        dr_sampler_next2(&dirs, &u1, &u2);
        dr_vec3 wi, wiw;
        if (dr_bsdf_deriv_sample(&v->bsdf, v->wo, mask & BM_PARAMS, ul, u1, u2, &wi, &pd) && usable(v, wi, &wiw))
            r[n++] = deriv_ray(opts, v, smp, STREAM_BM_PATH, DR_DERIV_BM, wi, wiw, pd);
    }
    for (unsigned part = DR_BSDF_D_ROUGHNESS; part <= DR_BSDF_D_COAT_ROUGHNESS; part <<= 1) {
        if (!(mask & part))
            continue;
        const bool coat = part == DR_BSDF_D_COAT_ROUGHNESS;
        enum dr_bsdf_dlobe lobe[2];
        pair_lobes(part, lobe);
        double u1, u2;
        dr_sampler_next2(&dirs, &u1, &u2);
        for (int side = 0; side < 2; side++) {
            dr_vec3 wi = dr_bsdf_deriv_sample_dir(&v->bsdf, v->wo, lobe[side], side == 0 ? u1 : 1.0 - u1, u2), wiw;
            double p = dr_bsdf_deriv_lobe_pdf(&v->bsdf, v->wo, wi, lobe[side]);
            const int kind = coat ? (side == 0 ? DR_DERIV_COAT_POS : DR_DERIV_COAT_NEG)
                                  : (side == 0 ? DR_DERIV_POS : DR_DERIV_NEG);
            if (p > 0.0 && usable(v, wi, &wiw))
                r[n++] = deriv_ray(opts, v, smp, coat ? STREAM_COAT_PAIR_PATH : STREAM_PAIR_PATH, kind, wi, wiw, p);
        }
    }
    return n;
}

/* (path_deriv.h) B's term: MIS-weighted against light and forward
 * sampling; A's parts: E weighted against next-event estimation (only one
 * lobe of a pair is non-zero at wi), each part by its own pair. */
void d_path_deriv_rays(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                       const struct dr_deriv_ray *r, const struct dr_deriv_light *light, int n, dr_vec3 d_beta,
                       struct dr_grad_sink *sink)
{
    unsigned mask = vertex_dparams(s, opts, v);
    for (int i = 0; i < n; i++) {
        const dr_vec3 E = light[i].E, L_ind = light[i].L_ind;
        const double pl = light[i].pl, pf = r[i].pf, p = r[i].pd, cos = fabs(r[i].wi.z);
        if (r[i].kind == DR_DERIV_BM) {
            dr_vec3 L = dr_add(dr_scale(E, 1.0 / (pl + pf + p)), dr_scale(L_ind, 1.0 / (pf + p)));
            if (dr_v3_finite(L) && !dr_is_black(L))
                d_rest_along(s, opts->params, v, mask, r[i].wi, dr_scale(dr_mul(d_beta, L), cos), sink);
        } else {
            const bool coat = r[i].kind == DR_DERIV_COAT_POS || r[i].kind == DR_DERIV_COAT_NEG;
            dr_vec3 L = dr_scale(dr_add(dr_scale(E, p / (pl + p)), L_ind), cos / p);
            if (dr_v3_finite(L) && !dr_is_black(L))
                d_ndf_along(s, opts->params, v, coat ? DR_BSDF_D_COAT_ROUGHNESS : DR_BSDF_D_ROUGHNESS, r[i].wi,
                            dr_mul(d_beta, L), sink);
        }
    }
}

void d_path_deriv_sample(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                         const struct dr_sampler *smp, dr_vec3 d_beta, struct dr_grad_sink *sink,
                         struct dr_ray_counts *counts)
{
    if (dr_is_black(d_beta))
        return;
    struct dr_deriv_ray r[DR_DERIV_RAYS];
    struct dr_deriv_light light[DR_DERIV_RAYS];
    int n = dr_path_deriv_rays(s, opts, v, smp, r);
    for (int i = 0; i < n; i++)
        dr_path_deriv_radiance(s, opts, &r[i], &light[i], counts);
    d_path_deriv_rays(s, opts, v, r, light, n, d_beta, sink);
}
