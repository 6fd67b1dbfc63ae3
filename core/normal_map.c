/* Normal maps: tangent generation and the perturbed shading normal (normal_map.h). */
#include "normal_map.h"

#include <stdlib.h>

#include "error.h"
#include "image.h"

static dr_vec3 vertex_vec3(const float *a, uint32_t v)
{
    return dr_v3(a[3 * (size_t)v], a[3 * (size_t)v + 1], a[3 * (size_t)v + 2]);
}

/* The corner's normal: the vertex normal when the triangle has one, else the face's. */
static dr_vec3 corner_normal(const struct dr_mesh *m, uint32_t t, uint32_t v, dr_vec3 face_n)
{
    if (!(m->flags[t] & DR_TRI_HAS_NORMALS))
        return face_n;
    dr_vec3 n = vertex_vec3(m->normals, v);
    double l = dr_length(n);
    return l > 0.0 ? dr_scale(n, 1.0 / l) : face_n;
}

/* Adds triangle t's corners to acc (xyz: angle-weighted tangent, w: angle-weighted sign). */
static void accumulate_triangle(const struct dr_mesh *m, uint32_t t, const uint8_t *gen, double *acc)
{
    const uint32_t *idx = m->indices + 3 * (size_t)t;
    if (!gen[idx[0]] && !gen[idx[1]] && !gen[idx[2]])
        return;
    dr_vec3 p[3];
    double uv[3][2];
    for (int k = 0; k < 3; k++) {
        p[k] = dr_mesh_vertex(m, idx[k]);
        uv[k][0] = m->uvs[2 * (size_t)idx[k]];
        uv[k][1] = m->uvs[2 * (size_t)idx[k] + 1];
    }
    dr_vec3 e1 = dr_sub(p[1], p[0]), e2 = dr_sub(p[2], p[0]);
    double du1 = uv[1][0] - uv[0][0], dv1 = uv[1][1] - uv[0][1];
    double du2 = uv[2][0] - uv[0][0], dv2 = uv[2][1] - uv[0][1];
    double det = du1 * dv2 - du2 * dv1;
    dr_vec3 fn = dr_cross(e1, e2);
    double fl = dr_length(fn);
    if (det == 0.0 || !isfinite(det) || !(fl > 0.0))
        return;   /* degenerate UVs or area: this triangle says nothing */
    fn = dr_scale(fn, 1.0 / fl);
    /* dP/du and dP/dv: [e1 e2] = [dP/du dP/dv] [du1 du2; dv1 dv2] */
    dr_vec3 tu = dr_scale(dr_sub(dr_scale(e1, dv2), dr_scale(e2, dv1)), 1.0 / det);
    dr_vec3 tv = dr_scale(dr_sub(dr_scale(e2, du1), dr_scale(e1, du2)), 1.0 / det);
    double tl = dr_length(tu);
    if (!(tl > 0.0) || !isfinite(tl))
        return;
    tu = dr_scale(tu, 1.0 / tl);
    for (int k = 0; k < 3; k++) {
        uint32_t v = idx[k];
        if (!gen[v])
            continue;
        dr_vec3 n = corner_normal(m, t, v, fn);
        dr_vec3 tp = dr_sub(tu, dr_scale(n, dr_dot(n, tu)));
        double l = dr_length(tp);
        if (!(l > 1e-12))
            continue;   /* dP/du along this corner's normal */
        tp = dr_scale(tp, 1.0 / l);
        dr_vec3 a = dr_sub(p[(k + 1) % 3], p[k]), b = dr_sub(p[(k + 2) % 3], p[k]);
        double la = dr_length(a), lb = dr_length(b);
        double angle = la > 0.0 && lb > 0.0 ? acos(dr_clamp(dr_dot(a, b) / (la * lb), -1.0, 1.0)) : 0.0;
        /* glTF: bitangent = cross(n, t) w points to the image's +Y, i.e. -dP/dv */
        double sign = dr_dot(dr_cross(n, tp), tv) <= 0.0 ? 1.0 : -1.0;
        double *ac = acc + 4 * (size_t)v;
        ac[0] += angle * tp.x;
        ac[1] += angle * tp.y;
        ac[2] += angle * tp.z;
        ac[3] += angle * sign;
    }
}

int dr_mesh_generate_tangents(struct dr_mesh *m)
{
    size_t nv = m->n_vertices;
    double *acc = calloc(4 * nv + 4, sizeof(double));
    uint8_t *gen = calloc(nv + 1, 1);
    if (!acc || !gen) {
        free(acc);
        free(gen);
        return -1;
    }
    for (size_t v = 0; v < nv; v++)
        gen[v] = m->tangents[4 * v + 3] == 0.0f;
    for (uint32_t t = 0; t < m->n_triangles; t++)
        if (m->flags[t] & DR_TRI_HAS_UVS)
            accumulate_triangle(m, t, gen, acc);
    for (size_t v = 0; v < nv; v++) {
        const double *a = acc + 4 * v;
        double l = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        if (!gen[v] || !(l > 0.0))
            continue;   /* supplied, or no triangle gave a tangent: stays w = 0 */
        float *t = m->tangents + 4 * v;
        t[0] = (float)(a[0] / l);
        t[1] = (float)(a[1] / l);
        t[2] = (float)(a[2] / l);
        t[3] = a[3] < 0.0 ? -1.0f : 1.0f;
    }
    free(acc);
    free(gen);
    return 0;
}

int dr_mesh_prepare_tangents(struct dr_scene *s)
{
    struct dr_mesh *m = &s->mesh;
    bool needed = false;
    for (uint32_t t = 0; t < m->n_triangles && !needed; t++)
        needed = dr_material_needs_tangents(&s->materials[m->material[t]]);
    if (!needed)
        return 0;
    if (!m->tangents) {
        m->tangents = calloc(4 * (size_t)m->n_vertices + 4, sizeof(float));
        if (!m->tangents) {
            dr_set_error("out of memory");
            return DR_ERR_NOMEM;
        }
    }
    if (dr_mesh_generate_tangents(m) != 0) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    return 0;
}

/* +1, or -1 when the loader's interpolated normal was flipped onto ng's side
 * (dr_hit_compute): the authored tangent frame belongs to the unflipped one. */
static double authored_side(const struct dr_mesh *m, const struct dr_hit *hit, const uint32_t *idx)
{
    if (!(m->flags[hit->tri] & DR_TRI_HAS_NORMALS))
        return 1.0;
    double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    dr_vec3 n = dr_add(dr_add(dr_scale(vertex_vec3(m->normals, idx[0]), b0), dr_scale(vertex_vec3(m->normals, idx[1]), b1)),
                       dr_scale(vertex_vec3(m->normals, idx[2]), b2));
    return dr_dot(n, hit->ng) < 0.0 ? -1.0 : 1.0;
}

/* The interpolated tangent at hit made orthonormal to hit->ns (*t) and the
 * bitangent's sign (*w); false where there is none: no tangents or UVs, a
 * corner without one, or a tangent along the normal (degenerate UVs). */
static bool hit_tangent(const struct dr_mesh *m, const struct dr_hit *hit, const uint32_t *idx, dr_vec3 *t_out,
                        double *w)
{
    if (!m->tangents || !(m->flags[hit->tri] & DR_TRI_HAS_UVS))
        return false;
    const float *t0 = m->tangents + 4 * (size_t)idx[0], *t1 = m->tangents + 4 * (size_t)idx[1],
                *t2 = m->tangents + 4 * (size_t)idx[2];
    if (t0[3] == 0.0f || t1[3] == 0.0f || t2[3] == 0.0f)
        return false;
    double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    dr_vec3 n = hit->ns;
    dr_vec3 t = dr_v3(b0 * t0[0] + b1 * t1[0] + b2 * t2[0], b0 * t0[1] + b1 * t1[1] + b2 * t2[1],
                      b0 * t0[2] + b1 * t1[2] + b2 * t2[2]);
    *w = b0 * t0[3] + b1 * t1[3] + b2 * t2[3] < 0.0 ? -1.0 : 1.0;
    t = dr_sub(t, dr_scale(n, dr_dot(n, t)));   /* Gram-Schmidt against the normal */
    double tl = dr_length(t);
    if (!(tl > 1e-6))
        return false;
    *t_out = dr_scale(t, 1.0 / tl);
    return true;
}

bool dr_hit_tangent_frame(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 *t, dr_vec3 *b)
{
    const uint32_t *idx = s->mesh.indices + 3 * (size_t)hit->tri;
    double w;
    if (!hit_tangent(&s->mesh, hit, idx, t, &w))
        return false;
    /* B_a = w cross(N_a, T) with N_a = side ns, the authored normal */
    *b = dr_scale(dr_cross(hit->ns, *t), w * authored_side(&s->mesh, hit, idx));
    return true;
}

/* t = u / |u|, u = t_raw - ns (ns . t_raw); b = k (ns x t), k = w side:
 *   d ns += k (t x d_b),  d t += k (d_b x ns),
 *   d u = (d t - t (t . d t)) / |u|,
 *   d t_raw = d u - ns (ns . d u),  d ns -= (ns . t_raw) d u + t_raw (ns . d u). */
void d_hit_tangent_frame(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 d_t, dr_vec3 d_b,
                         struct dr_d_hit *d_hit)
{
    const struct dr_mesh *m = &s->mesh;
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    dr_vec3 t;
    double w;
    if (!hit_tangent(m, hit, idx, &t, &w))
        return;
    const float *t0 = m->tangents + 4 * (size_t)idx[0], *t1 = m->tangents + 4 * (size_t)idx[1],
                *t2 = m->tangents + 4 * (size_t)idx[2];
    const double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    const dr_vec3 raw = dr_v3(b0 * t0[0] + b1 * t1[0] + b2 * t2[0], b0 * t0[1] + b1 * t1[1] + b2 * t2[1],
                              b0 * t0[2] + b1 * t1[2] + b2 * t2[2]);
    const dr_vec3 n = hit->ns, u = dr_sub(raw, dr_scale(n, dr_dot(n, raw)));
    const double k = w * authored_side(m, hit, idx), ul = dr_length(u);
    dr_vec3 d_n = dr_scale(dr_cross(t, d_b), k);
    d_t = dr_add(d_t, dr_scale(dr_cross(d_b, n), k));
    const dr_vec3 d_u = dr_scale(dr_sub(d_t, dr_scale(t, dr_dot(t, d_t))), 1.0 / ul);
    d_hit->tangent = dr_add(d_hit->tangent, dr_sub(d_u, dr_scale(n, dr_dot(n, d_u))));
    d_n = dr_sub(d_n, dr_add(dr_scale(d_u, dr_dot(n, raw)), dr_scale(raw, dr_dot(n, d_u))));
    d_hit->ns = dr_add(d_hit->ns, d_n);
}

void dr_normal_map_apply(const struct dr_scene *s, struct dr_hit *hit)
{
    const struct dr_material *mat = &s->materials[hit->material];
    const struct dr_mesh *m = &s->mesh;
    if (mat->normal_tex.texture < 0)
        return;
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    dr_vec3 t, n = hit->ns;
    double w;
    if (!hit_tangent(m, hit, idx, &t, &w))
        return;   /* no tangent frame here: the interpolated normal stays */
    const struct dr_texture *tex = &s->textures[mat->normal_tex.texture];
    double px[4], uv[2];
    dr_texref_uv(m, &mat->normal_tex, hit, uv);   /* its TEXCOORD set and KHR_texture_transform */
    dr_texture_eval(tex, &s->images[tex->image], uv[0], uv[1], false, px);
    double x = (2.0 * px[0] - 1.0) * mat->normal_scale, y = (2.0 * px[1] - 1.0) * mat->normal_scale;
    double z = 2.0 * px[2] - 1.0;
    /* with ns = side * N_authored: side (x T + y B_a + z N_a) = side x T + y w (ns x T) + z ns */
    dr_vec3 p = dr_add(dr_add(dr_scale(t, authored_side(m, hit, idx) * x), dr_scale(dr_cross(n, t), w * y)),
                       dr_scale(n, z));
    double pl = dr_length(p);
    if (pl > 0.0 && isfinite(pl))
        hit->ns = dr_scale(p, 1.0 / pl);
}

/* One root of ensure_valid_reflection: the normal (x, z) in the (X, ng) plane. */
static bool root_valid(double z2)
{
    return z2 > 1e-5 && z2 <= 1.0 + 1e-5;
}

dr_vec3 dr_shading_normal_valid(dr_vec3 ng, dr_vec3 wo, dr_vec3 n)
{
    double iz = dr_dot(wo, ng);
    dr_vec3 r = dr_sub(dr_scale(n, 2.0 * dr_dot(n, wo)), wo);
    /* a reflection may always be at least as shallow as the arriving ray */
    double thr = dr_min(0.9 * iz, 0.01);
    if (dr_dot(ng, r) >= thr)
        return n;
    /* frame: ng is z, x is n's component orthogonal to ng; find n' in that
     * plane with dot(reflect(wo, n'), ng) = thr */
    dr_vec3 x = dr_sub(n, dr_scale(ng, dr_dot(n, ng)));
    double xl = dr_length(x);
    if (!(xl > 1e-12))
        return ng;
    x = dr_scale(x, 1.0 / xl);
    double ix = dr_dot(wo, x), ix2 = ix * ix, iz2 = iz * iz, a = ix2 + iz2;
    if (!(a > 1e-24))
        return ng;
    double b = sqrt(dr_max(0.0, ix2 * (a - thr * thr))), c = iz * thr + a;
    double z1 = 0.5 / a * (b + c), z2 = 0.5 / a * (c - b);
    bool v1 = root_valid(z1), v2 = root_valid(z2);
    double nz2;
    if (v1 && v2) {
        double n1x = sqrt(dr_max(0.0, 1.0 - z1)), n1z = sqrt(z1);
        double n2x = sqrt(dr_max(0.0, 1.0 - z2)), n2z = sqrt(z2);
        double r1 = 2.0 * (n1x * ix + n1z * iz) * n1z - iz, r2 = 2.0 * (n2x * ix + n2z * iz) * n2z - iz;
        bool ok1 = r1 >= 1e-5, ok2 = r2 >= 1e-5;
        /* both valid: the shallower reflection is closer to the input */
        nz2 = ok1 && ok2 ? (r1 < r2 ? z1 : z2) : (r1 > r2 ? z1 : z2);
    } else if (v1 || v2) {
        nz2 = v1 ? z1 : z2;
    } else {
        return ng;
    }
    dr_vec3 out = dr_add(dr_scale(x, sqrt(dr_max(0.0, 1.0 - nz2))), dr_scale(ng, sqrt(nz2)));
    double ol = dr_length(out);
    if (!(ol > 0.0) || !isfinite(ol))
        return ng;
    out = dr_scale(out, 1.0 / ol);
    /* at grazing wo (wo.ng ~ 1e-9) the roots lose the last bits: a result a
     * rounding error below wo, or reflecting below ng, falls back to ng */
    double ow = dr_dot(out, wo);
    return ow > 0.0 && 2.0 * ow * dr_dot(out, ng) - iz >= 0.0 ? out : ng;
}
