/* The run every estimator shares, so an estimator file holds only its
 * algorithm: set-up (camera, walker options and stages, accumulators),
 * per-thread counters, the sink a thread writes to, forward-mode image
 * channels, and the statistics at the end.
 *
 * An algorithm (struct dr_estimator_ops.run) walks paths with dr_path_step
 * and, per sample of a pixel:
 *     dr_vec3 adj;
 *     if (!dr_est_sample_adjoint(b, pixel, &adj)) skip;   // pixel does not matter
 *     ... d_path_* (..., sink) with adjoints scaled by adj ...
 *     dr_est_sample_done(b, pixel, &sink);                 // forward: its image channels
 * between dr_est_sink_begin / dr_est_sink_end for each piece of work. */
#ifndef DR_ESTIMATORS_COMMON_H
#define DR_ESTIMATORS_COMMON_H

#include "camera.h"
#include "estimator.h"
#include "mis.h"
#include "parallel.h"
#include "path.h"
#include "sampler.h"

/* Per-thread accumulation. Scalar-sized problems sum each chunk of work in a
 * small local buffer first (pairwise-style), so 1e8 samples lose no precision. */
struct dr_est_accum {
    int threads;
    int64_t total;                        /* gradient entries */
    double *grad[DR_MAX_THREADS];         /* reverse mode: thread t's sum; grad[0] is the caller's
                                             output (none with mis or exact) */
    struct dr_exact_sum *exact;           /* instead of grad[]: one shared exact sum (many threads) */
    double *chunk[DR_MAX_THREADS];        /* NULL when total is large */
    double *image[DR_FORWARD_MAX];        /* forward mode: the caller's d images (w*h*3), one a group
                                             (b->n_groups), every thread writes its own pixels */
    uint64_t bytes;                       /* what the buffers above hold */
    struct dr_est_scratch *scratch;       /* where grad[1..] and exact come from, if anywhere
                                             (the problem's: not freed by the run) */
    const struct dr_grad_consumer *consumer;   /* where the sums go instead of grad[0] (then the
                                                  scratch's too): estimator.h */
    uint64_t *touched[DR_MAX_THREADS];    /* with a consumer and no chunks: grad[t]'s block mask, the
                                             scratch's (zero_blocks.h), set by the sinks */
};

/* What the samples of the pixel a thread started last share
 * (dr_est_camera_ray): its place in the frame and its samplers' per-pixel
 * hashes, one set per half under the sobol cross primal (else half[0]).
 * A pixel's samples are started one after another, so most starts reuse
 * it: a Sobol start hashes once instead of nine times. */
struct dr_est_pixel_start {
    bool valid;
    int64_t pixel;
    int x, y;
    struct dr_sampler_pixel half[2];
};

/* Per-thread counters and state, padded apart against false sharing. */
struct dr_est_counters {
    struct dr_ray_counts rays;
    uint64_t invalid;
    struct dr_est_pixel_start start;
    char pad[64];
};

struct dr_est_base {
    const struct dr_grad_problem *p;
    struct dr_camera_view view;
    struct dr_path_opts popts;
    const float *adjoint;   /* reverse mode */
    const double *dir;      /* forward mode (NULL in reverse mode) */
    int n_groups;           /* forward mode: images (grad_sink.h's groups; 1 without) */
    const int64_t *group_end;
    struct dr_est_accum acc;
    struct dr_est_counters thr[DR_MAX_THREADS];
    uint64_t record_bytes;  /* the algorithm's peak recorded-path memory, if any */
    uint64_t scratch_bytes; /* ... and its other working buffers (prb's parked samples) */
    double t0;
    bool mis;               /* --sampling mis that runs as such: samples go to b->mis_acc, not acc */
    struct dr_mis_accum mis_acc;
    struct dr_medium_gain_choice media_gain[DR_STATS_MEDIA_GAIN];   /* (dr_grad_stats') */
    int n_media_gain;
};

/* Sampler and camera ray of sample `sample` of pixel `pixel` (an index into
 * the rendered rectangle; film.h maps it to the frame and draws the filter's
 * offset), started by thread `thread` (its dr_est_pixel_start). */
void dr_est_camera_ray(struct dr_est_base *b, int thread, int64_t pixel, int sample, struct dr_sampler *smp,
                       dr_vec3 *o, dr_vec3 *d);
/* The same for eight samples at once, lane l sample[l] of pixel[l] (any
 * pixels), with dr_est_camera_ray's bits in each lane: the samplers'
 * first draws and the rays eight at a time (sampler8.h, camera8.h), as
 * render's start_run_samples8. */
void dr_est_camera_rays8(struct dr_est_base *b, int thread, const int64_t pixel[8], const int sample[8],
                         struct dr_sampler smp[8], dr_vec3 o[8], dr_vec3 d[8]);

/* The sink a thread writes a piece of work into (reverse mode: a chunk
 * buffer summed into the thread's gradient by dr_est_sink_end). */
struct dr_grad_sink dr_est_sink_begin(struct dr_est_base *b, int thread);
void dr_est_sink_end(struct dr_est_base *b, int thread);

/* The adjoint of one sample's radiance at a pixel: adjoint / spp in reverse
 * mode (false: the pixel does not matter to the loss, skip it), all ones in
 * forward mode (the sink keeps the channels apart). */
bool dr_est_sample_adjoint(const struct dr_est_base *b, int64_t pixel, dr_vec3 *adj);
/* Cross mode (dr_grad_problem.cross): a pixel's sample radiances summed
 * (a non-finite sample counted as 0, as the renderer does), all of them
 * and by half (samples of even and of odd index), by dr_cross_sum_add.
 * dr_est_cross_pixel stores the pixel's mean in the cross image;
 * dr_est_cross_adjoint is the adjoint of the pixel's sample `sample` of
 * radiance L: the loss's adjoint at the mean of the samples independent of
 * it, / spp. With independent numbers those are all the others (leave one
 * out); under the sobol sampler a pixel's halves are two sequences
 * scrambled apart (dr_est_camera_ray), and the sample's are those of the
 * other half. */
struct dr_cross_sum {
    dr_vec3 all, half[2];
};
static inline void dr_cross_sum_add(struct dr_cross_sum *s, int sample, dr_vec3 L)
{
    s->all = dr_add(s->all, L);
    s->half[sample & 1] = dr_add(s->half[sample & 1], L);
}
void dr_est_cross_pixel(const struct dr_est_base *b, int64_t pixel, const struct dr_cross_sum *sum);
dr_vec3 dr_est_cross_adjoint(const struct dr_est_base *b, int64_t pixel, const struct dr_cross_sum *sum, int sample,
                             dr_vec3 L);
/* Forward mode: moves the sink's three channels into the pixel of the d
 * image (divided by spp; the pixel is the calling thread's alone). Reverse
 * mode: nothing. */
void dr_est_sample_done(struct dr_est_base *b, int64_t pixel, struct dr_grad_sink *sink);

/* mis (mis.h): the sinks of one sample of a pixel, for its detached and
 * attached derivatives (reverse mode: the scratch vectors, or the pixel's
 * group's gradient vectors; forward mode: the direction). */
void dr_est_mis_sinks(struct dr_est_base *b, int thread, int64_t pixel, struct dr_grad_sink *det,
                      struct dr_grad_sink *att);
/* After the sample: forward mode moves both sinks' channels into the pixel
 * of the group's images (divided by spp); reverse mode with per-sample
 * statistics moves the scratch vectors into the group (mis.h). */
void dr_est_mis_sample_done(struct dr_est_base *b, int thread, int64_t pixel, struct dr_grad_sink *det,
                            struct dr_grad_sink *att);

#endif
