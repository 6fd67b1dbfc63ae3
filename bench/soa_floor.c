/* How fast could any design of drender's primal be on Debian's Embree 3?
 * (issue 11: the primal bar is the peer's 1.16 s on its Cornell box.)
 *
 * A deliberately minimal path tracer, written the way the "SoA wave" design
 * would be: all path state in float arrays (structure of arrays), rays sent
 * to Embree as 16-wide packets straight from those arrays, the shading loops
 * plain loops over lanes that GCC vectorises, dead paths compacted away after
 * every bounce. It does the same work per sample as `drender render` on a
 * scene of Lambertian surfaces and emissive triangles (the peer's box):
 * camera ray; at every hit the emission seen (power-heuristic MIS against
 * light sampling), one shadow ray to a uniform point of an emissive triangle
 * chosen by area (MIS against the BSDF), a cosine-sampled bounce; Russian
 * roulette from depth 5 with survival min(max throughput, 0.95); at most
 * MAX_DEPTH segments; box filter, one sample per pixel jittered.
 *
 * What it leaves out, so that its time is a floor rather than a renderer:
 * textures, other BSDFs, media, parameters, single-sided culling (no
 * coverage filter), shading normals, invalid-sample checks, progress, tiles,
 * drender's sampler (a 32-bit hash of sample index and dimension here).
 * It is not part of drender and not tested; make bench runs it for its time.
 * It prints its image mean, which bench/README compares with drender's to
 * show that the two estimate the same thing.
 *
 *   soa_floor SCENE [WIDTH HEIGHT SPP [THREADS [MAX_DEPTH]]]
 *
 * Prints one JSON object: seconds, rays by kind, image mean. */
#include <embree3/rtcore.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "camera.h"
#include "clock.h"
#include "error.h"
#include "geometry.h"
#include "path_args.h"
#include "raw_scene.h"
#include "scene.h"

/* The arithmetic's precision: float, as the peer; FLOOR_DOUBLE=1 builds
 * the same loops in double, as drender shades (make bench reports both). */
#if FLOOR_DOUBLE
typedef double real;
#define SQRT sqrt
#define FABS fabs
#define COPYSIGN copysign
#else
typedef float real;
#define SQRT sqrtf
#define FABS fabsf
#define COPYSIGN copysignf
#endif

#ifndef WAVE
#define WAVE 1024   /* paths per wave */
#endif
/* Each array is padded so that the arrays do not start at the same offset
 * modulo 4 KiB: otherwise a loop touching ten of them at lane i maps them all
 * to one cache set (measured: 4096 lanes unpadded spent a third of the
 * non-Embree time in the compaction's stores). */
#define LANES (WAVE + 48)
#define PACKET 16

/* Per-triangle data the shading reads, structure of arrays (one
 * gather per field and lane). */
struct tri_data {
    real *nx, *ny, *nz;   /* unit geometric normal */
    real *ar, *ag, *ab;   /* base colour / pi */
    real *er, *eg, *eb;   /* emitted radiance (front side) */
};

#define MAX_LIGHTS 16   /* emissive triangles the floor handles (the peer's box has 2) */

/* The emissive triangles, chosen by area: vertex p0, edges e1 e2, normal,
 * radiance, cdf. */
struct lights {
    real p0x[MAX_LIGHTS], p0y[MAX_LIGHTS], p0z[MAX_LIGHTS], e1x[MAX_LIGHTS], e1y[MAX_LIGHTS], e1z[MAX_LIGHTS];
    real e2x[MAX_LIGHTS], e2y[MAX_LIGHTS], e2z[MAX_LIGHTS], nx[MAX_LIGHTS], ny[MAX_LIGHTS], nz[MAX_LIGHTS];
    real er[MAX_LIGHTS], eg[MAX_LIGHTS], eb[MAX_LIGHTS], cdf[MAX_LIGHTS];
    int n;
    real total_area;
};

struct ctx {
    const struct dr_scene *sc;
    RTCScene rtc;
    struct dr_accel *acc;   /* FLOOR_DR_ACCEL: drender's query layer instead */
    const float *v0;        /* FLOOR_DR_ACCEL: each triangle's first vertex and unit normal (t from the plane) */
    struct dr_camera_view view;
    struct tri_data td;
    struct lights L;
    int W, H, S, D;
    real *film;   /* W * H * 3, summed radiance */
    atomic_int next_wave;
    int n_waves;
};

/* The path state of one wave, structure of arrays. */
struct wave {
    real ox[LANES], oy[LANES], oz[LANES], dx[LANES], dy[LANES], dz[LANES];
    real tr[LANES], tg[LANES], tb[LANES];        /* throughput */
    real lr[LANES], lg[LANES], lb[LANES];        /* radiance so far */
    real prev_pdf[LANES];                      /* solid-angle pdf of the last bounce (MIS) */
    uint32_t pix[LANES], key[LANES], dim[LANES];  /* pixel, hash key of (pixel, sample), next dimension */
    /* per-bounce scratch */
    real t[LANES];
    uint32_t prim[LANES];
    real sr[LANES], sg[LANES], sb[LANES];        /* shadow ray's contribution if unoccluded */
    real sox[LANES], soy[LANES], soz[LANES], sdx[LANES], sdy[LANES], sdz[LANES], stf[LANES];
    int32_t slane[LANES];                       /* lanes with a shadow ray */
    int32_t has_shadow[LANES];
#if FLOOR_DR_ACCEL
    dr_vec3 qo[LANES], qd[LANES];   /* the rays as drender's query layer takes them */
    double qtmax[LANES];
    int64_t qtri[LANES];
    bool qocc[LANES];
#endif
    int n;
};

static inline uint32_t hash32(uint32_t x)
{
    x ^= x >> 16, x *= 0x7feb352dU, x ^= x >> 15, x *= 0x846ca68bU, x ^= x >> 16;
    return x;
}

/* Uniform number in [0, 1) for dimension dim of the path keyed key. */
static inline real rnd(uint32_t key, uint32_t dim)
{
    return (real)(hash32(key ^ hash32(dim * 0x9e3779b9U)) >> 8) * 0x1p-24f;
}

/* fmaxf and fminf as selections, which vectorise (fmaxf's NaN rules do not). */
static inline real max_f(real a, real b)
{
    return a > b ? a : b;
}
static inline real min_f(real a, real b)
{
    return a < b ? a : b;
}

/* sin and cos of 2 pi u, u in [0, 1), branch-free so that the shading loop
 * vectorises (libm's sincosf does not): a degree-9 odd polynomial for sin on
 * [-pi/2, pi/2] (error < 4e-6), cos from it. */
static inline void sincos_2pi(real u, real *s, real *c)
{
    const real x = 2.0f * (real)M_PI * (u - 0.5f);   /* angle - pi, in [-pi, pi) */
    const real h = (real)M_PI_2;
    const real y = x > h ? (real)M_PI - x : (x < -h ? -(real)M_PI - x : x);
    const real y2 = y * y;
    const real sn = y * (1.0f + y2 * (-1.6666654611e-1f + y2 * (8.3321608736e-3f + y2 * (-1.9515295891e-4f +
                                                                                       y2 * 2.6083159e-6f))));
    const real cs = SQRT(max_f(0.0f, 1.0f - sn * sn)) * (FABS(x) <= h ? 1.0f : -1.0f);
    *s = -sn, *c = -cs;   /* of angle + pi */
}

static void start_paths(struct ctx *c, struct wave *w, uint64_t first)
{
    const uint64_t total = (uint64_t)c->W * c->H * c->S;
    w->n = 0;
    for (uint64_t s = first; s < first + WAVE && s < total; s++) {
        const int i = w->n++;
        const uint32_t pix = (uint32_t)(s / (uint64_t)c->S);
        w->pix[i] = pix, w->key[i] = hash32((uint32_t)s * 2654435761U + 1u), w->dim[i] = 2;
        dr_vec3 o, d;
        dr_camera_ray(&c->view, (int)(pix % (uint32_t)c->W) + rnd(w->key[i], 0),
                      (int)(pix / (uint32_t)c->W) + rnd(w->key[i], 1), &o, &d);
        w->ox[i] = (real)o.x, w->oy[i] = (real)o.y, w->oz[i] = (real)o.z;
        w->dx[i] = (real)d.x, w->dy[i] = (real)d.y, w->dz[i] = (real)d.z;
        w->tr[i] = w->tg[i] = w->tb[i] = 1.0f;
        w->lr[i] = w->lg[i] = w->lb[i] = 0.0f;
        w->prev_pdf[i] = 0.0f;
    }
}

#if FLOOR_DR_ACCEL
/* FLOOR_DR_ACCEL: the queries through drender's own layer (core/accel.h:
 * double rays, its unfiltered copy first and its coverage filter for the
 * single-sided surfaces, camera rays as coherent packets), which answers
 * the triangle only: t comes from the triangle's plane. */
static void intersect(struct ctx *c, struct wave *w, struct RTCIntersectContext *ic, long *rays, int depth)
{
    (void)ic;
    for (int i = 0; i < w->n; i++) {
        w->qo[i] = dr_v3(w->ox[i], w->oy[i], w->oz[i]), w->qd[i] = dr_v3(w->dx[i], w->dy[i], w->dz[i]);
        w->qtmax[i] = INFINITY;
    }
    const struct dr_accel_rays r = {
        .n = w->n, .o = w->qo, .d = w->qd, .tmax = w->qtmax, .coherent = depth == 0 ? w->n : 0};
    dr_accel_intersect_many(c->acc, &r, w->qtri);
    for (int i = 0; i < w->n; i++) {
        const int64_t tri = w->qtri[i];
        const float *q = c->v0 + 6 * (tri < 0 ? 0 : tri);
        const real dn = w->dx[i] * q[3] + w->dy[i] * q[4] + w->dz[i] * q[5];
        w->t[i] = ((q[0] - w->ox[i]) * q[3] + (q[1] - w->oy[i]) * q[4] + (q[2] - w->oz[i]) * q[5]) / dn;
        w->prim[i] = tri < 0 ? ~0u : (uint32_t)tri;
    }
    *rays += w->n;
}
#else
/* Closest hits of lanes [0, n): t and primitive (or ~0u) per lane. */
static void intersect(struct ctx *c, struct wave *w, struct RTCIntersectContext *ic, long *rays, int depth)
{
    struct RTCIntersectContext camera;   /* a pixel's samples are consecutive: coherent packets, as drender */
    rtcInitIntersectContext(&camera);
    camera.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    if (depth == 0)
        ic = &camera;
    for (int b = 0; b < w->n; b += PACKET) {
        _Alignas(64) struct RTCRayHit16 p;
        _Alignas(64) int valid[PACKET];
        const int m = w->n - b < PACKET ? w->n - b : PACKET;
        for (int l = 0; l < PACKET; l++) {
            const int i = b + (l < m ? l : 0);
            valid[l] = l < m ? -1 : 0;
            p.ray.org_x[l] = w->ox[i], p.ray.org_y[l] = w->oy[i], p.ray.org_z[l] = w->oz[i];
            p.ray.dir_x[l] = w->dx[i], p.ray.dir_y[l] = w->dy[i], p.ray.dir_z[l] = w->dz[i];
            p.ray.tnear[l] = 0.0f, p.ray.tfar[l] = INFINITY, p.ray.time[l] = 0.0f;
            p.ray.mask[l] = ~0u, p.ray.flags[l] = 0, p.ray.id[l] = 0;
            p.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid, c->rtc, ic, &p);
        for (int l = 0; l < m; l++) {
            w->t[b + l] = p.ray.tfar[l];
            w->prim[b + l] = p.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID ? ~0u : p.hit.primID[l];
        }
    }
    *rays += w->n;
}
#endif

static inline real power_heuristic(real a, real b)
{
    return a * a / max_f(a * a + b * b, 1e-30f);
}

/* Emission seen, next-event sample and bounce of every live lane, as one
 * loop without branches that GCC vectorises (16 floats or 8 doubles per
 * AVX-512 register; it needs the build's -fno-math-errno for sqrt):
 * every lane computes everything and masks pick what is kept. Returns the
 * number of shadow rays set up (their lanes in w->slane). A lane whose path
 * ends gets t < 0. Longer than a screen on purpose: the vectoriser sees one
 * loop body, which is what the floor measures. */
static int shade(struct ctx *c, struct wave *w, int depth)
{
    const struct tri_data td = c->td;
    const struct lights *L = &c->L;
    const int n = w->n, last = depth + 1 >= c->D;
    /* loop-invariant choices as values, not conditions (GCC does not vectorise
     * a selection on a scalar condition): the camera ray's emission counts
     * fully; before depth 5 the survival probability is 1 */
    const real first = depth == 0 ? 1.0f : 0.0f, q_floor = depth + 1 >= 5 ? 0.0f : 1.0f;
    real *restrict ox_ = w->ox, *restrict oy_ = w->oy, *restrict oz_ = w->oz;
    real *restrict dx_ = w->dx, *restrict dy_ = w->dy, *restrict dz_ = w->dz;
    real *restrict tr_ = w->tr, *restrict tg_ = w->tg, *restrict tb_ = w->tb;
    real *restrict lr_ = w->lr, *restrict lg_ = w->lg, *restrict lb_ = w->lb;
    real *restrict prev_pdf_ = w->prev_pdf, *restrict t_ = w->t;
    real *restrict sr_ = w->sr, *restrict sg_ = w->sg, *restrict sb_ = w->sb;
    real *restrict sox_ = w->sox, *restrict soy_ = w->soy, *restrict soz_ = w->soz;
    real *restrict sdx_ = w->sdx, *restrict sdy_ = w->sdy, *restrict sdz_ = w->sdz, *restrict stf_ = w->stf;
    uint32_t *restrict prim_ = w->prim, *restrict key_ = w->key, *restrict dim_ = w->dim;
    int32_t *restrict has_shadow_ = w->has_shadow;
#pragma GCC ivdep
    for (int i = 0; i < n; i++) {
        const uint32_t prim = prim_[i];
        const real t_hit = t_[i];
        const int hit = prim != ~0u;
        const uint32_t pr = hit ? prim : 0u;
        const real t = hit ? t_hit : 0.0f;
        const real px = ox_[i] + t * dx_[i], py = oy_[i] + t * dy_[i], pz = oz_[i] + t * dz_[i];
        const real cos_in = -(td.nx[pr] * dx_[i] + td.ny[pr] * dy_[i] + td.nz[pr] * dz_[i]);
        const real sgn = cos_in >= 0.0f ? 1.0f : -1.0f;   /* the side the ray arrived on */
        const real nx = sgn * td.nx[pr], ny = sgn * td.ny[pr], nz = sgn * td.nz[pr];
        /* emission seen (emitters shine from their front) */
        const real er = td.er[pr], eg = td.eg[pr], eb = td.eb[pr];
        const real pdf_e = t * t / (max_f(cos_in, 1e-20f) * L->total_area);
        const real we = max_f(first, power_heuristic(prev_pdf_[i], pdf_e));
        const real emit = (hit & (cos_in > 0.0f)) ? we : 0.0f;
        lr_[i] += emit * tr_[i] * er, lg_[i] += emit * tg_[i] * eg, lb_[i] += emit * tb_[i] * eb;
        const real ar = tr_[i] * td.ar[pr], ag = tg_[i] * td.ag[pr], ab = tb_[i] * td.ab[pr];
        const int goes_on = hit & !last & (max_f(ar, max_f(ag, ab)) > 0.0f);   /* black: no shadow ray, no bounce */
        const uint32_t key = key_[i], dim = dim_[i];
        /* next-event estimation: a triangle by area (counting cdf entries <= u), a uniform point on it */
        const real u = rnd(key, dim), b1 = SQRT(rnd(key, dim + 1)), b2 = rnd(key, dim + 2);
        int k = 0;
#pragma GCC unroll 16
        for (int j = 0; j < MAX_LIGHTS - 1; j++)
            k += (j < L->n - 1) & (L->cdf[j] <= u);
        const real a1 = b2 * b1, a2 = b1 - a1;   /* weights of e1, e2 (a0 = 1 - b1) */
        const real lx = L->p0x[k] + a1 * L->e1x[k] + a2 * L->e2x[k], ly = L->p0y[k] + a1 * L->e1y[k] + a2 * L->e2y[k],
                    lz = L->p0z[k] + a1 * L->e1z[k] + a2 * L->e2z[k];
        real tx = lx - px, ty = ly - py, tz = lz - pz;
        const real d2 = tx * tx + ty * ty + tz * tz, dist = SQRT(d2), inv = 1.0f / max_f(dist, 1e-30f);
        tx *= inv, ty *= inv, tz *= inv;
        const real cs = nx * tx + ny * ty + nz * tz, cl = -(L->nx[k] * tx + L->ny[k] * ty + L->nz[k] * tz);
        const int shadow = goes_on & (L->n > 0) & (cs > 0.0f) & (cl > 0.0f);
        const real pdf_l = d2 / (max_f(cl, 1e-20f) * L->total_area), pdf_b = cs * (real)M_1_PI;
        const real f = shadow ? cs / pdf_l * power_heuristic(pdf_l, pdf_b) : 0.0f;
        const real eps = 1e-4f * (1.0f + max_f(FABS(px), max_f(FABS(py), FABS(pz))));
        has_shadow_[i] = shadow;
        sr_[i] = ar * L->er[k] * f, sg_[i] = ag * L->eg[k] * f, sb_[i] = ab * L->eb[k] * f;
        /* the shadow ray starts off the surface and stops short of the light
         * point, measured from its own origin (from p it could reach the
         * light and find it in the way) */
        const real sx = px + eps * nx, sy = py + eps * ny, sz = pz + eps * nz;
        const real gx = lx - sx, gy = ly - sy, gz = lz - sz;
        sox_[i] = sx, soy_[i] = sy, soz_[i] = sz;
        sdx_[i] = tx, sdy_[i] = ty, sdz_[i] = tz, stf_[i] = SQRT(gx * gx + gy * gy + gz * gz) * (1.0f - 1e-4f);
        /* bounce: cosine-weighted, throughput *= albedo (cos / pdf = pi); roulette */
        real tr = ar * (real)M_PI, tg = ag * (real)M_PI, tb = ab * (real)M_PI;
        const real q = max_f(q_floor, min_f(max_f(tr, max_f(tg, tb)), 0.95f));
        const int survives = goes_on & (rnd(key, dim + 3) < q);
        const real iq = 1.0f / max_f(q, 1e-30f);
        tr *= iq, tg *= iq, tb *= iq;
        const real u1 = rnd(key, dim + 4), r = SQRT(u1);
        real sn, co;
        sincos_2pi(rnd(key, dim + 5), &sn, &co);
        const real dlx = r * co, dly = r * sn, dlz = SQRT(max_f(0.0f, 1.0f - u1));
        /* an orthonormal frame around n (Duff et al.) */
        const real s = COPYSIGN(1.0f, nz), a = -1.0f / (s + nz), bb = nx * ny * a;
        const real bx = 1.0f + s * nx * nx * a, by = s * bb, bz = -s * nx;
        const real cx = bb, cy = s + ny * ny * a, cz = -ny;
        dx_[i] = dlx * bx + dly * cx + dlz * nx, dy_[i] = dlx * by + dly * cy + dlz * ny,
        dz_[i] = dlx * bz + dly * cz + dlz * nz;
        ox_[i] = px + eps * nx, oy_[i] = py + eps * ny, oz_[i] = pz + eps * nz;
        tr_[i] = tr, tg_[i] = tg, tb_[i] = tb;
        prev_pdf_[i] = dlz * (real)M_1_PI;
        dim_[i] = dim + 6;
        t_[i] = survives ? 1.0f : -1.0f;
    }
    int ns = 0;   /* the lanes with a shadow ray, in order */
    for (int i = 0; i < n; i++) {
        w->slane[ns] = i;
        ns += w->has_shadow[i];
    }
    return ns;
}

#if FLOOR_DR_ACCEL
static void shadow_rays(struct ctx *c, struct wave *w, int ns, struct RTCIntersectContext *ic, long *rays)
{
    (void)ic;
    for (int k = 0; k < ns; k++) {
        const int j = w->slane[k];
        w->qo[k] = dr_v3(w->sox[j], w->soy[j], w->soz[j]), w->qd[k] = dr_v3(w->sdx[j], w->sdy[j], w->sdz[j]);
        w->qtmax[k] = w->stf[j];
    }
    const struct dr_accel_rays r = {.n = ns, .o = w->qo, .d = w->qd, .tmax = w->qtmax};
    dr_accel_occluded_many(c->acc, &r, w->qocc);
    for (int k = 0; k < ns; k++) {
        const int i = w->slane[k];
        if (!w->qocc[k])
            w->lr[i] += w->sr[i], w->lg[i] += w->sg[i], w->lb[i] += w->sb[i];
    }
    *rays += ns;
}
#else
static void shadow_rays(struct ctx *c, struct wave *w, int ns, struct RTCIntersectContext *ic, long *rays)
{
    for (int b = 0; b < ns; b += PACKET) {
        _Alignas(64) struct RTCRay16 p;
        _Alignas(64) int valid[PACKET];
        const int m = ns - b < PACKET ? ns - b : PACKET;
        for (int l = 0; l < PACKET; l++) {
            const int j = w->slane[b + (l < m ? l : 0)];
            valid[l] = l < m ? -1 : 0;
            p.org_x[l] = w->sox[j], p.org_y[l] = w->soy[j], p.org_z[l] = w->soz[j];
            p.dir_x[l] = w->sdx[j], p.dir_y[l] = w->sdy[j], p.dir_z[l] = w->sdz[j];
            p.tnear[l] = 0.0f, p.tfar[l] = w->stf[j], p.time[l] = 0.0f;
            p.mask[l] = ~0u, p.flags[l] = 0, p.id[l] = 0;
        }
        rtcOccluded16(valid, c->rtc, ic, &p);
        for (int l = 0; l < m; l++) {
            if (p.tfar[l] >= 0.0f) {   /* unoccluded */
                const int i = w->slane[b + l];
                w->lr[i] += w->sr[i], w->lg[i] += w->sg[i], w->lb[i] += w->sb[i];
            }
        }
    }
    *rays += ns;
}
#endif

/* Finished lanes' radiance to the film; the live ones moved to the front. */
static void compact(struct ctx *c, struct wave *w)
{
    int k = 0;
    for (int i = 0; i < w->n; i++) {
        if (w->t[i] < 0.0f) {
            real *f = c->film + 3 * (size_t)w->pix[i];
            f[0] += w->lr[i], f[1] += w->lg[i], f[2] += w->lb[i];
            continue;
        }
#define MOVE(a) w->a[k] = w->a[i]
        MOVE(ox), MOVE(oy), MOVE(oz), MOVE(dx), MOVE(dy), MOVE(dz), MOVE(tr), MOVE(tg), MOVE(tb);
        MOVE(lr), MOVE(lg), MOVE(lb), MOVE(prev_pdf), MOVE(pix), MOVE(key), MOVE(dim);
#undef MOVE
        k++;
    }
    w->n = k;
}

struct worker {
    struct ctx *c;
    long rays[2];
    real *film;
};

static void *work(void *arg)
{
    struct worker *wk = arg;
    struct ctx c = *wk->c;
    c.film = wk->film;
    struct wave *w = aligned_alloc(64, (sizeof *w + 63) / 64 * 64);   /* C11: a multiple of the alignment */
    struct RTCIntersectContext ic;
    rtcInitIntersectContext(&ic);
    ic.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    for (;;) {
        const int wv = atomic_fetch_add(&wk->c->next_wave, 1);
        if (wv >= c.n_waves)
            break;
        start_paths(&c, w, (uint64_t)wv * WAVE);
        for (int depth = 0; w->n > 0; depth++) {
            intersect(&c, w, &ic, &wk->rays[0], depth);
            const int ns = shade(&c, w, depth);
            shadow_rays(&c, w, ns, &ic, &wk->rays[1]);
            compact(&c, w);
        }
    }
    free(w);
    return NULL;
}

static struct tri_data triangle_data(const struct dr_scene *sc, struct lights *L)
{
    const struct dr_mesh *m = &sc->mesh;
    struct tri_data td;
    real **f[9] = {&td.nx, &td.ny, &td.nz, &td.ar, &td.ag, &td.ab, &td.er, &td.eg, &td.eb};
    for (int k = 0; k < 9; k++)
        *f[k] = calloc(m->n_triangles + 1u, sizeof(real));
    L->n = 0;
    double total = 0.0;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        const dr_vec3 a = dr_mesh_vertex(m, m->indices[3 * t]), b = dr_mesh_vertex(m, m->indices[3 * t + 1]),
                      e = dr_mesh_vertex(m, m->indices[3 * t + 2]);
        const dr_vec3 cr = dr_cross(dr_sub(b, a), dr_sub(e, a));
        const double len = dr_length(cr);
        const dr_vec3 n = len > 0.0 ? dr_scale(cr, 1.0 / len) : dr_v3(0, 0, 1);
        const struct dr_material *mat = &sc->materials[m->material[t]];
        const dr_vec3 le = dr_scale(mat->emissive_factor, mat->emissive_strength);
        td.nx[t] = (real)n.x, td.ny[t] = (real)n.y, td.nz[t] = (real)n.z;
        td.ar[t] = (real)(mat->base_color.x * M_1_PI), td.ag[t] = (real)(mat->base_color.y * M_1_PI),
        td.ab[t] = (real)(mat->base_color.z * M_1_PI);
        td.er[t] = (real)le.x, td.eg[t] = (real)le.y, td.eb[t] = (real)le.z;
        if (le.x + le.y + le.z > 0.0 && len > 0.0) {
            if (L->n == MAX_LIGHTS) {
                fprintf(stderr, "soa_floor: more than %d emissive triangles\n", MAX_LIGHTS);
                exit(1);
            }
            const int k = L->n++;
            L->p0x[k] = (real)a.x, L->p0y[k] = (real)a.y, L->p0z[k] = (real)a.z;
            L->e1x[k] = (real)(b.x - a.x), L->e1y[k] = (real)(b.y - a.y), L->e1z[k] = (real)(b.z - a.z);
            L->e2x[k] = (real)(e.x - a.x), L->e2y[k] = (real)(e.y - a.y), L->e2z[k] = (real)(e.z - a.z);
            L->nx[k] = (real)n.x, L->ny[k] = (real)n.y, L->nz[k] = (real)n.z;
            L->er[k] = (real)le.x, L->eg[k] = (real)le.y, L->eb[k] = (real)le.z;
            total += 0.5 * len;
            L->cdf[k] = (real)total;
        }
    }
    for (int k = 0; k < L->n; k++)
        L->cdf[k] /= (real)total;
    L->total_area = (real)total;
    return td;
}

int main(int argc, char **argv)
{
    struct path_args args;
    struct dr_scene *sc;
    int rc = path_args_open(argc, argv, "soa_floor", 64, &args, &sc);
    if (rc)
        return rc;
    const int W = args.width, H = args.height, S = args.spp, T = args.threads, D = args.max_depth;
    struct ctx c = {.sc = sc, .W = W, .H = H, .S = S, .D = D};
    const struct dr_camera cam = sc->n_cameras > 0 ? sc->cameras[0] : dr_camera_default(sc);
    c.view = dr_camera_view(&cam, W, H);
    c.td = triangle_data(sc, &c.L);
    RTCDevice dev = rtcNewDevice(NULL);
    c.rtc = bench_raw_scene(dev, sc);
#if FLOOR_DR_ACCEL
    c.acc = dr_accel_create_scene(sc);
    float *v0 = malloc(sizeof(float) * 6 * (sc->mesh.n_triangles + 1u));
    for (uint32_t t = 0; t < sc->mesh.n_triangles; t++) {
        const float *p = sc->mesh.positions + 3 * (size_t)sc->mesh.indices[3 * t];
        v0[6 * t] = p[0], v0[6 * t + 1] = p[1], v0[6 * t + 2] = p[2];
        v0[6 * t + 3] = (float)c.td.nx[t], v0[6 * t + 4] = (float)c.td.ny[t], v0[6 * t + 5] = (float)c.td.nz[t];
    }
    c.v0 = v0;
    if (!c.acc) {
        fprintf(stderr, "soa_floor: %s: %s\n", argv[1], dr_last_error());
        return 1;
    }
#endif
    const uint64_t total = (uint64_t)W * H * S;
    c.n_waves = (int)((total + WAVE - 1) / WAVE);
    struct worker wk[64];
    pthread_t id[64];
    double best = INFINITY, mean = 0.0;
    long rays[2] = {0, 0};
    for (int rep = 0; rep < 4; rep++) {   /* a warm-up, then the best of three */
        atomic_store(&c.next_wave, 0);
        for (int t = 0; t < T; t++)
            wk[t] = (struct worker){&c, {0, 0}, calloc((size_t)W * H * 3, sizeof(real))};
        const double t0 = dr_clock_seconds();
        for (int t = 1; t < T; t++)
            pthread_create(&id[t], NULL, work, &wk[t]);
        work(&wk[0]);
        for (int t = 1; t < T; t++)
            pthread_join(id[t], NULL);
        const double sec = dr_clock_seconds() - t0;
        if (rep > 0)
            best = fmin(best, sec);
        double sum = 0.0;
        rays[0] = rays[1] = 0;
        for (int t = 0; t < T; t++) {
            for (size_t k = 0; k < (size_t)W * H * 3; k++)
                sum += wk[t].film[k];
            rays[0] += wk[t].rays[0], rays[1] += wk[t].rays[1];
            free(wk[t].film);
        }
        mean = sum / ((double)W * H * 3 * S);
    }
    printf("{\"scene\": \"%s\", \"width\": %d, \"height\": %d, \"spp\": %d, \"threads\": %d, \"max_depth\": %d, "
           "\"seconds\": %.4f, \"rays\": {\"extension\": %ld, \"shadow\": %ld, \"total\": %ld}, "
           "\"rays_per_sample\": {\"extension\": %.3f, \"shadow\": %.3f}, \"image_mean\": %.6f}\n",
           argv[1], W, H, S, T, D, best, rays[0], rays[1], rays[0] + rays[1], rays[0] / (double)total - 1.0,
           rays[1] / (double)total, mean);
    rtcReleaseScene(c.rtc);
#if FLOOR_DR_ACCEL
    dr_accel_destroy(c.acc);
    free((void *)c.v0);
#endif
    rtcReleaseDevice(dev);
    real *fields[9] = {c.td.nx, c.td.ny, c.td.nz, c.td.ar, c.td.ag, c.td.ab, c.td.er, c.td.eg, c.td.eb};
    for (int k = 0; k < 9; k++)
        free(fields[k]);
    dr_scene_destroy(sc);
    return 0;
}
