#include "accel.h"

#include <embree3/rtcore.h>
#include <float.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel_build.h"
#include "backface.h"
#include "coverage.h"
#include "error.h"
#include "parallel.h"
#include "simd.h"

/* A geometry's map to the scene's triangles. */
struct dr_accel_geom {
    uint32_t *tri;               /* primID -> scene triangle; NULL: the same */
};

/* Coverage (coverage.h) is tested in Embree's per-geometry intersection and
 * occlusion filters rather than by re-tracing from past a rejected hit: the
 * filter sees every candidate inside one traversal, so nothing is skipped or
 * hit twice near the surface a re-traced ray would start from, and shadow
 * rays stay one rtcOccluded1. Triangles whose material needs no test go into
 * a geometry without a filter; when no triangle needs one the structure is
 * exactly the unfiltered one (same buffers, same build), so such scenes pay
 * nothing and render bit for bit as before.
 *
 * Filters cost: Embree calls back for every candidate, and glTF's default
 * (single-sided) puts nearly every real asset's triangles behind one. So a
 * query on a filtered scene asks `plain` first: the same triangles without
 * filters. Its closest hit, if the filter would accept it, is the filtered
 * query's answer too (every candidate the filtered traversal accepts is one
 * of plain's, and nothing is nearer); no hit there is no hit at all. Only a
 * nearest hit the filter would reject (a back face, a hole) asks the
 * filtered query. Shadow rays in packets ask plain for any hit, and a
 * filter notes whether the first blocker found counts
 * (first_blocker_filter): no blocker, or one that counts, is the answer;
 * only a blocker that would not count asks again, one ray at a time as
 * above. (Rejecting such blockers inside the traversal instead, as the
 * filtered query does, calls back for every candidate: slower on big
 * scenes, measured.) Exact up to which of two triangles wins a tie in t.
 *
 * Plain and filtered queries use one structure. A query that filters
 * hands Embree its filter in the query's context (a context filter:
 * RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION), which sees every candidate of
 * every geometry and passes the unfiltered part's; the only geometry
 * filter is first_blocker_filter's on the filtered part, for occlusion,
 * which passes everything in any other query (a context filter there
 * would be called for every blocked shadow ray, of either part). Until
 * 2026-12 plain was a second Embree scene, built again from the same
 * buffers: on real assets, whose triangles are mostly filtered, that
 * doubled the build (127k triangles: two builds of 0.23 s on one core) and
 * the structure's memory.
 *
 * Which triangles need a test is decided per triangle: a single-sided
 * triangle whose back no ray can reach (backface.h: the walls of a room,
 * the faces of a closed box) needs none, and goes with the unfiltered
 * triangles, in both scenes. */
struct dr_accel {
    RTCDevice device;
    RTCScene scene;
    bool plain;                     /* plain queries ask scene as it is, filtered ones with a context
                                       filter (see above); false: the filtered part carries
                                       cover_filter, or nothing is filtered */
    const struct dr_scene *cover;   /* NULL: nothing is filtered */
    uint8_t *tri_bits;              /* per triangle: enum dr_cover_bits, less culling where no ray
                                       can meet the back (backface.h) */
    struct dr_accel_geom geom[2];   /* by geomID: 0 unfiltered, 1 filtered */
    uint32_t *indices[2];           /* owned index buffers when the mesh is split */
    uint32_t n_part[2];             /* ... their triangles */
    bool split;                     /* geomID 0 and 1 hold the two kinds (else one geometry, 0) */
    bool packet8;                   /* packets traced as 8-wide halves (packet_intersect) */
};

/* The query context a filter receives: Embree's, then the structure, the
 * query's key, or for a packet every ray's key by the ray's id (its lane). */
struct query_ctx {
    struct RTCIntersectContext rtc;
    const struct dr_accel *accel;
    uint64_t key;
    const uint64_t *keys;   /* NULL: key for every ray */
    bool *passed;           /* plain's occlusion queries: the blocker found for ray j would not count
                               (first_blocker_filter) */
};


static void embree_error(void *user, enum RTCError code, const char *msg)
{
    (void)user;
    dr_set_error("Embree error %d: %s", (int)code, msg ? msg : "");
}

/* The scene's triangle of Embree's hit (geomID, primID). */
static inline int64_t scene_tri(const struct dr_accel *a, unsigned geom, unsigned prim)
{
    const uint32_t *map = a->geom[geom & 1].tri;
    return map ? (int64_t)map[prim] : (int64_t)prim;
}

/* Embree's RTCRayN / RTCHitN accessors are C++ only; the SOA layout they
 * index (rtcore_ray.h): ray dir_x, dir_y, dir_z at 4N, 5N, 6N floats; hit u, v
 * at 3N, 4N floats, primID at 5N and geomID at 6N. The filters find the
 * triangle by geomID: as a context filter they see every geometry's
 * candidates, and the unfiltered part's pass (dr_coverage_blocks, bits 0). */
static void cover_filter(const struct RTCFilterFunctionNArguments *args)
{
    const struct query_ctx *q = (const struct query_ctx *)args->context;
    const struct dr_accel *a = q->accel;
    const unsigned N = args->N;
    const float *ray = (const float *)args->ray, *hit = (const float *)args->hit;
    const unsigned *hit_u32 = (const unsigned *)args->hit;
    const unsigned *ray_u32 = (const unsigned *)args->ray;
    for (unsigned i = 0; i < N; i++) {
        if (args->valid[i] != -1)
            continue;
        uint64_t key = q->keys ? q->keys[ray_u32[10 * N + i] % DR_ACCEL_PACKET] : q->key;   /* id at 10N */
        int64_t tri = scene_tri(a, hit_u32[6 * N + i], hit_u32[5 * N + i]);
        dr_vec3 d = dr_v3(ray[4 * N + i], ray[5 * N + i], ray[6 * N + i]);
        if (!dr_coverage_blocks(a->cover, a->tri_bits[tri], tri, hit[3 * N + i], hit[4 * N + i], d, key))
            args->valid[i] = 0;
    }
}

static bool filter_accepts(const struct dr_accel *a, int64_t tri, float u, float v, dr_vec3 d, uint64_t key);

/* plain's occlusion filter: takes the first candidate Embree finds, which
 * ends the query, and notes whether the filtered query would have taken it
 * too (passed[j] false: the ray is blocked for certain). So a shadow ray
 * costs one any-hit traversal and one callback where it is blocked; only
 * a ray whose first-found blocker would not count (a back face, a hole)
 * asks again (dr_accel_occluded_many). The filtered part's occlusion filter
 * where a->plain: a filtered query's context (passed NULL) passes every
 * candidate to its own filter. */
static void first_blocker_filter(const struct RTCFilterFunctionNArguments *args)
{
    const struct query_ctx *q = (const struct query_ctx *)args->context;
    const struct dr_accel *a = q->accel;
    const unsigned N = args->N;
    const float *ray = (const float *)args->ray, *hit = (const float *)args->hit;
    const unsigned *hit_u32 = (const unsigned *)args->hit, *ray_u32 = (const unsigned *)args->ray;
    for (unsigned i = 0; q->passed && i < N; i++) {
        if (args->valid[i] != -1)
            continue;
        unsigned id = ray_u32[10 * N + i] % DR_ACCEL_PACKET;   /* the ray's lane */
        uint64_t key = q->keys ? q->keys[id] : q->key;
        dr_vec3 d = dr_v3(ray[4 * N + i], ray[5 * N + i], ray[6 * N + i]);
        int64_t tri = scene_tri(a, hit_u32[6 * N + i], hit_u32[5 * N + i]);
        q->passed[id] = !filter_accepts(a, tri, hit[3 * N + i], hit[4 * N + i], d, key);
    }
}

/* Attaches geometry id to sc over indices (n triangles), with the
 * intersection and occlusion filters given (NULL: none). */
static void add_geometry(struct dr_accel *a, RTCScene sc, const struct dr_mesh *mesh, unsigned id,
                         const uint32_t *indices, uint32_t n, RTCFilterFunctionN isect, RTCFilterFunctionN occ)
{
    RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    /* Shared buffers: the mesh arrays are used in place (positions carry
     * the one float of padding Embree's 16-byte loads need). */
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, mesh->positions, 0,
                               3 * sizeof(float), mesh->n_vertices);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices, 0, 3 * sizeof(uint32_t), n);
    if (isect)
        rtcSetGeometryIntersectFilterFunction(g, isect);
    if (occ)
        rtcSetGeometryOccludedFilterFunction(g, occ);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(sc, g, id);
    rtcReleaseGeometry(g);
}

/* The triangles as an unfiltered part 0 and a filtered part 1: index
 * buffers and maps to the scene's triangles (a->split). */
static int split_mesh(struct dr_accel *a, const struct dr_mesh *mesh, uint32_t n_filtered)
{
    uint32_t n[2] = {mesh->n_triangles - n_filtered, n_filtered};
    for (int k = 0; k < 2; k++) {
        a->indices[k] = malloc(3 * sizeof(uint32_t) * n[k]);
        a->geom[k].tri = malloc(sizeof(uint32_t) * n[k]);
        if (!a->indices[k] || !a->geom[k].tri) {
            dr_set_error("out of memory");
            return -1;
        }
    }
    uint32_t fill[2] = {0, 0};
    for (uint32_t t = 0; t < mesh->n_triangles; t++) {
        int k = a->tri_bits[t] ? 1 : 0;
        for (int c = 0; c < 3; c++)
            a->indices[k][3 * fill[k] + c] = mesh->indices[3 * (size_t)t + c];
        a->geom[k].tri[fill[k]++] = t;
    }
    a->n_part[0] = n[0];
    a->n_part[1] = n[1];
    a->split = true;
    return 0;
}

/* Scene sc's geometries; the filtered part gets the filters given. */
static void add_geometries(struct dr_accel *a, RTCScene sc, const struct dr_mesh *mesh, RTCFilterFunctionN isect,
                           RTCFilterFunctionN occ)
{
    if (a->split) {
        add_geometry(a, sc, mesh, 0, a->indices[0], a->n_part[0], NULL, NULL);
        add_geometry(a, sc, mesh, 1, a->indices[1], a->n_part[1], isect, occ);
    } else {
        bool filtered = a->cover != NULL;
        add_geometry(a, sc, mesh, 0, mesh->indices, mesh->n_triangles, filtered ? isect : NULL,
                     filtered ? occ : NULL);
    }
}

/* Per-triangle coverage bits; returns how many triangles need a filter. */
static int64_t classify(struct dr_accel *a, const struct dr_scene *s)
{
    a->tri_bits = malloc((size_t)s->mesh.n_triangles + 1);
    if (!a->tri_bits) {
        dr_set_error("out of memory");
        return -1;
    }
    const uint8_t *unreachable = dr_backface_marks(s->backface);
    int64_t n = 0;
    for (uint32_t t = 0; t < s->mesh.n_triangles; t++) {
        unsigned bits = dr_material_coverage(s, s->mesh.material[t]);
        if (unreachable && unreachable[t])
            bits &= ~(unsigned)DR_COVER_CULL;
        a->tri_bits[t] = (uint8_t)bits;
        n += bits != 0;
    }
    return n;
}

static RTCScene new_scene(struct dr_accel *a)
{
    RTCScene sc = rtcNewScene(a->device);
    rtcSetSceneFlags(sc, DR_ACCEL_SCENE_FLAGS | (a->plain ? RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION : 0));
    rtcSetSceneBuildQuality(sc, DR_ACCEL_BUILD_QUALITY);
    return sc;
}

static struct dr_accel *build(const struct dr_mesh *mesh, const struct dr_scene *cover, bool with_plain)
{
    struct dr_accel *a = calloc(1, sizeof *a);
    if (!a) {
        dr_set_error("out of memory");
        return NULL;
    }
    /* DRENDER_EMBREE_CONFIG: Embree's device configuration (e.g. "isa=avx2":
     * how a machine without AVX-512 traces; the tests use it). Its builds
     * keep to the run's threads (dr_default_threads: --threads), where
     * they took every CPU whatever the command line said. */
    const char *env = getenv("DRENDER_EMBREE_CONFIG");
    char config[1024];
    if (snprintf(config, sizeof config, "threads=%d%s%s", dr_default_threads(), env && *env ? "," : "",
                 env ? env : "") >= (int)sizeof config) {
        dr_set_error("DRENDER_EMBREE_CONFIG is too long (%zu characters)", env ? strlen(env) : (size_t)0);
        free(a);
        return NULL;
    }
    a->device = rtcNewDevice(config);
    if (!a->device) {
        dr_set_error("cannot create the Embree device");
        free(a);
        return NULL;
    }
    rtcSetDeviceErrorFunction(a->device, embree_error, NULL);
    a->packet8 = !rtcGetDeviceProperty(a->device, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) &&
                 rtcGetDeviceProperty(a->device, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED);
    int64_t n_filtered = 0;
    if (cover && (n_filtered = classify(a, cover)) < 0) {
        dr_accel_destroy(a);
        return NULL;
    }
    if (n_filtered > 0)
        a->cover = cover;
    if (n_filtered > 0 && n_filtered < (int64_t)mesh->n_triangles && split_mesh(a, mesh, (uint32_t)n_filtered) != 0) {
        dr_accel_destroy(a);
        return NULL;
    }
    a->plain = with_plain && a->cover && mesh->n_triangles > 0;
    a->scene = new_scene(a);
    if (mesh->n_triangles > 0)
        add_geometries(a, a->scene, mesh, a->plain ? NULL : cover_filter,
                       a->plain ? first_blocker_filter : cover_filter);
    rtcCommitScene(a->scene);
    if (rtcGetDeviceError(a->device) != RTC_ERROR_NONE) {
        dr_accel_destroy(a);
        return NULL;
    }
    return a;
}

struct dr_accel *dr_accel_create(const struct dr_mesh *mesh)
{
    return build(mesh, NULL, false);
}

struct dr_accel *dr_accel_create_scene(const struct dr_scene *scene)
{
    return build(&scene->mesh, scene, true);
}

struct dr_accel *dr_accel_create_scene_filtered(const struct dr_scene *scene)
{
    return build(&scene->mesh, scene, false);
}

static void warm_up_once(void)
{
    RTCDevice d = rtcNewDevice("threads=1");
    if (!d)
        return;   /* (the real build reports it) */
    RTCScene sc = rtcNewScene(d);
    RTCGeometry g = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4);
    unsigned *ix = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 1);
    if (v && ix) {
        const float tri[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0};   /* (4 vertices: Embree reads 16 bytes) */
        memcpy(v, tri, sizeof tri);
        ix[0] = 0, ix[1] = 1, ix[2] = 2;
        rtcCommitGeometry(g);
        rtcAttachGeometry(sc, g);
        rtcCommitScene(sc);
    }
    rtcReleaseGeometry(g);
    rtcReleaseScene(sc);
    rtcReleaseDevice(d);
}

void dr_accel_warm_up(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, warm_up_once);
}

void dr_accel_destroy(struct dr_accel *a)
{
    if (!a)
        return;
    if (a->scene)
        rtcReleaseScene(a->scene);
    if (a->device)
        rtcReleaseDevice(a->device);
    for (int k = 0; k < 2; k++) {
        free(a->indices[k]);
        free(a->geom[k].tri);
    }
    free(a->tri_bits);
    free(a);
}

static void fill_ray(struct RTCRay *r, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    r->org_x = (float)o.x;
    r->org_y = (float)o.y;
    r->org_z = (float)o.z;
    r->dir_x = (float)d.x;
    r->dir_y = (float)d.y;
    r->dir_z = (float)d.z;
    r->tnear = (float)tmin;
    r->tfar = tmax >= FLT_MAX ? INFINITY : (float)tmax;
    r->time = 0.0f;
    r->mask = 0xFFFFFFFFu;
    r->id = 0;
    r->flags = 0;
}

/* The filtered query's context: the filter sees every candidate (where
 * the geometries carry none, as the context's filter). */
static void filtered_context(const struct dr_accel *a, struct query_ctx *q, uint64_t key)
{
    rtcInitIntersectContext(&q->rtc);
    q->rtc.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    if (a->plain)
        q->rtc.filter = cover_filter;
    q->accel = a;
    q->key = key;
    q->keys = NULL;
    q->passed = NULL;
}

/* The filtered query's answers. */
static int64_t filtered_intersect(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax,
                                  uint64_t key)
{
    struct query_ctx q;
    filtered_context(a, &q, key);
    struct RTCRayHit rh;
    fill_ray(&rh.ray, o, d, tmin, tmax);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(a->scene, &q.rtc, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return -1;
    return scene_tri(a, rh.hit.geomID, rh.hit.primID);
}

static bool filtered_occluded(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax, uint64_t key)
{
    struct query_ctx q;
    filtered_context(a, &q, key);
    struct RTCRay r;
    fill_ray(&r, o, d, tmin, tmax);
    rtcOccluded1(a->scene, &q.rtc, &r);
    return r.tfar < 0.0f;  /* Embree sets tfar = -inf on a hit */
}

/* Would the filter accept plain's hit on tri at (u, v)? Asked with what the
 * filter sees: the ray's float direction, Embree's float barycentrics. */
static bool filter_accepts(const struct dr_accel *a, int64_t tri, float u, float v, dr_vec3 d, uint64_t key)
{
    unsigned bits = a->tri_bits[tri];
    dr_vec3 df = dr_v3((float)d.x, (float)d.y, (float)d.z);
    return !bits || dr_coverage_blocks(a->cover, bits, tri, u, v, df, key);
}

/* plain's closest hit: the triangle (-1: none) and its barycentrics. */
static int64_t plain_intersect(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax, float *u,
                               float *v)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    struct RTCRayHit rh;
    fill_ray(&rh.ray, o, d, tmin, tmax);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(a->scene, &ctx, &rh);
    *u = rh.hit.u;
    *v = rh.hit.v;
    return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : scene_tri(a, rh.hit.geomID, rh.hit.primID);
}

int64_t dr_accel_intersect_key(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax,
                               uint64_t key)
{
    if (a->plain) {
        float u, v;
        int64_t tri = plain_intersect(a, o, d, tmin, tmax, &u, &v);
        if (tri < 0 || filter_accepts(a, tri, u, v, d, key))
            return tri;
    }
    return filtered_intersect(a, o, d, tmin, tmax, key);
}

bool dr_accel_occluded_key(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax, uint64_t key)
{
    if (a->plain) {
        float u, v;
        int64_t tri = plain_intersect(a, o, d, tmin, tmax, &u, &v);
        if (tri < 0)
            return false;
        if (filter_accepts(a, tri, u, v, d, key))
            return true;
    }
    return filtered_occluded(a, o, d, tmin, tmax, key);
}

int64_t dr_accel_intersect(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    return dr_accel_intersect_key(a, o, d, tmin, tmax, 0);
}

bool dr_accel_occluded(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    return dr_accel_occluded_key(a, o, d, tmin, tmax, 0);
}

/* ---------------------------------------------------------------- packets */

/* Eight floats from eight doubles, each rounded as (float) rounds it: one
 * conversion instruction where the target has 8-double registers, where
 * the lane-by-lane loop below compiled to scalar conversions and stores
 * (fill_packet16 was 1500 instructions, 2.5 % of a peer-box render). */
typedef float dr_f8f __attribute__((vector_size(8 * sizeof(float))));
static inline void store_floats8(float *dst, dr_f8 v)
{
    dr_f8f f = __builtin_convertvector(v, dr_f8f);
    memcpy(dst, &f, sizeof f);
}
static inline dr_f8 load_doubles8(const double *src)
{
    dr_f8 v;
    memcpy(&v, src, sizeof v);
    return v;
}
static inline void floats8(float *dst, const double *src)
{
    store_floats8(dst, load_doubles8(src));
}
/* ... the same for tfar: a tmax of FLT_MAX or more is Embree's infinity (fill_ray) */
static inline void tfar8(float *dst, const double *tmax)
{
    dr_f8 t = load_doubles8(tmax);
    store_floats8(dst, dr_f8_sel(dr_f8_ge(t, dr_f8s(FLT_MAX)), dr_f8s(INFINITY), t));
}

/* Packet r from rays [first, first + m): lane j from ray first + j, as
 * fill_ray converts it (the same floats); lanes from m on unused, masked off
 * by valid and also well-formed, inactive rays (tfar < tnear), as Embree's
 * 8-wide split of a 16-wide packet checks every lane of a half it traces (an
 * assertion on machines without AVX-512). One field at a time, so that the
 * compiler stores each field's lanes as vectors. The ray's id is its lane in
 * the group of DR_ACCEL_PACKET (id0 + j: the filters find its key and
 * answer by it). One body for Embree's 8- and 16-wide layouts. */
#define DEFINE_FILL_PACKET(W)                                                                                  \
    static void fill_packet##W(struct RTCRay##W *r, const struct dr_accel_rays *rays, int first, int m,         \
                               unsigned id0)                                                                    \
    {                                                                                                           \
        const bool whole = !rays->o && m == W;   /* a full packet from arrays: whole vectors */                 \
        if (whole) {                                                                                            \
            for (int b = 0; b < W; b += 8) {                                                                    \
                floats8(r->org_x + b, rays->ox + first + b), floats8(r->org_y + b, rays->oy + first + b);       \
                floats8(r->org_z + b, rays->oz + first + b), floats8(r->dir_x + b, rays->dx + first + b);       \
                floats8(r->dir_y + b, rays->dy + first + b), floats8(r->dir_z + b, rays->dz + first + b);       \
                tfar8(r->tfar + b, rays->tmax + first + b);                                                     \
            }                                                                                                   \
        } else if (rays->o) {                                                                                   \
            const dr_vec3 *o = rays->o + first, *d = rays->d + first;                                           \
            for (int j = 0; j < W; j++) {                                                                       \
                r->org_x[j] = j < m ? (float)o[j].x : 0.0f;                                                     \
                r->org_y[j] = j < m ? (float)o[j].y : 0.0f;                                                     \
                r->org_z[j] = j < m ? (float)o[j].z : 0.0f;                                                     \
            }                                                                                                   \
            for (int j = 0; j < W; j++) {                                                                       \
                r->dir_x[j] = j < m ? (float)d[j].x : 0.0f;                                                     \
                r->dir_y[j] = j < m ? (float)d[j].y : 0.0f;                                                     \
                r->dir_z[j] = j < m ? (float)d[j].z : 1.0f;                                                     \
            }                                                                                                   \
        } else {                                                                                                \
            for (int j = 0; j < W; j++) r->org_x[j] = j < m ? (float)rays->ox[first + j] : 0.0f;               \
            for (int j = 0; j < W; j++) r->org_y[j] = j < m ? (float)rays->oy[first + j] : 0.0f;               \
            for (int j = 0; j < W; j++) r->org_z[j] = j < m ? (float)rays->oz[first + j] : 0.0f;               \
            for (int j = 0; j < W; j++) r->dir_x[j] = j < m ? (float)rays->dx[first + j] : 0.0f;               \
            for (int j = 0; j < W; j++) r->dir_y[j] = j < m ? (float)rays->dy[first + j] : 0.0f;               \
            for (int j = 0; j < W; j++) r->dir_z[j] = j < m ? (float)rays->dz[first + j] : 1.0f;               \
        }                                                                                                       \
        const double *tmax = rays->tmax + first;                                                                \
        for (int j = 0; !whole && j < W; j++)                                                                   \
            r->tfar[j] = j >= m ? -INFINITY : tmax[j] >= FLT_MAX ? INFINITY : (float)tmax[j];                   \
        for (int j = 0; j < W; j++) {                                                                           \
            r->tnear[j] = 0.0f;                                                                                 \
            r->time[j] = 0.0f;                                                                                  \
            r->mask[j] = j < m ? 0xFFFFFFFFu : 0u;                                                              \
            r->id[j] = id0 + (unsigned)j;                                                                       \
            r->flags[j] = 0;                                                                                    \
        }                                                                                                       \
    }
DEFINE_FILL_PACKET(8)
DEFINE_FILL_PACKET(16)
#undef DEFINE_FILL_PACKET

/* Ray i's origin and direction, in either layout. */
static dr_vec3 ray_o(const struct dr_accel_rays *rays, int i)
{
    return rays->o ? rays->o[i] : dr_v3(rays->ox[i], rays->oy[i], rays->oz[i]);
}
static dr_vec3 ray_d(const struct dr_accel_rays *rays, int i)
{
    return rays->d ? rays->d[i] : dr_v3(rays->dx[i], rays->dy[i], rays->dz[i]);
}

/* Packet k's lanes: rays [16k, min(16k + 16, n)); valid marks them. */
static int packet_lanes(const struct dr_accel *a, const struct dr_accel_rays *rays, int k, int valid[DR_ACCEL_PACKET],
                        struct query_ctx *q)
{
    int first = k * DR_ACCEL_PACKET, m = rays->n - first < DR_ACCEL_PACKET ? rays->n - first : DR_ACCEL_PACKET;
    for (int j = 0; j < DR_ACCEL_PACKET; j++)
        valid[j] = j < m ? -1 : 0;
    rtcInitIntersectContext(&q->rtc);
    q->rtc.flags = first + m <= rays->coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT
                                               : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    q->accel = a;
    q->key = 0;
    q->keys = rays->key ? rays->key + first : NULL;
    q->passed = NULL;
    return m;
}

/* Packet k's closest hits (a plain query where a->plain): tri[j] for ray 16k + j (-1: none)
 * and, where asked, Embree's barycentrics. Returns its number of rays.
 * Traced as one 16-wide packet where the device's kernels are 16 wide, else
 * as two 8-wide ones (a->packet8): Embree splits a 16-wide packet into
 * such halves anyway, but through a copy; its coherent rays traced at 28
 * Mrays/s as 16-wide packets against 33-45 as 8-wide ones on an AVX2
 * machine (bench part a, runs 12 and 13), and the peer's box renders in
 * 0.93 x the time at depth 1, 0.96 x at depth 8. The same hits either way
 * (test_render's images). */
static int packet_intersect(const struct dr_accel *a, const struct dr_accel_rays *rays, int k,
                            int64_t *tri, float *u, float *v)
{
    int valid[DR_ACCEL_PACKET] __attribute__((aligned(64)));   /* Embree: 64-byte aligned */
    struct query_ctx q;
    int first = k * DR_ACCEL_PACKET, m = packet_lanes(a, rays, k, valid, &q);
    unsigned geom[DR_ACCEL_PACKET], prim[DR_ACCEL_PACKET];
    float hu[DR_ACCEL_PACKET], hv[DR_ACCEL_PACKET];
    if (a->packet8) {
        for (int h = 0; h * 8 < m; h++) {
            struct RTCRayHit8 rh __attribute__((aligned(32)));
            fill_packet8(&rh.ray, rays, first + 8 * h, m - 8 * h, 8u * (unsigned)h);
            for (int j = 0; j < 8; j++) {
                rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect8(valid + 8 * h, a->scene, &q.rtc, &rh);
            memcpy(geom + 8 * h, rh.hit.geomID, sizeof rh.hit.geomID);
            memcpy(prim + 8 * h, rh.hit.primID, sizeof rh.hit.primID);
            memcpy(hu + 8 * h, rh.hit.u, sizeof rh.hit.u);
            memcpy(hv + 8 * h, rh.hit.v, sizeof rh.hit.v);
        }
    } else {
        struct RTCRayHit16 rh __attribute__((aligned(64)));
        fill_packet16(&rh.ray, rays, first, m, 0);
        for (int j = 0; j < DR_ACCEL_PACKET; j++) {
            rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid, a->scene, &q.rtc, &rh);
        memcpy(geom, rh.hit.geomID, sizeof geom);
        memcpy(prim, rh.hit.primID, sizeof prim);
        memcpy(hu, rh.hit.u, sizeof hu);
        memcpy(hv, rh.hit.v, sizeof hv);
    }
    for (int j = 0; j < m; j++) {
        tri[j] = geom[j] == RTC_INVALID_GEOMETRY_ID ? -1 : scene_tri(a, geom[j], prim[j]);
        if (u) {
            u[j] = hu[j];
            v[j] = hv[j];
        }
    }
    return m;
}

static uint64_t ray_key(const struct dr_accel_rays *rays, int i)
{
    return rays->key ? rays->key[i] : 0;
}

void dr_accel_intersect_many(const struct dr_accel *a, const struct dr_accel_rays *rays, int64_t *tri)
{
    for (int k = 0; k * DR_ACCEL_PACKET < rays->n; k++) {
        int64_t *t = tri + k * DR_ACCEL_PACKET;
        if (!a->plain) {
            packet_intersect(a, rays, k, t, NULL, NULL);
            continue;
        }
        float u[DR_ACCEL_PACKET], v[DR_ACCEL_PACKET];
        int m = packet_intersect(a, rays, k, t, u, v);
        for (int j = 0, i = k * DR_ACCEL_PACKET; j < m; j++, i++)
            if (t[j] >= 0 && !filter_accepts(a, t[j], u[j], v[j], ray_d(rays, i), ray_key(rays, i)))
                t[j] = filtered_intersect(a, ray_o(rays, i), ray_d(rays, i), 0.0, rays->tmax[i], ray_key(rays, i));
    }
}

/* Rays [first, first + m)'s any-hit queries (q's filter, if any), in the width
 * packet_intersect uses; tfar[j] < 0: ray first + j is blocked. */
static void occluded_packet(const struct dr_accel *a, const struct dr_accel_rays *rays, int first, int m,
                            int *valid, struct query_ctx *q, float *tfar)
{
    if (a->packet8) {
        for (int h = 0; h * 8 < m; h++) {
            struct RTCRay8 r __attribute__((aligned(32)));
            fill_packet8(&r, rays, first + 8 * h, m - 8 * h, 8u * (unsigned)h);
            rtcOccluded8(valid + 8 * h, a->scene, &q->rtc, &r);
            memcpy(tfar + 8 * h, r.tfar, sizeof r.tfar);
        }
        return;
    }
    struct RTCRay16 r __attribute__((aligned(64)));
    fill_packet16(&r, rays, first, m, 0);
    rtcOccluded16(valid, a->scene, &q->rtc, &r);
    memcpy(tfar, r.tfar, sizeof r.tfar);
}

void dr_accel_occluded_many(const struct dr_accel *a, const struct dr_accel_rays *rays, bool *occluded)
{
    for (int k = 0; k * DR_ACCEL_PACKET < rays->n; k++) {
        int first = k * DR_ACCEL_PACKET;
        int valid[DR_ACCEL_PACKET] __attribute__((aligned(64)));   /* Embree: 64-byte aligned */
        struct query_ctx q;
        bool passed[DR_ACCEL_PACKET] = {false};
        int m = packet_lanes(a, rays, k, valid, &q);
        if (a->plain)
            q.passed = passed;   /* plain: any blocker, and whether it counts (first_blocker_filter) */
        float tfar[DR_ACCEL_PACKET];
        occluded_packet(a, rays, first, m, valid, &q, tfar);
        if (!a->plain) {
            for (int j = 0; j < m; j++)
                occluded[first + j] = tfar[j] < 0.0f;
            continue;
        }
        for (int j = 0, i = first; j < m; j++, i++)
            occluded[i] = tfar[j] < 0.0f &&
                          (!passed[j] || dr_accel_occluded_key(a, ray_o(rays, i), ray_d(rays, i), 0.0,
                                                               rays->tmax[i], ray_key(rays, i)));
    }
}
