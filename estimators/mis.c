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
                const int64_t *size, bool per_sample, bool scratch)
{
    memset(m, 0, sizeof *m);
    m->threads = threads;
    m->n = n;
    m->stride = n + 1;
    m->segments = segments;
    m->per_sample = per_sample;
    m->seg_off = malloc(sizeof(int64_t) * 2 * (size_t)(segments > 0 ? segments : 1));
    if (!m->seg_off)
        goto nomem;
    m->seg_size = m->seg_off + segments;
    memcpy(m->seg_off, off, sizeof(int64_t) * (size_t)segments);
    memcpy(m->seg_size, size, sizeof(int64_t) * (size_t)segments);
    for (int t = 0; t < threads; t++) {
        if (!(m->buf[t] = alloc_part(m, (size_t)m->stride * 2 * DR_MIS_GROUPS)) ||
            !(m->stats[t] = alloc_part(m, (size_t)segments * NSTAT * DR_MIS_GROUPS)))
            goto nomem;
        if (scratch && !(m->scratch[t] = alloc_part(m, (size_t)m->stride * 2)))
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
        free(m->buf[t]);
        free(m->stats[t]);
        free(m->scratch[t]);
        m->buf[t] = m->stats[t] = m->scratch[t] = NULL;
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

void dr_mis_add(struct dr_mis_accum *m, int thread, int g, int seg, int64_t at, int64_t len, const double *d,
                const double *a)
{
    double *D = dr_mis_slot(m, thread, g, DR_MIS_DETACHED) + at, *A = dr_mis_slot(m, thread, g, DR_MIS_ATTACHED) + at;
    for (int64_t i = 0; i < len; i++) {
        D[i] += d[i];
        A[i] += a[i];
    }
    if (m->per_sample)
        products(d, a, len, stat(m, thread, g, seg));
}

void dr_mis_add_scratch(struct dr_mis_accum *m, int thread, int g)
{
    double *d = m->scratch[thread], *a = d + m->stride;
    for (int k = 0; k < m->segments; k++)
        dr_mis_add(m, thread, g, k, m->seg_off[k], m->seg_size[k], d + m->seg_off[k], a + m->seg_off[k]);
    memset(d, 0, sizeof(double) * 2 * (size_t)m->stride);
}

/* One segment: group g's attached weight a_g from the other groups' P and Q
 * (mis.h), the combination into out, and the mean detached weight. */
static double combine_segment(const struct dr_mis_accum *m, int seg, double *out)
{
    const int64_t off = m->seg_off[seg], size = m->seg_size[seg];
    double s[DR_MIS_GROUPS][NSTAT], all[NSTAT] = {0.0, 0.0, 0.0};
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        memset(s[g], 0, sizeof s[g]);
        if (m->per_sample)
            memcpy(s[g], stat(m, 0, g, seg), sizeof s[g]);
        else
            products(dr_mis_slot(m, 0, g, DR_MIS_DETACHED) + off, dr_mis_slot(m, 0, g, DR_MIS_ATTACHED) + off, size,
                     s[g]);
        for (int k = 0; k < NSTAT; k++)
            all[k] += s[g][k];
    }
    memset(out + off, 0, sizeof(double) * (size_t)size);
    double w_sum = 0.0;
    int used = 0;
    for (int g = 0; g < DR_MIS_GROUPS; g++) {
        double P = all[P_] - s[g][P_], Q = all[Q_] - s[g][Q_], R = all[R_] - s[g][R_], a = 0.0;
        if (Q > ROUNDING_RATIO * R && Q > 0.0)
            a = dr_clamp(-P / Q, 0.0, 1.0);
        const double *D = dr_mis_slot(m, 0, g, DR_MIS_DETACHED) + off;
        const double *A = dr_mis_slot(m, 0, g, DR_MIS_ATTACHED) + off;
        for (int64_t i = 0; i < size; i++)
            out[off + i] += D[i] + a * (A[i] - D[i]);
        if (s[g][Q_] > 0.0 || s[g][R_] > 0.0) {   /* a group with samples in this segment */
            w_sum += 1.0 - a;
            used++;
        }
    }
    return used ? w_sum / used : 1.0;
}

void dr_mis_combine(struct dr_mis_accum *m, double *out, double *w_detached)
{
    /* the threads into thread 0's buffers, in thread order */
    const int64_t nb = m->stride * 2 * DR_MIS_GROUPS, ns = (int64_t)m->segments * NSTAT * DR_MIS_GROUPS;
    for (int t = 1; t < m->threads; t++) {
        for (int64_t i = 0; i < nb; i++)
            m->buf[0][i] += m->buf[t][i];
        for (int64_t i = 0; i < ns; i++)
            m->stats[0][i] += m->stats[t][i];
    }
    for (int k = 0; k < m->segments; k++) {
        double w = combine_segment(m, k, out);
        if (w_detached)
            w_detached[k] = w;
    }
}
