/* Forward rendering of a whole image: tiles over threads, one independent
 * random stream per (seed, pixel, sample), mean per pixel accumulated in double. */
#ifndef DR_RENDER_H
#define DR_RENDER_H

#include <stdbool.h>
#include <stdint.h>

#include "film.h"
#include "sampler.h"
#include "path.h"
#include "scene.h"

struct dr_render_opts {
    int width, height;    /* the rendered rectangle (the frame, unless film crops it) */
    int spp;
    int max_depth;
    int rr_depth;
    uint64_t seed;
    int threads;          /* <= 0: one per CPU */
    bool progress;        /* draw a progress bar on stderr */
    struct dr_film film;  /* pixel filter and crop (zeroed: box, whole frame) */
    enum dr_sampler_kind sampler;   /* zero: independent */
};

struct dr_render_stats {
    double seconds;
    struct dr_ray_counts rays;
    uint64_t invalid_samples;   /* NaN/Inf path values dropped (should stay 0) */
    unsigned stages;            /* the walker's optional stages that ran (path.h) */
    int threads;
};

/* Renders into rgb (width * height * 3 floats, top row first): the
 * rectangle opts->film says of the frame (DR_ERR_ARG if it does not fit). */
int dr_render(const struct dr_scene *scene, const struct dr_camera *camera, const struct dr_render_opts *opts,
              float *rgb, struct dr_render_stats *stats);

/* Working storage dr_render allocates per thread for spp samples per pixel. */
size_t dr_render_thread_bytes(int spp);

/* Draws "label [=====     ] 42%" on stderr (call with done == total to end the line). */
void dr_progress_bar(const char *label, int done, int total);

#endif
