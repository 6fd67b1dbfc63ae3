/* What a packet/wavefront tracer could gain on Embree's side (issue 11),
 * measured on the rays a path tracer really casts rather than on random ones.
 *
 * Records the rays of diffuse paths through a scene (camera rays; at every
 * hit a shadow ray to a light point drawn by drender's own light sampler
 * (dr_light_sample: emitting triangles by power, points uniform) and a
 * cosine-sampled bounce; Russian roulette from depth 5 with drender's
 * survival probability min(max(throughput), 0.95), the throughput being the
 * product of the base colours; at most MAX_DEPTH segments): the same mix of extension and shadow rays that `drender render`
 * casts on the Cornell boxes, whose surfaces are all Lambertian. Recording
 * uses drender's own acceleration structure (core/accel.c, with its coverage
 * filter), so hits, culling and offsets are drender's. Then the identical
 * ray set is replayed, timed, through:
 *   drender_accel_path    dr_accel_intersect / dr_accel_occluded, one ray at
 *                         a time in path order (what the renderer does now,
 *                         filter included);
 *   rtc1_path             raw rtcIntersect1 / rtcOccluded1, path order;
 *   rtc1_wavefront        the same, all paths' depth-k rays together
 *                         (wavefront order);
 *   rtc16_wavefront       16-wide packets in wavefront order;
 *   rtc1M_wavefront       streams of 256 rays in wavefront order.
 * The raw scene is built like drender's (default traversal, high quality) without the
 * filter; on scenes whose materials are all single-sided the filter is the
 * difference between the first two lines.
 *
 *   path_rays SCENE [WIDTH HEIGHT SPP [THREADS [MAX_DEPTH]]]
 *
 * Prints one JSON object: rays per sample by kind and Mrays/s per variant.
 * Timings only; nothing here is checked (make bench runs it). */
#include <embree3/rtcore.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "camera.h"
#include "clock.h"
#include "path_args.h"
#include "raw_scene.h"
#include "error.h"
#include "geometry.h"
#include "lights.h"
#include "sampler.h"
#include "scene.h"

#define STREAM 256

struct ray {
    float o[3], d[3], tfar;
    uint32_t seq;   /* recording order: the order within a depth in wavefront order */
    uint8_t shadow, depth;
};

struct rays {
    struct ray *r;
    size_t n, cap;
};

static void push(struct rays *rs, dr_vec3 o, dr_vec3 d, double tfar, bool shadow, int depth)
{
    if (rs->n == rs->cap) {
        rs->cap = rs->cap ? 2 * rs->cap : 1 << 20;
        rs->r = realloc(rs->r, rs->cap * sizeof *rs->r);
        if (!rs->r) {
            fprintf(stderr, "path_rays: out of memory\n");
            exit(1);
        }
    }
    const uint32_t seq = (uint32_t)rs->n;
    rs->r[rs->n++] = (struct ray){{(float)o.x, (float)o.y, (float)o.z}, {(float)d.x, (float)d.y, (float)d.z},
                                  tfar >= FLT_MAX ? INFINITY : (float)tfar, seq, shadow, (uint8_t)depth};
}

/* ---- recording ---------------------------------------------------------- */

/* A cosine-distributed direction around n (the Lambertian walls' sampling;
 * the map differs from core/bsdf.c's concentric one, the distribution not). */
static dr_vec3 cosine_dir(dr_vec3 n, double u1, double u2)
{
    const dr_frame f = dr_frame_from_normal(n);
    double r = sqrt(u1), ph = 2.0 * M_PI * u2;
    return dr_frame_to_world(&f, dr_v3(r * cos(ph), r * sin(ph), sqrt(fmax(0.0, 1.0 - u1))));
}

/* One path from pixel (x, y), sample s: its rays appended to rs. Hits,
 * light points and ray offsets are drender's (core/geometry.h). */
static void record_path(const struct dr_scene *sc, const struct dr_accel *acc, const struct dr_camera_view *view,
                        int x, int y, int s, int max_depth, struct rays *rs)
{
    struct dr_sampler smp;
    dr_sampler_init(&smp, 7, (uint64_t)y * 65536u + (uint64_t)x, (uint64_t)s);
    dr_vec3 o, d;
    dr_camera_ray(view, x + dr_sampler_next(&smp), y + dr_sampler_next(&smp), &o, &d);
    double beta = 1.0;
    for (int depth = 0; depth < max_depth; depth++) {
        push(rs, o, d, INFINITY, false, depth);
        int64_t tri = dr_accel_intersect(acc, o, d, 0.0, INFINITY);
        if (tri < 0)
            return;
        struct dr_hit h;
        dr_hit_compute(&sc->mesh, tri, o, d, &h);
        const dr_vec3 n = h.front ? h.ng : dr_neg(h.ng);   /* the side the ray arrived on */
        const dr_vec3 c = sc->materials[h.material].base_color;
        beta *= fmax(c.x, fmax(c.y, c.z));
        if (!(beta > 0.0))
            return;   /* a black surface: no shadow ray, no bounce, as drender */
        /* next-event estimation: one shadow ray, to a light point chosen
         * as drender chooses it (dr_light_sample: emitters by power, their
         * points uniform by area; a sky as from a Lambertian surface, by the
         * cosine), ending where drender's ends */
        double u_pick = dr_sampler_next(&smp), u1 = dr_sampler_next(&smp), u2 = dr_sampler_next(&smp);
        const struct dr_bsdf lambert = {.base_color = c, .roughness = 1.0};
        const dr_frame frame = dr_frame_from_normal(n);
        const struct dr_sky_bsdf sky = {&lambert, frame, dr_frame_to_local(&frame, dr_neg(d)), n, 0.0};
        struct dr_light_sample ls;
        if (dr_light_sample(sc, sc->light_sampler, h.p, &sky, u_pick, u1, u2, &ls) && dr_dot(ls.wi, n) > 0.0) {
            dr_vec3 po = dr_offset_origin(&h, n, ls.wi);
            if (isinf(ls.dist))
                push(rs, po, ls.wi, INFINITY, true, depth);
            else {
                dr_vec3 to = dr_sub(ls.target, po);
                double dist = dr_length(to);
                if (dist > 0.0)
                    push(rs, po, dr_scale(to, 1.0 / dist), dist, true, depth);
            }
        }
        if (depth + 1 >= 5) {   /* roulette from depth 5 (segments so far) */
            double q = fmin(beta, 0.95);
            if (dr_sampler_next(&smp) >= q)
                return;
            beta /= q;
        }
        d = cosine_dir(n, dr_sampler_next(&smp), dr_sampler_next(&smp));
        o = dr_offset_origin(&h, n, d);
    }
}

/* ---- replay --------------------------------------------------------------- */

enum variant { DRENDER_PATH, RTC1_PATH, RTC1_WAVE, RTC16_WAVE, RTC1M_WAVE, VARIANTS };
static const char *const variant_names[VARIANTS] = {"drender_accel_path", "rtc1_path", "rtc1_wavefront",
                                                    "rtc16_wavefront", "rtc1M_wavefront"};

struct job {
    const struct ray *r;
    size_t n;
    enum variant v;
    RTCScene raw;
    const struct dr_accel *acc;
    long hits;
};

static void rtc_ray(struct RTCRay *out, const struct ray *r)
{
    memset(out, 0, sizeof *out);
    memcpy(&out->org_x, r->o, sizeof r->o);
    memcpy(&out->dir_x, r->d, sizeof r->d);
    out->tfar = r->tfar;
    out->mask = 0xFFFFFFFFu;
}

static long one_at_a_time(const struct job *j, struct RTCIntersectContext *ctx)
{
    long hits = 0;
    for (size_t i = 0; i < j->n; i++) {
        const struct ray *r = &j->r[i];
        if (j->v == DRENDER_PATH) {
            dr_vec3 o = dr_v3(r->o[0], r->o[1], r->o[2]), d = dr_v3(r->d[0], r->d[1], r->d[2]);
            hits += r->shadow ? dr_accel_occluded(j->acc, o, d, 0.0, r->tfar)
                              : dr_accel_intersect(j->acc, o, d, 0.0, r->tfar) >= 0;
        } else if (r->shadow) {
            struct RTCRay q;
            rtc_ray(&q, r);
            rtcOccluded1(j->raw, ctx, &q);
            hits += q.tfar < 0.0f;
        } else {
            struct RTCRayHit q;
            rtc_ray(&q.ray, r);
            q.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(j->raw, ctx, &q);
            hits += q.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        }
    }
    return hits;
}

/* Rays [i, i + n) of one kind into a 16-wide packet and through Embree. */
static long packet16(const struct job *j, struct RTCIntersectContext *ctx, size_t i, int n, bool shadow)
{
    _Alignas(64) struct RTCRayHit16 p;
    _Alignas(64) int valid[16];
    memset(&p, 0, sizeof p);
    for (int l = 0; l < 16; l++) {
        const struct ray *r = &j->r[i + (size_t)(l < n ? l : n - 1)];
        valid[l] = l < n ? -1 : 0;
        p.ray.org_x[l] = r->o[0], p.ray.org_y[l] = r->o[1], p.ray.org_z[l] = r->o[2];
        p.ray.dir_x[l] = r->d[0], p.ray.dir_y[l] = r->d[1], p.ray.dir_z[l] = r->d[2];
        p.ray.tfar[l] = r->tfar, p.ray.mask[l] = 0xFFFFFFFFu;
        p.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    }
    long hits = 0;
    if (shadow) {
        rtcOccluded16(valid, j->raw, ctx, &p.ray);
        for (int l = 0; l < n; l++)
            hits += p.ray.tfar[l] < 0.0f;
    } else {
        rtcIntersect16(valid, j->raw, ctx, &p);
        for (int l = 0; l < n; l++)
            hits += p.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID;
    }
    return hits;
}

static long stream(const struct job *j, struct RTCIntersectContext *ctx, size_t i, int n, bool shadow,
                   struct RTCRayHit *buf)
{
    for (int k = 0; k < n; k++) {
        rtc_ray(&buf[k].ray, &j->r[i + (size_t)k]);
        buf[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
    }
    long hits = 0;
    if (shadow) {
        rtcOccluded1M(j->raw, ctx, &buf[0].ray, (unsigned)n, sizeof *buf);
        for (int k = 0; k < n; k++)
            hits += buf[k].ray.tfar < 0.0f;
    } else {
        rtcIntersect1M(j->raw, ctx, buf, (unsigned)n, sizeof *buf);
        for (int k = 0; k < n; k++)
            hits += buf[k].hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
    return hits;
}

static void *replay(void *arg)
{
    struct job *j = arg;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    if (j->v <= RTC1_WAVE) {
        j->hits = one_at_a_time(j, &ctx);
        return NULL;
    }
    struct RTCRayHit *buf = aligned_alloc(64, sizeof(struct RTCRayHit) * STREAM);
    long hits = 0;
    const int width = j->v == RTC16_WAVE ? 16 : STREAM;
    for (size_t i = 0; i < j->n;) {   /* runs of one kind, cut into packets or streams */
        const bool shadow = j->r[i].shadow;
        int n = 0;
        while (n < width && i + (size_t)n < j->n && j->r[i + (size_t)n].shadow == shadow)
            n++;
        hits += j->v == RTC16_WAVE ? packet16(j, &ctx, i, n, shadow) : stream(j, &ctx, i, n, shadow, buf);
        i += (size_t)n;
    }
    free(buf);
    j->hits = hits;
    return NULL;
}

static int by_depth_kind(const void *a, const void *b)
{
    const struct ray *x = a, *y = b;
    int kx = x->depth * 2 + x->shadow, ky = y->depth * 2 + y->shadow;
    if (kx != ky)
        return (kx > ky) - (kx < ky);
    return (x->seq > y->seq) - (x->seq < y->seq);
}

/* Each thread replays its share: whole paths in path order, or the same rays
 * sorted by depth and kind, recording order within (wavefront order). */
static double timed(struct rays *per_thread, int threads, enum variant v, RTCScene raw, const struct dr_accel *acc,
                    long *hits)
{
    struct job j[64];
    pthread_t id[64];
    for (int t = 0; t < threads; t++)
        j[t] = (struct job){per_thread[t].r, per_thread[t].n, v, raw, acc, 0};
    double t0 = dr_clock_seconds();
    for (int t = 1; t < threads; t++)
        pthread_create(&id[t], NULL, replay, &j[t]);
    replay(&j[0]);
    for (int t = 1; t < threads; t++)
        pthread_join(id[t], NULL);
    double sec = dr_clock_seconds() - t0;
    *hits = 0;
    for (int t = 0; t < threads; t++)
        *hits += j[t].hits;
    return sec;
}

int main(int argc, char **argv)
{
    struct path_args args;
    struct dr_scene *sc;
    int rc = path_args_open(argc, argv, "path_rays", 8, &args, &sc);
    if (rc)
        return rc;
    const int W = args.width, H = args.height, S = args.spp, T = args.threads, D = args.max_depth;
    struct dr_accel *acc = dr_accel_create_scene(sc);
    if (!acc) {
        fprintf(stderr, "path_rays: %s: %s\n", args.scene, dr_last_error());
        return 1;
    }
    const struct dr_camera cam = sc->n_cameras > 0 ? sc->cameras[0] : dr_camera_default(sc);
    const struct dr_camera_view view = dr_camera_view(&cam, W, H);
    /* thread t records rows t, t + T, ...: its share, in path order */
    struct rays path[64] = {{0}}, wave[64] = {{0}};
    size_t counts[2] = {0, 0};
    for (int t = 0; t < T; t++) {
        for (int y = t; y < H; y += T)
            for (int x = 0; x < W; x++)
                for (int s = 0; s < S; s++)
                    record_path(sc, acc, &view, x, y, s, D, &path[t]);
        wave[t].n = wave[t].cap = path[t].n;
        wave[t].r = malloc(sizeof(struct ray) * (path[t].n + 1));
        memcpy(wave[t].r, path[t].r, sizeof(struct ray) * path[t].n);
        qsort(wave[t].r, wave[t].n, sizeof(struct ray), by_depth_kind);
        for (size_t i = 0; i < path[t].n; i++)
            counts[path[t].r[i].shadow]++;
    }
    RTCDevice dev = rtcNewDevice(NULL);
    RTCScene raw = bench_raw_scene(dev, sc);
    const double samples = (double)W * H * S, total = (double)(counts[0] + counts[1]);
    printf("{\"scene\": \"%s\", \"width\": %d, \"height\": %d, \"spp\": %d, \"threads\": %d, \"max_depth\": %d, "
           "\"rays_per_sample\": {\"extension\": %.3f, \"shadow\": %.3f}, \"mrays_per_second\": {",
           argv[1], W, H, S, T, D, counts[0] / samples, counts[1] / samples);
    for (int v = 0; v < VARIANTS; v++) {
        struct rays *set = v == DRENDER_PATH || v == RTC1_PATH ? path : wave;
        long hits;
        timed(set, T, (enum variant)v, raw, acc, &hits);   /* warm-up */
        double best = INFINITY;
        for (int rep = 0; rep < 3; rep++)
            best = fmin(best, timed(set, T, (enum variant)v, raw, acc, &hits));
        printf("%s\"%s\": %.2f", v ? ", " : "", variant_names[v], total / best * 1e-6);
        fflush(stdout);
    }
    printf("}}\n");
    for (int t = 0; t < T; t++) {
        free(path[t].r);
        free(wave[t].r);
    }
    rtcReleaseScene(raw);
    rtcReleaseDevice(dev);
    dr_accel_destroy(acc);
    dr_scene_destroy(sc);
    return 0;
}
