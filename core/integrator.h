/* Unidirectional path tracing with next-event estimation and multiple
 * importance sampling (power heuristic), Russian roulette after rr_depth.
 * Depth counts path segments: max_depth 1 shows only what the camera sees
 * directly emitting, 2 adds direct lighting, 8 = camera ray + 7 bounces. */
#ifndef DR_INTEGRATOR_H
#define DR_INTEGRATOR_H

#include <stdint.h>

#include "sampler.h"
#include "scene.h"
#include "vec.h"

struct dr_trace_opts {
    int max_depth;
    int rr_depth;          /* Russian roulette from this depth on (segments) */
};

struct dr_ray_counts {
    uint64_t camera, extension, shadow;
};

/* Dimensions a path uses: 2 for the pixel position, then a fixed block per
 * vertex so each decision owns its own random numbers whatever came before. */
#define DR_DIMS_CAMERA 2
#define DR_DIMS_PER_VERTEX 8

/* Radiance arriving at o from direction d (unit). */
dr_vec3 dr_path_radiance(const struct dr_scene *scene, const struct dr_trace_opts *opts, dr_vec3 o, dr_vec3 d,
                         struct dr_sampler *sampler, struct dr_ray_counts *counts);

/* Power heuristic (beta = 2) weight of strategy a against b. */
static inline double dr_mis_power(double pdf_a, double pdf_b)
{
    if (!(pdf_a > 0.0))
        return 0.0;
    if (!(pdf_b > 0.0))
        return 1.0;
    double r = pdf_b / pdf_a;   /* ratio form stays finite for huge densities */
    return 1.0 / (1.0 + r * r);
}

#endif
