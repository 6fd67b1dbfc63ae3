#include "exact_sum.h"

#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "error.h"

__extension__ typedef __int128 i128;   /* GCC's: the sums' two's complement values */
__extension__ typedef unsigned __int128 u128;

struct dr_exact_sum *dr_exact_sum_create(int64_t n)
{
    struct dr_exact_sum *e = calloc(1, sizeof *e);
    size_t n1 = (size_t)(n > 0 ? n : 1);
    if (e) {
        e->n = n;
        e->w = dr_calloc_big(n1, sizeof *e->w);   /* bigalloc.h: texture parameters */
        e->bad = dr_calloc_big(n1, 1);
    }
    if (!e || !e->w || !e->bad) {
        dr_exact_sum_destroy(e);
        dr_set_error("out of memory for the gradient (%lld entries)", (long long)n);
        return NULL;
    }
    return e;
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

int64_t dr_exact_sum_read(const struct dr_exact_sum *e, double *out)
{
    int64_t bad = 0;
    for (int64_t i = 0; i < e->n; i++) {
        if (e->bad[i]) {
            out[i] = NAN;
            bad++;
            continue;
        }
        u128 u = ((u128)e->w[i].hi << 64) | e->w[i].lo;
        i128 s = (i128)u;   /* GCC: modulo 2^128, the two's complement value */
        /* within a factor 2 of the range's end: it may have wrapped */
        if (s >= ((i128)1 << 126) || s <= -((i128)1 << 126)) {
            out[i] = NAN;
            bad++;
            continue;
        }
        /* the int128 -> double conversion rounds once; the scaling is exact */
        out[i] = (double)s * (1.0 / DR_EXACT_SCALE);
    }
    return bad;
}
