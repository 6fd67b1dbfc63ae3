/* Many paths advanced together, one stage at a time (the packet renderer):
 * every live path is traced in one batch of Embree packets, shaded, its
 * shadow rays tested in a second batch, and continued; a path that ends
 * frees its lane for the next one. Each path runs exactly the one-path
 * walker's stages (path.h: dr_path_step cut at its ray queries), so it
 * makes the same decisions with the same numbers; only the order in which
 * paths are worked on changes. Scenes with media use the one-path walker. */
#ifndef DR_WAVEFRONT_H
#define DR_WAVEFRONT_H

#include <stdint.h>

#include "path.h"
#include "sampler.h"
#include "scene.h"

/* Paths in flight per wavefront: four 16-wide packets. */
#define DR_WAVE_LANES 64

struct dr_wave;

/* Per-thread working storage (about DR_WAVE_LANES path vertices). NULL: out of memory. */
struct dr_wave *dr_wave_create(void);
void dr_wave_destroy(struct dr_wave *wave);
/* Bytes dr_wave_create allocates (for memory estimates). */
size_t dr_wave_bytes(void);

/* Starts path i: its sampler, and its camera ray o + t d. */
typedef void (*dr_wave_start_fn)(void *ctx, int64_t i, struct dr_sampler *sampler, dr_vec3 *o, dr_vec3 *d);

/* L[i] = the radiance of path i for i in [0, n), what dr_path_radiance gives
 * for the same start (up to exact ties between triangles, accel.h). */
void dr_wave_radiance(struct dr_wave *wave, const struct dr_scene *scene, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, void *ctx, dr_vec3 *L, struct dr_ray_counts *counts);

#endif
