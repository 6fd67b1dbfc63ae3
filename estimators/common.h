/* What the estimators share: the camera ray of (pixel, sample), the
 * derivative terms of one path vertex, per-thread gradient buffers. */
#ifndef DR_ESTIMATORS_COMMON_H
#define DR_ESTIMATORS_COMMON_H

#include "camera.h"
#include "d_scene.h"
#include "estimator.h"
#include "path.h"
#include "sampler.h"

#define DR_EST_MAX_THREADS 64

/* Sampler and camera ray of sample `sample` of pixel `pixel`. */
void dr_est_camera_ray(const struct dr_grad_problem *p, const struct dr_camera_view *view, int64_t pixel,
                       int sample, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d);

/* The derivative terms a vertex owes regardless of the rest of the path:
 * emission and next-event estimation, with adjoint a = adj * true throughput. */
void dr_est_vertex_terms(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 a, struct dr_grad_sink *sink);
/* The continuation's BSDF term: d_f = adjoint of the BSDF value along v->wi. */
void dr_est_continuation(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 d_f, struct dr_grad_sink *sink);

/* Per-thread accumulation. Scalar-sized problems sum each chunk of work in a
 * small local buffer first (pairwise-style), so 1e8 samples lose no precision. */
struct dr_est_accum {
    int threads;
    int64_t total;              /* gradient entries */
    double *grad[DR_EST_MAX_THREADS];
    double *chunk[DR_EST_MAX_THREADS];   /* NULL when total is large */
    double *image[DR_EST_MAX_THREADS];   /* forward mode: per-thread d image (w*h*3), else NULL */
};
int dr_est_accum_init(struct dr_est_accum *a, const struct dr_grad_problem *p, bool forward);
/* Sums the threads (in thread order) into grad / d_image, then frees. */
void dr_est_accum_finish(struct dr_est_accum *a, const struct dr_grad_problem *p, double *grad, double *d_image);
void dr_est_accum_free(struct dr_est_accum *a);
/* The gradient slots a chunk writes to (chunk buffer or thread buffer). */
double *dr_est_chunk_begin(struct dr_est_accum *a, int thread);
void dr_est_chunk_end(struct dr_est_accum *a, int thread);

/* Per-thread counters, padded apart against false sharing. */
struct dr_est_counters {
    struct dr_ray_counts rays;
    uint64_t invalid;
    char pad[64];
};
/* Sums the threads' counters into *st (when st is not NULL). */
void dr_est_stats_fill(struct dr_grad_stats *st, const struct dr_est_counters *c, int threads, double seconds);

/* What every estimator run holds: the problem, the camera set up for it, the
 * walker's options, the mode (adjoint image for reverse, direction for
 * forward), the accumulators and per-thread counters. */
struct dr_est_base {
    const struct dr_grad_problem *p;
    struct dr_camera_view view;
    struct dr_path_opts popts;
    const float *adjoint;   /* reverse mode */
    const double *dir;      /* forward mode (NULL in reverse mode) */
    struct dr_est_accum acc;
    struct dr_est_counters thr[DR_EST_MAX_THREADS];
    double t0;
};
int dr_est_base_init(struct dr_est_base *b, const struct dr_grad_problem *p, const float *adjoint,
                     const double *dir);
/* Sums the threads into grad / d_image and fills *st (may be NULL). */
void dr_est_base_finish(struct dr_est_base *b, double *grad, double *d_image, struct dr_grad_stats *st);
/* Adjoint of sample L at a pixel in reverse mode: adjoint / spp. */
dr_vec3 dr_est_pixel_adjoint(const struct dr_est_base *b, int64_t pixel);

int dr_est_thread_count(const struct dr_grad_problem *p);
double dr_est_now(void);
bool dr_vec3_finite(dr_vec3 v);

#endif
