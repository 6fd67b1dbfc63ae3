/* The packet tracer's lanes (wavefront.h). */
#include "wavefront.h"

#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "material.h"
#include "path_deriv.h"
#include "path_simd.h"
#include "wave_soa.h"

struct lane {
    /* what every pass over the lanes reads first, together */
    bool replaying;                   /* this walk replays the last one: answers from the log */
    bool occluded;                    /* the shadow ray's */
    bool simd;                        /* this vertex is shaded eight lanes at a time (path_simd.h) */
    bool simd_more;                   /* ... and its path goes on (dr_path8_continue) */
    bool whole_next;                  /* its walk's next vertex is whole (dr_wave_ops.next_whole) */
    enum dr_step_next next;           /* what the hit stage asked for */
    int64_t tri;                      /* the trace's answer */
    struct dr_path_state st;
    struct dr_sampler smp;
    struct dr_wave_arrival arrival;   /* the throughput v was reached with */
    struct dr_shadow_ray shadow;
    _Alignas(16) unsigned char user[DR_WAVE_USER_BYTES];
    struct dr_path_vertex v;
    struct dr_wave_log log;           /* the walk's ray answers, for a replay */
};

/* The rays of one batch, in the layout dr_accel_*_many reads. */
struct batch {
    dr_vec3 o[DR_WAVE_LANES], d[DR_WAVE_LANES];
    double tmax[DR_WAVE_LANES];
    uint64_t key[DR_WAVE_LANES];
    int owner[DR_WAVE_LANES];   /* the lane each ray belongs to */
    int n;
};

struct dr_wave {
    struct lane lane[DR_WAVE_LANES];
    int live[DR_WAVE_LANES];    /* indices of the lanes with a path, in start order */
    int free_[DR_WAVE_LANES];   /* and of those without */
    struct batch rays;
    int64_t tri[DR_WAVE_LANES];       /* by ray of the batch */
    bool occluded[DR_WAVE_LANES];
    bool prefetch;                    /* locate all hits before shading any (dr_wave_prefetches) */
    bool simd;                        /* shade the lanes path_simd.h accepts eight at a time */
    bool simd_diff;                   /* ... hits on materials with a BSDF parameter too (bsdf_terms) */
    bool env8;                        /* ... and the rays that left the scene (an environment stage
                                         dr_path8_escaped computes: escaped_group) */
    int n_groups;                     /* ... in these groups this step */
    int group_lane[DR_WAVE_LANES / DR_SIMD_W][DR_SIMD_W];
    struct dr_path8 group[DR_WAVE_LANES / DR_SIMD_W];
    struct dr_wave_soa *soa;          /* dr_wave_radiance's arrays, made on first use (wave_soa.h) */
};

/* Is the answer for the lane's current vertex in its log (a replay)? */
static bool from_log(const struct lane *l)
{
    return l->replaying && l->st.depth <= l->log.n;
}

/* Zeroed: a field no stage wrote reads the same on every run (the eight-lane
 * stages fill only part of a vertex, path_simd.h). */
struct dr_wave *dr_wave_create(void)
{
    size_t bytes = (sizeof(struct dr_wave) + 63) / 64 * 64;
    struct dr_wave *w = aligned_alloc(64, bytes);
    if (w)
        memset(w, 0, bytes);
    return w;
}

void dr_wave_destroy(struct dr_wave *wave)
{
    if (wave)
        dr_wave_soa_destroy(wave->soa);
    free(wave);
}

size_t dr_wave_bytes(void)
{
    return sizeof(struct dr_wave);
}

static void add_ray(struct batch *b, int owner, dr_vec3 o, dr_vec3 d, double tmax, uint64_t key)
{
    b->o[b->n] = o;
    b->d[b->n] = d;
    b->tmax[b->n] = tmax;
    b->key[b->n] = key;
    b->owner[b->n++] = owner;
}

static struct dr_accel_rays accel_rays(const struct batch *b)
{
    return (struct dr_accel_rays){.n = b->n, .o = b->o, .d = b->d, .tmax = b->tmax, .key = b->key};
}

/* The trace stage of every live lane: one batch of extension (or camera)
 * rays, but for replaying lanes whose answer is logged. */
static void trace_live(struct dr_wave *w, int n_live, const struct dr_scene *s, struct dr_ray_counts *counts)
{
    w->rays.n = 0;
    bool later = false;   /* extension rays wait for the camera rays */
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        l->arrival = (struct dr_wave_arrival){l->st.beta, l->st.ratio};
        dr_path_step_begin(&l->st, &l->v);
        if (from_log(l)) {
            l->tri = l->log.tri[l->st.depth - 1];
            continue;
        }
        dr_path_count_trace(&l->st, counts);
        if (l->st.depth == 1)
            add_ray(&w->rays, w->live[i], l->st.o, l->st.d, INFINITY, dr_path_trace_key(s, &l->st, &l->smp));
        else
            later = true;
    }
    /* Camera rays first, in start order: the lanes started together are
     * consecutive samples of a pixel, whose rays Embree traces fastest as
     * coherent packets. Then the rest. */
    int coherent = w->rays.n;
    for (int i = 0; later && i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        if (l->st.depth > 1 && !from_log(l))
            add_ray(&w->rays, w->live[i], l->st.o, l->st.d, INFINITY, dr_path_trace_key(s, &l->st, &l->smp));
    }
    struct dr_accel_rays r = accel_rays(&w->rays);
    r.coherent = coherent;
    dr_accel_intersect_many(s->accel, &r, w->tri);
    for (int k = 0; k < w->rays.n; k++) {
        struct lane *l = &w->lane[w->rays.owner[k]];
        l->tri = w->tri[k];
        if (!l->replaying && l->st.depth <= DR_WAVE_REPLAY_DEPTH)
            l->log.tri[(l->log.n = l->st.depth) - 1] = l->tri;
        if (w->prefetch && l->tri >= 0)
            dr_mesh_prefetch_triangle(&s->mesh, l->tri);
    }
}

/* Before shading (w->prefetch): every lane's hit point, and the texels its
 * shading will read asked for, so that the cache misses of a big scene or
 * texture overlap (geometry.h); the triangles' records were asked for as the
 * trace's answers came in, the vertices one pass before the hit points. */
static void locate_live(struct dr_wave *w, int n_live, const struct dr_scene *s)
{
    for (int i = 0; i < n_live; i++) {
        const struct lane *l = &w->lane[w->live[i]];
        if (l->tri >= 0)
            dr_mesh_prefetch_vertices(&s->mesh, l->tri);
    }
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        if (l->simd && !dr_path8_reads_textures(s, l->tri))
            continue;   /* the eight-lane stages locate their own */
        dr_path_step_locate(s, &l->st, &l->v, l->tri);
        if (l->tri >= 0 && s->n_textures > 0)
            dr_material_prefetch(s, &l->v.hit);
    }
}

/* Which lanes' vertices the eight-lane stages shade (path_simd.h). */
static void classify_live(struct dr_wave *w, int n_live, const struct dr_scene *s, const struct dr_path_opts *opts)
{
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        l->simd = w->simd && !l->whole_next &&
                  (w->simd_diff ? l->tri >= 0 : dr_path8_hit(s, opts, l->tri));
    }
}

/* dr_path8_shade of the lanes k[0..n-1], as the wave's next group. */
static void shade_group(struct dr_wave *w, const int *k, int n, const struct dr_scene *s,
                        const struct dr_path_opts *opts)
{
    struct dr_path_state *st[DR_SIMD_W] = {0};   /* (n >= 1: the kernels read [0..n-1]) */
    struct dr_sampler *smp[DR_SIMD_W] = {0};
    struct dr_path_vertex *v[DR_SIMD_W] = {0};
    struct dr_shadow_ray *shadow[DR_SIMD_W] = {0};
    int64_t tri[DR_SIMD_W] = {0};
    enum dr_step_next next[DR_SIMD_W];
    int g = w->n_groups++;
    for (int i = 0; i < n; i++) {
        struct lane *l = &w->lane[k[i]];
        st[i] = &l->st, smp[i] = &l->smp, v[i] = &l->v, shadow[i] = &l->shadow, tri[i] = l->tri;
        w->group_lane[g][i] = k[i];
    }
    dr_path8_shade(s, opts, n, st, smp, v, tri, shadow, next, w->prefetch, &w->group[g]);
    for (int i = 0; i < n; i++)
        w->lane[k[i]].next = next[i];
}

/* stage_escaped of the lanes k[0..n-1] (n <= DR_SIMD_W) whose rays left the
 * scene, eight at a time (dr_path8_escaped: the same bits); the rest of
 * their vertex is dr_path_step_begin's. */
static void escaped_group(struct dr_wave *w, const int *k, int n, const struct dr_scene *s)
{
    dr_m8 on;
    dr_v3x8 d;
    dr_f8 depth, prev_pdf, prev_sky;
    for (int i = 0; i < DR_SIMD_W; i++) {
        const struct dr_path_state *st = &w->lane[k[i < n ? i : 0]].st;   /* (padding repeats lane 0) */
        on[i] = i < n ? -1 : 0;
        d.x[i] = st->d.x, d.y[i] = st->d.y, d.z[i] = st->d.z;
        depth[i] = st->depth;
        prev_pdf[i] = st->prev_pdf;
        prev_sky[i] = st->prev_sky;
    }
    dr_v3x8 Le;
    dr_f8 emit_w;
    struct dr_env8_lookup at;
    const bool looked_up = dr_path8_escaped(s, on, d, depth, prev_pdf, prev_sky, &Le, &emit_w, &at);
    for (int i = 0; i < n; i++) {
        struct lane *l = &w->lane[k[i]];
        l->v.kind = DR_VERTEX_ESCAPED;
        l->v.emits = true;
        l->v.Le = dr_v3x8_get(&Le, i);
        l->v.emit_w = emit_w[i];
        if (looked_up)   /* (for the adjoint, d_env_radiance_at) */
            l->v.env_at = (struct dr_env_lookup){true, at.u[i], at.v[i], dr_v3x8_get(&at.map, i)};
        l->next = DR_STEP_END;
    }
}

/* Lane k's shadow ray into the batch, once its shading asked for one (a
 * replaying lane's logged answer stands in for the ray). */
static inline void collect_shadow(struct dr_wave *w, int k, struct dr_ray_counts *counts)
{
    struct lane *l = &w->lane[k];
    l->occluded = false;
    if (l->next != DR_STEP_SHADOW)
        return;
    if (from_log(l)) {   /* (no ray when tmax is not > 0: nee_end knows) */
        l->occluded = l->shadow.tmax > 0.0 && l->log.occ[l->st.depth - 1];
        return;
    }
    counts->shadow++;   /* counted as dr_path_step counts it */
    if (l->shadow.tmax > 0.0)
        add_ray(&w->rays, k, l->shadow.o, l->shadow.d, l->shadow.tmax, l->shadow.key);
}

/* The hit stage: shading up to the shadow ray (the lanes path_simd.h
 * accepts eight at a time, the others one by one); then the shadow rays.
 * Without eight-lane groups each lane's ray is collected as it is shaded. */
static void shade_live(struct dr_wave *w, int n_live, const struct dr_scene *s, const struct dr_path_opts *opts,
                       struct dr_ray_counts *counts)
{
    w->rays.n = 0;
    w->n_groups = 0;
    int pending[DR_SIMD_W], n_pending = 0, n_simd = 0, n_replayed = 0;
    int left[DR_SIMD_W], n_left = 0;   /* lanes whose rays left the scene, for escaped_group */
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        if (l->tri < 0 && w->env8) {
            left[n_left++] = w->live[i];
            if (n_left == DR_SIMD_W) {
                escaped_group(w, left, n_left, s);
                n_left = 0;
            }
            continue;
        }
        if (l->simd) {
            n_simd++;
            n_replayed += l->replaying;
            pending[n_pending++] = w->live[i];
            if (n_pending == DR_SIMD_W) {
                shade_group(w, pending, n_pending, s, opts);
                n_pending = 0;
            }
            continue;
        }
        l->next = w->prefetch ? dr_path_step_shade(s, opts, &l->st, &l->smp, &l->v, l->tri, &l->shadow)
                              : dr_path_step_hit(s, opts, &l->st, &l->smp, &l->v, l->tri, &l->shadow);
        if (!w->simd)
            collect_shadow(w, w->live[i], counts);
    }
    if (n_pending >= DR_SIMD_W / 2) {
        shade_group(w, pending, n_pending, s, opts);
    } else {   /* a few left over: cheaper one by one than as a group of mostly padding */
        for (int i = 0; i < n_pending; i++) {
            struct lane *l = &w->lane[pending[i]];
            l->simd = false;
            n_replayed -= l->replaying;
            /* (locate_live located it if it reads textures: not twice) */
            l->next = w->prefetch && dr_path8_reads_textures(s, l->tri)
                          ? dr_path_step_shade(s, opts, &l->st, &l->smp, &l->v, l->tri, &l->shadow)
                          : dr_path_step_hit(s, opts, &l->st, &l->smp, &l->v, l->tri, &l->shadow);
        }
        n_simd -= n_pending;
    }
    if (n_left > 0)
        escaped_group(w, left, n_left, s);
    counts->simd_vertices += (uint64_t)n_simd;
    counts->simd_replayed += (uint64_t)n_replayed;
    for (int i = 0; w->simd && i < n_live; i++)
        collect_shadow(w, w->live[i], counts);
    struct dr_accel_rays r = accel_rays(&w->rays);
    dr_accel_occluded_many(s->accel, &r, w->occluded);
    for (int k = 0; k < w->rays.n; k++) {
        struct lane *l = &w->lane[w->rays.owner[k]];
        l->occluded = w->occluded[k];
        if (!l->replaying && l->st.depth <= DR_WAVE_REPLAY_DEPTH)
            l->log.occ[l->st.depth - 1] = l->occluded;
    }
}

/* Starts the lane's next walk (or its item's first) from o, d: the state
 * as the caller wants it (start_state), and whether its first vertex is
 * whole (next_whole). */
static void begin_walk(struct lane *l, dr_vec3 o, dr_vec3 d, enum dr_wave_next how, const struct dr_wave_ops *ops,
                       void *ctx)
{
    dr_path_start(&l->st, o, d);
    if (ops->start_state)
        ops->start_state(ctx, l->user, &l->st);
    l->whole_next = ops->next_whole && ops->next_whole(ctx, l->user);
    l->replaying = how == DR_WAVE_REPLAY;
    if (!l->replaying)
        l->log.n = 0;
}

/* The end of the step: next-event results, the continuation, the vertex to
 * the caller; lanes whose item ended go to the free list. Returns how many
 * lanes live on (compacted, in order). */
static int finish_live(struct dr_wave *w, int n_live, int *n_free, const struct dr_scene *s,
                       const struct dr_path_opts *opts, const struct dr_wave_ops *ops, void *ctx)
{
    for (int g = 0; g < w->n_groups; g++) {   /* the eight-lane groups' ends first */
        struct dr_path_state *st[DR_SIMD_W];
        struct dr_path_vertex *v[DR_SIMD_W];
        bool occluded[DR_SIMD_W], more[DR_SIMD_W];
        int n = w->group[g].n;
        for (int i = 0; i < n; i++) {
            struct lane *l = &w->lane[w->group_lane[g][i]];
            st[i] = &l->st, v[i] = &l->v, occluded[i] = l->occluded;
        }
        dr_path8_continue(opts, &w->group[g], st, v, occluded, more);
        for (int i = 0; i < n; i++)
            w->lane[w->group_lane[g][i]].simd_more = more[i];
    }
    int kept = 0;
    for (int i = 0; i < n_live; i++) {
        int k = w->live[i];
        struct lane *l = &w->lane[k];
        bool more;
        if (l->simd) {
            more = l->simd_more;
        } else {
            if (l->next == DR_STEP_SHADOW)
                dr_path_nee_end(s, &l->v, &l->shadow, l->occluded);
            more = l->next != DR_STEP_END && dr_path_stage_continue(opts, &l->st, &l->v);
        }
        if (!ops->vertex(ctx, l->user, &l->arrival, &l->v, &l->smp, more))
            more = false;
        l->whole_next = more && ops->next_whole && ops->next_whole(ctx, l->user);
        if (!more && ops->keep_log && !l->replaying)
            ops->keep_log(ctx, l->user, &l->log);
        dr_vec3 o, d;
        enum dr_wave_next how = more ? DR_WAVE_WALK : ops->walk_end(ctx, l->user, &l->smp, &o, &d);
        if (how == DR_WAVE_DONE) {
            w->free_[(*n_free)++] = k;
            continue;
        }
        if (!more)
            begin_walk(l, o, d, how, ops, ctx);
        w->live[kept++] = k;
    }
    return kept;
}

/* (wavefront.h) The threshold is a core's L2 cache here. */
bool dr_wave_prefetches(const struct dr_scene *s)
{
    const struct dr_mesh *m = &s->mesh;
    size_t bytes = (size_t)m->n_vertices * (3 + 3 + 2) * sizeof(float) +
                   (size_t)m->n_triangles * (3 * sizeof(uint32_t) + 4 * sizeof(double) + sizeof(int32_t) + 1);
    return s->n_textures > 0 || bytes > ((size_t)1 << 20);
}

void dr_wave_run(struct dr_wave *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                 const struct dr_wave_ops *ops, void *ctx, struct dr_ray_counts *counts)
{
    w->prefetch = dr_wave_prefetches(s);
    w->simd = ops->partial_vertices &&
              (dr_path8_applies(s, opts) || (ops->light_terms && dr_path8_walks_apply(s, opts)));
    w->simd_diff = ops->bsdf_terms;
    /* (an escaped vertex is whole either way: stage_escaped sets only these) */
    w->env8 = (opts->stages & DR_STAGE_ENV) && !(opts->stages & DR_STAGE_MEDIA) && dr_path8_env_eight(s);
    int n_live = 0, n_free = DR_WAVE_LANES;
    for (int k = 0; k < DR_WAVE_LANES; k++)
        w->free_[k] = DR_WAVE_LANES - 1 - k;   /* lane 0 is handed out first */
    int64_t next = 0;
    while (next < n || n_live > 0) {
        while (n_free > 0 && next < n) {   /* refill: new items in order */
            int k = w->free_[--n_free];
            struct lane *l = &w->lane[k];
            dr_vec3 o, d;
            memset(l->user, 0, sizeof l->user);
            ops->start(ctx, next++, l->user, &l->smp, &o, &d);
            const struct dr_wave_log *log = ops->replay_log ? ops->replay_log(ctx, l->user) : NULL;
            if (log)
                dr_wave_log_copy(&l->log, log);
            begin_walk(l, o, d, log ? DR_WAVE_REPLAY : DR_WAVE_WALK, ops, ctx);
            w->live[n_live++] = k;
        }
        trace_live(w, n_live, s, counts);
        classify_live(w, n_live, s, opts);
        if (w->prefetch)
            locate_live(w, n_live, s);
        shade_live(w, n_live, s, opts, counts);
        n_live = finish_live(w, n_live, &n_free, s, opts, ops, ctx);
    }
}

bool dr_wave_log_step(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_wave_log *log,
                      struct dr_path_state *st, struct dr_sampler *smp, struct dr_path_vertex *v,
                      struct dr_ray_counts *counts)
{
    if (!log || st->depth >= log->n || (opts->stages & DR_STAGE_MEDIA))
        return dr_path_step(s, opts, st, smp, v, counts);
    /* dr_path_step's composition (path.h), the queries answered from the log */
    dr_path_step_begin(st, v);
    struct dr_shadow_ray shadow;
    switch (dr_path_step_hit(s, opts, st, smp, v, log->tri[st->depth - 1], &shadow)) {
    case DR_STEP_END:
        return false;
    case DR_STEP_SHADOW:
        dr_path_nee_end(s, v, &shadow, shadow.tmax > 0.0 && log->occ[st->depth - 1]);
        break;
    case DR_STEP_CONTINUE:
        break;
    }
    return dr_path_stage_continue(opts, st, v);
}

/* ------------------------------------------------------------- radiance */

struct radiance_ctx {
    dr_wave_start_fn start;
    void *ctx;
    dr_vec3 *L;
};
struct radiance_lane {
    int64_t path;
    dr_vec3 L;
};
_Static_assert(sizeof(struct radiance_lane) <= DR_WAVE_USER_BYTES, "lane state fits");

static void radiance_start(void *ctx, int64_t i, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    struct radiance_ctx *c = ctx;
    struct radiance_lane *r = user;
    r->path = i;
    r->L = dr_v3s(0.0);
    c->start(c->ctx, i, smp, o, d);
}

static bool radiance_vertex(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                            struct dr_sampler *smp, bool more)
{
    (void)ctx, (void)smp, (void)more;
    struct radiance_lane *r = user;
    r->L = dr_add(r->L, dr_mul(a->beta, dr_path_vertex_term(v)));
    return true;
}

static enum dr_wave_next radiance_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)smp, (void)o, (void)d;
    struct radiance_ctx *c = ctx;
    const struct radiance_lane *r = user;
    c->L[r->path] = r->L;
    return DR_WAVE_DONE;
}

void dr_wave_radiance(struct dr_wave *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, dr_vec3 *L,
                      struct dr_ray_counts *counts)
{
    if (dr_wave_soa_applies(s, opts) && (w->soa || (w->soa = dr_wave_soa_create()))) {
        dr_wave_soa_radiance(w->soa, s, opts, n, start, start8, ctx, L, counts);
        return;
    }   /* (out of memory for the arrays: the lanes, which need none) */
    if (!(opts->stages & DR_STAGE_MEDIA)) {
        dr_wave_radiance_lanes(w, s, opts, n, start, ctx, L, counts);
        return;
    }
    for (int64_t i = 0; i < n; i++) {   /* (media, which the lanes do not know: one path at a time) */
        struct dr_sampler smp;
        dr_vec3 o, d;
        start(ctx, i, &smp, &o, &d);
        L[i] = dr_path_radiance(s, opts, o, d, &smp, counts);
    }
}

void dr_wave_radiance_lanes(struct dr_wave *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                            dr_wave_start_fn start, void *ctx, dr_vec3 *L, struct dr_ray_counts *counts)
{
    static const struct dr_wave_ops ops = {.start = radiance_start, .vertex = radiance_vertex, .walk_end = radiance_end,
                                           .partial_vertices = true};
    struct radiance_ctx c = {start, ctx, L};
    dr_wave_run(w, s, opts, n, &ops, &c, counts);
}

/* ---------------------------------------- derivative sampling's radiance */

struct deriv_ctx {
    const struct dr_scene *s;
    const struct dr_path_opts *opts;
    const struct dr_deriv_ray *r;
    struct dr_deriv_light *out;
};
struct deriv_lane {
    int64_t ray;
    bool first;                /* its first vertex is next (whole: dr_path_deriv_first) */
    struct dr_deriv_light found;
};
_Static_assert(sizeof(struct deriv_lane) <= DR_WAVE_USER_BYTES, "lane state fits");

static void deriv_start(void *ctx, int64_t i, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct deriv_ctx *c = ctx;
    struct deriv_lane *l = user;
    l->ray = i;
    l->first = true;
    *smp = c->r[i].rng;
    *o = c->r[i].o;
    *d = c->r[i].d;
}

static void deriv_start_state(void *ctx, void *user, struct dr_path_state *st)
{
    const struct deriv_ctx *c = ctx;
    dr_path_deriv_start(c->s, c->opts, &c->r[((const struct deriv_lane *)user)->ray], st);
}

static bool deriv_next_whole(void *ctx, void *user)
{
    (void)ctx;
    return ((const struct deriv_lane *)user)->first;
}

static bool deriv_vertex(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                         struct dr_sampler *smp, bool more)
{
    (void)smp, (void)more;
    const struct deriv_ctx *c = ctx;
    struct deriv_lane *l = user;
    if (l->first)
        dr_path_deriv_first(c->s, c->opts, v, &l->found);
    else
        l->found.L_ind = dr_add(l->found.L_ind, dr_mul(a->beta, dr_path_vertex_term(v)));
    l->first = false;
    return true;
}

static enum dr_wave_next deriv_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)smp, (void)o, (void)d;
    const struct deriv_ctx *c = ctx;
    const struct deriv_lane *l = user;
    c->out[l->ray] = l->found;
    return DR_WAVE_DONE;
}

void dr_wave_deriv_radiance(struct dr_wave *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                            const struct dr_deriv_ray *r, struct dr_deriv_light *out, struct dr_ray_counts *counts)
{
    static const struct dr_wave_ops ops = {.start = deriv_start, .vertex = deriv_vertex, .walk_end = deriv_end,
                                           .partial_vertices = true, .next_whole = deriv_next_whole,
                                           .start_state = deriv_start_state};
    if (opts->stages & DR_STAGE_MEDIA) {   /* (media, which the lanes do not know: one path at a time) */
        for (int64_t i = 0; i < n; i++)
            dr_path_deriv_radiance(s, opts, &r[i], &out[i], counts);
        return;
    }
    struct dr_path_opts o = *opts;
    o.params = NULL;   /* (as dr_path_deriv_radiance) */
    struct deriv_ctx c = {s, &o, r, out};
    dr_wave_run(w, s, &o, n, &ops, &c, counts);
}
