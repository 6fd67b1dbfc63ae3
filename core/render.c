#include "render.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "clock.h"
#include "error.h"
#include "parallel.h"
#include "sampler.h"

struct render_job {
    const struct dr_scene *scene;
    const struct dr_camera *camera;
    struct dr_camera_view view;
    const struct dr_render_opts *opts;
    struct dr_path_opts path;
    float *rgb;
    /* per-thread counters, padded apart to avoid false sharing */
    struct {
        struct dr_ray_counts rays;
        uint64_t invalid;
        char pad[64];
    } counters[DR_MAX_THREADS];
};

static void render_tile(void *ctx, int thread, int x0, int y0, int x1, int y1)
{
    struct render_job *j = ctx;
    const struct dr_render_opts *o = j->opts;
    struct dr_ray_counts *rays = &j->counters[thread].rays;
    for (int y = y0; y < y1; y++) {
        for (int x = x0; x < x1; x++) {
            int fx, fy;   /* the frame pixel: random numbers and rays do not depend on the crop */
            int64_t local = (int64_t)y * o->width + x;
            uint64_t pixel = dr_film_pixel(&o->film, o->width, local, &fx, &fy);
            dr_vec3 sum = dr_v3s(0.0);
            for (int s = 0; s < o->spp; s++) {
                struct dr_sampler smp;
                dr_sampler_init_kind(&smp, o->sampler, o->seed, pixel, (uint64_t)s, o->spp);
                double u, v, px, py;
                dr_sampler_next2(&smp, &u, &v);
                dr_film_sample(&o->film.filter, fx, fy, u, v, &px, &py);
                dr_vec3 o, d;
                dr_camera_ray(&j->view, px, py, &o, &d);
                dr_vec3 L = dr_path_radiance(j->scene, &j->path, o, d, &smp, rays);
                if (dr_v3_finite(L))
                    sum = dr_add(sum, L);
                else
                    j->counters[thread].invalid++;
            }
            float *out = j->rgb + 3 * local;
            out[0] = (float)(sum.x / o->spp);
            out[1] = (float)(sum.y / o->spp);
            out[2] = (float)(sum.z / o->spp);
        }
    }
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

int dr_render(const struct dr_scene *scene, const struct dr_camera *camera, const struct dr_render_opts *opts,
              float *rgb, struct dr_render_stats *stats)
{
    if (dr_film_check(&opts->film, opts->width, opts->height) != 0)
        return DR_ERR_ARG;
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
    int threads = dr_thread_count(opts->threads);
    double t0 = dr_clock_seconds();
    int rc = dr_parallel_tiles(opts->width, opts->height, threads, render_tile, opts->progress ? progress : NULL, j);
    double t1 = dr_clock_seconds();
    if (stats) {
        memset(stats, 0, sizeof *stats);
        stats->seconds = t1 - t0;
        stats->threads = threads;
        stats->stages = j->path.stages;
        for (int i = 0; i < threads; i++) {
            stats->rays.camera += j->counters[i].rays.camera;
            stats->rays.extension += j->counters[i].rays.extension;
            stats->rays.shadow += j->counters[i].rays.shadow;
            stats->invalid_samples += j->counters[i].invalid;
        }
    }
    free(j);
    return rc;
}
