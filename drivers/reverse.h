/* Reverse mode with an honest standard error: d loss / d parameters for an
 * image loss against a target, as the mean of K batches that are independent
 * in every random input.
 *
 * Batch b renders its own primal image I_b (spp_b = ceil(spp / K) samples,
 * seed hash(hash(seed ^ "PRIMAL") + b)), takes the loss's adjoint
 * a_b = d loss / d I at I_b, and runs the gradient estimator with that
 * adjoint on samples of its own (seeds hash(hash(seed ^ "GRAD") + 2b + h)),
 * so the primal and the gradient samples of a batch are independent (no
 * correlation bias) and the K batch gradients g_b are i.i.d.:
 *
 *   gradient           = mean_b g_b
 *   stderr (total)     = sqrt(sum_b (g_b - mean)^2 / (K - 1) / K)
 *
 * The parts come from the law of total variance. Each batch's gradient
 * samples are run as two halves h = 0, 1 of n0 = ceil(spp_b / 2) and
 * n1 = floor(spp_b / 2) samples with the same adjoint, g_b = (n0 g_b0 +
 * n1 g_b1) / spp_b. Their difference carries gradient-sample noise only
 * (E[g_b0 - g_b1 | I_b] = 0), and E[(g_b0 - g_b1)^2] n0 n1 / spp_b^2 is the
 * gradient-sample variance of g_b given its primal. So
 *
 *   stderr_gradient    = sqrt(mean_b (g_b0 - g_b1)^2 n0 n1 / spp_b^2 / K)
 *   stderr_primal      = sqrt(max(0, stderr^2 - stderr_gradient^2))
 *
 * (NaN when spp_b = 1: there are no halves). The cost against one full-spp
 * primal: the same samples, K renders of spp_b instead of one of spp, and
 * two estimator runs per batch instead of one.
 *
 * DR_PRIMAL_CROSS (the default of grad and optimize) renders no primal
 * image: batch b's estimator run weights each sample's derivative with the
 * loss's adjoint at the mean of its pixel's other samples (estimator.h,
 * struct dr_cross_loss). That mean is independent of the sample, which keeps
 * the estimate unbiased, and the K batches stay i.i.d., so the standard error
 * is their spread as above; the parts are not estimated (a sample's primal
 * and derivative noise are no longer apart). It needs spp_b >= 2 and the
 * independent or sobol sampler (sobol: the mean of the other half of the
 * pixel's samples, estimator.h); otherwise the run is DR_PRIMAL_PER_BATCH.
 * The cost against DR_PRIMAL_PER_BATCH: one estimator run per batch and no
 * render, i.e. the estimator's own primal walks serve as the loss's primal.
 *
 * DR_PRIMAL_SHARED is the estimator drender used before: one primal at the
 * full spp shared by every batch, whose spread then misses the primal's noise.
 * It is kept to show (tests/test_reverse_stderr.c) that it undercovers. */
#ifndef DR_REVERSE_H
#define DR_REVERSE_H

#include "estimator.h"
#include "loss.h"
#include "render.h"

enum dr_primal_mode {
    DR_PRIMAL_PER_BATCH,   /* each batch its own primal image (the honest estimator) */
    DR_PRIMAL_CROSS,       /* each batch's paths are their own primal, leave one out (as honest, no render) */
    DR_PRIMAL_SHARED,      /* one primal for all batches (understates the error; tests only) */
};

/* What a run's batches sum into, kept from run to run by a caller that
 * runs many (optimize: one run an iteration) so that no run faults in
 * fresh pages for them (estimator.h's dr_est_scratch says why): a batch's
 * gradient halves and the estimator runs' own vectors. Zero-initialised,
 * caller-owned; dr_reverse_scratch_free releases it (and zeroes it). The
 * results are the same to the bit with or without it. */
struct dr_reverse_scratch {
    double *half[2];
    int64_t half_len[2];
    struct dr_est_scratch est;
};
void dr_reverse_scratch_free(struct dr_reverse_scratch *s);

struct dr_reverse_options {
    const struct dr_estimator_ops *estimator;
    struct dr_grad_problem problem;   /* .spp: samples per pixel in all (split over the batches) */
    enum dr_loss_kind loss;
    double loss_scale;                /* d_out of the loss (1; optimize: 1 / targets) */
    int batches;                      /* K >= 2 */
    enum dr_primal_mode primal;
    /* optional callbacks: progress (done of total steps) and every run's statistics */
    void (*progress)(void *ctx, int done, int total);
    void (*on_render)(void *ctx, const struct dr_render_stats *st);
    void (*on_gradient)(void *ctx, const struct dr_grad_stats *st);
    void *ctx;
    struct dr_reverse_scratch *scratch;   /* optional (above); NULL: the run's own, freed at its end */
};

struct dr_reverse_result {
    /* caller-allocated, params->total entries each; se_gradient and
     * se_primal may both be NULL (then only `parts` says whether they could
     * have been estimated: dr_reverse_parts tells before the run, so a caller
     * can allocate them only then) */
    double *grad, *se, *se_gradient, *se_primal;
    /* optional (may be NULL): the mean of the primal images, width * height * 3 */
    float *image;
    /* optional (may be NULL; in and out): a block mask of grad and se
     * (zero_blocks.h, dr_mask_words(params->total) words). On entry it
     * must be true of them: grad and se are +0 in every block it leaves
     * clear (fresh vectors: a clear mask and zeros; or what the last run
     * left). The run then reads and writes only the blocks marked on entry
     * and those its gradient reaches (with a texture seen at a preview
     * size, a few per cent), and on return the mask is true again, marking
     * those the run left non-zero. Where the run cannot keep it (halves'
     * vectors, se_gradient or se_primal asked for) every block is marked
     * and every entry written. */
    uint64_t *nonzero;
    /* optional (may be NULL: every entry's): a block mask (zero_blocks.h)
     * of the entries whose standard error is wanted. se is neither read nor
     * written outside it (nonzero's contract then holds of se inside it
     * only), and the fold keeps no sum of squares there: optimize shows
     * the standard errors of its scalar parameters, never a texture's, whose
     * vector would cost as much memory as its gradient. Ignored (every
     * entry's) where se_gradient or se_primal is asked for. */
    const uint64_t *se_blocks;
    double loss;                     /* loss of the mean primal image (scaled by loss_scale) */
    int spp_batch;                   /* samples per pixel of each batch */
    bool parts;                      /* se_gradient / se_primal were estimated */
    uint64_t primal_seed;            /* hash(seed ^ "PRIMAL"); batch b uses hash(primal_seed + b) */
    double t_primal, t_gradient;     /* seconds in renders and in estimator runs */
    enum dr_primal_mode primal_run;  /* what ran: DR_PRIMAL_CROSS with spp_batch < 2 or the
                                        stratified sampler runs per batch */
};

/* Samples per pixel of each of `batches` batches of spp in all. */
int dr_reverse_spp_batch(int spp, int batches);
/* The primal mode a run asked for `primal` runs: DR_PRIMAL_CROSS falls back
 * to DR_PRIMAL_PER_BATCH with one sample a batch or the stratified sampler. */
enum dr_primal_mode dr_reverse_primal_run(enum dr_primal_mode primal, int spp, int batches,
                                          enum dr_sampler_kind sampler);

/* Whether a run with these options estimates se_gradient and se_primal
 * (dr_reverse_result.parts). */
bool dr_reverse_parts(const struct dr_reverse_options *o);

/* target: width * height * 3 linear floats. 0 or a negative DR_ERR_*
 * (then r's vectors and mask hold nothing meaningful: the first batch
 * writes them whole, so nothing clears them before). */
int dr_reverse_gradient(const struct dr_reverse_options *o, const float *target, struct dr_reverse_result *r);

#endif
