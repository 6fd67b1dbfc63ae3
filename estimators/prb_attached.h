/* Path replay backpropagation with attached sampling (prb_attached.c). */
#ifndef DR_PRB_ATTACHED_H
#define DR_PRB_ATTACHED_H

#include "common.h"
#include "wavefront.h"

struct jacobian_cache;

/* What one sample's attached replay needs besides the shared run. */
struct prb_attached_ctx {
    const struct dr_est_base *b;
    double eps;                 /* --regularize: below this sigma_min/sigma_max a Jacobian is
                                   not inverted; forward mode restarts there */
    double radius;              /* the scene's radius: positions in commensurable units */
    struct dr_ray_counts *rays;
    const struct dr_wave_log *log;   /* the sample's primal walk's ray answers (NULL: none; the walks
                                        here take them: dr_wave_log_step) */
    struct jacobian_cache *cache;    /* prb_attached.c's own (set there; NULL outside a replay) */
};

/* A sample's primal: its radiance with the true throughput and with the
 * substitutes (path.h), summed vertex by vertex in path order. */
struct prb_attached_sums {
    dr_vec3 L_true, L_sub;
};

/* The whole derivative of one sample (primal, forward-mode pass, replay),
 * given its sampler and camera ray; adj as in the detached replay; false
 * when the path's value is not finite (nothing was added). sums: the
 * primal's, where the caller walked it already (the cross primal, prb.c:
 * the same sums bit for bit; NULL: walked here). det (mis; NULL: none)
 * receives the same path's detached derivative, from the same replay. */
bool prb_attached_sample(const struct prb_attached_ctx *c, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 adj,
                         const struct prb_attached_sums *sums, struct dr_grad_sink *sink, struct dr_grad_sink *det);

#endif
