/* Adjoints from what the tracer evaluates (BSDF inputs, emitted radiance,
 * environment radiance, punctual light radiance) down to the requested
 * parameters, through factors and textures.
 *
 * They write into a gradient sink: in reverse mode a gradient vector
 * (d loss / d theta, one slot per scalar of the parameter set), in forward
 * mode a running dot product with a direction (d value / d theta . dir). */
#ifndef DR_D_SCENE_H
#define DR_D_SCENE_H

#include "bsdf.h"
#include "geometry.h"
#include "lights.h"
#include "params.h"
#include "scene.h"

struct dr_grad_sink {
    double *grad;        /* reverse mode: gradient vector (+=) */
    const double *dir;   /* forward mode (when not NULL): direction */
    double forward;      /* forward mode: accumulated dot product */
};

static inline void dr_sink_add(struct dr_grad_sink *k, int64_t slot, double v)
{
    if (k->dir)
        k->forward += k->dir[slot] * v;
    else
        k->grad[slot] += v;
}

/* d_b: adjoint of the BSDF inputs at hit (dr_material_eval's output). */
void d_material_eval(const struct dr_scene *scene, const struct dr_param_set *params, const struct dr_hit *hit,
                     const struct dr_d_bsdf *d_b, struct dr_grad_sink *sink);
/* d_Le: adjoint of dr_emission(scene, hit). */
void d_emission(const struct dr_scene *scene, const struct dr_param_set *params, const struct dr_hit *hit,
                dr_vec3 d_Le, struct dr_grad_sink *sink);
/* d_L: adjoint of dr_env_radiance(scene, dir). */
void d_env_radiance(const struct dr_scene *scene, const struct dr_param_set *params, dr_vec3 dir, dr_vec3 d_L,
                    struct dr_grad_sink *sink);
/* d_L: adjoint of the radiance of light sample ls (area, punctual or environment). */
void d_light_radiance(const struct dr_scene *scene, const struct dr_param_set *params,
                      const struct dr_light_sample *ls, dr_vec3 d_L, struct dr_grad_sink *sink);

#endif
