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
 * components, which minimises the summed variance), from single samples:
 * the samples are independent across (pixel, sample) (sampler.h), so
 *     Cov(D, Delta) = sum_px n_px Cov_px(d, Delta),
 * each pixel's covariance estimated from its own n_px samples, centred on
 * their mean:
 *     P = sum_px [ sum_s d_s . Delta_s - (sum_s d_s) . (sum_s Delta_s) / n_px ],
 *     Q = sum_px [ sum_s |Delta_s|^2  - |sum_s Delta_s|^2 / n_px ],
 *     a* ~ -P / Q
 * (the common factor n / (n - 1) cancels in the ratio). The centring
 * matters: attached sampling drops the boundary term where a moving sample
 * crosses an edge of the integrand (a light's outline seen in a glossy
 * reflection), so per pixel E[Delta] is not 0, and the uncentred products
 * would mistake that bias for covariance (measured on the Cornell box:
 * weight 0.4 on detached where the variance-optimal one is 0.9 to 1).
 * Cross-fitting keeps the result unbiased: pixels are split into
 * DR_MIS_GROUPS groups (by a hash of the pixel; all samples of a pixel in
 * one group), each with its own sums D_g, A_g, P_g, Q_g, and group g's
 * weight comes from the OTHER groups only (leave-one-out),
 *     a_g = median_{h != g} clamp(-P_h / Q_h, 0, 1)     (why the median: below),
 * so a_g is independent of D_g and Delta_g: E[D_g + a_g Delta_g] is
 * E[D_g] + a_g E[Delta_g], exactly what a fixed weight gives (unbiased
 * where attached is). The estimate is sum_g (D_g + a_g Delta_g). Where
 * Delta vanishes (no parameter of the segment moves a sampling map:
 * attached == detached up to rounding) the weight is 1 on detached.
 *
 * Per-sample sums need each sample's vector apart and each pixel's sums:
 * free in forward mode (a sample is a pixel's three channels, the group's
 * image holds the pixel's sums), and in reverse mode kept for small
 * gradient vectors (DR_MIS_SAMPLE_STATS_MAX entries; a per-sample scratch
 * vector and per-pixel sums, at most DR_MIS_PIXEL_SUMS_MAX doubles per
 * thread). Otherwise, and when every pixel has a single sample (nothing to
 * centre on), the statistics come from the groups' sums, centred on the
 * other groups' mean: P_{-g} = sum_{h != g} (D_h - mean) . (Delta_h - mean)
 * (still unbiased; a noisier weight, from 7 numbers whose pixel sets differ).
 *
 * Why the weights need care: the attached roughness derivative is
 * heavy-tailed. On the Cornell box at roughness 0.5 (32x32), one pixel,
 * (20, 20), holds 82% of sum |Delta|^2 over 200 runs, in a few rare
 * samples: the sphere's highlight, where it reflects the small ceiling
 * light. There attached's per-sample values have a tail index of 1.8
 * (infinite variance; detached's: 14), and only on paths of 4 segments and
 * more (max depth 3: no tail, 4: index 4.6, 5 and 6: 1.8; Russian roulette
 * changes nothing): the motion of the later hit points, carried along the
 * diffuse bounces that follow the moving lobe. A run that has not seen them takes Var Delta for small and
 * leans to attached where detached is better. Three choices keep that in
 * check (measured with grad's default 4 batches of 4 spp at 32x32, 200
 * seeds):
 * - group g's weight is the MEDIAN of the other groups' own weights
 *   -P_h / Q_h (each clamped to [0, 1]), not the pooled ratio of their
 *   sums: a tail event in one group pulls the pooled ratio of all others
 *   its way, the median moves one vote (one 16-spp run per seed: pooled
 *   1.15x the better variance at roughness 0.5 and 1.39x at 0.1, median
 *   1.035x and 0.985x);
 * - earlier runs of the same problem (grad's and optimize's batches, via
 *   drivers/reverse.c) join the statistics through a struct dr_mis_history:
 *   they are independent of this run's samples, so group h's statistics
 *   can be this run's plus the history's without bias; this run's are
 *   added to the history after its combination;
 * - the reverse driver does not split a mis batch into halves: weights
 *   from 2-spp halves were the worst case (mis 2.0x detached's variance at
 *   roughness 0.5 before; 1.08x now, within the +-10% of a 200-seed
 *   variance, and 0.97x attached's at roughness 0.1).
 *
 * Memory: per thread, 2 G copies of the estimate (the gradient vector in
 * reverse mode, the derivative image in forward mode), plus the per-pixel
 * sums above. */
#ifndef DR_ESTIMATORS_MIS_H
#define DR_ESTIMATORS_MIS_H

#include <stdbool.h>
#include <stdint.h>

#include "parallel.h"
#include "sampler.h"

#define DR_MIS_GROUPS 8
/* Reverse mode: per-sample statistics for gradient vectors up to this size,
 * and per-pixel sums up to this many doubles per thread. */
#define DR_MIS_SAMPLE_STATS_MAX 256
#define DR_MIS_PIXEL_SUMS_MAX ((int64_t)8 << 20)

enum dr_mis_estimate { DR_MIS_DETACHED, DR_MIS_ATTACHED };

struct dr_mis_accum {
    int threads;
    int64_t n;                        /* entries of one estimate */
    int64_t stride;                   /* n + 1: a spare entry, as the gradient buffers have (common.c) */
    int64_t pixels;
    int segments;                     /* parameters (reverse mode) or 1 (forward mode) */
    int64_t *seg_off, *seg_size;
    bool forward;                     /* entries are the derivative image (pixel p at 3p) */
    bool per_sample;                  /* per-sample statistics, centred per pixel (else the groups') */
    double *buf[DR_MAX_THREADS];      /* per thread: [group][estimate][stride] */
    double *stats[DR_MAX_THREADS];    /* per_sample: [group][segment][P, Q, R], uncentred */
    double *count[DR_MAX_THREADS];    /* per_sample: samples per pixel */
    double *pix[DR_MAX_THREADS];      /* reverse, per_sample: [pixel][estimate][n], the pixel's sums */
    double *scratch[DR_MAX_THREADS];  /* reverse, per_sample: the current sample's [estimate][stride] */
    uint64_t bytes;
};

/* Segments [off[k], off[k] + size[k]) of n entries get one weight each.
 * forward: n = 3 pixels, one segment. Reverse mode keeps per-sample
 * statistics when n and pixels allow (above). 0, or DR_ERR_NOMEM (message set). */
int dr_mis_init(struct dr_mis_accum *m, int threads, int64_t n, int segments, const int64_t *off,
                const int64_t *size, int64_t pixels, bool forward);
void dr_mis_free(struct dr_mis_accum *m);

/* The group of a pixel (every sample of it). */
static inline int dr_mis_group(int64_t pixel)
{
    return (int)(dr_hash64((uint64_t)pixel ^ 0x4d49534d49534d49ULL) % DR_MIS_GROUPS);
}

/* Where thread `thread` accumulates group g's estimate e. */
static inline double *dr_mis_slot(const struct dr_mis_accum *m, int thread, int g, enum dr_mis_estimate e)
{
    return m->buf[thread] + ((int64_t)g * 2 + (int)e) * m->stride;
}

/* One sample of pixel px: d and a (its detached and attached values for
 * entries [at, at + len)) added to its group's sums and, with per_sample,
 * to the statistics and the pixel's sums. */
void dr_mis_add(struct dr_mis_accum *m, int thread, int64_t px, int64_t at, int64_t len, const double *d,
                const double *a);
/* Reverse mode, per_sample: the sample in thread's scratch vectors added
 * (dr_mis_add over the whole vector), and the scratch cleared. */
void dr_mis_add_scratch(struct dr_mis_accum *m, int thread, int64_t px);

/* Statistics of earlier runs of one problem (same parameters): per segment
 * and group, the sums of P, Q, R (per-sample, centred per pixel); a run
 * adds its own after its combination. */
struct dr_mis_history {
    int segments;
    double *stats;   /* [segment][group][P, Q, R] */
};
/* 0, or DR_ERR_NOMEM (message set). */
int dr_mis_history_init(struct dr_mis_history *h, int segments);
void dr_mis_history_free(struct dr_mis_history *h);

/* The combined estimate into out (n entries): the threads summed, then each
 * segment weighted as above; w_detached (may be NULL) gets each segment's
 * weight of the detached estimate, the mean of 1 - a_g over the groups that
 * have samples in it. history (may be NULL; used when its segments match
 * and the run kept per-sample statistics) joins the weights and takes this
 * run's statistics. */
void dr_mis_combine(struct dr_mis_accum *m, double *out, double *w_detached, struct dr_mis_history *history);

#endif
