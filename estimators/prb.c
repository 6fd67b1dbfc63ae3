/* Path replay backpropagation (Vicini et al. 2021): constant memory per path,
 * time linear in its length.
 *
 * The primal pass returns the path's radiance L. The replay re-traces the same
 * path with the same random numbers and, at vertex k, knows the radiance still
 * to come, R_k = L - (what vertices 1..k added), so the BSDF term of the
 * continuation gets d L / d f_k = R_k / f_k per channel: no tape of the path.
 * Where f_k is 0 in a channel, R_k is 0 too and the term is 0 (never 0/0);
 * a differentiated vertex with f_k = 0 was traced on with a substitute factor
 * (path.h), whose remaining radiance R_sub gives the derivative instead.
 * Primal and replay are one loop (as in Mitsuba's prb.py): with an adjoint,
 * the walk subtracts each vertex's contribution and sends derivatives to the
 * sink. All sums are in double. */
#include <stdlib.h>
#include <string.h>

#include "common.h"
#include "error.h"
#include "path_deriv.h"
#include "prb_attached.h"

#include "medium_grad.h"
#include "wave_soa.h"
#include "wavefront.h"

/* The wavefront's samples parked between their primal walks and their
 * replays (in cross mode, estimator.h, their adjoints wait for their pixels'
 * other samples); by sample (item), as dr_wave_soa_walk writes them. */
struct parked_samples {
    struct dr_wave_soa_walks walk;   /* the primal walks' radiance, last_diff (struct walk) and ray
                                        answers (log: the replay traces nothing again) */
    dr_vec3 *adj;                    /* the adjoint, once the pixel's samples are all walked */
    int32_t *order;                  /* the samples to replay */
    bool *in_media;                  /* in a scene with media: the samples whose paths met one
                                        (dr_wave_soa_walks.in_media; arrays_pixels) */
};

struct prb_job {
    struct dr_est_base b;   /* first: the shared part */
    bool attached;          /* attached or mis sampling: the replays are prb_attached.c's */
    double radius;          /* attached sampling: the scene's radius */
    bool wave;              /* detached, no media, no derivative sampling: samples as a wavefront */
    bool media_arrays;      /* detached with media, no derivative sampling: the primal walks in the
                               arrays where the paths meet no medium (arrays_pixels) */
    struct dr_path_opts outside_media;   /* ... and the replays of those paths: the run's options
                                            without the media's stages (a path that meets no medium
                                            is the same there, and its ray answers are logged) */
    struct dr_wave *waves[DR_MAX_THREADS];   /* ... per thread, made on first use */
    struct dr_wave_soa *soas[DR_MAX_THREADS];   /* the wavefront's primal walks where the arrays apply (wave_soa.h) */
    struct parked_samples items[DR_MAX_THREADS];   /* the wavefront: a group's parked samples, per thread */
    dr_vec3 *adj[DR_MAX_THREADS];            /* one path at a time: a pixel's samples' adjoints, per thread */
    struct primal_sums *sums[DR_MAX_THREADS];   /* one path at a time with the cross primal: the pixel's
                                                   samples' primal walks, which the replays then need not
                                                   walk again */
    struct deferred *deferred[DR_MAX_THREADS];   /* derivative sampling: the new directions the replays
                                                    drew, walked many at a time (deferred_add) */
    bool deferring[DR_MAX_THREADS];              /* ... within this thread's prb_pixels call */
    bool defer;   /* derivative sampling with a BSDF parameter (dr_est_sampling_run): the only
                     runs that draw new directions, so the only ones that make the buffers */
    int defer_rays;   /* ... the most a vertex draws (dr_path_deriv_max_rays): the buffers' rays per vertex */
};

/* Derivative sampling's new directions, deferred: a replay draws them
 * where d_path_deriv_sample would (dr_path_deriv_rays: the same streams),
 * and their radiance is walked for many vertices at once on the lanes
 * (dr_wave_deriv_radiance), as the tape's walk_ahead does, rather than one
 * scalar walk at a time (about 30 % of a prb run under derivative
 * sampling). Their terms (d_path_deriv_rays) then go to the thread's sink;
 * in forward mode each vertex's to its pixel, as dr_est_sample_done adds
 * the rest of its sample: the same sum in another order. */
#define DEFERRED_VERTICES 1024   /* per thread (about 1.6 MB with three rays each) */
struct deferred_vertex {
    struct dr_path_vertex v;
    dr_vec3 d_beta;   /* d_path_deriv_sample's */
    int64_t px;
    int32_t ray0;     /* its rays: rays[ray0 .. ray0 + n) */
    int n;
};
struct deferred {
    struct deferred_vertex *verts;
    struct dr_deriv_ray *rays;
    struct dr_deriv_light *found;
    int n_verts;
    int32_t n_rays;
    struct dr_grad_sink sink;   /* the thread's, for this prb_pixels call (deferred_begin) */
};

struct prb_radiance {
    dr_vec3 true_, sub;   /* L with the true throughput, and with substitutes */
};

/* What a replay one path at a time needs of its primal walk (struct walk's
 * sums and vertex count), where the cross primal walked it already. */
struct primal_sums {
    struct prb_attached_sums L;
    int vertices;   /* (the media derivatives'; 0 from the arrays, whose paths meet no medium: the
                       count only sets how often a media term is estimated, and theirs are 0) */
    bool no_term;   /* the arrays' walk met no vertex with a derivative term (last_diff 0) and its
                       sums are finite: no parameter reaches the path (attached, derivative
                       sampling or not), so its replay would add exact zeros */
};

/* Samples whose ray answers are parked at most (per thread: about 1.4 MB);
 * with more samples per pixel than this, a replay traces its rays again. */
#define LOGGED_ITEMS 4096

/* One walk over a path. Without `sink`: the primal, whose radiance goes to
 * L. With it: the replay, which turns L (the primal's result) into the
 * remaining radiance vertex by vertex. */
struct walk {
    struct prb_radiance L;
    dr_vec3 adj;
    struct dr_grad_sink *sink;
    int vertices;                      /* the primal counts them, the replay's media derivatives use the count */
    int last_diff;                     /* the primal: depth of the last vertex with a derivative term (0: none);
                                          the wavefront's replay ends there (detached sampling) */
    struct dr_medium_record *mrec;     /* media: what the replay re-traces, one vertex at a time */
    const struct dr_wave_log *log;     /* one path at a time: the primal walk's ray answers, for the
                                          replay (NULL: traced again) */
    const struct dr_path_opts *opts;   /* the walker's (NULL: the run's; prb_job.outside_media for a
                                          path that meets no medium) */
    /* derivative sampling: the last vertex, if differentiated and continued */
    struct dr_path_vertex *prev;
    bool have_prev;
    dr_vec3 prev_dt;
    struct deferred_ctx *deferred;   /* ... and where its new directions wait (NULL: walked at once) */
};

/* A replay's way to its thread's deferred directions, and its pixel. */
struct deferred_ctx {
    struct prb_job *j;
    int thread;
    int64_t px;
};
static void deferred_add(struct deferred_ctx *c, const struct dr_path_vertex *v, const struct dr_sampler *smp,
                         dr_vec3 d_beta);

/* The derivatives of a replay's vertex v (reached with beta, ratio) to the
 * walk's sink: w->L holds the sums with v's term subtracted, remaining
 * the true one before (walk_vertex). */
static void vertex_adjoints(const struct dr_est_base *b, struct walk *w, const struct dr_path_vertex *v, dr_vec3 beta,
                            dr_vec3 ratio, dr_vec3 remaining, struct dr_sampler *smp, struct dr_ray_counts *rays)
{
    const struct dr_scene *s = b->p->scene;
    const struct dr_param_set *ps = b->p->params;
    struct dr_grad_sink *sink = w->sink;
    const struct prb_radiance *L = &w->L;
    const dr_vec3 adj = w->adj;
    const bool dsamp = b->popts.deriv_params != 0;   /* derivative sampling runs */
    if (v->media)
        d_medium_vertex(s, &b->popts, v, w->mrec, w->vertices, dr_mul(adj, dr_mul(ratio, beta)), dr_mul(adj, remaining),
                        dr_mul(adj, L->true_), dr_mul(adj, dr_mul(dr_mul(ratio, beta), dr_path_vertex_nee(v))), sink);
    const dr_vec3 d_e = dr_mul(adj, dr_mul(ratio, beta));
    dr_vec3 d_f = dr_v3s(0.0);   /* the continuation's f (none: black) */
    if (v->cont && v->diff_bsdf)
        for (int ch = 0; ch < 3; ch++) {
            double f = dr_v3_get(v->f, ch), r;
            if (v->sub[ch])
                r = dr_v3_get(ratio, ch) * dr_v3_get(L->sub, ch) / dr_v3_get(v->s, ch);
            else
                r = f != 0.0 ? dr_v3_get(L->true_, ch) / f : 0.0;
            dr_v3_set(&d_f, ch, r * dr_v3_get(adj, ch));
        }
    if (dsamp) {   /* the three-strategy weights of the BSDF derivative terms (path_deriv.h) */
        d_path_vertex_term(s, ps, v, d_e, sink);
        if (w->have_prev)
            d_path_deriv_emission(s, &b->popts, w->prev, w->prev_dt, v, sink);
        d_path_deriv_nee(s, &b->popts, v, d_e, sink);
        if (v->cont && v->diff_bsdf)
            d_path_deriv_continuation(s, &b->popts, v, d_f, sink);
    } else {
        d_path_vertex(s, ps, v, d_e, d_f, sink);   /* (both BSDF values' material adjoint at once) */
    }
    /* the new directions: also where the forward sample failed or
     * Russian roulette ended the path (that strategy then gave 0) */
    if (dsamp && v->shaded && v->diff_bsdf) {
        if (w->deferred)
            deferred_add(w->deferred, v, smp, d_e);
        else
            d_path_deriv_sample(s, &b->popts, v, smp, d_e, sink, rays);
    }
    if ((w->have_prev = dsamp && v->cont && v->diff_bsdf)) {
        *w->prev = *v;
        w->prev_dt = dr_scale(d_e, v->cos_pdf_q);
    }
}

/* What vertex v (reached with throughput beta, ratio) does to the walk:
 * the body of the walk's loop, shared by the one-path walk and the wavefront. */
static void walk_vertex(const struct dr_est_base *b, struct walk *w, const struct dr_path_vertex *v, dr_vec3 beta,
                        dr_vec3 ratio, struct dr_sampler *smp, struct dr_ray_counts *rays)
{
    const struct dr_scene *s = b->p->scene;
    const struct dr_param_set *ps = b->p->params;
    struct dr_grad_sink *sink = w->sink;
    struct prb_radiance *L = &w->L;
    const double sign = sink ? -1.0 : 1.0;
    const bool dsamp = b->popts.deriv_params != 0;   /* path_deriv.h (only vertices with a BSDF parameter) */
    if (!sink)
        ++w->vertices;
    dr_vec3 c = dr_mul(beta, dr_path_vertex_term(v));   /* with substitutes */
    dr_vec3 remaining = L->true_;   /* replay: from this vertex on */
    L->sub = dr_madd(L->sub, c, sign);
    L->true_ = dr_madd(L->true_, dr_mul(ratio, c), sign);
    /* (in a scene with media: where the media give the vertex a term. Most
     * paths through a room with a smoke in it never meet the smoke, and
     * their replays now end where a scene without it would end them) */
    const bool has_derivative =
        dr_path_vertex_has_surface_derivative(s, ps, v) || dr_medium_vertex_has_derivative(ps, v);
    if (!sink) {
        if (has_derivative)
            w->last_diff = v->depth;
        return;
    }
    /* A vertex without a term adds nothing below (test_estimators checks the
     * predicate against the adjoints); skipping it also means a replay reads
     * no more of such a vertex than the primal did, so both walks can shade
     * it eight lanes at a time (path_simd.h). Derivative sampling still
     * needs its emission for the previous vertex's sampled direction. */
    if (!has_derivative && !dsamp)
        return;
    vertex_adjoints(b, w, v, beta, ratio, remaining, smp, rays);
}

/* The walk of (smp, o, d), one path at a time. */
static void walk(const struct dr_est_base *b, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, struct walk *w,
                 struct dr_ray_counts *rays)
{
    struct dr_path_state st;
    struct dr_path_vertex v;
    v.mrec = w->mrec;
    w->have_prev = false;
    dr_path_start(&st, o, d);
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio;
        bool more = dr_wave_log_step(b->p->scene, w->opts ? w->opts : &b->popts, w->log, &st, &smp, &v, rays);
        walk_vertex(b, w, &v, beta, ratio, &smp, rays);
        if (!more)
            break;
    }
}

/* One pixel's samples with attached sampling (prb_attached.c); under mis
 * each sample's attached and detached derivatives, from one replay, go to
 * its group's two estimates (mis.h). */
static void attached_pixel(struct prb_job *j, int thread, int64_t px, const dr_vec3 *adj,
                           const struct primal_sums *primal, const struct dr_wave_log *logs,
                           struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    struct prb_attached_ctx c = {.b = b, .eps = b->p->regularize, .radius = j->radius,
                                 .rays = &b->thr[thread].rays};
    for (int sidx = 0; sidx < b->p->spp; sidx++) {
        struct dr_grad_sink det, att;
        if (dr_is_black(adj[sidx]))
            continue;   /* (cross mode: this sample does not matter to the loss) */
        if (b->mis)
            dr_est_mis_sinks(b, thread, px, &det, &att);
        /* (a path without a derivative term: no vertex's sampling moves
         * either, dr_path_vertex_sampling_moves implies diff_bsdf; its
         * replay, two walks and a vertex adjoint per vertex, would add
         * exact zeros, so neither it nor its camera ray is made. Still a
         * sample: MIS counts it) */
        if (!(primal && primal[sidx].no_term)) {
            struct dr_sampler smp;
            dr_vec3 o, d;
            dr_est_camera_ray(b, thread, px, sidx, &smp, &o, &d);
            c.log = logs ? &logs[sidx] : NULL;
            const struct prb_attached_sums *sums = primal ? &primal[sidx].L : NULL;
            if (!prb_attached_sample(&c, smp, o, d, adj[sidx], sums, b->mis ? &att : sink, b->mis ? &det : NULL)) {
                b->thr[thread].invalid++;
                continue;
            }
        }
        if (b->mis)
            dr_est_mis_sample_done(b, thread, px, &det, &att);
        else
            dr_est_sample_done(b, px, sink);
    }
}

/* ---- the wavefront (wavefront.h, wave_soa.h): a chunk's pixels that
 * matter to the loss, in groups whose samples are parked between their
 * primal walks and their replays: the primal walks of all the group's
 * samples (in arrays where they apply), then each sample's adjoint (in cross
 * mode, estimator.h, from its pixel's other samples), then the replays in
 * the lanes, which answer their ray queries from the primal walks' logs.
 * Each replay has its own sink (forward mode keeps a sample's three channel
 * sums in it; reverse mode's all add to the thread's gradient). Detached
 * sampling without media or derivative sampling only. */

/* Pixels per parallel chunk (and at most per wavefront run). */
#define PIXEL_CHUNK 16

/* What every wavefront callback needs of its run. */
struct lane_ctx {
    struct prb_job *j;
    int thread;
};

/* The replay ends at the primal's last vertex with a derivative term: the
 * vertices after it add nothing to the gradient (their share of L is never
 * needed), so it neither shades nor traces them. */
static bool replay_goes_on(const struct walk *w, const struct dr_path_vertex *v)
{
    return !w->sink || v->depth < w->last_diff;
}

/* A lane's vertex, primal or replay: its lane state begins with its walk
 * (struct park_lane). */
static bool lane_vertex(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                        struct dr_sampler *smp, bool more)
{
    (void)more;
    const struct lane_ctx *c = ctx;
    struct walk *w = user;
    walk_vertex(&c->j->b, w, v, a->beta, a->ratio, smp, &c->j->b.thr[c->thread].rays);
    return replay_goes_on(w, v);
}

struct park_ctx {
    struct lane_ctx run;
    struct dr_grad_sink sink;
    const int64_t *px;           /* item i: sample i % spp of pixel px[i / spp] */
    const struct parked_samples *items;
};

struct park_lane {
    struct walk w;
    struct dr_grad_sink sink;
    int64_t item, px;
};
_Static_assert(sizeof(struct park_lane) <= DR_WAVE_USER_BYTES, "a park lane's state fits");

/* Item i's sampler and camera ray (the arrays' primal walks start so:
 * dr_wave_soa_walk); returns its pixel. */
static int64_t sample_ray(void *ctx, int64_t i, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct park_ctx *c = ctx;
    const int spp = c->run.j->b.p->spp;
    const int64_t px = c->px[i / spp];
    dr_est_camera_ray(&c->run.j->b, c->run.thread, px, (int)(i % spp), smp, o, d);
    return px;
}

/* The same for a lane's walk. */
static void lane_ray(struct park_ctx *c, struct park_lane *l, int64_t i, struct dr_sampler *smp, dr_vec3 *o,
                     dr_vec3 *d)
{
    l->item = i;
    l->px = sample_ray(c, i, smp, o, d);
}

static void primal_start(void *ctx, int64_t i, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    lane_ray(ctx, user, i, smp, o, d);
}

static void soa_start(void *ctx, int64_t i, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)sample_ray(ctx, i, smp, o, d);
}

/* soa_start for items first .. first + 7 at once (dr_wave_start8_fn). */
static void soa_start8(void *ctx, int64_t first, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct park_ctx *c = ctx;
    const int spp = c->run.j->b.p->spp;
    int64_t px[8];
    int sample[8];
    for (int l = 0; l < 8; l++)
        px[l] = c->px[(first + l) / spp], sample[l] = (int)((first + l) % spp);
    dr_est_camera_rays8(&c->run.j->b, c->run.thread, px, sample, smp, o, d);
}

static void primal_keep_log(void *ctx, void *user, const struct dr_wave_log *log)
{
    struct park_ctx *c = ctx;
    const struct park_lane *l = user;
    if (c->items->walk.log)
        dr_wave_log_copy(&c->items->walk.log[l->item], log);
}

static enum dr_wave_next primal_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)smp, (void)o, (void)d;
    struct park_ctx *c = ctx;
    const struct park_lane *l = user;
    const struct dr_wave_soa_walks *out = &c->items->walk;
    out->L[l->item] = l->w.L.true_;
    out->L_sub[l->item] = l->w.L.sub;
    out->last_diff[l->item] = l->w.last_diff;
    return DR_WAVE_DONE;
}

static void replay_start(void *ctx, int64_t k, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    struct park_ctx *c = ctx;
    struct park_lane *l = user;
    const struct parked_samples *it = c->items;
    lane_ray(c, l, it->order[k], smp, o, d);
    l->w.L = (struct prb_radiance){it->walk.L[l->item], it->walk.L_sub[l->item]};
    l->w.last_diff = it->walk.last_diff[l->item];
    l->w.adj = it->adj[l->item];
    l->sink = c->sink;
    l->w.sink = &l->sink;
}

static const struct dr_wave_log *replay_log(void *ctx, void *user)
{
    struct park_ctx *c = ctx;
    const struct park_lane *l = user;
    return c->items->walk.log ? &c->items->walk.log[l->item] : NULL;
}

static enum dr_wave_next replay_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)smp, (void)o, (void)d;
    struct park_ctx *c = ctx;
    struct park_lane *l = user;
    dr_est_sample_done(&c->run.j->b, l->px, &l->sink);
    return DR_WAVE_DONE;
}

/* The arrays' replays (dr_wave_soa_replay): item k is the replay of sample
 * order[k]; the vertices with a derivative term come whole, with the sums
 * walk_vertex would hold. All paths share the thread's sink: in forward
 * mode each vertex's channel sums go to its pixel at once (the lanes sum a
 * sample's first, replay_end; the same numbers added in another order). */
static void soa_replay_start(void *ctx, int64_t k, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct park_ctx *c = ctx;
    (void)sample_ray(ctx, c->items->order[k], smp, o, d);
}

/* soa_replay_start for items first .. first + 7 at once. */
static void soa_replay_start8(void *ctx, int64_t first, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct park_ctx *c = ctx;
    const int spp = c->run.j->b.p->spp;
    int64_t px[8];
    int sample[8];
    for (int l = 0; l < 8; l++) {
        const int32_t i = c->items->order[first + l];
        px[l] = c->px[i / spp], sample[l] = i % spp;
    }
    dr_est_camera_rays8(&c->run.j->b, c->run.thread, px, sample, smp, o, d);
}

static void soa_replay_vertex(void *ctx, int64_t k, const struct dr_path_vertex *v,
                              const struct dr_wave_soa_replay_lanes *g, int i)
{
    struct park_ctx *c = ctx;
    struct dr_est_base *b = &c->run.j->b;
    const int32_t sample = c->items->order[k];
    struct walk w = {.L = {dr_v3x8_get(&g->L_true, i), dr_v3x8_get(&g->L_sub, i)}, .adj = c->items->adj[sample],
                     .sink = &c->sink};
    vertex_adjoints(b, &w, v, dr_v3x8_get(&g->beta, i), dr_v3x8_get(&g->ratio, i), dr_v3x8_get(&g->remaining, i),
                    NULL, &b->thr[c->run.thread].rays);
    if (c->sink.dir)
        dr_est_sample_done(b, c->px[sample / b->p->spp], &c->sink);
}

/* The replays of a group's n parked samples (items->order): in the arrays
 * where they apply, else in the lanes. */
static void replay_walks(struct prb_job *j, int thread, struct park_ctx *c, int32_t n)
{
    struct dr_est_base *b = &j->b;
    /* (light_terms, bsdf_terms: walk_vertex's adjoint reads the light
     * sample's record, a differentiated emitter's hit and a differentiated
     * BSDF's vertex, which the eight-lane stages fill) */
    static const struct dr_wave_ops replay = {.start = replay_start, .vertex = lane_vertex, .walk_end = replay_end,
                                              .replay_log = replay_log, .partial_vertices = true,
                                              .light_terms = true, .bsdf_terms = true};
    const struct parked_samples *it = c->items;
    const struct dr_wave_soa_replay r = {c, it->order, it->walk.L, it->walk.L_sub, it->walk.last_diff, it->walk.log,
                                         soa_replay_vertex};
    if (j->soas[thread] && dr_wave_soa_replays_apply(b->p->scene, &b->popts) &&
        dr_wave_soa_replay(j->soas[thread], b->p->scene, &b->popts, n, soa_replay_start, soa_replay_start8, c, &r,
                           &b->thr[thread].rays))
        return;
    dr_wave_run(j->waves[thread], b->p->scene, &b->popts, n, &replay, c, &b->thr[thread].rays);
}

/* Pixels a group holds: its samples' logs fit LOGGED_ITEMS. */
static int64_t park_group(int spp)
{
    return spp < LOGGED_ITEMS ? LOGGED_ITEMS / spp : 1;
}

/* Bytes of one thread's parked samples (cap of them). */
static uint64_t parked_bytes(int64_t cap)
{
    uint64_t log = cap <= LOGGED_ITEMS ? sizeof(struct dr_wave_log) : 0;
    return (uint64_t)cap * (3 * sizeof(dr_vec3) + sizeof(int) + sizeof(int32_t) + sizeof(bool) + log);
}

/* A thread's parked samples, made on first use (cap of them; ray answers
 * only if they fit LOGGED_ITEMS). False: out of memory. */
static void parked_free(struct parked_samples *it)
{
    free(it->walk.L);
    free(it->walk.L_sub);
    free(it->walk.last_diff);
    free(it->walk.log);
    free(it->adj);
    free(it->order);
    free(it->in_media);
    *it = (struct parked_samples){0};
}

static bool parked_make(struct parked_samples *it, int64_t cap)
{
    if (it->order)
        return true;
    it->walk.L = malloc(sizeof(dr_vec3) * (size_t)cap);
    it->walk.L_sub = malloc(sizeof(dr_vec3) * (size_t)cap);
    it->walk.last_diff = malloc(sizeof(int) * (size_t)cap);
    it->walk.log = cap <= LOGGED_ITEMS ? malloc(sizeof(struct dr_wave_log) * (size_t)cap) : NULL;
    it->adj = malloc(sizeof(dr_vec3) * (size_t)cap);
    it->in_media = malloc(sizeof(bool) * (size_t)cap);
    it->order = malloc(sizeof(int32_t) * (size_t)cap);
    if (it->walk.L && it->walk.L_sub && it->walk.last_diff && (it->walk.log || cap > LOGGED_ITEMS) && it->adj &&
        it->in_media && it->order)
        return true;
    parked_free(it);   /* all or none: `order` marks a whole set */
    return false;
}

/* The primal walks of a group's n samples: in arrays where they apply
 * (wave_soa.h: the same sums and ray answers, faster), else in the lanes. */
static void primal_walks(struct prb_job *j, int thread, struct park_ctx *c, int64_t n)
{
    struct dr_est_base *b = &j->b;
    static const struct dr_wave_ops primal = {.start = primal_start, .vertex = lane_vertex, .walk_end = primal_end,
                                              .keep_log = primal_keep_log, .partial_vertices = true,
                                              .light_terms = true, .bsdf_terms = true};
    if (dr_wave_soa_walks_apply(b->p->scene, &b->popts) &&
        (j->soas[thread] || (j->soas[thread] = dr_wave_soa_create())) &&
        dr_wave_soa_walk(j->soas[thread], b->p->scene, &b->popts, n, soa_start, soa_start8, c, &c->items->walk,
                         &b->thr[thread].rays))
        return;   /* (out of memory for the arrays: the lanes, which need none) */
    dr_wave_run(j->waves[thread], b->p->scene, &b->popts, n, &primal, c, &b->thr[thread].rays);
}

/* The group's valid samples (finite primal sums) that matter to the loss
 * and have a derivative term, with their adjoints, into items->order; n_px
 * pixels from px (adj: their adjoint, but in cross mode). Returns how many. */
static int32_t replays(struct prb_job *j, int thread, const int64_t *px, const dr_vec3 *adj, int64_t n_px,
                       const struct parked_samples *it)
{
    struct dr_est_base *b = &j->b;
    const int spp = b->p->spp;
    const struct dr_wave_soa_walks *walk = &it->walk;
    int32_t n = 0;
    for (int64_t k = 0; k < n_px; k++) {
        const int64_t i0 = k * spp;
        struct dr_cross_sum sum = {0};
        for (int64_t i = i0; i < i0 + spp; i++) {
            if (dr_v3_finite(walk->L[i]) && dr_v3_finite(walk->L_sub[i]))
                dr_cross_sum_add(&sum, (int)(i - i0), walk->L[i]);
            else
                b->thr[thread].invalid++;
        }
        if (b->p->cross)
            dr_est_cross_pixel(b, px[k], &sum);
        for (int64_t i = i0; i < i0 + spp; i++) {
            if (!dr_v3_finite(walk->L[i]) || !dr_v3_finite(walk->L_sub[i]))
                continue;
            it->adj[i] = b->p->cross ? dr_est_cross_adjoint(b, px[k], &sum, (int)(i - i0), walk->L[i]) : adj[k];
            /* (else the sample does not matter to the loss, or its path has no derivative term) */
            if (!dr_is_black(it->adj[i]) && walk->last_diff[i] > 0)
                it->order[n++] = (int32_t)i;
        }
    }
    return n;
}

/* Pixels [begin, end) (at most PIXEL_CHUNK) on the wavefront. False: no
 * memory for the lanes or the parked samples (then one path at a time). */
static bool wave_pixels(struct prb_job *j, int thread, int64_t begin, int64_t end, struct dr_grad_sink sink)
{
    struct dr_est_base *b = &j->b;
    const int spp = b->p->spp;
    const int64_t group = park_group(spp), cap = group * spp;
    if (!j->waves[thread] && !(j->waves[thread] = dr_wave_create()))
        return false;
    struct parked_samples *it = &j->items[thread];
    if (!parked_make(it, cap))
        return false;
    int64_t px[PIXEL_CHUNK];
    dr_vec3 adj[PIXEL_CHUNK];   /* (but in cross mode) */
    int64_t n_all = 0;
    for (int64_t p = begin; p < end; p++)
        if (b->p->cross || dr_est_sample_adjoint(b, p, &adj[n_all]))
            px[n_all++] = p;
    for (int64_t first = 0; first < n_all; first += group) {
        const int64_t n_px = n_all - first < group ? n_all - first : group;
        struct park_ctx c = {.run = {j, thread}, .sink = sink, .px = px + first, .items = it};
        primal_walks(j, thread, &c, n_px * spp);
        replay_walks(j, thread, &c, replays(j, thread, px + first, adj + first, n_px, it));
    }
    return true;
}

/* The adjoint of each of pixel px's samples into adj[0, spp) (false: none
 * matters to the loss). Cross mode (estimator.h): from primal walks of all
 * its samples (their replays walk them again). */
/* The cross primal (estimator.h): pixel px's samples' radiance in adj
 * (0 where not finite) becomes their adjoints. False: none matters to the
 * loss. */
static bool cross_adjoints(struct dr_est_base *b, int64_t px, dr_vec3 *adj)
{
    struct dr_cross_sum sum = {0};
    for (int sidx = 0; sidx < b->p->spp; sidx++)
        dr_cross_sum_add(&sum, sidx, adj[sidx]);
    dr_est_cross_pixel(b, px, &sum);
    bool any = false;
    for (int sidx = 0; sidx < b->p->spp; sidx++) {
        adj[sidx] = dr_est_cross_adjoint(b, px, &sum, sidx, adj[sidx]);
        any = any || !dr_is_black(adj[sidx]);
    }
    return any;
}

/* The primal walk of pixel px's sample sidx, one path at a time: its sums
 * and vertex count. */
static struct primal_sums one_path_primal(struct dr_est_base *b, int thread, int64_t px, int sidx)
{
    struct dr_medium_record mrec;
    struct dr_path_vertex prev;
    struct dr_sampler smp;
    dr_vec3 o, d;
    struct walk w = {.mrec = &mrec, .prev = &prev};
    dr_est_camera_ray(b, thread, px, sidx, &smp, &o, &d);
    walk(b, smp, o, d, &w, &b->thr[thread].rays);
    return (struct primal_sums){{w.L.true_, w.L.sub}, w.vertices, false};
}

static bool pixel_adjoints(struct prb_job *j, int thread, int64_t px, dr_vec3 *adj)
{
    struct dr_est_base *b = &j->b;
    const int spp = b->p->spp;
    if (!b->p->cross) {
        if (!dr_est_sample_adjoint(b, px, &adj[0]))
            return false;
        for (int sidx = 1; sidx < spp; sidx++)
            adj[sidx] = adj[0];
        return true;
    }
    for (int sidx = 0; sidx < spp; sidx++) {   /* adj holds the samples' radiance meanwhile */
        const struct primal_sums p = one_path_primal(b, thread, px, sidx);
        adj[sidx] = dr_v3_finite(p.L.L_true) && dr_v3_finite(p.L.L_sub) ? p.L.L_true : dr_v3s(0.0);
        if (j->sums[thread])   /* (for the replays: pixel_replays) */
            j->sums[thread][sidx] = p;
    }
    return cross_adjoints(b, px, adj);
}

/* ---- derivative sampling's deferred directions (struct deferred) ---- */

static void deferred_free(struct deferred *d)
{
    if (!d)
        return;
    free(d->verts);
    free(d->rays);
    free(d->found);
    free(d);
}

static uint64_t deferred_bytes(int rays)
{
    return sizeof(struct deferred) +
           DEFERRED_VERTICES * (sizeof(struct deferred_vertex) +
                                (uint64_t)rays * (sizeof(struct dr_deriv_ray) + sizeof(struct dr_deriv_light)));
}

/* The thread's deferred directions for a prb_pixels call that adds to sink:
 * made on first use, with the lanes they are walked on. False (then each
 * replay walks its own, d_path_deriv_sample): no new directions to draw
 * (prb_job.defer), or out of memory. */
static bool deferred_begin(struct prb_job *j, int thread, const struct dr_grad_sink *sink)
{
    if (!j->defer)
        return false;
    if (!j->waves[thread] && !(j->waves[thread] = dr_wave_create()))
        return false;
    struct deferred *d = j->deferred[thread];
    if (!d) {
        if (!(d = calloc(1, sizeof *d)))
            return false;
        d->verts = malloc(sizeof *d->verts * DEFERRED_VERTICES);
        d->rays = malloc(sizeof *d->rays * DEFERRED_VERTICES * (size_t)j->defer_rays);
        d->found = malloc(sizeof *d->found * DEFERRED_VERTICES * (size_t)j->defer_rays);
        if (!d->verts || !d->rays || !d->found) {
            deferred_free(d);
            return false;
        }
        j->deferred[thread] = d;
    }
    d->sink = *sink;
    return true;
}

/* The radiance of every deferred direction, walked at once on the lanes,
 * and the terms of their vertices. */
static void deferred_flush(struct prb_job *j, int thread)
{
    struct deferred *d = j->deferred[thread];
    struct dr_est_base *b = &j->b;
    if (d->n_rays > 0)
        dr_wave_deriv_radiance(j->waves[thread], b->p->scene, &b->popts, d->n_rays, d->rays, d->found,
                               &b->thr[thread].rays);
    for (int k = 0; k < d->n_verts; k++) {
        const struct deferred_vertex *dv = &d->verts[k];
        struct dr_grad_sink sink = d->sink;
        if (sink.dir)   /* (forward mode: this vertex's sums alone, then added to its pixel) */
            memset(sink.forward, 0, sizeof sink.forward);
        d_path_deriv_rays(b->p->scene, &b->popts, &dv->v, &d->rays[dv->ray0], &d->found[dv->ray0], dv->n, dv->d_beta,
                          &sink);
        dr_est_sample_done(b, dv->px, &sink);
    }
    d->n_verts = 0;
    d->n_rays = 0;
}

/* What d_path_deriv_sample does at replay vertex v, deferred: its new
 * directions are drawn now (from smp's sub-streams, which the replay does
 * not advance), their walks and terms at the next flush. */
static void deferred_add(struct deferred_ctx *c, const struct dr_path_vertex *v, const struct dr_sampler *smp,
                         dr_vec3 d_beta)
{
    if (dr_is_black(d_beta))
        return;   /* (as d_path_deriv_sample: no term, and no rays drawn) */
    struct deferred *d = c->j->deferred[c->thread];
    if (d->n_verts == DEFERRED_VERTICES)
        deferred_flush(c->j, c->thread);
    struct deferred_vertex *dv = &d->verts[d->n_verts++];
    dv->v = *v;
    dv->d_beta = d_beta;
    dv->px = c->px;
    dv->ray0 = d->n_rays;
    dv->n = dr_path_deriv_rays(c->j->b.p->scene, &c->j->b.popts, v, smp, &d->rays[d->n_rays]);
    d->n_rays += dv->n;
}

/* The replay of pixel px's sample sidx, one path at a time, given its
 * adjoint, its primal walk's sums (NULL: walked first here) and ray answers
 * (log; NULL: traced), and the walker's options (NULL: the run's). */
static void replay_one(struct prb_job *j, int thread, int64_t px, int sidx, dr_vec3 adj,
                       const struct primal_sums *sums, const struct dr_wave_log *log, const struct dr_path_opts *opts,
                       struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    struct dr_medium_record mrec;
    struct dr_path_vertex prev;
    struct dr_sampler smp;
    dr_vec3 o, d;
    struct deferred_ctx dc = {j, thread, px};
    struct walk w = {.adj = adj, .mrec = &mrec, .prev = &prev, .log = log, .opts = opts};
    dr_est_camera_ray(b, thread, px, sidx, &smp, &o, &d);
    if (sums)
        w.L = (struct prb_radiance){sums->L.L_true, sums->L.L_sub}, w.vertices = sums->vertices;
    else
        walk(b, smp, o, d, &w, &b->thr[thread].rays);
    if (!dr_v3_finite(w.L.true_) || !dr_v3_finite(w.L.sub)) {
        b->thr[thread].invalid++;
        return;
    }
    w.sink = sink;
    w.deferred = j->deferring[thread] ? &dc : NULL;
    walk(b, smp, o, d, &w, &b->thr[thread].rays);
    dr_est_sample_done(b, px, sink);
}

/* Pixel px's samples' replays one path at a time, given their adjoints
 * (attached sampling: prb_attached.c's; else walk's), and their primal
 * walks' sums where they were walked already (sums, by sample: the cross
 * primal's, or the arrays'; NULL: each path's primal is walked first) and
 * ray answers where the arrays logged them (logs, by sample; NULL:
 * traced). In a scene with media, in_media (by sample; NULL: all) says
 * which paths met a medium: the others replay without the media's stages,
 * from their logs (prb_job.outside_media). */
static void pixel_replays(struct prb_job *j, int thread, int64_t px, const dr_vec3 *adj,
                          const struct primal_sums *sums, const struct dr_wave_log *logs, const bool *in_media,
                          struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    if (j->attached) {
        attached_pixel(j, thread, px, adj, sums, logs, sink);
        return;
    }
    for (int sidx = 0; sidx < b->p->spp; sidx++)
        /* (a black adjoint: in cross mode, this sample does not matter to
         * the loss; no_term: nothing to replay, as in attached_pixel) */
        if (!dr_is_black(adj[sidx]) && !(sums && sums[sidx].no_term))
            replay_one(j, thread, px, sidx, adj[sidx], sums ? &sums[sidx] : NULL, logs ? &logs[sidx] : NULL,
                       in_media && !in_media[sidx] ? &j->outside_media : NULL, sink);
}

/* In a scene with media, the replays of a group's n samples whose paths met
 * no medium and have a derivative term (items->order): in the arrays, as
 * the wavefront's, without the media's stages (prb_job.outside_media: such
 * a path is the same there); one path at a time where there is no memory
 * for them. */
static void media_replays(struct prb_job *j, int thread, struct park_ctx *c, int32_t n, struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    const struct parked_samples *it = c->items;
    const struct dr_wave_soa_replay r = {c, it->order, it->walk.L, it->walk.L_sub, it->walk.last_diff, it->walk.log,
                                         soa_replay_vertex};
    if (dr_wave_soa_replay(j->soas[thread], b->p->scene, &j->outside_media, n, soa_replay_start, soa_replay_start8, c,
                           &r, &b->thr[thread].rays))
        return;
    const int spp = b->p->spp;
    for (int32_t k = 0; k < n; k++) {
        const int32_t i = it->order[k];
        const struct primal_sums sums = {{it->walk.L[i], it->walk.L_sub[i]}, 0, false};
        replay_one(j, thread, c->px[i / spp], i % spp, it->adj[i], &sums, it->walk.log ? &it->walk.log[i] : NULL,
                   &j->outside_media, sink);
    }
}

/* One path at a time, pixels [begin, end) (at most PIXEL_CHUNK): the
 * primal walks of a group's samples in the arrays (wave_soa.h: their sums
 * are the one-path walk's, bit for bit, and their ray answers are logged),
 * then each pixel's adjoints (with the cross primal from those sums, else
 * the loss's; pixels that do not matter to the loss are not walked) and its
 * samples' replays (pixel_replays, given the sums and the logs). In a scene
 * with media (j->media_arrays) the arrays hand back the paths that meet a
 * medium, whose primal walks are then made one path at a time here; a
 * path that met none and has no derivative term is not replayed (with media
 * parameters alone, that is most of them), those with a term replay in the
 * arrays after the group (media_replays). Returns the first pixel not
 * done: where the arrays do not apply or there is no memory for them,
 * prb_pixels walks the rest one path at a time. */
static int64_t arrays_pixels(struct prb_job *j, int thread, int64_t begin, int64_t end, struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    const int spp = b->p->spp;
    const int64_t group = park_group(spp);
    struct parked_samples *it = &j->items[thread];
    const bool media = j->media_arrays;
    if (!(media || dr_wave_soa_walks_apply(b->p->scene, &b->popts)) || !parked_make(it, group * spp) ||
        !(j->soas[thread] || (j->soas[thread] = dr_wave_soa_create())))
        return begin;
    struct dr_wave_soa_walks sums = it->walk;   /* (with ray answers where they fit LOGGED_ITEMS) */
    if (media)   /* (the logs of the paths that met a medium go unread: dr_wave_log_step traces there) */
        sums.in_media = it->in_media;
    dr_vec3 *adj = j->adj[thread];
    int64_t px[PIXEL_CHUNK], n_all = 0;
    dr_vec3 px_adj[PIXEL_CHUNK];   /* (but with the cross primal) */
    for (int64_t p = begin; p < end; p++)
        if (b->p->cross || dr_est_sample_adjoint(b, p, &px_adj[n_all]))
            px[n_all++] = p;
    for (int64_t first = 0; first < n_all; first += group) {
        const int64_t n_px = n_all - first < group ? n_all - first : group;
        struct park_ctx c = {.run = {j, thread}, .sink = *sink, .px = px + first, .items = it};
        if (!dr_wave_soa_walk(j->soas[thread], b->p->scene, &b->popts, n_px * spp, soa_start, soa_start8, &c, &sums,
                              &b->thr[thread].rays))
            return px[first];
        int32_t n_arrays = 0;   /* (media: the replays for the arrays, it->order) */
        for (int64_t k = 0; k < n_px; k++) {
            for (int sidx = 0; sidx < spp; sidx++) {
                const int64_t i = k * spp + sidx;
                struct primal_sums *p = &j->sums[thread][sidx];
                if (media && it->in_media[i])
                    *p = one_path_primal(b, thread, px[first + k], sidx);
                else
                    *p = (struct primal_sums){{sums.L[i], sums.L_sub[i]}, 0,
                                              sums.last_diff[i] == 0 && dr_v3_finite(sums.L[i]) &&
                                                  dr_v3_finite(sums.L_sub[i])};
                if (b->p->cross)
                    adj[sidx] = dr_v3_finite(p->L.L_true) && dr_v3_finite(p->L.L_sub) ? p->L.L_true : dr_v3s(0.0);
                else
                    adj[sidx] = px_adj[first + k];
            }
            if (b->p->cross && !cross_adjoints(b, px[first + k], adj))
                continue;
            for (int sidx = 0; media && sidx < spp; sidx++) {
                const int64_t i = k * spp + sidx;
                const struct primal_sums *p = &j->sums[thread][sidx];
                if (it->in_media[i] || dr_is_black(adj[sidx]) || !dr_v3_finite(p->L.L_true) ||
                    !dr_v3_finite(p->L.L_sub))
                    continue;
                if (sums.last_diff[i] > 0)   /* (a term: replayed in the arrays below) */
                    it->adj[i] = adj[sidx], it->order[n_arrays++] = (int32_t)i;
                adj[sidx] = dr_v3s(0.0);   /* (else no term: its replay would add nothing) */
            }
            pixel_replays(j, thread, px[first + k], adj, j->sums[thread], sums.log ? &sums.log[k * spp] : NULL,
                          media ? &it->in_media[k * spp] : NULL, sink);
        }
        if (n_arrays > 0)
            media_replays(j, thread, &c, n_arrays, sink);
    }
    return end;
}

static void prb_pixels(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct prb_job *j = ctx;
    struct dr_est_base *b = &j->b;
    struct dr_grad_sink sink = dr_est_sink_begin(b, thread);
    if (j->wave && end - begin <= PIXEL_CHUNK && wave_pixels(j, thread, begin, end, sink)) {
        dr_est_sink_end(b, thread);
        return;
    }
    j->deferring[thread] = deferred_begin(j, thread, &sink);
    if (j->sums[thread] && end - begin <= PIXEL_CHUNK)
        begin = arrays_pixels(j, thread, begin, end, &sink);   /* (the rest, if any: below) */
    dr_vec3 *adj = j->adj[thread];   /* by sample (all the same but in cross mode) */
    for (int64_t px = begin; px < end; px++)   /* (pixel_adjoints walks the cross primal into j->sums) */
        if (pixel_adjoints(j, thread, px, adj))   /* (else this pixel does not matter to the loss) */
            pixel_replays(j, thread, px, adj, b->p->cross ? j->sums[thread] : NULL, NULL, NULL, &sink);
    if (j->deferring[thread])
        deferred_flush(j, thread);
    dr_est_sink_end(b, thread);
}

static int prb_run(struct dr_est_base *b)
{
    struct prb_job *j = (struct prb_job *)b;
    const enum dr_sampling run = dr_est_sampling_run(b->p);
    if (run == DR_SAMPLING_ATTACHED || run == DR_SAMPLING_MIS) {   /* mis: both from one replay */
        j->attached = true;
        const struct dr_scene *s = b->p->scene;
        j->radius = 0.5 * dr_length(dr_sub(s->bbox_max, s->bbox_min));
        if (!(j->radius > 0.0) || !isfinite(j->radius))
            j->radius = 1.0;
    }
    /* every run that is detached in the end takes the wavefront or the
     * arrays, --sampling derivative without a BSDF parameter included; the
     * one-path walk is a test's (one_path_walks: wave_against_one_path) */
    const bool detached = run == DR_SAMPLING_DETACHED && !b->p->one_path_walks;
    j->wave = detached && !(b->popts.stages & DR_STAGE_MEDIA);
    j->media_arrays = detached && dr_wave_soa_media_walks_apply(b->p->scene, &b->popts);
    j->outside_media = b->popts;
    j->outside_media.stages &= ~(unsigned)(DR_STAGE_MEDIA | DR_STAGE_DIELECTRIC);
    /* one path at a time: the primal walks' sums, the cross primal's or
     * the arrays' (arrays_pixels), which the replays then need not walk */
    const bool arrays = j->media_arrays || dr_wave_soa_walks_apply(b->p->scene, &b->popts);
    const bool keep_sums = !j->wave && (b->p->cross || arrays);
    for (int t = 0; t < b->acc.threads; t++)
        if (!(j->adj[t] = malloc(sizeof(dr_vec3) * (size_t)b->p->spp)) ||
            (keep_sums && !(j->sums[t] = malloc(sizeof(struct primal_sums) * (size_t)b->p->spp)))) {
            dr_set_error("out of memory (%d samples per pixel)", b->p->spp);
            return DR_ERR_NOMEM;
        }
    /* what the workers hold besides the gradient: the samples' adjoints (and
     * the cross primal's sums), and on the wavefront the lanes, the parked
     * samples and the arrays (wave_pixels, arrays_pixels) */
    uint64_t per_thread = sizeof(dr_vec3) * (uint64_t)b->p->spp;
    if (keep_sums)
        per_thread += sizeof(struct primal_sums) * (uint64_t)b->p->spp;
    if (keep_sums && arrays)   /* (arrays_pixels) */
        per_thread += parked_bytes(park_group(b->p->spp) * b->p->spp) + dr_wave_soa_walk_bytes();
    if (j->wave) {
        per_thread += dr_wave_bytes() + parked_bytes(park_group(b->p->spp) * b->p->spp);
        if (arrays)
            per_thread += dr_wave_soa_walk_bytes();
    }
    j->defer = dr_sampling_is_derivative(run);
    j->defer_rays = j->defer ? dr_path_deriv_max_rays(b->p->scene, &b->popts) : 0;
    if (j->defer)   /* (deferred_begin: the directions, and the lanes) */
        per_thread += deferred_bytes(j->defer_rays) + (j->wave ? 0 : dr_wave_bytes());
    b->scratch_bytes = per_thread * (uint64_t)b->acc.threads;   /* (at most prb_thread_bytes each) */
    return dr_parallel_for_static((int64_t)b->p->width * b->p->height, PIXEL_CHUNK, b->acc.threads, prb_pixels, j);
}

static void prb_release(struct dr_est_base *b)
{
    struct prb_job *j = (struct prb_job *)b;
    for (int t = 0; t < DR_MAX_THREADS; t++) {
        dr_wave_destroy(j->waves[t]);
        dr_wave_soa_destroy(j->soas[t]);
        parked_free(&j->items[t]);
        free(j->adj[t]);
        free(j->sums[t]);
        deferred_free(j->deferred[t]);
    }
}

/* At most prb_run's per_thread: the wavefront, the arrays and derivative
 * sampling's deferred directions (which never all serve one run). */
static uint64_t prb_thread_bytes(int spp)
{
    return sizeof(dr_vec3) * (uint64_t)spp + dr_wave_bytes() + parked_bytes(park_group(spp) * spp) +
           dr_wave_soa_walk_bytes() + deferred_bytes(DR_DERIV_RAYS);
}

const struct dr_estimator_ops dr_estimator_prb = {
    .name = "prb",
    .summary = "path replay backpropagation: primal pass + replay, constant memory per path, time linear in depth",
    .sampling = (1u << DR_SAMPLING_DETACHED) | (1u << DR_SAMPLING_ATTACHED) | (1u << DR_SAMPLING_MIS) |
                (1u << DR_SAMPLING_DERIVATIVE) | (1u << DR_SAMPLING_DERIVATIVE_ROUGHNESS),
    .job_size = sizeof(struct prb_job),
    .run = prb_run,
    .release = prb_release,
    .thread_bytes = prb_thread_bytes,
};
