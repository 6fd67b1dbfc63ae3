/* The staged path walker (path.h) and the adjoints of a vertex's terms. */
#include "path.h"

#include <stdio.h>
#include <string.h>

#include "accel.h"
#include "anisotropy.h"
#include "coverage.h"
#include "material.h"
#include "normal_map.h"

struct dr_path_state;
/* The stages are exported to the medium walker too (end of file), yet kept inlined into
 * dr_path_step: a scene without media must not pay a call for that. */
static inline bool stage_material(const struct dr_scene *s, const struct dr_path_opts *opts,
                                  const struct dr_path_state *st, struct dr_sampler *sampler,
                                  struct dr_path_vertex *v) __attribute__((always_inline));
static inline void stage_escaped(const struct dr_scene *s, const struct dr_path_opts *opts,
                                 const struct dr_path_state *st, struct dr_path_vertex *v)
    __attribute__((always_inline));
static inline bool stage_continue(const struct dr_path_opts *opts, struct dr_path_state *st,
                                  struct dr_path_vertex *v) __attribute__((always_inline));

/* ------------------------------------------------------------------ plan */

unsigned dr_path_plan(const struct dr_scene *s, const struct dr_param_set *ps)
{
    unsigned st = 0;
    if (s->env.present)
        st |= DR_STAGE_ENV;
    bool emission_differentiated = false;
    for (int m = 0; ps && m < ps->n_materials; m++)
        emission_differentiated |= ps->mat_emission_active[m];
    if ((s->effects & DR_FX_AREA_LIGHTS) || emission_differentiated)
        st |= DR_STAGE_EMISSION;
    if (!dr_light_sampler_empty(s->light_sampler))
        st |= DR_STAGE_NEE;
    if (s->n_media > 0)
        st |= DR_STAGE_MEDIA;
    if (s->effects & DR_FX_DIELECTRIC_BOUNDARIES)
        st |= DR_STAGE_DIELECTRIC;
    return st;
}

void dr_path_stages_describe(unsigned stages, char *buf, int size)
{
    static const struct { unsigned bit; const char *name; } names[] = {
        {DR_STAGE_ENV, "environment_lookup"},
        {DR_STAGE_EMISSION, "surface_emission"},
        {DR_STAGE_NEE, "next_event_estimation"},
        {DR_STAGE_MEDIA, "participating_media"},
        {DR_STAGE_DIELECTRIC, "dielectric_boundaries"},
    };
    int n = 0;
    buf[0] = '\0';
    for (size_t i = 0; i < sizeof names / sizeof names[0] && n < size; i++)
        if (stages & names[i].bit)
            n += snprintf(buf + n, (size_t)(size - n), "%s%s", n ? "," : "", names[i].name);
}

/* ------------------------------------------------------------------- MIS */

/* dr_mis_power computes w = 1 / (1 + r^2), r = pb / pa. With t = r / (1 + r^2)
 * (so t^2 = w (1 - w)) and w = 1 / (1 + r^2):
 *   dw/dpa = 2 w (1 - w) / pa = 2 t^2 / pa,   dw/dpb = -2 w (1 - w) / pb = -2 t w / pa,
 * i.e. 2 pa pb^2 / (pa^2 + pb^2)^2 and its mirror, without forming 1 - w (it
 * cancels for w near 1) and without squaring a huge ratio (t is formed as
 * 1 / (r + 1/r) for r > 1). The primal's branches pa <= 0 (w = 0) and
 * pb <= 0 (w = 1) are w's limits and its derivative vanishes towards them:
 * zero there. */
void d_mis_power(double pdf_a, double pdf_b, double d_w, double *d_pa, double *d_pb)
{
    if (!(pdf_a > 0.0) || !(pdf_b > 0.0))
        return;
    double r = pdf_b / pdf_a;
    if (!isfinite(r))
        return;
    double t, w;
    if (r > 1.0) {
        t = 1.0 / (r + 1.0 / r);
        w = t / r;
    } else {
        w = 1.0 / (1.0 + r * r);
        t = r * w;
    }
    double k = 2.0 * d_w * t / pdf_a;
    if (d_pa)
        *d_pa += k * t;
    if (d_pb)
        *d_pb -= k * w;
}

/* ---------------------------------------------------------------- stages */

void dr_path_start(struct dr_path_state *st, dr_vec3 o, dr_vec3 d)
{
    *st = (struct dr_path_state){.o = o, .d = d, .prev_pdf = 0.0, .prev_sky = DR_SKY_SPHERE, .prev_p = o, .depth = 0,
                                 .beta = dr_v3s(1.0), .ratio = dr_v3s(1.0)};
}

uint64_t dr_path_trace_key(const struct dr_scene *s, const struct dr_path_state *st, const struct dr_sampler *sampler)
{
    return (s->effects & DR_FX_KEYED_TRACES) ? dr_coverage_key(sampler->key, st->depth, DR_RAY_TRACE) : 0;
}

void dr_path_count_trace(const struct dr_path_state *st, struct dr_ray_counts *counts)
{
    if (st->depth == 1)
        counts->camera++;
    else
        counts->extension++;
}

/* Stage trace: the closest triangle along the current ray (-1: none). BLEND
 * surfaces decide by the path's key at this depth (coverage.h). */
static int64_t stage_trace(const struct dr_scene *s, const struct dr_path_state *st, const struct dr_sampler *sampler,
                           struct dr_ray_counts *counts)
{
    dr_path_count_trace(st, counts);
    return dr_accel_intersect_key(s->accel, st->o, st->d, 0.0, INFINITY, dr_path_trace_key(s, st, sampler));
}

/* Stage escaped: environment radiance seen along the ray, MIS-weighted
 * against next-event estimation of the environment. */
static void stage_escaped(const struct dr_scene *s, const struct dr_path_opts *opts,
                          const struct dr_path_state *st, struct dr_path_vertex *v)
{
    v->kind = DR_VERTEX_ESCAPED;
    if (!(opts->stages & DR_STAGE_ENV))
        return;
    v->emits = true;
    v->Le = dr_path_escaped_radiance(s, st->depth, st->prev_pdf, st->prev_sky, st->d, &v->emit_w);
}

dr_vec3 dr_path_escaped_radiance(const struct dr_scene *s, int depth, double prev_pdf, double prev_sky, dr_vec3 d,
                                 double *emit_w)
{
    double pdf;
    dr_vec3 Le = dr_env_radiance_pdf(s, s->light_sampler, d, prev_sky, depth == 1 ? NULL : &pdf);
    *emit_w = depth == 1 ? 1.0 : dr_mis_power(prev_pdf, pdf);
    return Le;
}

static bool surface_emits(const struct dr_scene *s, const struct dr_path_opts *o, int64_t tri, int mat)
{
    if (dr_light_pdf_area_pick(s->light_sampler, tri) > 0.0)
        return true;
    /* a dark emitter whose emission is being differentiated still counts */
    return o->params && o->params->mat_emission_active[mat];
}

/* The hit point (recomputed in double: Embree only says which triangle). */
static inline void stage_locate(const struct dr_scene *s, const struct dr_path_state *st, int64_t tri,
                                struct dr_path_vertex *v)
{
    v->kind = DR_VERTEX_SURFACE;
    dr_hit_compute(&s->mesh, tri, st->o, st->d, &v->hit);
}

/* Stage emission, after stage_locate: the shading normal and the radiance the
 * hit emits towards the ray, MIS-weighted against next-event estimation of
 * that triangle. */
static inline void stage_emission(const struct dr_scene *s, const struct dr_path_opts *opts,
                                  const struct dr_path_state *st, int64_t tri, struct dr_path_vertex *v)
{
    struct dr_hit *hit = &v->hit;
    if (s->effects & DR_FX_NORMAL_MAPS)
        dr_normal_map_apply(s, hit);
    if (!(opts->stages & DR_STAGE_EMISSION) || !surface_emits(s, opts, tri, hit->material))
        return;
    v->emits = true;
    v->Le = dr_emission(s, hit);
    v->emit_w = st->depth == 1 ? 1.0 : dr_mis_power(st->prev_pdf, dr_light_pdf_area(s, s->light_sampler, st->prev_p, hit));
}

/* Stage material: the shading frame oriented towards the arriving ray, the
 * BSDF inputs, and the vertex's block of random numbers. False when the
 * surface reflects nothing (last segment, or the back of a single-sided one). */
static bool stage_material(const struct dr_scene *s, const struct dr_path_opts *opts,
                           const struct dr_path_state *st, struct dr_sampler *sampler, struct dr_path_vertex *v)
{
    const struct dr_hit *hit = &v->hit;
    if (st->depth >= opts->max_depth)
        return false;
    if (!hit->front && !s->materials[hit->material].double_sided)
        return false;
    v->ng = hit->front ? hit->ng : dr_neg(hit->ng);
    dr_vec3 n = hit->front ? hit->ns : dr_neg(hit->ns);
    if (s->materials[hit->material].normal_tex.texture >= 0)   /* a mapped normal may face away from wo */
        n = dr_shading_normal_valid(v->ng, dr_neg(st->d), n);
    dr_material_eval(s, hit, &v->bsdf);
    /* an anisotropic lobe stretches along the frame's first axis, and is
     * isotropic where the surface gives no direction (anisotropy.h) */
    if (!s->materials[hit->material].anisotropic)
        v->frame = dr_frame_from_normal(n);
    else if (!dr_anisotropy_frame(s, hit, n, &v->frame))
        v->bsdf.anisotropy = 0.0;
    v->wo = dr_frame_to_local(&v->frame, dr_neg(st->d));
    v->shaded = true;
    v->diff_bsdf = opts->params && opts->params->mat_bsdf_active[hit->material];

    sampler->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(st->depth - 1);
    struct dr_vertex_randoms *u = &v->u;
    u->light_pick = dr_sampler_next(sampler);
    dr_sampler_next2(sampler, &u->light_u1, &u->light_u2);   /* a 2D point on the light */
    u->lobe = dr_sampler_next(sampler);
    dr_sampler_next2(sampler, &u->bsdf_u1, &u->bsdf_u2);     /* a 2D direction sample */
    u->rr = dr_sampler_next(sampler);
    u->cover_key = (s->effects & DR_FX_KEYED_SHADOWS) ? dr_coverage_key(sampler->key, st->depth, DR_RAY_SHADOW) : 0;
    return true;
}

bool dr_path_nee_begin(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_vertex *v,
                       struct dr_shadow_ray *ray)
{
    const struct dr_hit *hit = &v->hit;
    const struct dr_vertex_randoms *u = &v->u;
    struct dr_sky_bsdf sky;
    const bool carries = dr_light_sample(s, s->light_sampler, hit->p, dr_path_sky_bsdf(opts, v, &sky), u->light_pick,
                                         u->light_u1, u->light_u2, &v->ls);
    if (!dr_path_light_kept(s, opts->params, carries, &v->ls) || dr_dot(v->ls.wi, v->ng) <= 0.0)
        return false;
    v->nee_wi = dr_frame_to_local(&v->frame, v->ls.wi);
    v->nee_f = dr_bsdf_eval_pdf(&v->bsdf, v->wo, v->nee_wi, &v->nee_bsdf_pdf);
    /* A zero BSDF contributes nothing, but its derivative may not be zero. */
    if (dr_is_black(v->nee_f) && !v->diff_bsdf)
        return false;
    /* The shadow ray joins the two offset end points: aiming it from the
     * lifted origin along the unlifted direction would reach a grazing
     * light's plane early and shadow itself. */
    dr_vec3 so = dr_offset_origin(hit, v->ng, v->ls.wi), sd = v->ls.wi;
    double tmax = INFINITY;
    if (!isinf(v->ls.dist)) {
        sd = dr_sub(v->ls.target, so);
        tmax = dr_length(sd);
        sd = dr_scale(sd, 1.0 / tmax);
    }
    *ray = (struct dr_shadow_ray){.o = so, .d = sd, .tmax = tmax, .key = u->cover_key};
    return true;
}

void dr_path_nee_end(const struct dr_scene *s, struct dr_path_vertex *v, const struct dr_shadow_ray *ray,
                     bool occluded)
{
    if (!(ray->tmax > 0.0) || occluded)
        return;
    if ((s->effects & (DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND)) && v->ls.type == DR_LS_AREA &&
        !dr_coverage_point_present(s, v->ls.index, v->ls.b1, v->ls.b2, ray->key))
        return;   /* the light point is a hole in a cut-out emitter */
    double w = v->ls.delta ? 1.0 : dr_mis_power(v->ls.pdf, v->nee_bsdf_pdf);
    v->nee_scale = fabs(v->nee_wi.z) * w / v->ls.pdf;
    v->nee = true;
}

/* The shadow ray of dr_path_nee_begin, one at a time, and the estimate's end. */
static void nee_trace_one(const struct dr_scene *s, struct dr_path_vertex *v, const struct dr_shadow_ray *ray,
                          struct dr_ray_counts *counts)
{
    counts->shadow++;
    bool occluded = ray->tmax > 0.0 && dr_accel_occluded_key(s->accel, ray->o, ray->d, 0.0, ray->tmax, ray->key);
    dr_path_nee_end(s, v, ray, occluded);
}

void dr_path_nee(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_vertex *v,
                 struct dr_ray_counts *counts)
{
    struct dr_shadow_ray ray;
    if (dr_path_nee_begin(s, opts, v, &ray))
        nee_trace_one(s, v, &ray, counts);
}

/* At a differentiated vertex, channels whose BSDF value is exactly 0 are
 * traced on with the substitute factor (path.h), once per channel. */
static void substitute_zero_channels(const struct dr_path_state *st, struct dr_path_vertex *v)
{
    v->s = v->f;
    v->sub[0] = v->sub[1] = v->sub[2] = false;
    if (!v->diff_bsdf)
        return;
    for (int c = 0; c < 3; c++)
        if (dr_v3_get(v->s, c) == 0.0 && dr_v3_get(st->ratio, c) != 0.0) {
            dr_v3_set(&v->s, c, DR_PATH_SUBSTITUTE);
            v->sub[c] = true;
        }
}

/* Stage continue: BSDF sample, Russian roulette, the next ray. False when
 * the path ends here. */
static bool stage_continue(const struct dr_path_opts *opts, struct dr_path_state *st, struct dr_path_vertex *v)
{
    const struct dr_vertex_randoms *u = &v->u;
    struct dr_bsdf_sample bs;
    if (!dr_bsdf_sample(&v->bsdf, v->wo, u->lobe, u->bsdf_u1, u->bsdf_u2, &bs) || !(bs.pdf > 0.0))
        return false;
    dr_vec3 wi = dr_frame_to_world(&v->frame, bs.wi);
    if (dr_dot(wi, v->ng) <= 0.0)
        return false;   /* shading normal points where the geometry does not */
    v->wi = bs.wi;
    v->f = bs.f;
    v->pdf = bs.pdf;
    v->lobe = bs.lobe;
    substitute_zero_channels(st, v);
    double cos_pdf = fabs(bs.wi.z) / bs.pdf;
    dr_vec3 beta = dr_mul(st->beta, dr_scale(v->s, cos_pdf));
    if (dr_is_black(beta))
        return false;
    double q = 1.0;
    if (st->depth >= opts->rr_depth) {
        q = dr_min(dr_max3(beta), 0.95);
        if (u->rr >= q)
            return false;
    }
    v->cos_pdf_q = cos_pdf / q;
    v->cont = true;
    st->beta = dr_scale(beta, 1.0 / q);
    for (int c = 0; c < 3; c++)
        if (v->sub[c])
            dr_v3_set(&st->ratio, c, 0.0);
    st->prev_pdf = bs.pdf;
    st->prev_sky = dr_path_leaving_sky(opts, v, dr_dot(wi, v->ng), bs.pdf);
    st->prev_p = v->hit.p;
    st->o = dr_offset_origin(&v->hit, v->ng, wi);
    st->d = wi;
    return true;
}

void dr_path_step_begin(struct dr_path_state *st, struct dr_path_vertex *v)
{
    v->depth = ++st->depth;
    v->d = st->d;
    v->o = st->o;
    v->prev_pdf = st->prev_pdf;
    v->prev_sky = st->prev_sky;
    v->prev_p = st->prev_p;
    v->emits = v->shaded = v->nee = v->cont = v->diff_bsdf = v->media = false;
    v->env_at.valid = false;
}

void dr_path_step_locate(const struct dr_scene *s, const struct dr_path_state *st, struct dr_path_vertex *v,
                         int64_t tri)
{
    if (tri >= 0)
        stage_locate(s, st, tri, v);
}

/* dr_path_step_shade's body, inlined into dr_path_step_hit as well. */
static inline __attribute__((always_inline)) enum dr_step_next
step_shade(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_state *st,
           struct dr_sampler *sampler, struct dr_path_vertex *v, int64_t tri, struct dr_shadow_ray *shadow)
{
    if (tri < 0) {
        stage_escaped(s, opts, st, v);
        return DR_STEP_END;
    }
    stage_emission(s, opts, st, tri, v);
    if (!stage_material(s, opts, st, sampler, v))
        return DR_STEP_END;
    if ((opts->stages & DR_STAGE_NEE) && dr_path_nee_begin(s, opts, v, shadow))
        return DR_STEP_SHADOW;
    return DR_STEP_CONTINUE;
}

enum dr_step_next dr_path_step_hit(const struct dr_scene *s, const struct dr_path_opts *opts,
                                   const struct dr_path_state *st, struct dr_sampler *sampler,
                                   struct dr_path_vertex *v, int64_t tri, struct dr_shadow_ray *shadow)
{
    if (tri >= 0)
        stage_locate(s, st, tri, v);
    return step_shade(s, opts, st, sampler, v, tri, shadow);
}

enum dr_step_next dr_path_step_shade(const struct dr_scene *s, const struct dr_path_opts *opts,
                                     const struct dr_path_state *st, struct dr_sampler *sampler,
                                     struct dr_path_vertex *v, int64_t tri, struct dr_shadow_ray *shadow)
{
    return step_shade(s, opts, st, sampler, v, tri, shadow);
}

bool dr_path_step(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                  struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts)
{
    if (opts->stages & DR_STAGE_MEDIA)
        return dr_medium_path_step(s, opts, st, sampler, v, counts);
    dr_path_step_begin(st, v);
    int64_t tri = stage_trace(s, st, sampler, counts);
    struct dr_shadow_ray shadow;
    switch (dr_path_step_hit(s, opts, st, sampler, v, tri, &shadow)) {
    case DR_STEP_END:
        return false;
    case DR_STEP_SHADOW:
        nee_trace_one(s, v, &shadow, counts);
        break;
    case DR_STEP_CONTINUE:
        break;
    }
    return stage_continue(opts, st, v);
}

dr_vec3 dr_path_radiance(const struct dr_scene *s, const struct dr_path_opts *opts, dr_vec3 o, dr_vec3 d,
                         struct dr_sampler *sampler, struct dr_ray_counts *counts)
{
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, o, d);
    dr_vec3 L = dr_v3s(0.0);
    for (;;) {
        dr_vec3 beta = st.beta;
        bool more = dr_path_step(s, opts, &st, sampler, &v, counts);
        L = dr_add(L, dr_mul(beta, dr_path_vertex_term(&v)));
        if (!more)
            return L;
    }
}

/* -------------------------------------------------------------- adjoints */

bool dr_path_vertex_has_derivative(const struct dr_scene *s, const struct dr_param_set *ps,
                                   const struct dr_path_vertex *v)
{
    return v->media || dr_path_vertex_has_surface_derivative(s, ps, v);
}

bool dr_path_vertex_has_surface_derivative(const struct dr_scene *s, const struct dr_param_set *ps,
                                           const struct dr_path_vertex *v)
{
    if (v->diff_bsdf)
        return true;
    if (!ps->radiance_active)   /* (then nothing else of v is read: the eight-lane stages rely on it) */
        return false;
    /* the conditions under which d_emission, d_env_radiance and d_light_radiance work */
    if (v->emits && (v->kind == DR_VERTEX_SURFACE ? ps->mat_emission_active[v->hit.material] : ps->env_active))
        return true;
    if (!v->nee)
        return false;
    return dr_path_light_differentiated(ps, v->ls.type, v->ls.type == DR_LS_AREA ? s->mesh.material[v->ls.index] : -1);
}

/* The vertex's adjoints for one image channel (forward mode) or all
 * (reverse mode): d_e of its term e_k, d_f of its continuation's f (black:
 * none). Its two BSDF values, towards the light and along the
 * continuation, are of one material at one hit: their adjoints are summed
 * before the material's (d_material_eval is linear in them), which then
 * reads the hit's textures once instead of twice: a texture gradient's
 * texel adjoints took 8 % of its time twice over. */
static void emission_part(const struct dr_scene *s, const struct dr_param_set *ps, enum dr_vertex_kind kind,
                          const struct dr_hit *hit, const struct dr_env_lookup *env_at, dr_vec3 d, dr_vec3 d_Le,
                          struct dr_grad_sink *sink);

static void vertex_part(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                        dr_vec3 d_e, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    struct dr_d_bsdf db = {0};
    bool bsdf = false;
    if (!dr_is_black(d_e)) {
        if (v->emits) {
            dr_vec3 d_Le = dr_scale(d_e, v->emit_w);
            if (v->media)
                d_Le = dr_mul(d_Le, v->seg);   /* folded into Le by the medium walker */
            emission_part(s, ps, v->kind, &v->hit, &v->env_at, v->d, d_Le, sink);
        }
        if (v->nee) {
            if (v->diff_bsdf) {
                d_bsdf_eval(&v->bsdf, v->wo, v->nee_wi, dr_scale(dr_mul(d_e, v->ls.radiance), v->nee_scale), &db,
                            NULL, NULL);
                bsdf = true;
            }
            dr_vec3 d_L = dr_scale(dr_mul(d_e, v->nee_f), v->nee_scale);
            d_light_radiance(s, ps, &v->ls, v->media ? dr_mul(d_L, v->nee_tr) : d_L, sink);
        }
    }
    if (!dr_is_black(d_f)) {
        d_bsdf_eval(&v->bsdf, v->wo, v->wi, d_f, &db, NULL, NULL);
        bsdf = true;
    }
    if (bsdf)
        d_material_eval(s, ps, &v->hit, &db, sink);
}

/* Every path term is diagonal in the colour channels, so forward mode can
 * keep the image channels apart by splitting the adjoints: one pass over
 * the path serves all three (instead of one replay per channel). */
void d_path_vertex(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                   dr_vec3 d_e, dr_vec3 d_f, struct dr_grad_sink *sink)
{
    if (dr_is_black(d_e) && dr_is_black(d_f))
        return;
    if (!sink->dir) {
        vertex_part(s, ps, v, d_e, d_f, sink);
        return;
    }
    for (int c = 0; c < 3; c++) {
        if (dr_v3_get(d_e, c) == 0.0 && dr_v3_get(d_f, c) == 0.0)
            continue;
        sink->channel = c;
        vertex_part(s, ps, v, dr_v3_channel(d_e, c), dr_v3_channel(d_f, c), sink);
    }
}

/* The adjoint of the emission Le a vertex sees (d_Le), where it sees it: an
 * emitter's hit, or the environment along d (the escaped stage's own lookup
 * there, where it kept one). */
static void emission_part(const struct dr_scene *s, const struct dr_param_set *ps, enum dr_vertex_kind kind,
                          const struct dr_hit *hit, const struct dr_env_lookup *env_at, dr_vec3 d, dr_vec3 d_Le,
                          struct dr_grad_sink *sink)
{
    if (kind == DR_VERTEX_SURFACE)
        d_emission(s, ps, hit, d_Le, sink);
    else if (env_at->valid)
        d_env_radiance_at(s, ps, env_at, d_Le, sink);
    else
        d_env_radiance(s, ps, d, d_Le, sink);
}

void dr_path_light_terms_take(const struct dr_path_vertex *v, struct dr_path_light_terms *t)
{
    t->kind = v->kind;
    t->emits = v->emits;
    t->nee = v->nee;
    if (v->emits) {
        t->emit_w = v->emit_w;
        if (v->kind == DR_VERTEX_SURFACE) {
            t->hit = v->hit;
        } else {
            t->d = v->d;
            t->env_at = v->env_at;
        }
    }
    if (v->nee) {
        t->nee_f = v->nee_f;
        t->nee_scale = v->nee_scale;
        t->ls = v->ls;
    }
}

/* vertex_part's d_e part for such a vertex (its d_f is black: no BSDF parameter). */
static void light_terms_part(const struct dr_scene *s, const struct dr_param_set *ps,
                             const struct dr_path_light_terms *t, dr_vec3 d_e, struct dr_grad_sink *sink)
{
    if (t->emits)
        emission_part(s, ps, t->kind, &t->hit, &t->env_at, t->d, dr_scale(d_e, t->emit_w), sink);
    if (t->nee)
        d_light_radiance(s, ps, &t->ls, dr_scale(dr_mul(d_e, t->nee_f), t->nee_scale), sink);
}

/* (d_path_vertex's channel split) */
void d_path_light_terms(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_light_terms *t,
                        dr_vec3 d_e, struct dr_grad_sink *sink)
{
    if (dr_is_black(d_e))
        return;
    if (!sink->dir) {
        light_terms_part(s, ps, t, d_e, sink);
        return;
    }
    for (int c = 0; c < 3; c++) {
        if (dr_v3_get(d_e, c) == 0.0)
            continue;
        sink->channel = c;
        light_terms_part(s, ps, t, dr_v3_channel(d_e, c), sink);
    }
}

void d_path_vertex_term(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                        dr_vec3 d_e, struct dr_grad_sink *sink)
{
    d_path_vertex(s, ps, v, d_e, dr_v3s(0.0), sink);
}

void d_path_continuation(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 d_f, struct dr_grad_sink *sink)
{
    d_path_vertex(s, ps, v, dr_v3s(0.0), d_f, sink);
}

/* ------------------------------------------- stages for the medium walker */

void dr_path_stage_escaped(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_state *st,
                           struct dr_path_vertex *v)
{
    stage_escaped(s, opts, st, v);
}

void dr_path_stage_surface_hit(const struct dr_scene *s, const struct dr_path_opts *opts,
                               const struct dr_path_state *st, const struct dr_hit *located, struct dr_path_vertex *v)
{
    v->kind = DR_VERTEX_SURFACE;   /* stage_locate's hit, from the place the walker found */
    v->hit = *located;
    dr_hit_shade(&s->mesh, &v->hit);
    stage_emission(s, opts, st, located->tri, v);
}

bool dr_path_stage_material(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_state *st,
                            struct dr_sampler *sampler, struct dr_path_vertex *v)
{
    return stage_material(s, opts, st, sampler, v);
}

bool dr_path_stage_continue(const struct dr_path_opts *opts, struct dr_path_state *st, struct dr_path_vertex *v)
{
    return stage_continue(opts, st, v);
}
