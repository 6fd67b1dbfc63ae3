/* Gradient estimators: coarse-grained plug-ins behind one interface.
 * Adding one = one .c file in estimators/ + one line in registry.c.
 *
 * Both modes differentiate the rendered image I (mean of `spp` samples per
 * pixel) with respect to the parameters of `params`. The sampling mode says
 * how sampled quantities enter the derivative: `detached` (directions, pdfs,
 * MIS weights and Russian roulette are constants of the derivative:
 * differentiate-then-reparametrize with the forward sampler) or `attached`
 * (directions, hit points, pdfs and MIS weights move with the parameters:
 * reparametrize-then-differentiate; see path.h), `mis` (both from the
 * same paths, combined with per-parameter weights: mis.h), or `derivative`
 * (detached, plus directions drawn from densities made for the BSDF's
 * derivative and combined by MIS: reparametrize-then-differentiate-then-
 * reparametrize; see path_deriv.h). */#ifndef DR_ESTIMATOR_H
#define DR_ESTIMATOR_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "film.h"
#include "loss.h"
#include "medium_grad.h"
#include "sampler.h"
#include "parallel.h"
#include "params.h"
#include "path.h"
#include "scene.h"

enum dr_sampling {
    DR_SAMPLING_DETACHED,   /* differentiate-then-reparametrize */
    DR_SAMPLING_ATTACHED,   /* reparametrize-then-differentiate (path.h: what moves, what stays) */
    DR_SAMPLING_MIS,        /* both from the same paths, combined per parameter with weights
                               estimated by cross-fitting (mis.h) */
    DR_SAMPLING_DERIVATIVE, /* detached + a direction sampled for d f / d theta, by MIS (path_deriv.h) */
    DR_SAMPLING_DERIVATIVE_ROUGHNESS, /* derivative sampling for the roughness alone: base colour and
                                         metallic keep detached sampling's strategies (path_deriv.h) */
    DR_SAMPLING_COUNT
};
/* "detached", "attached", "mis", "derivative", "derivative-roughness"; and
 * back (-1: unknown name). */
const char *dr_sampling_name(enum dr_sampling s);
int dr_sampling_parse(const char *name);

/* One of the two derivative sampling modes (the same estimator, path_deriv.h). */
static inline bool dr_sampling_is_derivative(enum dr_sampling s)
{
    return s == DR_SAMPLING_DERIVATIVE || s == DR_SAMPLING_DERIVATIVE_ROUGHNESS;
}
/* The BSDF inputs (enum dr_bsdf_dparam bits) a derivative sampling mode
 * samples directions for (dr_path_opts.deriv_params); 0 for the others. */
unsigned dr_sampling_deriv_params(enum dr_sampling s);

struct dr_mis_history;
struct dr_estimator_ops;

/* Reverse mode with the loss's adjoint taken from the estimator's own paths
 * (the reverse driver's cross primal, reverse.h), instead of an adjoint
 * image from a separate primal render. Each sample's derivative is weighted
 * with the loss's adjoint at the mean of its pixel's other samples (leave
 * one out): that mean is independent of the sample, so the estimate is
 * unbiased, as with a separate primal (for l2 it is the U-statistic of the
 * product of the two means, the least-variance unbiased use of the same
 * paths), and the primal costs nothing beyond the walks the gradient makes
 * anyway. Needs spp >= 2 and not the stratified sampler, which makes a
 * pixel's samples depend on each other (they share the strata): the mean of
 * the others would then be correlated with the sample, a bias of order
 * 1/spp. Under the sobol sampler a pixel's samples of even and of odd index
 * are two sequences scrambled apart, and a sample's weight is the adjoint at
 * the mean of the other half (common.h, dr_est_cross_adjoint). */
struct dr_cross_loss {
    enum dr_loss_kind loss;
    const float *target;   /* the rendered rectangle's width * height * 3 values */
    double scale;          /* d_out of the loss */
    double *image;         /* out: each pixel's mean radiance over all its samples (width * height * 3) */
};

struct dr_grad_problem {
    const struct dr_scene *scene;
    const struct dr_camera *camera;
    const struct dr_param_set *params;
    int width, height, spp, max_depth, rr_depth;
    uint64_t seed;
    int threads;               /* <= 0: one per CPU (at most DR_MAX_THREADS) */
    int64_t batch;             /* tape: paths per record/sweep (0: one sample of every pixel) */
    enum dr_sampling sampling;
    /* The pixel filter and the crop (zeroed: box, whole frame). width and
     * height above are the rendered rectangle: estimators iterate its pixels
     * and every image (adjoint, d image) has its size. */
    struct dr_film film;
    enum dr_sampler_kind sampler;   /* the random numbers (zero: independent) */
    double regularize;         /* prb, attached: Jacobians with sigma_min/sigma_max below this are not
                                  inverted, forward mode restarts there (0: always invert) */
    enum dr_medium_grad medium_grad;   /* media: DRT (default, 0) or the biased baseline (path.h) */
    double *mis_weights;       /* mis (optional output): params->n entries, each parameter's weight of
                                  the detached estimate (mean over the groups, mis.h); 1 where the
                                  run was detached. Left alone by the other modes */
    struct dr_mis_history *mis_history;   /* mis (optional, in/out): statistics of earlier runs of
                                             this problem for the weights (mis.h); NULL: this run's only */
    const struct dr_cross_loss *cross;    /* reverse mode: the adjoint from the paths themselves (NULL: from
                                             the adjoint image dr_estimator_backward is given) */
    struct dr_media_plan *media_plan;     /* DRT (optional, in/out): the media pilot's choice, reused by
                                             later runs where it still applies (medium_grad.h); NULL:
                                             every run that needs one pilots */
    struct dr_est_scratch *scratch;       /* reverse mode (optional, in/out): the run's own gradient
                                             vectors, kept for the next run (below); NULL: allocated
                                             and freed by every run */
    const struct dr_grad_consumer *consumer;   /* reverse mode (optional): the gradient handed over in
                                                  pieces instead of written whole (below) */
    bool one_path_walks;       /* prb, detached (tests): walk one path at a time where the wavefront or
                                  the arrays would run, so test_estimators can hold the two equal (no
                                  user-facing mode walks this way: it is the slower of the two) */
};

/* Where a reverse-mode run can hand its gradient instead of writing it to
 * the caller's vector: take(ctx, begin, end, g, mask) gets g[k] = entry
 * begin + k (the bits the vector would hold), every entry exactly once, in
 * pieces of at most 1024 that begin at multiples of 1024 (the last may be
 * shorter), from several threads at once (disjoint pieces). A caller that
 * folds the gradient into running sums (reverse.h's batches: Welford) so
 * reads the threads' sums while they are in the cache: no vector is
 * written with them and read back (thread 0 then sums into a scratch
 * vector, not the caller's: the same memory), two passes over a texture's
 * gradient less per run. mask, when not NULL, is the piece's block mask
 * (zero_blocks.h; its word 0 is entry begin's): only the marked blocks of
 * g are written, the others are +0 and g there holds anything. It is given
 * where the estimator tracked which blocks its paths reached (more than
 * 4096 entries), so that a preview's texture gradient, a few per cent of
 * the entries, costs what it touches. Honoured where
 * dr_estimator_consumes says so (the threads' vectors, or the shared exact
 * sum, must be the scratch's); dr_estimator_backward's grad may then be
 * NULL. */
struct dr_grad_consumer {
    void (*take)(void *ctx, int64_t begin, int64_t end, const double *g, const uint64_t *mask);
    void *ctx;
};

/* The big vectors a reverse-mode run sums into besides the caller's: the
 * second and later threads' gradient vectors, or from four threads on the
 * shared exact sum (dr_estimator_shared_sums). A texture parameter makes
 * them big (100 MB for a 2k texture), and fresh memory is expensive on
 * the virtual machines drender runs on: the kernel maps and zeroes every
 * page at its first touch, about 60 ms per 100 MB, which was 15 % of a
 * 2k-texture gradient's time (4 batches, 2 threads). A caller that runs
 * the same problem many times (grad's batches, optimize's iterations)
 * keeps them here: a later run of the same size clears memory it already
 * holds instead. Caller-owned, zero-initialised; dr_est_scratch_free
 * releases what the runs left (and zeroes it). The results are the same
 * to the bit with or without it. */
struct dr_exact_sum;   /* exact_sum.h */
struct dr_est_scratch {
    double *grad[DR_MAX_THREADS];   /* [0]: only with a consumer (else thread 0 sums into the caller's vector) */
    int64_t len[DR_MAX_THREADS];
    bool dirty[DR_MAX_THREADS];     /* grad[t] may hold non-zero entries (false: the run that summed it
                                       cleared it as it read it, so the next one need not) */
    uint64_t *touched[DR_MAX_THREADS];   /* with a consumer: thread t's block mask (zero_blocks.h) of
                                            grad[t] or of the exact sum, all clear between runs but
                                            after a failed one (dirty, exact_dirty) */
    struct dr_exact_sum *exact;
    int64_t exact_len;
    bool exact_dirty;               /* exact may hold non-zero entries (false: a consumer's run read and
                                       cleared it as it went) */
    bool many_runs;                 /* set by a caller that runs the problem many times (optimize): the
                                       masked runs' vectors in huge pages too, resident in 2 MiB pages
                                       where written but passed over sparsely run after run without a
                                       TLB miss a block (with 4 KiB pages optimize's iterations were
                                       10-20 % slower); else in 4 KiB pages (bigalloc.h) */
};
void dr_est_scratch_free(struct dr_est_scratch *s);

/* The sampling an algorithm runs: attached (or mis) sampling where no
 * requested parameter enters a sampling map, and derivative sampling with no
 * BSDF parameter, is detached sampling, bit for bit, and runs as such
 * (path.h). */
enum dr_sampling dr_est_sampling_run(const struct dr_grad_problem *p);

/* What estimator e with p->sampling cannot run on p's scene and parameters
 * (media, normal maps, a mode it does not implement): 0, or DR_ERR_ARG with
 * the message set. Every run checks it first; front ends call it before any
 * work to report bad usage. */
int dr_estimator_check(const struct dr_estimator_ops *e, const struct dr_grad_problem *p);

/* prb --sampling attached: the default --regularize. */
#define DR_PRB_REGULARIZE_DEFAULT 1e-3

struct dr_grad_stats {
    double seconds;
    struct dr_ray_counts rays;
    uint64_t invalid_samples;   /* non-finite path values or derivatives dropped */
    uint64_t memory_bytes;      /* peak bytes the estimator held: gradient buffers, images, records */
    uint64_t record_bytes;      /* the part holding recorded path vertices (tape), 0 if none */
    unsigned stages;            /* the walker's optional stages that ran (path.h) */
    int threads;
    enum dr_sampling sampling_run;   /* what ran: attached or mis with no parameter entering a
                                        sampling map is detached (identical, cheaper) */
    /* DRT: where each medium whose sigma_t is differentiated took its
     * scattering gain (medium_grad.h; the first DR_STATS_MEDIA_GAIN) */
    struct dr_medium_gain_choice media_gain[DR_STATS_MEDIA_GAIN];
    int n_media_gain;
};

struct dr_est_base;   /* common.h: the run every estimator shares */

struct dr_estimator_ops {
    const char *name, *summary;
    unsigned sampling;        /* bit (1 << enum dr_sampling) per supported mode */
    size_t job_size;          /* the algorithm's job, struct dr_est_base first */
    /* The algorithm: fills the base's accumulators (see common.h). 0 or DR_ERR_*. */
    int (*run)(struct dr_est_base *job);
    /* Frees what run allocated beyond the base (may be NULL). */
    void (*release)(struct dr_est_base *job);
    /* At most the bytes one worker holds besides the gradient buffers at spp
     * samples per pixel (its packet tracer's paths, prb's parked samples):
     * the CLI's memory estimate counts one per thread (NULL: none). */
    uint64_t (*thread_bytes)(int spp);
};

extern const struct dr_estimator_ops *const dr_estimators[];   /* NULL-terminated */
const struct dr_estimator_ops *dr_estimator_find(const char *name);

/* Bytes the tape estimator records per path vertex (its record plus the path's
 * share is bounded by this; under derivative sampling with the new
 * directions it walks ahead of the sweep); the CLI's memory estimate uses it
 * so that the estimate follows the record when the record changes. */
size_t dr_tape_vertex_bytes(bool derivative);
/* The tape's default batch: paths each worker records before it sweeps them.
 * About 2 MB of tape per worker on a Cornell box, so the sweep reads it
 * back from the cache (see tape.c). */
#define DR_TAPE_PATHS_PER_WORKER 512
/* Paths the tape holds at once over all workers, for --batch `batch` (0: the
 * default): each worker's share in whole pixels of spp paths, at least one. */
double dr_tape_batch_paths(int64_t batch, int threads, int spp);
bool dr_estimator_supports(const struct dr_estimator_ops *e, enum dr_sampling s);

/* Reverse mode sums a thread's adjoints into a gradient vector of its own
 * (the first thread into the caller's), except from 4 threads on for
 * vectors of at least DR_SHARED_SUMS_MIN entries (texture parameters): one
 * vector all threads add to exactly (core/exact_sum.h), 17 bytes an entry
 * against 8 for each thread but the first, whose result is the same for any
 * thread count from 4 on. */
#define DR_SHARED_SUMS_MIN 65536
bool dr_estimator_shared_sums(int threads, int64_t total);

/* Does a reverse-mode run of p hand its gradient to p->consumer: one is
 * set, with a scratch, and the run sums per-thread vectors or the shared
 * exact sum (not mis sampling). */
bool dr_estimator_consumes(const struct dr_grad_problem *p);

/* Forward mode: d_image (width * height * 3 doubles) = d I / d theta . dir,
 * dir having params->total entries. */
int dr_estimator_forward(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const double *dir,
                         double *d_image, struct dr_grad_stats *st);
/* Reverse mode: grad (params->total entries, overwritten) = sum over pixels
 * and channels of adjoint * d I / d theta, adjoint being d loss / d I
 * (width * height * 3 floats; NULL with p->cross, which says how to take it
 * from the paths). */
/* Forward mode for n_groups (1 .. DR_FORWARD_MAX, grad_sink.h) groups of
 * slots at once, group g ending at slot group_end[g] (ascending; the last
 * group takes the slots past its end): d_images[g] = d I / d theta . dir
 * over group g's slots, each the image dr_estimator_forward gives with dir
 * zero outside group g, from one pass over the paths. Not with mis
 * sampling (its weight is the direction's: one group). */
int dr_estimator_forward_groups(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const double *dir,
                                int n_groups, const int64_t *group_end, double *const *d_images,
                                struct dr_grad_stats *st);
/* How many parameters one forward pass keeps apart under `sampling`:
 * DR_FORWARD_MAX, or 1 under mis (its weight is the pass's direction's). */
int dr_forward_per_pass(enum dr_sampling sampling);
/* The direction and groups of a pass over parameters first .. first +
 * count - 1 of ps (count <= DR_FORWARD_MAX), each along all its components:
 * dir 1 on their slots and 0 elsewhere (ps->total entries), group_end[k]
 * the end of parameter first + k's slots. */
void dr_forward_param_groups(const struct dr_param_set *ps, int first, int count, double *dir, int64_t *group_end);
int dr_estimator_backward(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const float *adjoint,
                          double *grad, struct dr_grad_stats *st);

#endif
