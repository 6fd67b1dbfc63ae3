#include "render.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "camera8.h"
#include "clock.h"
#include "error.h"
#include "parallel.h"
#include "sampler.h"
#include "sampler8.h"
#include "wave_soa.h"
#include "wavefront.h"

struct render_job {
    const struct dr_scene *scene;
    const struct dr_camera *camera;
    struct dr_camera_view view;
    const struct dr_render_opts *opts;
    struct dr_path_opts path;
    float *rgb;
    bool wave;               /* the packet renderer (wavefront.h); false: one path at a time (media) */
    int chunk_pixels;        /* pixels whose samples one wavefront run takes */
    /* per-thread counters and wavefront storage, padded apart to avoid false sharing */
    struct {
        struct dr_ray_counts rays;
        uint64_t invalid;
        struct dr_wave *wave;
        dr_vec3 *L;          /* chunk_pixels * spp path values */
        char pad[64];
    } counters[DR_MAX_THREADS];
};

/* Frame pixel `pixel`'s share of its samples' random numbers. The frame
 * pixel (not the crop's) keys them, so a crop renders the same pixels. */
static void start_pixel(const struct render_job *j, uint64_t pixel, struct dr_sampler_pixel *p)
{
    dr_sampler_pixel_init(p, j->opts->sampler, j->opts->seed, pixel, j->opts->spp);
}

/* Sample s of frame pixel (fx, fy) (p: start_pixel's): its random numbers
 * and camera ray. */
static void start_sample(const struct render_job *j, int fx, int fy, const struct dr_sampler_pixel *p, int s,
                         struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    dr_sampler_pixel_sample(p, (uint64_t)s, smp);
    double u, v, px, py;
    dr_sampler_pixel_first2(p, smp, &u, &v);
    dr_film_sample(&j->opts->film.filter, fx, fy, u, v, &px, &py);
    dr_camera_ray(&j->view, px, py, o, d);
}

/* The pixel's mean over its samples, summed in sample order (so the value
 * does not depend on the order in which the paths were worked on). */
static void store_pixel(struct render_job *j, int thread, int64_t local, const dr_vec3 *L)
{
    const int spp = j->opts->spp;
    dr_vec3 sum = dr_v3s(0.0);
    for (int s = 0; s < spp; s++) {
        if (dr_v3_finite(L[s]))
            sum = dr_add(sum, L[s]);
        else
            j->counters[thread].invalid++;
    }
    float *out = j->rgb + 3 * local;
    out[0] = (float)(sum.x / spp);
    out[1] = (float)(sum.y / spp);
    out[2] = (float)(sum.z / spp);
}

/* One path at a time (scenes with a global medium). */
static void render_tile_scalar(struct render_job *j, int thread, int x0, int y0, int x1, int y1)
{
    const struct dr_render_opts *o = j->opts;
    struct dr_ray_counts *rays = &j->counters[thread].rays;
    dr_vec3 *L = j->counters[thread].L;
    for (int y = y0; y < y1; y++) {
        for (int x = x0; x < x1; x++) {
            int fx, fy;
            int64_t local = (int64_t)y * o->width + x;
            struct dr_sampler_pixel p;
            start_pixel(j, dr_film_pixel(&o->film, o->width, local, &fx, &fy), &p);
            for (int s = 0; s < o->spp; s++) {
                struct dr_sampler smp;
                dr_vec3 ro, rd;
                start_sample(j, fx, fy, &p, s, &smp, &ro, &rd);
                L[s] = dr_path_radiance(j->scene, &j->path, ro, rd, &smp, rays);
            }
            store_pixel(j, thread, local, L);
        }
    }
}

/* A run of a tile's pixels (row-major in the tile) for the wavefront. */
struct pixel_run {
    const struct render_job *j;
    int first;               /* index of the run's first pixel in the tile */
    int64_t local[DR_TILE_SIZE * DR_TILE_SIZE];
    int fx[DR_TILE_SIZE * DR_TILE_SIZE], fy[DR_TILE_SIZE * DR_TILE_SIZE];
    struct dr_sampler_pixel pixel[DR_TILE_SIZE * DR_TILE_SIZE];   /* start_pixel's */
};

static void start_run_sample(void *ctx, int64_t i, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct pixel_run *r = ctx;
    const int spp = r->j->opts->spp;
    int p = r->first + (int)(i / spp);
    start_sample(r->j, r->fx[p], r->fy[p], &r->pixel[p], (int)(i % spp), smp, o, d);
}

/* start_run_sample for items first .. first + 7 (dr_wave_start8_fn): their
 * samplers, camera draws, film positions and rays eight at a time, each
 * lane with start_sample's bits (filters other than the box lane by lane). */
static void start_run_samples8(void *ctx, int64_t first, struct dr_sampler *smp, dr_vec3 *o, dr_vec3 *d)
{
    const struct pixel_run *r = ctx;
    const struct render_job *j = r->j;
    const int spp = j->opts->spp;
    const struct dr_sampler_pixel *pixel[8];
    uint64_t sample[8];
    int at[8];   /* each lane's pixel in the run */
    for (int l = 0, p = r->first + (int)(first / spp), k = (int)(first % spp); l < 8; l++) {
        at[l] = p, pixel[l] = &r->pixel[p], sample[l] = (uint64_t)k;
        if (++k == spp)   /* (one division for the eight lanes, not sixteen) */
            k = 0, p++;
    }
#define X(l) (double)r->fx[at[l]]
#define Y(l) (double)r->fy[at[l]]
    const dr_f8 x = DR_LANES8(dr_f8, X), y = DR_LANES8(dr_f8, Y);
#undef X
#undef Y
    dr_f8 u, v;
    dr_sampler_pixel_first2_8(pixel, sample, smp, &u, &v);
    dr_f8 px = x + u, py = y + v;   /* dr_film_sample's box */
    if (j->opts->film.filter.kind != DR_FILTER_BOX)
        for (int l = 0; l < 8; l++) {   /* (clang takes no address of a vector's element) */
            double fx, fy;
            dr_film_sample(&j->opts->film.filter, (int)x[l], (int)y[l], u[l], v[l], &fx, &fy);
            px[l] = fx;
            py[l] = fy;
        }
    dr_v3x8 o8, d8;
    dr_camera_ray8(&j->view, px, py, &o8, &d8);
    for (int l = 0; l < 8; l++)
        o[l] = dr_v3x8_get(&o8, l), d[l] = dr_v3x8_get(&d8, l);
}

/* Many paths at a time (wavefront.h), chunk_pixels pixels' samples per run. */
static void render_tile_wave(struct render_job *j, int thread, int x0, int y0, int x1, int y1)
{
    const struct dr_render_opts *o = j->opts;
    struct pixel_run run = {.j = j};
    int n = 0;
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++, n++) {
            run.local[n] = (int64_t)y * o->width + x;
            start_pixel(j, dr_film_pixel(&o->film, o->width, run.local[n], &run.fx[n], &run.fy[n]), &run.pixel[n]);
        }
    dr_vec3 *L = j->counters[thread].L;
    for (run.first = 0; run.first < n; run.first += j->chunk_pixels) {
        int m = n - run.first < j->chunk_pixels ? n - run.first : j->chunk_pixels;
        dr_wave_radiance(j->counters[thread].wave, j->scene, &j->path, (int64_t)m * o->spp, start_run_sample,
                         start_run_samples8, &run, L, &j->counters[thread].rays);
        for (int p = 0; p < m; p++)
            store_pixel(j, thread, run.local[run.first + p], L + (int64_t)p * o->spp);
    }
}

static void render_tile(void *ctx, int thread, int x0, int y0, int x1, int y1)
{
    struct render_job *j = ctx;
    if (j->wave)
        render_tile_wave(j, thread, x0, y0, x1, y1);
    else
        render_tile_scalar(j, thread, x0, y0, x1, y1);
}

void dr_progress_bar(const char *label, int done, int total)
{
    static int last_pct = -1;
    int pct = total > 0 ? (int)(100.0 * done / total) : 100;
    if (pct == last_pct && done != total)
        return;
    last_pct = pct;
    const int width = 40;
    int fill = pct * width / 100;
    char bar[64];
    for (int i = 0; i < width; i++)
        bar[i] = i < fill ? '=' : ' ';
    bar[width] = '\0';
    fprintf(stderr, "\r%s [%s] %3d%%", label, bar, pct);
    if (done >= total) {
        fputc('\n', stderr);
        last_pct = -1;
    }
    fflush(stderr);
}

static void progress(void *ctx, int done, int total)
{
    (void)ctx;
    dr_progress_bar("rendering", done, total);
}

/* Pixels per wavefront run: enough that a run keeps the lanes busy, but
 * never more path values than 4096 (or one pixel's spp), nor a whole tile. */
static int chunk_pixels(int spp)
{
    int n = spp >= 4096 ? 1 : 4096 / spp;
    return n < DR_TILE_SIZE * DR_TILE_SIZE ? n : DR_TILE_SIZE * DR_TILE_SIZE;
}

size_t dr_render_thread_bytes(int spp)
{
    return dr_wave_bytes() + dr_wave_soa_bytes() +
           sizeof(dr_vec3) * (size_t)chunk_pixels(spp) * (size_t)(spp > 0 ? spp : 1);
}

int dr_render(const struct dr_scene *scene, const struct dr_camera *camera, const struct dr_render_opts *opts,
              float *rgb, struct dr_render_stats *stats)
{
    if (dr_film_check(&opts->film, opts->width, opts->height) != 0)
        return DR_ERR_ARG;
    int vrc = dr_scene_check_viewpoint(scene, camera);
    if (vrc != 0)
        return vrc;
    struct render_job *j = calloc(1, sizeof *j);
    if (!j) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    j->scene = scene;
    j->camera = camera;
    j->view = dr_camera_view(camera, dr_film_frame_w(&opts->film, opts->width),
                             dr_film_frame_h(&opts->film, opts->height));
    j->opts = opts;
    j->path = (struct dr_path_opts){.max_depth = opts->max_depth, .rr_depth = opts->rr_depth,
                                    .stages = dr_path_plan(scene, NULL)};
    j->rgb = rgb;
    /* (media: the packet tracer where every medium is bounded, wave_soa.c) */
    j->wave = !(j->path.stages & DR_STAGE_MEDIA) || dr_wave_soa_applies(scene, &j->path);
    j->chunk_pixels = chunk_pixels(opts->spp);
    int threads = dr_thread_count(opts->threads);
    int rc = 0;
    for (int i = 0; i < threads && rc == 0; i++) {
        j->counters[i].L = malloc(sizeof(dr_vec3) * (size_t)j->chunk_pixels * (size_t)opts->spp);
        j->counters[i].wave = j->wave ? dr_wave_create() : NULL;
        if (!j->counters[i].L || (j->wave && !j->counters[i].wave)) {
            dr_set_error("out of memory");
            rc = DR_ERR_NOMEM;
        }
    }
    double t0 = dr_clock_seconds();
    if (rc == 0)
        rc = dr_parallel_tiles(opts->width, opts->height, threads, render_tile, opts->progress ? progress : NULL, j);
    double t1 = dr_clock_seconds();
    if (stats) {
        memset(stats, 0, sizeof *stats);
        stats->seconds = t1 - t0;
        stats->threads = threads;
        stats->stages = j->path.stages;
        for (int i = 0; i < threads; i++) {
            dr_ray_counts_add(&stats->rays, &j->counters[i].rays);
            stats->invalid_samples += j->counters[i].invalid;
        }
    }
    for (int i = 0; i < threads; i++) {
        free(j->counters[i].L);
        dr_wave_destroy(j->counters[i].wave);
    }
    free(j);
    return rc;
}
