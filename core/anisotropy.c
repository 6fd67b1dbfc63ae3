/* KHR_materials_anisotropy's shading frame (anisotropy.h). */
#include "anisotropy.h"

#include "image.h"
#include "normal_map.h"

bool dr_anisotropy_direction(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 *dir)
{
    const struct dr_material *m = &s->materials[hit->material];
    dr_vec3 t, b;
    if (!m->anisotropic || !dr_hit_tangent_frame(s, hit, &t, &b))
        return false;
    double x = 1.0, y = 0.0;
    const struct dr_texref *r = dr_material_anisotropy_tex(m);
    if (r) {   /* RG: the direction in [-1, 1]^2 (linear data) */
        const struct dr_texture *tex = &s->textures[r->texture];
        double px[4], uv[2];
        dr_texref_uv(&s->mesh, r, hit, uv);
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
    dr_vec3 d = dr_add(dr_scale(t, x), dr_scale(b, y));
    double l = dr_length(d);
    if (!(l > 1e-9) || !isfinite(l))
        return false;   /* a texel of no direction (0.5, 0.5) */
    *dir = dr_scale(d, 1.0 / l);
    return true;
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
