/* Jittered stratification of a pixel's samples, one dimension at a time, as
 * pure functions of (sample index, sample count, a per-dimension seed): no
 * table is stored, so replay, the tape and finite differences recompute the
 * same numbers. Used by sampler.h's `stratified` kind.
 *
 * 1D: N samples, N strata; the sample-to-stratum map is a hashed permutation
 *     seeded per dimension, so two dimensions of one path are decorrelated
 *     (the same sample index does not land in the same stratum of both).
 * 2D: correlated multi-jittering (Kensler 2013, "Correlated Multi-Jittered
 *     Sampling"): an m x n grid of cells, each cell sub-divided so the points
 *     are also a Latin hypercube. The grid is N = m x n exactly when N has
 *     such factors with m <= 2n (every square, every power of two, 12, 24,
 *     48, ...): every cell holds one sample. Otherwise (primes, 14, ...) the
 *     grid is padded, m = ceil(sqrt N), n = ceil(N/m): each sample takes a cell
 *     of a random permutation of all m*n cells (not of the first N), so every
 *     sample is still uniform over the square (unbiased) and no two share a
 *     cell, but a few cells go empty (measured: the error at a padded 32 was
 *     above that at 16, hence exact grids wherever they exist).
 *
 * Over the random seeds (per seed, pixel and dimension) every sample is
 * uniform on [0,1) resp. [0,1)^2, so the pixel estimate stays unbiased and
 * batches with different seeds are independent stratified sets. */
#ifndef DR_STRATIFIED_H
#define DR_STRATIFIED_H

#include <math.h>
#include <stdint.h>

/* (i + p) mod l for i < l without a 64-bit division: t < r means the 32-bit
 * sum wrapped (l > 2^31), and t - l then wraps back. */
static inline uint32_t dr_strat_rotate(uint32_t i, uint32_t p, uint32_t l)
{
    uint32_t r = p % l, t = i + r;
    return t >= l || t < r ? t - l : t;
}

/* A pseudo-random permutation of [0, l) evaluated at i, seeded by p:
 * Kensler's hash (every step is a bijection on the bits under mask w) with
 * cycle-walking until the result falls inside [0, l). l must be >= 1. */
static inline uint32_t dr_strat_permute(uint32_t i, uint32_t l, uint32_t p)
{
    if (l <= 1)
        return 0;
    uint32_t w = l - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    do {
        i ^= p;
        i *= 0xe170893du;
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i *= 0x0929eb3fu;
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i *= 1u | p >> 27;
        i *= 0x6935fa69u;
        i ^= (i & w) >> 11;
        i *= 0x74dcb303u;
        i ^= (i & w) >> 2;
        i *= 0x9e501cc3u;
        i ^= (i & w) >> 2;
        i *= 0xc860a3dfu;
        i &= w;
        i ^= i >> 5;
    } while (i >= l);
    return dr_strat_rotate(i, p, l);
}

/* (k + jitter) / n as a number in [0, 1): rounding can reach 1.0 for the last
 * stratum, which callers (inverse CDFs) must never see. */
static inline double dr_strat_unit(double k, double jitter, double n)
{
    double u = (k + jitter) / n;
    return u < 1.0 ? u : 0x1.fffffffffffffp-1;
}

/* 53-bit jitter in [0, 1) from a hash. */
static inline double dr_strat_jitter(uint64_t h)
{
    return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

/* Sample `index` of `count` of a stratified 1D draw: its stratum is a
 * permutation (seed p) of the index, the jitter comes from hash h. */
static inline double dr_strat_1d(uint32_t index, uint32_t count, uint32_t p, uint64_t h)
{
    if (count <= 1)
        return dr_strat_jitter(h);
    return dr_strat_unit((double)dr_strat_permute(index, count, p), dr_strat_jitter(h), (double)count);
}

/* The grid of a 2D draw of `count` samples: m columns, n rows, m*n >= count
 * (see the top). O(sqrt count): computed once per sample (sampler.h). */
static inline void dr_strat_grid(uint32_t count, uint32_t *m, uint32_t *n)
{
    uint32_t c = count ? count : 1;
    uint32_t s = (uint32_t)ceil(sqrt((double)c));
    while (s > 1 && (uint64_t)(s - 1) * (s - 1) >= c)   /* guard sqrt's rounding */
        s--;
    while ((uint64_t)s * s < c)
        s++;
    /* s = ceil(sqrt c); an exact factor pair c = m * n with n <= sqrt c <= m <= 2n */
    for (uint32_t r = (uint64_t)s * s == c ? s : s - 1; r >= 1 && 2ull * r * r >= c; r--)
        if (c % r == 0) {
            *m = c / r;
            *n = r;
            return;
        }
    *m = s;
    *n = (c + s - 1) / s;
}

/* Sample `index` of a (padded) correlated multi-jittered 2D draw on the m x n
 * grid of dr_strat_grid; p seeds the cell permutation and the two sub-cell
 * permutations, h1 and h2 are the jitters. */
static inline void dr_strat_2d(uint32_t index, uint32_t m, uint32_t n, uint64_t p, uint64_t h1, uint64_t h2,
                               double *x, double *y)
{
    uint32_t cell = dr_strat_permute(index, m * n, (uint32_t)p);
    uint32_t c = cell % m, r = cell / m;
    /* the sub-cell offsets: column c's x sub-stratum follows its row's
     * permuted index and vice versa, which makes the set a Latin hypercube */
    uint32_t sx = dr_strat_permute(c, m, (uint32_t)(p >> 32));
    uint32_t sy = dr_strat_permute(r, n, (uint32_t)(p >> 32) * 0x9e3779b9u + 0x7f4a7c15u);
    *x = dr_strat_unit((double)c, dr_strat_unit((double)sy, dr_strat_jitter(h1), (double)n), (double)m);
    *y = dr_strat_unit((double)r, dr_strat_unit((double)sx, dr_strat_jitter(h2), (double)m), (double)n);
}

#endif
