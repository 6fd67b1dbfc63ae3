#include "reverse.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "error.h"
#include "mis.h"
#include "parallel.h"
#include "sampler.h"
#include "zero_blocks.h"

#define PRIMAL_SEED_SALT 0x5052494d414cULL   /* "PRIMAL" */
#define GRAD_SEED_SALT 0x47524144ULL         /* "GRAD" */

/* Scratch of one run: images, adjoint and per-entry sums. */
struct rev_work {
    const struct dr_reverse_options *o;
    const float *target;
    size_t n;                  /* pixels * 3 */
    int64_t T;
    float *img, *adj;
    double *img_sum;           /* sum of the batches' primal images */
    double *cross_img;         /* cross mode: a batch's primal image, from its estimator run */
    /* a batch's gradient (its two halves); Welford's sum of squares and the
     * halves' (the caller's se and se_gradient, finished in place) */
    double *half[2], *m2, *dsq;
    bool consume;              /* a batch's last estimator run hands its gradient to the fold (welford_take) */
    uint64_t *nonzero;         /* r->nonzero where the fold keeps it (work_alloc), else NULL */
    const uint64_t *se_blocks; /* r->se_blocks where it applies (work_alloc), else NULL: every block's */
    int done, steps;
    struct dr_mis_history mis;   /* mis without the caller's history: this run's batches' */
    struct dr_media_plan media_plan;   /* the batches' media pilot (medium_grad.h), unless the caller's */
    struct dr_reverse_scratch own;     /* the batches' vectors, unless the caller keeps them (o->scratch) */
    struct dr_reverse_scratch *scratch;   /* o->scratch or &own */
};

static void work_free(struct rev_work *w)
{
    free(w->img);
    free(w->adj);
    free(w->img_sum);
    free(w->cross_img);
    dr_reverse_scratch_free(&w->own);
    dr_mis_history_free(&w->mis);
    dr_media_plan_free(&w->media_plan);
}

void dr_reverse_scratch_free(struct dr_reverse_scratch *s)
{
    if (!s)
        return;
    free(s->half[0]);
    free(s->half[1]);
    dr_est_scratch_free(&s->est);
    memset(s, 0, sizeof *s);
}

/* The scratch's half h, T1 entries (not cleared: a batch overwrites it). */
static double *scratch_half(struct dr_reverse_scratch *s, int h, size_t T1)
{
    bool kept;
    return dr_big_vector_keep(&s->half[h], &s->half_len[h], (int64_t)T1, false, &kept);
}

/* Scratch for a run: the sums live in the caller's se and se_gradient
 * (the last batch turns them into standard errors in place). Where the
 * estimator hands a run's gradient over in pieces (estimator.h's
 * dr_grad_consumer: not with mis sampling nor the shared exact sum), a
 * batch's last run is folded in as it is summed, so a batch vector is kept
 * only for the first of two halves; else one for each half. So a texture
 * parameter costs its result vectors and at most two batch vectors, not
 * eight. */
static int work_alloc(struct rev_work *w, const struct dr_reverse_result *r)
{
    size_t T1 = (size_t)(w->T > 0 ? w->T : 1);
    const bool split = r->parts && r->spp_batch / 2 > 0;
    w->img = malloc(sizeof(float) * w->n);
    w->adj = malloc(sizeof(float) * w->n);
    w->img_sum = calloc(w->n, sizeof(double));
    w->cross_img = calloc(w->n, sizeof(double));
    w->scratch = w->o->scratch ? w->o->scratch : &w->own;
    struct dr_grad_problem q = w->o->problem;   /* (as run_estimator will run it) */
    const struct dr_grad_consumer probe = {0};
    q.consumer = &probe;
    if (!q.scratch)
        q.scratch = &w->scratch->est;
    w->consume = dr_estimator_consumes(&q);
    const bool need0 = split || !w->consume, need1 = split && !w->consume;   /* (batch(): what goes to a vector) */
    w->half[0] = need0 ? scratch_half(w->scratch, 0, T1) : NULL;
    w->half[1] = need1 ? scratch_half(w->scratch, 1, T1) : NULL;
    w->m2 = r->se;   /* (batch 0 writes it whole: welford_range) */
    /* the result's mask, where the fold can keep it: not with the halves'
     * vectors (dense) nor the parts (written whole); else all marked */
    const bool keep_mask = r->nonzero && !split && !r->se_gradient && !r->se_primal;
    w->nonzero = keep_mask ? r->nonzero : NULL;
    if (r->nonzero && !keep_mask)
        memset(r->nonzero, 0xff, sizeof(uint64_t) * (size_t)dr_mask_words(w->T));
    /* the halves' squared differences feed se_gradient and se_primal only */
    w->dsq = r->parts && r->se_gradient ? r->se_gradient : NULL;
    w->se_blocks = r->se_gradient || r->se_primal ? NULL : r->se_blocks;
    if (w->img && w->adj && w->img_sum && w->cross_img && (w->half[0] || !need0) && (w->half[1] || !need1))
        return 0;
    dr_set_error("out of memory (%lld gradient entries, %zu image values)", (long long)w->T, w->n);
    return DR_ERR_NOMEM;
}

static void step_done(struct rev_work *w)
{
    if (w->o->progress)
        w->o->progress(w->o->ctx, ++w->done, w->steps);
}

/* A primal image with this seed and the loss's adjoint at it. */
static int primal(struct rev_work *w, uint64_t seed, int spp, struct dr_reverse_result *r)
{
    const struct dr_grad_problem *p = &w->o->problem;
    struct dr_render_opts ro = {.width = p->width, .height = p->height, .spp = spp, .max_depth = p->max_depth,
                                .rr_depth = p->rr_depth, .seed = seed, .threads = p->threads, .film = p->film};
    struct dr_render_stats rs = {0};
    int rc = dr_render(p->scene, p->camera, &ro, w->img, &rs);
    if (rc != 0)
        return rc;
    r->t_primal += rs.seconds;
    if (w->o->on_render)
        w->o->on_render(w->o->ctx, &rs);
    for (size_t i = 0; i < w->n; i++)
        w->img_sum[i] += w->img[i];
    d_loss_eval(w->o->loss, w->img, w->target, w->n, w->o->loss_scale, w->adj);
    step_done(w);
    return 0;
}

/* The estimator: spp samples, this seed, into g or (g NULL) to fold; with
 * the current adjoint image, or with cross non-NULL from the paths
 * themselves. */
static int run_estimator(struct rev_work *w, uint64_t seed, int spp, const struct dr_cross_loss *cross, double *g,
                         const struct dr_grad_consumer *fold, struct dr_reverse_result *r)
{
    struct dr_grad_problem p = w->o->problem;
    p.spp = spp;
    p.seed = seed;
    p.cross = cross;
    p.consumer = g ? NULL : fold;
    if (!p.mis_history && w->mis.stats)
        p.mis_history = &w->mis;
    if (!p.media_plan)
        p.media_plan = &w->media_plan;
    if (!p.scratch)
        p.scratch = &w->scratch->est;
    struct dr_grad_stats st = {0};
    int rc = dr_estimator_backward(w->o->estimator, &p, cross ? NULL : w->adj, g, &st);
    if (rc != 0)
        return rc;
    r->t_gradient += st.seconds;
    if (w->o->on_gradient)
        w->o->on_gradient(w->o->ctx, &st);
    return 0;
}

static int gradient(struct rev_work *w, uint64_t seed, int spp, double *g, const struct dr_grad_consumer *fold,
                    struct dr_reverse_result *r)
{
    return run_estimator(w, seed, spp, NULL, g, fold, r);
}

/* Cross mode: batch b's gradient into g (or to fold), from one estimator
 * run whose paths are their own primal; its image goes into the sum. */
static int cross_gradient(struct rev_work *w, uint64_t seed, double *g, const struct dr_grad_consumer *fold,
                          struct dr_reverse_result *r)
{
    const struct dr_cross_loss cross = {.loss = w->o->loss, .target = w->target, .scale = w->o->loss_scale,
                                        .image = w->cross_img};
    int rc = run_estimator(w, seed, r->spp_batch, &cross, g, fold, r);
    for (size_t i = 0; rc == 0 && i < w->n; i++)
        w->img_sum[i] += w->cross_img[i];
    return rc;
}

/* A batch's fold into the running sums, entry by entry (each on its own,
 * so from any thread: dr_parallel_elements, dr_grad_consumer). */
struct welford_step {
    struct rev_work *w;
    struct dr_reverse_result *r;
    int b, K, n0, n1, spp;
    bool split;
};

/* Entries [i0, i0 + n)'s update (n <= DR_ZERO_BLOCK) with batch b's
 * gradient there, g[i - i0] (split halves: g the second's, h0[i] the
 * first's): the running mean (Welford) in r->grad and its sum of squares in
 * m2, with two halves their squared difference into dsq (the last batch's
 * standard_errors turn them into standard errors in place: se holds m2,
 * se_gradient dsq). Batch 0 starts every entry from +0 itself (the same
 * operations on the zeros the sums would hold) and writes it, so nothing is
 * cleared before it, nor read (without a result mask, fold has batch 0
 * write every block: a caller's vectors may then hold anything). */
static inline __attribute__((always_inline)) void fold_block(const struct welford_step *x, int64_t i0, int64_t n,
                                                             const double *g, const double *h0, bool first,
                                                             bool split, bool pow2, bool se)
{
    struct rev_work *w = x->w;
    double *grad = x->r->grad, *m2 = w->m2, *dsq = w->dsq;   /* (dsq: only with split halves, plan()) */
    const int b = x->b, n0 = x->n0, n1 = x->n1, spp = x->spp;
    const double inv = 1.0 / (b + 1);   /* (pow2: exact, so d * inv is d / (b + 1) to the bit) */
    for (int64_t i = i0; i < i0 + n; i++) {
        const double hb = g[i - i0];
        const double gi = split ? (n0 * h0[i] + n1 * hb) / spp : hb;
        const double mean = first ? 0.0 : grad[i];
        const double d = gi - mean;
        grad[i] = mean + (pow2 ? d * inv : d / (b + 1));
        if (se)   /* (se: the block's standard error is wanted, w->se_blocks) */
            m2[i] = (first ? 0.0 : m2[i]) + d * (gi - grad[i]);
        if (split && dsq) {
            const double h = h0[i] - hb;
            dsq[i] = (first ? 0.0 : dsq[i]) + h * h * n0 * n1 / ((double)spp * spp);
        }
    }
}

/* fold_block with its block's length and standard-error choice made
 * constants where it can (each variant compiled apart, branch-free) */
static inline __attribute__((always_inline)) void fold_block_sized(const struct welford_step *x, int64_t i0,
                                                                   int64_t n, const double *g, const double *h0,
                                                                   bool first, bool split, bool pow2, bool se)
{
    if (n == DR_ZERO_BLOCK && se)
        fold_block(x, i0, DR_ZERO_BLOCK, g, h0, first, split, pow2, true);
    else if (n == DR_ZERO_BLOCK)
        fold_block(x, i0, DR_ZERO_BLOCK, g, h0, first, split, pow2, false);
    else
        fold_block(x, i0, n, g, h0, first, split, pow2, se);
}

static const double zero_block[DR_ZERO_BLOCK];

/* The fold of entries [begin, end) (begin a multiple of 512: a mask word
 * is this range's), g[i - begin] the gradient there; with mask (the
 * consumer's: estimator.h), only its marked blocks of g are read, the
 * others are +0. Blocks whose result is what they hold are left alone:
 *  - with the run's mask of the result (w->nonzero: r->nonzero's contract,
 *    reverse.h), a block neither marked in it nor in mask, without reading
 *    it; the mask is kept true as blocks are written (batch 0: marked where
 *    g is, as batch 0 clears the others; later: where either is);
 *  - else after batch 0, a block at +0 with a +0 gradient (mean + (+0 -
 *    +0) * inv = +0, m2 + +0 * +0 = +0, dsq likewise), read to see so.
 * FIRST, SPLIT and POW2 are constants where fold_run calls it, so that each
 * variant's loop compiles branch-free to vector operations (with the tests
 * inside the loop it ran one entry at a time: twice as slow). */
static inline __attribute__((always_inline)) void fold(const struct welford_step *x, int64_t begin, int64_t end,
                                                       const double *g, const uint64_t *mask, const double *h0,
                                                       bool first, bool split, bool pow2)
{
    struct rev_work *w = x->w;
    const double *grad = x->r->grad, *m2 = w->m2, *dsq = w->dsq;
    uint64_t *nonzero = w->nonzero;
    for (int64_t iw = begin; iw < end; iw += DR_MASK_SPAN) {
        /* the blocks to look at: with the result's mask, those of either
         * mask (a word of neither skipped whole), else all */
        uint64_t *held = nonzero ? &nonzero[iw / DR_MASK_SPAN] : NULL;
        const uint64_t in_word = mask ? mask[(iw - begin) / DR_MASK_SPAN] : ~UINT64_C(0);
        for (uint64_t visit = held ? in_word | *held : ~UINT64_C(0); visit; visit &= visit - 1) {
            const int bit = __builtin_ctzll(visit);
            const int64_t i0 = iw + bit * DR_ZERO_BLOCK;
            if (i0 >= end)
                break;
            const int64_t n = end - i0 < DR_ZERO_BLOCK ? end - i0 : DR_ZERO_BLOCK;
            const bool in = in_word >> bit & 1;
            const bool se = !w->se_blocks || dr_mask_test(w->se_blocks, i0);
            const double *gb = in ? g + (i0 - begin) : zero_block;
            /* a block the result's mask leaves clear is +0 in every sum: a
             * later batch reaching it for the first time starts it from +0
             * as batch 0 does, without reading it (the same bits). Its pages
             * are often fresh: a read maps the kernel's zero page, and the
             * write after it copies that page and interrupts the other CPU
             * to drop the old mapping (a texture's fold: 15 % of its
             * gradient's time in such faults) */
            const bool fresh = held && !(*held >> bit & 1);
            if (held) {
                /* batch 0 clears the blocks it does not reach; later ones keep them */
                *held = first && !in ? *held & ~(UINT64_C(1) << bit) : *held | UINT64_C(1) << bit;
            } else if (!first && n == DR_ZERO_BLOCK && (!in || dr_block_zero(gb)) && dr_block_zero(grad + i0) &&
                       (!se || dr_block_zero(m2 + i0)) && (!split || dr_block_zero(h0 + i0)) &&
                       (!(split && dsq) || dr_block_zero(dsq + i0))) {
                continue;
            }
            if (fresh && !first)
                fold_block_sized(x, i0, n, gb, h0, true, split, pow2, se);
            else
                fold_block_sized(x, i0, n, gb, h0, first, split, pow2, se);
        }
    }
}

static bool power_of_two(int n)
{
    return n > 0 && (n & (n - 1)) == 0;
}

/* (Dividing by a power of two is multiplying by its reciprocal, exactly:
 * batch b where b + 1 is one (0, 1, 3, 7 ...), and K = 2's standard
 * errors, need no division, the slowest operation of these loops.) */
static void fold_run(const struct welford_step *x, int64_t begin, int64_t end, const double *g, const uint64_t *mask,
                     const double *h0)
{
    const bool pow2 = power_of_two(x->b + 1);
    if (x->b == 0)
        x->split ? fold(x, begin, end, g, mask, h0, true, true, true)
                 : fold(x, begin, end, g, mask, h0, true, false, true);
    else if (pow2)
        x->split ? fold(x, begin, end, g, mask, h0, false, true, true)
                 : fold(x, begin, end, g, mask, h0, false, false, true);
    else
        x->split ? fold(x, begin, end, g, mask, h0, false, true, false)
                 : fold(x, begin, end, g, mask, h0, false, false, false);
}

/* The last batch's standard errors of [begin, end), in place of the sums. */
static void standard_errors(const struct welford_step *x, int64_t begin, int64_t end)
{
    struct dr_reverse_result *r = x->r;
    const double *dsq = x->w->dsq;
    const int K = x->K;
    /* (in place of m2; where a block of it is +0, sqrt(+0 / (K - 1) / K) = +0 is there already) */
    const bool halves = power_of_two(K - 1) && power_of_two(K);   /* (K = 2) */
    const double inv = 1.0 / (K - 1), inv_k = 1.0 / K;
    const uint64_t *nonzero = x->w->nonzero, *wanted = x->w->se_blocks;
    for (int64_t i0 = nonzero ? dr_mask_next(nonzero, NULL, begin, end) : begin; i0 < end;
         i0 = nonzero ? dr_mask_next(nonzero, NULL, dr_block_end(i0, end), end) : i0 + DR_ZERO_BLOCK) {
        const int64_t i1 = dr_block_end(i0, end);
        if (wanted && !dr_mask_test(wanted, i0))
            continue;
        if (!nonzero && i1 - i0 == DR_ZERO_BLOCK && dr_block_zero(r->se + i0))
            continue;
        for (int64_t i = i0; i < i1; i++)
            r->se[i] = halves ? sqrt(r->se[i] * inv * inv_k) : sqrt(r->se[i] / (K - 1) / K);
    }
    for (int64_t i = begin; r->se_gradient && i < end; i++) {
        const double sg2 = dsq ? dsq[i] / K / K : NAN;
        r->se_gradient[i] = r->parts ? sqrt(sg2) : NAN;   /* (in place of dsq) */
        if (r->se_primal)
            r->se_primal[i] = r->parts ? sqrt(fmax(0.0, r->se[i] * r->se[i] - sg2)) : NAN;
    }
}

/* The fold of [begin, end), g[i - begin] its gradient (split: the second
 * half's, h0 the first's; mask: g's marked blocks, fold), a cache-sized
 * piece at a time so that the last batch's standard errors read the sums
 * it has just written. */
#define FOLD_PIECE 1024
static void fold_piece(const struct welford_step *x, int64_t begin, int64_t end, const double *g,
                       const uint64_t *mask, const double *h0)
{
    for (int64_t i0 = begin; i0 < end; i0 += FOLD_PIECE) {
        const int64_t i1 = end - i0 < FOLD_PIECE ? end : i0 + FOLD_PIECE;
        fold_run(x, i0, i1, g + (i0 - begin), mask ? mask + (i0 - begin) / DR_MASK_SPAN : NULL, h0);
        if (x->b == x->K - 1)
            standard_errors(x, i0, i1);
    }
}

/* The fold of entries [begin, end) from the batch's vectors. */
static void welford_range(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct welford_step *x = ctx;
    const double *h0 = x->w->half[0], *h1 = x->w->half[1];
    fold_piece(x, begin, end, x->split ? h1 + begin : h0 + begin, NULL, x->split ? h0 : NULL);
}

/* The fold of a piece of the batch's last estimator run as it is summed
 * (dr_grad_consumer): g is the batch's gradient there, or with split
 * halves the second half's (the first's is in half[0]). */
static void welford_take(void *ctx, int64_t begin, int64_t end, const double *g, const uint64_t *mask)
{
    const struct welford_step *x = ctx;
    fold_piece(x, begin, end, g, mask, x->split ? x->w->half[0] : NULL);
}

/* Batch b's gradient g_b folded into the sums (fold): its last
 * estimator run's as it is summed where the estimator hands it over
 * (w->consume), else from the batch's vectors afterwards. */
static int batch(struct rev_work *w, int b, uint64_t grad_base, struct dr_reverse_result *r)
{
    const int spp = r->spp_batch, n0 = (spp + 1) / 2, n1 = spp / 2;
    const bool split = r->parts && n1 > 0;
    const struct welford_step ws = {w, r, b, w->o->batches, n0, n1, spp, split};
    const struct dr_grad_consumer to_fold = {welford_take, (void *)&ws};
    double *last = w->consume ? NULL : split ? w->half[1] : w->half[0];   /* (NULL: to fold) */
    int rc;
    if (r->primal_run == DR_PRIMAL_CROSS)
        rc = cross_gradient(w, dr_hash64(grad_base + 2 * (uint64_t)b), last, &to_fold, r);
    else if (w->o->primal == DR_PRIMAL_SHARED)
        rc = gradient(w, w->o->problem.seed + 1 + (uint64_t)b, spp, last, &to_fold, r);
    else if (!split)
        rc = gradient(w, dr_hash64(grad_base + 2 * (uint64_t)b), spp, last, &to_fold, r);
    else {
        rc = gradient(w, dr_hash64(grad_base + 2 * (uint64_t)b), n0, w->half[0], NULL, r);
        if (rc == 0)
            rc = gradient(w, dr_hash64(grad_base + 2 * (uint64_t)b + 1), n1, last, &to_fold, r);
    }
    if (rc != 0)
        return rc;
    if (!w->consume)
        dr_parallel_elements(w->T, w->o->problem.threads, welford_range, (void *)&ws);
    step_done(w);
    return 0;
}

/* The loss of the mean primal image (the standard errors: the last
 * batch's fold). */
static void finish(struct rev_work *w, struct dr_reverse_result *r, int primals)
{
    for (size_t i = 0; i < w->n; i++)
        w->img[i] = (float)(w->img_sum[i] / primals);
    r->loss = w->o->loss_scale * dr_loss_eval(w->o->loss, w->img, w->target, w->n);
    if (r->image)
        memcpy(r->image, w->img, sizeof(float) * w->n);
}

/* What will run: samples per batch, the primal mode, whether the standard
 * error's parts are estimated. */
int dr_reverse_spp_batch(int spp, int batches)
{
    return (int)(((int64_t)spp + batches - 1) / batches);
}

enum dr_primal_mode dr_reverse_primal_run(enum dr_primal_mode primal, int spp, int batches,
                                          enum dr_sampler_kind sampler)
{
    /* the cross primal needs samples of a pixel independent of each other:
     * not so with one sample, nor under the stratified sampler, whose samples
     * of a pixel share their strata (sobol: two halves scrambled apart,
     * estimator.h) */
    const bool cross_ok = dr_reverse_spp_batch(spp, batches) >= 2 && sampler != DR_SAMPLER_STRATIFIED;
    return primal == DR_PRIMAL_CROSS && !cross_ok ? DR_PRIMAL_PER_BATCH : primal;
}

static void plan(const struct dr_reverse_options *o, struct dr_reverse_result *r)
{
    const struct dr_grad_problem *p = &o->problem;
    r->spp_batch = dr_reverse_spp_batch(p->spp, o->batches);
    r->primal_run = dr_reverse_primal_run(o->primal, p->spp, o->batches, p->sampler);
    /* mis: a batch in one piece (no halves, so no se_gradient/se_primal
     * split): weights from halves of 2 spp were poor (mis.h) */
    const bool mis = dr_est_sampling_run(p) == DR_SAMPLING_MIS;
    r->parts = r->primal_run == DR_PRIMAL_PER_BATCH && r->spp_batch >= 2 && !mis;
}

bool dr_reverse_parts(const struct dr_reverse_options *o)
{
    struct dr_reverse_result r = {0};
    if (o->batches < 1)
        return false;
    plan(o, &r);
    return r.parts;
}

int dr_reverse_gradient(const struct dr_reverse_options *o, const float *target, struct dr_reverse_result *r)
{
    const struct dr_grad_problem *p = &o->problem;
    const int K = o->batches;
    if (K < 2) {
        dr_set_error("reverse mode needs at least 2 batches for a standard error");
        return DR_ERR_ARG;
    }
    plan(o, r);
    /* progress steps: a render and an estimator run per batch, or (cross) the run alone */
    struct rev_work w = {.o = o, .target = target, .n = (size_t)p->width * (size_t)p->height * 3,
                         .T = p->params->total, .steps = r->primal_run == DR_PRIMAL_CROSS ? K : 2 * K};
    const bool mis = dr_est_sampling_run(p) == DR_SAMPLING_MIS;
    r->primal_seed = dr_hash64(p->seed ^ PRIMAL_SEED_SALT);
    r->t_primal = r->t_gradient = 0.0;   /* (r->grad: batch 0 writes it whole) */
    const uint64_t grad_base = dr_hash64(p->seed ^ GRAD_SEED_SALT);
    int rc = work_alloc(&w, r);
    /* mis: the weights of each batch (and half) from the earlier ones too (mis.h) */
    if (rc == 0 && mis && !p->mis_history)
        rc = dr_mis_history_init(&w.mis, p->params->n);
    if (rc == 0 && o->primal == DR_PRIMAL_SHARED) {
        w.steps = K + 1;
        rc = primal(&w, r->primal_seed, p->spp, r);
    }
    for (int b = 0; b < K && rc == 0; b++) {
        if (r->primal_run == DR_PRIMAL_PER_BATCH)
            rc = primal(&w, dr_hash64(r->primal_seed + (uint64_t)b), r->spp_batch, r);
        if (rc == 0)
            rc = batch(&w, b, grad_base, r);
    }
    if (rc == 0)
        finish(&w, r, o->primal == DR_PRIMAL_SHARED ? 1 : K);
    work_free(&w);
    return rc;
}
