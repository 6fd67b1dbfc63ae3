#include "geometry.h"

#include <stdlib.h>

static void attributes(const struct dr_mesh *m, int64_t tri, double b1, double b2, struct dr_hit *hit)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    const double *ne = m->tri_normal_eps + 4 * (size_t)tri;
    double b0 = 1.0 - b1 - b2;
    const float *p0 = m->positions + 3 * (size_t)idx[0], *p1 = m->positions + 3 * (size_t)idx[1],
                *p2 = m->positions + 3 * (size_t)idx[2];
    hit->tri = tri;
    hit->p = dr_v3(b0 * p0[0] + b1 * p1[0] + b2 * p2[0], b0 * p0[1] + b1 * p1[1] + b2 * p2[1],
                   b0 * p0[2] + b1 * p1[2] + b2 * p2[2]);
    hit->ng = dr_v3(ne[0], ne[1], ne[2]);
    hit->eps = ne[3];
    hit->ns = hit->ng;
    uint8_t flags = m->flags[tri];
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
    } else {
        hit->uv[0] = hit->uv[1] = 0.0;
    }
    hit->material = m->material[tri];
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
    }
    return 0;
}

void dr_hit_compute(const struct dr_mesh *m, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_hit *hit)
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
    attributes(m, tri, b1, b2, hit);
    hit->t = t > 0.0 ? t : dr_length(dr_sub(hit->p, o));
    hit->front = dr_dot(d, hit->ng) < 0.0;
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

dr_vec3 dr_offset_origin(const struct dr_hit *hit, dr_vec3 ng, dr_vec3 d)
{
    return dr_madd(hit->p, ng, dr_dot(d, ng) >= 0.0 ? hit->eps : -hit->eps);
}
