/* Conventional reverse mode with a tape: the baseline PRB is measured against.
 *
 * Each worker records every vertex of a batch of paths (DR_TAPE_PATHS_PER_WORKER
 * by default, --batch N paths over all workers otherwise; whole pixels, every
 * sample of each, so at least one pixel's spp paths), then sweeps that
 * tape backward, path by path, from the last vertex to the first, carrying
 * the adjoint of the throughput:  abar_k = adj * e_k + abar_{k+1} * t_k,  and
 * the BSDF term of vertex k gets d t_k = abar_{k+1} * beta_k. No division by f
 * (unlike PRB), so with the same random numbers the two estimators agree to
 * rounding. Memory: (vertices per path) x (paths per batch), reported as
 * record_bytes.
 *
 * A worker records and sweeps its own batch with no barrier between them
 * (the loss's adjoint is known before the record), and the default batch is
 * small enough that the tape is swept while it is still in the cache: the
 * sweep reads back every byte the record wrote (1072 bytes per vertex with
 * a derivative term, 528 where that term is a light's alone: struct
 * tape_light; 56 per step without one: struct tape_step).
 * Under plain detached sampling the record runs on the packet tracer's
 * arrays (wave_soa.h; in a scene with media, for the paths that meet none:
 * record_soa), under the other samplings without media on its lanes
 * (wavefront.h), else one path at a time. On the packet tracer paths
 * advance together, so a path's vertices are not adjacent in the tape:
 * each vertex links to the one before it on its path. */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "common.h"
#include "medium_grad.h"
#include "error.h"
#include "path_deriv.h"
#include "wave_soa.h"
#include "wavefront.h"

struct tape_vertex {
    struct dr_path_vertex v;
    dr_vec3 bt;        /* true throughput arriving at the vertex */
    int64_t prev;      /* the path's vertex before this one (-1: the first; a link, see TAPE_STEP) */
    int32_t rays;      /* derivative sampling: its new directions' first index in the tape's rays */
    int32_t n_rays;    /* ... and how many (-1: not walked ahead: the sweep walks them) */
};

/* A vertex without a derivative term of its own (dr_path_vertex_has_derivative)
 * under plain detached sampling: the sweep needs only what it adds and how it
 * passes the throughput on, 56 bytes instead of a whole vertex's 900, so the
 * record copies and the sweep reads far less. */
struct tape_step {
    dr_vec3 e;         /* dr_path_vertex_term */
    dr_vec3 t;         /* the continuation factor f |cos| / pdf / q (0: the path ends) */
    int64_t prev;
};
/* A vertex whose derivative term is all in its light terms (no BSDF
 * parameter, not a medium vertex: dr_path_light_terms_hold), under plain
 * detached sampling: where a light has a parameter most vertices are such.
 * A step's part and what the light terms' adjoint reads, 528 bytes instead
 * of the whole vertex's 1072: the peer's box's emission gradient spent a
 * sixth of its time copying whole vertices and reading them back. */
struct tape_light {
    dr_vec3 e, t;      /* as a step's */
    dr_vec3 bt;        /* true throughput arriving at the vertex */
    int64_t prev;
    struct dr_path_light_terms terms;
};
/* Links (tape_vertex.prev, tape_path.last) with this bit name a tape_step,
 * with this one a tape_light. */
#define TAPE_STEP ((int64_t)1 << 62)
#define TAPE_LIGHT ((int64_t)1 << 61)

size_t dr_tape_vertex_bytes(bool derivative)
{
    return sizeof(struct tape_vertex) +
           (derivative ? DR_DERIV_RAYS * (sizeof(struct dr_deriv_ray) + sizeof(struct dr_deriv_light)) : 0);
}

struct tape_path {
    int64_t pixel;
    int64_t last;      /* index of its last vertex (-1: none yet); the links lead back */
    int count;
    bool dropped;      /* not finite: left out of the sweep */
    int moving;        /* attached sampling: first vertex whose sampling moves with a parameter (count: none) */
    bool derivative;   /* some vertex may have a derivative term (else the sweep would add nothing): set
                          by each whole vertex and light record (compact steps have none) */
    dr_vec3 adj;       /* d loss / d L of this sample (forward mode: ones; cross mode: set after the record) */
    uint64_t key;      /* its sampler's key: derivative sampling's sub-streams hang off it */
    dr_vec3 L;         /* its radiance (cross mode: the others' adjoints are taken without it) */
};

struct tape {
    struct tape_vertex *verts;
    int64_t n_verts, cap_verts;
    struct tape_step *steps;
    int64_t n_steps, cap_steps;
    struct tape_light *lights;
    int64_t n_lights, cap_lights;
    struct dr_medium_record *mrecs;   /* one per vertex, only when media parameters are requested */
    int64_t cap_mrecs;
    struct tape_path *paths;
    int64_t n_paths, cap_paths;
    struct dr_deriv_ray *rays;        /* derivative sampling: the sweep's new directions (walk_ahead) */
    struct dr_deriv_light *found;     /* ... what their radiance walks found */
    int64_t n_rays, cap_rays, cap_found;
    uint64_t peak;     /* this run's largest record, in bytes (the mappings may be larger:
                          they grow by doubling and are kept from earlier runs) */
    bool failed;       /* out of memory while recording */
};

struct tape_job {
    struct dr_est_base b;   /* first: the shared part */
    struct tape tapes[DR_MAX_THREADS];
    struct dr_wave *waves[DR_MAX_THREADS];   /* the packet tracer's lanes, per worker, made on first use */
    struct dr_wave_soa *soas[DR_MAX_THREADS];   /* ... or its arrays, where they apply (wave_soa.h) */
    int64_t *pixels[DR_MAX_THREADS];         /* ... and the batch's pixels that matter to the loss */
    int64_t batch;           /* pixels (all their samples) a worker records before it sweeps */
    bool wave;               /* no media, or media_arrays: the record runs on the packet tracer */
    bool media_arrays;       /* media: the paths that meet none are recorded in the arrays (record_soa) */
    bool *in_media[DR_MAX_THREADS];          /* ... the walk's marks, per worker (a batch's paths) */
    bool attached;           /* attached sampling (or mis), and some parameter enters a sampling map */
    bool derivative;         /* derivative sampling (path_deriv.h) */
    bool steps;              /* vertices without a derivative term are recorded as steps (tape_step) */
    bool steps_before_moving;   /* attached (or mis) on the lanes: ... before a path's first moving
                                   vertex (whole from it on: the attached sweep reads them) */
    bool steps_off_bsdf;        /* derivative sampling on the lanes: ... but after a vertex with a
                                   BSDF parameter (whole: sweep_derivative reads it as next) */
};

/* The tape's arrays live in mappings of their own. Grown with realloc, a
 * tape of tens of MB came from the heap (glibc's threshold for mapping a
 * block rises to 32 MB), so every doubling copied it into fresh memory and
 * every estimator run faulted it in again in 4 KiB pages: 124k page faults,
 * 1.3 s of kernel time in a 3.3 s gradient here. mremap moves pages without
 * copying, and transparent huge pages fault 2 MiB at a time. */
static void *map_grow(void *p, size_t old_bytes, size_t new_bytes)
{
    void *q = p ? mremap(p, old_bytes, new_bytes, MREMAP_MAYMOVE)
                : mmap(NULL, new_bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (q == MAP_FAILED)
        return NULL;
    madvise(q, new_bytes, MADV_HUGEPAGE);   /* advice only: failure changes nothing */
    return q;
}

static void map_free(void *p, int64_t cap, size_t elem)
{
    if (p)
        munmap(p, (size_t)cap * elem);
}

static bool grow(void **p, int64_t *cap, int64_t need, size_t elem)
{
    if (need <= *cap)
        return true;
    int64_t c = *cap > 0 ? *cap : 1024;
    while (c < need)
        c *= 2;
    void *q = map_grow(*p, (size_t)*cap * elem, (size_t)c * elem);
    if (!q)
        return false;
    *p = q;
    *cap = c;
    return true;
}

/* Bytes the record in tp holds now. */
static uint64_t tape_bytes(const struct tape *t, bool media)
{
    return (uint64_t)t->n_verts * (sizeof(struct tape_vertex) + (media ? sizeof(struct dr_medium_record) : 0)) +
           (uint64_t)t->n_steps * sizeof(struct tape_step) + (uint64_t)t->n_lights * sizeof(struct tape_light) +
           (uint64_t)t->n_paths * sizeof(struct tape_path) +
           (uint64_t)t->n_rays * (sizeof(struct dr_deriv_ray) + sizeof(struct dr_deriv_light));
}

/* Pixels in a worker's batch: its share of the paths, in whole pixels (at least one). */
static int64_t batch_pixels(int64_t batch, int threads, int spp)
{
    threads = threads > 0 ? threads : 1;
    spp = spp > 0 ? spp : 1;
    const int64_t paths = batch > 0 ? batch : (int64_t)DR_TAPE_PATHS_PER_WORKER * threads;
    const int64_t share = paths / threads + (paths % threads != 0);   /* (no overflow at INT64_MAX) */
    return share / spp > 1 ? share / spp : 1;
}

double dr_tape_batch_paths(int64_t batch, int threads, int spp)
{
    /* (in double: a --batch near INT64_MAX must not wrap) */
    return (double)batch_pixels(batch, threads, spp) * (spp > 0 ? spp : 1) * (threads > 0 ? threads : 1);
}

/* A new path of the tape (NULL: out of memory). */
static struct tape_path *new_path(struct tape *tp, int64_t px, dr_vec3 adj, uint64_t key)
{
    if (!grow((void **)&tp->paths, &tp->cap_paths, tp->n_paths + 1, sizeof *tp->paths))
        return NULL;
    struct tape_path *path = &tp->paths[tp->n_paths++];
    *path = (struct tape_path){.pixel = px, .last = -1, .count = 0, .moving = -1, .adj = adj, .key = key};
    return path;
}

/* The adjoint of one sample of pixel px, when it is known before the record
 * (false: the pixel does not matter); cross mode: every pixel is recorded,
 * its adjoint comes after (cross_adjoints). */
static bool adjoint_before(const struct tape_job *j, int64_t px, dr_vec3 *adj)
{
    if (j->b.p->cross) {
        *adj = dr_v3s(0.0);
        return true;
    }
    return dr_est_sample_adjoint(&j->b, px, adj);
}

/* The path's next vertex slot, linked after its last (NULL: out of memory). */
static struct tape_vertex *new_vertex(struct tape *tp, struct tape_path *path, bool media)
{
    if (!grow((void **)&tp->verts, &tp->cap_verts, tp->n_verts + 1, sizeof *tp->verts))
        return NULL;
    if (media && !grow((void **)&tp->mrecs, &tp->cap_mrecs, tp->n_verts + 1, sizeof *tp->mrecs))
        return NULL;
    struct tape_vertex *tv = &tp->verts[tp->n_verts];
    tv->prev = path->last;
    tv->n_rays = -1;
    path->last = tp->n_verts++;
    path->count++;
    return tv;
}

/* Records a vertex with term e and continuation factor t (reached with true
 * throughput bt) as a step of the path and adds its part to L; false when
 * out of memory. */
static bool new_step(struct tape *tp, struct tape_path *path, dr_vec3 e, dr_vec3 t, dr_vec3 *L, dr_vec3 bt)
{
    if (!grow((void **)&tp->steps, &tp->cap_steps, tp->n_steps + 1, sizeof *tp->steps))
        return false;
    struct tape_step *st = &tp->steps[tp->n_steps];
    st->e = e;
    st->t = t;
    st->prev = path->last;
    path->last = TAPE_STEP | tp->n_steps++;
    path->count++;
    *L = dr_add(*L, dr_mul(bt, st->e));
    return true;
}

/* Records vertex v (reached with true throughput bt), whose derivative term
 * is all in its light terms, as a tape_light and adds its part to L; false
 * when out of memory. */
static bool new_light(struct tape *tp, struct tape_path *path, const struct dr_path_vertex *v, dr_vec3 *L, dr_vec3 bt)
{
    if (!grow((void **)&tp->lights, &tp->cap_lights, tp->n_lights + 1, sizeof *tp->lights))
        return false;
    struct tape_light *l = &tp->lights[tp->n_lights];
    dr_path_light_terms_take(v, &l->terms);
    l->e = dr_path_vertex_term(v);
    l->t = v->cont ? dr_scale(v->f, v->cos_pdf_q) : dr_v3s(0.0);
    l->bt = bt;
    l->prev = path->last;
    path->last = TAPE_LIGHT | tp->n_lights++;
    path->count++;
    *L = dr_add(*L, dr_mul(bt, l->e));
    path->derivative = true;
    return true;
}

/* What the record notes of vertex v (already on the tape): its part of L,
 * and whether attached sampling moves it. */
static void note_vertex(const struct tape_job *j, struct tape_path *path, const struct tape_vertex *tv, dr_vec3 *L)
{
    *L = dr_add(*L, dr_mul(tv->bt, dr_path_vertex_term(&tv->v)));
    if (path->moving < 0 && j->attached && dr_path_vertex_sampling_moves(j->b.p->scene, j->b.p->params, &tv->v))
        path->moving = path->count - 1;
}

/* The path's record is complete (L: its radiance). */
static void end_path(struct tape_job *j, int thread, struct tape_path *path, dr_vec3 L)
{
    if (path->moving < 0)
        path->moving = path->count;
    path->L = L;
    if (!dr_v3_finite(L)) {
        path->dropped = true;
        j->b.thr[thread].invalid++;
    }
}

/* Cross mode: each path's adjoint from its pixel's other samples
 * (estimator.h). The tape holds whole pixels, their paths one after the other
 * in sample order (record_path's loop and lane_start's items both go
 * sample by sample), so a path's sample is its place in its pixel. */
static void cross_adjoints(const struct tape_job *j, struct tape *tp)
{
    for (int64_t first = 0, end; first < tp->n_paths; first = end) {
        const int64_t px = tp->paths[first].pixel;
        struct dr_cross_sum sum = {0};
        for (end = first; end < tp->n_paths && tp->paths[end].pixel == px; end++)
            if (!tp->paths[end].dropped)
                dr_cross_sum_add(&sum, (int)(end - first), tp->paths[end].L);
        dr_est_cross_pixel(&j->b, px, &sum);
        for (int64_t k = first; k < end; k++)
            if (!tp->paths[k].dropped)
                tp->paths[k].adj = dr_est_cross_adjoint(&j->b, px, &sum, (int)(k - first), tp->paths[k].L);
    }
}

/* Records path (sample sidx of its pixel, no vertex recorded yet) one
 * vertex after the other (the one-path walker: scenes with media); false
 * when out of memory. */
static bool record_walk(struct tape_job *j, struct tape *tp, int thread, struct tape_path *path, int sidx)
{
    struct dr_sampler smp;
    dr_vec3 o, d;
    dr_est_camera_ray(&j->b, thread, path->pixel, sidx, &smp, &o, &d);
    path->key = smp.key;
    path->derivative = true;   /* (not asked vertex by vertex: swept) */
    const bool media = j->b.popts.params->media_active;
    struct dr_path_state st;
    dr_path_start(&st, o, d);
    dr_vec3 L = dr_v3s(0.0);
    for (;;) {
        struct tape_vertex *tv = new_vertex(tp, path, media);
        if (!tv)
            return false;
        tv->v.mrec = media ? &tp->mrecs[path->last] : NULL;
        tv->bt = dr_mul(st.ratio, st.beta);
        bool more = dr_path_step(j->b.p->scene, &j->b.popts, &st, &smp, &tv->v, &j->b.thr[thread].rays);
        note_vertex(j, path, tv, &L);
        if (!more)
            break;
    }
    end_path(j, thread, path, L);
    return true;
}

/* Records the path of sample sidx of pixel px (record_walk); false when out of memory. */
static bool record_path(struct tape_job *j, struct tape *tp, int thread, int64_t px, int sidx, dr_vec3 adj)
{
    struct tape_path *path = new_path(tp, px, adj, 0);
    return path && record_walk(j, tp, thread, path, sidx);
}

/* Pixels [begin, end), every sample, one path after the other. */
static void record_one_by_one(struct tape_job *j, struct tape *tp, int thread, int64_t begin, int64_t end)
{
    for (int64_t px = begin; px < end && !tp->failed; px++) {
        dr_vec3 adj;
        if (!adjoint_before(j, px, &adj))
            continue;   /* this pixel does not matter to the loss */
        for (int sidx = 0; sidx < j->b.p->spp && !tp->failed; sidx++)
            if (!record_path(j, tp, thread, px, sidx, adj))
                tp->failed = true;
    }
}

/* ---- the record on the packet tracer: a lane's item is one path */

struct wave_record {
    struct tape_job *j;
    struct tape *tp;
    int thread;
    const int64_t *px;    /* the batch's pixels that matter; item i is sample i % spp of px[i / spp] */
    int64_t first_path;   /* the record in arrays: item i's path */
    const bool *in_media; /* ... in a scene with media, by item: the walk handed the path back (NULL: none) */
};

struct record_lane {
    int64_t path;   /* its index in tp->paths (-1: out of memory) */
    dr_vec3 L;
};
_Static_assert(sizeof(struct record_lane) <= DR_WAVE_USER_BYTES, "a record lane's state fits");

static void lane_start(void *ctx, int64_t i, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    struct wave_record *c = ctx;
    struct record_lane *l = user;
    const int spp = c->j->b.p->spp;
    const int64_t px = c->px[i / spp];
    dr_vec3 adj;
    adjoint_before(c->j, px, &adj);
    dr_est_camera_ray(&c->j->b, c->thread, px, (int)(i % spp), smp, o, d);
    struct tape_path *path = c->tp->failed ? NULL : new_path(c->tp, px, adj, smp->key);
    if (!path)
        c->tp->failed = true;
    l->path = path ? c->tp->n_paths - 1 : -1;
}

/* Is the path's last record a whole vertex with a BSDF parameter? */
static bool after_bsdf(const struct tape *tp, const struct tape_path *path)
{
    return path->last >= 0 && !(path->last & (TAPE_STEP | TAPE_LIGHT)) && tp->verts[path->last].v.diff_bsdf;
}

/* Must the path's next vertex be recorded whole? The one rule of which
 * vertices the sweeps read whole, asked by record_vertex and, through
 * lane_next_whole, by the lanes (which then take that vertex from the scalar
 * stages). Plain detached sampling reads none whole but those with a term.
 * Attached sampling (steps_before_moving) reads every vertex from a path's
 * first moving one on (sweep_attached: d_path_vertex_attached); derivative
 * sampling (steps_off_bsdf) the vertex right after one with a BSDF parameter
 * (sweep_derivative reads it as next). Without the lanes every vertex is
 * whole. */
static bool next_whole(const struct tape_job *j, const struct tape *tp, const struct tape_path *path)
{
    if (j->steps)
        return false;
    if (j->steps_before_moving)
        return path->moving >= 0;
    if (j->steps_off_bsdf)
        return after_bsdf(tp, path);
    return true;
}

/* Vertex v of the path (reached with a): a step (tape_step) where it has no
 * derivative term and need not be whole (next_whole), a tape_light where its
 * term is all light, else whole; its part added to L. */
static void record_vertex(struct wave_record *c, struct tape_path *path, const struct dr_wave_arrival *a,
                          const struct dr_path_vertex *v, dr_vec3 *L)
{
    const bool compact = !next_whole(c->j, c->tp, path);
    if (compact && !dr_path_vertex_has_derivative(c->j->b.p->scene, c->j->b.p->params, v)) {
        dr_vec3 t = v->cont ? dr_scale(v->f, v->cos_pdf_q) : dr_v3s(0.0);
        if (!new_step(c->tp, path, dr_path_vertex_term(v), t, L, dr_mul(a->ratio, a->beta)))
            c->tp->failed = true;
        return;
    }
    if (compact && dr_path_light_terms_hold(v)) {
        if (!new_light(c->tp, path, v, L, dr_mul(a->ratio, a->beta)))
            c->tp->failed = true;
        return;
    }
    struct tape_vertex *tv = new_vertex(c->tp, path, false);
    if (!tv) {
        c->tp->failed = true;
        return;
    }
    tv->v = *v;   /* (the lane's vertex is overwritten at its next step) */
    tv->v.mrec = NULL;
    tv->bt = dr_mul(a->ratio, a->beta);
    note_vertex(c->j, path, tv, L);
    path->derivative = true;
}

static bool lane_vertex(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                        struct dr_sampler *smp, bool more)
{
    (void)smp, (void)more;
    struct wave_record *c = ctx;
    struct record_lane *l = user;
    if (l->path >= 0 && !c->tp->failed)
        record_vertex(c, &c->tp->paths[l->path], a, v, &l->L);
    return true;
}

static bool lane_next_whole(void *ctx, void *user)
{
    const struct wave_record *c = ctx;
    const struct record_lane *l = user;
    return l->path >= 0 && !c->tp->failed && next_whole(c->j, c->tp, &c->tp->paths[l->path]);
}

static enum dr_wave_next lane_walk_end(void *ctx, void *user, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    (void)smp, (void)o, (void)d;
    struct wave_record *c = ctx;
    struct record_lane *l = user;
    if (l->path >= 0 && !c->tp->failed)
        end_path(c->j, c->thread, &c->tp->paths[l->path], l->L);
    return DR_WAVE_DONE;
}

/* ---- the record in arrays (wave_soa.h): item i is path first_path + i,
 * whose radiance is summed in its L as the record goes */

static void soa_start(void *ctx, int64_t i, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    struct record_lane l;   /* (its path index is first_path + i: items start in order) */
    lane_start(ctx, i, &l, smp, o, d);
}

static void soa_step(void *ctx, int64_t i, dr_vec3 e, dr_vec3 t, dr_vec3 bt)
{
    struct wave_record *c = ctx;
    if (c->tp->failed || (c->in_media && c->in_media[i]))
        return;
    struct tape_path *path = &c->tp->paths[c->first_path + i];
    if (!new_step(c->tp, path, e, t, &path->L, bt))
        c->tp->failed = true;
}

static void soa_vertex(void *ctx, int64_t i, const struct dr_wave_arrival *a, const struct dr_path_vertex *v)
{
    struct wave_record *c = ctx;
    if (!c->tp->failed && !(c->in_media && c->in_media[i]))
        record_vertex(c, &c->tp->paths[c->first_path + i], a, v, &c->tp->paths[c->first_path + i].L);
}

/* The path's record dropped (its vertices stay in the arrays, unlinked):
 * the walk handed it back. */
static void forget_path(struct tape_path *path)
{
    path->last = -1;
    path->count = 0;
    path->moving = -1;
    path->derivative = false;
    path->L = dr_v3s(0.0);
}

/* The record of n paths in arrays; false when they cannot be had (nothing
 * recorded). In a scene with media (j->media_arrays) the walk hands back
 * the paths that could meet a medium (wave_soa.h's in_media: from the step
 * whose ray hits a medium's boundary, or whose shadow ray crosses a
 * medium's box); each is then recorded again from its start by the one-path
 * walker, in its place among its pixel's samples (cross mode reads them in
 * that order). */
static bool record_soa(struct tape_job *j, int thread, struct wave_record *c, int64_t n)
{
    const struct dr_scene *s = j->b.p->scene;
    if (!j->steps || !(j->media_arrays || dr_wave_soa_walks_apply(s, &j->b.popts)))
        return false;
    if (!j->soas[thread] && !(j->soas[thread] = dr_wave_soa_create()))
        return false;
    const size_t items = (size_t)j->batch * (size_t)j->b.p->spp;
    if (j->media_arrays && !j->in_media[thread] && !(j->in_media[thread] = malloc(items)))
        return false;
    bool *in_media = j->media_arrays ? j->in_media[thread] : NULL;
    const struct dr_wave_soa_walks out = {.ctx = c, .step = soa_step, .vertex = soa_vertex, .in_media = in_media};
    c->first_path = c->tp->n_paths;
    c->in_media = in_media;
    if (!dr_wave_soa_walk(j->soas[thread], s, &j->b.popts, n, soa_start, NULL, c, &out, &j->b.thr[thread].rays))
        return false;
    const int spp = j->b.p->spp;
    for (int64_t i = 0; i < n && !c->tp->failed; i++) {
        struct tape_path *path = &c->tp->paths[c->first_path + i];
        if (!(in_media && in_media[i])) {
            end_path(j, thread, path, path->L);
            continue;
        }
        forget_path(path);
        if (!record_walk(j, c->tp, thread, path, (int)(i % spp)))
            c->tp->failed = true;
    }
    return true;
}

/* False when the lanes cannot be had (then one path at a time). */
static bool record_wave(struct tape_job *j, struct tape *tp, int thread, int64_t begin, int64_t end)
{
    if (!j->pixels[thread] && !(j->pixels[thread] = malloc(sizeof(int64_t) * (size_t)j->batch)))
        return false;
    int64_t n = 0;
    dr_vec3 adj;
    for (int64_t px = begin; px < end; px++)
        if (adjoint_before(j, px, &adj))
            j->pixels[thread][n++] = px;
    struct wave_record c = {.j = j, .tp = tp, .thread = thread, .px = j->pixels[thread]};
    if (record_soa(j, thread, &c, n * j->b.p->spp))
        return true;
    if (j->media_arrays)
        return false;   /* (the lanes take no media) */
    if (!j->waves[thread] && !(j->waves[thread] = dr_wave_create()))
        return false;
    /* With compact steps a vertex without a derivative term is read for its
     * step only (new_step): eight lanes at a time where they can, and the
     * vertices of a light's terms too (light_terms), as in the arrays */
    static const struct dr_wave_ops whole = {.start = lane_start, .vertex = lane_vertex, .walk_end = lane_walk_end};
    static const struct dr_wave_ops steps = {.start = lane_start, .vertex = lane_vertex, .walk_end = lane_walk_end,
                                             .partial_vertices = true, .light_terms = true};
    /* (attached and derivative sampling: so but for the vertices next_whole
     * asks for whole) */
    static const struct dr_wave_ops some_whole = {.start = lane_start, .vertex = lane_vertex,
                                                  .walk_end = lane_walk_end, .partial_vertices = true,
                                                  .light_terms = true, .next_whole = lane_next_whole};
    const struct dr_wave_ops *ops = j->steps                                      ? &steps
                                    : j->steps_before_moving || j->steps_off_bsdf ? &some_whole
                                                                                  : &whole;
    dr_wave_run(j->waves[thread], j->b.p->scene, &j->b.popts, n * j->b.p->spp, ops, &c, &j->b.thr[thread].rays);
    return true;
}

/* ---- the backward sweep */

/* Derivative sampling's terms of vertex tv (path_deriv.h), beside detached
 * sampling's: the changed weights of next-event estimation and of the
 * emission the continuation sees at the next vertex (NULL: none), and the new
 * directions with their radiance paths (from the path's sub-streams, as prb
 * draws them). */
static void sweep_derivative(const struct tape_job *j, const struct tape *tp, const struct tape_vertex *tv,
                             const struct tape_vertex *next, const struct tape_path *path, struct dr_grad_sink *sink,
                             struct dr_ray_counts *rays)
{
    const struct dr_path_vertex *v = &tv->v;
    if (!v->diff_bsdf)
        return;
    dr_vec3 d_beta = dr_mul(path->adj, tv->bt);
    d_path_deriv_nee(j->b.p->scene, &j->b.popts, v, d_beta, sink);
    if (v->cont && next)
        d_path_deriv_emission(j->b.p->scene, &j->b.popts, v, dr_scale(d_beta, v->cos_pdf_q), &next->v, sink);
    if (tv->n_rays >= 0) {   /* (walked ahead: walk_ahead) */
        d_path_deriv_rays(j->b.p->scene, &j->b.popts, v, &tp->rays[tv->rays], &tp->found[tv->rays], tv->n_rays,
                          d_beta, sink);
    } else if (v->shaded) {
        struct dr_sampler smp = {.key = path->key};
        d_path_deriv_sample(j->b.p->scene, &j->b.popts, v, &smp, d_beta, sink, rays);
    }
}

/* The sweep over the compact records from link i back (steps and
 * tape_lights: nothing but their terms' adjoints and what they pass on to
 * abar, the adjoint of the true throughput after them), to the first whole
 * vertex's index (-1: the path's start). */
static int64_t sweep_compact(const struct tape_job *j, const struct tape *tp, int64_t i, dr_vec3 adj, dr_vec3 *abar,
                             struct dr_grad_sink *sink)
{
    while (i >= 0 && (i & (TAPE_STEP | TAPE_LIGHT))) {
        if (i & TAPE_STEP) {   /* steps: no derivative term, only what they pass on */
            const struct tape_step *st = &tp->steps[i & ~TAPE_STEP];
            *abar = dr_add(dr_mul(adj, st->e), dr_mul(*abar, st->t));
            i = st->prev;
            continue;
        }
        /* a light's terms: the whole vertex's adjoint calls (d_f black) */
        const struct tape_light *l = &tp->lights[i & ~TAPE_LIGHT];
        d_path_light_terms(j->b.p->scene, j->b.p->params, &l->terms, dr_mul(adj, l->bt), sink);
        *abar = dr_add(dr_mul(adj, l->e), dr_mul(*abar, l->t));
        i = l->prev;
    }
    return i;
}

/* Backward sweep over one path (its adjoint path->adj). rays: where
 * derivative sampling counts its extra rays. */
static void sweep(const struct tape_job *j, const struct tape *tp, const struct dr_medium_record *mrecs,
                  const struct tape_path *path, struct dr_grad_sink *sink, struct dr_ray_counts *rays)
{
    const struct tape_vertex *verts = tp->verts;
    const int count = path->count;
    const dr_vec3 adj = path->adj;
    const struct dr_scene *s = j->b.p->scene;
    const struct dr_param_set *ps = j->b.p->params;
    dr_vec3 abar = dr_v3s(0.0);   /* adjoint of the true throughput after the vertex */
    dr_vec3 after = dr_v3s(0.0);  /* media: radiance gathered after the vertex */
    /* the whole vertex after this one, as far as sweep_derivative reads it:
     * compact records may lie between, but never right after a vertex
     * with a BSDF parameter (steps_off_bsdf), the only one it reads next of */
    const struct tape_vertex *next = NULL;
    for (int64_t i = path->last; i >= 0; i = verts[i].prev) {
        i = sweep_compact(j, tp, i, adj, &abar, sink);
        if (i < 0)
            break;
        const struct dr_path_vertex *v = &verts[i].v;
        dr_vec3 bt = verts[i].bt;
        if (v->media) {
            dr_vec3 from = dr_add(after, dr_mul(bt, dr_path_vertex_term(v)));
            d_medium_vertex(s, &j->b.popts, v, mrecs ? &mrecs[i] : NULL, count, dr_mul(adj, bt), dr_mul(adj, from),
                            dr_mul(adj, after),
                            dr_mul(adj, dr_mul(bt, dr_path_vertex_nee(v))), sink);
            after = from;
        }
        dr_vec3 t = dr_v3s(0.0), d_f = dr_v3s(0.0);   /* (d_f: the continuation's f; none: black) */
        if (v->cont) {
            /* in media the throughput also took the segment's weight (path.h) */
            dr_vec3 bts = v->media ? dr_mul(bt, v->seg) : bt;
            if (v->diff_bsdf && j->derivative)
                d_path_deriv_continuation(s, &j->b.popts, v, dr_scale(dr_mul(abar, bts), v->cos_pdf_q), sink);
            else if (v->diff_bsdf)
                d_f = dr_scale(dr_mul(abar, bts), v->cos_pdf_q);
            t = dr_scale(v->f, v->cos_pdf_q);
            if (v->media)
                t = dr_mul(t, v->seg);
        }
        d_path_vertex(s, ps, v, dr_mul(adj, bt), d_f, sink);   /* (both BSDF values' material adjoint at once) */
        if (j->derivative)
            sweep_derivative(j, tp, &verts[i], next, path, sink, rays);
        abar = dr_add(dr_mul(adj, dr_path_vertex_term(v)), dr_mul(abar, t));
        next = &verts[i];
    }
}

/* Backward sweep under attached sampling. Vertices from path->moving on see
 * a ray that moves with the parameters: their reverse mode also carries the
 * adjoint of the walker's state (d_path_vertex_attached), from the last
 * vertex back to the first moving one, whose own arriving ray is fixed.
 * Before it, the detached adjoints are the whole story, and only there may
 * the record hold compact records (steps_before_moving). */
static void sweep_attached(const struct tape_job *j, const struct tape *tp, const struct tape_path *path,
                           dr_vec3 adj, struct dr_grad_sink *sink)
{
    const struct dr_scene *s = j->b.p->scene;
    const struct dr_param_set *ps = j->b.p->params;
    const struct tape_vertex *verts = tp->verts;
    dr_vec3 abar = dr_v3s(0.0);
    struct dr_d_path_state d_next, d_this;
    memset(&d_next, 0, sizeof d_next);
    int k = path->count - 1;   /* the vertex's place on its path (before the first moving one: at most) */
    for (int64_t i = path->last; i >= 0; i = verts[i].prev, k--) {
        if (k < path->moving && (i = sweep_compact(j, tp, i, adj, &abar, sink)) < 0)
            break;
        const struct dr_path_vertex *v = &verts[i].v;
        dr_vec3 bt = verts[i].bt;
        dr_vec3 t = v->cont ? dr_scale(v->f, v->cos_pdf_q) : dr_v3s(0.0);
        if (k >= path->moving) {
            d_path_vertex_attached(s, &j->b.popts, v, dr_mul(adj, bt), dr_mul(abar, bt), &d_next, &d_this, sink);
            d_next = d_this;
        } else {
            const dr_vec3 d_f = v->cont && v->diff_bsdf ? dr_scale(dr_mul(abar, bt), v->cos_pdf_q) : dr_v3s(0.0);
            d_path_vertex(s, ps, v, dr_mul(adj, bt), d_f, sink);
        }
        abar = dr_add(dr_mul(adj, dr_path_vertex_term(v)), dr_mul(abar, t));
    }
}

/* One recorded path's sweep. The attached state adjoint mixes the colour
 * channels, so in forward mode each image channel gets its own sweep. */
static void sweep_path(const struct tape_job *j, const struct tape *tp, const struct dr_medium_record *mrecs,
                       const struct tape_path *path, struct dr_grad_sink *sink, struct dr_ray_counts *rays)
{
    if (path->moving >= path->count) {
        sweep(j, tp, mrecs, path, sink, rays);
        return;
    }
    if (!sink->dir) {
        sweep_attached(j, tp, path, path->adj, sink);
        return;
    }
    for (int c = 0; c < 3; c++) {
        sink->channel = c;
        sweep_attached(j, tp, path, dr_v3_channel(path->adj, c), sink);
    }
}

/* mis: one recorded path swept twice, detached and attached, into its
 * group's two estimates (mis.h): the record (every ray) is shared. A path
 * without a derivative term is not swept, but still counts as a sample of
 * its pixel (mis weighs by the per-pixel variances). */
static void sweep_path_mis(struct tape_job *j, int thread, const struct tape *tp, const struct dr_medium_record *mrecs,
                           const struct tape_path *path)
{
    struct dr_grad_sink det, att;
    dr_est_mis_sinks(&j->b, thread, path->pixel, &det, &att);
    struct dr_ray_counts *rays = &j->b.thr[thread].rays;   /* unused: mis is not derivative sampling */
    if (path->derivative) {
        sweep(j, tp, mrecs, path, &det, rays);
        sweep_path(j, tp, mrecs, path, &att, rays);
    }
    dr_est_mis_sample_done(&j->b, thread, path->pixel, &det, &att);
}

/* Will the sweep take path's derivative terms (not a dropped path, nor
 * one whose pixel does not matter to the loss)? */
static bool swept(const struct tape_job *j, const struct tape_path *path)
{
    return !path->dropped && !(j->b.p->cross && dr_is_black(path->adj));
}

/* Derivative sampling: the new directions of every vertex the sweep will
 * take them at (sweep_derivative), and their radiance walked ahead of the
 * sweep, all at once on the lanes, rather than one walk at a time inside
 * it (the radiance does not depend on the adjoints). The same directions,
 * streams and walks as d_path_deriv_sample's, so the gradients are the same
 * to rounding (the lanes shade eight vertices at a time). False when the
 * lanes or the memory cannot be had: then the sweep walks them itself. */
static bool walk_ahead(struct tape_job *j, int thread, struct tape *tp)
{
    const struct dr_scene *s = j->b.p->scene;
    tp->n_rays = 0;
    if (!j->waves[thread] && !(j->waves[thread] = dr_wave_create()))
        return false;
    for (int64_t pi = 0; pi < tp->n_paths; pi++) {
        const struct tape_path *path = &tp->paths[pi];
        if (!swept(j, path) || !path->derivative)
            continue;
        const struct dr_sampler smp = {.key = path->key};
        for (int64_t i = path->last; i >= 0;) {
            if (i & TAPE_STEP) {
                i = tp->steps[i & ~TAPE_STEP].prev;
                continue;
            }
            if (i & TAPE_LIGHT) {
                i = tp->lights[i & ~TAPE_LIGHT].prev;
                continue;
            }
            struct tape_vertex *tv = &tp->verts[i];
            i = tv->prev;
            if (!tv->v.diff_bsdf || !tv->v.shaded || dr_is_black(dr_mul(path->adj, tv->bt)))
                continue;
            if (!grow((void **)&tp->rays, &tp->cap_rays, tp->n_rays + DR_DERIV_RAYS, sizeof *tp->rays))
                return false;
            tv->rays = (int32_t)tp->n_rays;   /* (3 per whole vertex of ~1 KB: far below 2^31) */
            tv->n_rays = dr_path_deriv_rays(s, &j->b.popts, &tv->v, &smp, &tp->rays[tp->n_rays]);
            tp->n_rays += tv->n_rays;
        }
    }
    if (!grow((void **)&tp->found, &tp->cap_found, tp->n_rays, sizeof *tp->found))
        return false;
    dr_wave_deriv_radiance(j->waves[thread], s, &j->b.popts, tp->n_rays, tp->rays, tp->found,
                           &j->b.thr[thread].rays);
    return true;
}

/* The sweep of the worker's tape, path by path. */
static void sweep_tape(struct tape_job *j, int thread, const struct tape *tp)
{
    struct dr_grad_sink sink = dr_est_sink_begin(&j->b, thread);
    /* medium records only when this run made them (a kept mapping may hold an earlier run's) */
    const struct dr_medium_record *mrecs = j->b.popts.params->media_active ? tp->mrecs : NULL;
    for (int64_t pi = 0; pi < tp->n_paths; pi++) {
        const struct tape_path *path = &tp->paths[pi];
        if (!swept(j, path))
            continue;
        if (j->b.mis) {
            sweep_path_mis(j, thread, tp, mrecs, path);
            continue;
        }
        if (!path->derivative)
            continue;   /* (no term to add; forward mode adds a sample's zeros) */
        sweep_path(j, tp, mrecs, path, &sink, &j->b.thr[thread].rays);
        dr_est_sample_done(&j->b, path->pixel, &sink);
    }
    dr_est_sink_end(&j->b, thread);
}

static void tape_unmap(struct tape *tp)
{
    map_free(tp->verts, tp->cap_verts, sizeof *tp->verts);
    map_free(tp->steps, tp->cap_steps, sizeof *tp->steps);
    map_free(tp->lights, tp->cap_lights, sizeof *tp->lights);
    map_free(tp->mrecs, tp->cap_mrecs, sizeof *tp->mrecs);
    map_free(tp->paths, tp->cap_paths, sizeof *tp->paths);
    map_free(tp->rays, tp->cap_rays, sizeof *tp->rays);
    map_free(tp->found, tp->cap_found, sizeof *tp->found);
    *tp = (struct tape){0};
}

/* Each worker's tape mappings, kept from one estimator run to the next: the
 * reverse driver runs the estimator twice per batch, and a tape faulted in
 * afresh every run (4 KiB at a time, about 10 us each on a VM) doubled the
 * tape's time on small images (Cornell box 64x64, 32 spp in 8 batches:
 * 0.27 s, now 0.13 s; prb 0.145 s). Held until the process ends; the OS
 * takes them back. */
static struct {
    pthread_mutex_t lock;
    struct tape kept[DR_MAX_THREADS];
} tape_pool = {.lock = PTHREAD_MUTEX_INITIALIZER};

/* Worker t's tape starts from the mappings the last run left (if any). */
static void tape_take(struct tape *tp, int t)
{
    pthread_mutex_lock(&tape_pool.lock);
    *tp = tape_pool.kept[t];
    tape_pool.kept[t] = (struct tape){0};
    pthread_mutex_unlock(&tape_pool.lock);
    tp->n_verts = tp->n_steps = tp->n_lights = tp->n_paths = 0;
    tp->peak = 0;
    tp->failed = false;
}

/* ... and leaves its own for the next (unmapped if another run's are there). */
static void tape_leave(struct tape *tp, int t)
{
    pthread_mutex_lock(&tape_pool.lock);
    struct tape old = tape_pool.kept[t];
    tape_pool.kept[t] = *tp;
    pthread_mutex_unlock(&tape_pool.lock);
    tape_unmap(&old);
    *tp = (struct tape){0};
}

/* One worker's batch: every sample of pixels [begin, end) recorded, then
 * swept. A pixel's samples stay in one batch, in sample order, so its sums
 * do not depend on where the batches are cut (a crop's pixels are bit for bit
 * the full frame's). */
static void record_and_sweep(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct tape_job *j = ctx;
    struct tape *tp = &j->tapes[thread];
    if (tp->failed)
        return;
    tp->n_verts = tp->n_steps = tp->n_lights = tp->n_paths = tp->n_rays = 0;
    if (!(j->wave && record_wave(j, tp, thread, begin, end)))
        record_one_by_one(j, tp, thread, begin, end);
    if (!tp->failed && j->b.p->cross)
        cross_adjoints(j, tp);
    if (!tp->failed && j->derivative && j->wave && !(j->b.popts.stages & DR_STAGE_MEDIA) &&
        !walk_ahead(j, thread, tp))
        for (int64_t i = 0; i < tp->n_verts; i++)
            tp->verts[i].n_rays = -1;   /* (out of memory: the sweep walks them) */
    /* (after walk_ahead: its rays are held with the record until the sweep) */
    uint64_t bytes = tape_bytes(tp, j->b.popts.params->media_active);
    tp->peak = bytes > tp->peak ? bytes : tp->peak;
    if (!tp->failed)
        sweep_tape(j, thread, tp);
}

static int tape_run(struct dr_est_base *b)
{
    struct tape_job *j = (struct tape_job *)b;
    const struct dr_grad_problem *p = b->p;
    const int threads = b->acc.threads;
    const enum dr_sampling run = dr_est_sampling_run(p);
    j->attached = run == DR_SAMPLING_ATTACHED || run == DR_SAMPLING_MIS;
    j->derivative = dr_sampling_is_derivative(run);
    /* steps: plain detached sampling on the packet tracer (attached, mis and
     * derivative sampling read whole vertices where detached has no term) */
    const bool plain = run == DR_SAMPLING_DETACHED && !b->mis;
    const bool media = (b->popts.stages & DR_STAGE_MEDIA) != 0;
    j->media_arrays = media && plain && dr_wave_soa_media_walks_apply(p->scene, &b->popts);
    j->wave = !media || j->media_arrays;
    j->steps = j->wave && plain;
    j->steps_before_moving = j->wave && j->attached;
    j->steps_off_bsdf = j->wave && j->derivative;
    for (int t = 0; t < threads; t++)
        tape_take(&j->tapes[t], t);
    const int64_t pixels = (int64_t)p->width * p->height;
    j->batch = batch_pixels(p->batch, threads, p->spp);
    if (j->batch > pixels)
        j->batch = pixels > 0 ? pixels : 1;   /* (the pixel list holds a batch) */
    if (j->wave) {   /* what the workers hold besides the tape: the packet tracer's arrays or lanes */
        const bool soa = j->steps && (j->media_arrays || dr_wave_soa_walks_apply(p->scene, &b->popts));
        b->scratch_bytes = (uint64_t)threads * (soa ? dr_wave_soa_walk_bytes() : dr_wave_bytes());
    }
    int rc = dr_parallel_for_static(pixels, j->batch, threads, record_and_sweep, j);
    uint64_t bytes = 0;
    for (int t = 0; t < threads; t++)
        bytes += j->tapes[t].peak;   /* (workers may peak at different times: an upper bound) */
    b->record_bytes = bytes;
    for (int t = 0; t < threads && rc == 0; t++)
        if (j->tapes[t].failed) {
            dr_set_error("out of memory recording the tape (%llu bytes so far); use --batch to bound it",
                         (unsigned long long)bytes);
            rc = DR_ERR_NOMEM;
        }
    return rc;
}

static void tape_release(struct dr_est_base *b)
{
    struct tape_job *j = (struct tape_job *)b;
    for (int t = 0; t < DR_MAX_THREADS; t++) {
        if (j->tapes[t].failed)
            tape_unmap(&j->tapes[t]);   /* (an out-of-memory tape is not worth keeping) */
        else if (j->tapes[t].cap_verts || j->tapes[t].cap_steps || j->tapes[t].cap_lights || j->tapes[t].cap_paths ||
                 j->tapes[t].cap_mrecs)
            tape_leave(&j->tapes[t], t);
        dr_wave_destroy(j->waves[t]);
        dr_wave_soa_destroy(j->soas[t]);
        free(j->pixels[t]);
        free(j->in_media[t]);
    }
}

/* tape_run's scratch_bytes per thread: the arrays or the lanes, the larger. */
static uint64_t tape_thread_bytes(int spp)
{
    (void)spp;
    const uint64_t soa = dr_wave_soa_walk_bytes(), lanes = dr_wave_bytes();
    return soa > lanes ? soa : lanes;
}

const struct dr_estimator_ops dr_estimator_tape = {
    .name = "tape",
    .summary = "conventional reverse mode: records every vertex of a batch of paths, then sweeps backward; memory "
               "grows with depth x paths per batch",
    .sampling = (1u << DR_SAMPLING_DETACHED) | (1u << DR_SAMPLING_ATTACHED) | (1u << DR_SAMPLING_MIS) |
                (1u << DR_SAMPLING_DERIVATIVE) | (1u << DR_SAMPLING_DERIVATIVE_ROUGHNESS),
    .job_size = sizeof(struct tape_job),
    .run = tape_run,
    .release = tape_release,
    .thread_bytes = tape_thread_bytes,
};
