/* The packet tracer's radiance in structure-of-arrays form: `render`'s
 * common case, every hit shaded eight lanes at a time (path_simd.h).
 *
 * wavefront.c keeps each path in a lane structure of about 1.9 KB (its
 * state, sampler, whole vertex, replay log and caller's state) and gathers
 * eight of them into vectors at every stage; most of its own time went to
 * cache misses on those structures, visited five times per step. Here a
 * path is a slot in a set of arrays that hold only what the radiance needs
 * (ray, throughput, previous point and density, depth, sampler key or a
 * structured sampler, sum),
 * live paths are kept contiguous (compacted after every bounce), and a
 * group of eight is eight consecutive slots. The shading is path_simd.c's
 * kernels, so every path gets the same bits as the one-path walker
 * (test_render compares them in double).
 *
 * It applies where every hit can take the eight-lane stages: a run that
 * dr_path8_applies to, without parameters (dr_wave_soa_walk: with them).
 * Every path of a run must have a sampler of one kind.
 * Rays that leave the scene end there, with the environment's radiance
 * eight at a time where dr_path8_env_eight (renders, and walks without a
 * step hook: prb's), else one by one. */
#ifndef DR_WAVE_SOA_H
#define DR_WAVE_SOA_H

#include <stddef.h>
#include <stdint.h>

#include "path.h"
#include "scene.h"
#include "simd.h"
#include "wavefront.h"

struct dr_wave_soa;

/* Working storage of one thread. NULL: out of memory. */
struct dr_wave_soa *dr_wave_soa_create(void);
void dr_wave_soa_destroy(struct dr_wave_soa *w);
/* Bytes dr_wave_soa_create allocates (for memory estimates). */
size_t dr_wave_soa_bytes(void);

/* Can a radiance run use it (opts without parameters)? */
bool dr_wave_soa_applies(const struct dr_scene *scene, const struct dr_path_opts *opts);

/* What a gradient's primal walks give of each path, by item (the lanes'
 * walks of the same paths give the same: estimators/prb.c, tape.c). Every
 * member may be NULL (not wanted). */
struct dr_wave_soa_walks {
    /* path replay's (prb.c) */
    dr_vec3 *L;                 /* the radiance (with the true throughput, summed as prb's walk sums) */
    dr_vec3 *L_sub;             /* ... and with the substitutes' (path.h) */
    int *last_diff;             /* the depth of the last vertex with a derivative term (0: none) */
    struct dr_wave_log *log;    /* the walk's ray answers for its replay */
    /* a tape's (tape.c), each path's vertices in order: */
    void *ctx;
    /* a vertex without a derivative term: its term e (dr_path_vertex_term),
     * its continuation's factor t (f |cos| / pdf / q; 0 where the path ends)
     * and the true throughput bt (ratio beta) it was reached with */
    void (*step)(void *ctx, int64_t item, dr_vec3 e, dr_vec3 t, dr_vec3 bt);
    /* a vertex with a derivative term (on a material with a BSDF
     * parameter, or a light's term where a light has a parameter), whole,
     * reached with a: made from the eight-lane stages as a replay's, as far
     * as d_path_vertex and the continuation read it (the differentiated hit
     * the shading kept, the emitter's hit, the light sample's record); an
     * escaped vertex under an environment parameter from the scalar escaped
     * stage. NULL (prb's walks): every vertex to step, if given. */
    void (*vertex)(void *ctx, int64_t item, const struct dr_wave_arrival *a, const struct dr_path_vertex *v);
    /* in a scene with media (dr_wave_soa_media_walks_apply; NULL
     * elsewhere), by item: the path met a medium (its ray hit a medium's
     * boundary, or it started in one, or a shadow ray of it crossed a
     * medium's box). Its sums, last_diff and log are not given: the caller
     * walks it one path at a time, from its start. Every item's is set. */
    bool *in_media;
};

/* Can a gradient's primal walks use the arrays (parameters allowed, a
 * light's radiance's too: dr_path8_walks_apply)? Every hit then takes the
 * eight-lane stages, the vertices with a derivative term included. */
bool dr_wave_soa_walks_apply(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* Can a gradient's primal walks (path replay's, a tape's) use the arrays
 * in a scene with media, for the paths that meet none
 * (dr_wave_soa_walks.in_media, which such walks must be given)? Where
 * every medium is bounded by a mesh and the eight-lane stages take every
 * hit. The media's parameters are then as if absent: no vertex of such a
 * path has a media term. The
 * hooks may have been called for a path's first vertices before it was
 * handed back: the caller drops them. */
bool dr_wave_soa_media_walks_apply(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* Bytes dr_wave_soa_create and dr_wave_soa_walk allocate (for memory estimates). */
size_t dr_wave_soa_walk_bytes(void);

/* The primal walks of paths [0, n) (started by start, or eight at a time
 * by start8 where not NULL) into out, with the decisions and sums of
 * dr_wave_run's walks of the same paths (prb.c's lane_vertex without a
 * sink). False: no memory for its working storage (nothing walked). */
bool dr_wave_soa_walk(struct dr_wave_soa *w, const struct dr_scene *scene, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, const struct dr_wave_soa_walks *out,
                      struct dr_ray_counts *counts);

/* Path replay's second walks (prb.c) in the arrays: the walk of each path
 * again, with the same sampler, ray and decisions (its ray answers from the
 * first walk's log where it holds them, as a DR_WAVE_REPLAY of dr_wave_run,
 * whose replays give the same vertices), each vertex's term subtracted from
 * the first walk's sums, to the depth of its last vertex with a derivative
 * term. Item k replays the first walk of sample `sample[k]`. */
/* A replay group's sums and throughputs at a vertex, lane by lane
 * (dr_v3x8_get(&beta, i): lane i's): the throughput the vertex was reached
 * with (beta, ratio), the sums with its term subtracted (L_true, L_sub)
 * and the true one before (remaining). */
struct dr_wave_soa_replay_lanes {
    dr_v3x8 beta, ratio, remaining, L_true, L_sub;
};

struct dr_wave_soa_replay {
    void *ctx;
    const int32_t *sample;
    const dr_vec3 *L, *L_sub;           /* by sample: the first walk's sums (dr_wave_soa_walks') */
    const int *last_diff;
    const struct dr_wave_log *log;      /* NULL: every ray traced again */
    /* A vertex with a derivative term (dr_path_vertex_has_derivative) in
     * lane i of a group, whole as far as prb's adjoints read it (as
     * dr_wave_run's lanes give it with partial_vertices, light_terms and
     * bsdf_terms), with its lane's sums in g. (The group's vectors, not
     * one lane's values: values passed one by one were stored just before
     * the call and read back at once, a store-forwarding stall each.) */
    void (*vertex)(void *ctx, int64_t item, const struct dr_path_vertex *v, const struct dr_wave_soa_replay_lanes *g,
                   int i);
};

/* Can a gradient's replays use the arrays? Where the primal walks can
 * (dr_wave_soa_walks_apply's sums_only). Where the environment has a
 * parameter, a path that leaves the scene ends on a vertex with a
 * derivative term: the replay makes it, as the one-path walker's escaped
 * stage does, for the caller's vertex hook. */
bool dr_wave_soa_replays_apply(const struct dr_scene *scene, const struct dr_path_opts *opts);

/* The replays of items [0, n) (start: item k's sampler and camera ray;
 * start8, if not NULL, eight items' at once, as in dr_wave_radiance).
 * False: no memory for its working storage (nothing replayed). */
bool dr_wave_soa_replay(struct dr_wave_soa *w, const struct dr_scene *scene, const struct dr_path_opts *opts,
                        int64_t n, dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx,
                        const struct dr_wave_soa_replay *replay,
                        struct dr_ray_counts *counts);

/* L[i] = the radiance of path i for i in [0, n), as dr_wave_radiance. */
void dr_wave_soa_radiance(struct dr_wave_soa *w, const struct dr_scene *scene, const struct dr_path_opts *opts,
                          int64_t n, dr_wave_start_fn start, dr_wave_start8_fn start8, void *ctx, dr_vec3 *L,
                          struct dr_ray_counts *counts);

#endif
