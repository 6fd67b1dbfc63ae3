/* Checking an estimator against finite differences, statistically.
 *
 * Objective: J(theta) = mean over pixels and channels of the rendered image.
 * For each direction (every scalar of a colour or scalar parameter; for an
 * image, all texels at once and a fixed random +-1 pattern), K independent
 * batches (seeds seed + b) each give
 *   - the estimator's dJ/dtheta . dir in reverse mode (uniform adjoint) and in
 *     forward mode (mean of the derivative image),
 *   - a central difference (J(theta + eps dir) - J(theta - eps dir)) / 2 eps from
 *     two renders with the same seed (common random numbers); one-sided,
 *     second order, where theta - eps dir would leave the parameter's range.
 * Means and standard errors over the batches give z = (g - fd) / sqrt(se_g^2 + se_fd^2);
 * se_fd includes the bound on the differences' rounding error (the image's
 * float values), which is all that is left where the estimates are exact. */
#ifndef DR_FDCHECK_H
#define DR_FDCHECK_H

#include <stdbool.h>
#include <stdint.h>

#include "estimator.h"
#include "params.h"
#include "scene.h"

struct dr_fd_options {
    const struct dr_estimator_ops *estimator;
    enum dr_sampling sampling;
    enum dr_medium_grad medium_grad;   /* media: drt (default) or baseline */
    int width, height;
    int spp;            /* per batch */
    int batches;        /* >= 2 */
    int max_depth, rr_depth;
    uint64_t seed;
    int threads;
    double eps;         /* step along the direction (absolute) */
    double z_max;       /* agreement threshold on |z| */
    struct dr_film film;   /* filter and crop; width x height above is the rendered rectangle */
    enum dr_sampler_kind sampler;   /* the random numbers, shared by estimator and differences */
    double regularize;  /* prb, attached: conditioning threshold (estimator.h) */
    struct dr_grad_stats *stats;   /* optional out: the last reverse-mode estimator run's statistics
                                      (their media_gain: where DRT took each medium's gain) */
};

struct dr_fd_entry {
    char label[DR_PARAM_NAME_MAX + 32];   /* parameter name + component */
    double reverse, reverse_se;           /* estimator, reverse mode */
    double forward, forward_se;           /* estimator, forward mode */
    double fd, fd_se;                     /* finite differences (se with their rounding bound) */
    double z_reverse, z_forward;
    bool agree;                           /* both |z| <= z_max */
};

/* Runs the check for every parameter of ps (the scene is modified during the
 * run and restored). *entries is malloc'd. 0 or a negative DR_ERR_*. */
int dr_fdcheck(struct dr_scene *scene, const struct dr_camera *camera, const struct dr_param_set *ps,
               const struct dr_fd_options *o, struct dr_fd_entry **entries, int *count);

/* The finite difference of the rendered image along dir (params->total
 * entries) with common random numbers (seed): central, or one-sided second
 * order where theta - eps dir would leave a parameter's range. Uses o's size,
 * spp, depths, threads and eps (estimator, batches, z_max unused). dimg:
 * width * height * 3 doubles. The scene is modified and restored. 0 or DR_ERR_*. */
int dr_fd_image(struct dr_scene *scene, const struct dr_camera *camera, const struct dr_param_set *ps,
                const struct dr_fd_options *o, const double *dir, uint64_t seed, double *dimg);

#endif
