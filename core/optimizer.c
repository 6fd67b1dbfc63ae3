#include "optimizer.h"

#include <math.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>

#include "error.h"
#include "parallel.h"
#include "zero_blocks.h"

double dr_param_default_lr(const struct dr_param *p, const double *values)
{
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR:
    case DR_PARAM_METALLIC:
    case DR_PARAM_ROUGHNESS:
    case DR_PARAM_CLEARCOAT:
    case DR_PARAM_CLEARCOAT_ROUGHNESS:
    case DR_PARAM_ANISOTROPY_STRENGTH:
    case DR_PARAM_SHEEN_COLOR:
    case DR_PARAM_SHEEN_ROUGHNESS:
    case DR_PARAM_IMAGE:
    case DR_PARAM_MEDIUM_ALBEDO:
    case DR_PARAM_MEDIUM_G: return 0.02;
    case DR_PARAM_MEDIUM_DENSITY: return 0.05;   /* voxels: densities of order 1, often starting at 0 */
    default: {
        double mean = 0.0;
        for (int64_t i = 0; i < p->size; i++)
            mean += fabs(values[i]);
        mean /= (double)(p->size > 0 ? p->size : 1);
        return 0.05 * (mean > 0.2 ? mean : 0.2);
    }
    }
}

void dr_adam_destroy(struct dr_adam *a)
{
    if (!a)
        return;
    free(a->m);
    free(a->v);
    free(a->moved);
    free(a->offset);
    free(a->size);
    free(a->lr);
    free(a->lo);
    free(a->hi);
    free(a);
}

struct dr_adam *dr_adam_create(const struct dr_param_set *ps, const double *theta, double lr_override)
{
    struct dr_adam *a = calloc(1, sizeof *a);
    if (!a)
        goto nomem;
    a->n = ps->total;
    a->threads = 1;
    a->beta1 = 0.9;
    a->beta2 = 0.999;
    a->eps = 1e-8;
    size_t n = (size_t)(a->n > 0 ? a->n : 1), np = (size_t)(ps->n > 0 ? ps->n : 1);
    a->n_params = ps->n;
    a->m = calloc(n, sizeof(double));
    a->v = calloc(n, sizeof(double));
    a->moved = calloc((size_t)dr_mask_words((int64_t)n), sizeof(uint64_t));   /* (m and v: +0) */
    a->moved_known = true;
    a->offset = malloc(np * sizeof(int64_t));
    a->size = malloc(np * sizeof(int64_t));
    a->lr = malloc(np * sizeof(double));
    a->lo = malloc(np * sizeof(double));
    a->hi = malloc(np * sizeof(double));
    if (!a->m || !a->v || !a->moved || !a->offset || !a->size || !a->lr || !a->lo || !a->hi)
        goto nomem;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        a->offset[k] = p->offset;
        a->size[k] = p->size;
        dr_param_range(p, &a->lo[k], &a->hi[k]);
        a->lr[k] = lr_override > 0.0 ? lr_override : dr_param_default_lr(p, theta + p->offset);
    }
    return a;
nomem:
    dr_set_error("out of memory");
    dr_adam_destroy(a);
    return NULL;
}

int dr_adam_param_of(const struct dr_adam *a, int64_t i)
{
    for (int k = 0; k < a->n_params; k++)
        if (i >= a->offset[k] && i < a->offset[k] + a->size[k])
            return k;
    return -1;
}

/* Entry i's step; false if its gradient was not finite (taken as 0).
 * fresh: m[i] and v[i] are known to be +0 and are not read, only written
 * (the same operations on the +0 they hold: the same bits). Why it
 * matters: a read of a page nothing wrote yet maps the kernel's shared
 * zero page, and the write after it then costs a copy-on-write fault with
 * a TLB shootdown on every other CPU the process runs on; written first,
 * the page is a plain fresh one. A texture's first steps at a preview size
 * spent 15 % of their time in those shootdowns. */
static inline __attribute__((always_inline)) bool adam_entry(const struct dr_adam *a, int64_t i,
                                                             double *restrict m, double *restrict v,
                                                             double *restrict theta, const double *restrict grad,
                                                             double lr, double lo, double hi, double c1, double c2,
                                                             bool fresh)
{
    const double b1 = a->beta1, b2 = a->beta2, eps = a->eps;
    double g = grad ? grad[i] : 0.0;   /* (NULL: a block the gradient's mask leaves +0, not read) */
    const bool finite = isfinite(g);
    g = finite ? g : 0.0;
    m[i] = b1 * (fresh ? 0.0 : m[i]) + (1.0 - b1) * g;
    v[i] = b2 * (fresh ? 0.0 : v[i]) + (1.0 - b2) * g * g;
    const double step = lr * (m[i] / c1) / (sqrt(v[i] / c2) + eps);
    const double x = theta[i] - step;
    theta[i] = x < lo ? lo : (x > hi ? hi : x);
    return finite;
}

/* One parameter's scalars. restrict: m, v, theta and grad never overlap, so
 * GCC may vectorise (the same operations in the same order: the same bits). */
static int64_t adam_span(const struct dr_adam *a, int64_t n, double *restrict m, double *restrict v,
                         double *restrict theta, const double *restrict grad, double lr, double lo, double hi,
                         double c1, double c2)
{
    int64_t bad = 0;
    int64_t i0 = 0;
    for (; i0 + DR_ZERO_BLOCK <= n; i0 += DR_ZERO_BLOCK) {
        /* an entry no gradient has reached yet (m, v and its gradient +0)
         * inside its bounds does not move: m and v stay +0, the step is
         * lr * +0 / (+0 + eps) = +0 (lr, eps > 0), theta - +0 = theta; most
         * of a texture's, in the first iterations at a preview size
         * (zero_blocks.h) */
        if (dr_block_zero(grad + i0) && dr_block_zero(m + i0) && dr_block_zero(v + i0) && lr > 0.0 &&
            a->eps > 0.0) {
            bool inside = true;
            for (int64_t i = i0; i < i0 + DR_ZERO_BLOCK; i++)
                inside &= theta[i] >= lo && theta[i] <= hi;
            if (inside)
                continue;
        }
        for (int64_t i = i0; i < i0 + DR_ZERO_BLOCK; i++)
            bad += !adam_entry(a, i, m, v, theta, grad, lr, lo, hi, c1, c2, false);
    }
    for (int64_t i = i0; i < n; i++)
        bad += !adam_entry(a, i, m, v, theta, grad, lr, lo, hi, c1, c2, false);
    return bad;
}

/* One parameter's step on scalars [begin, end) of it (dr_parallel_elements). */
struct adam_step {
    const struct dr_adam *a;
    int k;
    double *theta, c1, c2;
    const double *grad;
    const uint64_t *grad_mask;   /* adam_marked: grad's mask (a->moved the moments') */
    _Atomic int64_t bad;
};

static void adam_range(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    struct adam_step *x = ctx;
    const struct dr_adam *a = x->a;
    const int64_t o = a->offset[x->k] + begin;
    x->bad += adam_span(a, end - begin, a->m + o, a->v + o, x->theta + o, x->grad + o, a->lr[x->k], a->lo[x->k],
                        a->hi[x->k], x->c1, x->c2);
}

/* n entries' steps, nothing skipped (restrict: vectorised, the same
 * bits); fresh: their m and v are +0, written without being read
 * (adam_entry). */
static inline __attribute__((always_inline)) int64_t adam_run(const struct dr_adam *a, int64_t n,
                                                              double *restrict m, double *restrict v,
                                                              double *restrict theta, const double *restrict grad,
                                                              double lr, double lo, double hi, double c1, double c2,
                                                              bool fresh)
{
    int64_t bad = 0;
    for (int64_t i = 0; i < n; i++)
        bad += !adam_entry(a, i, m, v, theta, grad, lr, lo, hi, c1, c2, fresh);
    return bad;
}

/* What a block of a masked step reads: the moments' mask says whether
 * its m and v may not be +0 (else they are written unread, adam_entry's
 * fresh), the gradient's whether its gradient may not be +0 (else it is
 * not read either: once a third of a texture has moved, most stepped
 * blocks only decay, and a stream fewer is a quarter less to read). */
static inline int block_reads(const struct adam_step *x, int64_t b)
{
    return dr_mask_test(x->a->moved, b) | dr_mask_test(x->grad_mask, b) << 1;
}

/* adam_run of [i, j) (global entries, blocks either mask marks), in
 * stretches of blocks that read the same (block_reads). */
static int64_t adam_run_masked(const struct adam_step *x, int64_t i, int64_t j)
{
    const struct dr_adam *a = x->a;
    const int k = x->k;
    const double lr = a->lr[k], lo = a->lo[k], hi = a->hi[k];
    int64_t bad = 0;
    for (int64_t b = i; b < j;) {
        const int reads = block_reads(x, b);
        int64_t c = dr_block_end(b, j);
        while (c < j && block_reads(x, c) == reads)
            c = dr_block_end(c, j);
        double *m = a->m + b, *v = a->v + b, *theta = x->theta + b;
        const double *g = x->grad + b;
        if (reads == 3)   /* (each case's flags constants: a loop of its own) */
            bad += adam_run(a, c - b, m, v, theta, g, lr, lo, hi, x->c1, x->c2, false);
        else if (reads == 1)
            bad += adam_run(a, c - b, m, v, theta, NULL, lr, lo, hi, x->c1, x->c2, false);
        else
            bad += adam_run(a, c - b, m, v, theta, g, lr, lo, hi, x->c1, x->c2, true);
        b = c;
    }
    return bad;
}

/* adam_range over the runs of blocks grad's or the moments' mask marks:
 * [begin, end) of parameter k, global entries o + begin ... (a block may
 * straddle two ranges: each steps its own entries of it; the masks are
 * only read). */
static void adam_marked(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    struct adam_step *x = ctx;
    const struct dr_adam *a = x->a;
    const int k = x->k;
    const int64_t o = a->offset[k], e = o + end;
    int64_t bad = 0;
    for (int64_t i = dr_mask_next(x->grad_mask, a->moved, o + begin, e); i < e;) {
        const int64_t j = dr_mask_run_end(x->grad_mask, a->moved, i, e);
        bad += adam_run_masked(x, i, j);
        i = dr_mask_next(x->grad_mask, a->moved, j, e);
    }
    x->bad += bad;
}

/* a->moved from m and v, words [begin, end) (dr_parallel_elements over
 * words: each its own). */
static void moved_from_moments(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    struct dr_adam *a = ctx;
    for (int64_t w = begin; w < end; w++) {
        uint64_t bits = 0;
        for (int b = 0; b < 64; b++) {
            const int64_t i = w * DR_MASK_SPAN + b * DR_ZERO_BLOCK;
            if (i >= a->n)
                break;
            bool zero = true;
            if (i + DR_ZERO_BLOCK <= a->n)   /* (a whole block: its words as bits, -0 not a zero) */
                zero = dr_block_zero(a->m + i) && dr_block_zero(a->v + i);
            for (int64_t j = i; i + DR_ZERO_BLOCK > a->n && j < a->n; j++)
                zero &= a->m[j] == 0.0 && !signbit(a->m[j]) && a->v[j] == 0.0 && !signbit(a->v[j]);
            bits |= (uint64_t)!zero << b;
        }
        a->moved[w] = bits;
    }
}

/* While the values' ranges are not known (dr_adam_step_masked): the
 * blocks of [begin, end) of parameter k that neither mask marks, stepped
 * where a value is outside its range (the step clamps it; m and v stay +0:
 * b1 * +0 + (1 - b1) * +0), found by reading the values alone. */
static void adam_range_unmarked(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    struct adam_step *x = ctx;
    const struct dr_adam *a = x->a;
    const int k = x->k;
    const double lo = a->lo[k], hi = a->hi[k];
    const int64_t o = a->offset[k], e = o + end;
    for (int64_t i = o + begin; i < e;) {
        const int64_t j = dr_mask_next(x->grad_mask, a->moved, i, e);   /* [i, j): unmarked */
        for (int64_t b = i; b < j; b = dr_block_end(b, j)) {
            bool inside = true;
            for (int64_t l = b; l < dr_block_end(b, j); l++)
                inside &= x->theta[l] >= lo && x->theta[l] <= hi;
            for (int64_t l = b; !inside && l < dr_block_end(b, j); l++)
                x->bad += !adam_entry(a, l, a->m, a->v, x->theta, x->grad, a->lr[k], lo, hi, x->c1, x->c2, true);
        }
        i = dr_mask_run_end(x->grad_mask, a->moved, j, e);
    }
}

static int64_t adam_steps(struct dr_adam *a, double *theta, const double *grad, const uint64_t *grad_mask)
{
    a->t++;
    struct adam_step x = {.a = a, .theta = theta, .grad = grad, .grad_mask = grad_mask,
                          .c1 = 1.0 - pow(a->beta1, (double)a->t), .c2 = 1.0 - pow(a->beta2, (double)a->t)};
    atomic_init(&x.bad, 0);
    for (x.k = 0; x.k < a->n_params; x.k++) {
        dr_parallel_elements(a->size[x.k], a->threads, grad_mask ? adam_marked : adam_range, &x);
        if (grad_mask && !a->ranged)
            dr_parallel_elements(a->size[x.k], a->threads, adam_range_unmarked, &x);
    }
    return atomic_load(&x.bad);
}

int64_t dr_adam_step(struct dr_adam *a, double *theta, const double *grad)
{
    a->moved_known = a->ranged = false, a->changed = NULL;
    return adam_steps(a, theta, grad, NULL);
}

int64_t dr_adam_step_masked(struct dr_adam *a, double *theta, const double *grad, const uint64_t *grad_mask)
{
    /* (the skipped entries need lr > 0 and eps > 0: a step of +0, as adam_span's) */
    bool lr_positive = a->eps > 0.0;
    for (int k = 0; k < a->n_params; k++)
        lr_positive &= a->lr[k] > 0.0;
    if (!grad_mask || !lr_positive)
        return dr_adam_step(a, theta, grad);
    if (!a->moved_known)   /* (after a checkpoint: m and v are resident, read them) */
        dr_parallel_elements(dr_mask_words(a->n), a->threads, moved_from_moments, a);
    a->moved_known = true;
    const bool ranged = a->ranged;
    const int64_t bad = adam_steps(a, theta, grad, grad_mask);
    for (int64_t w = 0; w < dr_mask_words(a->n); w++)   /* (the moments reached now: after every range) */
        a->moved[w] |= grad_mask[w];
    a->ranged = true;   /* (every value outside the masks was inside its range, or clamped into it) */
    a->changed = ranged ? a->moved : NULL;   /* (a clamped value may be anywhere) */
    return bad;
}

const uint64_t *dr_adam_changed(const struct dr_adam *a)
{
    return a->changed;
}

const uint64_t *dr_adam_moments(const struct dr_adam *a)
{
    return a->moved_known ? a->moved : NULL;
}
