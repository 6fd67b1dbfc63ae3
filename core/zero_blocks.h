/* Skipping the zeros of big, sparse vectors.
 *
 * A texture parameter's gradient at a preview resolution is mostly zeros:
 * a 2k texture seen in a 64 x 64 render at 8 spp has 0.8 % of its 12.6 M
 * entries non-zero. The element-wise passes over such vectors (the
 * threads' sums, the batches' Welford fold, Adam's step) then spend their
 * time writing back the zeros they found and dividing them. These helpers
 * look at eight entries at a time, one cache line: a block whose words are
 * all +0 (as bits: -0 does not count) is left alone, and a line a pass only
 * reads is never written back. Whether skipping a block changes nothing is
 * each caller's to show (the +0 results of its operations on +0 inputs). */
#ifndef DR_ZERO_BLOCKS_H
#define DR_ZERO_BLOCKS_H

#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#define DR_ZERO_BLOCK 8

/* Are v[0..8) all +0. */
static inline __attribute__((always_inline)) bool dr_block_zero(const double *v)
{
    uint64_t w[DR_ZERO_BLOCK];
    memcpy(w, v, sizeof w);
    return !(w[0] | w[1] | w[2] | w[3] | w[4] | w[5] | w[6] | w[7]);
}

/* v[0..n) to +0, writing only the blocks that are not all +0 already. */
static inline __attribute__((always_inline)) void dr_clear_touched(double *v, int64_t n)
{
    int64_t k = 0;
    for (; k + DR_ZERO_BLOCK <= n; k += DR_ZERO_BLOCK)
        if (!dr_block_zero(v + k))
            memset(v + k, 0, DR_ZERO_BLOCK * sizeof *v);
    for (; k < n; k++)
        v[k] = 0.0;
}

#endif
