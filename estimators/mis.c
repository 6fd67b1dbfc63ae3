#include "mis.h"

#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "vec.h"

/* Delta this small against D is rounding between two code paths that compute
 * the same number (the parameter moves no sampling map), not a second estimate. */
#define ROUNDING_RATIO 1e-24

enum { P_, Q_, R_, NSTAT };

static double *alloc_part(struct dr_mis_accum *m, size_t count)
{
    m->bytes += count * sizeof(double);
    return calloc(count ? count : 1, sizeof(double));
}

int dr_mis_init(struct dr_mis_accum *m, int threads, int64_t n, int segments, const int64_t *off,
                const int64_t *size, int64_t pixels, bool forward)
{
    memset(m, 0, sizeof *m);
    m->threads = threads;
    m->n = n;
    m->stride = n + 1;
    m->pixels = pixels;
    m->segments = segments;
    m->forward = forward;
    m->per_sample = forward || (n <= DR_MIS_SAMPLE_STATS_MAX && pixels * 2 * n <= DR_MIS_PIXEL_SUMS_MAX);
    m->seg_off = malloc(sizeof(int64_t) * 2 * (size_t)(segments > 0 ? segments : 1));
    if (!m->seg_off)
        goto nomem;
    m->seg_size = m->seg_off + segments;
    memcpy(m->seg_off, off, sizeof(int64_t) * (size_t)segments);
    memcpy(m->seg_size, size, sizeof(int64_t) * (size_t)segments);
    for (int t = 0; t < threads; t++) {
        if (!(m->buf[t] = alloc_part(m, (size_t)m->stride * 2 * DR_MIS_GROUPS)))
            goto nomem;
        if (!m->per_sample)
            continue;
        if (!(m->stats[t] = alloc_part(m, (size_t)segments * NSTAT * DR_MIS_GROUPS)) ||
            !(m->count[t] = alloc_part(m, (size_t)pixels)))
            goto nomem;
        if (!forward && (!(m->pix[t] = alloc_part(m, (size_t)(pixels * 2 * n))) ||
                         !(m->scratch[t] = alloc_part(m, (size_t)m->stride * 2))))
            goto nomem;
    }
    return 0;
nomem:
    dr_mis_free(m);
    dr_set_error("out of memory for the mis estimates (%d groups x 2 x %lld entries per thread)", DR_MIS_GROUPS,
                 (long long)n);
    return DR_ERR_NOMEM;
}

void dr_mis_free(struct dr_mis_accum *m)
{
    for (int t = 0; t < DR_MAX_THREADS; t++) {
        double **parts[] = {&m->buf[t], &m->stats[t], &m->count[t], &m->pix[t], &m->scratch[t]};
        for (size_t k = 0; k < sizeof parts / sizeof parts[0]; k++) {
            free(*parts[k]);
            *parts[k] = NULL;
        }
    }
    free(m->seg_off);
    m->seg_off = m->seg_size = NULL;
}

static double *stat(const struct dr_mis_accum *m, int thread, int g, int seg)
{
    return m->stats[thread] + ((int64_t)g * m->segments + seg) * NSTAT;
}

/* P, Q, R of vectors d and a = d + Delta (len entries) into st (+=). */
static void products(const double *d, const double *a, int64_t len, double *st)
{
    for (int64_t i = 0; i < len; i++) {
        double delta = a[i] - d[i];
        st[P_] += d[i] * delta;
        st[Q_] += delta * delta;
        st[R_] += d[i] * d[i];
    }
}

void dr_mis_add(struct dr_mis_accum *m, int thread, int64_t px, int64_t at, int64_t len, const double *d,
                const double *a)
{
    const int g = dr_mis_group(px);
    double *D = dr_mis_slot(m, thread, g, DR_MIS_DETACHED), *A = dr_mis_slot(m, thread, g, DR_MIS_ATTACHED);
    for (int64_t i = 0; i < len; i++) {
        D[at + i] += d[i];
        A[at + i] += a[i];
    }
    if (!m->per_sample)
        return;
    m->count[thread][px] += 1.0;
    for (int k = 0; k < m->segments; k++) {   /* the part of [at, at + len) in segment k */
        int64_t lo = m->seg_off[k] > at ? m->seg_off[k] : at;
        int64_t hi = m->seg_off[k] + m->seg_size[k] < at + len ? m->seg_off[k] + m->seg_size[k] : at + len;
        if (lo < hi)
            products(d + (lo - at), a + (lo - at), hi - lo, stat(m, thread, g, k));
    }
    if (m->pix[thread]) {   /* reverse mode: the pixel's own sums (forward: the group's image holds them) */
        double *pd = m->pix[thread] + px * 2 * m->n, *pa = pd + m->n;
        for (int64_t i = 0; i < len; i++) {
            pd[at + i] += d[i];
            pa[at + i] += a[i];
        }
    }
}

void dr_mis_add_scratch(struct dr_mis_accum *m, int thread, int64_t px)
{
    double *d = m->scratch[thread], *a = d + m->stride;
    dr_mis_add(m, thread, px, 0, m->n, d, a);
    memset(d, 0, sizeof(double) * 2 * (size_t)m->stride);
}

/* The sums of pixel px's samples over segment k: D and A (len entries). */
static void pixel_sums(const struct dr_mis_accum *m, int64_t px, int k, const double **D, const double **A)
{
    if (m->forward) {   /* one segment, the image: the pixel's three channels in its group's image */
        int g = dr_mis_group(px);
        *D = dr_mis_slot(m, 0, g, DR_MIS_DETACHED) + 3 * px;
        *A = dr_mis_slot(m, 0, g, DR_MIS_ATTACHED) + 3 * px;
        return;
    }
    *D = m->pix[0] + px * 2 * m->n + m->seg_off[k];
    *A = *D + m->n;
}

/* Per-sample statistics of segment k, centred per pixel, per group (mis.h).
 * False when no pixel has two samples (nothing to centre on). */
static bool stats_per_sample(const struct dr_mis_accum *m, int k, double s[DR_MIS_GROUPS][NSTAT])
{
    bool any = false;
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        memcpy(s[g], stat(m, 0, g, k), sizeof s[g]);
    const int64_t len = m->forward ? 3 : m->seg_size[k];
    for (int64_t px = 0; px < m->pixels; px++) {
        double n = m->count[0][px];
        if (n < 1.0)
            continue;
        any |= n >= 2.0;
        const double *D, *A;
        pixel_sums(m, px, k, &D, &A);
        double c[NSTAT] = {0.0, 0.0, 0.0};
        products(D, A, len, c);
        int g = dr_mis_group(px);
        s[g][P_] -= c[P_] / n;
        s[g][Q_] -= c[Q_] / n;
        s[g][R_] -= c[R_] / n;
    }
    return any;
}

/* Leave-one-out statistics from the groups' sums, centred on the other
 * groups' mean (mis.h): s[g] = what group g's weight uses. */
static void stats_loo_groups(const struct dr_mis_accum *m, int k, double s[DR_MIS_GROUPS][NSTAT])
{
    const int64_t off = m->seg_off[k], size = m->seg_size[k];
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        memset(s[g], 0, sizeof s[g]);
        for (int64_t i = off; i < off + size; i++) {
            double md = 0.0, ma = 0.0;
            for (int h = 0; h < DR_MIS_GROUPS; h++)
                if (h != g) {
                    md += dr_mis_slot(m, 0, h, DR_MIS_DETACHED)[i] / (DR_MIS_GROUPS - 1);
                    ma += dr_mis_slot(m, 0, h, DR_MIS_ATTACHED)[i] / (DR_MIS_GROUPS - 1);
                }
            for (int h = 0; h < DR_MIS_GROUPS; h++)
                if (h != g) {
                    double d = dr_mis_slot(m, 0, h, DR_MIS_DETACHED)[i] - md;
                    double a = dr_mis_slot(m, 0, h, DR_MIS_ATTACHED)[i] - ma;
                    products(&d, &a, 1, s[g]);
                }
        }
    }
}

/* Group h's own variance-optimal weight from its statistics st: -P / Q
 * clamped to [0, 1]; 0 (detached) where Delta is rounding. False when the
 * group has no samples in the segment (it casts no vote). */
static bool group_weight(const double st[NSTAT], double *a)
{
    *a = 0.0;
    if (st[Q_] <= 0.0 && st[R_] <= 0.0)
        return false;
    if (st[Q_] > ROUNDING_RATIO * st[R_] && st[Q_] > 0.0)
        *a = dr_clamp(-st[P_] / st[Q_], 0.0, 1.0);
    return true;
}

static int cmp_double(const void *x, const void *y)
{
    double a = *(const double *)x, b = *(const double *)y;
    return (a > b) - (a < b);
}

/* Each group's weight as the median of the OTHER groups' own weights (mis.h:
 * why a median and not the pooled ratio). 0 where no other group votes. */
static void weights_median(double s[DR_MIS_GROUPS][NSTAT], double a[DR_MIS_GROUPS])
{
    double own[DR_MIS_GROUPS];
    bool votes[DR_MIS_GROUPS];
    for (int h = 0; h < DR_MIS_GROUPS; h++)
        votes[h] = group_weight(s[h], &own[h]);
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        double v[DR_MIS_GROUPS];
        int n = 0;
        for (int h = 0; h < DR_MIS_GROUPS; h++)
            if (h != g && votes[h])
                v[n++] = own[h];
        qsort(v, (size_t)n, sizeof v[0], cmp_double);
        a[g] = n == 0 ? 0.0 : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    }
}

/* Each group's weight from the leave-one-out statistics of the groups' sums
 * (no per-sample statistics: one number per group, too few for a median). */
static void weights_pooled(const struct dr_mis_accum *m, int k, double a[DR_MIS_GROUPS])
{
    double loo[DR_MIS_GROUPS][NSTAT];
    stats_loo_groups(m, k, loo);
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        group_weight(loo[g], &a[g]);
}

int dr_mis_history_init(struct dr_mis_history *h, int segments)
{
    h->segments = segments;
    h->stats = calloc((size_t)(segments > 0 ? segments : 1) * DR_MIS_GROUPS * NSTAT, sizeof(double));
    if (h->stats)
        return 0;
    dr_set_error("out of memory for the mis statistics of %d parameters", segments);
    return DR_ERR_NOMEM;
}

void dr_mis_history_free(struct dr_mis_history *h)
{
    free(h->stats);
    h->stats = NULL;
}

/* Segment k's groups' statistics s with the history's added (for the
 * weights), and the history updated with this run's own. */
static void join_history(struct dr_mis_history *h, int k, double s[DR_MIS_GROUPS][NSTAT])
{
    double *hs = h->stats + (size_t)k * DR_MIS_GROUPS * NSTAT;
    for (int g = 0; g < DR_MIS_GROUPS; g++)
        for (int j = 0; j < NSTAT; j++) {
            s[g][j] += hs[g * NSTAT + j];
            hs[g * NSTAT + j] = s[g][j];
        }
}

/* One segment: each group's attached weight a_g from the other groups (and
 * the history), the combination into out, and the mean detached weight. */
static double combine_segment(const struct dr_mis_accum *m, int k, double *out, struct dr_mis_history *h)
{
    const int64_t off = m->seg_off[k], size = m->seg_size[k];
    double s[DR_MIS_GROUPS][NSTAT], a[DR_MIS_GROUPS];
    if (m->per_sample && stats_per_sample(m, k, s)) {
        if (h && h->stats && h->segments == m->segments)
            join_history(h, k, s);
        weights_median(s, a);
    } else {
        weights_pooled(m, k, a);
    }
    memset(out + off, 0, sizeof(double) * (size_t)size);
    double w_sum = 0.0;
    int used = 0;
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        const double *D = dr_mis_slot(m, 0, g, DR_MIS_DETACHED) + off;
        const double *A = dr_mis_slot(m, 0, g, DR_MIS_ATTACHED) + off;
        bool has = false;
        for (int64_t i = 0; i < size; i++) {
            out[off + i] += D[i] + a[g] * (A[i] - D[i]);
            has |= D[i] != 0.0 || A[i] != 0.0;
        }
        if (has) {   /* a group with samples in this segment */
            w_sum += 1.0 - a[g];
            used++;
        }
    }
    return used ? w_sum / used : 1.0;
}

static void sum_threads(double *const *parts, int threads, int64_t count)
{
    for (int t = 1; t < threads && parts[0]; t++)
        for (int64_t i = 0; i < count; i++)
            parts[0][i] += parts[t][i];
}

void dr_mis_combine(struct dr_mis_accum *m, double *out, double *w_detached, struct dr_mis_history *history)
{
    /* the threads into thread 0's buffers, in thread order */
    sum_threads(m->buf, m->threads, m->stride * 2 * DR_MIS_GROUPS);
    sum_threads(m->stats, m->threads, (int64_t)m->segments * NSTAT * DR_MIS_GROUPS);
    sum_threads(m->count, m->threads, m->pixels);
    sum_threads(m->pix, m->threads, m->pixels * 2 * m->n);
    for (int k = 0; k < m->segments; k++) {
        double w = combine_segment(m, k, out, history);
        if (w_detached)
            w_detached[k] = w;
    }
}
