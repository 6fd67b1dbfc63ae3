/* Small double-precision vector maths used by the tracer.
 * Value types, all inline: the inner loop lives on these. */
#ifndef DR_VEC_H
#define DR_VEC_H

#include <math.h>
#include <stdbool.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
/* Adjoints of the frame maps (attached sampling: frames move with the shading
 * normal). d_f collects d loss / d (s, t, n) of the frame. */
static inline void d_frame_to_local(const dr_frame *f, dr_vec3 v, dr_vec3 d_out, dr_vec3 *d_v, dr_frame *d_f)
{
    if (d_v)
        *d_v = dr_add(*d_v, dr_add(dr_add(dr_scale(f->s, d_out.x), dr_scale(f->t, d_out.y)), dr_scale(f->n, d_out.z)));
    if (d_f) {
        d_f->s = dr_madd(d_f->s, v, d_out.x);
        d_f->t = dr_madd(d_f->t, v, d_out.y);
        d_f->n = dr_madd(d_f->n, v, d_out.z);
    }
}
static inline void d_frame_to_world(const dr_frame *f, dr_vec3 v, dr_vec3 d_out, dr_vec3 *d_v, dr_frame *d_f)
{
    if (d_v)
        *d_v = dr_add(*d_v, dr_v3(dr_dot(f->s, d_out), dr_dot(f->t, d_out), dr_dot(f->n, d_out)));
    if (d_f) {
        d_f->s = dr_madd(d_f->s, d_out, v.x);
        d_f->t = dr_madd(d_f->t, d_out, v.y);
        d_f->n = dr_madd(d_f->n, d_out, v.z);
    }
}
/* Reverse mode of dr_frame_from_normal: d_f (of s, t, n) into *d_n. The
 * sign branch is constant (the frame jumps where n.z changes sign, a set of
 * measure zero); with a = -1 / (sign + n.z), da/dn.z = a^2, b = n.x n.y a. */
static inline void d_frame_from_normal(dr_vec3 n, const dr_frame *d_f, dr_vec3 *d_n)
{
    double sign = copysign(1.0, n.z);
    double a = -1.0 / (sign + n.z);
    /* s = (1 + sign nx^2 a, sign b, -sign nx), t = (b, sign + ny^2 a, -ny) */
    double g_b = sign * d_f->s.y + d_f->t.x;
    double g_a = sign * n.x * n.x * d_f->s.x + n.y * n.y * d_f->t.y + n.x * n.y * g_b;
    double gx = 2.0 * sign * n.x * a * d_f->s.x - sign * d_f->s.z + n.y * a * g_b;
    double gy = 2.0 * n.y * a * d_f->t.y - d_f->t.z + n.x * a * g_b;
    double gz = g_a * a * a;
    *d_n = dr_add(*d_n, dr_add(d_f->n, dr_v3(gx, gy, gz)));
}

#endif
#define DR_INV_PI (1.0 / M_PI)

typedef struct { double x, y, z; } dr_vec3;

static inline dr_vec3 dr_v3(double x, double y, double z) { dr_vec3 r = {x, y, z}; return r; }
static inline dr_vec3 dr_v3s(double s) { return dr_v3(s, s, s); }
static inline dr_vec3 dr_add(dr_vec3 a, dr_vec3 b) { return dr_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline dr_vec3 dr_sub(dr_vec3 a, dr_vec3 b) { return dr_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline dr_vec3 dr_mul(dr_vec3 a, dr_vec3 b) { return dr_v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline dr_vec3 dr_scale(dr_vec3 a, double s) { return dr_v3(a.x * s, a.y * s, a.z * s); }
static inline dr_vec3 dr_neg(dr_vec3 a) { return dr_v3(-a.x, -a.y, -a.z); }
static inline dr_vec3 dr_madd(dr_vec3 a, dr_vec3 b, double s) { return dr_v3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s); }
static inline double dr_dot(dr_vec3 a, dr_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline dr_vec3 dr_cross(dr_vec3 a, dr_vec3 b)
{
    return dr_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double dr_length(dr_vec3 a) { return sqrt(dr_dot(a, a)); }
static inline dr_vec3 dr_normalize(dr_vec3 a)
{
    double l = dr_length(a);
    return l > 0.0 ? dr_scale(a, 1.0 / l) : a;
}
static inline dr_vec3 dr_lerp3(dr_vec3 a, dr_vec3 b, double t) { return dr_add(dr_scale(a, 1.0 - t), dr_scale(b, t)); }
/* Plain comparisons: fmin/fmax are library calls unless -ffast-math. */
static inline double dr_min(double a, double b) { return a < b ? a : b; }
static inline double dr_max(double a, double b) { return a > b ? a : b; }
static inline double dr_max3(dr_vec3 a) { return dr_max(a.x, dr_max(a.y, a.z)); }
/* Rec. 709 luminance of linear RGB. */
static inline double dr_luminance(dr_vec3 c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }
static inline bool dr_is_black(dr_vec3 c) { return c.x == 0.0 && c.y == 0.0 && c.z == 0.0; }
static inline double dr_clamp(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }
static inline double dr_sqr(double v) { return v * v; }
/* Channel c (0, 1, 2) of a colour, without indexing past a struct member. */
static inline double dr_v3_get(dr_vec3 v, int c) { return c == 0 ? v.x : (c == 1 ? v.y : v.z); }
static inline void dr_v3_set(dr_vec3 *v, int c, double s)
{
    if (c == 0)
        v->x = s;
    else if (c == 1)
        v->y = s;
    else
        v->z = s;
}
/* The colour with only channel c kept (the others exactly 0). */
static inline dr_vec3 dr_v3_channel(dr_vec3 v, int c)
{
    return dr_v3(c == 0 ? v.x : 0.0, c == 1 ? v.y : 0.0, c == 2 ? v.z : 0.0);
}
static inline bool dr_v3_finite(dr_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* Orthonormal frame around a unit normal n (Duff et al. 2017, branchless). */
typedef struct { dr_vec3 s, t, n; } dr_frame;

static inline dr_frame dr_frame_from_normal(dr_vec3 n)
{
    double sign = copysign(1.0, n.z);
    double a = -1.0 / (sign + n.z);
    double b = n.x * n.y * a;
    dr_frame f;
    f.s = dr_v3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    f.t = dr_v3(b, sign + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
}
static inline dr_vec3 dr_frame_to_local(const dr_frame *f, dr_vec3 v)
{
    return dr_v3(dr_dot(v, f->s), dr_dot(v, f->t), dr_dot(v, f->n));
}
static inline dr_vec3 dr_frame_to_world(const dr_frame *f, dr_vec3 v)
{
    return dr_add(dr_add(dr_scale(f->s, v.x), dr_scale(f->t, v.y)), dr_scale(f->n, v.z));
}

/* Adjoints of the frame maps (attached sampling: frames move with the shading
 * normal). d_f collects d loss / d (s, t, n) of the frame. */
static inline void d_frame_to_local(const dr_frame *f, dr_vec3 v, dr_vec3 d_out, dr_vec3 *d_v, dr_frame *d_f)
{
    if (d_v)
        *d_v = dr_add(*d_v, dr_add(dr_add(dr_scale(f->s, d_out.x), dr_scale(f->t, d_out.y)), dr_scale(f->n, d_out.z)));
    if (d_f) {
        d_f->s = dr_madd(d_f->s, v, d_out.x);
        d_f->t = dr_madd(d_f->t, v, d_out.y);
        d_f->n = dr_madd(d_f->n, v, d_out.z);
    }
}
static inline void d_frame_to_world(const dr_frame *f, dr_vec3 v, dr_vec3 d_out, dr_vec3 *d_v, dr_frame *d_f)
{
    if (d_v)
        *d_v = dr_add(*d_v, dr_v3(dr_dot(f->s, d_out), dr_dot(f->t, d_out), dr_dot(f->n, d_out)));
    if (d_f) {
        d_f->s = dr_madd(d_f->s, d_out, v.x);
        d_f->t = dr_madd(d_f->t, d_out, v.y);
        d_f->n = dr_madd(d_f->n, d_out, v.z);
    }
}
/* Reverse mode of dr_frame_from_normal: d_f (of s, t, n) into *d_n. The
 * sign branch is constant (the frame jumps where n.z changes sign, a set of
 * measure zero); with a = -1 / (sign + n.z), da/dn.z = a^2, b = n.x n.y a. */
static inline void d_frame_from_normal(dr_vec3 n, const dr_frame *d_f, dr_vec3 *d_n)
{
    double sign = copysign(1.0, n.z);
    double a = -1.0 / (sign + n.z);
    /* s = (1 + sign nx^2 a, sign b, -sign nx), t = (b, sign + ny^2 a, -ny) */
    double g_b = sign * d_f->s.y + d_f->t.x;
    double g_a = sign * n.x * n.x * d_f->s.x + n.y * n.y * d_f->t.y + n.x * n.y * g_b;
    double gx = 2.0 * sign * n.x * a * d_f->s.x - sign * d_f->s.z + n.y * a * g_b;
    double gy = 2.0 * n.y * a * d_f->t.y - d_f->t.z + n.x * a * g_b;
    double gz = g_a * a * a;
    *d_n = dr_add(*d_n, dr_add(d_f->n, dr_v3(gx, gy, gz)));
}

#endif
