/* How drender builds its Embree scenes: the flags and the build quality,
 * shared by core/accel.c and the bench's raw ceilings (bench/raw_scene.h),
 * so the ceiling is measured on the same kind of tree. */
#ifndef DR_ACCEL_BUILD_H
#define DR_ACCEL_BUILD_H

#include <embree3/rtcore.h>

/* Embree's default traversal, not RTC_SCENE_FLAG_ROBUST, which drender used
 * until 2026-11: robust mode was meant to stop rays slipping through the
 * shared edges of neighbouring triangles, but it does not stop them, and it
 * costs 15 % of a render. Measured on a closed box of 12 triangles with grey
 * walls, the camera inside and an environment of 1000 outside (a lit pixel
 * is a leak), 11 runs of 16 M paths (~1.3 G rays): 13 leaking pixels with
 * robust mode, 23 without, about one path in 13 M and in 8 M, far below any
 * render's noise. The peer's box renders in 0.85 x the time without it
 * (bench/ab.sh, 5 rounds). Mitsuba 3 traces without it too (its
 * embree_use_robust_intersections is off by default). */
#define DR_ACCEL_SCENE_FLAGS RTC_SCENE_FLAG_NONE

/* Medium quality (Embree's binned SAH builder), not high (spatial splits),
 * which drender used until 2026-12. Measured on 2 threads, 256x256, 64 spp,
 * depth 8, interleaved runs (bench/ab.sh): the big bench scene (127k
 * triangles) renders in 0.914 x the time and reaches its first ray 65 ms
 * sooner (its build took 82 ms); the big textured scene 0.939 x; the peer's
 * box (36 triangles) the same. The peer's and the bundled box render the
 * same images; the big scenes 2 pixels of 65 536 differ by one path's
 * worth: a ray through the edge two triangles share, at the same distance,
 * may be given either, and which one depends on the tree. */
#define DR_ACCEL_BUILD_QUALITY RTC_BUILD_QUALITY_MEDIUM

#endif
