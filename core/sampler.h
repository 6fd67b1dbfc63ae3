/* Random numbers as a pure function of (seed, pixel, sample, dimension), so a
 * path can be replayed bit for bit, finite differences share random numbers,
 * and an image does not depend on the thread count or tile order. */
#ifndef DR_SAMPLER_H
#define DR_SAMPLER_H

#include <stddef.h>
#include <stdint.h>

#include "stratified.h"

#if defined(__GFNI__) && defined(__SSE2__)
#include <immintrin.h>   /* dr_reverse_bits32 */
#endif

/* SplitMix64's finaliser, a strong 64-bit mix, on x: a uint64_t or a vector
 * of them (sampler8.h's dr_hash64x8 runs the same text). */
#define DR_HASH64_STEPS(x)            \
    do {                              \
        x ^= x >> 30;                 \
        x *= 0xbf58476d1ce4e5b9ULL;   \
        x ^= x >> 27;                 \
        x *= 0x94d049bb133111ebULL;   \
        x ^= x >> 31;                 \
    } while (0)
static inline uint64_t dr_hash64(uint64_t x)
{
    DR_HASH64_STEPS(x);
    return x;
}

/* Which numbers a sampler draws. All are pure functions of
 * (seed, pixel, sample, dimension) and, for stratified, the pixel's sample
 * count (spp of the run, or of the batch half that draws them).
 *  independent  every number is an independent hash;
 *  stratified   jittered stratification of every draw over the pixel's spp
 *               samples (stratified.h): 1D draws in spp strata, 2D draws
 *               correlated multi-jittered on an m x n grid (spp = m x n
 *               where spp factors so, padded otherwise), with the
 *               sample-to-stratum map permuted per dimension by a hash, so
 *               dimensions are decorrelated. Any spp works (not only squares
 *               or powers of two); independent seeds give independent sets;
 *  sobol        Owen-scrambled Sobol points (hash-based nested uniform
 *               scrambling and index shuffling, Burley 2020 "Practical
 *               Hash-based Owen Scrambling"): over a pixel's samples each
 *               1D draw is stratified, and each 2D draw (dr_sampler_next2:
 *               camera offset, light point, BSDF direction) is a (0,2)
 *               sequence, stratified in every elementary interval at powers of
 *               two; different dimensions are decorrelated by their own
 *               scrambling seeds. Independent seeds (batches) give
 *               independent randomised point sets, so batch statistics stay
 *               valid standard errors. */
enum dr_sampler_kind { DR_SAMPLER_INDEPENDENT = 0, DR_SAMPLER_SOBOL = 1, DR_SAMPLER_STRATIFIED = 2 };

struct dr_sampler {
    uint64_t key;     /* hash of (seed, pixel, sample) */
    uint32_t dim;     /* next dimension */
    uint32_t kind;    /* enum dr_sampler_kind */
    uint64_t pkey;    /* sobol, stratified: hash of (seed, pixel), the scrambling/permutation seed */
    uint32_t index;   /* sobol, stratified: the sample's index in the pixel */
    uint32_t count;   /* stratified: the pixel's sample count (the strata) */
    uint32_t grid_m, grid_n;   /* stratified: the 2D draws' grid (stratified.h) */
};

/* Dimension dim's hash of a pixel's scrambling seed pkey: the Sobol pair's
 * scrambling seed, the stratified draw's permutation seed. */
static inline uint64_t dr_sampler_dim_hash(uint64_t pkey, uint32_t dim)
{
    return dr_hash64(pkey + (uint64_t)dim * 0xd1b54a32d192ed03ULL);
}

/* A Sobol dimension's hashes: h (dr_sampler_dim_hash) scrambles the index,
 * h1 and h2 the pair's two numbers. */
struct dr_sobol_hashes {
    uint64_t h, h1, h2;
};
static inline struct dr_sobol_hashes dr_sobol_hashes_of(uint64_t h)
{
    struct dr_sobol_hashes d = {h, dr_hash64(h ^ 0x1111111111111111ULL), dr_hash64(h ^ 0x2222222222222222ULL)};
    return d;
}

/* What the samples of one pixel share: the hash of (seed, pixel) their keys
 * start from, the scrambling seed and the strata (in `shared`, whose key,
 * index and dim each sample sets), and the hashes of the first draw's
 * dimension (dr_sampler_pixel_first2). A pixel's spp samples made through
 * it (dr_sampler_pixel_sample) are dr_sampler_init_kind's, with seven of a
 * Sobol sample's eight hashes up to its first draw, and two of an
 * independent sample's five, computed once per pixel. */
struct dr_sampler_pixel {
    struct dr_sampler shared;
    uint64_t pixel_key;                 /* dr_hash64(dr_hash64(seed + phi) ^ pixel) */
    struct dr_sobol_hashes first;       /* dimension 1's (sobol; stratified: first.h, its
                                           dr_sampler_dim_hash, alone) */
};

/* The pixel's share of dr_sampler_init_kind (spp: the pixel's sample count,
 * as there) but the first draw's hashes. */
static inline void dr_sampler_pixel_shared(struct dr_sampler_pixel *p, enum dr_sampler_kind kind, uint64_t seed,
                                           uint64_t pixel, int spp)
{
    struct dr_sampler *s = &p->shared;
    s->key = 0, s->dim = 0, s->kind = DR_SAMPLER_INDEPENDENT, s->pkey = 0, s->index = 0, s->count = 0;
    s->grid_m = s->grid_n = 0;
    p->pixel_key = dr_hash64(dr_hash64(seed + 0x9e3779b97f4a7c15ULL) ^ pixel);
    if (kind == DR_SAMPLER_SOBOL) {
        s->kind = DR_SAMPLER_SOBOL;
        s->pkey = dr_hash64(dr_hash64(seed ^ 0x5b0b5b0b5b0b5b0bULL) ^ (pixel * 0xd6e8feb86659fd93ULL));
    } else if (kind == DR_SAMPLER_STRATIFIED) {
        s->kind = DR_SAMPLER_STRATIFIED;
        s->pkey = dr_hash64(dr_hash64(seed ^ 0x57a7157a7157a715ULL) ^ (pixel * 0xd6e8feb86659fd93ULL));
        s->count = spp > 0 ? (uint32_t)spp : 1u;
        dr_strat_grid(s->count, &s->grid_m, &s->grid_n);
    }
}

/* All of the pixel's share, for its samples' dr_sampler_pixel_first2. */
static inline void dr_sampler_pixel_init(struct dr_sampler_pixel *p, enum dr_sampler_kind kind, uint64_t seed,
                                         uint64_t pixel, int spp)
{
    dr_sampler_pixel_shared(p, kind, seed, pixel, spp);
    const uint64_t h = dr_sampler_dim_hash(p->shared.pkey, 1);
    if (kind == DR_SAMPLER_SOBOL)
        p->first = dr_sobol_hashes_of(h);
    else
        p->first.h = h, p->first.h1 = p->first.h2 = 0;
}

/* Sample `sample` of the pixel (sample < spp). */
static inline void dr_sampler_pixel_sample(const struct dr_sampler_pixel *p, uint64_t sample, struct dr_sampler *s)
{
    *s = p->shared;
    s->key = dr_hash64(p->pixel_key ^ (sample * 0x9e3779b97f4a7c15ULL));
    if (s->kind != DR_SAMPLER_INDEPENDENT)
        s->index = (uint32_t)sample;
}

/* A sampler of the independent kind: sample `sample` of `pixel`. */
static inline void dr_sampler_init(struct dr_sampler *s, uint64_t seed, uint64_t pixel, uint64_t sample)
{
    struct dr_sampler_pixel p;
    dr_sampler_pixel_shared(&p, DR_SAMPLER_INDEPENDENT, seed, pixel, 0);
    dr_sampler_pixel_sample(&p, sample, s);
}

/* Sample `sample` of the `spp` samples of `pixel`. spp only matters to the
 * stratified kind (its strata); it must be the number of samples drawn with
 * this seed for this pixel, sample < spp. */
static inline void dr_sampler_init_kind(struct dr_sampler *s, enum dr_sampler_kind kind, uint64_t seed,
                                        uint64_t pixel, uint64_t sample, int spp)
{
    struct dr_sampler_pixel p;
    dr_sampler_pixel_shared(&p, kind, seed, pixel, spp);
    dr_sampler_pixel_sample(&p, sample, s);
}

/* ---- Owen-scrambled Sobol (the two dimensions of a (0,2) sequence) ---- */

/* The steps of the bit reversal and of the Laine-Karras permutation below,
 * on x: a uint32_t, or a vector of them (sampler8.h's eight-lane forms run
 * the same text). */
#define DR_REVERSE_BITS_STEPS(x)                                        \
    do {                                                                \
        x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);        \
        x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);        \
        x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);        \
        x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);        \
        x = (x >> 16) | (x << 16);                                      \
    } while (0)
#define DR_LAINE_KARRAS_STEPS(x, seed) \
    do {                               \
        x += seed;                     \
        x ^= x * 0x6c50b47cu;          \
        x ^= x * 0xb82f1e52u;          \
        x ^= x * 0xc7afe638u;          \
        x ^= x * 0x8d22f6e6u;          \
    } while (0)

/* Reverses a 32-bit number's bits. With GFNI one affine transform over
 * GF(2) reverses each byte's bits (the matrix 0x8040201008040201) and a byte
 * swap does the rest: four instructions for the twenty of the shifts. */
static inline uint32_t dr_reverse_bits32(uint32_t x)
{
#if defined(__GFNI__) && defined(__SSE2__)
    const __m128i byte_reversal = _mm_set1_epi64x(0x8040201008040201LL);
    return __builtin_bswap32((uint32_t)_mm_cvtsi128_si32(_mm_gf2p8affine_epi64_epi8(_mm_cvtsi32_si128((int)x), byte_reversal, 0)));
#else
    DR_REVERSE_BITS_STEPS(x);
    return x;
#endif
}

/* The Laine-Karras permutation with Burley's constants: a hash in which a
 * bit affects only the bits above it. */
static inline uint32_t dr_laine_karras(uint32_t x, uint32_t seed)
{
    DR_LAINE_KARRAS_STEPS(x, seed);
    return x;
}

/* Nested uniform (Owen) scrambling of a 32-bit fixed-point number: the
 * Laine-Karras permutation applied to the reversed bits, so that higher bits
 * affect only lower ones. */
static inline uint32_t dr_owen_scramble(uint32_t x, uint32_t seed)
{
    return dr_reverse_bits32(dr_laine_karras(dr_reverse_bits32(x), seed));
}

/* Sobol dimension 1's generator matrix (Pascal's triangle mod 2), as the
 * direction numbers of Joe and Kuo's table; dimension 0 is bit reversal.
 * The map is linear over GF(2): the XOR of its columns for the index's set
 * bits, taken four bits at a time from the table (sampler.c; test_sampler
 * holds it to the columns v_0 = 2^31, v_(b+1) = v_b ^ (v_b >> 1)). A branch
 * per bit mispredicted half the time on the Owen-scrambled index: the
 * Sobol sampler's draws took a third of a render. */
extern const uint32_t dr_sobol_dim1_nibble[8][16];
static inline uint32_t dr_sobol_dim1(uint32_t i)
{
    uint32_t x = 0;
    for (int n = 0; n < 8; n++, i >>= 4)
        x ^= dr_sobol_dim1_nibble[n][i & 15u];
    return x;
}

/* 53-bit double from a 32-bit point; the low 21 bits are random within the
 * point's cell, so no two samples coincide and 0 is never returned exactly. */
static inline double dr_sobol_to_double(uint32_t x, uint64_t h)
{
    return (double)(((uint64_t)x << 21) | (h >> 43)) * (1.0 / 9007199254740992.0);
}

/* The Sobol pair of the dimension with hashes d for the sample with index
 * `index`; u2 NULL: the first number only. */
static inline void dr_sobol2_hashed(const struct dr_sobol_hashes *d, uint32_t index, double *u1, double *u2)
{
    uint32_t i = dr_owen_scramble(index, (uint32_t)d->h);   /* Burley's shuffled index */
    /* dimension 0, dr_owen_scramble(dr_reverse_bits32(i)): its two inner reversals cancel */
    *u1 = dr_sobol_to_double(dr_reverse_bits32(dr_laine_karras(i, (uint32_t)(d->h1 >> 32))), d->h1);
    if (u2)
        *u2 = dr_sobol_to_double(dr_owen_scramble(dr_sobol_dim1(i), (uint32_t)(d->h2 >> 32)), d->h2);
}

/* The Sobol pair of dimension `dim` (its seed) for this sampler's sample. */
static inline void dr_sampler_sobol2(const struct dr_sampler *s, uint32_t dim, double *u1, double *u2)
{
    const struct dr_sobol_hashes d = dr_sobol_hashes_of(dr_sampler_dim_hash(s->pkey, dim));
    dr_sobol2_hashed(&d, s->index, u1, u2);
}

/* ---- stratified (stratified.h) ---- */

/* Dimension `dim`'s permutation seed (shared by the pixel's samples) and the
 * sample's own jitter hash for it. */
static inline uint64_t dr_sampler_strat_seed(const struct dr_sampler *s, uint32_t dim)
{
    return dr_sampler_dim_hash(s->pkey, dim);
}

static inline uint64_t dr_sampler_strat_jitter(const struct dr_sampler *s, uint32_t dim, uint64_t salt)
{
    return dr_hash64((s->key ^ salt) + (uint64_t)dim * 0xd1b54a32d192ed03ULL);
}

/* A uniform number in [0, 1) from a hash's top 53 bits. */
static inline double dr_hash_unit(uint64_t h)
{
    return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

/* The independent sampler's draw of dimension dim: 53 random bits. */
static inline double dr_sampler_independent(const struct dr_sampler *s, uint32_t dim)
{
    return dr_hash_unit(dr_hash64(s->key + (uint64_t)dim * 0xd1b54a32d192ed03ULL));
}

/* The Sobol and stratified draws (sampler.c): out of line, so the
 * independent sampler's few instructions inline into every caller (a path
 * vertex draws seven numbers; through the general function they cost a
 * quarter of its shading). */
double dr_sampler_next_structured(struct dr_sampler *s);
void dr_sampler_next2_structured(struct dr_sampler *s, double *u1, double *u2);
/* dr_sampler_next2 on sample s of pixel p as dr_sampler_pixel_sample made
 * it (its first draw, dimensions 1 and 2: the camera's film offset), with
 * the pixel's hash of the dimension. */
void dr_sampler_pixel_first2(const struct dr_sampler_pixel *p, struct dr_sampler *s, double *u1, double *u2);

/* Uniform double in [0, 1) with 53 random bits. */
static inline double dr_sampler_next(struct dr_sampler *s)
{
    if (__builtin_expect(s->kind == DR_SAMPLER_INDEPENDENT, 1))
        return dr_sampler_independent(s, ++s->dim);
    return dr_sampler_next_structured(s);
}

/* Two numbers that belong together (a 2D sample): two independent draws, one
 * Sobol pair, or one multi-jittered point. Uses two dimensions either way, so
 * the layout of a path's dimensions does not depend on the sampler. */
static inline void dr_sampler_next2(struct dr_sampler *s, double *u1, double *u2)
{
    if (__builtin_expect(s->kind == DR_SAMPLER_INDEPENDENT, 1)) {
        *u1 = dr_sampler_independent(s, ++s->dim);
        *u2 = dr_sampler_independent(s, ++s->dim);
        return;
    }
    dr_sampler_next2_structured(s, u1, u2);
}

const char *dr_sampler_kind_name(enum dr_sampler_kind k);
int dr_sampler_kind_parse(const char *name);   /* -1 if unknown */

#endif
