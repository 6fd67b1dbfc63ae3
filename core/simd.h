/* Eight doubles as one value, for shading the packet tracer's lanes together
 * (path_simd.c).
 *
 * GCC vector extensions: the compiler lowers them to what the target has (one
 * AVX-512 register here, two AVX or four SSE registers elsewhere), so this is
 * portable C with no intrinsics. +, -, *, / and sqrt round exactly as the
 * scalar operations do, and -std=c11 keeps GCC from contracting a * b + c
 * into an FMA; so a kernel written with the scalar code's operations in the
 * scalar code's order gives every lane the scalar code's bits. That is what
 * lets the packet renderer's images stay equal to the one-path walker's
 * (test_render).
 *
 * Comparisons give masks (all bits set where true); dr_f8_sel picks by mask.
 * Per-lane loads are best built as an initialiser list of the eight values
 * (path_simd.c's gathers), which compiles to inserts: a vector load right
 * after eight scalar stores would stall on store forwarding. */
#ifndef DR_SIMD_H
#define DR_SIMD_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <string.h>
#if defined(__AVX512F__)
#include <immintrin.h>   /* dr_compress8, dr_f8_sqrt */
#endif

#include "vec.h"

#define DR_SIMD_W 8

/* Every function on these types is inlined: where the target has no 8-double
 * registers, a call passes each vector through memory (GCC's inliner judged
 * dr_v3x8_sel, locate and eval_pdf_above too big on AVX2, and the copies
 * cost more than their work). */
#define DR_SIMD_INLINE static inline __attribute__((always_inline))

typedef double dr_f8 __attribute__((vector_size(8 * sizeof(double))));
typedef int64_t dr_m8 __attribute__((vector_size(8 * sizeof(int64_t))));
typedef uint64_t dr_u8 __attribute__((vector_size(8 * sizeof(uint64_t))));

DR_SIMD_INLINE dr_f8 dr_f8s(double s) { return (dr_f8){s, s, s, s, s, s, s, s}; }

/* Comparisons and selection. Write dr_f8_lt(a, b), never a < b, on these
 * types: where the target has no 8-double registers (AVX2, AVX), GCC turns
 * a comparison of 8-wide vectors, and a selection by its mask, into eight
 * scalar compares and branches (-Wvector-operation-performance says
 * "vector condition will be expanded piecewise"), which made the shading
 * kernel three times slower on an AVX2 machine. There the functions below
 * compare and select the two 4-wide halves, which AVX has instructions for;
 * with AVX-512 they are the plain operators. Exact either way. */
#if defined(__AVX512F__) || !defined(__AVX__)
#define DR_F8_CMP(name, op) \
    DR_SIMD_INLINE dr_m8 name(dr_f8 a, dr_f8 b) { return a op b; }
/* a where m is set, else b */
DR_SIMD_INLINE dr_f8 dr_f8_sel(dr_m8 m, dr_f8 a, dr_f8 b) { return (dr_f8)((m & (dr_m8)a) | (~m & (dr_m8)b)); }
#else
typedef double dr_f4 __attribute__((vector_size(4 * sizeof(double))));
typedef int64_t dr_m4 __attribute__((vector_size(4 * sizeof(int64_t))));
/* The halves through a union: GCC keeps these in registers, where joining
 * halves with __builtin_shufflevector went through the stack lane by lane. */
union dr_f8_halves { dr_f8 v; dr_f4 h[2]; };
union dr_m8_halves { dr_m8 v; dr_m4 h[2]; };
#define DR_F8_CMP(name, op) \
    DR_SIMD_INLINE dr_m8 name(dr_f8 a, dr_f8 b) \
    { \
        union dr_f8_halves ua = {a}, ub = {b}; \
        union dr_m8_halves r; \
        r.h[0] = ua.h[0] op ub.h[0]; \
        r.h[1] = ua.h[1] op ub.h[1]; \
        return r.v; \
    }
/* a where m is set, else b */
DR_SIMD_INLINE dr_f8 dr_f8_sel(dr_m8 m, dr_f8 a, dr_f8 b)
{
    union dr_m8_halves um = {m};
    union dr_f8_halves ua = {a}, ub = {b}, r;
    for (int k = 0; k < 2; k++)
        r.h[k] = (dr_f4)((um.h[k] & (dr_m4)ua.h[k]) | (~um.h[k] & (dr_m4)ub.h[k]));
    return r.v;
}
#endif
DR_F8_CMP(dr_f8_lt, <)
DR_F8_CMP(dr_f8_le, <=)
DR_F8_CMP(dr_f8_gt, >)
DR_F8_CMP(dr_f8_ge, >=)
DR_F8_CMP(dr_f8_eq, ==)
DR_F8_CMP(dr_f8_ne, !=)
#undef DR_F8_CMP
DR_SIMD_INLINE dr_f8 dr_f8_sqrt(dr_f8 a)
{
#if defined(__AVX512F__)
    /* one instruction: GCC merged the lanes below into two 256-bit square
     * roots stored to the stack apart and read back as one 512-bit value, a
     * load that cannot be forwarded from two stores (a stall at each of
     * the shading's normalisations: 15 % of dr_path8_shade_lanes) */
    return (dr_f8)_mm512_sqrt_pd((__m512d)a);
#else
    dr_f8 r;
    for (int i = 0; i < DR_SIMD_W; i++)   /* one vector square root: GCC merges the lanes */
        r[i] = sqrt(a[i]);
    return r;
#endif
}
/* floor, lane by lane (exact: rounding towards minus infinity) */
DR_SIMD_INLINE dr_f8 dr_f8_floor(dr_f8 a)
{
#if defined(__AVX512F__)
    return (dr_f8)_mm512_roundscale_pd((__m512d)a, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
#else
    dr_f8 r;
    for (int i = 0; i < DR_SIMD_W; i++)
        r[i] = floor(a[i]);
    return r;
#endif
}
DR_SIMD_INLINE dr_f8 dr_f8_abs(dr_f8 a) { return (dr_f8)((dr_m8)a & ~(dr_m8)dr_f8s(-0.0)); }
/* copysign(1.0, a) */
DR_SIMD_INLINE dr_f8 dr_f8_sign1(dr_f8 a)
{
    return (dr_f8)(((dr_m8)a & (dr_m8)dr_f8s(-0.0)) | (dr_m8)dr_f8s(1.0));
}
/* vec.h's branches, as selects: dr_min, dr_max (a > b ? a : b), dr_clamp */
DR_SIMD_INLINE dr_f8 dr_f8_min(dr_f8 a, dr_f8 b) { return dr_f8_sel(dr_f8_lt(a, b), a, b); }
DR_SIMD_INLINE dr_f8 dr_f8_max(dr_f8 a, dr_f8 b) { return dr_f8_sel(dr_f8_gt(a, b), a, b); }
DR_SIMD_INLINE dr_f8 dr_f8_clamp(dr_f8 v, double lo, double hi)
{
    return dr_f8_sel(dr_f8_lt(v, dr_f8s(lo)), dr_f8s(lo), dr_f8_sel(dr_f8_gt(v, dr_f8s(hi)), dr_f8s(hi), v));
}
DR_SIMD_INLINE int dr_m8_any(dr_m8 m)
{
    int64_t a = 0;
    for (int i = 0; i < DR_SIMD_W; i++)
        a |= m[i];
    return a != 0;
}

/* The mask of eight bools (b[i] true: every bit set). With AVX-512 one
 * widening of the eight bytes and a negation: the loop below compiled to a
 * chain of eight dependent masked broadcasts (~40 instructions), and the
 * stages make a dozen such masks per group. Exact either way (a bool is 0
 * or 1). */
DR_SIMD_INLINE dr_m8 dr_m8_from_bools(const bool *b)
{
#if defined(__AVX512F__)
    uint64_t w;
    memcpy(&w, b, sizeof w);
    return (dr_m8)_mm512_sub_epi64(_mm512_setzero_si512(), _mm512_cvtepu8_epi64(_mm_cvtsi64_si128((long long)w)));
#else
    dr_m8 m;
    for (int i = 0; i < DR_SIMD_W; i++)
        m[i] = b[i] ? -1 : 0;
    return m;
#endif
}
/* Lanes [0, n) of a group (0 <= n <= 8): a window on a table, not eight
 * conditional inserts. */
DR_SIMD_INLINE dr_m8 dr_m8_first(int n)
{
    static const int64_t window[2 * DR_SIMD_W] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};
    dr_m8 m;
    memcpy(&m, window + DR_SIMD_W - n, sizeof m);
    return m;
}
/* The lanes where a (64-bit integers) is negative: its sign bit spread,
 * shifts that AVX2 has too (a comparison written with < would not be). */
DR_SIMD_INLINE dr_m8 dr_m8_negative(dr_m8 a)
{
    return (dr_m8)((dr_u8){0} - ((dr_u8)a >> 63));
}

/* Closing up: the 64-bit words src[i] of the lanes i where keep is set, in
 * lane order, to dst[0 .. count); dst[count .. 8) get unspecified words (a
 * caller's arrays must have room for them, and must not read them before
 * writing them again). src is read whole before dst is written, so dst may
 * overlap it. With AVX-512: one compress in registers and one store (the
 * store form of the compress is slow on some processors), where closing up
 * lane by lane took a slot's twenty moves per path and step. */
DR_SIMD_INLINE void dr_compress8(void *dst, const void *src, dr_m8 keep)
{
#if defined(__AVX512F__)
    __m512i v = _mm512_loadu_si512(src);
    __mmask8 k = _mm512_test_epi64_mask((__m512i)keep, (__m512i)keep);
    _mm512_storeu_si512(dst, _mm512_maskz_compress_epi64(k, v));
#else
    uint64_t v[DR_SIMD_W];
    memcpy(v, src, sizeof v);
    for (int i = 0, j = 0; i < DR_SIMD_W; i++)
        if (keep[i])
            memcpy((char *)dst + sizeof(uint64_t) * (size_t)j++, &v[i], sizeof(uint64_t));
#endif
}

/* Three coordinates of eight vectors; the operations mirror vec.h's. */
typedef struct { dr_f8 x, y, z; } dr_v3x8;

DR_SIMD_INLINE dr_v3x8 dr_v3x8_add(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x + b.x, a.y + b.y, a.z + b.z}; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_sub(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x - b.x, a.y - b.y, a.z - b.z}; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_mul(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x * b.x, a.y * b.y, a.z * b.z}; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_scale(dr_v3x8 a, dr_f8 s) { return (dr_v3x8){a.x * s, a.y * s, a.z * s}; }
/* The eight lanes' values of an expression of the lane l, e(l), as a vector
 * of type T: an initialiser list, which compiles to one insert per lane,
 * where eight stores into a vector on the stack make its load wait for them
 * to forward (see above). */
#define DR_LANES8(T, e) (T){e(0), e(1), e(2), e(3), e(4), e(5), e(6), e(7)}
/* a in every lane */
DR_SIMD_INLINE dr_v3x8 dr_v3x8_splat(dr_vec3 a) { return (dr_v3x8){dr_f8s(a.x), dr_f8s(a.y), dr_f8s(a.z)}; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_neg(dr_v3x8 a) { return (dr_v3x8){-a.x, -a.y, -a.z}; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_madd(dr_v3x8 a, dr_v3x8 b, dr_f8 s)
{
    return (dr_v3x8){a.x + b.x * s, a.y + b.y * s, a.z + b.z * s};
}
DR_SIMD_INLINE dr_f8 dr_v3x8_dot(dr_v3x8 a, dr_v3x8 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
DR_SIMD_INLINE dr_v3x8 dr_v3x8_cross(dr_v3x8 a, dr_v3x8 b)
{
    return (dr_v3x8){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
DR_SIMD_INLINE dr_v3x8 dr_v3x8_sel(dr_m8 m, dr_v3x8 a, dr_v3x8 b)
{
    return (dr_v3x8){dr_f8_sel(m, a.x, b.x), dr_f8_sel(m, a.y, b.y), dr_f8_sel(m, a.z, b.z)};
}
DR_SIMD_INLINE dr_m8 dr_v3x8_is_black(dr_v3x8 c)
{
    const dr_f8 zero = dr_f8s(0.0);
    return dr_f8_eq(c.x, zero) & dr_f8_eq(c.y, zero) & dr_f8_eq(c.z, zero);
}
/* Lane i of a (by pointer: passed by value, GCC copies all 192 bytes of a
 * vector kept in memory with a memcpy call before reading one lane). */
DR_SIMD_INLINE dr_vec3 dr_v3x8_get(const dr_v3x8 *a, int i) { return dr_v3(a->x[i], a->y[i], a->z[i]); }

#endif
