/* The packet renderer's lanes (wavefront.h). */
#include "wavefront.h"

#include <stdlib.h>

#include "accel.h"

struct lane {
    struct dr_path_state st;
    struct dr_sampler smp;
    struct dr_path_vertex v;
    dr_vec3 L;               /* the path's sum so far */
    dr_vec3 beta;            /* its throughput on arrival at v */
    int64_t path;            /* which path (index into L of dr_wave_radiance) */
    enum dr_step_next next;  /* what the hit stage asked for */
    struct dr_shadow_ray shadow;
};

/* The rays of one batch, in the layout dr_accel_*_many reads. */
struct batch {
    dr_vec3 o[DR_WAVE_LANES], d[DR_WAVE_LANES];
    double tmax[DR_WAVE_LANES];
    uint64_t key[DR_WAVE_LANES];
    int owner[DR_WAVE_LANES];   /* the lane each ray belongs to */
    int n;
};

struct dr_wave {
    struct lane lane[DR_WAVE_LANES];
    int live[DR_WAVE_LANES];    /* indices of the lanes with a path, in start order */
    int free_[DR_WAVE_LANES];   /* and of those without */
    struct batch rays;
    int64_t tri[DR_WAVE_LANES];
    bool occluded[DR_WAVE_LANES];
};

struct dr_wave *dr_wave_create(void)
{
    return aligned_alloc(64, (sizeof(struct dr_wave) + 63) / 64 * 64);
}

void dr_wave_destroy(struct dr_wave *wave)
{
    free(wave);
}

size_t dr_wave_bytes(void)
{
    return sizeof(struct dr_wave);
}

static void add_ray(struct batch *b, int owner, dr_vec3 o, dr_vec3 d, double tmax, uint64_t key)
{
    b->o[b->n] = o;
    b->d[b->n] = d;
    b->tmax[b->n] = tmax;
    b->key[b->n] = key;
    b->owner[b->n++] = owner;
}

static struct dr_accel_rays accel_rays(const struct batch *b)
{
    return (struct dr_accel_rays){.n = b->n, .o = b->o, .d = b->d, .tmax = b->tmax, .key = b->key};
}

/* Ends lane k's path: its sum to L, the lane to the free list. */
static void retire(struct dr_wave *w, int *n_free, int k, dr_vec3 *L)
{
    L[w->lane[k].path] = w->lane[k].L;
    w->free_[(*n_free)++] = k;
}

/* The trace stage of every live lane: one batch of extension (or camera) rays. */
static void trace_live(struct dr_wave *w, int n_live, const struct dr_scene *s, struct dr_ray_counts *counts)
{
    w->rays.n = 0;
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        l->beta = l->st.beta;
        dr_path_step_begin(&l->st, &l->v);
        dr_path_count_trace(&l->st, counts);
        add_ray(&w->rays, w->live[i], l->st.o, l->st.d, INFINITY, dr_path_trace_key(s, &l->st, &l->smp));
    }
    struct dr_accel_rays r = accel_rays(&w->rays);
    dr_accel_intersect_many(s->accel, &r, w->tri);
}

/* The hit stage: shading up to the shadow ray; collects the shadow rays. */
static void shade_live(struct dr_wave *w, int n_live, const struct dr_scene *s, const struct dr_path_opts *opts,
                       struct dr_ray_counts *counts)
{
    w->rays.n = 0;
    for (int i = 0; i < n_live; i++) {
        struct lane *l = &w->lane[w->live[i]];
        l->next = dr_path_step_hit(s, opts, &l->st, &l->smp, &l->v, w->tri[i], &l->shadow);
        if (l->next != DR_STEP_SHADOW)
            continue;
        counts->shadow++;
        if (l->shadow.tmax > 0.0)
            add_ray(&w->rays, w->live[i], l->shadow.o, l->shadow.d, l->shadow.tmax, l->shadow.key);
    }
    struct dr_accel_rays r = accel_rays(&w->rays);
    dr_accel_occluded_many(s->accel, &r, w->occluded);
}

/* The end of the step: next-event results, the vertex's terms, the
 * continuation. Returns how many lanes live on (compacted in order). */
static int finish_live(struct dr_wave *w, int n_live, int *n_free, const struct dr_scene *s,
                       const struct dr_path_opts *opts, dr_vec3 *L)
{
    for (int r = 0; r < w->rays.n; r++) {
        struct lane *l = &w->lane[w->rays.owner[r]];
        dr_path_nee_end(s, &l->v, &l->shadow, w->occluded[r]);
    }
    int kept = 0;
    for (int i = 0; i < n_live; i++) {
        int k = w->live[i];
        struct lane *l = &w->lane[k];
        if (l->next == DR_STEP_SHADOW && !(l->shadow.tmax > 0.0))
            dr_path_nee_end(s, &l->v, &l->shadow, false);   /* no ray: nothing contributes */
        bool more = l->next != DR_STEP_END && dr_path_stage_continue(opts, &l->st, &l->v);
        l->L = dr_add(l->L, dr_mul(l->beta, dr_path_vertex_term(&l->v)));
        if (more)
            w->live[kept++] = k;
        else
            retire(w, n_free, k, L);
    }
    return kept;
}

void dr_wave_radiance(struct dr_wave *w, const struct dr_scene *s, const struct dr_path_opts *opts, int64_t n,
                      dr_wave_start_fn start, void *ctx, dr_vec3 *L, struct dr_ray_counts *counts)
{
    int n_live = 0, n_free = DR_WAVE_LANES;
    for (int k = 0; k < DR_WAVE_LANES; k++)
        w->free_[k] = DR_WAVE_LANES - 1 - k;   /* lane 0 is handed out first */
    int64_t next = 0;
    while (next < n || n_live > 0) {
        while (n_free > 0 && next < n) {   /* refill: new paths in start order */
            int k = w->free_[--n_free];
            struct lane *l = &w->lane[k];
            dr_vec3 o, d;
            start(ctx, next, &l->smp, &o, &d);
            dr_path_start(&l->st, o, d);
            l->L = dr_v3s(0.0);
            l->path = next++;
            w->live[n_live++] = k;
        }
        trace_live(w, n_live, s, counts);
        shade_live(w, n_live, s, opts, counts);
        n_live = finish_live(w, n_live, &n_free, s, opts, L);
    }
}
