/* The packet tracer's radiance in structure-of-arrays form: `render`'s
 * common case, every hit shaded eight lanes at a time (path_simd.h).
 *
 * wavefront.c keeps each path in a lane structure of about 1.9 KB (its
 * state, sampler, whole vertex, replay log and caller's state) and gathers
 * eight of them into vectors at every stage; most of its own time went to
 * cache misses on those structures, visited five times per step. Here a
 * path is a slot in a set of arrays that hold only what the radiance needs
 * (ray, throughput, previous point and density, depth, sampler key, sum),
 * live paths are kept contiguous (compacted after every bounce), and a
 * group of eight is eight consecutive slots. The shading is path_simd.c's
 * kernels, so every path gets the same bits as the one-path walker
 * (test_render compares them in double).
 *
 * It applies where every hit can take the eight-lane stages: a run that
 * dr_path8_applies to, without parameters, with the independent sampler.
 * Rays that leave the scene take the scalar stage (the environment's
 * radiance) and end there. */
#ifndef DR_WAVE_SOA_H
#define DR_WAVE_SOA_H

#include <stddef.h>
#include <stdint.h>

#include "path.h"
#include "scene.h"
#include "wavefront.h"

struct dr_wave_soa;

/* Working storage of one thread. NULL: out of memory. */
struct dr_wave_soa *dr_wave_soa_create(void);
void dr_wave_soa_destroy(struct dr_wave_soa *w);
/* Bytes dr_wave_soa_create allocates (for memory estimates). */
size_t dr_wave_soa_bytes(void);

/* Can a radiance run use it (opts without parameters, paths whose samplers
 * are of kind `sampler_kind`)? */
bool dr_wave_soa_applies(const struct dr_scene *scene, const struct dr_path_opts *opts, uint32_t sampler_kind);

/* L[i] = the radiance of path i for i in [0, n), as dr_wave_radiance. */
void dr_wave_soa_radiance(struct dr_wave_soa *w, const struct dr_scene *scene, const struct dr_path_opts *opts,
                          int64_t n, dr_wave_start_fn start, void *ctx, dr_vec3 *L,
                          struct dr_ray_counts *counts);

#endif
