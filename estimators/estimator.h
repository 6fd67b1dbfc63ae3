/* Gradient estimators: coarse-grained plug-ins behind one interface.
 * Adding one = one .c file in estimators/ + one line in registry.c.
 *
 * Both modes differentiate the rendered image I (mean of `spp` samples per
 * pixel) with respect to the parameters of `params`, with detached sampling:
 * directions, pdfs, MIS weights and Russian roulette are constants of the
 * derivative (differentiate-then-reparametrize with the forward sampler). */
#ifndef DR_ESTIMATOR_H
#define DR_ESTIMATOR_H

#include <stdbool.h>
#include <stdint.h>

#include "integrator.h"
#include "params.h"
#include "scene.h"

struct dr_grad_problem {
    const struct dr_scene *scene;
    const struct dr_camera *camera;
    const struct dr_param_set *params;
    int width, height, spp, max_depth, rr_depth;
    uint64_t seed;
    int threads;            /* <= 0: one per CPU */
    int64_t batch;          /* tape: paths per record/sweep (0: one sample of every pixel) */
};

struct dr_grad_stats {
    double seconds;
    struct dr_ray_counts rays;
    uint64_t invalid_samples;   /* non-finite path values or derivatives dropped */
    uint64_t tape_peak_bytes;   /* tape: largest tape held at once (all threads) */
    int threads;
};

struct dr_estimator_ops {
    const char *name, *summary;
    /* Forward mode: d_image (width * height * 3 doubles) = d I / d theta . dir,
     * dir having params->total entries. */
    int (*forward)(const struct dr_grad_problem *p, const double *dir, double *d_image, struct dr_grad_stats *st);
    /* Reverse mode: grad (params->total entries, overwritten) =
     * sum over pixels and channels of adjoint * d I / d theta, adjoint being
     * d loss / d I (width * height * 3 floats). */
    int (*backward)(const struct dr_grad_problem *p, const float *adjoint, double *grad, struct dr_grad_stats *st);
};

extern const struct dr_estimator_ops *const dr_estimators[];   /* NULL-terminated */
const struct dr_estimator_ops *dr_estimator_find(const char *name);

#endif
