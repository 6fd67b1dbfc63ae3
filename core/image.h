/* In-memory images and texture lookup.
 * Pixels are row-major, top row first, `channels` interleaved values: floats,
 * or (a scene texture from an 8-bit file) bytes standing for floats. */
#ifndef DR_IMAGE_H
#define DR_IMAGE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "bigalloc.h"   /* pixel buffers: dr_alloc_big */
#include "vec.h"

#ifdef __cplusplus
extern "C" {
#endif

struct dr_image {
    int width, height, channels;
    float *data;     /* values as stored in the file (8-bit colour: sRGB-encoded, 0..1) */
    float *linear;   /* sRGB-decoded copy of data (RGB decoded, alpha kept); NULL until
                        dr_image_make_linear(); colour textures are looked up here */
    bool file_is_srgb; /* the file declares sRGB-encoded values (PNG/JPEG, 8-bit)      */
    bool linear_in_data; /* linear is data itself, decoded in place (dr_image_make_linear_in_place) */
    /* Eight-bit storage (dr_image_read_memory8), instead of data and linear: a
     * texture from an 8-bit file holds at most 256 values, so value i is
     * lut[bytes[i]] and its decoded one lut_linear[bytes[i]] (alpha: lut's),
     * the same floats as data and linear would hold, in a quarter of the
     * memory. Read them through dr_image_value, dr_texture_eval and the
     * other lookups; dr_image_expand goes back to floats (parameters). */
    uint8_t *bytes;
    float *lut;          /* 256 values as stored; NULL without bytes */
    float *lut_linear;   /* 256 decoded (lut + 256), NULL until dr_image_make_linear */
};

/* Colour channels (sRGB-decoded) of a c-channel image; the rest is alpha
 * (channel 1 of 2, 3 of 4), kept as stored. */
static inline int dr_image_colour_channels(int c)
{
    return c == 2 ? 1 : (c >= 4 ? 3 : c);
}

/* Has pixels, in float or eight-bit storage. */
static inline bool dr_image_has_pixels(const struct dr_image *img)
{
    return img->data || img->bytes;
}

/* Has its sRGB-decoded values (dr_image_make_linear or _in_place ran). */
static inline bool dr_image_has_linear(const struct dr_image *img)
{
    return img->linear || img->lut_linear;
}

/* Value i (texel * channels + channel): the decoded one where use_linear and
 * the image has them (dr_image_has_linear), else data's (the stored one, or
 * the decoded one where it was decoded in place); 0 without pixels. */
static inline float dr_image_value(const struct dr_image *img, size_t i, bool use_linear)
{
    if (img->bytes) {
        const int ch = (int)(i % (size_t)img->channels);
        const bool decoded = (use_linear || img->linear_in_data) && img->lut_linear;   /* (as data and linear) */
        return (decoded && ch < dr_image_colour_channels(img->channels) ? img->lut_linear : img->lut)[img->bytes[i]];
    }
    const float *px = use_linear && img->linear ? img->linear : img->data;
    return px ? px[i] : 0.0f;
}

/* Back to float storage (data, and linear if decoded), the same values.
 * No-op for float images. Returns 0 or DR_ERR_NOMEM (then unchanged). */
int dr_image_expand(struct dr_image *img);
/* Bytes its pixels take (both float arrays, or the bytes and tables). */
size_t dr_image_pixel_bytes(const struct dr_image *img);

enum dr_wrap { DR_WRAP_REPEAT, DR_WRAP_CLAMP, DR_WRAP_MIRROR };

/* glTF texture = image + sampler. */
struct dr_texture {
    int image;                /* index into scene->images */
    enum dr_wrap wrap_s, wrap_t;
};

double dr_srgb_to_linear(double v);
double dr_linear_to_srgb(double v);

/* Fills img->linear from img->data (idempotent). Returns 0 or DR_ERR_NOMEM. */
int dr_image_make_linear(struct dr_image *img);
/* The same for an image only ever looked up as colour: decodes data in
 * place and makes linear the same array (no second copy to allocate, fault
 * in and keep; the file's encoded values are gone). Returns 0 or DR_ERR_ARG. */
int dr_image_make_linear_in_place(struct dr_image *img);
void dr_image_release(struct dr_image *img);   /* frees data and linear */

/* Bilinear lookup at glTF uv (u right, v down, texel centres at (i+0.5)/w),
 * honouring the wrap modes. Returns up to 4 channels in out (missing channels:
 * 0 for colour, 1 for alpha). `use_linear` selects img->linear (must exist). */
void dr_texture_eval(const struct dr_texture *tex, const struct dr_image *img,
                     double u, double v, bool use_linear, double out[4]);

/* The (at most) four texels a bilinear lookup blends: texel index (y * width
 * + x, 0 when its weight is 0) and weight; dr_texture_eval(...) channel c is
 * sum_i w[i] * pixels[idx[i] * channels + c]. Derivatives use the same taps. */
void dr_texture_taps(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                     int64_t idx[4], double w[4]);
/* Asks the cache for the texels dr_texture_eval(tex, img, u, v, use_linear)
 * will read, without waiting for them: a packet tracer calls it for all its
 * hits before shading any, so the misses of a large texture overlap instead
 * of stalling one lane after another. Changes no result. */
void dr_texture_prefetch(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                         bool use_linear);

/* How an rgba adjoint d_out lands on an image's channels (grey images gather
 * r+g+b into channel 0): fills g[0..k) and returns k = min(channels, 4). */
static inline int dr_texture_channel_adjoint(int channels, const double d_out[4], double g[4])
{
    if (channels == 1) {
        g[0] = d_out[0] + d_out[1] + d_out[2];
        return 1;
    }
    if (channels == 2) {
        g[0] = d_out[0] + d_out[1] + d_out[2];
        g[1] = d_out[3];
        return 2;
    }
    int k = channels < 4 ? channels : 4;
    for (int i = 0; i < k; i++)
        g[i] = d_out[i];
    return k;
}

struct dr_grad_sink;   /* grad_sink.h */

/* Adjoint of dr_texture_eval with respect to the texel values: d_out[c] *
 * weight lands in the sink at slot + texel * channels + c for the blended
 * texels (c < min(channels, 4)); slot is the image's first gradient entry. */
void d_texture_eval(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                    const double d_out[4], int64_t slot, struct dr_grad_sink *sink);

/* Adjoint of dr_texture_eval with respect to (u, v) (attached sampling: the
 * lookup moves with the hit point): adds sum_c d_out[c] * d out[c] / d u to
 * *d_u and likewise *d_v. Bilinear weights are piecewise linear: at a texel
 * centre or a wrap seam the adjoint is the one-sided slope of the cell the
 * primal used; CLAMP beyond [-1, 2] (where reduce_coord clamps) gives zero. */
void d_texture_eval_uv(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                       bool use_linear, const double d_out[4], double *d_u, double *d_v);

#ifdef __cplusplus
}
#endif
#endif
