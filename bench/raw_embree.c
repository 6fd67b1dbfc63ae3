/* Raw Embree ray casting on a scene's geometry: the ceilings for drender's own
 * ray throughput. Loads the scene through drender (so the geometry is
 * identical), builds its own Embree BVH with the same flags, and casts rays
 * on T threads through three of Embree's interfaces:
 *   rtcIntersect1    one ray per call (what drender does today),
 *   rtcIntersect8    8-wide SoA packets (native on AVX2 machines),
 *   rtcIntersect16   16-wide SoA packets (native with AVX-512),
 *   rtcIntersect1M   streams of 256 AoS rays per call,
 * for two ray sets:
 *   incoherent  uniform origins in the bounding box, uniform directions
 *               (like bounce rays),
 *   coherent    pinhole camera rays through a 512x512 image in 8x8 tiles
 *               (like primary rays), from outside the bounding box.
 * Every variant generates its rays into the same 256-ray batch first, so the
 * generation cost is the same for all; the time covers generation + casting.
 * Prints one JSON object: the historical rtcIntersect1-incoherent figure at
 * the top level (rays_per_second) and all six in "ceilings". */
#include <embree3/rtcore.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "raw_scene.h"
#include "error.h"
#include "sampler.h"
#include "scene.h"

#define BATCH 256

enum api { API_1, API_8, API_16, API_1M, API_COUNT };
enum pattern { INCOHERENT, COHERENT, PATTERN_COUNT };
static const char *const api_names[API_COUNT] = {"rtcIntersect1", "rtcIntersect8", "rtcIntersect16",
                                                        "rtcIntersect1M"};
static const char *const pattern_names[PATTERN_COUNT] = {"incoherent", "coherent"};

struct worker {
    RTCScene scene;
    dr_vec3 lo, hi;
    long rays;
    int index;
    enum api api;
    enum pattern pattern;
    long hits;
};

static void ray_init(struct RTCRayHit *rh, dr_vec3 o, dr_vec3 d)
{
    memset(rh, 0, sizeof *rh);
    rh->ray.org_x = (float)o.x, rh->ray.org_y = (float)o.y, rh->ray.org_z = (float)o.z;
    rh->ray.dir_x = (float)d.x, rh->ray.dir_y = (float)d.y, rh->ray.dir_z = (float)d.z;
    rh->ray.tfar = INFINITY;
    rh->ray.mask = 0xFFFFFFFFu;
    rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
}

/* Fills batch[0..n) with rays number first.. of the worker's ray set. */
static void generate(const struct worker *w, struct dr_sampler *s, long first, int n, struct RTCRayHit *batch)
{
    const dr_vec3 c = {0.5 * (w->lo.x + w->hi.x), 0.5 * (w->lo.y + w->hi.y), 0.5 * (w->lo.z + w->hi.z)};
    const double radius = 0.5 * sqrt((w->hi.x - w->lo.x) * (w->hi.x - w->lo.x) +
                                     (w->hi.y - w->lo.y) * (w->hi.y - w->lo.y) +
                                     (w->hi.z - w->lo.z) * (w->hi.z - w->lo.z));
    for (int i = 0; i < n; i++) {
        if (w->pattern == INCOHERENT) {
            s->dim = 0;
            s->key = dr_hash64(s->key + 1);
            double z = 1 - 2 * dr_sampler_next(s), r = sqrt(fmax(0, 1 - z * z)), ph = 2 * M_PI * dr_sampler_next(s);
            dr_vec3 o = {w->lo.x + (w->hi.x - w->lo.x) * dr_sampler_next(s),
                         w->lo.y + (w->hi.y - w->lo.y) * dr_sampler_next(s),
                         w->lo.z + (w->hi.z - w->lo.z) * dr_sampler_next(s)};
            ray_init(&batch[i], o, (dr_vec3){r * cos(ph), r * sin(ph), z});
        } else {
            /* pixel index -> 8x8 tile order over a 512x512 image, 40 degree view */
            long k = (first + i) % (512 * 512), tile = k / 64, in = k % 64;
            int px = (int)(tile % 64) * 8 + (int)(in % 8), py = (int)(tile / 64) * 8 + (int)(in / 8);
            double t = tan(0.5 * 40.0 * M_PI / 180.0);
            dr_vec3 d = {(2.0 * (px + 0.5) / 512 - 1) * t, (1 - 2.0 * (py + 0.5) / 512) * t, -1.0};
            double len = sqrt(d.x * d.x + d.y * d.y + 1.0);
            d.x /= len, d.y /= len, d.z /= len;
            ray_init(&batch[i], (dr_vec3){c.x, c.y, c.z + 2.5 * radius}, d);
        }
    }
}

/* Casts batch[0..n) as W-wide packets of type RAYHIT through INTERSECT
 * (lanes past n repeat the last ray, masked off by valid). */
#define CAST_PACKETS(W, RAYHIT, INTERSECT) \
    for (int b = 0; b < n; b += (W)) { \
        _Alignas(64) struct RAYHIT p; \
        _Alignas(64) int valid[W]; \
        for (int l = 0; l < (W); l++) { \
            const struct RTCRayHit *r = &batch[b + l < n ? b + l : n - 1]; \
            valid[l] = b + l < n ? -1 : 0; \
            p.ray.org_x[l] = r->ray.org_x, p.ray.org_y[l] = r->ray.org_y, p.ray.org_z[l] = r->ray.org_z; \
            p.ray.dir_x[l] = r->ray.dir_x, p.ray.dir_y[l] = r->ray.dir_y, p.ray.dir_z[l] = r->ray.dir_z; \
            p.ray.tnear[l] = 0.0f, p.ray.tfar[l] = INFINITY, p.ray.time[l] = 0.0f; \
            p.ray.mask[l] = 0xFFFFFFFFu, p.ray.id[l] = 0, p.ray.flags[l] = 0; \
            p.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID; \
        } \
        INTERSECT(valid, w->scene, ctx, &p); \
        for (int l = 0; l < (W) && b + l < n; l++) \
            batch[b + l].hit.geomID = p.hit.geomID[l]; \
    }

static long cast_batch(const struct worker *w, struct RTCIntersectContext *ctx, struct RTCRayHit *batch, int n)
{
    long hits = 0;
    if (w->api == API_1) {
        for (int i = 0; i < n; i++)
            rtcIntersect1(w->scene, ctx, &batch[i]);
    } else if (w->api == API_1M) {
        rtcIntersect1M(w->scene, ctx, batch, (unsigned)n, sizeof *batch);
    } else if (w->api == API_8) {
        CAST_PACKETS(8, RTCRayHit8, rtcIntersect8)
    } else {
        CAST_PACKETS(16, RTCRayHit16, rtcIntersect16)
    }
    for (int i = 0; i < n; i++)
        hits += batch[i].hit.geomID != RTC_INVALID_GEOMETRY_ID;
    return hits;
}

static void *cast(void *arg)
{
    struct worker *w = arg;
    struct dr_sampler s;
    dr_sampler_init(&s, 12345, (uint64_t)w->index, 0);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = w->pattern == COHERENT ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    struct RTCRayHit *batch = aligned_alloc(64, sizeof(struct RTCRayHit) * BATCH);
    long hits = 0, first = (long)w->index * w->rays;
    for (long done = 0; done < w->rays; done += BATCH) {
        int n = w->rays - done < BATCH ? (int)(w->rays - done) : BATCH;
        generate(w, &s, first + done, n, batch);
        hits += cast_batch(w, &ctx, batch, n);
    }
    free(batch);
    w->hits = hits;
    return NULL;
}

/* One timed run of an api x pattern on T threads after a one-thread warm-up;
 * returns rays per second and the hit fraction. */
static double run(RTCScene es, const struct dr_scene *scene, long rays, int threads, enum api api,
                  enum pattern pattern, double *hit_fraction)
{
    struct worker w[64];
    pthread_t ids[64];
    for (int i = 0; i < threads; i++)
        w[i] = (struct worker){es, scene->bbox_min, scene->bbox_max, rays / threads, i, api, pattern, 0};
    struct worker warm = w[0];
    warm.rays = w[0].rays / 4 + 1;
    cast(&warm);   /* caches, lazy initialisation */
    double t0 = dr_clock_seconds();
    for (int i = 1; i < threads; i++)
        pthread_create(&ids[i], NULL, cast, &w[i]);
    cast(&w[0]);
    for (int i = 1; i < threads; i++)
        pthread_join(ids[i], NULL);
    double t = dr_clock_seconds() - t0;
    long total = (rays / threads) * threads, hits = 0;
    for (int i = 0; i < threads; i++)
        hits += w[i].hits;
    *hit_fraction = (double)hits / (double)total;
    return (double)total / t;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: raw_embree SCENE [RAYS] [THREADS]\n");
        return 2;
    }
    long rays = argc > 2 ? atol(argv[2]) : 4000000;
    int threads = argc > 3 ? atoi(argv[3]) : 2;
    if (threads < 1 || threads > 64)
        threads = 2;
    struct dr_scene *scene = dr_scene_load(argv[1]);
    if (!scene) {
        fprintf(stderr, "raw_embree: %s\n", dr_last_error());
        return 1;
    }
    RTCDevice dev = rtcNewDevice(NULL);
    RTCScene es = bench_raw_scene(dev, scene);
    double rps[API_COUNT][PATTERN_COUNT], hitf[API_COUNT][PATTERN_COUNT];
    for (int a = 0; a < API_COUNT; a++)
        for (int p = 0; p < PATTERN_COUNT; p++)
            rps[a][p] = run(es, scene, rays, threads, (enum api)a, (enum pattern)p, &hitf[a][p]);
    printf("{\"scene\": \"%s\", \"triangles\": %u, \"threads\": %d, \"rays\": %ld, \"rays_per_second\": %.1f, "
           "\"hit_fraction\": %.4f, \"ceilings\": {",
           argv[1], scene->mesh.n_triangles, threads, (rays / threads) * threads, rps[API_1][INCOHERENT],
           hitf[API_1][INCOHERENT]);
    for (int a = 0; a < API_COUNT; a++)
        for (int p = 0; p < PATTERN_COUNT; p++)
            printf("%s\"%s_%s\": %.1f", a + p ? ", " : "", api_names[a], pattern_names[p], rps[a][p]);
    printf("}, \"coherent_hit_fraction\": %.4f}\n", hitf[API_1][COHERENT]);
    rtcReleaseScene(es);
    rtcReleaseDevice(dev);
    dr_scene_destroy(scene);
    return 0;
}
