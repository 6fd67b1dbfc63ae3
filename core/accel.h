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

/* Builds a robust-mode BVH over mesh (which must outlive the accel). */
struct dr_accel *dr_accel_create(const struct dr_mesh *mesh);
void dr_accel_destroy(struct dr_accel *accel);

/* Closest hit along o + t d, t in (tmin, tmax). Returns the triangle index or
 * -1. Safe to call from many threads at once. */
int64_t dr_accel_intersect(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax);
/* True when anything blocks o + t d for t in (tmin, tmax). */
bool dr_accel_occluded(const struct dr_accel *accel, dr_vec3 o, dr_vec3 d, double tmin, double tmax);

#endif
