/* Path replay backpropagation (Vicini et al. 2021): constant memory per path,
 * time linear in its length.
 *
 * The primal pass returns the path's radiance L. The replay re-traces the same
 * path with the same random numbers and, at vertex k, knows the radiance still
 * to come, R_k = L - (what vertices 1..k added), so the BSDF term of the
 * continuation gets d L / d f_k = R_k / f_k per channel: no tape of the path.
 * Where f_k is 0 in a channel, R_k is 0 too and the term is 0 (never 0/0);
 * a differentiated vertex with f_k = 0 was traced on with a substitute factor
 * (path.h), whose remaining radiance R_sub gives the derivative instead.
 * All sums are in double. */
#include <stdlib.h>
#include <string.h>

#include "common.h"
#include "error.h"
#include "parallel.h"

struct prb_job {
    struct dr_est_base b;   /* first: the shared part */
};

/* Primal pass: L_true (the estimate) and L_sub (with substitutes). */
static void primal(const struct prb_job *j, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 *L_true,
                   dr_vec3 *L_sub, struct dr_ray_counts *rays)
{
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, o, d);
    dr_vec3 lt = dr_v3s(0.0), ls = dr_v3s(0.0);
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio;
        bool more = dr_path_step(j->b.p->scene, &j->b.popts, &st, &smp, &v, rays);
        dr_vec3 c = dr_mul(beta, dr_path_vertex_term(&v));
        ls = dr_add(ls, c);
        lt = dr_add(lt, dr_mul(ratio, c));
        if (!more)
            break;
    }
    *L_true = lt;
    *L_sub = ls;
}

/* Replay with adjoint adj (d loss / d L of this sample). */
static void replay(const struct prb_job *j, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 L_true,
                   dr_vec3 L_sub, dr_vec3 adj, struct dr_grad_sink *sink, struct dr_ray_counts *rays)
{
    const struct dr_scene *s = j->b.p->scene;
    const struct dr_param_set *ps = j->b.p->params;
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, o, d);
    dr_vec3 R_true = L_true, R_sub = L_sub;
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio;
        bool more = dr_path_step(s, &j->b.popts, &st, &smp, &v, rays);
        dr_vec3 e = dr_path_vertex_term(&v);
        dr_vec3 bt = dr_mul(ratio, beta);           /* true throughput */
        R_sub = dr_sub(R_sub, dr_mul(beta, e));
        R_true = dr_sub(R_true, dr_mul(bt, e));
        dr_est_vertex_terms(s, ps, &v, dr_mul(adj, bt), sink);
        if (v.cont && v.diff_bsdf) {
            double d_f[3];
            for (int c = 0; c < 3; c++) {
                double f = (&v.f.x)[c];
                if (v.sub[c])
                    d_f[c] = (&ratio.x)[c] * (&R_sub.x)[c] / (&v.s.x)[c];
                else
                    d_f[c] = f != 0.0 ? (&R_true.x)[c] / f : 0.0;
                d_f[c] *= (&adj.x)[c];
            }
            dr_est_continuation(s, ps, &v, dr_v3(d_f[0], d_f[1], d_f[2]), sink);
        }
        if (!more)
            break;
    }
}

static void prb_pixels(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct prb_job *j = ctx;
    const struct dr_grad_problem *p = j->b.p;
    struct dr_ray_counts *rays = &j->b.thr[thread].rays;
    const double inv_spp = 1.0 / p->spp;
    struct dr_grad_sink sink = {NULL, j->b.dir, 0.0};
    if (!j->b.dir)
        sink.grad = dr_est_chunk_begin(&j->b.acc, thread);
    for (int64_t px = begin; px < end; px++) {
        dr_vec3 adj = dr_v3s(0.0);
        if (!j->b.dir) {
            adj = dr_est_pixel_adjoint(&j->b, px);
            if (dr_is_black(adj))
                continue;   /* this pixel does not matter to the loss */
        }
        for (int sidx = 0; sidx < p->spp; sidx++) {
            struct dr_sampler smp;
            dr_vec3 o, d, L_true, L_sub;
            dr_est_camera_ray(p, &j->b.view, px, sidx, &smp, &o, &d);
            primal(j, smp, o, d, &L_true, &L_sub, rays);
            if (!dr_vec3_finite(L_true) || !dr_vec3_finite(L_sub)) {
                j->b.thr[thread].invalid++;
                continue;
            }
            if (!j->b.dir) {
                replay(j, smp, o, d, L_true, L_sub, adj, &sink, rays);
                continue;
            }
            /* forward mode: one replay per output channel */
            double *out = j->b.acc.image[thread] + 3 * px;
            for (int c = 0; c < 3; c++) {
                dr_vec3 e = dr_v3(c == 0, c == 1, c == 2);
                sink.forward = 0.0;
                replay(j, smp, o, d, L_true, L_sub, e, &sink, rays);
                out[c] += sink.forward * inv_spp;
            }
        }
    }
    if (!j->b.dir)
        dr_est_chunk_end(&j->b.acc, thread);
}

static int prb_run(const struct dr_grad_problem *p, const float *adjoint, const double *dir, double *grad,
                   double *d_image, struct dr_grad_stats *st)
{
    struct prb_job *j = calloc(1, sizeof *j);
    if (!j) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int rc = dr_est_base_init(&j->b, p, adjoint, dir);
    if (rc != 0) {
        free(j);
        return rc;
    }
    rc = dr_parallel_for_static((int64_t)p->width * p->height, 16, j->b.acc.threads, prb_pixels, j);
    dr_est_base_finish(&j->b, grad, d_image, st);
    free(j);
    return rc;
}

static int prb_forward(const struct dr_grad_problem *p, const double *dir, double *d_image, struct dr_grad_stats *st)
{
    return prb_run(p, NULL, dir, NULL, d_image, st);
}

static int prb_backward(const struct dr_grad_problem *p, const float *adjoint, double *grad,
                        struct dr_grad_stats *st)
{
    return prb_run(p, adjoint, NULL, grad, NULL, st);
}

const struct dr_estimator_ops dr_estimator_prb = {
    "prb",
    "path replay backpropagation: primal pass + replay, constant memory per path, time linear in depth",
    prb_forward,
    prb_backward,
};
