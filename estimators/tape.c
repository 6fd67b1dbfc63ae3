/* Conventional reverse mode with a tape: the baseline PRB is measured against.
 *
 * The forward pass records every vertex of every path of a batch (default: one
 * sample of every pixel, --batch N paths otherwise); then one backward sweep
 * per path, from the last vertex to the first, carries the adjoint of the
 * throughput:  abar_k = adj * e_k + abar_{k+1} * t_k,  and the BSDF term of
 * vertex k gets d t_k = abar_{k+1} * beta_k. No division by f (unlike PRB),
 * so with the same random numbers the two estimators agree to rounding.
 * Memory: (vertices per path) x (paths per batch), reported as tape_peak_bytes. */
#include <stdlib.h>
#include <string.h>

#include "common.h"
#include "error.h"
#include "parallel.h"

struct tape_vertex {
    struct dr_path_vertex v;
    dr_vec3 bt;        /* true throughput arriving at the vertex */
};

struct tape_path {
    int64_t pixel;
    int64_t first;     /* index of its first vertex */
    int count;
    dr_vec3 adj;       /* reverse mode: d loss / d L of this sample */
};

struct tape {
    struct tape_vertex *verts;
    int64_t n_verts, cap_verts;
    struct tape_path *paths;
    int64_t n_paths, cap_paths;
    bool failed;       /* out of memory while recording */
};

struct tape_job {
    struct dr_est_base b;   /* first: the shared part */
    struct tape tapes[DR_EST_MAX_THREADS];
    int64_t batch_begin;     /* path ids of the current batch start here */
    uint64_t peak_bytes;
};

static bool grow(void **p, int64_t *cap, int64_t need, size_t elem)
{
    if (need <= *cap)
        return true;
    int64_t c = *cap > 0 ? *cap : 1024;
    while (c < need)
        c *= 2;
    void *q = realloc(*p, (size_t)c * elem);
    if (!q)
        return false;
    *p = q;
    *cap = c;
    return true;
}

static uint64_t tape_bytes(const struct tape *t)
{
    return (uint64_t)t->cap_verts * sizeof(struct tape_vertex) + (uint64_t)t->cap_paths * sizeof(struct tape_path);
}

/* Record phase: path ids [begin, end) of the batch; id = sample * pixels + pixel. */
static void record(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct tape_job *j = ctx;
    const struct dr_grad_problem *p = j->b.p;
    struct tape *tp = &j->tapes[thread];
    const int64_t pixels = (int64_t)p->width * p->height;
    for (int64_t id = j->batch_begin + begin; id < j->batch_begin + end; id++) {
        int64_t px = id % pixels;
        int sidx = (int)(id / pixels);
        dr_vec3 adj = dr_v3s(0.0);
        if (!j->b.dir) {
            adj = dr_est_pixel_adjoint(&j->b, px);
            if (dr_is_black(adj))
                continue;
        }
        struct dr_sampler smp;
        dr_vec3 o, d;
        dr_est_camera_ray(p, &j->b.view, px, sidx, &smp, &o, &d);
        if (!grow((void **)&tp->paths, &tp->cap_paths, tp->n_paths + 1, sizeof *tp->paths)) {
            tp->failed = true;
            return;
        }
        struct tape_path *path = &tp->paths[tp->n_paths];
        path->pixel = px;
        path->first = tp->n_verts;
        path->count = 0;
        path->adj = adj;
        struct dr_path_state st;
        dr_path_start(&st, o, d);
        dr_vec3 L = dr_v3s(0.0);
        for (;;) {
            if (!grow((void **)&tp->verts, &tp->cap_verts, tp->n_verts + 1, sizeof *tp->verts)) {
                tp->failed = true;
                return;
            }
            struct tape_vertex *tv = &tp->verts[tp->n_verts];
            tv->bt = dr_mul(st.ratio, st.beta);
            bool more = dr_path_step(p->scene, &j->b.popts, &st, &smp, &tv->v, &j->b.thr[thread].rays);
            L = dr_add(L, dr_mul(tv->bt, dr_path_vertex_term(&tv->v)));
            tp->n_verts++;
            path->count++;
            if (!more)
                break;
        }
        if (!dr_vec3_finite(L)) {   /* drop the path */
            tp->n_verts = path->first;
            j->b.thr[thread].invalid++;
            continue;
        }
        tp->n_paths++;
    }
}

/* Backward sweep over one path with adjoint adj. */
static void sweep(const struct tape_job *j, const struct tape_vertex *verts, int count, dr_vec3 adj,
                  struct dr_grad_sink *sink)
{
    const struct dr_scene *s = j->b.p->scene;
    const struct dr_param_set *ps = j->b.p->params;
    dr_vec3 abar = dr_v3s(0.0);   /* adjoint of the true throughput after the vertex */
    for (int k = count - 1; k >= 0; k--) {
        const struct dr_path_vertex *v = &verts[k].v;
        dr_vec3 bt = verts[k].bt;
        dr_vec3 t = dr_v3s(0.0);
        if (v->cont) {
            if (v->diff_bsdf)
                dr_est_continuation(s, ps, v, dr_scale(dr_mul(abar, bt), v->cos_pdf_q), sink);
            t = dr_scale(v->f, v->cos_pdf_q);
        }
        dr_est_vertex_terms(s, ps, v, dr_mul(adj, bt), sink);
        abar = dr_add(dr_mul(adj, dr_path_vertex_term(v)), dr_mul(abar, t));
    }
}

/* Sweep phase: item i sweeps tape i (recorded by worker i). */
static void sweep_tape(void *ctx, int thread, int64_t begin, int64_t end)
{
    struct tape_job *j = ctx;
    const double inv_spp = 1.0 / j->b.p->spp;
    for (int64_t i = begin; i < end; i++) {
        const struct tape *tp = &j->tapes[i];
        struct dr_grad_sink sink = {NULL, j->b.dir, 0.0};
        if (!j->b.dir)
            sink.grad = dr_est_chunk_begin(&j->b.acc, thread);
        for (int64_t pi = 0; pi < tp->n_paths; pi++) {
            const struct tape_path *path = &tp->paths[pi];
            const struct tape_vertex *verts = tp->verts + path->first;
            if (!j->b.dir) {
                sweep(j, verts, path->count, path->adj, &sink);
                continue;
            }
            double *out = j->b.acc.image[thread] + 3 * path->pixel;
            for (int c = 0; c < 3; c++) {
                sink.forward = 0.0;
                sweep(j, verts, path->count, dr_v3(c == 0, c == 1, c == 2), &sink);
                out[c] += sink.forward * inv_spp;
            }
        }
        if (!j->b.dir)
            dr_est_chunk_end(&j->b.acc, thread);
    }
}

static int tape_run(const struct dr_grad_problem *p, const float *adjoint, const double *dir, double *grad,
                    double *d_image, struct dr_grad_stats *st)
{
    struct tape_job *j = calloc(1, sizeof *j);
    if (!j) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int rc = dr_est_base_init(&j->b, p, adjoint, dir);
    if (rc != 0) {
        free(j);
        return rc;
    }
    const int threads = j->b.acc.threads;
    const int64_t total = (int64_t)p->width * p->height * p->spp;
    const int64_t batch = p->batch > 0 ? p->batch : (int64_t)p->width * p->height;
    for (j->batch_begin = 0; j->batch_begin < total && rc == 0; j->batch_begin += batch) {
        int64_t n = total - j->batch_begin < batch ? total - j->batch_begin : batch;
        for (int t = 0; t < threads; t++)
            j->tapes[t].n_verts = j->tapes[t].n_paths = 0;
        rc = dr_parallel_for_static(n, 16, threads, record, j);
        uint64_t bytes = 0;
        for (int t = 0; t < threads; t++) {
            bytes += tape_bytes(&j->tapes[t]);
            if (j->tapes[t].failed) {
                dr_set_error("out of memory recording the tape (%llu bytes so far); use --batch to bound it",
                             (unsigned long long)bytes);
                rc = DR_ERR_NOMEM;
            }
        }
        if (bytes > j->peak_bytes)
            j->peak_bytes = bytes;
        if (rc == 0)
            rc = dr_parallel_for_static(threads, 1, threads, sweep_tape, j);
    }
    dr_est_base_finish(&j->b, grad, d_image, st);
    if (st)
        st->tape_peak_bytes = j->peak_bytes;
    for (int t = 0; t < threads; t++) {
        free(j->tapes[t].verts);
        free(j->tapes[t].paths);
    }
    free(j);
    return rc;
}

static int tape_forward(const struct dr_grad_problem *p, const double *dir, double *d_image,
                        struct dr_grad_stats *st)
{
    return tape_run(p, NULL, dir, NULL, d_image, st);
}

static int tape_backward(const struct dr_grad_problem *p, const float *adjoint, double *grad,
                         struct dr_grad_stats *st)
{
    return tape_run(p, adjoint, NULL, grad, NULL, st);
}

const struct dr_estimator_ops dr_estimator_tape = {
    "tape",
    "conventional reverse mode: records every vertex of a batch of paths, then sweeps backward; memory grows "
    "with depth x paths per batch",
    tape_forward,
    tape_backward,
};
