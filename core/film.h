/* The film: the pixel filter and the rectangle of the frame that is rendered.
 *
 * Pixel filters by filter importance sampling: a pixel's value is
 * integral f(t) L(c + t) dt over film offsets t from its centre c, with f a
 * normalised filter; each sample draws its offset from f itself (two
 * uniforms, the camera ray's first two dimensions), so every sample has
 * weight 1, pixels stay independent, and gradients need no splatting.
 *   box       f = 1 on the pixel's square (the default: drender's film so far)
 *   tent      f(t) = (1 - |tx|) (1 - |ty|) on |tx|, |ty| < 1 (radius 1 pixel)
 *   gaussian  f(t) = N(0, s^2) in x and y (default s = 0.5 pixel), not truncated
 *
 * Crop windows: the frame (frame_w x frame_h) is the image the camera sees;
 * only a rectangle of it (the rendered width x height, at x0, y0) is rendered.
 * Random numbers and camera rays depend on the frame pixel, so a cropped
 * render is, bit for bit, the same rectangle of the full render.
 * A zeroed struct dr_film is the box filter over the whole frame. */
#ifndef DR_FILM_H
#define DR_FILM_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

enum dr_filter_kind { DR_FILTER_BOX, DR_FILTER_TENT, DR_FILTER_GAUSSIAN };

#define DR_FILTER_GAUSSIAN_STDDEV 0.5

struct dr_filter {
    enum dr_filter_kind kind;
    double stddev;   /* gaussian: standard deviation in pixels (0: the default) */
};

struct dr_film {
    struct dr_filter filter;
    int frame_w, frame_h;   /* the full frame; 0: the rendered rectangle is the frame */
    int x0, y0;             /* the rendered rectangle's top-left pixel in the frame */
};

/* "box", "tent", "gaussian", "gaussian:S" (S > 0, at most 16 pixels).
 * 0, or DR_ERR_ARG with a message for dr_last_error(). */
int dr_filter_parse(const char *text, struct dr_filter *f);
/* "box", "tent", "gaussian:0.5" into buf. */
void dr_filter_format(const struct dr_filter *f, char *buf, size_t size);

/* Offset in [-r, r] of a normalised 1-D tent of radius 1 from a uniform u:
 * the inverse of its distribution function. */
static inline double dr_tent_sample(double u)
{
    return u < 0.5 ? sqrt(2.0 * u) - 1.0 : 1.0 - sqrt(2.0 - 2.0 * u);
}

/* Film position (pixels; (0, 0) is the frame's top-left corner) of a sample
 * of frame pixel (x, y) from two uniforms in [0, 1). */
static inline void dr_film_sample(const struct dr_filter *f, int x, int y, double u, double v, double *fx,
                                  double *fy)
{
    switch (f->kind) {
    case DR_FILTER_TENT:
        *fx = x + 0.5 + dr_tent_sample(u);
        *fy = y + 0.5 + dr_tent_sample(v);
        return;
    case DR_FILTER_GAUSSIAN: {
        /* Box-Muller: one 2-D normal from the two uniforms (1 - u > 0) */
        double s = f->stddev > 0.0 ? f->stddev : DR_FILTER_GAUSSIAN_STDDEV;
        double r = s * sqrt(-2.0 * log(1.0 - u)), phi = 2.0 * M_PI * v;
        *fx = x + 0.5 + r * cos(phi);
        *fy = y + 0.5 + r * sin(phi);
        return;
    }
    case DR_FILTER_BOX:
    default:
        /* x + u, not x + 0.5 + (u - 0.5): the same numbers as before filters existed */
        *fx = x + u;
        *fy = y + v;
        return;
    }
}

static inline int dr_film_frame_w(const struct dr_film *f, int width) { return f->frame_w > 0 ? f->frame_w : width; }
static inline int dr_film_frame_h(const struct dr_film *f, int height)
{
    return f->frame_h > 0 ? f->frame_h : height;
}

/* Frame pixel (x, y) and its index in the frame (what random numbers are
 * keyed on) of pixel `local` of the rendered rectangle, `width` wide. */
static inline uint64_t dr_film_pixel(const struct dr_film *f, int width, int64_t local, int *x, int *y)
{
    *x = f->x0 + (int)(local % width);
    *y = f->y0 + (int)(local / width);
    return (uint64_t)*y * (uint64_t)dr_film_frame_w(f, width) + (uint64_t)*x;
}

/* 0 when the rectangle width x height at (x0, y0) lies in the frame, else
 * DR_ERR_ARG with a message. */
int dr_film_check(const struct dr_film *f, int width, int height);

#endif
