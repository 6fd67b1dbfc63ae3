/* Derivatives with respect to media parameters (medium_grad.c). */
#ifndef DR_MEDIUM_GRAD_H
#define DR_MEDIUM_GRAD_H

#include "path.h"

/* Every media-parameter derivative vertex v contributes, from what the walker
 * recorded in rec (nothing unless the vertex came from the medium walker with
 * media parameters requested); path_vertices: how many the path has (DRT's
 * gain paths are spread over them so the cost stays linear in its length):
 *   d_beta = adjoint (x) the true throughput arriving at the segment into v;
 *   d_R   = adjoint (x) the true radiance the path gathers from v on, v's own terms included;
 *   d_Rn  = the same from the next vertex on;
 *   d_nee = adjoint (x) v's next-event contribution (true throughput).
 * Forward mode: the channels of these land in the sink's channels. */
void d_medium_vertex(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                     const struct dr_medium_record *rec, int path_vertices, dr_vec3 d_beta, dr_vec3 d_R,
                     dr_vec3 d_Rn, dr_vec3 d_nee, struct dr_grad_sink *sink);

/* Does d_medium_vertex give v a term? Only where media parameters are
 * requested and v's segment or shadow ray crossed a medium (the recorded
 * pieces, which its gain paths follow too) or v scattered in a
 * differentiated one: a vertex of the medium walker whose rays stayed out
 * of every medium has none. Read right after the walker's step (v->mrec
 * then holds v's pieces). */
bool dr_medium_vertex_has_derivative(const struct dr_param_set *params, const struct dr_path_vertex *v);

/* Where DRT takes the sigma_t share of scattering in a thin homogeneous
 * medium (thickness below 1, medium_grad.c's gain_at_collisions):
 * from the path's collisions where a pilot saw many of the stretches
 * through the medium end in one, else from gain paths. The estimators run the pilot
 * (estimators/common.c) where dr_medium_gain_pilot_wanted says so, tally
 * its vertices per medium and decide into dr_path_opts.collision_gain. */
struct dr_medium_tally {
    uint64_t stretches, collisions;
};
/* Is some medium whose sigma_t DRT differentiates (opts) of that kind? */
bool dr_medium_gain_pilot_wanted(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* Adds the stretches of media vertex v's incoming flight crossed (its
 * record, v->mrec: the walker fills it where media parameters are
 * requested), and its collision, to their media's tallies (one per medium). */
void dr_medium_tally_vertex(const struct dr_path_vertex *v, struct dr_medium_tally *t);
/* collision_gain[i] (one per medium): the tally of medium i says collisions. */
void dr_medium_gain_decide(const struct dr_scene *scene, const struct dr_medium_tally *t,
                           unsigned char *collision_gain);
/* The pilot's choice kept for later runs of the same problem (a
 * dr_grad_problem's media_plan, the caller's): the runs of a command's
 * batches, of its parameters one by one, of compare's estimators, reuse it
 * where what it depends on is the same (key: the scene, camera, image and
 * film, depth, Russian roulette, stages and every medium's values), so the
 * pilot is paid once, not per run. Surfaces are not in the key: a caller
 * that changes them between runs (optimize's steps) uses a fresh plan.
 * Zeroed: empty. */
struct dr_media_plan {
    bool valid;
    uint64_t key;
    int n_media;
    unsigned char *collision_gain;   /* per medium, as dr_path_opts.collision_gain */
    struct dr_medium_tally *tally;   /* per medium: the pilot's */
};
void dr_media_plan_free(struct dr_media_plan *plan);   /* (zeroes it) */
/* h hashed on with every medium's values the pilot's choice depends on. */
uint64_t dr_media_values_hash(const struct dr_scene *scene, uint64_t h);

/* The pilot's paths (spread over the rendered pixels, a fixed seed, one
 * thread: every batch, seed and thread count decide alike) and its longest. */
#define DR_MEDIUM_PILOT_PATHS 1024
#define DR_MEDIUM_PILOT_VERTICES 64

/* For the reports: where DRT took a differentiated medium's sigma_t gain,
 * and why: a medium with a channel that does not scatter (extinction or
 * albedo 0) takes gain paths, a thick homogeneous one and a grid the
 * collisions (a grid's voxels gain paths), a thin homogeneous one the
 * pilot's choice. */
enum dr_gain_reason { DR_GAIN_NONSCATTERING, DR_GAIN_THICK, DR_GAIN_GRID, DR_GAIN_PILOT };
struct dr_medium_gain_choice {
    int material;                  /* the medium's boundary material (-1: the global medium) */
    bool collisions;               /* from the path's collisions, else from gain paths */
    bool grid;                     /* a grid: its voxels' gain from gain paths */
    enum dr_gain_reason why;
    uint64_t stretches, collided;  /* the pilot's tally (why == DR_GAIN_PILOT; else 0) */
};
/* The choices for the media whose sigma_t opts differentiates with DRT (none
 * with the baseline), the first max of them, into out; t: the pilot's
 * tally, or NULL if none ran. Returns how many. */
int dr_medium_gain_choices(const struct dr_scene *scene, const struct dr_path_opts *opts,
                           const struct dr_medium_tally *t, struct dr_medium_gain_choice *out, int max);
#define DR_STATS_MEDIA_GAIN 8
/* "nonscattering_channel", "thick", "grid", "pilot" (--json). */
const char *dr_gain_reason_name(enum dr_gain_reason r);

/* Radiance scattered at x (in medium `medium`, the ray arriving along d)
 * towards -d, per unit scattering coefficient: NEE and a phase-sampled path
 * from x as if the path's vertex `depth` were there (medium_path.c). */
dr_vec3 dr_medium_inscattered(const struct dr_scene *scene, const struct dr_path_opts *opts, dr_vec3 x, dr_vec3 d,
                              int medium, int depth, uint64_t key, struct dr_ray_counts *counts);

/* v's next-event term (what dr_path_vertex_term adds for NEE). */
static inline dr_vec3 dr_path_vertex_nee(const struct dr_path_vertex *v)
{
    return v->nee ? dr_scale(dr_mul(v->nee_f, v->ls.radiance), v->nee_scale) : dr_v3s(0.0);
}

#endif
