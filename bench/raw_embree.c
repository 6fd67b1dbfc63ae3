/* Raw Embree incoherent ray casting on a scene's geometry: the ceiling for
 * drender's own ray throughput. Loads the scene through drender (so the
 * geometry is identical), builds its own Embree BVH with the same flags,
 * and casts random rays (uniform origins in the bounding box, uniform
 * directions) with rtcIntersect1 on T threads. Prints one JSON object. */
#include "clock.h"
#include <embree3/rtcore.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "sampler.h"
#include "scene.h"
#include "error.h"

struct worker {
    RTCScene scene;
    dr_vec3 lo, hi;
    long rays;
    int index;
    long hits;
};

static void *cast(void *arg)
{
    struct worker *w = arg;
    struct dr_sampler s;
    dr_sampler_init(&s, 12345, (uint64_t)w->index, 0);
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    long hits = 0;
    for (long i = 0; i < w->rays; i++) {
        s.dim = 0;
        s.key = dr_hash64(s.key + 1);
        double z = 1 - 2 * dr_sampler_next(&s), r = sqrt(fmax(0, 1 - z * z)), ph = 2 * M_PI * dr_sampler_next(&s);
        struct RTCRayHit rh;
        rh.ray.org_x = (float)(w->lo.x + (w->hi.x - w->lo.x) * dr_sampler_next(&s));
        rh.ray.org_y = (float)(w->lo.y + (w->hi.y - w->lo.y) * dr_sampler_next(&s));
        rh.ray.org_z = (float)(w->lo.z + (w->hi.z - w->lo.z) * dr_sampler_next(&s));
        rh.ray.dir_x = (float)(r * cos(ph));
        rh.ray.dir_y = (float)(r * sin(ph));
        rh.ray.dir_z = (float)z;
        rh.ray.tnear = 0.0f;
        rh.ray.tfar = INFINITY;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(w->scene, &ctx, &rh);
        hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
    w->hits = hits;
    return NULL;
}

static double now(void) { return dr_clock_seconds(); }

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: raw_embree SCENE [RAYS] [THREADS]\n");
        return 2;
    }
    long rays = argc > 2 ? atol(argv[2]) : 4000000;
    int threads = argc > 3 ? atoi(argv[3]) : 2;
    struct dr_scene *scene = dr_scene_load(argv[1]);
    if (!scene) {
        fprintf(stderr, "raw_embree: %s\n", dr_last_error());
        return 1;
    }
    RTCDevice dev = rtcNewDevice(NULL);
    RTCScene es = rtcNewScene(dev);
    rtcSetSceneFlags(es, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(es, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, scene->mesh.positions, 0,
                               3 * sizeof(float), scene->mesh.n_vertices);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, scene->mesh.indices, 0,
                               3 * sizeof(uint32_t), scene->mesh.n_triangles);
    rtcCommitGeometry(g);
    rtcAttachGeometry(es, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(es);

    struct worker w[64];
    pthread_t ids[64];
    if (threads < 1 || threads > 64)
        threads = 2;
    for (int i = 0; i < threads; i++)
        w[i] = (struct worker){es, scene->bbox_min, scene->bbox_max, rays / threads, i, 0};
    cast(&w[0]);   /* warm-up pass on one thread (caches, lazy init) */
    double t0 = now();
    for (int i = 1; i < threads; i++)
        pthread_create(&ids[i], NULL, cast, &w[i]);
    cast(&w[0]);
    for (int i = 1; i < threads; i++)
        pthread_join(ids[i], NULL);
    double t = now() - t0;
    long total = (rays / threads) * threads, hits = 0;
    for (int i = 0; i < threads; i++)
        hits += w[i].hits;
    printf("{\"scene\": \"%s\", \"triangles\": %u, \"threads\": %d, \"rays\": %ld, \"seconds\": %.4f, "
           "\"rays_per_second\": %.1f, \"hit_fraction\": %.4f}\n",
           argv[1], scene->mesh.n_triangles, threads, total, t, total / t, (double)hits / total);
    rtcReleaseScene(es);
    rtcReleaseDevice(dev);
    dr_scene_destroy(scene);
    return 0;
}
