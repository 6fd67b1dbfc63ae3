/* Single-sided triangles whose backs no ray can reach (backface.h). */
#include "backface.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "coverage.h"
#include "error.h"
#include "geometry.h"
#include "sampler.h"
#include "weld.h"

/* A closed component the marks rely on: its triangles are
 * closed_tris[first .. first + count). */
struct sealed {
    int64_t first, count;
    bool inward;   /* its normals point into what it encloses (a room seen from inside) */
};

struct dr_backface {
    uint8_t *marks;     /* per triangle; NULL: nothing marked */
    int64_t n_marked;
    dr_vec3 *views;     /* the viewpoints analysed */
    int n_views;
    dr_vec3 *added;     /* ... of those, the ones not the scene's cameras' (dr_scene_add_viewpoint) */
    int n_added;
    bool parallel;      /* an orthographic camera was added: nothing is marked */
    /* what the marks assume, for testing another viewpoint (dr_backface_admits) */
    uint32_t *room;     /* triangles marked by the room test */
    int64_t n_room;
    uint32_t *closed_tris;
    struct sealed *sealed;
    int n_sealed;
};

/* ---------------------------------------------------------- the room test */

/* How far behind a plane a point may lie and still count as in front:
 * only the double rounding of the distance (the plane and the corners are
 * the same stored floats, so a corner on the plane is at ~1e-16 of the
 * coordinates). Not a geometric slack: with one, a scene far from the
 * origin (coordinates of 1e5) would let a surface sit a visible distance
 * behind a wall and still count as in front. Surface points lifted off
 * their triangle (dr_offset_origin, 1e-5 of the coordinates) move only to
 * the side their rays leave from. */
static double room_tolerance(const struct dr_scene *s)
{
    double m = 0.0;
    for (int k = 0; k < 3; k++)
        m = fmax(m, fmax(fabs(dr_v3_get(s->bbox_min, k)), fabs(dr_v3_get(s->bbox_max, k))));
    return 1e-9 * m + 1e-30;
}

/* Signed distance of p from triangle t's plane (positive: in front). */
static double plane_distance(const struct dr_mesh *m, uint32_t t, dr_vec3 p)
{
    const double *n = m->tri_normal_eps + 4 * (size_t)t;
    dr_vec3 a = dr_mesh_vertex(m, m->indices[3 * (size_t)t]);
    return n[0] * (p.x - a.x) + n[1] * (p.y - a.y) + n[2] * (p.z - a.z);
}

/* Is viewpoint v strictly in front of t's plane? */
static bool room_sees_front(const struct dr_mesh *m, uint32_t t, dr_vec3 v, double tol)
{
    return plane_distance(m, t, v) > tol;
}

/* Every corner of the scene's box (so every surface point) in front of, or
 * on, t's plane, and every viewpoint strictly in front. */
static bool room_holds(const struct dr_scene *s, uint32_t t, const dr_vec3 *views, int n_views, double tol)
{
    for (int c = 0; c < 8; c++) {
        dr_vec3 p = dr_v3(c & 1 ? s->bbox_max.x : s->bbox_min.x, c & 2 ? s->bbox_max.y : s->bbox_min.y,
                          c & 4 ? s->bbox_max.z : s->bbox_min.z);
        if (plane_distance(&s->mesh, t, p) < -tol)
            return false;
    }
    for (int i = 0; i < n_views; i++)
        if (!room_sees_front(&s->mesh, t, views[i], tol))
            return false;
    return true;
}

/* ------------------------------------------------ closed components */

static uint32_t find_root(uint32_t *parent, uint32_t t)
{
    while (parent[t] != t) {
        parent[t] = parent[parent[t]];   /* path halving */
        t = parent[t];
    }
    return t;
}

/* One use of an undirected edge by a triangle, filed under the edge's
 * lower welded end: the higher end, the triangle, the corner it starts at
 * and whether it runs low -> high. */
struct edge_use {
    uint32_t hi, tri;
    uint8_t k, forward;
};

/* Orders a vertex's uses by the other end, then in file order (triangle,
 * corner): the order link_edges takes an edge's uses in. */
static int use_order(const void *pa, const void *pb)
{
    const struct edge_use *a = pa, *b = pb;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    if (a->tri != b->tri)
        return a->tri < b->tri ? -1 : 1;
    return (a->k > b->k) - (a->k < b->k);
}

static void sort_uses(struct edge_use *u, size_t n)
{
    if (n > 24) {
        qsort(u, n, sizeof *u, use_order);
        return;
    }
    for (size_t i = 1; i < n; i++)   /* insertion sort: most buckets hold 2 to 6 */
        for (size_t j = i; j > 0 && use_order(&u[j - 1], &u[j]) > 0; j--) {
            struct edge_use t = u[j];
            u[j] = u[j - 1];
            u[j - 1] = t;
        }
}

/* One edge's uses u[0 .. n), in file order: the second, run the other way,
 * joins the two triangles; any other case opens them. */
static void link_edge(const struct edge_use *u, size_t n, uint32_t *parent, uint8_t *open)
{
    for (size_t i = 1; i < n; i++) {
        if (i == 1 && u[1].forward != u[0].forward)
            parent[find_root(parent, u[1].tri)] = find_root(parent, u[0].tri);
        else
            open[u[i].tri] = open[u[0].tri] = 1;
    }
    if (n != 2)
        open[u[0].tri] = 1;
}

/* Joins triangles across shared edges into components (parent) and sets
 * open[t] where t's component cannot be closed: an edge used once (a
 * boundary), more than twice, or twice in the same direction (inconsistent
 * winding), or a triangle with two corners welded together.
 *
 * The uses are filed by their lower end (a counting sort) and each
 * vertex's few sorted, not looked up in a hash table of every edge: on the
 * big bench scene (381k edge uses) the table's random probes missed the
 * cache at almost every use and took most of the analysis. */
static int link_edges(const struct dr_mesh *m, const uint32_t *wid, uint32_t *parent, uint8_t *open)
{
    const size_t nv = m->n_vertices;
    uint32_t *first = calloc(nv + 2, sizeof *first);
    struct edge_use *use = malloc(sizeof *use * (3 * (size_t)m->n_triangles + 1));
    if (!first || !use) {
        free(first);
        free(use);
        return -1;
    }
    for (uint32_t t = 0; t < m->n_triangles; t++)   /* count each vertex's uses, at first[lo + 2] */
        for (int k = 0; k < 3; k++) {
            const uint32_t *idx = m->indices + 3 * (size_t)t;
            uint32_t a = wid[idx[k]], b = wid[idx[(k + 1) % 3]];
            if (a != b)
                first[(a < b ? a : b) + 2]++;
        }
    for (size_t v = 2; v < nv + 2; v++)
        first[v] += first[v - 1];
    for (uint32_t t = 0; t < m->n_triangles; t++)   /* file them: first[lo + 1] is lo's fill point */
        for (int k = 0; k < 3; k++) {
            const uint32_t *idx = m->indices + 3 * (size_t)t;
            uint32_t a = wid[idx[k]], b = wid[idx[(k + 1) % 3]];
            if (a == b)
                open[t] = 1;
            else
                use[first[(a < b ? a : b) + 1]++] = (struct edge_use){
                    .hi = a < b ? b : a, .tri = t, .k = (uint8_t)k, .forward = a < b};
        }
    for (size_t v = 0; v < nv; v++) {   /* now first[v] .. first[v + 1] are v's */
        struct edge_use *u = use + first[v];
        size_t n = first[v + 1] - first[v];
        sort_uses(u, n);
        for (size_t i = 0, j; i < n; i = j) {
            for (j = i + 1; j < n && u[j].hi == u[i].hi; j++)
                ;
            link_edge(u + i, j - i, parent, open);
        }
    }
    free(first);
    free(use);
    return 0;
}

/* Van Oosterom and Strackee's solid angle of triangle t seen from x, signed:
 * positive when x is behind the triangle's front face. */
static double solid_angle(const struct dr_mesh *m, uint32_t t, dr_vec3 x)
{
    const uint32_t *idx = m->indices + 3 * (size_t)t;
    dr_vec3 a = dr_sub(dr_mesh_vertex(m, idx[0]), x), b = dr_sub(dr_mesh_vertex(m, idx[1]), x),
            c = dr_sub(dr_mesh_vertex(m, idx[2]), x);
    double la = dr_length(a), lb = dr_length(b), lc = dr_length(c);
    double num = dr_dot(a, dr_cross(b, c));
    double den = la * lb * lc + dr_dot(a, b) * lc + dr_dot(a, c) * lb + dr_dot(b, c) * la;
    return 2.0 * atan2(num, den);
}

/* Is x on the front side of the closed component tris[0 .. n)? Its
 * winding number is 0 outside an outward-facing surface, -1 inside an
 * inward-facing one; a point near the surface gets a fraction and is
 * refused. */
static bool closed_sees_front(const struct dr_mesh *m, const uint32_t *tris, int64_t n, bool inward, dr_vec3 x)
{
    double w = 0.0;
    for (int64_t i = 0; i < n; i++)
        w += solid_angle(m, tris[i], x);
    w /= 4.0 * M_PI;
    return fabs(w - (inward ? -1.0 : 0.0)) < 0.25;
}

/* Per component root: what decides whether it is sealed. */
struct comp_info {
    double volume;      /* 6 x the signed volume it encloses */
    int64_t n;          /* its triangles */
    uint8_t open;       /* not watertight, or a MASK / BLEND triangle (holes let rays in) */
    uint8_t wants;      /* it has a culled triangle the room test did not mark */
};

/* Each connected component's (its root's) volume, size, and whether it is
 * open (a border edge, or a cut-out or blended triangle) and has a triangle
 * that wants culling. */
static void component_infos(const struct dr_backface *b, const struct dr_mesh *m, const uint8_t *tri_bits,
                            uint32_t *parent, const uint8_t *open, struct comp_info *ci)
{
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        struct comp_info *c = &ci[find_root(parent, t)];
        const uint32_t *idx = m->indices + 3 * (size_t)t;
        dr_vec3 p0 = dr_mesh_vertex(m, idx[0]), p1 = dr_mesh_vertex(m, idx[1]), p2 = dr_mesh_vertex(m, idx[2]);
        c->volume += dr_dot(p0, dr_cross(p1, p2));
        c->n++;
        c->open |= open[t] | ((tri_bits[t] & (DR_COVER_MASK | DR_COVER_BLEND | DR_COVER_THIN)) != 0);
        c->wants |= (tri_bits[t] & DR_COVER_CULL) && !b->marks[t];
    }
}

/* The candidate components (closed, wanting culling, enclosing a volume):
 * their triangles gathered in b->closed_tris, component by component from
 * start[root] (-1: not a candidate); ci[root].n becomes the count. */
static int gather_candidates(struct dr_backface *b, const struct dr_scene *s, uint32_t *parent,
                             struct comp_info *ci, int64_t *start)
{
    const uint32_t n_tri = s->mesh.n_triangles;
    /* a component enclosing no volume (a sheet of back-to-back triangles)
     * has no front side */
    dr_vec3 ext = dr_sub(s->bbox_max, s->bbox_min);
    double min_volume = 1e-12 * pow(dr_length(ext), 3.0);
    int64_t n_cand = 0;
    for (uint32_t r = 0; r < n_tri; r++) {
        struct comp_info *c = &ci[r];
        bool cand = c->n > 0 && !c->open && c->wants && fabs(c->volume) > min_volume;
        start[r] = cand ? n_cand : -1;
        n_cand += cand ? c->n : 0;
        c->n = 0;   /* (the fill count below) */
    }
    b->closed_tris = malloc(sizeof(uint32_t) * (size_t)(n_cand + 1));
    b->sealed = malloc(sizeof(struct sealed) * (size_t)(n_cand + 1));
    if (!b->closed_tris || !b->sealed)
        return -1;
    for (uint32_t t = 0; t < n_tri; t++) {
        uint32_t r = find_root(parent, t);
        if (start[r] >= 0)
            b->closed_tris[start[r] + ci[r].n++] = t;
    }
    return 0;
}

/* The candidates whose front every view sees from outside are sealed:
 * their triangles stay in b->closed_tris (moved up over the dropped ones)
 * and the ones wanting culling are marked. */
static void seal_candidates(struct dr_backface *b, const struct dr_mesh *m, const uint8_t *tri_bits,
                            const struct comp_info *ci, const int64_t *start)
{
    int64_t kept = 0;
    for (uint32_t r = 0; r < m->n_triangles; r++) {
        if (start[r] < 0)
            continue;
        const uint32_t *tris = b->closed_tris + start[r];
        struct sealed sc = {.first = kept, .count = ci[r].n, .inward = ci[r].volume < 0.0};
        bool ok = true;
        for (int i = 0; ok && i < b->n_views; i++)
            ok = closed_sees_front(m, tris, sc.count, sc.inward, b->views[i]);
        if (!ok)
            continue;
        memmove(b->closed_tris + kept, tris, sizeof(uint32_t) * (size_t)sc.count);   /* (kept <= start[r]) */
        for (int64_t i = 0; i < sc.count; i++) {
            uint32_t t = b->closed_tris[kept + i];
            if ((tri_bits[t] & DR_COVER_CULL) && !b->marks[t]) {
                b->marks[t] = 1;
                b->n_marked++;
            }
        }
        b->sealed[b->n_sealed++] = sc;
        kept += sc.count;
    }
}

/* Marks the culled triangles of the closed components every viewpoint sees
 * from the front, and records those components in b. */
static int mark_closed(struct dr_backface *b, const struct dr_scene *s, const uint8_t *tri_bits)
{
    const struct dr_mesh *m = &s->mesh;
    uint32_t n_tri = m->n_triangles;
    uint32_t *wid = dr_mesh_weld(m), *parent = malloc(sizeof(uint32_t) * n_tri);
    uint8_t *open = calloc(n_tri, 1);
    struct comp_info *ci = calloc(n_tri, sizeof *ci);
    int64_t *start = malloc(sizeof(int64_t) * n_tri);
    int rc = -1;
    if (!wid || !parent || !open || !ci || !start)
        goto out;
    for (uint32_t t = 0; t < n_tri; t++)
        parent[t] = t;
    if (link_edges(m, wid, parent, open) != 0)
        goto out;
    component_infos(b, m, tri_bits, parent, open, ci);
    if (gather_candidates(b, s, parent, ci, start) != 0)
        goto out;
    seal_candidates(b, m, tri_bits, ci, start);
    rc = 0;
out:
    free(wid);
    free(parent);
    free(open);
    free(ci);
    free(start);
    return rc;
}

/* ------------------------------------------------------------ analysis */

/* The viewpoints: the cameras' origins (the default view's without any),
 * then the added ones. False when some camera's rays do not start at one
 * point. */
static bool gather_views(struct dr_backface *b, const struct dr_scene *s)
{
    for (int i = 0; i < s->n_cameras; i++) {
        if (s->cameras[i].orthographic)
            return false;
        b->views[b->n_views++] = s->cameras[i].origin;
    }
    if (s->n_cameras == 0)
        b->views[b->n_views++] = dr_camera_default(s).origin;
    for (int i = 0; i < b->n_added; i++)
        b->views[b->n_views++] = b->added[i];
    return !b->parallel;
}

static int analyse(struct dr_backface *b, const struct dr_scene *s)
{
    const struct dr_mesh *m = &s->mesh;
    b->views = malloc(sizeof(dr_vec3) * (size_t)(s->n_cameras + 1 + b->n_added));
    if (!b->views)
        return -1;
    if (!gather_views(b, s) || s->n_media > 0 || m->n_triangles == 0 || !m->tri_normal_eps)
        return 0;
    uint8_t *tri_bits = malloc(m->n_triangles);
    int64_t n_cull = 0;
    if (!tri_bits)
        return -1;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        tri_bits[t] = (uint8_t)dr_material_coverage(s, m->material[t]);
        n_cull += (tri_bits[t] & DR_COVER_CULL) != 0;
    }
    int rc = 0;
    if (n_cull > 0) {
        b->marks = calloc(m->n_triangles, 1);
        b->room = malloc(sizeof(uint32_t) * m->n_triangles);
        rc = b->marks && b->room ? 0 : -1;
        double tol = room_tolerance(s);
        for (uint32_t t = 0; rc == 0 && t < m->n_triangles; t++) {
            if ((tri_bits[t] & DR_COVER_CULL) && room_holds(s, t, b->views, b->n_views, tol)) {
                b->marks[t] = 1;
                b->room[b->n_room++] = t;
            }
        }
        b->n_marked = b->n_room;
        if (rc == 0 && b->n_room < n_cull)   /* (culled triangles left for the closed test) */
            rc = mark_closed(b, s, tri_bits);
        if (rc == 0 && b->n_marked == 0) {
            free(b->marks);
            b->marks = NULL;
        }
    }
    free(tri_bits);
    return rc;
}

struct dr_backface *dr_backface_analyse(const struct dr_scene *s, const struct dr_backface *prev,
                                        const struct dr_camera *add)
{
    struct dr_backface *b = calloc(1, sizeof *b);
    int n_prev = prev ? prev->n_added : 0;
    if (b)
        b->added = malloc(sizeof(dr_vec3) * (size_t)(n_prev + 1));
    if (!b || !b->added)
        goto fail;
    if (prev) {
        memcpy(b->added, prev->added, sizeof(dr_vec3) * (size_t)n_prev);
        b->n_added = n_prev;
        b->parallel = prev->parallel;
    }
    if (add && add->orthographic)
        b->parallel = true;
    else if (add)
        b->added[b->n_added++] = add->origin;
    if (analyse(b, s) != 0)
        goto fail;
    return b;
fail:
    dr_backface_destroy(b);
    dr_set_error("out of memory");
    return NULL;
}

void dr_backface_destroy(struct dr_backface *b)
{
    if (!b)
        return;
    free(b->marks);
    free(b->views);
    free(b->added);
    free(b->room);
    free(b->closed_tris);
    free(b->sealed);
    free(b);
}

const uint8_t *dr_backface_marks(const struct dr_backface *b)
{
    return b ? b->marks : NULL;
}

int64_t dr_backface_count(const struct dr_backface *b)
{
    return b && b->marks ? b->n_marked : 0;
}

int dr_backface_n_viewpoints(const struct dr_backface *b)
{
    return b ? b->n_views : 0;
}

dr_vec3 dr_backface_viewpoint(const struct dr_backface *b, int i)
{
    return b->views[i];
}

bool dr_backface_admits(const struct dr_backface *b, const struct dr_scene *s, const struct dr_camera *camera)
{
    if (!b || !b->marks)
        return true;
    if (camera->orthographic)
        return false;
    dr_vec3 v = camera->origin;
    for (int i = 0; i < b->n_views; i++)
        if (b->views[i].x == v.x && b->views[i].y == v.y && b->views[i].z == v.z)
            return true;
    double tol = room_tolerance(s);
    for (int64_t i = 0; i < b->n_room; i++)
        if (!room_sees_front(&s->mesh, b->room[i], v, tol))
            return false;
    for (int i = 0; i < b->n_sealed; i++)
        if (!closed_sees_front(&s->mesh, b->closed_tris + b->sealed[i].first, b->sealed[i].count,
                               b->sealed[i].inward, v))
            return false;
    return true;
}
