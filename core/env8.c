/* The environment map eight lanes at once (env8.h). Each function names
 * the scalar one in lights.c it mirrors; keep them in step (test_render's
 * map-lit boxes fail otherwise). */
#include "env8.h"

#include "cdf.h"
#include "image.h"
#include "simd_trig.h"
#include "texture8.h"

const struct dr_texture dr_env_texture = {0, DR_WRAP_REPEAT, DR_WRAP_CLAMP};

/* dr_env_dir_to_uv. */
void dr_env8_dir_to_uv(dr_v3x8 d, dr_f8 *u, dr_f8 *v)
{
    *u = 0.5 + dr_f8_atan2(d.x, -d.z) * (0.5 / M_PI);
    *v = dr_f8_acos(dr_f8_clamp(d.y, -1.0, 1.0)) * DR_INV_PI;
}

/* dr_env_uv_to_dir: phi = 2 pi (u - 1/2), theta = pi v. */
DR_SIMD_INLINE dr_v3x8 uv_to_dir(dr_f8 u, dr_f8 v)
{
    dr_f8 sin_phi, cos_phi, sin_theta, cos_theta;
    dr_f8_sincos_turn(u - 0.5, &sin_phi, &cos_phi);
    dr_f8_sincos_turn(0.5 * v, &sin_theta, &cos_theta);
    return (dr_v3x8){sin_theta * sin_phi, cos_theta, -sin_theta * cos_phi};
}

/* env_radiance_uv: colour x strength x the map's texel blend at (u, v)
 * (the blend also into *px). */
static dr_v3x8 radiance_uv(const struct dr_scene *s, dr_m8 on, dr_f8 u, dr_f8 v, dr_v3x8 *px)
{
    const dr_vec3 k = dr_scale(s->env.color, s->env.strength);
    *px = dr_texture8_rgb(&dr_env_texture, &s->env.map, on, u, v, true);
    return (dr_v3x8){k.x * px->x, k.y * px->y, k.z * px->z};
}

/* dr_env_cell, eight lanes, as integers for the table reads. */
DR_SIMD_INLINE void cells(dr_f8 t, int n, int64_t c[DR_SIMD_W])
{
    dr_f8 f = dr_f8_floor(t * n);
    f = dr_f8_sel(dr_f8_eq(f, f), dr_f8_clamp(f, 0.0, n - 1.0), dr_f8s(0.0));
    for (int i = 0; i < DR_SIMD_W; i++)
        c[i] = (int64_t)f[i];
}

/* env_pdf_uv: the piecewise-constant density of cell (x, y) over the
 * sphere, with the row-centre sine the weights were built with (lanes off:
 * 0; every lane reads a cell, cells() keeping them in the map). */
static dr_f8 pdf_uv(const struct dr_env_tables *t, dr_m8 on, dr_f8 u, dr_f8 v)
{
    int64_t x[DR_SIMD_W], y[DR_SIMD_W];
    cells(u, t->w, x);
    cells(v, t->h, y);
    const double *row[DR_SIMD_W];
    for (int i = 0; i < DR_SIMD_W; i++)
        row[i] = t->conditional + (size_t)y[i] * (size_t)(t->w + 1);
#define DM(i) (t->marginal[y[i] + 1] - t->marginal[y[i]])
#define DC(i) (row[i][x[i] + 1] - row[i][x[i]])
#define ST(i) t->row_sin[y[i]]
    const dr_f8 dm = DR_LANES8(dr_f8, DM), dc = DR_LANES8(dr_f8, DC), st = dr_f8_sel(on, DR_LANES8(dr_f8, ST), dr_f8s(0.0));
#undef DM
#undef DC
#undef ST
    const dr_f8 p_uv = dm * dc * (double)t->w * (double)t->h;
    return dr_f8_sel(dr_f8_gt(st, dr_f8s(0.0)), p_uv / (2.0 * M_PI * M_PI * st), dr_f8s(0.0));
}

dr_v3x8 dr_env8_radiance_pdf(const struct dr_scene *s, const struct dr_env_tables *t, dr_m8 on, dr_v3x8 dir,
                             dr_f8 *pdf, struct dr_env8_lookup *at)
{
    dr_f8 u, v;
    dr_env8_dir_to_uv(dir, &u, &v);
    if (pdf)   /* dr_light_pdf_env's: the pick times the map's density */
        *pdf = t->pick * pdf_uv(t, on, u, v);
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    dr_v3x8 px;
    const dr_v3x8 L = dr_v3x8_sel(on, radiance_uv(s, on, u, v, &px), zero);
    if (at)
        *at = (struct dr_env8_lookup){u, v, px};
    return L;
}

/* sample_env's two searches: each lane's row y by the marginal cdf at u1,
 * then its column x by that row's conditional cdf at u2, with the cdf
 * values either side of each (lanes without a row with weight, py <= 0,
 * search no column). Each row is a cache miss in a large map: the rows
 * are asked for together before any is searched (the guide entry exactly;
 * the cdf at the bucket's own index, where an even row's answer lies, a
 * guess elsewhere). */
static void find_cells(const struct dr_env_tables *t, dr_m8 on, dr_f8 u1, dr_f8 u2, int64_t x[DR_SIMD_W],
                       int64_t y[DR_SIMD_W], dr_f8 *m0, dr_f8 *py, dr_f8 *r0, dr_f8 *px)
{
    const size_t stride = (size_t)t->w + 1;
    for (int i = 0; i < DR_SIMD_W; i++) {
        x[i] = y[i] = 0;
        if (!on[i])
            continue;
        y[i] = dr_cdf_find_guided(t->marginal, t->h, t->marginal_guide, t->h, u1[i]);
        (*m0)[i] = t->marginal[y[i]];
        (*py)[i] = t->marginal[y[i] + 1] - t->marginal[y[i]];
        const int64_t j = dr_cdf_guide_bucket(t->w, u2[i]);
        if (j >= 0) {
            __builtin_prefetch(t->conditional_guide + (size_t)y[i] * stride + (size_t)j);
            __builtin_prefetch(t->conditional + (size_t)y[i] * stride + (size_t)j);
        }
    }
    for (int i = 0; i < DR_SIMD_W; i++) {
        if (!on[i] || !((*py)[i] > 0.0))
            continue;
        const double *row = t->conditional + (size_t)y[i] * stride;
        x[i] = dr_cdf_find_guided(row, t->w, t->conditional_guide + (size_t)y[i] * stride, t->w, u2[i]);
        (*r0)[i] = row[x[i]];
        (*px)[i] = row[x[i] + 1] - row[x[i]];
    }
}

dr_m8 dr_env8_sample(const struct dr_scene *s, const struct dr_env_tables *t, dr_m8 on, dr_f8 u1, dr_f8 u2,
                     dr_m8 keep_black, dr_v3x8 *wi, dr_v3x8 *radiance, dr_f8 *pdf, struct dr_env8_lookup *at)
{
    if (!(t->pick > 0.0))   /* (dr_light_sample: an entry never picked samples nothing) */
        return (dr_m8){0};
    int64_t x[DR_SIMD_W], y[DR_SIMD_W];
    dr_f8 m0 = dr_f8s(0.0), py = dr_f8s(0.0), r0 = dr_f8s(0.0), px = dr_f8s(0.0);
    find_cells(t, on, u1, u2, x, y, &m0, &py, &r0, &px);
    dr_m8 ok = on & dr_f8_gt(py, dr_f8s(0.0)) & dr_f8_gt(px, dr_f8s(0.0));
    const dr_f8 one = dr_f8s(1.0);
    const dr_f8 dv = (u1 - m0) / dr_f8_sel(ok, py, one), du = (u2 - r0) / dr_f8_sel(ok, px, one);
#define XF(i) (double)x[i]
#define YF(i) (double)y[i]
#define ST(i) t->row_sin[y[i]]
    const dr_f8 xf = DR_LANES8(dr_f8, XF), yf = DR_LANES8(dr_f8, YF), st = dr_f8_sel(ok, DR_LANES8(dr_f8, ST), dr_f8s(0.0));
#undef XF
#undef YF
#undef ST
    const dr_f8 u = (xf + dr_f8_clamp(du, 0.0, 1.0)) / (double)t->w, v = (yf + dr_f8_clamp(dv, 0.0, 1.0)) / (double)t->h;
    *wi = uv_to_dir(u, v);
    const dr_f8 p = dr_f8_sel(dr_f8_gt(st, dr_f8s(0.0)),
                              py * px * (double)t->w * (double)t->h / (2.0 * M_PI * M_PI * st), dr_f8s(0.0));
    ok &= dr_f8_gt(p, dr_f8s(0.0));
    *pdf = p * t->pick;
    /* dr_env_radiance at the direction (its map coordinates computed from
     * it again, as the scalar sample does) */
    *radiance = dr_env8_radiance_pdf(s, t, ok, *wi, NULL, at);
    return ok & (~dr_v3x8_is_black(*radiance) | keep_black);
}
