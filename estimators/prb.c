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
 * Primal and replay are one loop (as in Mitsuba's prb.py): with an adjoint,
 * the walk subtracts each vertex's contribution and sends derivatives to the
 * sink. All sums are in double. */
#include <stdlib.h>

#include "common.h"
#include "error.h"
#include "path_deriv.h"
#include "prb_attached.h"

struct prb_job {
    struct dr_est_base b;   /* first: the shared part */
    double *zeros;          /* attached sampling: a sink direction that discards (params->total zeros) */
    double radius;          /* attached sampling: the scene's radius */
};
#include "medium_grad.h"

struct prb_radiance {
    dr_vec3 true_, sub;   /* L with the true throughput, and with substitutes */
};

/* One walk over the path of (smp, o, d). Without `sink`: the primal, whose
 * radiance goes to *L. With it: the replay, which turns *L (the primal's
 * result) into the remaining radiance vertex by vertex. */
static void walk(const struct dr_est_base *b, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, struct prb_radiance *L,
                 dr_vec3 adj, struct dr_grad_sink *sink, struct dr_ray_counts *rays, int *vertices)
{
    const struct dr_scene *s = b->p->scene;
    const struct dr_param_set *ps = b->p->params;
    const double sign = sink ? -1.0 : 1.0;
    const bool dsamp = b->p->sampling == DR_SAMPLING_DERIVATIVE;   /* path_deriv.h (only vertices with a BSDF parameter) */
    struct dr_path_vertex prev;   /* derivative sampling: the last vertex, if differentiated and continued */
    bool have_prev = false;
    dr_vec3 prev_dt = dr_v3s(0.0);
    struct dr_path_state st;
    struct dr_path_vertex v;
    struct dr_medium_record mrec;   /* media: what the replay re-traces, one vertex at a time */
    v.mrec = &mrec;
    dr_path_start(&st, o, d);
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio;
        bool more = dr_path_step(s, &b->popts, &st, &smp, &v, rays);
        if (!sink)
            ++*vertices;
        dr_vec3 c = dr_mul(beta, dr_path_vertex_term(&v));   /* with substitutes */
        dr_vec3 remaining = L->true_;   /* replay: from this vertex on */
        L->sub = dr_madd(L->sub, c, sign);
        L->true_ = dr_madd(L->true_, dr_mul(ratio, c), sign);
        if (sink && v.media)
            d_medium_vertex(s, &b->popts, &v, &mrec, *vertices, dr_mul(adj, dr_mul(ratio, beta)), dr_mul(adj, remaining),
                            dr_mul(adj, L->true_),
                            dr_mul(adj, dr_mul(dr_mul(ratio, beta), dr_path_vertex_nee(&v))), sink);
        if (sink) {
            d_path_vertex_term(s, ps, &v, dr_mul(adj, dr_mul(ratio, beta)), sink);
            if (dsamp) {   /* the three-strategy weights of the BSDF derivative terms (path_deriv.h) */
                if (have_prev)
                    d_path_deriv_emission(s, &b->popts, &prev, prev_dt, &v, sink);
                d_path_deriv_nee(s, &b->popts, &v, dr_mul(adj, dr_mul(ratio, beta)), sink);
            }
            if (v.cont && v.diff_bsdf) {
                dr_vec3 d_f;
                for (int ch = 0; ch < 3; ch++) {
                    double f = dr_v3_get(v.f, ch), r;
                    if (v.sub[ch])
                        r = dr_v3_get(ratio, ch) * dr_v3_get(L->sub, ch) / dr_v3_get(v.s, ch);
                    else
                        r = f != 0.0 ? dr_v3_get(L->true_, ch) / f : 0.0;
                    dr_v3_set(&d_f, ch, r * dr_v3_get(adj, ch));
                }
                if (dsamp)
                    d_path_deriv_continuation(s, ps, &v, d_f, sink);
                else
                    d_path_continuation(s, ps, &v, d_f, sink);
            }
            /* the new directions: also where the forward sample failed or
             * Russian roulette ended the path (that strategy then gave 0) */
            if (dsamp && v.shaded && v.diff_bsdf)
                d_path_deriv_sample(s, &b->popts, &v, &smp, dr_mul(adj, dr_mul(ratio, beta)), sink, rays);
            if ((have_prev = dsamp && v.cont && v.diff_bsdf)) {
                prev = v;
                prev_dt = dr_scale(dr_mul(adj, dr_mul(ratio, beta)), v.cos_pdf_q);
            }
        }
        if (!more)
            break;
    }
}

/* One pixel's samples with attached sampling (prb_attached.c); under mis
 * each sample's attached and detached derivatives, from one replay, go to
 * its group's two estimates (mis.h). */
static void attached_pixel(struct prb_job *j, int thread, int64_t px, dr_vec3 adj, struct dr_grad_sink *sink)
{
    struct dr_est_base *b = &j->b;
    struct prb_attached_ctx c = {.b = b, .zeros = j->zeros, .eps = b->p->regularize, .radius = j->radius,
                                 .rays = &b->thr[thread].rays};
    for (int sidx = 0; sidx < b->p->spp; sidx++) {
        struct dr_sampler smp;
        dr_vec3 o, d;
        struct dr_grad_sink det, att;
        if (b->mis)
            dr_est_mis_sinks(b, thread, px, &det, &att);
        dr_est_camera_ray(b, px, sidx, &smp, &o, &d);
        if (!prb_attached_sample(&c, smp, o, d, adj, b->mis ? &att : sink, b->mis ? &det : NULL)) {
            b->thr[thread].invalid++;
            continue;
        }
        if (b->mis)
            dr_est_mis_sample_done(b, thread, px, &det, &att);
        else
            dr_est_sample_done(b, thread, px, sink);
    }
}

static void prb_pixels(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct prb_job *j = ctx;
    struct dr_est_base *b = &j->b;
    struct dr_ray_counts *rays = &b->thr[thread].rays;
    struct dr_grad_sink sink = dr_est_sink_begin(b, thread);
    for (int64_t px = begin; px < end; px++) {
        dr_vec3 adj;
        if (!dr_est_sample_adjoint(b, px, &adj))
            continue;   /* this pixel does not matter to the loss */
        if (j->zeros) {
            attached_pixel(j, thread, px, adj, &sink);
            continue;
        }
        for (int sidx = 0; sidx < b->p->spp; sidx++) {
            struct dr_sampler smp;
            dr_vec3 o, d;
            struct prb_radiance L = {dr_v3s(0.0), dr_v3s(0.0)};
            dr_est_camera_ray(b, px, sidx, &smp, &o, &d);
            int vertices = 0;   /* the primal counts them, the replay's media derivatives use the count */
            walk(b, smp, o, d, &L, adj, NULL, rays, &vertices);
            if (!dr_v3_finite(L.true_) || !dr_v3_finite(L.sub)) {
                b->thr[thread].invalid++;
                continue;
            }
            walk(b, smp, o, d, &L, adj, &sink, rays, &vertices);
            dr_est_sample_done(b, thread, px, &sink);
        }
    }
    dr_est_sink_end(b, thread);
}

static int prb_run(struct dr_est_base *b)
{
    struct prb_job *j = (struct prb_job *)b;
    const enum dr_sampling run = dr_est_sampling_run(b->p);
    if (run == DR_SAMPLING_ATTACHED || run == DR_SAMPLING_MIS) {   /* mis: both from one replay */
        if (!(j->zeros = calloc((size_t)b->p->params->total + 1, sizeof(double)))) {
            dr_set_error("out of memory");
            return DR_ERR_NOMEM;
        }
        const struct dr_scene *s = b->p->scene;
        j->radius = 0.5 * dr_length(dr_sub(s->bbox_max, s->bbox_min));
        if (!(j->radius > 0.0) || !isfinite(j->radius))
            j->radius = 1.0;
    }
    return dr_parallel_for_static((int64_t)b->p->width * b->p->height, 16, b->acc.threads, prb_pixels, j);
}

static void prb_release(struct dr_est_base *b)
{
    free(((struct prb_job *)b)->zeros);
}

const struct dr_estimator_ops dr_estimator_prb = {
    .name = "prb",
    .summary = "path replay backpropagation: primal pass + replay, constant memory per path, time linear in depth",
    .sampling = (1u << DR_SAMPLING_DETACHED) | (1u << DR_SAMPLING_ATTACHED) | (1u << DR_SAMPLING_MIS) |
                (1u << DR_SAMPLING_DERIVATIVE),
    .job_size = sizeof(struct prb_job),
    .run = prb_run,
    .release = prb_release,
};
