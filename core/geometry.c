#include "geometry.h"

#include <stdlib.h>

/* The hit's place on triangle tri at barycentrics (b1, b2): the position,
 * the geometric normal and the ray offset, all that a medium's boundary
 * crossing reads (dr_hit_locate). */
static void place(const struct dr_mesh *m, int64_t tri, double b1, double b2, struct dr_hit *hit)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    const double *ne = m->tri_normal_eps + 4 * (size_t)tri;
    double b0 = 1.0 - b1 - b2;
    const float *p0 = m->positions + 3 * (size_t)idx[0], *p1 = m->positions + 3 * (size_t)idx[1],
                *p2 = m->positions + 3 * (size_t)idx[2];
    hit->tri = tri;
    hit->b1 = b1;
    hit->b2 = b2;
    hit->p = dr_v3(b0 * p0[0] + b1 * p1[0] + b2 * p2[0], b0 * p0[1] + b1 * p1[1] + b2 * p2[1],
                   b0 * p0[2] + b1 * p1[2] + b2 * p2[2]);
    hit->ng = dr_v3(ne[0], ne[1], ne[2]);
    hit->eps = ne[3];
    hit->ns = hit->ng;
    hit->uv[0] = hit->uv[1] = 0.0;
    hit->material = m->material[tri];
}

/* What shading reads besides the place: the interpolated shading normal and
 * TEXCOORD_0. */
void dr_hit_shade(const struct dr_mesh *m, struct dr_hit *hit)
{
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    const double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    uint8_t flags = m->flags[hit->tri];
    if (flags & DR_TRI_HAS_NORMALS) {
        const float *n0 = m->normals + 3 * (size_t)idx[0], *n1 = m->normals + 3 * (size_t)idx[1],
                    *n2 = m->normals + 3 * (size_t)idx[2];
        dr_vec3 ns = dr_v3(b0 * n0[0] + b1 * n1[0] + b2 * n2[0], b0 * n0[1] + b1 * n1[1] + b2 * n2[1],
                           b0 * n0[2] + b1 * n1[2] + b2 * n2[2]);
        double l2 = dr_dot(ns, ns);
        if (l2 > 0.0) {
            ns = dr_scale(ns, 1.0 / sqrt(l2));
            /* Authored normals may face away from the winding; keep them on
             * the geometric front side so "front" means one thing. */
            hit->ns = dr_dot(ns, hit->ng) < 0.0 ? dr_neg(ns) : ns;
        }
    }
    if (flags & DR_TRI_HAS_UVS) {
        const float *t0 = m->uvs + 2 * (size_t)idx[0], *t1 = m->uvs + 2 * (size_t)idx[1],
                    *t2 = m->uvs + 2 * (size_t)idx[2];
        hit->uv[0] = b0 * t0[0] + b1 * t1[0] + b2 * t2[0];
        hit->uv[1] = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
    }
}

/* Are the three vertex normals the face's own (a flat-shaded face: a box,
 * a wall)? Within 1e-6 radians, about ten times the rounding of a unit
 * normal stored in floats: interpolating them gives ng to that precision,
 * so the triangle is shaded with ng and the hits skip the interpolation
 * (1.6 % of a peer-box render, whose 36 triangles are all flat). */
static bool flat_normals(const struct dr_mesh *m, const uint32_t *idx, dr_vec3 ng)
{
    for (int k = 0; k < 3; k++) {
        const float *n = m->normals + 3 * (size_t)idx[k];
        dr_vec3 v = dr_v3(n[0], n[1], n[2]);
        double l = dr_length(v);
        if (!(l > 0.0) || dr_dot(v, ng) < (1.0 - 5e-13) * l)
            return false;
    }
    return true;
}

int dr_mesh_derive(struct dr_mesh *m)
{
    free(m->tri_normal_eps);
    m->tri_normal_eps = malloc(sizeof(double) * 4 * ((size_t)m->n_triangles + 1));
    if (!m->tri_normal_eps)
        return -1;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        const uint32_t *idx = m->indices + 3 * (size_t)t;
        dr_vec3 p0 = dr_mesh_vertex(m, idx[0]), p1 = dr_mesh_vertex(m, idx[1]), p2 = dr_mesh_vertex(m, idx[2]);
        dr_vec3 ng = dr_cross(dr_sub(p1, p0), dr_sub(p2, p0));
        double len = dr_length(ng);
        ng = len > 0.0 ? dr_scale(ng, 1.0 / len) : dr_v3(0, 0, 1);
        double mag = 0.0;
        for (int k = 0; k < 3; k++) {
            const float *v = m->positions + 3 * (size_t)idx[k];
            mag = dr_max(mag, dr_max(fabs(v[0]), dr_max(fabs(v[1]), fabs(v[2]))));
        }
        double *ne = m->tri_normal_eps + 4 * (size_t)t;
        ne[0] = ng.x;
        ne[1] = ng.y;
        ne[2] = ng.z;
        ne[3] = 1e-5 * mag + 1e-30;
        if ((m->flags[t] & DR_TRI_HAS_NORMALS) && flat_normals(m, idx, ng))
            m->flags[t] &= (uint8_t)~DR_TRI_HAS_NORMALS;
    }
    return 0;
}

void dr_hit_locate(const struct dr_mesh *m, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_hit *hit)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    dr_vec3 p0 = dr_mesh_vertex(m, idx[0]);
    dr_vec3 e1 = dr_sub(dr_mesh_vertex(m, idx[1]), p0), e2 = dr_sub(dr_mesh_vertex(m, idx[2]), p0);
    /* Moller-Trumbore without rejection: Embree already decided it is a hit. */
    dr_vec3 pv = dr_cross(d, e2);
    double det = dr_dot(e1, pv);
    double b1 = 0.0, b2 = 0.0, t = 0.0;
    if (det != 0.0) {
        double inv = 1.0 / det;
        dr_vec3 tv = dr_sub(o, p0);
        b1 = dr_dot(tv, pv) * inv;
        dr_vec3 qv = dr_cross(tv, e1);
        b2 = dr_dot(d, qv) * inv;
        t = dr_dot(e2, qv) * inv;
    }
    /* Clamp into the triangle (float/double disagreement at edges). */
    b1 = dr_clamp(b1, 0.0, 1.0);
    b2 = dr_clamp(b2, 0.0, 1.0);
    if (b1 + b2 > 1.0) {
        double s = b1 + b2;
        b1 /= s;
        b2 /= s;
    }
    place(m, tri, b1, b2, hit);
    hit->t = t > 0.0 ? t : dr_length(dr_sub(hit->p, o));
    hit->front = dr_dot(d, hit->ng) < 0.0;
}

void dr_hit_compute(const struct dr_mesh *m, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_hit *hit)
{
    dr_hit_locate(m, tri, o, d, hit);
    dr_hit_shade(m, hit);
}

/* d loss / d (b1, b2) of the shading normal: ns = sign * n / |n|,
 * n = b0 n0 + b1 n1 + b2 n2 (sign: the flip onto ng's side). */
static void d_shading_normal(const struct dr_mesh *m, const struct dr_hit *hit, const uint32_t *idx, dr_vec3 d_ns,
                             double *d_b1, double *d_b2)
{
    if (!(m->flags[hit->tri] & DR_TRI_HAS_NORMALS) || dr_is_black(d_ns))
        return;
    dr_vec3 n0 = dr_v3(m->normals[3 * (size_t)idx[0]], m->normals[3 * (size_t)idx[0] + 1], m->normals[3 * (size_t)idx[0] + 2]);
    dr_vec3 n1 = dr_v3(m->normals[3 * (size_t)idx[1]], m->normals[3 * (size_t)idx[1] + 1], m->normals[3 * (size_t)idx[1] + 2]);
    dr_vec3 n2 = dr_v3(m->normals[3 * (size_t)idx[2]], m->normals[3 * (size_t)idx[2] + 1], m->normals[3 * (size_t)idx[2] + 2]);
    double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    dr_vec3 n = dr_add(dr_add(dr_scale(n0, b0), dr_scale(n1, b1)), dr_scale(n2, b2));
    double len = dr_length(n);
    if (!(len > 0.0))
        return;   /* the primal fell back to ng: constant */
    dr_vec3 u = dr_scale(n, 1.0 / len);
    double sign = dr_dot(hit->ns, u) < 0.0 ? -1.0 : 1.0;
    /* d n = sign (d_ns - u (u . d_ns)) / |n| */
    dr_vec3 dn = dr_scale(dr_sub(d_ns, dr_scale(u, dr_dot(u, d_ns))), sign / len);
    *d_b1 += dr_dot(dn, dr_sub(n1, n0));
    *d_b2 += dr_dot(dn, dr_sub(n2, n0));
}

void d_hit_compute(const struct dr_mesh *m, const struct dr_hit *hit, dr_vec3 o, dr_vec3 d,
                   const struct dr_d_hit *d_hit, dr_vec3 *d_o, dr_vec3 *d_d)
{
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    dr_vec3 p0 = dr_mesh_vertex(m, idx[0]);
    dr_vec3 e1 = dr_sub(dr_mesh_vertex(m, idx[1]), p0), e2 = dr_sub(dr_mesh_vertex(m, idx[2]), p0);
    dr_vec3 n = dr_cross(e1, e2);
    double n2 = dr_dot(n, n), dn = dr_dot(n, d);
    if (!(n2 > 0.0) || dn == 0.0)
        return;
    /* Barycentrics of a point in the plane: b1 = (p - p0) . c1, b2 = (p - p0) . c2
     * with the dual basis c1 = (e2 x n) / |n|^2, c2 = (n x e1) / |n|^2. */
    double d_b1 = 0.0, d_b2 = 0.0;
    if (m->flags[hit->tri] & DR_TRI_HAS_UVS) {
        const float *t0 = m->uvs + 2 * (size_t)idx[0], *t1 = m->uvs + 2 * (size_t)idx[1],
                    *t2 = m->uvs + 2 * (size_t)idx[2];
        d_b1 += d_hit->uv[0] * (t1[0] - t0[0]) + d_hit->uv[1] * (t1[1] - t0[1]);
        d_b2 += d_hit->uv[0] * (t2[0] - t0[0]) + d_hit->uv[1] * (t2[1] - t0[1]);
    }
    if (m->uvs1) {
        const float *t0 = m->uvs1 + 2 * (size_t)idx[0], *t1 = m->uvs1 + 2 * (size_t)idx[1],
                    *t2 = m->uvs1 + 2 * (size_t)idx[2];
        d_b1 += d_hit->uv1[0] * (t1[0] - t0[0]) + d_hit->uv1[1] * (t1[1] - t0[1]);
        d_b2 += d_hit->uv1[0] * (t2[0] - t0[0]) + d_hit->uv1[1] * (t2[1] - t0[1]);
    }
    if (m->colors) {
        const float *c0 = m->colors + 3 * (size_t)idx[0], *c1 = m->colors + 3 * (size_t)idx[1],
                    *c2 = m->colors + 3 * (size_t)idx[2];
        const dr_vec3 dc = d_hit->color;
        d_b1 += dc.x * (c1[0] - c0[0]) + dc.y * (c1[1] - c0[1]) + dc.z * (c1[2] - c0[2]);
        d_b2 += dc.x * (c2[0] - c0[0]) + dc.y * (c2[1] - c0[1]) + dc.z * (c2[2] - c0[2]);
    }
    d_shading_normal(m, hit, idx, d_hit->ns, &d_b1, &d_b2);
    if (m->tangents && !dr_is_black(d_hit->tangent)) {   /* t = b0 t0 + b1 t1 + b2 t2 (xyz) */
        const float *t0 = m->tangents + 4 * (size_t)idx[0], *t1 = m->tangents + 4 * (size_t)idx[1],
                    *t2 = m->tangents + 4 * (size_t)idx[2];
        const dr_vec3 dt = d_hit->tangent;
        d_b1 += dt.x * (t1[0] - t0[0]) + dt.y * (t1[1] - t0[1]) + dt.z * (t1[2] - t0[2]);
        d_b2 += dt.x * (t2[0] - t0[0]) + dt.y * (t2[1] - t0[1]) + dt.z * (t2[2] - t0[2]);
    }
    dr_vec3 c1 = dr_scale(dr_cross(e2, n), 1.0 / n2), c2 = dr_scale(dr_cross(n, e1), 1.0 / n2);
    dr_vec3 d_p = dr_add(d_hit->p, dr_add(dr_scale(c1, d_b1), dr_scale(c2, d_b2)));
    /* p = o + t d, t = n . (p0 - o) / (n . d):
     *   dp = (I - d n^T / (n . d)) (do + t dd) */
    double t = dr_dot(n, dr_sub(p0, o)) / dn;
    dr_vec3 g = dr_sub(d_p, dr_scale(n, dr_dot(d, d_p) / dn));
    if (d_o)
        *d_o = dr_add(*d_o, g);
    if (d_d)
        *d_d = dr_madd(*d_d, g, t);
}

void dr_hit_at(const struct dr_mesh *m, int64_t tri, double b1, double b2, struct dr_hit *hit)
{
    /* Points on emitters need no shading normal: only p, ng, eps, uv. */
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    const double *ne = m->tri_normal_eps + 4 * (size_t)tri;
    double b0 = 1.0 - b1 - b2;
    const float *p0 = m->positions + 3 * (size_t)idx[0], *p1 = m->positions + 3 * (size_t)idx[1],
                *p2 = m->positions + 3 * (size_t)idx[2];
    hit->tri = tri;
    hit->b1 = b1;
    hit->b2 = b2;
    hit->p = dr_v3(b0 * p0[0] + b1 * p1[0] + b2 * p2[0], b0 * p0[1] + b1 * p1[1] + b2 * p2[1],
                   b0 * p0[2] + b1 * p1[2] + b2 * p2[2]);
    hit->ng = hit->ns = dr_v3(ne[0], ne[1], ne[2]);
    hit->eps = ne[3];
    hit->uv[0] = hit->uv[1] = 0.0;
    if (m->flags[tri] & DR_TRI_HAS_UVS) {
        const float *t0 = m->uvs + 2 * (size_t)idx[0], *t1 = m->uvs + 2 * (size_t)idx[1],
                    *t2 = m->uvs + 2 * (size_t)idx[2];
        hit->uv[0] = b0 * t0[0] + b1 * t1[0] + b2 * t2[0];
        hit->uv[1] = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
    }
    hit->material = m->material[tri];
    hit->t = 0.0;
    hit->front = true;
}

double dr_triangle_area(const struct dr_mesh *m, int64_t tri)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    dr_vec3 p0 = dr_mesh_vertex(m, idx[0]);
    return 0.5 * dr_length(dr_cross(dr_sub(dr_mesh_vertex(m, idx[1]), p0), dr_sub(dr_mesh_vertex(m, idx[2]), p0)));
}
