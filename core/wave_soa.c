/* The packet tracer's radiance as arrays (wave_soa.h). */
#include "wave_soa.h"

#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "clock.h"
#include "coverage.h"
#include "material.h"
#include "medium_scene.h"
#include "path_simd.h"
#include "wavefront.h"

/* Paths in flight per thread: enough for long runs of full Embree packets
 * and eight-lane groups, few enough that the arrays stay in a core's L2
 * cache (693 KiB in all, of which the group states take 5 KB per eight
 * paths; a render touches 4 KB of those: the light sample's record in
 * dr_path8 is written only where a light has a parameter). */
#ifndef DR_SOA_LANES
#define DR_SOA_LANES 512
#endif
#define LANES DR_SOA_LANES
/* Each array's length: LANES plus one cache line. Arrays of a power-of-two
 * size would all start at the same offset modulo 4 KiB, and a loop reading
 * ten of them at slot i would map them all to one cache set (measured in
 * bench/soa_floor.c). The spare slots also hold the last group's padding. */
#define SLOTS (LANES + 8)

struct dr_wave_soa {
    /* each path's state by slot; live paths are slots [0, n_live) */
    double ox[SLOTS], oy[SLOTS], oz[SLOTS];     /* the next ray */
    double dx[SLOTS], dy[SLOTS], dz[SLOTS];
    double px[SLOTS], py[SLOTS], pz[SLOTS];     /* the point it leaves (dr_path_state's prev_p) */
    double prev_pdf[SLOTS];                     /* its BSDF density (0: camera ray) */
    double prev_sky[SLOTS];                     /* dr_path_state's prev_sky */
    double bx[SLOTS], by[SLOTS], bz[SLOTS];     /* throughput */
    double Lx[SLOTS], Ly[SLOTS], Lz[SLOTS];     /* radiance so far */
    double depth[SLOTS];                        /* segments traced */
    uint64_t key[SLOTS];                        /* the sampler's key */
    struct dr_sampler smp[SLOTS];               /* the whole sampler, where it is a structured one */
    bool structured;                            /* ... (this run's paths' samplers are) */
    int64_t item[SLOTS];                        /* the path's index in the run */
    int64_t tri[SLOTS];                         /* the trace's answer */
    bool occluded[SLOTS];                       /* the shadow ray's */
    /* one step's shadow rays, and whose they are */
    double sox[SLOTS], soy[SLOTS], soz[SLOTS], sdx[SLOTS], sdy[SLOTS], sdz[SLOTS];
    double stmax[SLOTS];
    int64_t sowner[SLOTS];   /* (their coverage keys: skey, below) */
    bool socc[SLOTS];
    double inf[SLOTS];                          /* the traces' tmax */
    uint64_t tkey[SLOTS];                       /* the traces' coverage keys (coverage.h: BLEND scenes) */
    uint64_t skey[SLOTS];                       /* the shadow rays' (by their index, as sox) */
    struct dr_hit hit[SLOTS];                   /* scalar hits of textured lanes (dr_path8_locate_hits) */
    struct dr_path8 group[LANES / DR_SIMD_W];   /* the hit stage's results, for the continuation */
    /* before shading: the hit points of the groups located (locate_textured),
     * the random numbers and light picks taken ahead (pick_ahead) */
    struct dr_path8_located loc[LANES / DR_SIMD_W];
    bool loc_valid[LANES / DR_SIMD_W];
    struct dr_path8_ahead ahead[LANES / DR_SIMD_W];
    bool ahead_valid;
    /* path replay's primal walks only (dr_wave_soa_walk; out is NULL in a radiance run) */
    const struct dr_wave_soa_walks *out;
    double rx[SLOTS], ry[SLOTS], rz[SLOTS];     /* true / tracing throughput (dr_path_state's ratio) */
    double Tx[SLOTS], Ty[SLOTS], Tz[SLOTS];     /* radiance with the true throughput (L: the tracing one's) */
    int last_diff[SLOTS];
    /* path replay's second walks only (dr_wave_soa_replay; NULL otherwise;
     * out then points at replay_out, which asks for nothing) */
    const struct dr_wave_soa_replay *replay;
    struct dr_wave_soa_walks replay_out;
    struct dr_hit *diff_hit;                    /* by slot: a differentiated vertex's hit (dr_path8_in's) */
    struct dr_path_vertex *vertex;              /* where its vertex is made whole (replay_step) */
    int traced[SLOTS];                          /* the slots whose rays a replay traces, and */
    int64_t traced_tri[SLOTS];                  /* their answers */
    /* a radiance run in a scene with media (every one bounded): the paths
     * that could meet a medium go to the one-path walker (finish_in_media) */
    bool media;
    void *words[27];   /* word_arrays' list, made once (dr_wave_soa_create) */
};

static void list_word_arrays(struct dr_wave_soa *w);

struct dr_wave_soa *dr_wave_soa_create(void)
{
    size_t bytes = (sizeof(struct dr_wave_soa) + 63) / 64 * 64;
    struct dr_wave_soa *w = aligned_alloc(64, bytes);
    if (!w)
        return NULL;
    memset(w, 0, bytes);   /* (padding lanes read slots no path has written) */
    for (int k = 0; k < SLOTS; k++)
        w->inf[k] = INFINITY;
    list_word_arrays(w);
    return w;
}

void dr_wave_soa_destroy(struct dr_wave_soa *w)
{
    if (w) {
        free(w->diff_hit);
        free(w->vertex);
    }
    free(w);
}

size_t dr_wave_soa_bytes(void)
{
    return sizeof(struct dr_wave_soa);
}

size_t dr_wave_soa_walk_bytes(void)
{
    return sizeof(struct dr_wave_soa) + sizeof(struct dr_hit) * SLOTS + sizeof(struct dr_path_vertex);
}

bool dr_wave_soa_walks_apply(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    return dr_path8_walks_apply(s, opts);
}

bool dr_wave_soa_media_walks_apply(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    return (opts->stages & DR_STAGE_MEDIA) && dr_media_all_bounded(s) && dr_path8_walks_apply_outside_media(s, opts);
}

bool dr_wave_soa_replays_apply(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    return dr_path8_walks_apply(s, opts);
}

bool dr_wave_soa_applies(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    if (opts->stages & DR_STAGE_MEDIA)   /* (the paths that meet no medium: finish_in_media) */
        return dr_media_all_bounded(s) && dr_path8_applies_outside_media(s, opts);
    return !opts->params && dr_path8_applies(s, opts);
}

/* ----------------------------------------------------------- the slots */

/* Slot k takes item `item`, whose sampler and camera ray the caller's start
 * made (dr_path_start). */
static void start_path(struct dr_wave_soa *w, int k, int64_t item, const struct dr_sampler *smp, dr_vec3 o, dr_vec3 d)
{
    w->ox[k] = o.x, w->oy[k] = o.y, w->oz[k] = o.z;
    w->dx[k] = d.x, w->dy[k] = d.y, w->dz[k] = d.z;
    w->px[k] = o.x, w->py[k] = o.y, w->pz[k] = o.z;
    w->prev_pdf[k] = 0.0;
    w->prev_sky[k] = DR_SKY_SPHERE;
    w->bx[k] = w->by[k] = w->bz[k] = 1.0;
    w->Lx[k] = w->Ly[k] = w->Lz[k] = 0.0;
    w->depth[k] = 0.0;
    w->key[k] = smp->key;
    w->item[k] = item;
    if (smp->kind != DR_SAMPLER_INDEPENDENT) {   /* (one kind for all: set before any path moves) */
        w->structured = true;
        w->smp[k] = *smp;
    }
    if (w->out) {
        w->rx[k] = w->ry[k] = w->rz[k] = 1.0;
        w->Tx[k] = w->Ty[k] = w->Tz[k] = 0.0;
        w->last_diff[k] = 0;
        if (w->out->log)
            w->out->log[item].n = 0;
        if (w->out->in_media)
            w->out->in_media[item] = false;
    }
    if (w->replay) {   /* the first walk's sums, which the replay takes apart */
        const struct dr_wave_soa_replay *r = w->replay;
        const int32_t i = r->sample[item];
        w->Lx[k] = r->L_sub[i].x, w->Ly[k] = r->L_sub[i].y, w->Lz[k] = r->L_sub[i].z;
        w->Tx[k] = r->L[i].x, w->Ty[k] = r->L[i].y, w->Tz[k] = r->L[i].z;
        w->last_diff[k] = r->last_diff[i];
    }
}

/* The slots' arrays of 64-bit elements that move with a path (a walk's
 * too): the one list move_path and close_up move, made once per tracer
 * (made at every call, it was 1.3 % of a render). advance writes the same
 * arrays from its vectors: an array added here goes there too. */
#define WORD_ARRAYS 27
static void list_word_arrays(struct dr_wave_soa *w)
{
    void *const all[] = {w->ox, w->oy, w->oz, w->dx, w->dy, w->dz, w->px, w->py, w->pz, w->prev_pdf, w->prev_sky,
                         w->bx, w->by, w->bz, w->Lx, w->Ly, w->Lz, w->depth, w->key, w->item, w->tri,
                         w->rx, w->ry, w->rz, w->Tx, w->Ty, w->Tz};   /* (the last six: a walk's) */
    _Static_assert(sizeof all / sizeof *all == WORD_ARRAYS, "word_arrays' list");
    _Static_assert(sizeof w->words / sizeof *w->words == WORD_ARRAYS, "word_arrays' room");
    memcpy(w->words, all, sizeof all);
}

/* The list and how many of it this run's paths carry. */
static inline int word_arrays(struct dr_wave_soa *w, void *const **a)
{
    *a = w->words;
    return w->out ? WORD_ARRAYS : WORD_ARRAYS - 6;
}

/* Slot from's path to slot to. */
static void move_path(struct dr_wave_soa *w, int to, int from)
{
    void *const *a;
    for (int j = 0, n = word_arrays(w, &a); j < n; j++)
        memcpy((char *)a[j] + 8 * (size_t)to, (char *)a[j] + 8 * (size_t)from, 8);
    if (w->structured)
        w->smp[to] = w->smp[from];
    if (w->out)
        w->last_diff[to] = w->last_diff[from];
}

/* The paths of slots [i0, i0 + 8) where keep is set, closed up to the slots
 * from `to` (<= i0) by whole vectors; the samplers and last_diff, which are
 * not 64-bit words, the caller moves slot by slot. */
static void close_up(struct dr_wave_soa *w, int to, int i0, dr_m8 keep)
{
    void *const *a;
    for (int j = 0, n = word_arrays(w, &a); j < n; j++)
        dr_compress8((char *)a[j] + 8 * (size_t)to, (char *)a[j] + 8 * (size_t)i0, keep);
}

/* Lanes [0, n) of a group. */
static inline dr_m8 first_lanes(int n)
{
    return dr_m8_first(n);
}

/* A walk's end (dr_wave_soa_walk): its sums to the caller (L_sub: the
 * arrays' L, with the tracing throughput; L_true: their T). */
static void walk_done(const struct dr_wave_soa *w, int64_t item, dr_vec3 L_sub, dr_vec3 L_true, int last_diff)
{
    if (w->out->L)
        w->out->L[item] = L_true;
    if (w->out->L_sub)
        w->out->L_sub[item] = L_sub;
    if (w->out->last_diff)
        w->out->last_diff[item] = last_diff;
}

/* The trace's answer (`tri`) and the shadow ray's (`occ`, with occluded) of
 * the path at `depth`, for its replay (wavefront.h). */
static inline void log_trace(const struct dr_wave_soa *w, int64_t item, int depth, int64_t tri)
{
    if (w->out && w->out->log && depth <= DR_WAVE_REPLAY_DEPTH) {
        struct dr_wave_log *log = &w->out->log[item];
        log->tri[(log->n = depth) - 1] = tri;
        log->occ[depth - 1] = false;   /* (until a shadow ray answers: a vertex without one has a defined entry) */
    }
}
static inline void log_shadow(const struct dr_wave_soa *w, int64_t item, int depth, bool occluded)
{
    if (w->out && w->out->log && depth <= DR_WAVE_REPLAY_DEPTH)
        w->out->log[item].occ[depth - 1] = occluded;
}

static inline dr_f8 load8(const double *a)
{
    dr_f8 v;
    memcpy(&v, a, sizeof v);
    return v;
}
static inline dr_v3x8 load3(const double *x, const double *y, const double *z)
{
    return (dr_v3x8){load8(x), load8(y), load8(z)};
}

/* The log slot k's replay answers from (NULL: none, or not a replay). */
static inline const struct dr_wave_log *replay_log(const struct dr_wave_soa *w, int k)
{
    const struct dr_wave_soa_replay *r = w->replay;
    return r && r->log ? &r->log[r->sample[w->item[k]]] : NULL;
}

/* ------------------------------------------------------------ the stages */

/* Does a ray's coverage key matter (coverage.h: which BLEND surfaces and
 * thin glass it passes; the queries take keys only then). */
static inline bool keyed_traces(const struct dr_scene *s)
{
    return (s->effects & DR_FX_KEYED_TRACES) != 0;
}
static inline bool keyed_shadows(const struct dr_scene *s)
{
    return (s->effects & DR_FX_KEYED_SHADOWS) != 0;
}

/* Slot k's trace key (dr_path_trace_key, at the depth trace() counted). */
static inline uint64_t trace_key(const struct dr_wave_soa *w, int k)
{
    return dr_coverage_key(w->key[k], (int)w->depth[k], DR_RAY_TRACE);
}

/* A replay's trace: the answers its first walk logged where the log holds
 * them (no ray traced or counted, as in dr_wave_run's replays), the other
 * rays traced as one batch. */
static void replay_trace(struct dr_wave_soa *w, const struct dr_scene *s, int n_live, int first_new,
                         struct dr_ray_counts *counts)
{
    int n = 0;
    for (int k = 0; k < n_live; k++) {
        const struct dr_wave_log *log = replay_log(w, k);
        const int depth = (int)w->depth[k];
        if (log && depth <= log->n) {
            w->tri[k] = log->tri[depth - 1];
            continue;
        }
        if (k < first_new)
            counts->extension++;
        else
            counts->camera++;
        w->sox[n] = w->ox[k], w->soy[n] = w->oy[k], w->soz[n] = w->oz[k];
        w->sdx[n] = w->dx[k], w->sdy[n] = w->dy[k], w->sdz[n] = w->dz[k];
        w->skey[n] = keyed_traces(s) ? trace_key(w, k) : 0;
        w->traced[n++] = k;
    }
    if (n == 0)
        return;
    struct dr_accel_rays r = {.n = n, .ox = w->sox, .oy = w->soy, .oz = w->soz,
                              .dx = w->sdx, .dy = w->sdy, .dz = w->sdz, .tmax = w->inf,
                              .key = keyed_traces(s) ? w->skey : NULL};
    dr_accel_intersect_many(s->accel, &r, w->traced_tri);
    for (int j = 0; j < n; j++)
        w->tri[w->traced[j]] = w->traced_tri[j];
}

/* The trace of every live path: the extension rays of slots [0, first_new),
 * then the camera rays of the paths just started (consecutive samples of a
 * pixel: Embree traces them fastest as coherent packets). */
static void trace(struct dr_wave_soa *w, const struct dr_scene *s, int n_live, int first_new, bool prefetch,
                  struct dr_ray_counts *counts)
{
    for (int k = 0; k < n_live; k++)
        w->depth[k] += 1.0;   /* dr_path_step_begin */
    if (w->replay) {
        replay_trace(w, s, n_live, first_new, counts);
        for (int k = 0; prefetch && k < n_live; k++)
            if (w->tri[k] >= 0)
                dr_mesh_prefetch_triangle(&s->mesh, w->tri[k]);
        return;
    }
    counts->extension += (uint64_t)first_new;
    counts->camera += (uint64_t)(n_live - first_new);
    const bool keyed = keyed_traces(s);
    for (int k = 0; keyed && k < n_live; k++)
        w->tkey[k] = trace_key(w, k);
    struct dr_accel_rays old = {.n = first_new, .ox = w->ox, .oy = w->oy, .oz = w->oz,
                                .dx = w->dx, .dy = w->dy, .dz = w->dz, .tmax = w->inf,
                                .key = keyed ? w->tkey : NULL};
    const int f = first_new;
    struct dr_accel_rays cam = {.n = n_live - f, .ox = w->ox + f, .oy = w->oy + f, .oz = w->oz + f,
                                .dx = w->dx + f, .dy = w->dy + f, .dz = w->dz + f, .tmax = w->inf,
                                .key = keyed ? w->tkey + f : NULL, .coherent = n_live - f};
    if (old.n > 0)
        dr_accel_intersect_many(s->accel, &old, w->tri);
    if (cam.n > 0)
        dr_accel_intersect_many(s->accel, &cam, w->tri + first_new);
    for (int k = 0; prefetch && k < n_live; k++)
        if (w->tri[k] >= 0)
            dr_mesh_prefetch_triangle(&s->mesh, w->tri[k]);
    for (int k = 0; w->out && k < n_live; k++)
        log_trace(w, w->item[k], (int)w->depth[k], w->tri[k]);
}

/* Slot k's path and sampler as the scalar walker holds them before the
 * step whose ray (the arrays' o, d) the trace has just traced. */
static void path_state(const struct dr_wave_soa *w, int k, struct dr_path_state *st, struct dr_sampler *smp)
{
    dr_path_start(st, dr_v3(w->ox[k], w->oy[k], w->oz[k]), dr_v3(w->dx[k], w->dy[k], w->dz[k]));
    st->prev_pdf = w->prev_pdf[k];
    st->prev_sky = w->prev_sky[k];
    st->prev_p = dr_v3(w->px[k], w->py[k], w->pz[k]);
    st->depth = (int)w->depth[k] - 1;
    st->beta = dr_v3(w->bx[k], w->by[k], w->bz[k]);
    if (w->out)
        st->ratio = dr_v3(w->rx[k], w->ry[k], w->rz[k]);
    if (w->structured) {
        *smp = w->smp[k];
    } else {
        dr_sampler_init(smp, 0, 0, 0);
        smp->key = w->key[k];
    }
    smp->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)st->depth;
}

/* ------------------------------------------ paths that could meet a medium */

/* In a scene with media (every one bounded by a mesh) the eight-lane
 * stages take the paths until they could enter one: a camera ray that
 * starts in a medium, a ray that hits a medium's boundary. Such a path
 * goes back to the start of its step and the one-path walker takes it from
 * there to its end (the step's ray query answered by the stages' trace),
 * with its own operations on the path's own numbers, so that the image is
 * the one-path walker's (test_render; but with alphaMode BLEND surfaces,
 * whose shadow rays draw their coverage from another stream there,
 * medium_scene.h's dr_media_shadow_key: the same odds, not the same
 * draws). A shadow ray through a medium's box, where the stages' occlusion
 * test would take the boundary for a wall, takes the walker's transmittance
 * (shadows_through_media) and its path stays. So the paths that never
 * enter a medium, most of them where a smoke or fog fills part of a scene,
 * run as in a scene without media. Path replay's primal walks
 * (dr_wave_soa_media_walks_apply) hand such paths, and those whose shadow
 * rays cross a medium's box, back to their caller instead (in_media), who
 * walks them one path at a time from their start: a path that meets no
 * medium has no media term, so its sums are the one-path walk's even where
 * the media have parameters. */
static void finish_in_media(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                            int k, dr_vec3 *out, struct dr_ray_counts *counts)
{
    struct dr_path_state st;
    struct dr_sampler smp;
    struct dr_path_vertex v;
    path_state(w, k, &st, &smp);
    v.mrec = NULL;   /* (nothing recorded: no parameters) */
    dr_medium_path_resume(s, &st, &smp);
    dr_vec3 L = dr_v3(w->Lx[k], w->Ly[k], w->Lz[k]);   /* (summed on as dr_path_radiance sums) */
    for (bool more = true, first = true; more; first = false) {
        const dr_vec3 beta = st.beta;
        more = first ? dr_medium_path_step_traced(s, opts, &st, &smp, &v, counts, &w->tri[k])
                     : dr_path_step(s, opts, &st, &smp, &v, counts);
        L = dr_add(L, dr_mul(beta, dr_path_vertex_term(&v)));
    }
    out[w->item[k]] = L;
}

/* Does slot k's traced ray end on a medium's boundary, or start in a medium
 * (a camera ray: where its origin is in a medium's box, the medium there as
 * the one-path walker finds it, dr_medium_at: a ray more, uncounted there
 * too)? */
static bool meets_medium(const struct dr_wave_soa *w, const struct dr_scene *s, int k)
{
    if (w->tri[k] >= 0 && dr_boundary_medium(s, w->tri[k]) >= 0)
        return true;
    const dr_vec3 o = dr_v3(w->ox[k], w->oy[k], w->oz[k]);
    return w->depth[k] == 1.0 && dr_media_box_holds(s, o) &&
           dr_medium_at(s, o, dr_v3(w->dx[k], w->dy[k], w->dz[k])) >= 0;
}

/* The lanes whose segment from o along d up to tmax crosses some medium's
 * box (dr_media_box_holds' boxes): the slab test, eight lanes at a time
 * (one lane at a time it took 3 % of a render). A direction's zero
 * component is taken as 1e-300, so that no lane divides 0 by 0. */
static dr_m8 crosses_media_boxes(const struct dr_scene *s, dr_v3x8 o, dr_v3x8 d, dr_f8 tmax)
{
    const dr_f8 zero = dr_f8s(0.0), tiny = dr_f8s(1e-300);
    const dr_f8 ox[3] = {o.x, o.y, o.z}, dx[3] = {d.x, d.y, d.z};
    dr_f8 inv[3];
    for (int a = 0; a < 3; a++)
        inv[a] = 1.0 / dr_f8_sel(dr_f8_eq(dx[a], zero), tiny, dx[a]);
    dr_m8 crossed = {0};
    for (int i = 0; i < s->n_media; i++) {
        const struct dr_medium *m = &s->media[i];
        const double lo[3] = {m->bmin.x, m->bmin.y, m->bmin.z}, hi[3] = {m->bmax.x, m->bmax.y, m->bmax.z};
        dr_f8 t0 = zero, t1 = tmax;
        for (int a = 0; a < 3; a++) {
            const dr_f8 ta = (lo[a] - ox[a]) * inv[a], tb = (hi[a] - ox[a]) * inv[a];
            t0 = dr_f8_max(t0, dr_f8_min(ta, tb));
            t1 = dr_f8_min(t1, dr_f8_max(ta, tb));
        }
        crossed |= dr_f8_le(t0, t1);
    }
    return crossed;
}

/* The group's shadow rays that cross a medium's box, among those cast:
 * their transmittance as the one-path walker's media_nee finds it, through
 * the media and their boundaries (dr_medium_shadow_transmittance; a surface
 * in the way: 0, occluded), folded into the light's radiance as media_nee
 * folds it. Returns them: they leave the batch of occlusion queries. */
static dr_m8 shadows_through_media(struct dr_wave_soa *w, const struct dr_scene *s, struct dr_path8 *G, int i0,
                                   dr_m8 cast, struct dr_ray_counts *counts)
{
    const dr_m8 through = cast & dr_f8_gt(G->tmax, dr_f8s(0.0)) & crosses_media_boxes(s, G->so, G->sd, G->tmax);
    for (int i = 0; i < G->n; i++) {
        const int k = i0 + i;
        if (!through[i])
            continue;
        if (w->out) {   /* a walk's: its vertex has a media term; the caller walks it again
                           (the path ends at its next step: end_escaped) */
            w->out->in_media[w->item[k]] = true;
            w->occluded[k] = true;
            continue;
        }
        const dr_vec3 so = dr_v3x8_get(&G->so, i), sd = dr_v3x8_get(&G->sd, i);
        const dr_vec3 tr = dr_medium_shadow_transmittance(s, w->key[k], (int)w->depth[k], so, sd, G->tmax[i],
                                                          &counts->shadow);
        w->occluded[k] = dr_is_black(tr);
        G->ls_radiance.x[i] *= tr.x, G->ls_radiance.y[i] *= tr.y, G->ls_radiance.z[i] *= tr.z;
    }
    return through;
}

/* Slot k's vertex for a replay's hook (or a tape's: a walk's vertex hook),
 * begun as dr_path_step_begin begins it from the path's state before the
 * step whose ray the slot holds (as a lane's vertex in wavefront.c: the same
 * storage for every vertex); st: that state, after the begin. */
static struct dr_path_vertex *replay_vertex_begin(const struct dr_wave_soa *w, int k, struct dr_path_state *st)
{
    *st = (struct dr_path_state){.o = dr_v3(w->ox[k], w->oy[k], w->oz[k]), .d = dr_v3(w->dx[k], w->dy[k], w->dz[k]),
                                 .prev_p = dr_v3(w->px[k], w->py[k], w->pz[k]), .prev_pdf = w->prev_pdf[k],
                                 .prev_sky = w->prev_sky[k], .depth = (int)w->depth[k] - 1};
    dr_path_step_begin(st, w->vertex);
    return w->vertex;
}

/* A ray that left the scene: the escaped stage's maths (the environment's
 * radiance, if any, with its MIS weight: dr_path_escaped_radiance, which the
 * scalar stage calls too), and the path's end. In a walk where the
 * environment has a parameter the vertex has a derivative term (it emits:
 * dr_path_vertex_has_derivative): a walk with a vertex hook (a tape's) gets
 * it whole, from the scalar stage. Building a scalar state and vertex for
 * every escaped path, as before, took a tenth of a render where most rays
 * leave (a real asset under the default sky). */
static void escaped(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int k,
                    dr_vec3 *out)
{
    dr_vec3 e = dr_v3s(0.0);   /* nothing out there: a term of 0, summed as the walker sums it */
    if (opts->stages & DR_STAGE_ENV) {
        double emit_w;
        dr_vec3 Le = dr_path_escaped_radiance(s, (int)w->depth[k], w->prev_pdf[k], w->prev_sky[k],
                                              dr_v3(w->dx[k], w->dy[k], w->dz[k]), &emit_w);
        e = dr_scale(Le, emit_w);   /* dr_path_vertex_term of the escaped vertex */
    }
    dr_vec3 c = dr_mul(dr_v3(w->bx[k], w->by[k], w->bz[k]), e), L = dr_add(dr_v3(w->Lx[k], w->Ly[k], w->Lz[k]), c);
    if (!w->out) {
        out[w->item[k]] = L;
        return;
    }
    dr_vec3 ratio = dr_v3(w->rx[k], w->ry[k], w->rz[k]), T = dr_add(dr_v3(w->Tx[k], w->Ty[k], w->Tz[k]), dr_mul(ratio, c));
    const bool diff = (opts->stages & DR_STAGE_ENV) && opts->params && opts->params->env_active;
    const dr_vec3 beta = dr_v3(w->bx[k], w->by[k], w->bz[k]);
    if (diff && w->out->vertex) {   /* (a tape's: the vertex whole, as the scalar stage makes it) */
        struct dr_path_state st;
        struct dr_path_vertex *v = replay_vertex_begin(w, k, &st);
        dr_path_stage_escaped(s, opts, &st, v);
        w->out->vertex(w->out->ctx, w->item[k], &(struct dr_wave_arrival){beta, ratio}, v);
    } else if (w->out->step) {
        w->out->step(w->out->ctx, w->item[k], e, dr_v3s(0.0), dr_mul(ratio, beta));
    }
    walk_done(w, w->item[k], L, T, diff ? (int)w->depth[k] : w->last_diff[k]);
}

/* Group i0's paths whose ray left the scene (slots past n_live masked). */
static inline dr_m8 escaped_lanes(const struct dr_wave_soa *w, int n_live, int i0)
{
    dr_m8 tri;
    memcpy(&tri, w->tri + i0, sizeof tri);
    return first_lanes(n_live - i0 < DR_SIMD_W ? n_live - i0 : DR_SIMD_W) & dr_m8_negative(tri);
}

/* The sums of group i0's paths whose rays left the scene, eight at once:
 * escaped()'s with the same operations (dr_path8_escaped_term): the
 * radiance (w->L's) in *L, and in a walk the true throughput's (w->T's) in
 * *T. False when none left. */
static bool escaped_group(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                          int n_live, int i0, dr_v3x8 *L, dr_v3x8 *T)
{
    const dr_m8 left = escaped_lanes(w, n_live, i0);
    if (!dr_m8_any(left))
        return false;
    dr_v3x8 e = dr_path8_escaped_term(s, opts, left, load3(w->dx + i0, w->dy + i0, w->dz + i0), load8(w->depth + i0),
                                      load8(w->prev_pdf + i0), load8(w->prev_sky + i0));
    dr_v3x8 c = dr_v3x8_mul(load3(w->bx + i0, w->by + i0, w->bz + i0), e);
    *L = dr_v3x8_add(load3(w->Lx + i0, w->Ly + i0, w->Lz + i0), c);
    if (w->out)
        *T = dr_v3x8_add(load3(w->Tx + i0, w->Ty + i0, w->Tz + i0),
                         dr_v3x8_mul(load3(w->rx + i0, w->ry + i0, w->rz + i0), c));
    return true;
}

/* A replay group's sums at a vertex whose terms, times the throughput, are
 * be (prb.c's walk_vertex subtracts them as the walk goes): the sums after
 * it, and the true one before (remaining). */
static struct dr_wave_soa_replay_lanes replay_lanes(const struct dr_wave_soa *w, int i0, dr_v3x8 beta, dr_v3x8 ratio,
                                                    dr_v3x8 be)
{
    struct dr_wave_soa_replay_lanes g = {.beta = beta, .ratio = ratio};
    g.remaining = load3(w->Tx + i0, w->Ty + i0, w->Tz + i0);
    g.L_sub = dr_v3x8_sub(load3(w->Lx + i0, w->Ly + i0, w->Lz + i0), be);
    g.L_true = dr_v3x8_sub(g.remaining, dr_v3x8_mul(ratio, be));
    return g;
}

/* A replay's paths that left the scene where the environment has a
 * parameter: their escaped vertex has a derivative term (the path's last,
 * its first walk's last_diff). Each is made as the one-path walker's
 * escaped stage makes it (dr_path_stage_escaped: radiance and MIS weight,
 * here dr_path8_escaped's, the same bits, eight at a time) with the map's
 * lookup along d kept (env_at: the adjoint then reads the texels there
 * instead of mapping d again, d_env_radiance_at), and handed to the
 * replay's caller with the group's sums after its term, as replay_step
 * hands a hit's. The term subtracted is the one the first walk added
 * (escaped_group's). Made one lane at a time through the scalar stage,
 * the replays of the sample Box under a map took 1.1 x as long as in the
 * lanes (dr_wave_run), two inverse-trigonometric mappings a vertex. */
static void replay_escaped(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                           int n_live, int i0)
{
    const dr_m8 left = escaped_lanes(w, n_live, i0);
    if (!dr_m8_any(left))
        return;
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    dr_v3x8 Le = zero, e = zero;
    dr_f8 emit_w = dr_f8s(0.0);
    struct dr_env8_lookup at;
    bool looked_up = false;
    const bool env = (opts->stages & DR_STAGE_ENV) != 0;
    if (env) {   /* (dr_path8_escaped_term's operations) */
        looked_up = dr_path8_escaped(s, left, load3(w->dx + i0, w->dy + i0, w->dz + i0), load8(w->depth + i0),
                                     load8(w->prev_pdf + i0), load8(w->prev_sky + i0), &Le, &emit_w, &at);
        e = dr_v3x8_sel(left, (dr_v3x8){Le.x * emit_w, Le.y * emit_w, Le.z * emit_w}, zero);
    }
    const dr_v3x8 beta = load3(w->bx + i0, w->by + i0, w->bz + i0), ratio = load3(w->rx + i0, w->ry + i0, w->rz + i0);
    const struct dr_wave_soa_replay_lanes g = replay_lanes(w, i0, beta, ratio, dr_v3x8_mul(beta, e));
    for (int i = 0; i < DR_SIMD_W; i++) {
        if (!left[i])
            continue;
        const int k = i0 + i;
        struct dr_path_state st;
        struct dr_path_vertex *v = replay_vertex_begin(w, k, &st);
        v->kind = DR_VERTEX_ESCAPED;   /* (stage_escaped's) */
        if (env) {
            v->emits = true;
            v->Le = dr_v3x8_get(&Le, i);
            v->emit_w = emit_w[i];
            if (looked_up)
                v->env_at = (struct dr_env_lookup){true, at.u[i], at.v[i], dr_v3x8_get(&at.map, i)};
        }
        w->replay->vertex(w->replay->ctx, w->item[k], v, &g, i);
    }
}

/* The paths whose ray left the scene end; the
 * others close up, in order (moving the last paths into the gaps instead
 * was slower: a pixel's samples, started together, stay neighbours and
 * their first bounces make the more coherent packets). Returns how many
 * remain. */
static int end_escaped(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int n_live,
                       bool prefetch, dr_vec3 *out, struct dr_ray_counts *counts)
{
    int kept = 0;
    /* (a render's radiance, or a walk's sums without a step hook: prb's) */
    const bool eight_at_once = (!w->out || !w->out->step) && dr_path8_env_eight(s);
    const bool diff_env = (opts->stages & DR_STAGE_ENV) && opts->params && opts->params->env_active;
    for (int i0 = 0; i0 < n_live; i0 += DR_SIMD_W) {   /* (group by group: close_up) */
        bool keeps[DR_SIMD_W] = {false};
        int j = kept;
        dr_v3x8 L_esc, T_esc;
        /* (a replay's escaped paths end without sums: nothing reads them,
         * but where their vertex has a derivative term) */
        const bool grouped = !w->replay && eight_at_once && escaped_group(w, s, opts, n_live, i0, &L_esc, &T_esc);
        if (w->replay && diff_env)
            replay_escaped(w, s, opts, n_live, i0);
        for (int i = 0; i < DR_SIMD_W && i0 + i < n_live; i++) {
            const int k = i0 + i;
            if (w->media && w->out && w->out->in_media[w->item[k]])
                continue;   /* (a walk's path marked by a shadow ray through a medium: the caller's) */
            if (w->media && meets_medium(w, s, k)) {
                if (w->out)   /* (a walk's: the caller walks it again, one path at a time) */
                    w->out->in_media[w->item[k]] = true;
                else
                    finish_in_media(w, s, opts, k, out, counts);
                continue;
            }
            if (w->tri[k] < 0) {
                if (w->replay)
                    continue;
                if (!grouped)
                    escaped(w, s, opts, k, out);
                else if (!w->out)
                    out[w->item[k]] = dr_v3x8_get(&L_esc, i);
                else   /* (escaped()'s end of a walk) */
                    walk_done(w, w->item[k], dr_v3x8_get(&L_esc, i), dr_v3x8_get(&T_esc, i),
                              diff_env ? (int)w->depth[k] : w->last_diff[k]);
                continue;
            }
            if (prefetch)
                dr_mesh_prefetch_vertices(&s->mesh, w->tri[k]);
            keeps[i] = true;
            if (w->structured)
                w->smp[j] = w->smp[k];
            if (w->out)
                w->last_diff[j] = w->last_diff[k];
            j++;
        }
        /* (after the group's slots were read above; where no path before
         * and none of the group left, every path is in its place already) */
        const int in_group = n_live - i0 < DR_SIMD_W ? n_live - i0 : DR_SIMD_W;
        if (kept != i0 || j - kept != in_group)
            close_up(w, kept, i0, dr_m8_from_bools(keeps));
        kept = j;
    }
    return kept;
}

/* Before shading (prefetching): the hit points of the groups with lanes
 * that read textures (and the scalar hits of the lanes that need one), and
 * their texels asked for, so that the cache misses overlap. */
static void locate_textured(struct dr_wave_soa *w, const struct dr_scene *s, int n_live)
{
    for (int i0 = 0; i0 < n_live; i0 += DR_SIMD_W) {   /* (the last group padded: pad_last_group) */
        bool want[DR_SIMD_W], any = false;
        for (int i = 0; i < DR_SIMD_W; i++)
            any |= want[i] = i0 + i < n_live && dr_path8_reads_textures(s, w->tri[i0 + i]);
        w->loc_valid[i0 / DR_SIMD_W] = any;
        if (!any)
            continue;
        dr_path8_locate_hits(s, w->tri + i0, load3(w->ox + i0, w->oy + i0, w->oz + i0),
                             load3(w->dx + i0, w->dy + i0, w->dz + i0), want, w->hit + i0, &w->loc[i0 / DR_SIMD_W]);
    }
}

/* Group g's inputs: slots 8g .. 8g+7 (the last group's padding slots repeat
 * its first path: pad_last_group). In a replay, diff_hit (not NULL) gets
 * where each lane's differentiated hit goes, which in->diff_hit points to. */
static void group_inputs(const struct dr_wave_soa *w, int g, int n_live, bool located, struct dr_path8_in *in,
                         struct dr_hit *diff_hit[DR_SIMD_W])
{
    int i0 = g * DR_SIMD_W;
    in->n = n_live - i0 < DR_SIMD_W ? n_live - i0 : DR_SIMD_W;
    memcpy(in->tri, w->tri + i0, sizeof in->tri);
    memcpy(&in->key, w->key + i0, sizeof in->key);
    in->o = load3(w->ox + i0, w->oy + i0, w->oz + i0);
    in->d = load3(w->dx + i0, w->dy + i0, w->dz + i0);
    in->prev_p = load3(w->px + i0, w->py + i0, w->pz + i0);
    in->prev_pdf = load8(w->prev_pdf + i0);
    in->depth = load8(w->depth + i0);
    for (int i = 0; i < DR_SIMD_W; i++) {
        in->hit[i] = located ? &w->hit[i0 + (i < in->n ? i : 0)] : NULL;
        in->sampler[i] = w->structured ? &w->smp[i0 + (i < in->n ? i : 0)] : NULL;
    }
    in->located = located && w->loc_valid[g] ? &w->loc[g] : NULL;
    in->ahead = w->ahead_valid ? &w->ahead[g] : NULL;
    /* (the first walks' sums need no hit; a replay's differentiated
     * vertices do: padding lanes repeat the group's first slot, as above) */
    in->diff_hit = NULL;
    const bool wanted = diff_hit && (w->replay || (w->out && w->out->vertex));
    for (int i = 0; wanted && i < DR_SIMD_W; i++)
        diff_hit[i] = &w->diff_hit[i0 + (i < in->n ? i : 0)];
    if (wanted)
        in->diff_hit = diff_hit;
}

/* Before shading, in a scene with many emitting triangles: every group's
 * random numbers and light picks, stage by stage over the whole wave, so
 * that the cache misses of a stage overlap (dr_path8_ahead_stage). */
static void pick_ahead(struct dr_wave_soa *w, const struct dr_scene *s, int n_live)
{
    const int n_groups = (n_live + DR_SIMD_W - 1) / DR_SIMD_W;
    for (int g = 0; g < n_groups; g++) {
        struct dr_path8_in in;
        group_inputs(w, g, n_live, false, &in, NULL);
        dr_path8_ahead_stage(s, &in, 0, &w->ahead[g]);
    }
    for (int stage = 1; stage < DR_PATH8_AHEAD_STAGES; stage++)
        for (int g = 0; g < n_groups; g++)
            dr_path8_ahead_stage(s, NULL, stage, &w->ahead[g]);
    w->ahead_valid = true;
}

/* The kernels work on whole groups: the slots after the last path, up to the
 * group's end, repeat the group's first path. */
static void pad_last_group(struct dr_wave_soa *w, int n_live)
{
    int i0 = (n_live - 1) / DR_SIMD_W * DR_SIMD_W;
    for (int k = n_live; k < i0 + DR_SIMD_W; k++)
        move_path(w, k, i0);
}

/* A replay group's lanes whose shadow ray its log answers (as
 * collect_shadow in wavefront.c: occluded only where a ray would have been
 * cast), their answers set. */
static dr_m8 logged_shadows(struct dr_wave_soa *w, const struct dr_path8 *G, int i0)
{
    dr_m8 logged = {0};
    for (int i = 0; i < G->n; i++) {
        const int k = i0 + i, depth = (int)w->depth[k];
        const struct dr_wave_log *log = replay_log(w, k);
        if (!G->shadow[i] || !log || depth > log->n)
            continue;
        logged[i] = -1;
        w->occluded[k] = G->tmax[i] > 0.0 && log->occ[depth - 1];
    }
    return logged;
}

/* The hit stage of every live path, then their shadow rays as one batch. */
static void shade(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int n_live,
                  bool located, struct dr_ray_counts *counts)
{
    int n_shadow = 0;
    for (int g = 0; g * DR_SIMD_W < n_live; g++) {
        struct dr_path8_in in;
        struct dr_hit *diff_hit[DR_SIMD_W];
        group_inputs(w, g, n_live, located, &in, diff_hit);
        struct dr_path8 *G = &w->group[g];
        dr_path8_shade_lanes(s, opts, &in, G);
        const int i0 = g * DR_SIMD_W;
        memset(w->occluded + i0, 0, sizeof(bool) * (size_t)in.n);
        /* the group's shadow rays appended as whole vectors (counted as
         * dr_path_step counts them: no ray when tmax is not > 0), but a
         * replay's that its log answers */
        dr_m8 cast = G->shadow & first_lanes(in.n);
        if (w->replay)
            cast &= ~logged_shadows(w, G, i0);
        if (w->media)
            cast &= ~shadows_through_media(w, s, G, i0, cast, counts);
        const dr_m8 ray = cast & dr_f8_gt(G->tmax, dr_f8s(0.0));
        const int64_t owner[DR_SIMD_W] = {i0, i0 + 1, i0 + 2, i0 + 3, i0 + 4, i0 + 5, i0 + 6, i0 + 7};
        const struct { void *a; const void *v; } rays[] = {
            {w->sox, &G->so.x}, {w->soy, &G->so.y}, {w->soz, &G->so.z}, {w->sdx, &G->sd.x}, {w->sdy, &G->sd.y},
            {w->sdz, &G->sd.z}, {w->stmax, &G->tmax}, {w->sowner, owner}};
        for (size_t a = 0; a < sizeof rays / sizeof *rays; a++)
            dr_compress8((uint64_t *)rays[a].a + n_shadow, rays[a].v, ray);
        if (keyed_shadows(s))
            dr_compress8(w->skey + n_shadow, G->skey, ray);
        for (int i = 0; i < DR_SIMD_W; i++)
            counts->shadow += cast[i] != 0, n_shadow += ray[i] != 0;
    }
    counts->simd_vertices += (uint64_t)n_live;
    if (w->replay)
        counts->simd_replayed += (uint64_t)n_live;
    struct dr_accel_rays r = {.n = n_shadow, .ox = w->sox, .oy = w->soy, .oz = w->soz,
                              .dx = w->sdx, .dy = w->sdy, .dz = w->sdz, .tmax = w->stmax,
                              .key = keyed_shadows(s) ? w->skey : NULL};
    if (n_shadow > 0) {
        const double t0 = dr_clock_seconds();
        dr_accel_occluded_many(s->accel, &r, w->socc);
        counts->cpu.queries += dr_clock_seconds() - t0;   /* (taken off the shading below: run) */
    }
    for (int j = 0; j < n_shadow; j++) {
        const int64_t k = w->sowner[j];
        w->occluded[k] = w->socc[j];
        log_shadow(w, w->item[k], (int)w->depth[k], w->occluded[k]);
    }
}

/* Lane i of group G, whose vertex has a derivative term, made whole for a
 * hook (a replay's, or a tape's walk): begun from the slot's state, its
 * differentiated hit as the shading kept it (G->diff: w->diff_hit), then
 * the stages' fields (dr_path8_vertex). */
static struct dr_path_vertex *group_vertex(const struct dr_wave_soa *w, const struct dr_scene *s,
                                           const struct dr_path_opts *opts, const struct dr_path8 *G,
                                           const struct dr_path8_out *c, int i)
{
    const int k = (int)(G - w->group) * DR_SIMD_W + i;
    struct dr_path_state st;
    struct dr_path_vertex *v = replay_vertex_begin(w, k, &st);
    if (G->diff[i])
        v->hit = w->diff_hit[k];
    dr_path8_vertex(s, opts, G, c, i, w->tri[k], st.o, st.d, v);
    return v;
}

/* A group's vertices to the walk's hooks (dr_wave_soa_walks), with its
 * throughputs before them (beta, ratio): the lanes in diff (a derivative
 * term: a light's, where a light has a parameter; a BSDF parameter's) to
 * the vertex hook (group_vertex), where the walk has one; the others, and
 * every lane of a walk without one, to the step hook. */
static void steps(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                  const struct dr_path8 *G, const struct dr_path8_out *c, dr_v3x8 beta, dr_v3x8 ratio, dr_v3x8 e,
                  dr_m8 diff)
{
    const int i0 = (int)(G - w->group) * DR_SIMD_W;
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    dr_v3x8 t = dr_v3x8_sel(c->more, dr_v3x8_scale(c->f, c->cos_pdf_q), zero);   /* (tape.c's new_step) */
    dr_v3x8 bt = dr_v3x8_mul(ratio, beta);
    for (int i = 0; i < G->n; i++) {
        const int k = i0 + i;
        if (!diff[i] || !w->out->vertex) {
            w->out->step(w->out->ctx, w->item[k], dr_v3x8_get(&e, i), dr_v3x8_get(&t, i), dr_v3x8_get(&bt, i));
            continue;
        }
        const struct dr_wave_arrival a = {dr_v3x8_get(&beta, i), dr_v3x8_get(&ratio, i)};
        w->out->vertex(w->out->ctx, w->item[k], &a, group_vertex(w, s, opts, G, c, i));
    }
}

/* The group's lanes whose vertex has a derivative term
 * (dr_path_vertex_has_derivative, from the stages' marks). */
static inline dr_m8 differentiated8(const struct dr_path8 *G, const struct dr_path8_out *c)
{
    return G->diff | G->diff_emit | (G->diff_nee & c->nee);
}

/* A replay's step of the group at slot i0 (prb.c's walk_vertex with an
 * adjoint): each vertex's term beta e (be) subtracted from the sums, as the
 * walk subtracts it, into *L (with the tracing throughput) and *T (the true
 * one), and each vertex with a derivative term (the test advance makes for
 * a first walk's last_diff) made whole for the caller. Returns the lanes
 * whose replay goes on past this vertex (prb.c's replay_goes_on: it is
 * before the last such vertex). */
static dr_m8 replay_step(const struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                         const struct dr_path8 *G, const struct dr_path8_out *c, int i0, dr_v3x8 beta, dr_v3x8 ratio,
                         dr_v3x8 be, dr_v3x8 *L, dr_v3x8 *T)
{
    const struct dr_wave_soa_replay_lanes g = replay_lanes(w, i0, beta, ratio, be);
    *L = g.L_sub, *T = g.L_true;
    dr_m8 goes_on = {0};
    const dr_m8 diff = differentiated8(G, c);
    for (int i = 0; i < G->n; i++) {
        const int k = i0 + i;
        goes_on[i] = G->depth[i] < w->last_diff[k] ? -1 : 0;
        if (!diff[i])
            continue;
        w->replay->vertex(w->replay->ctx, w->item[k], group_vertex(w, s, opts, G, c, i), &g, i);
    }
    return goes_on;
}

/* The next-event estimates and continuations: each path's vertex term added
 * to its radiance, the paths that end written out, the others closed up.
 * Returns how many
 * go on. (A path only ever moves to a lower slot, one that has been read
 * already.) */
static int advance(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int n_live,
                   dr_vec3 *out)
{
    int kept = 0;
    for (int g = 0; g * DR_SIMD_W < n_live; g++) {
        const int i0 = g * DR_SIMD_W;
        const struct dr_path8 *G = &w->group[g];
        dr_v3x8 beta = load3(w->bx + i0, w->by + i0, w->bz + i0);
        const dr_m8 occluded = dr_m8_from_bools(w->occluded + i0);   /* (past G->n: masked by go_on) */
        struct dr_path8_out c;
        dr_v3x8 ratio;
        if (w->out)
            ratio = load3(w->rx + i0, w->ry + i0, w->rz + i0);
        dr_path8_continue_lanes(opts, G, beta, w->out ? &ratio : NULL, occluded, &c);
        dr_v3x8 e = dr_path8_term(G, &c);   /* L += beta e, as dr_path_radiance sums */
        dr_v3x8 be = dr_v3x8_mul(beta, e);
        dr_m8 go_on = c.more & first_lanes(G->n);
        dr_v3x8 L, T;
        if (w->replay) {
            go_on &= replay_step(w, s, opts, G, &c, i0, beta, ratio, be, &L, &T);
        } else {
            L = (dr_v3x8){load8(w->Lx + i0) + be.x, load8(w->Ly + i0) + be.y, load8(w->Lz + i0) + be.z};
            T = L;   /* a walk: T += ratio beta e, as prb.c's walk_vertex sums */
            if (w->out)
                T = dr_v3x8_add(load3(w->Tx + i0, w->Ty + i0, w->Tz + i0), dr_v3x8_mul(ratio, be));
        }
        const dr_m8 diff = differentiated8(G, &c);
        if (w->out && w->out->step)
            steps(w, s, opts, G, &c, beta, ratio, e, diff);
        int j = kept;
        for (int i = 0; i < G->n; i++) {
            int k = i0 + i;
            if (w->out && !w->replay && diff[i])
                w->last_diff[k] = (int)G->depth[i];
            if (!go_on[i]) {
                if (w->out)
                    walk_done(w, w->item[k], dr_v3x8_get(&L, i), dr_v3x8_get(&T, i), w->last_diff[k]);
                else
                    out[w->item[k]] = dr_v3x8_get(&L, i);
                continue;
            }
            if (w->structured)
                w->smp[j] = w->smp[k];
            if (w->out)
                w->last_diff[j] = w->last_diff[k];
            j++;
        }
        /* the paths that go on, closed up by whole vectors (after the
         * group's slots were read above) */
        const struct { double *a; const void *v; } moved[] = {
            {w->ox, &c.o.x}, {w->oy, &c.o.y}, {w->oz, &c.o.z}, {w->dx, &c.d.x}, {w->dy, &c.d.y}, {w->dz, &c.d.z},
            {w->px, &G->p.x}, {w->py, &G->p.y}, {w->pz, &G->p.z}, {w->prev_pdf, &c.prev_pdf}, {w->prev_sky, &c.prev_sky},
            {w->bx, &c.beta.x}, {w->by, &c.beta.y}, {w->bz, &c.beta.z}, {w->Lx, &L.x}, {w->Ly, &L.y}, {w->Lz, &L.z}};
        for (size_t a = 0; a < sizeof moved / sizeof *moved; a++)
            dr_compress8(moved[a].a + kept, moved[a].v, go_on);
        dr_compress8(w->depth + kept, w->depth + i0, go_on);
        dr_compress8(w->key + kept, w->key + i0, go_on);
        dr_compress8(w->item + kept, w->item + i0, go_on);
        if (w->out) {
            const struct { double *a; const void *v; } walked[] = {
                {w->rx, &c.ratio.x}, {w->ry, &c.ratio.y}, {w->rz, &c.ratio.z}, {w->Tx, &T.x}, {w->Ty, &T.y}, {w->Tz, &T.z}};
            for (size_t a = 0; a < sizeof walked / sizeof *walked; a++)
                dr_compress8(walked[a].a + kept, walked[a].v, go_on);
        }
        kept = j;
    }
    return kept;
}

/* Slots n_live.. take items next.. up to LANES slots or item n: eight at a
 * time through start8 where it is given, the rest one at a time. Returns the
 * slots live then. */
static int start_paths(struct dr_wave_soa *w, int n_live, int64_t *next, int64_t n, dr_wave_start_fn start,
                       dr_wave_start8_fn start8, void *ctx)
{
    struct dr_sampler smp[8];
    dr_vec3 o[8], d[8];
    while (start8 && n_live + 8 <= LANES && *next + 8 <= n) {
        start8(ctx, *next, smp, o, d);
        for (int j = 0; j < 8; j++)
            start_path(w, n_live++, (*next)++, &smp[j], o[j], d[j]);
    }
    while (n_live < LANES && *next < n) {
        start(ctx, *next, &smp[0], &o[0], &d[0]);
        start_path(w, n_live++, (*next)++, &smp[0], o[0], d[0]);
    }
    return n_live;
}

/* Paths [0, n) to their ends: radiance into L, or (w->out) a walk's sums. */
static void run(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, dr_vec3 *L, struct dr_ray_counts *counts)
{
    const bool prefetch = dr_wave_prefetches(s), picks_ahead = dr_path8_picks_ahead(s);
    int n_live = 0;
    int64_t next = 0;
    w->structured = false;
    /* (dr_wave_soa_applies: a radiance run; dr_wave_soa_media_walks_apply:
     * path replay's walks, which hand back the paths that meet a medium) */
    w->media = (opts->stages & DR_STAGE_MEDIA) && (!w->out || w->out->in_media);
    struct dr_stage_seconds *cpu = &counts->cpu;
    double t = dr_clock_seconds(), t_next;   /* (the stages' times: path.h) */
#define STAGE(field) (t_next = dr_clock_seconds(), cpu->field += t_next - t, t = t_next)
    while (next < n || n_live > 0) {
        int first_new = n_live;
        n_live = start_paths(w, n_live, &next, n, start, start8, ctx);
        STAGE(start);
        trace(w, s, n_live, first_new, prefetch, counts);   /* (its queries, and a pass over the slots) */
        STAGE(queries);
        n_live = end_escaped(w, s, opts, n_live, prefetch, L, counts);
        STAGE(ends);
        if (n_live == 0)
            continue;
        pad_last_group(w, n_live);
        if (prefetch)
            locate_textured(w, s, n_live);
        w->ahead_valid = false;
        if (picks_ahead)
            pick_ahead(w, s, n_live);
        const double shadows = cpu->queries;
        shade(w, s, opts, n_live, prefetch, counts);
        t += cpu->queries - shadows;   /* (counted as queries there) */
        STAGE(shade);
        n_live = advance(w, s, opts, n_live, L);
        STAGE(advance);
    }
#undef STAGE
}

void dr_wave_soa_radiance(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                          int64_t n, dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, dr_vec3 *L,
                          struct dr_ray_counts *counts)
{
    w->out = NULL;
    run(w, s, opts, n, start, start8, ctx, L, counts);
}

bool dr_wave_soa_replay(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts,
                        int64_t n, dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx,
                        const struct dr_wave_soa_replay *replay,
                        struct dr_ray_counts *counts)
{
    /* (zeroed: a field no stage writes reads the same on every run) */
    if (!w->diff_hit && !(w->diff_hit = calloc(SLOTS, sizeof(struct dr_hit))))
        return false;
    if (!w->vertex && !(w->vertex = calloc(1, sizeof(struct dr_path_vertex))))
        return false;
    w->replay_out = (struct dr_wave_soa_walks){0};   /* (a walk's arrays move; nothing is written out) */
    w->out = &w->replay_out;
    w->replay = replay;
    run(w, s, opts, n, start, start8, ctx, NULL, counts);
    w->out = NULL;
    w->replay = NULL;
    return true;
}

bool dr_wave_soa_walk(struct dr_wave_soa *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, const struct dr_wave_soa_walks *out,
                      struct dr_ray_counts *counts)
{
    /* (a tape's walk hands the vertices with a derivative term whole, made
     * as a replay's: group_vertex; zeroed, as the lanes in wavefront.c: a
     * field no stage wrote reads the same on every run) */
    if (out->vertex && !w->vertex && !(w->vertex = calloc(1, sizeof(struct dr_path_vertex))))
        return false;
    if (out->vertex && !w->diff_hit && !(w->diff_hit = calloc(SLOTS, sizeof(struct dr_hit))))
        return false;
    w->out = out;
    run(w, s, opts, n, start, start8, ctx, NULL, counts);
    w->out = NULL;
    return true;
}
