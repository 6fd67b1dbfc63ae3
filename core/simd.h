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
#include <stdint.h>

#include "vec.h"

#define DR_SIMD_W 8

typedef double dr_f8 __attribute__((vector_size(8 * sizeof(double))));
typedef int64_t dr_m8 __attribute__((vector_size(8 * sizeof(int64_t))));
typedef uint64_t dr_u8 __attribute__((vector_size(8 * sizeof(uint64_t))));

static inline dr_f8 dr_f8s(double s) { return (dr_f8){s, s, s, s, s, s, s, s}; }
/* a where m is set, else b */
static inline dr_f8 dr_f8_sel(dr_m8 m, dr_f8 a, dr_f8 b) { return (dr_f8)((m & (dr_m8)a) | (~m & (dr_m8)b)); }
static inline dr_f8 dr_f8_sqrt(dr_f8 a)
{
    dr_f8 r;
    for (int i = 0; i < DR_SIMD_W; i++)   /* one vector square root: GCC merges the lanes */
        r[i] = sqrt(a[i]);
    return r;
}
static inline dr_f8 dr_f8_abs(dr_f8 a) { return (dr_f8)((dr_m8)a & ~(dr_m8)dr_f8s(-0.0)); }
/* copysign(1.0, a) */
static inline dr_f8 dr_f8_sign1(dr_f8 a)
{
    return (dr_f8)(((dr_m8)a & (dr_m8)dr_f8s(-0.0)) | (dr_m8)dr_f8s(1.0));
}
/* vec.h's branches, as selects: dr_min, dr_max (a > b ? a : b), dr_clamp */
static inline dr_f8 dr_f8_min(dr_f8 a, dr_f8 b) { return dr_f8_sel(a < b, a, b); }
static inline dr_f8 dr_f8_max(dr_f8 a, dr_f8 b) { return dr_f8_sel(a > b, a, b); }
static inline dr_f8 dr_f8_clamp(dr_f8 v, double lo, double hi)
{
    return dr_f8_sel(v < lo, dr_f8s(lo), dr_f8_sel(v > hi, dr_f8s(hi), v));
}
static inline int dr_m8_any(dr_m8 m)
{
    int64_t a = 0;
    for (int i = 0; i < DR_SIMD_W; i++)
        a |= m[i];
    return a != 0;
}

/* Three coordinates of eight vectors; the operations mirror vec.h's. */
typedef struct { dr_f8 x, y, z; } dr_v3x8;

static inline dr_v3x8 dr_v3x8_add(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline dr_v3x8 dr_v3x8_sub(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x - b.x, a.y - b.y, a.z - b.z}; }
static inline dr_v3x8 dr_v3x8_mul(dr_v3x8 a, dr_v3x8 b) { return (dr_v3x8){a.x * b.x, a.y * b.y, a.z * b.z}; }
static inline dr_v3x8 dr_v3x8_scale(dr_v3x8 a, dr_f8 s) { return (dr_v3x8){a.x * s, a.y * s, a.z * s}; }
static inline dr_v3x8 dr_v3x8_neg(dr_v3x8 a) { return (dr_v3x8){-a.x, -a.y, -a.z}; }
static inline dr_v3x8 dr_v3x8_madd(dr_v3x8 a, dr_v3x8 b, dr_f8 s)
{
    return (dr_v3x8){a.x + b.x * s, a.y + b.y * s, a.z + b.z * s};
}
static inline dr_f8 dr_v3x8_dot(dr_v3x8 a, dr_v3x8 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline dr_v3x8 dr_v3x8_cross(dr_v3x8 a, dr_v3x8 b)
{
    return (dr_v3x8){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static inline dr_v3x8 dr_v3x8_sel(dr_m8 m, dr_v3x8 a, dr_v3x8 b)
{
    return (dr_v3x8){dr_f8_sel(m, a.x, b.x), dr_f8_sel(m, a.y, b.y), dr_f8_sel(m, a.z, b.z)};
}
static inline dr_m8 dr_v3x8_is_black(dr_v3x8 c) { return (c.x == 0.0) & (c.y == 0.0) & (c.z == 0.0); }
static inline dr_vec3 dr_v3x8_get(dr_v3x8 a, int i) { return dr_v3(a.x[i], a.y[i], a.z[i]); }

#endif
