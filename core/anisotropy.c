/* KHR_materials_anisotropy's shading frame (anisotropy.h). */
#include "anisotropy.h"

#include "image.h"
#include "normal_map.h"

/* The direction before normalisation, d = x t + y b, and its parts: (x, y)
 * the texel's RG (or (1, 0)) turned by the rotation, (t, b) the tangent
 * frame; false where there is no tangent frame. */
struct raw_direction {
    dr_vec3 t, b, d;
    double x, y;
};

static bool raw_direction(const struct dr_scene *s, const struct dr_hit *hit, struct raw_direction *r)
{
    const struct dr_material *m = &s->materials[hit->material];
    if (!m->anisotropic || !dr_hit_tangent_frame(s, hit, &r->t, &r->b))
        return false;
    double x = 1.0, y = 0.0;
    const struct dr_texref *tr = dr_material_anisotropy_tex(m);
    if (tr) {   /* RG: the direction in [-1, 1]^2 (linear data) */
        const struct dr_texture *tex = &s->textures[tr->texture];
        double px[4], uv[2];
        dr_texref_uv(&s->mesh, tr, hit, uv);
        dr_texture_eval(tex, &s->images[tex->image], uv[0], uv[1], false, px);
        x = 2.0 * px[0] - 1.0;
        y = 2.0 * px[1] - 1.0;
    }
    if (m->anisotropy_rotation != 0.0) {   /* counter-clockwise: from T towards B */
        double c = cos(m->anisotropy_rotation), sn = sin(m->anisotropy_rotation);
        double xr = c * x - sn * y;
        y = sn * x + c * y;
        x = xr;
    }
    r->x = x, r->y = y;
    r->d = dr_add(dr_scale(r->t, x), dr_scale(r->b, y));
    return true;
}

bool dr_anisotropy_direction(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 *dir)
{
    struct raw_direction r;
    if (!raw_direction(s, hit, &r))
        return false;
    double l = dr_length(r.d);
    if (!(l > 1e-9) || !isfinite(l))
        return false;   /* a texel of no direction (0.5, 0.5) */
    *dir = dr_scale(r.d, 1.0 / l);
    return true;
}

/* dir = d / |d|, d = x t + y b, (x, y) = R (2 texel.rg - 1):
 *   d d = (d dir - dir (dir . d dir)) / |d|; d t = x d d, d b = y d d,
 *   d (x, y) = (t . d d, b . d d), turned back by R^T to the texel's RG. */
static void d_anisotropy_direction(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 d_dir,
                                   struct dr_d_hit *d_hit)
{
    struct raw_direction r;
    if (!raw_direction(s, hit, &r))
        return;
    const double l = dr_length(r.d);
    const dr_vec3 dir = dr_scale(r.d, 1.0 / l);
    const dr_vec3 dd = dr_scale(dr_sub(d_dir, dr_scale(dir, dr_dot(dir, d_dir))), 1.0 / l);
    d_hit_tangent_frame(s, hit, dr_scale(dd, r.x), dr_scale(dd, r.y), d_hit);
    const struct dr_material *m = &s->materials[hit->material];
    const struct dr_texref *tr = dr_material_anisotropy_tex(m);
    if (!tr)
        return;
    double dx = dr_dot(r.t, dd), dy = dr_dot(r.b, dd);
    if (m->anisotropy_rotation != 0.0) {
        const double c = cos(m->anisotropy_rotation), sn = sin(m->anisotropy_rotation), dxr = c * dx + sn * dy;
        dy = -sn * dx + c * dy;
        dx = dxr;
    }
    const struct dr_texture *tex = &s->textures[tr->texture];
    double uv[2], d_uv[2] = {0.0, 0.0};
    const double d_out[4] = {2.0 * dx, 2.0 * dy, 0.0, 0.0};
    dr_texref_uv(&s->mesh, tr, hit, uv);
    d_texture_eval_uv(tex, &s->images[tex->image], uv[0], uv[1], false, d_out, &d_uv[0], &d_uv[1]);
    d_texref_uv(tr, d_uv, d_hit);
}

bool dr_anisotropy_frame(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 n, dr_frame *f)
{
    dr_vec3 d;
    *f = dr_frame_from_normal(n);
    if (!dr_anisotropy_direction(s, hit, &d))
        return false;
    /* n may differ from the normal the tangent was made orthogonal to (the
     * side it faces, a bent normal): project again */
    d = dr_sub(d, dr_scale(n, dr_dot(n, d)));
    double l = dr_length(d);
    if (!(l > 1e-6))
        return false;
    f->s = dr_scale(d, 1.0 / l);
    f->t = dr_cross(n, f->s);   /* s x t = n, as dr_frame_from_normal's */
    return true;
}

/* s = g / |g|, g = dir - n (n . dir), t = n x s:
 *   d s += d_t x n, d n += s x d_t,
 *   d g = (d s - s (s . d s)) / |g|,
 *   d dir = d g - n (n . d g), d n -= (n . dir) d g + dir (n . d g). */
bool d_anisotropy_frame(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 n, const dr_frame *d_f,
                        dr_vec3 *d_n, struct dr_d_hit *d_hit)
{
    dr_vec3 dir;
    if (!dr_anisotropy_direction(s, hit, &dir))
        return false;
    const dr_vec3 g = dr_sub(dir, dr_scale(n, dr_dot(n, dir)));
    const double l = dr_length(g);
    if (!(l > 1e-6))
        return false;   /* (dr_anisotropy_frame's fallback) */
    const dr_vec3 fs = dr_scale(g, 1.0 / l);
    const dr_vec3 d_s = dr_add(d_f->s, dr_cross(d_f->t, n));
    *d_n = dr_add(*d_n, dr_cross(fs, d_f->t));
    const dr_vec3 d_g = dr_scale(dr_sub(d_s, dr_scale(fs, dr_dot(fs, d_s))), 1.0 / l);
    *d_n = dr_sub(*d_n, dr_add(dr_scale(d_g, dr_dot(n, dir)), dr_scale(dir, dr_dot(n, d_g))));
    d_anisotropy_direction(s, hit, dr_sub(d_g, dr_scale(n, dr_dot(n, d_g))), d_hit);
    return true;
}
