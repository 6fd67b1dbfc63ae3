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

/* Block masks: one bit per block of DR_ZERO_BLOCK entries of a vector,
 * bit (i / 8) % 64 of word i / 512 for entry i. A clear bit says the block
 * is all +0; a set bit, that it may not be. A pass that follows such a mask
 * reads and writes only the set blocks: with a preview's texture gradient,
 * a few per cent of the vector, where dr_block_zero still reads all of it.
 * Who keeps a mask true is each mask's owner's to say. */
#define DR_MASK_SPAN (64 * DR_ZERO_BLOCK)   /* entries a word covers */

static inline int64_t dr_mask_words(int64_t n)
{
    return (n + DR_MASK_SPAN - 1) / DR_MASK_SPAN;
}

/* Marks the block holding entry i. */
static inline __attribute__((always_inline)) void dr_mask_mark(uint64_t *mask, int64_t i)
{
    mask[i / DR_MASK_SPAN] |= UINT64_C(1) << (i / DR_ZERO_BLOCK % 64);
}

/* Whether the block holding entry i is marked. */
static inline __attribute__((always_inline)) bool dr_mask_test(const uint64_t *mask, int64_t i)
{
    return mask[i / DR_MASK_SPAN] >> (i / DR_ZERO_BLOCK % 64) & 1;
}

/* The first entry at or after i, below end, of a block marked in mask or
 * in also (which may be NULL); end if there is none. Words of neither are
 * skipped 512 entries at a time. */
static inline int64_t dr_mask_next(const uint64_t *mask, const uint64_t *also, int64_t i, int64_t end)
{
    if (i >= end)
        return end;
    int64_t w = i / DR_MASK_SPAN;
    uint64_t bits = (mask[w] | (also ? also[w] : 0)) & (~UINT64_C(0) << (i / DR_ZERO_BLOCK % 64));
    while (!bits) {
        if (++w * DR_MASK_SPAN >= end)
            return end;
        bits = mask[w] | (also ? also[w] : 0);
    }
    const int64_t first = w * DR_MASK_SPAN + __builtin_ctzll(bits) * DR_ZERO_BLOCK;
    return first < i ? i : (first < end ? first : end);
}

/* The first entry at or after i, at most end, of a block marked in neither
 * mask nor also (NULL: none): with dr_mask_next, the end of a run of
 * marked blocks, which a pass can then take as one span (vectorised). */
static inline int64_t dr_mask_run_end(const uint64_t *mask, const uint64_t *also, int64_t i, int64_t end)
{
    if (i >= end)
        return end;
    int64_t w = i / DR_MASK_SPAN;
    uint64_t bits = ~(mask[w] | (also ? also[w] : 0)) & (~UINT64_C(0) << (i / DR_ZERO_BLOCK % 64));
    while (!bits) {
        if (++w * DR_MASK_SPAN >= end)
            return end;
        bits = ~(mask[w] | (also ? also[w] : 0));
    }
    const int64_t first = w * DR_MASK_SPAN + __builtin_ctzll(bits) * DR_ZERO_BLOCK;
    return first < end ? first : end;
}

/* The end of the block holding entry i, at most end. */
static inline int64_t dr_block_end(int64_t i, int64_t end)
{
    const int64_t e = (i / DR_ZERO_BLOCK + 1) * DR_ZERO_BLOCK;
    return e < end ? e : end;
}

#endif
