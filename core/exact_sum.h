/* A vector of sums that every thread adds into at once, exactly.
 *
 * Why: a reverse-mode estimator run sums each thread's parameter adjoints
 * into a vector of its own and adds those in thread order at the end
 * (estimators/common.c), so the gradient is the same to the bit for a
 * given thread count. For a texture parameter that is a vector of the
 * texture's size per thread: a 4096x4096 RGB texture on 16 threads, 6.4 GB.
 * Here every entry is a 128-bit fixed-point integer in units of 2^-88, added
 * to with atomic integer additions. Integer addition is exact and
 * associative, so the sum does not depend on the order the threads' adds
 * arrive in: one shared vector of 17 bytes an entry (16 and a flag) whatever
 * the thread count, with the same bits for any thread count (per-thread
 * vectors' results change in the last digits with it). The estimators use
 * it from 4 threads on (estimator.h), where it is the smaller.
 *
 * Range: each contribution is rounded to the nearest multiple of 2^-88
 * (3.2e-27: a relative error below 1e-15 for anything above 3e-12) and must
 * be smaller than 2^24 (1.7e7) in magnitude; the entries' sums must stay
 * below 2^39 (5.5e11). A gradient contribution is an adjoint (d loss / d
 * pixel, of order 1 / pixels) times path terms, far inside both; one outside
 * them, or not finite, marks its entry (dr_exact_sum_read reports it rather
 * than give a wrong number).
 *
 * Cost: a conversion and one atomic addition per contribution (two when the
 * low word carries), against a plain addition into a thread's own vector. */
#ifndef DR_EXACT_SUM_H
#define DR_EXACT_SUM_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>

struct dr_exact_word {
    uint64_t lo;   /* low 64 bits of the two's complement 128-bit sum */
    uint64_t hi;   /* high 64 bits (unsigned: the additions wrap, as two's complement does) */
};

struct dr_exact_sum {
    int64_t n;
    struct dr_exact_word *w;
    uint8_t *bad;   /* per entry: a contribution out of range or not finite (set, never cleared) */
};

#define DR_EXACT_SCALE 0x1p88       /* units per 1.0 */
#define DR_EXACT_MAX_ADD 0x1p24     /* a contribution's magnitude must be below this */

/* n entries, all zero; NULL + dr_last_error on out of memory. _sparse:
 * for sums added to in few places (a preview's texture gradient, read
 * back with dr_exact_sum_take): fresh pages, resident only where written
 * (bigalloc.h's dr_big_vector_keep says why). */
struct dr_exact_sum *dr_exact_sum_create(int64_t n);
struct dr_exact_sum *dr_exact_sum_create_sparse(int64_t n);
void dr_exact_sum_destroy(struct dr_exact_sum *e);
/* Every entry back to zero (and no longer bad): as created, in the memory
 * it has (estimator.h's dr_est_scratch). */
void dr_exact_sum_clear(struct dr_exact_sum *e);
/* Bytes held for n entries. */
uint64_t dr_exact_sum_bytes(int64_t n);
/* Entries [0, n) as doubles (correctly rounded) into out; an entry with a
 * contribution out of range or not finite, or a sum within a factor 2 of
 * the range's end, becomes NaN. Returns how many did.
 * Call after every thread's last dr_exact_add (the threads joined). */
int64_t dr_exact_sum_read(const struct dr_exact_sum *e, double *out);
/* Entries [begin, end) as dr_exact_sum_read gives them, into out[0 ..
 * end - begin), each then zero again (and no longer bad): a sum read piece
 * by piece where it was added to, and left as created. */
int64_t dr_exact_sum_take(struct dr_exact_sum *e, int64_t begin, int64_t end, double *out);

/* Entry i += v, from any thread. */
static inline void dr_exact_add(struct dr_exact_sum *e, int64_t i, double v)
{
    double a = fabs(v);
    if (!(a < DR_EXACT_MAX_ADD)) {   /* also NaN */
        __atomic_store_n(&e->bad[i], 1, __ATOMIC_RELAXED);
        return;
    }
    /* a * 2^88 < 2^112 as hi * 2^64 + lo, both exact: hi is a's integer
     * part above 2^64, lo the rest, rounded to the nearest integer (lo below
     * 2^52 has a fraction, and lo + 0.5 is exact there; above, it is an
     * integer already) */
    double x = a * DR_EXACT_SCALE;
    double hd = floor(x * 0x1p-64);
    double ld = x - hd * 0x1p64;
    uint64_t lo = ld < 0x1p52 ? (uint64_t)(ld + 0.5) : (uint64_t)ld;
    uint64_t hi = (uint64_t)hd;
    if (v < 0) {   /* two's complement of (hi, lo) */
        lo = ~lo + 1;
        hi = ~hi + (lo == 0);
    }
    /* the carry of this addition into the low word: the total of the
     * carries is exact whatever the order (each fetch_add sees the word as
     * it is when it adds) */
    uint64_t old = __atomic_fetch_add(&e->w[i].lo, lo, __ATOMIC_RELAXED);
    uint64_t carry = old + lo < old;
    uint64_t add_hi = hi + carry;
    if (add_hi)
        __atomic_fetch_add(&e->w[i].hi, add_hi, __ATOMIC_RELAXED);
}

#endif
