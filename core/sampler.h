/* Random numbers as a pure function of (seed, pixel, sample, dimension), so a
 * path can be replayed bit for bit, finite differences share random numbers,
 * and an image does not depend on the thread count or tile order. */
#ifndef DR_SAMPLER_H
#define DR_SAMPLER_H

#include <stdint.h>

/* SplitMix64's finaliser: a strong 64-bit mix. */
static inline uint64_t dr_hash64(uint64_t x)
{
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ULL;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebULL;
    x ^= x >> 31;
    return x;
}

struct dr_sampler {
    uint64_t key;   /* hash of (seed, pixel, sample) */
    uint32_t dim;   /* next dimension */
};

static inline void dr_sampler_init(struct dr_sampler *s, uint64_t seed, uint64_t pixel, uint64_t sample)
{
    s->key = dr_hash64(dr_hash64(dr_hash64(seed + 0x9e3779b97f4a7c15ULL) ^ pixel) ^ (sample * 0x9e3779b97f4a7c15ULL));
    s->dim = 0;
}

/* Uniform double in [0, 1) with 53 random bits. */
static inline double dr_sampler_next(struct dr_sampler *s)
{
    uint64_t h = dr_hash64(s->key + (uint64_t)(++s->dim) * 0xd1b54a32d192ed03ULL);
    return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

#endif
