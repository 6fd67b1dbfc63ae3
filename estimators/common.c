#include "common.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "error.h"
#include "parallel.h"

/* Scalar problems up to this size sum each chunk locally first. */
#define CHUNK_LOCAL_MAX 4096

void dr_est_camera_ray(const struct dr_grad_problem *p, const struct dr_camera_view *view, int64_t pixel,
                       int sample, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    dr_sampler_init(smp, p->seed, (uint64_t)pixel, (uint64_t)sample);
    double jx = dr_sampler_next(smp), jy = dr_sampler_next(smp);
    int x = (int)(pixel % p->width), y = (int)(pixel / p->width);
    *o = view->origin;
    *d = dr_camera_direction(view, x + jx, y + jy);
}

void dr_est_vertex_terms(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 a, struct dr_grad_sink *sink)
{
    if (dr_is_black(a))
        return;
    if (v->emits) {
        dr_vec3 d_Le = dr_scale(a, v->emit_w);
        if (v->kind == DR_VERTEX_SURFACE)
            d_emission(s, ps, &v->hit, d_Le, sink);
        else
            d_env_radiance(s, ps, v->d, d_Le, sink);
    }
    if (v->nee) {
        if (v->diff_bsdf) {
            struct dr_d_bsdf db = {dr_v3s(0.0), 0.0, 0.0};
            d_bsdf_eval(&v->bsdf, v->wo, v->nee_wi, dr_scale(dr_mul(a, v->ls.radiance), v->nee_scale), &db);
            d_material_eval(s, ps, &v->hit, &db, sink);
        }
        d_light_radiance(s, ps, &v->ls, dr_scale(dr_mul(a, v->nee_f), v->nee_scale), sink);
    }
}

void dr_est_continuation(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_path_vertex *v,
                         dr_vec3 d_f, struct dr_grad_sink *sink)
{
    if (dr_is_black(d_f))
        return;
    struct dr_d_bsdf db = {dr_v3s(0.0), 0.0, 0.0};
    d_bsdf_eval(&v->bsdf, v->wo, v->wi, d_f, &db);
    d_material_eval(s, ps, &v->hit, &db, sink);
}

void dr_est_stats_fill(struct dr_grad_stats *st, const struct dr_est_counters *c, int threads, double seconds)
{
    if (!st)
        return;
    memset(st, 0, sizeof *st);
    st->seconds = seconds;
    st->threads = threads;
    for (int t = 0; t < threads; t++) {
        st->rays.camera += c[t].rays.camera;
        st->rays.extension += c[t].rays.extension;
        st->rays.shadow += c[t].rays.shadow;
        st->invalid_samples += c[t].invalid;
    }
}

int dr_est_thread_count(const struct dr_grad_problem *p)
{
    int t = p->threads > 0 ? p->threads : dr_cpu_count();
    return t > DR_EST_MAX_THREADS ? DR_EST_MAX_THREADS : t;
}

double dr_est_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

bool dr_vec3_finite(dr_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

int dr_est_accum_init(struct dr_est_accum *a, const struct dr_grad_problem *p, bool forward)
{
    memset(a, 0, sizeof *a);
    a->threads = dr_est_thread_count(p);
    a->total = p->params->total;
    size_t pixels = (size_t)p->width * (size_t)p->height;
    for (int t = 0; t < a->threads; t++) {
        if (forward) {
            a->image[t] = calloc(pixels * 3, sizeof(double));
            if (!a->image[t])
                goto nomem;
            continue;
        }
        a->grad[t] = calloc((size_t)a->total + 1, sizeof(double));
        if (!a->grad[t])
            goto nomem;
        if (a->total <= CHUNK_LOCAL_MAX) {
            a->chunk[t] = calloc((size_t)a->total + 1, sizeof(double));
            if (!a->chunk[t])
                goto nomem;
        }
    }
    return 0;
nomem:
    dr_est_accum_free(a);
    dr_set_error("out of memory for the gradient buffers");
    return DR_ERR_NOMEM;
}

void dr_est_accum_free(struct dr_est_accum *a)
{
    for (int t = 0; t < DR_EST_MAX_THREADS; t++) {
        free(a->grad[t]);
        free(a->chunk[t]);
        free(a->image[t]);
        a->grad[t] = a->chunk[t] = NULL;
        a->image[t] = NULL;
    }
}

void dr_est_accum_finish(struct dr_est_accum *a, const struct dr_grad_problem *p, double *grad, double *d_image)
{
    if (grad) {
        memset(grad, 0, sizeof(double) * (size_t)a->total);
        for (int t = 0; t < a->threads; t++)
            for (int64_t i = 0; i < a->total; i++)
                grad[i] += a->grad[t][i];
    }
    if (d_image) {
        size_t n = (size_t)p->width * (size_t)p->height * 3;
        for (size_t i = 0; i < n; i++) {
            double v = 0.0;
            for (int t = 0; t < a->threads; t++)
                v += a->image[t][i];
            d_image[i] = v;
        }
    }
    dr_est_accum_free(a);
}

double *dr_est_chunk_begin(struct dr_est_accum *a, int thread)
{
    if (!a->chunk[thread])
        return a->grad[thread];
    memset(a->chunk[thread], 0, sizeof(double) * (size_t)a->total);
    return a->chunk[thread];
}

void dr_est_chunk_end(struct dr_est_accum *a, int thread)
{
    if (!a->chunk[thread])
        return;
    double *g = a->grad[thread], *c = a->chunk[thread];
    for (int64_t i = 0; i < a->total; i++)
        g[i] += c[i];
}

int dr_est_base_init(struct dr_est_base *b, const struct dr_grad_problem *p, const float *adjoint,
                     const double *dir)
{
    b->p = p;
    b->view = dr_camera_view(p->camera, p->width, p->height);
    b->popts = (struct dr_path_opts){p->max_depth, p->rr_depth, p->params};
    b->adjoint = adjoint;
    b->dir = dir;
    memset(b->thr, 0, sizeof b->thr);
    b->t0 = dr_est_now();
    return dr_est_accum_init(&b->acc, p, dir != NULL);
}

void dr_est_base_finish(struct dr_est_base *b, double *grad, double *d_image, struct dr_grad_stats *st)
{
    double t1 = dr_est_now();
    dr_est_accum_finish(&b->acc, b->p, grad, d_image);
    dr_est_stats_fill(st, b->thr, b->acc.threads, t1 - b->t0);
}

dr_vec3 dr_est_pixel_adjoint(const struct dr_est_base *b, int64_t pixel)
{
    const float *a = b->adjoint + 3 * pixel;
    return dr_scale(dr_v3(a[0], a[1], a[2]), 1.0 / b->p->spp);
}
