/* The path walker's step for scenes with participating media (path.h:
 * dr_path_step hands over here when DR_STAGE_MEDIA is planned; a scene
 * without media never comes here).
 *
 * A step traces the current ray, samples a free flight in the current medium
 * up to the hit (delta tracking with spectral MIS, medium.h), and then either scatters in
 * the medium (a medium vertex: HG phase next-event estimation and phase
 * sampling), crosses an index-matched boundary (the medium changes, the ray
 * goes on within the same step: boundaries are not vertices), escapes, or
 * reaches an ordinary surface (the stages of path.c, with shadow rays that
 * estimate transmittance through media and boundaries). A dielectric boundary
 * (only in scenes planned with DR_STAGE_DIELECTRIC) is a vertex of its own: a
 * specular reflection or refraction (dielectric_vertex).
 *
 * Spectral MIS (medium.h) weights what the path gathers at a vertex by
 * r / mean(r) of the events so far; the change of that weight over the
 * segment arriving at a vertex is the vertex's `seg`: folded into what the
 * vertex adds (Le, ls.radiance; path.h keeps seg for the derivatives) and
 * into the throughput. Tracking draws its uniforms from streams of their own (keyed by
 * the path's sampler and the depth), so the vertex's block of dimensions is
 * the same as without media and a replay draws the same numbers. */
#include <math.h>

#include "accel.h"
#include "coverage.h"
#include "medium_grad.h"
#include "medium_scene.h"

/* Boundaries one segment may cross before the path gives up. */
#define MAX_CROSSINGS 256

enum { STREAM_FREE_FLIGHT = 1, STREAM_SHADOW = 2, STREAM_HERO = 3 };

static struct dr_sampler tracking_stream(const struct dr_sampler *smp, int depth, uint64_t which)
{
    /* free-flight and tracking numbers: independent hashes, whatever the sampler */
    struct dr_sampler r = {.key = dr_hash64(smp->key ^ (which * 0x632be59bd9b4e019ULL)),
                           .dim = (uint32_t)depth << 20, .kind = DR_SAMPLER_INDEPENDENT};
    return r;
}

/* Derivatives of media parameters are requested: record what to re-trace. */
static bool recording(const struct dr_path_opts *opts, const struct dr_path_vertex *v)
{
    return opts->params && opts->params->media_active && v->mrec;
}

static void draw_vertex_randoms(struct dr_sampler *sampler, int depth, struct dr_vertex_randoms *u)
{
    sampler->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(depth - 1);
    u->light_pick = dr_sampler_next(sampler);
    dr_sampler_next2(sampler, &u->light_u1, &u->light_u2);   /* as stage_material in path.c */
    u->lobe = dr_sampler_next(sampler);
    dr_sampler_next2(sampler, &u->bsdf_u1, &u->bsdf_u2);
    u->rr = dr_sampler_next(sampler);
}

/* Next-event estimation from a surface or medium vertex: the light sample,
 * the BSDF or phase value towards it, and the transmittance to it through
 * media; that and the segment's weight are folded into ls.radiance. */
static void media_nee(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_vertex *v,
                      const struct dr_sampler *smp, bool rec, struct dr_ray_counts *counts)
{
    const struct dr_vertex_randoms *u = &v->u;
    const bool in_medium = v->kind == DR_VERTEX_MEDIUM;
    struct dr_sky_bsdf sky;   /* (a medium point: a sky over the sphere) */
    const struct dr_sky_bsdf *by = in_medium ? NULL : dr_path_sky_bsdf(opts, v, &sky);
    const bool carries = dr_light_sample(s, s->light_sampler, v->hit.p, by, u->light_pick, u->light_u1, u->light_u2,
                                         &v->ls);
    if (!dr_path_light_kept(s, opts->params, carries, &v->ls))
        return;
    double pdf, cosine = 1.0;
    dr_vec3 so = v->hit.p;
    if (in_medium) {
        v->nee_wi = v->ls.wi;
        pdf = dr_hg_eval(s->media[v->medium].g, dr_dot(v->d, v->ls.wi));
        v->nee_f = dr_v3s(pdf);
    } else {
        if (dr_dot(v->ls.wi, v->ng) <= 0.0)
            return;
        v->nee_wi = dr_frame_to_local(&v->frame, v->ls.wi);
        v->nee_f = dr_bsdf_eval_pdf(&v->bsdf, v->wo, v->nee_wi, &pdf);
        if (dr_is_black(v->nee_f) && !v->diff_bsdf)
            return;
        so = dr_offset_origin(&v->hit, v->ng, v->ls.wi);
        cosine = fabs(v->nee_wi.z);
    }
    dr_vec3 sd = v->ls.wi;
    double tmax = INFINITY;
    if (!isinf(v->ls.dist)) {
        sd = dr_sub(v->ls.target, so);
        tmax = dr_length(sd);
        sd = dr_scale(sd, 1.0 / tmax);
    }
    if (!(tmax > 0.0))
        return;
    struct dr_sampler rng = tracking_stream(smp, v->depth, STREAM_SHADOW);
    if ((s->effects & (DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND)) && v->ls.type == DR_LS_AREA &&
        !dr_coverage_point_present(s, v->ls.index, v->ls.b1, v->ls.b2, dr_media_shadow_key(&rng)))
        return;   /* the light point is a hole in a cut-out emitter */
    dr_vec3 tr = dr_media_transmittance(s, so, sd, tmax, v->medium, &rng, &counts->shadow, rec ? &v->mrec->shadow : NULL);
    if (dr_is_black(tr))
        return;
    double w = v->ls.delta ? 1.0 : dr_mis_power(v->ls.pdf, pdf);
    v->nee_scale = cosine * w / v->ls.pdf;
    v->nee_tr = dr_mul(tr, v->seg);
    v->ls.radiance = dr_mul(v->ls.radiance, v->nee_tr);
    v->nee = true;
}

dr_vec3 dr_medium_shadow_transmittance(const struct dr_scene *s, uint64_t key, int depth, dr_vec3 so, dr_vec3 sd,
                                       double tmax, uint64_t *rays)
{
    const struct dr_sampler smp = {.key = key};
    struct dr_sampler rng = tracking_stream(&smp, depth, STREAM_SHADOW);
    return dr_media_transmittance(s, so, sd, tmax, s->global_medium, &rng, rays, NULL);
}

/* A scattering collision at p: NEE, then a phase-sampled continuation with
 * Russian roulette as at surfaces. The phase function is its own sampling
 * density, so the throughput changes only by the roulette. */
static bool medium_vertex(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                          struct dr_sampler *sampler, struct dr_path_vertex *v, dr_vec3 p,
                          struct dr_ray_counts *counts)
{
    v->kind = DR_VERTEX_MEDIUM;
    v->hit = (struct dr_hit){.tri = -1, .p = p, .material = -1};
    if (st->depth >= opts->max_depth)
        return false;
    v->shaded = true;
    v->frame = (dr_frame){dr_v3(1, 0, 0), dr_v3(0, 1, 0), dr_v3(0, 0, 1)};   /* local = world */
    v->wo = dr_neg(st->d);
    draw_vertex_randoms(sampler, st->depth, &v->u);
    if (opts->stages & DR_STAGE_NEE)
        media_nee(s, opts, v, sampler, recording(opts, v), counts);

    dr_vec3 wi;
    double pdf = dr_hg_sample(s->media[v->medium].g, st->d, v->u.bsdf_u1, v->u.bsdf_u2, &wi);
    if (!(pdf > 0.0))
        return false;
    v->wi = wi;
    v->f = v->s = dr_v3s(pdf);
    v->pdf = pdf;
    v->sub[0] = v->sub[1] = v->sub[2] = false;
    /* Russian roulette only once the throughput has dropped below 1 (as in
     * pbrt-v4's volumetric path tracer): a survival cap below 1 would make
     * the long walks of a bright, dense medium a heavy-tailed lottery (a white
     * medium of optical depth 2e4 averaged 0.8 instead of 1 with the 0.95 cap). */
    double q = 1.0;
    if (st->depth >= opts->rr_depth) {
        q = dr_min(dr_max3(st->beta), 1.0);
        if (v->u.rr >= q)
            return false;
    }
    v->cos_pdf_q = 1.0 / (pdf * q);
    v->cont = true;
    st->beta = dr_scale(st->beta, 1.0 / q);
    st->prev_pdf = pdf;
    st->prev_sky = DR_SKY_SPHERE;
    st->prev_p = p;
    st->o = p;
    st->d = wi;
    return true;
}

/* An ordinary surface: the stages of path.c with media-aware shadow rays. */
static bool surface_vertex(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                           struct dr_sampler *sampler, struct dr_path_vertex *v, const struct dr_hit *h,
                           struct dr_ray_counts *counts)
{
    dr_path_stage_surface_hit(s, opts, st, h, v);
    if (v->emits)
        v->Le = dr_mul(v->Le, v->seg);
    if (!dr_path_stage_material(s, opts, st, sampler, v))
        return false;
    if (opts->stages & DR_STAGE_NEE)
        media_nee(s, opts, v, sampler, recording(opts, v), counts);
    return dr_path_stage_continue(opts, st, v);
}

/* A smooth dielectric boundary of medium med, hit at h: reflection with the
 * Fresnel probability F, else refraction (Snell), chosen by the vertex's lobe
 * number. A delta event: no next-event estimation here (shadow rays are
 * blocked by the interface, dr_media_transmittance), and light found after
 * it counts with MIS weight 1 (prev_pdf = infinity: dr_mis_power(inf, p) = 1).
 * Weights: F / F = 1 for reflection; (1 - F) / (1 - F) / eta^2 for
 * refraction, eta = n_t / n_i along the path: radiance transport, in which
 * radiance inside a medium of index n is n^2 times larger (Mitsuba's and
 * pbrt's TransportMode::Radiance), so a path that enters and leaves carries
 * 1. No parameter enters the event: its adjoint is the weight (path.h). The
 * boundary's roughness is ignored (smooth only). No Russian roulette here:
 * the weight does not lower the throughput of a path that leaves again. */
static bool dielectric_vertex(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                              struct dr_sampler *sampler, struct dr_path_vertex *v, const struct dr_hit *h, int med)
{
    v->kind = DR_VERTEX_DIELECTRIC;
    v->hit = *h;
    if (st->depth >= opts->max_depth)
        return false;
    draw_vertex_randoms(sampler, st->depth, &v->u);
    v->ng = h->front ? h->ng : dr_neg(h->ng);   /* towards the arriving ray */
    const double eta = h->front ? s->media[med].ior : 1.0 / s->media[med].ior;
    const double cos_i = -dr_dot(st->d, v->ng);
    double cos_t, w = 1.0;
    const double F = dr_fresnel_dielectric(cos_i, eta, &cos_t);
    dr_vec3 wi;
    if (v->u.lobe < F) {
        wi = dr_normalize(dr_madd(st->d, v->ng, 2.0 * cos_i));
    } else {
        wi = dr_refract(st->d, v->ng, cos_i, cos_t, eta);
        w = 1.0 / (eta * eta);
        st->medium = h->front ? med : s->global_medium;
    }
    v->frame = (dr_frame){dr_v3(1, 0, 0), dr_v3(0, 1, 0), dr_v3(0, 0, 1)};   /* local = world */
    v->wo = dr_neg(st->d);
    v->wi = wi;
    v->f = v->s = dr_v3s(w);
    v->pdf = INFINITY;
    v->lobe = DR_BSDF_LOBE_SPECULAR;
    v->sub[0] = v->sub[1] = v->sub[2] = false;
    v->cos_pdf_q = 1.0;
    v->cont = true;
    st->beta = dr_scale(st->beta, w);
    st->prev_pdf = INFINITY;
    st->prev_sky = DR_SKY_SPHERE;   /* (weight 1 whatever the light's density) */
    st->prev_p = h->p;
    st->o = dr_offset_origin(h, h->ng, wi);
    st->d = wi;
    return true;
}

/* Ends the segment arriving at v: its spectral MIS weight change is v->seg
 * (the vertex's terms carry the path's weight r / mean(r), path.h), and the
 * throughput takes it on. */
static void end_segment(struct dr_path_state *st, struct dr_path_vertex *v, const struct dr_spectral_mis *mis,
                        dr_vec3 w_before)
{
    dr_vec3 w = dr_spectral_mis_weight(mis);
    for (int c = 0; c < 3; c++) {
        double b = dr_v3_get(w_before, c);
        dr_v3_set(&v->seg, c, b > 0.0 ? dr_v3_get(w, c) / b : 0.0);
        st->mis_r[c] = mis->r[c];
    }
    st->beta = dr_mul(st->beta, v->seg);
}

/* The path's hero channel (spectral MIS, medium.h): drawn from its own
 * stream, so whenever it is drawn it is the same. */
static int hero_channel(const struct dr_sampler *sampler)
{
    struct dr_sampler rng = tracking_stream(sampler, 0, STREAM_HERO);
    int hero = (int)(dr_sampler_next(&rng) * 3.0);
    return hero > 2 ? 2 : hero;
}

static void start_path(const struct dr_scene *s, struct dr_path_state *st, const struct dr_sampler *sampler)
{
    st->medium = dr_medium_at(s, st->o, st->d);
    st->hero = hero_channel(sampler);
    st->mis_r[0] = st->mis_r[1] = st->mis_r[2] = 1.0;
}

void dr_medium_path_resume(const struct dr_scene *s, struct dr_path_state *st, const struct dr_sampler *sampler)
{
    if (st->depth == 0)
        return;   /* (the camera ray: the first step starts the path itself) */
    st->medium = s->global_medium;
    st->hero = hero_channel(sampler);
    st->mis_r[0] = st->mis_r[1] = st->mis_r[2] = 1.0;   /* (no medium crossed: every channel's events alike) */
}

/* How far the segment's ray must be traced. In a homogeneous medium the
 * hero's next collision is drawn without knowing the surface ahead
 * (dr_medium_collision_ahead): a surface beyond it does not change the
 * event, so the ray stops there: in a dense medium most rays end at a
 * collision long before any surface, and Embree finds no hit (no hit to
 * compute either) sooner than the surface's (the dense fog's render 5 %
 * faster; for its shadow rays see medium_scene.c's roulette). The margin
 * covers
 * Embree's float distances against the double ones dr_medium_sample
 * compares (a relative error of about 1e-7 of the origin's and the
 * distance's magnitude; the margin is 100 times that): a hit that decides
 * the event is always found, so the events, the random numbers and the
 * image are exactly those of the full trace. */
static double segment_reach(const struct dr_scene *s, const struct dr_path_state *st, const struct dr_sampler *rng)
{
    if (st->medium < 0)
        return INFINITY;
    const struct dr_medium *m = &s->media[st->medium];
    /* where the hero's mean free path is longer than the medium's mean
     * chord, most flights end beyond the surface: the look ahead would cost
     * its clip and log1p for nothing (7 % of a thin global fog's render) */
    if (!(m->density_scale * dr_v3_get(m->extinction, st->hero) * m->mean_chord >= 1.0))
        return INFINITY;
    const double t = dr_medium_collision_ahead(m, st->o, st->d, *rng, st->hero);
    if (isinf(t))
        return INFINITY;
    const double scale = dr_max(fabs(st->o.x), dr_max(fabs(st->o.y), fabs(st->o.z)));
    return t + 1e-5 * (t + scale);
}

/* The ray query of the segment's crossing-th stretch (after as many
 * boundaries), counted. */
static int64_t segment_query(const struct dr_scene *s, const struct dr_path_state *st, const struct dr_sampler *sampler,
                             const struct dr_sampler *rng, int crossing, struct dr_ray_counts *counts)
{
    if (st->depth == 1 && crossing == 0)
        counts->camera++;
    else
        counts->extension++;
    uint64_t key = (s->effects & DR_FX_KEYED_TRACES) ? dr_coverage_key(sampler->key, st->depth, DR_RAY_TRACE) : 0;
    return dr_accel_intersect_key(s->accel, st->o, st->d, 0.0, segment_reach(s, st, rng), key);
}

bool dr_medium_path_step(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                         struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts)
{
    return dr_medium_path_step_traced(s, opts, st, sampler, v, counts, NULL);
}

/* (traced: see path.h. The answer of the full trace serves where the walker
 * would have traced only up to segment_reach: the events are the same, as
 * segment_reach says. One loop over the boundaries the segment crosses,
 * whose cases (absorbed, scattered, a dielectric, escaped or a surface, an
 * index-matched boundary crossed) read best in order: longer than a screen
 * for that.) */
bool dr_medium_path_step_traced(const struct dr_scene *s, const struct dr_path_opts *opts, struct dr_path_state *st,
                                struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts,
                                const int64_t *traced)
{
    v->depth = ++st->depth;
    v->d = st->d;
    v->o = st->o;
    /* the state on arrival, as dr_path_step_begin keeps it: derivative
     * sampling's emission weights read prev_p and prev_sky (path_deriv.c) */
    v->prev_pdf = st->prev_pdf;
    v->prev_sky = st->prev_sky;
    v->prev_p = st->prev_p;
    v->seg = dr_v3s(1.0);
    v->emits = v->shaded = v->nee = v->cont = v->diff_bsdf = false;
    v->env_at.valid = false;
    v->media = true;
    if (st->depth == 1)
        start_path(s, st, sampler);
    struct dr_sampler rng = tracking_stream(sampler, st->depth, STREAM_FREE_FLIGHT);
    const bool rec = recording(opts, v);
    if (rec) {
        v->mrec->seg = (struct dr_medium_trace){.rng_key = rng.key, .n = 0, .o0 = st->o, .d = st->d,
                                                .medium0 = st->medium};
        v->mrec->shadow.n = 0;
    }
    struct dr_spectral_mis mis = {st->hero, {st->mis_r[0], st->mis_r[1], st->mis_r[2]}};
    const dr_vec3 w_before = dr_spectral_mis_weight(&mis);
    for (int crossing = 0; crossing < MAX_CROSSINGS; crossing++) {
        v->medium = st->medium;
        const int64_t tri = crossing == 0 && traced ? *traced : segment_query(s, st, sampler, &rng, crossing, counts);
        struct dr_hit h;
        double thit = INFINITY;   /* (no surface up to the reach: the flight collides before it) */
        if (tri >= 0) {
            dr_hit_locate(&s->mesh, tri, st->o, st->d, &h);
            thit = dr_dot(dr_sub(h.p, st->o), st->d);
        }
        if (st->medium >= 0) {
            double t = thit;
            uint32_t dim0 = rng.dim;
            enum dr_medium_event ev = dr_medium_sample(&s->media[st->medium], st->o, st->d, thit, &rng, &mis, &t);
            if (rec)
                dr_medium_trace_add(&v->mrec->seg, st->medium, dim0, st->o, t);
            if (ev == DR_MEDIUM_ABSORB) {
                v->kind = DR_VERTEX_MEDIUM;
                v->hit = (struct dr_hit){.tri = -1, .p = dr_madd(st->o, st->d, t), .material = -1};
                v->seg = dr_v3s(0.0);
                st->beta = dr_v3s(0.0);
                return false;
            }
            if (ev == DR_MEDIUM_SCATTER) {
                end_segment(st, v, &mis, w_before);
                return medium_vertex(s, opts, st, sampler, v, dr_madd(st->o, st->d, t), counts);
            }
        }
        int med = tri >= 0 ? dr_boundary_medium(s, tri) : -1;
        if (med >= 0 && (opts->stages & DR_STAGE_DIELECTRIC) && s->media[med].ior > 0.0) {
            end_segment(st, v, &mis, w_before);
            dr_hit_shade(&s->mesh, &h);   /* (the vertex keeps a whole hit) */
            return dielectric_vertex(s, opts, st, sampler, v, &h, med);
        }
        if (tri < 0 || med < 0) {
            end_segment(st, v, &mis, w_before);
            if (tri < 0) {
                dr_path_stage_escaped(s, opts, st, v);
                v->Le = dr_mul(v->Le, v->seg);
                return false;
            }
            return surface_vertex(s, opts, st, sampler, v, &h, counts);
        }
        st->medium = h.front ? med : s->global_medium;
        st->o = dr_offset_origin(&h, h.ng, st->d);
    }
    return false;
}

dr_vec3 dr_medium_inscattered(const struct dr_scene *s, const struct dr_path_opts *opts, dr_vec3 x, dr_vec3 d,
                              int medium, int depth, uint64_t key, struct dr_ray_counts *counts)
{
    struct dr_path_opts o = *opts;
    o.params = NULL;   /* a primal estimate: nothing recorded */
    struct dr_sampler sampler = {.key = key, .dim = 0};
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, x, d);
    st.depth = depth;
    st.medium = medium;
    st.hero = hero_channel(&sampler);
    st.mis_r[0] = st.mis_r[1] = st.mis_r[2] = 1.0;
    v.depth = depth;
    v.d = d;
    v.seg = dr_v3s(1.0);
    v.emits = v.shaded = v.nee = v.cont = v.diff_bsdf = false;
    v.env_at.valid = false;
    v.media = true;
    v.medium = medium;
    bool more = medium_vertex(s, &o, &st, &sampler, &v, x, counts);
    dr_vec3 L = dr_path_vertex_term(&v);
    while (more) {
        dr_vec3 beta = st.beta;
        more = dr_medium_path_step(s, &o, &st, &sampler, &v, counts);
        L = dr_add(L, dr_mul(beta, dr_path_vertex_term(&v)));
    }
    return L;
}
