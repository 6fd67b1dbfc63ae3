/* --sampling mis: detached and attached sampling combined.
 *
 * Both estimators see the SAME path (same random numbers): D (detached: the
 * sample is a constant of the derivative) and A (attached: it moves with the
 * parameters through the sampling map, path.h). Where the sampling maps are
 * continuous both are unbiased for the same interior derivative, so their
 * difference Delta = A - D has mean 0: A is D plus a zero-mean control
 * variate, and every combination
 *     G(w) = w D + (1 - w) A = D + a Delta,      a = 1 - w,
 * with a weight that does not depend on the samples it multiplies is unbiased.
 * Its variance, Var D + 2 a Cov(D, Delta) + a^2 Var Delta, is smallest at
 *     a* = -Cov(D, Delta) / Var Delta
 *        = (Var_D - Cov(D, A)) / (Var_D + Var_A - 2 Cov(D, A)),
 *     w* = 1 - a* = (Var_A - Cov(D, A)) / (Var_D + Var_A - 2 Cov(D, A)),
 * where it equals Var D - Cov(D, Delta)^2 / Var Delta: never more than
 * Var D (a = 0) nor Var A (a = 1). Clamped to [0, 1] (a convex
 * combination, as a MIS weight), the optimum over [0, 1] still beats both
 * ends; the clamp keeps a noisy estimate of a* from extrapolating.
 *
 * Var and Cov are estimated from the run itself, per parameter (w is one
 * number for all components of a parameter: the sums below run over its
 * components, which minimises the summed variance). Since E[Delta] = 0,
 * Cov(D, Delta) = E[D . Delta] and Var Delta = E[|Delta|^2]: no means are
 * needed, so the estimates come straight from single samples (each path's
 * d_s and Delta_s, independent across (pixel, sample), sampler.h):
 *     P = sum_s d_s . Delta_s,   Q = sum_s |Delta_s|^2,   a* ~ -P / Q.
 * Cross-fitting keeps the result unbiased: the samples are split into
 * DR_MIS_GROUPS groups (sample s of pixel x: group (x + s) mod G), each with
 * its own sums D_g, A_g, P_g, Q_g, and group g's weight comes from the OTHER
 * groups only (leave-one-out),
 *     a_g = clamp(-sum_{h != g} P_h / sum_{h != g} Q_h, 0, 1),
 * so a_g is independent of D_g and Delta_g, and E[D_g + a_g Delta_g] = E[D_g].
 * The estimate is sum_g (D_g + a_g Delta_g). Where Delta vanishes (no
 * parameter of the segment moves a sampling map: attached == detached up to
 * rounding) the weight is 1 on detached.
 *
 * Per-sample sums need each sample's vector apart: cheap in forward mode (a
 * pixel's three channels) and for small gradient vectors (up to
 * DR_MIS_SAMPLE_STATS_MAX entries; a per-sample scratch vector). Larger ones
 * (textures) use the group sums themselves, P_h = D_h . Delta_h,
 * Q_h = |Delta_h|^2 (still unbiased; a noisier weight from 7 numbers).
 *
 * Memory: per thread, 2 G copies of the estimate (the gradient vector in
 * reverse mode, the derivative image in forward mode). */
#ifndef DR_ESTIMATORS_MIS_H
#define DR_ESTIMATORS_MIS_H

#include <stdbool.h>
#include <stdint.h>

#include "parallel.h"

#define DR_MIS_GROUPS 8
/* Reverse mode: gradient vectors up to this size get per-sample statistics. */
#define DR_MIS_SAMPLE_STATS_MAX 256

enum dr_mis_estimate { DR_MIS_DETACHED, DR_MIS_ATTACHED };

struct dr_mis_accum {
    int threads;
    int64_t n;                        /* entries of one estimate */
    int64_t stride;                   /* n + 1: a spare entry, as the gradient buffers have (common.c) */
    int segments;                     /* parameters (reverse mode) or 1 (forward mode) */
    int64_t *seg_off, *seg_size;
    bool per_sample;                  /* P, Q, R from single samples (else from the group sums) */
    double *buf[DR_MAX_THREADS];      /* per thread: [group][estimate][stride] */
    double *stats[DR_MAX_THREADS];    /* per thread: [group][segment][P, Q, R] */
    double *scratch[DR_MAX_THREADS];  /* reverse mode, per_sample: the current sample's [estimate][stride] */
    uint64_t bytes;
};

/* Segments [off[k], off[k] + size[k]) of n entries get one weight each;
 * scratch: reverse mode (samples land in a scratch vector first). 0, or
 * DR_ERR_NOMEM (message set). */
int dr_mis_init(struct dr_mis_accum *m, int threads, int64_t n, int segments, const int64_t *off,
                const int64_t *size, bool per_sample, bool scratch);
void dr_mis_free(struct dr_mis_accum *m);

/* The group of sample `sample` of pixel `pixel`. */
static inline int dr_mis_group(int64_t pixel, int sample)
{
    return (int)(((uint64_t)pixel + (uint64_t)sample) % DR_MIS_GROUPS);
}

/* Where thread `thread` accumulates group g's estimate e. */
static inline double *dr_mis_slot(const struct dr_mis_accum *m, int thread, int g, enum dr_mis_estimate e)
{
    return m->buf[thread] + ((int64_t)g * 2 + (int)e) * m->stride;
}

/* One sample's part of segment seg, entries [at, at + len): d and a (its
 * detached and attached values) added to group g's sums, and (per_sample)
 * their products to the group's statistics. */
void dr_mis_add(struct dr_mis_accum *m, int thread, int g, int seg, int64_t at, int64_t len, const double *d,
                const double *a);
/* Reverse mode, per_sample: the sample in thread's scratch vectors, every
 * segment, added to group g (dr_mis_add), and the scratch cleared. */
void dr_mis_add_scratch(struct dr_mis_accum *m, int thread, int g);

/* The combined estimate into out (n entries): the threads summed, then each
 * segment weighted as above; w_detached (may be NULL) gets each segment's
 * weight of the detached estimate, the mean of 1 - a_g over the groups that
 * have samples in it. */
void dr_mis_combine(struct dr_mis_accum *m, double *out, double *w_detached);

#endif
