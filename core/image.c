/* In-memory images: the sRGB transfer curves and bilinear texture lookup. */
#include "image.h"

#include "grad_sink.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"

/* IEC 61966-2-1 piecewise curves. Negative values use the linear segment. */
double dr_srgb_to_linear(double v)
{
    if (v <= 0.04045)
        return v / 12.92;
    return pow((v + 0.055) / 1.055, 2.4);
}

double dr_linear_to_srgb(double v)
{
    if (v <= 0.0031308)
        return v * 12.92;
    return 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

/* The last input seen at each 8-bit level and its decoded value. */
struct srgb_memo {
    float in[256], out[256];
    bool known[256];
};

static float srgb_to_linear_memo(struct srgb_memo *m, float v)
{
    float level = v * 255.0f;
    if (!(level >= 0.0f && level <= 255.0f))
        return (float)dr_srgb_to_linear(v);
    int k = (int)(level + 0.5f);
    if (m->known[k] && m->in[k] == v)
        return m->out[k];
    float out = (float)dr_srgb_to_linear(v);
    m->known[k] = true;
    m->in[k] = v;
    m->out[k] = out;
    return out;
}

/* dst = src with the colour channels sRGB-decoded (alpha, channel 1 of 2 or
 * 3 of 4, kept); dst may be src. 8-bit files hold at most 256 distinct
 * values, and pow() per texel was a quarter of loading a scene with two 2k
 * textures: each value is decoded once and remembered (by its nearest 8-bit
 * level, with the exact input, so any other input still goes through pow and
 * the result is bit for bit what it was). */
static void decode_srgb(const float *src, float *dst, size_t n, size_t c)
{
    struct srgb_memo memo;
    memset(&memo, 0, sizeof memo);
    size_t ncolour = (size_t)dr_image_colour_channels((int)c);
    for (size_t i = 0; i < n; ++i) {
        const float *s = src + i * c;
        float *d = dst + i * c;
        for (size_t k = 0; k < c; ++k)
            d[k] = k < ncolour ? srgb_to_linear_memo(&memo, s[k]) : s[k];
    }
}

static bool image_usable(const struct dr_image *img)
{
    return img && dr_image_has_pixels(img) && img->width > 0 && img->height > 0 && img->channels > 0;
}

static size_t value_count(const struct dr_image *img)
{
    return (size_t)img->width * (size_t)img->height * (size_t)img->channels;
}

/* ------------------------------------------------------ eight-bit storage */

/* The decoded table of an eight-bit image (its colour channels' values:
 * dr_image_value keeps alpha's from lut), as decode_srgb would decode each
 * value (the memo gives pow's bits). */
static void make_lut_linear(struct dr_image *img)
{
    float *lin = img->lut + 256;
    for (int k = 0; k < 256; k++)
        lin[k] = img->file_is_srgb ? (float)dr_srgb_to_linear(img->lut[k]) : img->lut[k];
    img->lut_linear = lin;
}

int dr_image_expand(struct dr_image *img)
{
    if (!img || !img->bytes)
        return DR_OK;
    const size_t n = value_count(img);
    const bool decoded = img->lut_linear != NULL, in_place = img->linear_in_data;
    float *data = dr_alloc_big(n * sizeof *data);
    float *lin = decoded && !in_place ? dr_alloc_big(n * sizeof *lin) : NULL;
    if (!data || (decoded && !in_place && !lin)) {
        free(data);
        free(lin);
        dr_set_error("out of memory expanding a %dx%d texture", img->width, img->height);
        return DR_ERR_NOMEM;
    }
    for (size_t i = 0; i < n; i++) {
        data[i] = dr_image_value(img, i, in_place);   /* decoded in place: data held the decoded values */
        if (lin)
            lin[i] = dr_image_value(img, i, true);
    }
    free(img->bytes);
    free(img->lut);
    img->bytes = NULL;
    img->lut = img->lut_linear = NULL;
    img->data = data;
    img->linear = in_place ? data : lin;
    return DR_OK;
}

size_t dr_image_pixel_bytes(const struct dr_image *img)
{
    if (img->bytes)
        return value_count(img) + 512 * sizeof(float);
    if (!img->data)
        return 0;
    const size_t floats = value_count(img) * sizeof(float);
    return img->linear && !img->linear_in_data ? 2 * floats : floats;
}

/* ------------------------------------------------------------ decoding */

int dr_image_make_linear(struct dr_image *img)
{
    if (!image_usable(img))
        return DR_ERR_ARG;
    if (dr_image_has_linear(img))
        return DR_OK;
    if (img->bytes) {
        make_lut_linear(img);
        return DR_OK;
    }
    size_t n = (size_t)img->width * (size_t)img->height;
    size_t c = (size_t)img->channels;
    float *lin = dr_alloc_big(n * c * sizeof *lin);
    if (!lin) {
        dr_set_error("out of memory decoding a %dx%d texture", img->width, img->height);
        return DR_ERR_NOMEM;
    }
    if (img->file_is_srgb)
        decode_srgb(img->data, lin, n, c);
    else
        memcpy(lin, img->data, n * c * sizeof *lin);   /* the stored values are linear already */
    img->linear = lin;
    return DR_OK;
}

int dr_image_make_linear_in_place(struct dr_image *img)
{
    if (!image_usable(img))
        return DR_ERR_ARG;
    if (dr_image_has_linear(img))
        return DR_OK;
    if (img->bytes) {   /* (both views stay: in place only says what data held, for dr_image_expand) */
        make_lut_linear(img);
        img->linear_in_data = true;
        return DR_OK;
    }
    if (img->file_is_srgb)
        decode_srgb(img->data, img->data, (size_t)img->width * (size_t)img->height, (size_t)img->channels);
    img->linear = img->data;
    img->linear_in_data = true;
    return DR_OK;
}

void dr_image_release(struct dr_image *img)
{
    if (!img)
        return;
    if (img->linear != img->data)
        free(img->linear);
    free(img->data);
    free(img->bytes);
    free(img->lut);
    img->data = NULL;
    img->linear = NULL;
    img->bytes = NULL;
    img->lut = img->lut_linear = NULL;
    img->linear_in_data = false;
    img->width = img->height = img->channels = 0;
    img->file_is_srgb = false;
}

/* Reduces a texture coordinate to a range where texel indices fit an int and
 * the wrap mode gives the same result: [0,1] for REPEAT (period 1), [0,2) for
 * MIRROR (period 2), [-1,2] for CLAMP. NaN and infinities become 0. Exact for
 * finite doubles: t - floor(t) has no rounding error. */
static inline double reduce_coord(double t, enum dr_wrap mode)
{
    if (!(t == t) || t - t != 0.0) /* NaN or +-inf */
        return 0.0;
    switch (mode) {
    case DR_WRAP_CLAMP:
        return t < -1.0 ? -1.0 : (t > 2.0 ? 2.0 : t);
    case DR_WRAP_MIRROR:
        return t - 2.0 * floor(0.5 * t);
    case DR_WRAP_REPEAT:
    default:
        return t - floor(t);
    }
}

/* Maps a texel index to [0, n) (OpenGL semantics). After reduce_coord an
 * index is nearly always in range already, so the division (four a lookup,
 * a third of dr_texture_taps' time) is only done where it is not. */
static inline int wrap_index(int i, int n, enum dr_wrap mode)
{
    switch (mode) {
    case DR_WRAP_CLAMP:
        return i < 0 ? 0 : (i >= n ? n - 1 : i);
    case DR_WRAP_MIRROR: {
        int p = 2 * n;
        int m = (unsigned)i < (unsigned)p ? i : i % p;
        if (m < 0)
            m += p;
        /* mirror(a) = a >= 0 ? a : -1 - a;  result = n - 1 - mirror(m - n) */
        int a = m - n;
        if (a < 0)
            a = -1 - a;
        return n - 1 - a;
    }
    case DR_WRAP_REPEAT:
    default: {
        if ((unsigned)i < (unsigned)n)
            return i;
        int m = i % n;
        return m < 0 ? m + n : m;
    }
    }
}

/* Adds weight * texel (expanded to RGBA) to acc. */
static inline void add_texel(const float *p, int channels, double weight, double acc[4])
{
    switch (channels) {
    case 1:
        acc[0] += weight * p[0];
        acc[1] += weight * p[0];
        acc[2] += weight * p[0];
        acc[3] += weight;
        break;
    case 2:
        acc[0] += weight * p[0];
        acc[1] += weight * p[0];
        acc[2] += weight * p[0];
        acc[3] += weight * p[1];
        break;
    case 3:
        acc[0] += weight * p[0];
        acc[1] += weight * p[1];
        acc[2] += weight * p[2];
        acc[3] += weight;
        break;
    default:
        acc[0] += weight * p[0];
        acc[1] += weight * p[1];
        acc[2] += weight * p[2];
        acc[3] += weight * p[3];
        break;
    }
}

void dr_texture_taps(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                     int64_t idx[4], double wt[4])
{
    enum dr_wrap ws = tex ? tex->wrap_s : DR_WRAP_REPEAT;
    enum dr_wrap wtm = tex ? tex->wrap_t : DR_WRAP_REPEAT;
    int w = img->width, h = img->height;
    double x = reduce_coord(u, ws) * w - 0.5;
    double y = reduce_coord(v, wtm) * h - 0.5;
    double fx0 = floor(x), fy0 = floor(y);
    double fx = x - fx0, fy = y - fy0;
    int i0 = (int)fx0, j0 = (int)fy0;
    int xa = wrap_index(i0, w, ws), xb = wrap_index(i0 + 1, w, ws);
    int ya = wrap_index(j0, h, wtm), yb = wrap_index(j0 + 1, h, wtm);
    int64_t row_a = (int64_t)ya * w, row_b = (int64_t)yb * w;
    idx[0] = row_a + xa;
    idx[1] = row_a + xb;
    idx[2] = row_b + xa;
    idx[3] = row_b + xb;
    wt[0] = (1.0 - fx) * (1.0 - fy);
    wt[1] = fx * (1.0 - fy);
    wt[2] = (1.0 - fx) * fy;
    wt[3] = fx * fy;
}

/* Texel idx of an image in eight-bit storage as the floats its float
 * storage would hold (dr_image_value), into t[0, channels) (at most 4 are
 * read), one case per channel count as add_texel (the colour channels of
 * each: dr_image_colour_channels). */
static inline const float *texel8(const struct dr_image *img, int64_t idx, bool use_linear, float t[4])
{
    const uint8_t *b = img->bytes + (size_t)idx * (size_t)img->channels;
    /* colour channels: decoded where asked (or where float storage would
     * have decoded data in place); alpha always as stored */
    const bool decoded = (use_linear || img->linear_in_data) && img->lut_linear;
    const float *colour = decoded ? img->lut_linear : img->lut, *alpha = img->lut;
    switch (img->channels) {
    case 1:
        t[0] = colour[b[0]];
        break;
    case 2:
        t[0] = colour[b[0]];
        t[1] = alpha[b[1]];
        break;
    case 3:
        t[0] = colour[b[0]];
        t[1] = colour[b[1]];
        t[2] = colour[b[2]];
        break;
    default:
        t[0] = colour[b[0]];
        t[1] = colour[b[1]];
        t[2] = colour[b[2]];
        t[3] = alpha[b[3]];
        break;
    }
    return t;
}

/* The stored texel array a lookup reads (NULL: eight-bit storage, texel8, or
 * no pixels). */
static inline const float *texels(const struct dr_image *img, bool use_linear)
{
    return use_linear && img->linear ? img->linear : img->data;
}

void dr_texture_eval(const struct dr_texture *tex, const struct dr_image *img,
                     double u, double v, bool use_linear, double out[4])
{
    if (!img || !dr_image_has_pixels(img) || img->width <= 0 || img->height <= 0 || img->channels <= 0) {
        out[0] = out[1] = out[2] = 0.0;
        out[3] = 1.0;
        return;
    }
    const float *pix = texels(img, use_linear);
    int c = img->channels;
    int64_t idx[4];
    double wt[4];
    dr_texture_taps(tex, img, u, v, idx, wt);
    double acc[4] = {0.0, 0.0, 0.0, 0.0};
    float t[4];
    for (int i = 0; i < 4; i++)
        add_texel(pix ? pix + (size_t)idx[i] * (size_t)c : texel8(img, idx[i], use_linear, t), c, wt[i], acc);
    out[0] = acc[0];
    out[1] = acc[1];
    out[2] = acc[2];
    out[3] = (c == 2 || c >= 4) ? acc[3] : 1.0; /* exactly opaque without alpha */
}

/* noipa: GCC's link-time optimisation judged this function, whose only
 * effect is __builtin_prefetch, free of side effects and dropped three of
 * dr_material_prefetch's four calls (a textured render's lookups then
 * waited on memory: dr_texture_eval 5 % -> 12 % of the big textured bench
 * scene). Kept opaque, every call stays. (Clang has no such attribute.) */
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((noipa))
#endif
void dr_texture_prefetch(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                         bool use_linear)
{
    if (!img || !dr_image_has_pixels(img) || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return;
    const float *pix = texels(img, use_linear);
    int64_t idx[4];
    double wt[4];
    dr_texture_taps(tex, img, u, v, idx, wt);
    for (int i = 0; i < 4; i++)
        __builtin_prefetch(pix ? (const void *)(pix + (size_t)idx[i] * (size_t)img->channels)
                               : (const void *)(img->bytes + (size_t)idx[i] * (size_t)img->channels));
}

void d_texture_eval(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                    const double d_out[4], int64_t slot, struct dr_grad_sink *sink)
{
    if (!img || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return;
    int64_t idx[4];
    double wt[4];
    dr_texture_taps(tex, img, u, v, idx, wt);
    double g[4];
    int k = dr_texture_channel_adjoint(img->channels, d_out, g);
    for (int i = 0; i < 4; i++) {
        if (wt[i] == 0.0)
            continue;
        int64_t t = slot + idx[i] * img->channels;
        for (int ch = 0; ch < k; ch++)
            dr_sink_add(sink, t + ch, wt[i] * g[ch]);
    }
}

/* Slope of reduce_coord: 1 except where CLAMP clamps. */
static inline double reduce_slope(double t, enum dr_wrap mode)
{
    if (!(t == t) || t - t != 0.0)
        return 0.0;
    return mode == DR_WRAP_CLAMP && (t < -1.0 || t > 2.0) ? 0.0 : 1.0;
}

void d_texture_eval_uv(const struct dr_texture *tex, const struct dr_image *img, double u, double v,
                       bool use_linear, const double d_out[4], double *d_u, double *d_v)
{
    if (!img || !dr_image_has_pixels(img) || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return;
    const float *pix = texels(img, use_linear);
    enum dr_wrap ws = tex ? tex->wrap_s : DR_WRAP_REPEAT;
    enum dr_wrap wtm = tex ? tex->wrap_t : DR_WRAP_REPEAT;
    int64_t idx[4];
    double wt[4];
    dr_texture_taps(tex, img, u, v, idx, wt);
    /* the fractions fx, fy back from the weights: wt1 + wt3 = fx, wt2 + wt3 = fy */
    double fx = wt[1] + wt[3], fy = wt[2] + wt[3];
    const int c = img->channels;
    double g[4];   /* sum_c d_out[c] * texel_i[c] */
    for (int i = 0; i < 4; i++) {
        double acc[4] = {0.0, 0.0, 0.0, 0.0};
        float t[4];
        add_texel(pix ? pix + (size_t)idx[i] * (size_t)c : texel8(img, idx[i], use_linear, t), c, 1.0, acc);
        if (c == 1 || c == 3)
            acc[3] = 0.0;   /* constant alpha: no slope */
        g[i] = d_out[0] * acc[0] + d_out[1] * acc[1] + d_out[2] * acc[2] + d_out[3] * acc[3];
    }
    /* wt0 = (1-fx)(1-fy), wt1 = fx(1-fy), wt2 = (1-fx)fy, wt3 = fx fy; x = u' w - 0.5 */
    double d_fx = (1.0 - fy) * (g[1] - g[0]) + fy * (g[3] - g[2]);
    double d_fy = (1.0 - fx) * (g[2] - g[0]) + fx * (g[3] - g[1]);
    if (d_u)
        *d_u += d_fx * img->width * reduce_slope(u, ws);
    if (d_v)
        *d_v += d_fy * img->height * reduce_slope(v, wtm);
}
