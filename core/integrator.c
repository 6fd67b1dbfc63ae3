#include "integrator.h"

#include "path.h"

dr_vec3 dr_path_radiance(const struct dr_scene *s, const struct dr_trace_opts *opts, dr_vec3 o, dr_vec3 d,
                         struct dr_sampler *sampler, struct dr_ray_counts *counts)
{
    /* The forward renderer is the path walker with nothing to differentiate,
     * so `render` and the primal pass of every estimator compute the same. */
    struct dr_path_opts po = {opts->max_depth, opts->rr_depth, NULL};
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, o, d);
    dr_vec3 L = dr_v3s(0.0);
    for (;;) {
        dr_vec3 beta = st.beta;
        bool more = dr_path_step(s, &po, &st, sampler, &v, counts);
        L = dr_add(L, dr_mul(beta, dr_path_vertex_term(&v)));
        if (!more)
            return L;
    }
}
