/* Ray queries. The only module that talks to Embree: it answers "which
 * triangle, and how far", and everything else about the hit is recomputed in
 * double by geometry.c (whose code has adjoints). */
#ifndef DR_ACCEL_H
#define DR_ACCEL_H

#include <stdbool.h>
#include <stdint.h>

#include "scene.h"
#include "vec.h"

struct dr_accel;

/* Builds a BVH over mesh (which must outlive the accel); every
 * triangle is opaque from both sides. */
struct dr_accel *dr_accel_create(const struct dr_mesh *mesh);
/* The same over scene->mesh, honouring alphaMode and doubleSided
 * (coverage.h) for every ray the scene's paths trace: single-sided
 * triangles whose backs no such ray can reach (scene->backface, backface.h)
 * are not culled, so a ray from anywhere else may meet their backs. The
 * scene must outlive the accel; its materials' alpha modes and sidedness
 * must not change afterwards. A scene without MASK/BLEND materials and
 * without single-sided triangles left to cull gets exactly
 * dr_accel_create's structure: no filter is installed. */
struct dr_accel *dr_accel_create_scene(const struct dr_scene *scene);
/* The same without the unfiltered copy (accel.c): every query runs the
 * filters. The reference the tests hold the fast path to. */
struct dr_accel *dr_accel_create_scene_filtered(const struct dr_scene *scene);
void dr_accel_destroy(struct dr_accel *accel);
/* Starts Embree's task system (a device and a one-triangle build, ~1 ms,
 * once per process). Its first start loads a library of its own, which
 * waits for any dlopen running on another thread: a scene whose images
 * decode beside its ray structure's build (scene.c) calls this before that
 * decode loads the image library, so that the build overlaps the load
 * instead of waiting 0.1-0.3 s for it. */
void dr_accel_warm_up(void);

/* Closest hit along o + t d, t in (tmin, tmax). Returns the triangle index or
 * -1. Safe to call from many threads at once. */
int64_t dr_accel_intersect(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax);
/* True when anything blocks o + t d for t in (tmin, tmax). */
bool dr_accel_occluded(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax);
/* The same with the query's key for stochastic transparency (alphaMode BLEND,
 * coverage.h: dr_coverage_key). The plain forms use key 0: right for queries
 * that only look past surfaces, wrong (every path would see the same BLEND
 * decisions) for a path's rays. */
int64_t dr_accel_intersect_key(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax,
                               uint64_t key);
bool dr_accel_occluded_key(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax,
                           uint64_t key);

/* Many rays at once, as Embree packets of DR_ACCEL_PACKET (the wavefront
 * renderer's stage boundaries): ray i from o[i] along d[i] over (0, tmax[i]),
 * with coverage key key[i] (NULL: all 0). Each ray gets the answer a single
 * query would give, except which of two triangles wins an exact tie in t
 * (Embree's packet and single-ray traversals visit nodes in different orders). */
#define DR_ACCEL_PACKET 16
struct dr_accel_rays {
    int n;
    const dr_vec3 *o, *d;
    const double *ox, *oy, *oz, *dx, *dy, *dz;   /* with o and d NULL: the same by coordinate
                                                    (for callers that keep rays as arrays) */
    const double *tmax;
    const uint64_t *key;
    int coherent;   /* the first `coherent` rays are alike (camera rays of one pixel's samples):
                       their full packets are traced with Embree's coherent flag */
};
/* tri[i]: the closest triangle or -1. */
void dr_accel_intersect_many(const struct dr_accel *accel, const struct dr_accel_rays *rays, int64_t *tri);
/* occluded[i]: anything blocks ray i. */
void dr_accel_occluded_many(const struct dr_accel *accel, const struct dr_accel_rays *rays, bool *occluded);

#endif
