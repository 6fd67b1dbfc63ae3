/* Sines, cosines and arc tangents of eight lanes at once (simd.h), without
 * libm: libm's are scalar calls, made lane by lane, and under an environment
 * map they took a sixth of a render.
 *
 * dr_f8_sincos_turn runs bsdf.c's dr_sincos_turn's operations, so a lane
 * gets the scalar function's bits (the packet renderer's exactness against
 * the one-path walker rests on that). dr_f8_atan2 and dr_f8_acos have their
 * scalar twins here, dr_atan2 and dr_acos, with the same operations
 * (test_bsdf compares them bit for bit); lights.c's dr_env_dir_to_uv uses
 * those. (Calling the eight-lane function for one value, as a first version
 * did, made the scalar walker's environment lookups 1.2 x slower than
 * libm's.) */
#ifndef DR_SIMD_TRIG_H
#define DR_SIMD_TRIG_H

#include "bsdf.h"   /* DR_SIN_SERIES, DR_COS_SERIES */
#include "simd.h"

/* bsdf.h's dr_horner, eight lanes. */
DR_SIMD_INLINE dr_f8 dr_f8_horner(dr_f8 x, const double *c, int n)
{
    dr_f8 p = dr_f8s(c[0]);
    for (int i = 1; i < n; i++)
        p = p * x + c[i];
    return p;
}

/* dr_sincos_turn (bsdf.h): sin and cos of 2 pi u, the same operations. */
DR_SIMD_INLINE void dr_f8_sincos_turn(dr_f8 u, dr_f8 *s, dr_f8 *c)
{
    const dr_f8 m = dr_f8_floor(4.0 * u + 0.5);
    const dr_f8 r = (2.0 * M_PI) * (u - 0.25 * m);
    const dr_f8 q = m - 4.0 * dr_f8_floor(0.25 * m);
    const dr_f8 r2 = r * r;
    const dr_f8 sr = r + r * r2 * dr_f8_horner(r2, DR_SIN_SERIES, 8);
    const dr_f8 cr = 1.0 - r2 * dr_f8_horner(r2, DR_COS_SERIES, 9);
    const dr_m8 q1 = dr_f8_eq(q, dr_f8s(1.0)), q2 = dr_f8_eq(q, dr_f8s(2.0)), q3 = dr_f8_eq(q, dr_f8s(3.0));
    *s = dr_f8_sel(q1, cr, dr_f8_sel(q2, -sr, dr_f8_sel(q3, -cr, sr)));
    *c = dr_f8_sel(q1, -sr, dr_f8_sel(q2, -cr, dr_f8_sel(q3, sr, cr)));
}

/* atan(k / 16), k = 0 .. 16, rounded to nearest (from atanl). */
static const double DR_ATAN_SIXTEENTHS[17] = {
    0, 0.06241880999595735, 0.12435499454676144, 0.18534794999569476, 0.24497866312686414,
    0.30288486837497142, 0.35877067027057225, 0.41241044159738732, 0.46364760900080609, 0.51238946031073773,
    0.55859931534356244, 0.60228734613496415, 0.64350110879328437, 0.68231655487474807, 0.71882999962162453,
    0.75315128096219441, 0.78539816339744828};
/* atan z = z + z^3 (-1/3 + z^2 (1/5 + ...)) to z^11: for |z| <= 1/32 the
 * first term left out, z^13 / 13, is below 1e-20 of z. */
static const double DR_ATAN_SERIES[5] = {-1.0 / 11.0, 1.0 / 9.0, -1.0 / 7.0, 1.0 / 5.0, -1.0 / 3.0};

/* atan2(y, x) in [-pi, pi], within a few ulp of libm's (test_bsdf measures
 * it). The ratio t = min / max of |x|, |y| is in [0, 1]; with c the nearest
 * sixteenth, atan t = atan c + atan z, z = (t - c) / (1 + t c), |z| <= 1/32;
 * then the octant's reflections. x = y = 0 gives 0, a NaN gives NaN, and
 * the sign of a zero is not looked at (-0 counts as 0). */
DR_SIMD_INLINE dr_f8 dr_f8_atan2(dr_f8 y, dr_f8 x)
{
    const dr_f8 ax = dr_f8_abs(x), ay = dr_f8_abs(y);
    const dr_m8 steep = dr_f8_gt(ay, ax);
    const dr_f8 num = dr_f8_sel(steep, ax, ay), den = dr_f8_sel(steep, ay, ax);
    const dr_f8 t = dr_f8_sel(dr_f8_eq(den, dr_f8s(0.0)), dr_f8s(0.0), num / den);
    dr_f8 k = dr_f8_floor(16.0 * t + 0.5);
    k = dr_f8_sel(dr_f8_eq(k, k), k, dr_f8s(0.0));   /* (NaN: any entry; the NaN comes through z) */
    dr_f8 base;
    for (int i = 0; i < DR_SIMD_W; i++)
        base[i] = DR_ATAN_SIXTEENTHS[(int)k[i]];
    const dr_f8 c = k * (1.0 / 16.0);
    const dr_f8 z = (t - c) / (1.0 + t * c), z2 = z * z;
    dr_f8 r = base + (z + z * z2 * dr_f8_horner(z2, DR_ATAN_SERIES, 5));
    r = dr_f8_sel(steep, M_PI / 2.0 - r, r);
    r = dr_f8_sel(dr_f8_lt(x, dr_f8s(0.0)), M_PI - r, r);
    return dr_f8_sel(dr_f8_lt(y, dr_f8s(0.0)), -r, r);
}

/* acos of y in [-1, 1]: 2 atan2(sqrt(1 - y), sqrt(1 + y)) (the tangent of
 * half the angle), accurate at both ends, where 1 -+ y is exact. */
DR_SIMD_INLINE dr_f8 dr_f8_acos(dr_f8 y)
{
    return 2.0 * dr_f8_atan2(dr_f8_sqrt(1.0 - y), dr_f8_sqrt(1.0 + y));
}

/* dr_f8_atan2 for one pair: the same operations. */
static inline double dr_atan2(double y, double x)
{
    const double ax = fabs(x), ay = fabs(y);
    const int steep = ay > ax;
    const double num = steep ? ax : ay, den = steep ? ay : ax;
    const double t = den == 0.0 ? 0.0 : num / den;
    double k = floor(16.0 * t + 0.5);
    if (!(k == k))
        k = 0.0;
    const double c = k * (1.0 / 16.0);
    const double z = (t - c) / (1.0 + t * c), z2 = z * z;
    double r = DR_ATAN_SIXTEENTHS[(int)k] + (z + z * z2 * dr_horner(z2, DR_ATAN_SERIES, 5));
    if (steep)
        r = M_PI / 2.0 - r;
    if (x < 0.0)
        r = M_PI - r;
    return y < 0.0 ? -r : r;
}

/* dr_f8_acos for one value: the same operations. */
static inline double dr_acos(double y)
{
    return 2.0 * dr_atan2(sqrt(1.0 - y), sqrt(1.0 + y));
}

#endif
