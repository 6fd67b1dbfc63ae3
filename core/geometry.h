/* Surface points recomputed in double from the triangle Embree reported, so
 * positions, normals and texture coordinates have well-defined derivatives. */
#ifndef DR_GEOMETRY_H
#define DR_GEOMETRY_H

#include <stdbool.h>
#include <stdint.h>

#include "scene.h"
#include "vec.h"

struct dr_hit {
    int64_t tri;
    double t;          /* distance along the (unit) ray direction */
    dr_vec3 p;         /* position, interpolated from the vertices */
    dr_vec3 ng;        /* unit geometric normal of the front face (CCW winding) */
    dr_vec3 ns;        /* unit shading normal, on the same side as ng */
    double uv[2];      /* TEXCOORD_0 (0,0 without UVs); TEXCOORD_1 and COLOR_0 are
                          interpolated on demand from (tri, b1, b2): dr_hit_uv1,
                          dr_hit_color (hits are recorded per path vertex, and
                          scenes without them must not pay for them) */
    double b1, b2;     /* barycentrics of p (weights of vertices 1 and 2) */
    bool front;        /* the ray arrived on the front face's side */
    int material;
    double eps;        /* ray-offset distance: bounds the float error of Embree's
                          intersection test on this triangle (see dr_offset_origin) */
};

static inline dr_vec3 dr_mesh_vertex(const struct dr_mesh *m, uint32_t v)
{
    const float *p = m->positions + 3 * (size_t)v;
    return dr_v3(p[0], p[1], p[2]);
}

/* Prefetching for a packet tracer, which has many hits to shade at once:
 * asking for all their data first overlaps the cache misses that shading
 * one hit after another would take in turn (a scene whose triangles do not
 * fit in the cache). Two rounds, as the vertices are found through the
 * indices: the triangle's own records, then (once they have arrived) the
 * attributes of its vertices that dr_hit_compute reads. No result changes. */
static inline void dr_mesh_prefetch_triangle(const struct dr_mesh *m, int64_t tri)
{
    __builtin_prefetch(m->indices + 3 * (size_t)tri);
    __builtin_prefetch(m->tri_normal_eps + 4 * (size_t)tri);
    __builtin_prefetch(m->material + tri);
    __builtin_prefetch(m->flags + tri);
}
/* Only the positions: a point sampled on the triangle (light sampling). */
static inline void dr_mesh_prefetch_positions(const struct dr_mesh *m, int64_t tri)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    for (int k = 0; k < 3; k++)
        __builtin_prefetch(m->positions + 3 * (size_t)idx[k]);
}
/* Only the texture coordinates (a textured emitter's light point). */
static inline void dr_mesh_prefetch_uvs(const struct dr_mesh *m, int64_t tri)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    for (int k = 0; k < 3; k++) {
        if (m->uvs)
            __builtin_prefetch(m->uvs + 2 * (size_t)idx[k]);
        if (m->uvs1)
            __builtin_prefetch(m->uvs1 + 2 * (size_t)idx[k]);
    }
}
static inline void dr_mesh_prefetch_vertices(const struct dr_mesh *m, int64_t tri)
{
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    for (int k = 0; k < 3; k++) {
        __builtin_prefetch(m->positions + 3 * (size_t)idx[k]);
        if (m->normals)
            __builtin_prefetch(m->normals + 3 * (size_t)idx[k]);
        if (m->uvs)
            __builtin_prefetch(m->uvs + 2 * (size_t)idx[k]);
        if (m->uvs1)   /* (only where a texture reads TEXCOORD_1) */
            __builtin_prefetch(m->uvs1 + 2 * (size_t)idx[k]);
    }
}

/* Fills hit for triangle tri hit by the ray o + t d (d unit). The barycentrics
 * are recomputed in double and clamped into the triangle, so a hit that float
 * traversal reported just outside an edge still yields a point on it. */
void dr_hit_compute(const struct dr_mesh *m, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_hit *hit);

/* dr_hit_compute in two parts. dr_hit_locate: tri, t, p, ng, eps, front,
 * b1, b2 and material, with ns = ng and uv = (0, 0): what a ray crossing a
 * medium's boundary reads (the interpolated normal and texture coordinates
 * were almost half of the hits' cost in a dense medium: 9.8 % of its
 * render in dr_hit_compute, 5.4 % in dr_hit_locate). dr_hit_shade then adds
 * ns and uv; the two together give dr_hit_compute's hit to the bit. */
void dr_hit_locate(const struct dr_mesh *m, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_hit *hit);
void dr_hit_shade(const struct dr_mesh *m, struct dr_hit *hit);

/* Adjoint of the differentiable outputs of dr_hit_compute (attached sampling:
 * the hit point moves with the ray). ng is constant on a triangle. */
struct dr_d_hit {
    dr_vec3 p, ns;
    double uv[2];
    double uv1[2];     /* TEXCOORD_1 (mesh.uvs1) */
    dr_vec3 color;     /* COLOR_0 (mesh.colors) */
    dr_vec3 tangent;   /* the interpolated mesh tangent, before Gram-Schmidt (normal_map.h's
                          d_hit_tangent_frame; mesh.tangents) */
};

/* Reverse mode of dr_hit_compute with respect to the ray: given d_hit, adds
 * d loss / d o and d loss / d d (+=; NULL: not needed). p = o + t d on the
 * triangle's plane; uv and ns follow the barycentrics of p. Where the primal
 * clamped the barycentrics (a hit float traversal put just outside an edge)
 * the adjoint is that of the unclamped plane point. A ray parallel to the
 * plane (never reported as a hit) gives nothing. */
void d_hit_compute(const struct dr_mesh *m, const struct dr_hit *hit, dr_vec3 o, dr_vec3 d,
                   const struct dr_d_hit *d_hit, dr_vec3 *d_o, dr_vec3 *d_d);

/* Surface attributes at barycentrics (b1, b2) of tri, for sampling points on
 * emitters: fills p, ng, uv, eps, material; ns = ng (t = 0, front = true). */
void dr_hit_at(const struct dr_mesh *m, int64_t tri, double b1, double b2, struct dr_hit *hit);

/* TEXCOORD_1 at the hit (0,0 when the mesh has no second set). */
static inline void dr_hit_uv1(const struct dr_mesh *m, const struct dr_hit *hit, double uv[2])
{
    uv[0] = uv[1] = 0.0;
    if (!m->uvs1)
        return;
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    const float *t0 = m->uvs1 + 2 * (size_t)idx[0], *t1 = m->uvs1 + 2 * (size_t)idx[1],
                *t2 = m->uvs1 + 2 * (size_t)idx[2];
    double b0 = 1.0 - hit->b1 - hit->b2;
    uv[0] = b0 * t0[0] + hit->b1 * t1[0] + hit->b2 * t2[0];
    uv[1] = b0 * t0[1] + hit->b1 * t1[1] + hit->b2 * t2[1];
}

/* COLOR_0 rgb at the hit; (1,1,1) when the mesh has no vertex colours. */
static inline dr_vec3 dr_hit_color(const struct dr_mesh *m, const struct dr_hit *hit)
{
    if (!m->colors)
        return dr_v3s(1.0);
    const uint32_t *idx = m->indices + 3 * (size_t)hit->tri;
    const float *c0 = m->colors + 3 * (size_t)idx[0], *c1 = m->colors + 3 * (size_t)idx[1],
                *c2 = m->colors + 3 * (size_t)idx[2];
    double b1 = hit->b1, b2 = hit->b2, b0 = 1.0 - b1 - b2;
    return dr_v3(b0 * c0[0] + b1 * c1[0] + b2 * c2[0], b0 * c0[1] + b1 * c1[1] + b2 * c2[1],
                 b0 * c0[2] + b1 * c1[2] + b2 * c2[2]);
}

/* The uv a texture reference looks up at hit: its TEXCOORD set, through its
 * KHR_texture_transform (uv' = xf * (u, v, 1)). */
static inline void dr_texref_uv(const struct dr_mesh *m, const struct dr_texref *r, const struct dr_hit *hit,
                                double uv[2])
{
    double s[2] = {hit->uv[0], hit->uv[1]};
    if (r->texcoord == 1)
        dr_hit_uv1(m, hit, s);
    if (!r->transformed) {
        uv[0] = s[0];
        uv[1] = s[1];
        return;
    }
    const double *x = r->xf;
    uv[0] = x[0] * s[0] + x[1] * s[1] + x[2];
    uv[1] = x[3] * s[0] + x[4] * s[1] + x[5];
}

/* Adjoint of dr_texref_uv: d loss / d (looked-up uv) onto the hit's set
 * (d_hit->uv or uv1, +=) through the transposed transform. */
static inline void d_texref_uv(const struct dr_texref *r, const double d_uv[2], struct dr_d_hit *d_hit)
{
    double g0 = d_uv[0], g1 = d_uv[1];
    if (r->transformed) {
        const double *x = r->xf;
        g0 = x[0] * d_uv[0] + x[3] * d_uv[1];
        g1 = x[1] * d_uv[0] + x[4] * d_uv[1];
    }
    double *dst = r->texcoord == 1 ? d_hit->uv1 : d_hit->uv;
    dst[0] += g0;
    dst[1] += g1;
}

double dr_triangle_area(const struct dr_mesh *m, int64_t tri);

/* Fills m->tri_normal_eps from the vertices (called by dr_scene_prepare),
 * and clears DR_TRI_HAS_NORMALS where a triangle's vertex normals are its
 * face normal (flat shading: nothing to interpolate). 0, or -1 when out of
 * memory. */
int dr_mesh_derive(struct dr_mesh *m);

/* Origin for a ray leaving hit->p towards d: pushed off the surface along ng
 * (on d's side) by hit->eps. Embree tests triangles in float, with an error
 * proportional to the magnitude of the triangle's vertices (not of p: a point
 * near the origin on a huge triangle is still imprecise), so eps is 1e-5 times
 * the largest vertex coordinate: ~50x the float error, at every scene scale. */
static inline dr_vec3 dr_offset_origin(const struct dr_hit *hit, dr_vec3 ng, dr_vec3 d)
{
    return dr_madd(hit->p, ng, dr_dot(d, ng) >= 0.0 ? hit->eps : -hit->eps);
}

#endif
