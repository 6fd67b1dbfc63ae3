#include "exact_sum.h"

#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "error.h"

__extension__ typedef __int128 i128;   /* GCC's: the sums' two's complement values */
__extension__ typedef unsigned __int128 u128;

static struct dr_exact_sum *create(int64_t n, bool sparse)
{
    struct dr_exact_sum *e = calloc(1, sizeof *e);
    size_t n1 = (size_t)(n > 0 ? n : 1);
    if (e) {
        e->n = n;
        e->w = sparse ? calloc(n1, sizeof *e->w) : dr_calloc_big(n1, sizeof *e->w);   /* (bigalloc.h) */
        e->bad = sparse ? calloc(n1, 1) : dr_calloc_big(n1, 1);
    }
    if (!e || !e->w || !e->bad) {
        dr_exact_sum_destroy(e);
        dr_set_error("out of memory for the gradient (%lld entries)", (long long)n);
        return NULL;
    }
    return e;
}

struct dr_exact_sum *dr_exact_sum_create(int64_t n)
{
    return create(n, false);
}

struct dr_exact_sum *dr_exact_sum_create_sparse(int64_t n)
{
    return create(n, true);
}

void dr_exact_sum_destroy(struct dr_exact_sum *e)
{
    if (!e)
        return;
    free(e->w);
    free(e->bad);
    free(e);
}

void dr_exact_sum_clear(struct dr_exact_sum *e)
{
    const size_t n1 = (size_t)(e->n > 0 ? e->n : 1);
    memset(e->w, 0, n1 * sizeof *e->w);
    memset(e->bad, 0, n1);
}

uint64_t dr_exact_sum_bytes(int64_t n)
{
    return (uint64_t)(n > 0 ? n : 1) * (sizeof(struct dr_exact_word) + 1);
}

/* Entry i as a double, or NaN (*bad set) where a contribution was out of
 * range or the sum is within a factor 2 of the range's end. */
static double entry(const struct dr_exact_sum *e, int64_t i, bool *bad)
{
    *bad = true;
    if (e->bad[i])
        return NAN;
    u128 u = ((u128)e->w[i].hi << 64) | e->w[i].lo;
    i128 s = (i128)u;   /* GCC: modulo 2^128, the two's complement value */
    /* within a factor 2 of the range's end: it may have wrapped */
    if (s >= ((i128)1 << 126) || s <= -((i128)1 << 126))
        return NAN;
    *bad = false;
    /* the int128 -> double conversion rounds once; the scaling is exact */
    return (double)s * (1.0 / DR_EXACT_SCALE);
}

int64_t dr_exact_sum_read(const struct dr_exact_sum *e, double *out)
{
    int64_t n_bad = 0;
    for (int64_t i = 0; i < e->n; i++) {
        bool bad;
        out[i] = entry(e, i, &bad);
        n_bad += bad;
    }
    return n_bad;
}

int64_t dr_exact_sum_take(struct dr_exact_sum *e, int64_t begin, int64_t end, double *out)
{
    int64_t n_bad = 0;
    for (int64_t i = begin; i < end; i++) {
        bool bad;
        out[i - begin] = entry(e, i, &bad);
        n_bad += bad;
    }
    memset(e->w + begin, 0, sizeof *e->w * (size_t)(end - begin));
    memset(e->bad + begin, 0, (size_t)(end - begin));
    return n_bad;
}
