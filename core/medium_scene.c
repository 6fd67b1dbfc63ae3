/* Participating media in a scene (medium_scene.h). */
#include "medium_scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "coverage.h"
#include "error.h"
#include "geometry.h"
#include "path.h"
#include "weld.h"

/* --------------------------------------------------------- closed meshes */

struct edge {
    uint32_t a, b;   /* welded vertex ids, a < b */
    int dir;         /* +1: a -> b in the triangle's winding, -1: b -> a */
};

static int cmp_edge(const void *x, const void *y)
{
    const struct edge *e = x, *f = y;
    if (e->a != f->a)
        return e->a < f->a ? -1 : 1;
    return e->b < f->b ? -1 : (e->b > f->b ? 1 : 0);
}

/* Every edge of the material's triangles is shared by exactly two of them,
 * wound oppositely (so inside and outside are well defined). DR_ERR_FORMAT
 * with the message set and *problem the reason alone when not. */
static int check_closed(const struct dr_scene *s, int material, const uint32_t *id, const char **problem_out)
{
    const struct dr_mesh *m = &s->mesh;
    size_t n = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++)
        n += m->material[t] == material ? 3 : 0;
    struct edge *e = malloc(sizeof *e * (n ? n : 1));
    if (!e) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    size_t k = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++)
        for (int j = 0; m->material[t] == material && j < 3; j++) {
            uint32_t a = id[m->indices[3 * t + j]], b = id[m->indices[3 * t + (j + 1) % 3]];
            e[k++] = a < b ? (struct edge){a, b, 1} : (struct edge){b, a, -1};
        }
    qsort(e, n, sizeof *e, cmp_edge);
    const char *problem = NULL;
    for (size_t i = 0; i < n && !problem;) {
        size_t j = i;
        int sum = 0;
        while (j < n && e[j].a == e[i].a && e[j].b == e[i].b)
            sum += e[j++].dir;
        if (j - i != 2)
            problem = j - i == 1 ? "an edge belongs to only one triangle (the mesh is open)"
                                 : "an edge is shared by more than two triangles";
        else if (sum != 0)
            problem = "two triangles sharing an edge are wound the same way (inconsistent orientation)";
        i = j;
    }
    free(e);
    if (n == 0)
        problem = "no triangle uses this material";
    if (problem) {
        dr_set_error("%s: /materials/%d (%s): a medium boundary must be a closed mesh: %s", s->path, material,
                     s->materials[material].name, problem);
        *problem_out = problem;
        return DR_ERR_FORMAT;
    }
    return 0;
}

/* The world bounds of the material's triangles: the default grid box. */
static void material_bounds(const struct dr_mesh *m, int material, dr_vec3 *lo, dr_vec3 *hi)
{
    *lo = dr_v3s(INFINITY);
    *hi = dr_v3s(-INFINITY);
    for (uint32_t t = 0; t < m->n_triangles; t++)
        for (int j = 0; m->material[t] == material && j < 3; j++) {
            dr_vec3 p = dr_mesh_vertex(m, m->indices[3 * t + j]);
            *lo = dr_v3(fmin(lo->x, p.x), fmin(lo->y, p.y), fmin(lo->z, p.z));
            *hi = dr_v3(fmax(hi->x, p.x), fmax(hi->y, p.y), fmax(hi->z, p.z));
        }
}

/* 4 V / S of the box [lo, hi]: the mean chord of a convex body (Cauchy);
 * 0 for a flat or empty box. */
static double box_mean_chord(dr_vec3 lo, dr_vec3 hi)
{
    dr_vec3 e = dr_sub(hi, lo);
    if (!(e.x > 0.0 && e.y > 0.0 && e.z > 0.0))
        return 0.0;
    return 4.0 * e.x * e.y * e.z / (2.0 * (e.x * e.y + e.y * e.z + e.z * e.x));
}

/* The box of every vertex of the scene (the global medium's extent). */
static void scene_bounds(const struct dr_mesh *m, dr_vec3 *lo, dr_vec3 *hi)
{
    *lo = dr_v3s(INFINITY);
    *hi = dr_v3s(-INFINITY);
    for (uint32_t v = 0; v < m->n_vertices; v++) {
        dr_vec3 p = dr_mesh_vertex(m, v);
        *lo = dr_v3(fmin(lo->x, p.x), fmin(lo->y, p.y), fmin(lo->z, p.z));
        *hi = dr_v3(fmax(hi->x, p.x), fmax(hi->y, p.y), fmax(hi->z, p.z));
    }
}

/* Medium i, a KHR_materials_volume whose mesh is open (why), becomes thin
 * glass on its material and leaves the scene's media. */
static void volume_to_thin_glass(struct dr_scene *s, int i, const char *why)
{
    const int m = s->media[i].material;
    const unsigned dropped = dr_material_make_thin(&s->materials[m], s->media[i].ior > 0.0 ? s->media[i].ior : 1.0);
    dr_warn("%s: /materials/%d (%s): KHR_materials_volume needs a closed mesh (%s): rendered as thin-walled glass "
            "instead%s", s->path, m, s->materials[m].name, why,
            dropped ? " (clear and not emitting: its base colour's tint, metallic-roughness texture and emission "
                      "are ignored)" : "");
    dr_grid_release(&s->media[i].grid);
    memmove(&s->media[i], &s->media[i + 1], sizeof *s->media * (size_t)(s->n_media - i - 1));
    s->n_media--;
    for (int k = 0; k < s->n_materials; k++)
        if (s->material_medium[k] == i)
            s->material_medium[k] = -1;
        else if (s->material_medium[k] > i)
            s->material_medium[k]--;
    if (s->global_medium > i)
        s->global_medium--;
}

int dr_media_prepare(struct dr_scene *s)
{
    uint32_t *id = dr_mesh_weld(&s->mesh);
    if (!id && s->mesh.n_vertices) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int rc = 0;
    for (int i = 0; i < s->n_media && rc == 0; i++) {
        struct dr_medium *med = &s->media[i];
        if (med->material < 0) {
            dr_vec3 lo, hi;
            scene_bounds(&s->mesh, &lo, &hi);
            med->mean_chord = box_mean_chord(lo, hi);
            continue;
        }
        const char *problem = NULL;
        rc = check_closed(s, med->material, id, &problem);
        if (rc == DR_ERR_FORMAT && med->thin_when_open) {
            volume_to_thin_glass(s, i--, problem);
            rc = 0;
            continue;
        }
        if (rc != 0)
            break;
        material_bounds(&s->mesh, med->material, &med->bmin, &med->bmax);
        /* a little slack: the boundary's own rounding */
        dr_vec3 slack = dr_v3s(1e-4 * dr_max3(dr_sub(med->bmax, med->bmin)));
        med->bmin = dr_sub(med->bmin, slack);
        med->bmax = dr_add(med->bmax, slack);
        med->bounded = true;
        med->mean_chord = box_mean_chord(med->bmin, med->bmax);
        struct dr_grid *g = &med->grid;
        if (med->has_grid && !(g->bmin.x < g->bmax.x)) {
            material_bounds(&s->mesh, med->material, &g->bmin, &g->bmax);
        }
    }
    free(id);
    if (rc == 0 && s->n_media == 0)   /* (every medium became thin glass: a scene without media) */
        dr_media_release(s);
    return rc;
}

int dr_media_refresh(struct dr_scene *s)
{
    s->effects |= DR_FX_MEDIA;
    for (int i = 0; i < s->n_media; i++)
        if (s->media[i].ior > 0.0 && s->media[i].material >= 0)
            s->effects |= DR_FX_DIELECTRIC_BOUNDARIES;
    for (int i = 0; i < s->n_media; i++)
        if (s->media[i].has_grid) {
            s->effects |= DR_FX_HETEROGENEOUS_MEDIA;
            int rc = dr_grid_build_majorants(&s->media[i].grid);
            if (rc != 0)
                return rc;
        }
    return 0;
}

void dr_media_release(struct dr_scene *s)
{
    for (int i = 0; i < s->n_media; i++)
        dr_grid_release(&s->media[i].grid);
    free(s->media);
    free(s->material_medium);
    s->media = NULL;
    s->material_medium = NULL;
    s->n_media = 0;
}

/* ------------------------------------------------------------- queries */

bool dr_media_all_bounded(const struct dr_scene *s)
{
    if (s->global_medium >= 0)
        return false;
    for (int i = 0; i < s->n_media; i++)
        if (!s->media[i].bounded)
            return false;
    return true;
}

bool dr_media_box_holds(const struct dr_scene *s, dr_vec3 p)
{
    for (int i = 0; i < s->n_media; i++) {
        const struct dr_medium *m = &s->media[i];
        if (!m->bounded || (p.x >= m->bmin.x && p.x <= m->bmax.x && p.y >= m->bmin.y && p.y <= m->bmax.y &&
                            p.z >= m->bmin.z && p.z <= m->bmax.z))
            return true;
    }
    return false;
}

/* Boundaries crossed before giving up (a ray grazing many thin shells). */
#define MAX_CROSSINGS 256

int dr_medium_at(const struct dr_scene *s, dr_vec3 o, dr_vec3 d)
{
    for (int i = 0; i < MAX_CROSSINGS; i++) {
        int64_t tri = dr_accel_intersect(s->accel, o, d, 0.0, INFINITY);
        if (tri < 0)
            return s->global_medium;
        struct dr_hit h;
        dr_hit_locate(&s->mesh, tri, o, d, &h);   /* (a boundary: no shading) */
        int med = dr_boundary_medium(s, tri);
        if (med >= 0)
            return h.front ? s->global_medium : med;
        o = dr_offset_origin(&h, h.front ? dr_neg(h.ng) : h.ng, d);   /* an ordinary surface: look past it */
    }
    return s->global_medium;
}

void dr_medium_trace_add(struct dr_medium_trace *rec, int medium, uint32_t rng_dim, dr_vec3 o, double len)
{
    if (rec->n < DR_MEDIUM_PIECES)
        rec->p[rec->n++] = (struct dr_medium_piece){medium, rng_dim, o, len};
}

/* (rec, if any, started by the caller) */
static dr_vec3 trace_transmittance(const struct dr_scene *s, dr_vec3 o, dr_vec3 d, double tmax, int medium,
                                   struct dr_sampler *rng, uint64_t *rays, struct dr_medium_trace *rec)
{
    dr_vec3 T = dr_v3s(1.0);
    /* BLEND surfaces and thin glass on a shadow ray: decided by the ray's own stream (coverage.h) */
    const uint64_t key = (s->effects & DR_FX_KEYED_TRACES) ? dr_media_shadow_key(rng) : 0;
    for (int i = 0; i < MAX_CROSSINGS; i++) {
        ++*rays;
        int64_t tri = dr_accel_intersect_key(s->accel, o, d, 0.0, tmax, key);
        struct dr_hit h;
        double seg = tmax;
        if (tri >= 0) {
            dr_hit_locate(&s->mesh, tri, o, d, &h);   /* (a boundary: no shading) */
            seg = dr_dot(dr_sub(h.p, o), d);
        }
        if (medium >= 0) {
            if (rec)
                dr_medium_trace_add(rec, medium, rng->dim, o, seg);
            T = dr_mul(T, dr_medium_transmittance(&s->media[medium], o, d, seg, rng));
        }
        if (tri < 0 || dr_is_black(T))
            return T;
        int med = dr_boundary_medium(s, tri);
        if (med < 0 || dr_boundary_dielectric(s, med))
            return dr_v3s(0.0);   /* an ordinary surface or a dielectric interface blocks the light */
        medium = h.front ? med : s->global_medium;
        dr_vec3 next = dr_offset_origin(&h, h.front ? dr_neg(h.ng) : h.ng, d);
        if (!isinf(tmax))
            tmax -= dr_dot(dr_sub(next, o), d);
        o = next;
        if (!(tmax > 0.0))
            return T;
    }
    return T;
}

/* Russian roulette for shadow rays that start deep in a homogeneous medium.
 * Over ROULETTE_DEPTH / (least extinction) every channel's transmittance
 * falls below exp(-ROULETTE_DEPTH) = 1 %; when no surface lies that close
 * (one occlusion query, which stops at the first surface found), the ray
 * is traced to its end only with probability ROULETTE_KEEP, its
 * transmittance then divided by it: unbiased, and the variance added is at
 * most (1 % of the unoccluded contribution)^2 (1 / ROULETTE_KEEP - 1). In
 * the bench's dense fog shadow rays were two thirds of the queries; the
 * render is 13 % faster, its pixel variance the same (8 seeds). The number
 * that decides comes from a hash of the ray's stream, not the stream
 * itself, so that a grid crossed further on draws what it drew before. */
#define ROULETTE_DEPTH 4.6
#define ROULETTE_KEEP 0.1

/* The distance over which medium m surely attenuates every channel below
 * exp(-ROULETTE_DEPTH); INFINITY where no such bound holds (a grid, a
 * channel of extinction 0) or where it is longer than the medium's mean
 * chord: there the query would nearly always find a surface and cost a
 * query for nothing (a thin global fog's shadow rays mostly found its
 * floor so). */
static double roulette_reach(const struct dr_medium *m)
{
    const double least = m->has_grid ? 0.0 : dr_medium_least_extinction(m);
    const double reach = least > 0.0 ? ROULETTE_DEPTH / least : INFINITY;
    return reach < m->mean_chord ? reach : INFINITY;
}

dr_vec3 dr_media_transmittance(const struct dr_scene *s, dr_vec3 o, dr_vec3 d, double tmax, int medium,
                               struct dr_sampler *rng, uint64_t *rays, struct dr_medium_trace *rec)
{
    if (rec) {
        rec->rng_key = rng->key;
        rec->n = 0;
        rec->d = d;
    }
    const double reach = medium >= 0 ? roulette_reach(&s->media[medium]) : INFINITY;
    double keep = 1.0;
    if (reach < tmax) {
        ++*rays;
        const uint64_t key = (s->effects & DR_FX_KEYED_TRACES) ? dr_media_shadow_key(rng) : 0;
        if (!dr_accel_occluded_key(s->accel, o, d, 0.0, reach, key)) {
            if (dr_hash_unit(dr_hash64(rng->key ^ 0x3c6ef372fe94f82bULL)) >= ROULETTE_KEEP)
                return dr_v3s(0.0);
            keep = ROULETTE_KEEP;
        }
    }
    dr_vec3 T = trace_transmittance(s, o, d, tmax, medium, rng, rays, rec);
    return keep < 1.0 ? dr_scale(T, 1.0 / keep) : T;
}
