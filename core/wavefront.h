/* Many paths advanced together, one stage at a time (the packet tracer):
 * every live path is traced in one batch of Embree packets, shaded, its
 * shadow rays tested in a second batch, and continued; a lane whose work
 * ends takes the next item. Each path runs exactly the one-path walker's
 * stages (path.h: dr_path_step cut at its ray queries), so it makes the same
 * decisions with the same numbers; only the order in which paths are worked
 * on changes. Scenes with media use the one-path walker (a render's
 * radiance, where every medium is bounded, the packet tracer until a path
 * could meet one: wave_soa.c's finish_in_media).
 *
 * A lane works on one item (a pixel sample) at a time, as one or more walks
 * (render: one; path replay: the primal walk, then the replay). What a walk
 * does with its vertices is the caller's (struct dr_wave_ops). */
#ifndef DR_WAVEFRONT_H
#define DR_WAVEFRONT_H

#include <stddef.h>
#include <stdint.h>

#include "path.h"
#include "sampler.h"
#include "scene.h"

/* Paths in flight per wavefront: four 16-wide packets. */
#define DR_WAVE_LANES 64
/* Bytes of the caller's per-lane state (dr_wave_ops.user). */
#define DR_WAVE_USER_BYTES 320

/* The walker's state a vertex was reached with (what the throughput was). */
struct dr_wave_arrival {
    dr_vec3 beta, ratio;
};

/* What a lane does when its walk ends (dr_wave_ops.walk_end). */
enum dr_wave_next {
    DR_WAVE_DONE,     /* the item is finished: the lane takes the next */
    DR_WAVE_WALK,     /* another walk of the item, from the sampler and ray set */
    DR_WAVE_REPLAY    /* the same walk again (same sampler, ray, and decisions,
                         as path replay's second pass): its first
                         DR_WAVE_REPLAY_DEPTH vertices' ray queries are answered
                         from what the walk before found instead of traced */
};
/* Vertices per lane whose trace and shadow-ray answers are kept for a
 * replay: a constant, so memory does not grow with the path's length
 * (longer paths trace the rest again). */
#define DR_WAVE_REPLAY_DEPTH 32

/* A walk's ray answers by vertex (depth - 1), for a replay of it. */
struct dr_wave_log {
    int n;                                  /* vertices logged */
    int64_t tri[DR_WAVE_REPLAY_DEPTH];      /* the trace's answer */
    bool occ[DR_WAVE_REPLAY_DEPTH];         /* the shadow ray's */
};

/* *to = *from as far as a replay reads it: the first n answers (a whole
 * struct is 300 bytes, most paths log a few vertices). */
static inline void dr_wave_log_copy(struct dr_wave_log *to, const struct dr_wave_log *from)
{
    to->n = from->n;
    for (int i = 0; i < from->n; i++) {
        to->tri[i] = from->tri[i];
        to->occ[i] = from->occ[i];
    }
}

/* dr_path_step, with the ray answers of the vertices log holds taken from
 * it instead of traced (a replay, one path at a time, of the walk that
 * logged them: the same sampler and decisions make the same queries, as in
 * DR_WAVE_REPLAY; counts then counts no ray for them). log NULL, vertices
 * past it, and scenes with media (whose walks log nothing): traced. */
bool dr_wave_log_step(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_wave_log *log,
                      struct dr_path_state *st, struct dr_sampler *sampler, struct dr_path_vertex *v,
                      struct dr_ray_counts *counts);

struct dr_wave_ops {
    /* Begins item i in a lane: its state in user (DR_WAVE_USER_BYTES,
     * zeroed), the first walk's sampler and ray. */
    void (*start)(void *ctx, int64_t i, void *user, struct dr_sampler *sampler, dr_vec3 *o, dr_vec3 *d);
    /* Vertex v of the walk, reached with throughput a; more: the walk goes
     * on. Returns false to end the walk here (then walk_end follows). */
    bool (*vertex)(void *ctx, void *user, const struct dr_wave_arrival *a, const struct dr_path_vertex *v,
                   struct dr_sampler *sampler, bool more);
    /* The walk ended: what next (DR_WAVE_WALK and DR_WAVE_REPLAY: set
     * *sampler, *o, *d to the next walk's start). */
    enum dr_wave_next (*walk_end)(void *ctx, void *user, struct dr_sampler *sampler, dr_vec3 *o, dr_vec3 *d);
    /* Optional (NULL: none), for a replay that comes later, in another run:
     * keep_log gets a traced walk's answers just before its walk_end;
     * replay_log, called after start, returns the answers of an earlier walk
     * with the same sampler and ray (NULL: none), and then the item's first
     * walk is a replay of it (as DR_WAVE_REPLAY). */
    void (*keep_log)(void *ctx, void *user, const struct dr_wave_log *log);
    const struct dr_wave_log *(*replay_log)(void *ctx, void *user);
    /* At a vertex dr_path_vertex_has_derivative calls derivative-free,
     * vertex reads only what dr_path_vertex_term (the radiance),
     * dr_path_vertex_has_derivative and v->depth read, and the
     * continuation's factor (v->cont, v->f, v->cos_pdf_q): then the lanes the
     * eight-lane stages accept (path_simd.h; only such vertices) are shaded
     * by them, in first walks and replays alike. */
    bool partial_vertices;
    /* With partial_vertices: vertex also takes the eight-lane stages'
     * vertices whose emission or light sample has a derivative term, in a
     * run with a light parameter (dr_path8_walks_apply), and reads of them
     * what d_path_vertex_term reads without a BSDF parameter (the hit of a
     * differentiated emitter, the light sample's record), which the stages
     * then fill (path_simd.h). Without it such runs take the scalar stages. */
    bool light_terms;
    /* With partial_vertices: vertex also takes the eight-lane stages'
     * vertices on materials with a BSDF parameter, whole as far as the
     * adjoints of their terms read them (dr_path8_shade says what the stages
     * fill; prb's walks and replays). Without it they take the scalar
     * stages (the tape's lanes, its record where the arrays, wave_soa.h,
     * cannot be had). */
    bool bsdf_terms;
    /* Optional (NULL: never), with partial_vertices and without bsdf_terms:
     * called at each walk's start and after each vertex the walk goes on
     * from; true sends the walk's next vertex to the scalar stages, whole. The caller decides which of
     * its vertices it reads whole, so the rule lives in one place, its own:
     * the tape's record asks for every vertex after a path's first moving
     * one under attached sampling (d_path_vertex_attached reads them), and
     * for the vertex after one with a BSDF parameter under derivative
     * sampling (d_path_deriv_emission reads its emission). */
    bool (*next_whole)(void *ctx, void *user);
    /* Optional (NULL: none): adjusts the state each walk begins in
     * (dr_path_start from the ray start or walk_end gave; user already set),
     * for a walk that continues another from its middle: derivative
     * sampling's radiance walks (path_deriv.h) start at a vertex's depth,
     * with its point and the forward density of their direction. */
    void (*start_state)(void *ctx, void *user, struct dr_path_state *st);
};

struct dr_wave;

/* Working storage of one thread (about DR_WAVE_LANES path vertices). NULL: out of memory. */
struct dr_wave *dr_wave_create(void);
void dr_wave_destroy(struct dr_wave *wave);
/* Bytes dr_wave_create allocates (for memory estimates). */
size_t dr_wave_bytes(void);

/* Works items [0, n) to their end, at most DR_WAVE_LANES at a time, started
 * in order. */
void dr_wave_run(struct dr_wave *wave, const struct dr_scene *scene, const struct dr_path_opts *opts, int64_t n,
                 const struct dr_wave_ops *ops, void *ctx, struct dr_ray_counts *counts);

/* Whether dr_wave_run locates all its lanes' hits and prefetches what
 * shading them reads (their triangles, vertices and texels) before shading
 * any: when the scene has textures, or its per-vertex and per-triangle
 * arrays outgrow 1 MiB, so that cache misses overlap instead of stalling one
 * lane after another. A small untextured scene is shaded in one pass per
 * step instead: there the extra pass over the lanes costs a few percent and
 * saves nothing (measured on the peer's Cornell box). Results are the same
 * either way. */
bool dr_wave_prefetches(const struct dr_scene *scene);

/* Starts path i: its sampler, and its camera ray o + t d. */
typedef void (*dr_wave_start_fn)(void *ctx, int64_t i, struct dr_sampler *sampler, dr_vec3 *o, dr_vec3 *d);
/* Starts paths first .. first + 7 at once, as eight calls of the caller's
 * dr_wave_start_fn would (into samplers[0..7], o[0..7], d[0..7]): its
 * vector form, where the starts vectorise (render's camera rays). */
typedef void (*dr_wave_start8_fn)(void *ctx, int64_t first, struct dr_sampler *samplers, dr_vec3 *o, dr_vec3 *d);

/* L[i] = the radiance of path i for i in [0, n), what dr_path_radiance gives
 * for the same start (up to exact ties between triangles, accel.h). Every
 * path's sampler must be of one kind. Where the eight-lane stages shade
 * every hit (wave_soa.h), the paths are kept in arrays instead of lanes,
 * and started eight at a time by start8 where it is given (else, and for a
 * run's last few, one at a time by start). */
void dr_wave_radiance(struct dr_wave *wave, const struct dr_scene *scene, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, dr_vec3 *L,
                      struct dr_ray_counts *counts);
/* The same always through the lanes (dr_wave_run), as the gradients' walks
 * use them: what dr_wave_radiance does where the arrays do not apply (and
 * test_render holds to the one-path walker's bits too). */
void dr_wave_radiance_lanes(struct dr_wave *wave, const struct dr_scene *scene, const struct dr_path_opts *opts,
                            int64_t n, dr_wave_start_fn start, void *ctx, dr_vec3 *L, struct dr_ray_counts *counts);

/* Derivative sampling's radiance walks of rays r[0..n) (path_deriv.h) into
 * out[0..n), on the lanes: what dr_path_deriv_radiance gives for each (to
 * rounding: the lanes shade most vertices eight at a time). Not for scenes
 * with media. */
struct dr_deriv_ray;
struct dr_deriv_light;
void dr_wave_deriv_radiance(struct dr_wave *wave, const struct dr_scene *scene, const struct dr_path_opts *opts,
                            int64_t n, const struct dr_deriv_ray *r, struct dr_deriv_light *out,
                            struct dr_ray_counts *counts);

#endif
