/* The samplers' draws (sampler.h) for eight lanes at once, for the packet
 * renderer: each function names the scalar one it mirrors and runs its
 * operations, so a lane gets the scalar draw's bits (test_render compares
 * the packet renderer with the one-path walker with every sampler). */
#ifndef DR_SAMPLER8_H
#define DR_SAMPLER8_H

#include <stdint.h>
#if defined(__AVX__)
#include <immintrin.h>   /* dr_reverse_bits8's GFNI, dr_sobol_dim1_8's permutation */
#endif

#include "sampler.h"
#include "simd.h"

/* (double)k for k < 2^53, exactly, with integer operations only: x86 has
 * no vector conversion from 64-bit integers before AVX-512DQ (GCC converts
 * lane by lane). Each 32-bit half becomes a double by placing it in the
 * mantissa of 2^52 (2^84 for the high half) and subtracting that; both
 * halves and their sum are exact below 2^53. */
DR_SIMD_INLINE dr_f8 dr_u53_to_f8(dr_u8 k)
{
#ifdef __AVX512DQ__
    return __builtin_convertvector((dr_m8)k, dr_f8);   /* one instruction there */
#else
    dr_f8 lo = (dr_f8)((k & 0xffffffffULL) | 0x4330000000000000ULL) - 0x1p52;
    dr_f8 hi = (dr_f8)((k >> 32) | 0x4530000000000000ULL) - 0x1p84;
    return hi + lo;
#endif
}

/* dr_hash64 */
DR_SIMD_INLINE dr_u8 dr_hash64x8(dr_u8 x)
{
    DR_HASH64_STEPS(x);
    return x;
}

/* dr_sampler_independent */
DR_SIMD_INLINE dr_f8 dr_independent8(dr_u8 key, dr_u8 dim)
{
    return dr_u53_to_f8(dr_hash64x8(key + dim * 0xd1b54a32d192ed03ULL) >> 11) * (1.0 / 9007199254740992.0);
}

/* ---- dr_sampler_sobol2 (sampler.h) on eight lanes' 32-bit numbers */

typedef uint32_t dr_u32x8 __attribute__((vector_size(8 * sizeof(uint32_t))));

/* dr_reverse_bits32: with GFNI, as there, an affine transform reversing
 * each byte's bits and a shuffle reversing each number's bytes. */
DR_SIMD_INLINE dr_u32x8 dr_reverse_bits8(dr_u32x8 x)
{
#if defined(__GFNI__) && defined(__AVX2__)
    const __m256i byte_reversal = _mm256_set1_epi64x(0x8040201008040201LL);
    const __m256i byte_swap = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6,
                                               5, 4, 11, 10, 9, 8, 15, 14, 13, 12);
    return (dr_u32x8)_mm256_shuffle_epi8(_mm256_gf2p8affine_epi64_epi8((__m256i)x, byte_reversal, 0), byte_swap);
#else
    DR_REVERSE_BITS_STEPS(x);
    return x;
#endif
}

/* dr_laine_karras */
DR_SIMD_INLINE dr_u32x8 dr_laine_karras8(dr_u32x8 x, dr_u32x8 seed)
{
    DR_LAINE_KARRAS_STEPS(x, seed);
    return x;
}

/* Dimension 1 of index vector i into x (zero on entry), from the generator
 * matrix's columns v_b for the set bits: where no permutation looks the
 * table up (a table lookup per lane costs more than the 32 steps). */
#define DR_SOBOL_DIM1_COLUMNS(x, i)                                \
    do {                                                           \
        uint32_t v_ = 0x80000000u;                                 \
        for (int b_ = 0; b_ < 32; b_++, (i) >>= 1, v_ ^= v_ >> 1)  \
            (x) ^= (0u - ((i) & 1u)) & v_;                         \
    } while (0)

/* dr_sobol_dim1. With AVX-512 its table's sixteen entries for a group of
 * four bits fit two registers, and one two-register permutation looks all
 * eight lanes up; elsewhere DR_SOBOL_DIM1_COLUMNS. */
DR_SIMD_INLINE dr_u32x8 dr_sobol_dim1_8(dr_u32x8 i)
{
    dr_u32x8 x = {0};
#if defined(__AVX512F__) && defined(__AVX512VL__)
    for (int n = 0; n < 8; n++, i >>= 4) {
        const uint32_t *t = dr_sobol_dim1_nibble[n];
        x ^= (dr_u32x8)_mm256_permutex2var_epi32(_mm256_loadu_si256((const __m256i *)t), (__m256i)(i & 15u),
                                              _mm256_loadu_si256((const __m256i *)(t + 8)));
    }
#else
    DR_SOBOL_DIM1_COLUMNS(x, i);
#endif
    return x;
}

/* dr_sobol_to_double */
DR_SIMD_INLINE dr_f8 dr_sobol_to_f8(dr_u32x8 x, dr_u8 h)
{
    dr_u8 k = (__builtin_convertvector(x, dr_u8) << 21) | (h >> 43);
    return dr_u53_to_f8(k) * (1.0 / 9007199254740992.0);
}

/* dr_sobol2_hashed for lanes whose dimension has the hashes h, h1, h2
 * (dr_sobol_hashes; h2 unread where u2 is NULL), their sample index given
 * as rindex = dr_reverse_bits8(index) (the same for all of a sample's
 * draws). dr_owen_scramble is reverse, Laine-Karras, reverse: the reversals
 * that meet cancel, for the same bits. */
DR_SIMD_INLINE void dr_sobol2_hashed8(dr_u8 h, dr_u8 h1, dr_u8 h2, dr_u32x8 rindex, dr_f8 *u1, dr_f8 *u2)
{
    dr_u32x8 i = dr_reverse_bits8(dr_laine_karras8(rindex, __builtin_convertvector(h, dr_u32x8)));
    *u1 = dr_sobol_to_f8(dr_reverse_bits8(dr_laine_karras8(i, __builtin_convertvector(h1 >> 32, dr_u32x8))), h1);
    if (u2) {
        dr_u32x8 s2 = __builtin_convertvector(h2 >> 32, dr_u32x8);
        *u2 = dr_sobol_to_f8(dr_reverse_bits8(dr_laine_karras8(dr_reverse_bits8(dr_sobol_dim1_8(i)), s2)), h2);
    }
}

/* ---- a path vertex's five Sobol draws, two dimensions to a register ----
 * A vertex draws five dimensions (vertex_randoms, path_simd.c). Their
 * 32-bit arithmetic on eight lanes (Laine-Karras chains, bit reversals,
 * dimension 1's table) filled half a register, and as a chain of dependent
 * multiplies each draw waited on its own: the draws took 10 % of a
 * render. With two dimensions joined in sixteen lanes the same operations
 * run about half as often, lane for lane the same bits. */

typedef uint32_t dr_u32x16 __attribute__((vector_size(16 * sizeof(uint32_t))));

DR_SIMD_INLINE dr_u32x16 dr_join16(dr_u32x8 a, dr_u32x8 b)
{
    return __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
}
DR_SIMD_INLINE dr_u32x8 dr_low8(dr_u32x16 x)
{
    return __builtin_shufflevector(x, x, 0, 1, 2, 3, 4, 5, 6, 7);
}
DR_SIMD_INLINE dr_u32x8 dr_high8(dr_u32x16 x)
{
    return __builtin_shufflevector(x, x, 8, 9, 10, 11, 12, 13, 14, 15);
}

/* dr_reverse_bits8 on sixteen lanes: one register's worth with AVX-512,
 * else the eight-lane form on each half (GFNI's, where there is GFNI) */
DR_SIMD_INLINE dr_u32x16 dr_reverse_bits16(dr_u32x16 x)
{
#if defined(__GFNI__) && defined(__AVX512BW__)
    const __m512i byte_reversal = _mm512_set1_epi64(0x8040201008040201LL);
    const __m512i byte_swap = _mm512_broadcast_i32x4(_mm_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12));
    return (dr_u32x16)_mm512_shuffle_epi8(_mm512_gf2p8affine_epi64_epi8((__m512i)x, byte_reversal, 0), byte_swap);
#else
    return dr_join16(dr_reverse_bits8(dr_low8(x)), dr_reverse_bits8(dr_high8(x)));
#endif
}

DR_SIMD_INLINE dr_u32x16 dr_laine_karras16(dr_u32x16 x, dr_u32x16 seed)
{
    DR_LAINE_KARRAS_STEPS(x, seed);
    return x;
}

/* dr_sobol_dim1_8 on sixteen lanes: with AVX-512 a four-bit group's
 * sixteen entries are one register, looked up by one permutation. */
DR_SIMD_INLINE dr_u32x16 dr_sobol_dim1_16(dr_u32x16 i)
{
    dr_u32x16 x = {0};
#if defined(__AVX512F__)
    for (int n = 0; n < 8; n++, i >>= 4)
        x ^= (dr_u32x16)_mm512_permutexvar_epi32((__m512i)(i & 15u), _mm512_loadu_si512(dr_sobol_dim1_nibble[n]));
#else
    DR_SOBOL_DIM1_COLUMNS(x, i);
#endif
    return x;
}

/* dr_sampler_sobol2's draws for lanes with scrambling seeds pkey, sample
 * indices given as rindex = dr_reverse_bits8(index), of dimensions d+1
 * (one number), d+2 (a pair), d+4 (one), d+5 (a pair) and d+7 (one) into
 * u[0 .. 7), in that order (a vertex's dr_sampler_next and next2 from
 * dimension d): the same hashes (dr_sobol_hashes_of), and
 * dr_sobol2_hashed8's operations with the dimensions taken two at a time
 * (d+1 with d+2, d+4 with d+5, the pairs' second numbers together). */
/* The twelve hashes of dr_sobol_vertex8's dimensions (dr_sobol_hashes_of
 * of dr_sampler_dim_hash(pkey, d + offset)). They depend on the pixel and
 * the dimension alone, and a group's lanes are mostly one pixel's samples
 * at one depth (a pixel's samples start side by side and stay in order):
 * then they are worked out once, in scalar registers, and broadcast, the
 * same bits (76 % of groups at 64 spp, 39 % at 16: the draws 6.6 -> 5.7 %
 * of the peer box's render). */
DR_SIMD_INLINE void dr_sobol_vertex_hashes8(dr_u8 pkey, dr_u8 d, dr_u8 h[5], dr_u8 h1[5], dr_u8 *h2a, dr_u8 *h2b)
{
    static const int offset[5] = {1, 2, 4, 5, 7};
    const dr_u8 zero = {0}, differ = (pkey ^ pkey[0]) | (d ^ d[0]);
    uint64_t any = 0;   /* (an OR of the lanes, not a vector comparison: cli_simd_lowering.sh) */
    for (int i = 0; i < DR_SIMD_W; i++)
        any |= differ[i];
    if (!any) {
        for (int k = 0; k < 5; k++) {
            const uint64_t hk = dr_hash64(pkey[0] + (d[0] + (uint64_t)offset[k]) * 0xd1b54a32d192ed03ULL);
            h[k] = zero + hk;
            h1[k] = zero + dr_hash64(hk ^ 0x1111111111111111ULL);
        }
        *h2a = zero + dr_hash64(h[1][0] ^ 0x2222222222222222ULL);
        *h2b = zero + dr_hash64(h[3][0] ^ 0x2222222222222222ULL);
        return;
    }
    for (int k = 0; k < 5; k++) {
        h[k] = dr_hash64x8(pkey + (d + (uint64_t)offset[k]) * 0xd1b54a32d192ed03ULL);
        h1[k] = dr_hash64x8(h[k] ^ 0x1111111111111111ULL);
    }
    *h2a = dr_hash64x8(h[1] ^ 0x2222222222222222ULL);
    *h2b = dr_hash64x8(h[3] ^ 0x2222222222222222ULL);
}

DR_SIMD_INLINE void dr_sobol_vertex8(dr_u8 pkey, dr_u32x8 rindex, dr_u8 d, dr_f8 u[7])
{
    dr_u8 h[5], h1[5], h2a, h2b;
    dr_sobol_vertex_hashes8(pkey, d, h, h1, &h2a, &h2b);
#define LOW32(v) __builtin_convertvector(v, dr_u32x8)
#define HIGH32(v) __builtin_convertvector((v) >> 32, dr_u32x8)
    /* the shuffled indices (dr_owen_scramble of the index, reversals met) */
    const dr_u32x16 r2 = dr_join16(rindex, rindex);
    const dr_u32x16 ia = dr_reverse_bits16(dr_laine_karras16(r2, dr_join16(LOW32(h[0]), LOW32(h[1]))));
    const dr_u32x16 ib = dr_reverse_bits16(dr_laine_karras16(r2, dr_join16(LOW32(h[2]), LOW32(h[3]))));
    const dr_u32x8 ic = dr_reverse_bits8(dr_laine_karras8(rindex, LOW32(h[4])));
    /* the first numbers: dimension 0 Owen-scrambled */
    const dr_u32x16 xa = dr_reverse_bits16(dr_laine_karras16(ia, dr_join16(HIGH32(h1[0]), HIGH32(h1[1]))));
    const dr_u32x16 xb = dr_reverse_bits16(dr_laine_karras16(ib, dr_join16(HIGH32(h1[2]), HIGH32(h1[3]))));
    u[0] = dr_sobol_to_f8(dr_low8(xa), h1[0]);
    u[1] = dr_sobol_to_f8(dr_high8(xa), h1[1]);
    u[3] = dr_sobol_to_f8(dr_low8(xb), h1[2]);
    u[4] = dr_sobol_to_f8(dr_high8(xb), h1[3]);
    u[6] = dr_sobol_to_f8(dr_reverse_bits8(dr_laine_karras8(ic, HIGH32(h1[4]))), h1[4]);
    /* the pairs' second numbers: dimension 1 Owen-scrambled */
    const dr_u32x16 y = dr_reverse_bits16(dr_laine_karras16(
        dr_reverse_bits16(dr_sobol_dim1_16(dr_join16(dr_high8(ia), dr_high8(ib)))), dr_join16(HIGH32(h2a), HIGH32(h2b))));
    u[2] = dr_sobol_to_f8(dr_low8(y), h2a);
    u[5] = dr_sobol_to_f8(dr_high8(y), h2b);
#undef LOW32
#undef HIGH32
}

/* dr_sampler_pixel_sample and dr_sampler_pixel_first2 for eight samples at
 * once: sample[l] of pixel p[l] (all of one kind). Their samplers into
 * s[0..7] and their first draws (the camera's) into *u1 and *u2; stratified
 * draws lane by lane through the scalar function. */
static inline void dr_sampler_pixel_first2_8(const struct dr_sampler_pixel *const p[8], const uint64_t sample[8],
                                             struct dr_sampler s[8], dr_f8 *u1, dr_f8 *u2)
{
#define PKEY(l) p[l]->pixel_key
#define SAMPLE(l) sample[l]
#define H(l) p[l]->first.h
#define H1(l) p[l]->first.h1
#define H2(l) p[l]->first.h2
    const dr_u8 pixel_key = DR_LANES8(dr_u8, PKEY), smp = DR_LANES8(dr_u8, SAMPLE), h = DR_LANES8(dr_u8, H),
                h1 = DR_LANES8(dr_u8, H1), h2 = DR_LANES8(dr_u8, H2);
#undef PKEY
#undef SAMPLE
#undef H
#undef H1
#undef H2
    const dr_u8 key = dr_hash64x8(pixel_key ^ (smp * 0x9e3779b97f4a7c15ULL));
    const uint32_t kind = p[0]->shared.kind;
    for (int l = 0; l < 8; l++) {
        s[l] = p[l]->shared;
        s[l].key = key[l];
        if (kind != DR_SAMPLER_INDEPENDENT)
            s[l].index = (uint32_t)sample[l];
    }
    if (kind == DR_SAMPLER_STRATIFIED) {
        for (int l = 0; l < 8; l++) {   /* (clang takes no address of a vector's element) */
            double a, b;
            dr_sampler_pixel_first2(p[l], &s[l], &a, &b);
            (*u1)[l] = a;
            (*u2)[l] = b;
        }
        return;
    }
    if (kind == DR_SAMPLER_SOBOL)
        dr_sobol2_hashed8(h, h1, h2, dr_reverse_bits8(__builtin_convertvector(smp, dr_u32x8)), u1, u2);
    else
        *u1 = dr_independent8(key, (dr_u8){1, 1, 1, 1, 1, 1, 1, 1}), *u2 = dr_independent8(key, (dr_u8){2, 2, 2, 2, 2, 2, 2, 2});
    for (int l = 0; l < 8; l++)
        s[l].dim = 2;
}

#endif
