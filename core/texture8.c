/* Eight-lane texture lookups (texture8.h). Each helper names the scalar
 * function in image.c or geometry.h it mirrors; keep them in step when
 * either changes (test_texture8 fails otherwise). */
#include "texture8.h"

#include "image.h"

bool dr_texref8_accepts(const struct dr_scene *s, const struct dr_texref *r)
{
    if (r->texture < 0 || (r->texcoord != 0 && r->texcoord != 1))
        return false;
    const struct dr_image *img = &s->images[s->textures[r->texture].image];
    const bool stored = img->bytes ? img->lut != NULL : img->data != NULL;   /* (blend reads either) */
    return stored && img->channels >= 1 && img->channels <= 4 && img->width > 0 && img->height > 0;
}

/* reduce_coord: NaN and infinities to 0, then the wrap mode's period. */
DR_SIMD_INLINE dr_f8 reduce_coord8(dr_f8 t, enum dr_wrap mode)
{
    t = dr_f8_sel(dr_f8_eq(t - t, dr_f8s(0.0)), t, dr_f8s(0.0));
    switch (mode) {
    case DR_WRAP_CLAMP:
        return dr_f8_clamp(t, -1.0, 2.0);
    case DR_WRAP_MIRROR:
        return t - 2.0 * dr_f8_floor(0.5 * t);
    case DR_WRAP_REPEAT:
    default:
        return t - dr_f8_floor(t);
    }
}

/* wrap_index for the indices a reduced coordinate gives (integers in
 * doubles): in [-1, n] for REPEAT, [-1, 2n] for MIRROR, where wrap_index's
 * remainder is one period added or taken off. */
DR_SIMD_INLINE dr_f8 wrap_index8(dr_f8 i, double n, enum dr_wrap mode)
{
    switch (mode) {
    case DR_WRAP_CLAMP:
        return dr_f8_clamp(i, 0.0, n - 1.0);
    case DR_WRAP_MIRROR: {
        const double p = 2.0 * n;
        dr_f8 m = dr_f8_sel(dr_f8_lt(i, dr_f8s(0.0)), i + p, dr_f8_sel(dr_f8_ge(i, dr_f8s(p)), i - p, i));
        dr_f8 a = m - n;
        a = dr_f8_sel(dr_f8_lt(a, dr_f8s(0.0)), -1.0 - a, a);
        return (n - 1.0) - a;
    }
    case DR_WRAP_REPEAT:
    default:
        return dr_f8_sel(dr_f8_lt(i, dr_f8s(0.0)), i + n, dr_f8_sel(dr_f8_ge(i, dr_f8s(n)), i - n, i));
    }
}

/* dr_texture_taps: the four texel indices and weights. */
static void taps8(const struct dr_texture *tex, const struct dr_image *img, dr_f8 u, dr_f8 v, int64_t idx[4][DR_SIMD_W],
                  dr_f8 wt[4])
{
    const double w = img->width, h = img->height;
    dr_f8 x = reduce_coord8(u, tex->wrap_s) * w - 0.5;
    dr_f8 y = reduce_coord8(v, tex->wrap_t) * h - 0.5;
    dr_f8 fx0 = dr_f8_floor(x), fy0 = dr_f8_floor(y);
    dr_f8 fx = x - fx0, fy = y - fy0;
    dr_f8 xa = wrap_index8(fx0, w, tex->wrap_s), xb = wrap_index8(fx0 + 1.0, w, tex->wrap_s);
    dr_f8 ya = wrap_index8(fy0, h, tex->wrap_t), yb = wrap_index8(fy0 + 1.0, h, tex->wrap_t);
    dr_f8 row_a = ya * w, row_b = yb * w;   /* (integers below 2^53: exact) */
    const dr_f8 i[4] = {row_a + xa, row_a + xb, row_b + xa, row_b + xb};
    for (int k = 0; k < 4; k++)
        for (int l = 0; l < DR_SIMD_W; l++)
            idx[k][l] = (int64_t)i[k][l];
    wt[0] = (1.0 - fx) * (1.0 - fy);
    wt[1] = fx * (1.0 - fy);
    wt[2] = (1.0 - fx) * fy;
    wt[3] = fx * fy;
}

/* dr_texref_uv's transform of the set's (u, v), if r has one. */
DR_SIMD_INLINE void texref_uv8(const struct dr_texref *r, dr_f8 *u, dr_f8 *v)
{
    if (!r->transformed)
        return;
    const double *x = r->xf;
    dr_f8 tu = x[0] * *u + x[1] * *v + x[2];
    *v = x[3] * *u + x[4] * *v + x[5];
    *u = tu;
}

/* The lanes of on with a texref. */
static dr_m8 with_texref(const struct dr_texref *const r[DR_SIMD_W], dr_m8 on)
{
    dr_m8 m;
    for (int i = 0; i < DR_SIMD_W; i++)
        m[i] = on[i] && r[i] ? -1 : 0;
    return m;
}

/* One group of a call's lanes: the lanes of pending whose texref is that of
 * pending's first lane (taken off pending), their image, and the taps of the
 * lookup at that texref's set of uv through its transform. */
struct group8 {
    dr_m8 lanes;
    const struct dr_image *img;
    int64_t idx[4][DR_SIMD_W];
    dr_f8 wt[4];
};

static void next_group(const struct dr_scene *s, const struct dr_texref *const r[DR_SIMD_W], dr_m8 *pending,
                       const struct dr_uv8 *uv, struct group8 *g)
{
    int first = 0;
    while (!(*pending)[first])
        first++;
    const struct dr_texref *ref = r[first];
    for (int i = 0; i < DR_SIMD_W; i++)
        g->lanes[i] = (*pending)[i] && r[i] == ref ? -1 : 0;
    *pending &= ~g->lanes;
    const struct dr_texture *tex = &s->textures[ref->texture];
    g->img = &s->images[tex->image];
    dr_f8 u = uv->u[ref->texcoord], v = uv->v[ref->texcoord];
    texref_uv8(ref, &u, &v);
    taps8(tex, g->img, u, v, g->idx, g->wt);
}

/* The 256 values an eight-bit image's colour channels stand for (texel8's
 * choice: decoded where asked, or where float storage would have decoded
 * in place). */
static const float *colour_lut(const struct dr_image *img, bool use_linear)
{
    return (use_linear || img->linear_in_data) && img->lut_linear ? img->lut_linear : img->lut;
}

/* dr_texture_eval's sum of the colour channels over the four taps, for the
 * lanes of `lanes`: tap by tap in its order, acc += wt * texel, with the
 * texels texel8 (eight-bit storage) or image.c's texels (float storage)
 * reads, widened to double (exact). A grey image's one colour channel
 * counts for all three, as add_texel counts it. Other lanes: 0.
 * The texels go straight into vector registers (initialiser lists, as
 * simd.h advises; lanes off read texel 0 and are zeroed after). Measured:
 * no change in time. Under an environment map this function still takes a
 * tenth of a render in perf, on the texel reads themselves: a map's texels
 * are read at random directions, mostly from beyond the L2 cache. */
static dr_v3x8 blend(const struct dr_image *img, dr_m8 lanes, int64_t idx[4][DR_SIMD_W], dr_f8 wt[4],
                     bool use_linear)
{
    const size_t c = (size_t)img->channels;
    const size_t g = c >= 3 ? 1 : 0, b = c >= 3 ? 2 : 0;   /* (green's and blue's channel) */
    const float *lut = img->bytes ? colour_lut(img, use_linear) : NULL;
    const float *pix = use_linear && img->linear ? img->linear : img->data;
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    dr_v3x8 acc = zero;
    for (int k = 0; k < 4; k++) {
        size_t o[DR_SIMD_W];   /* each lane's texel's first channel */
        for (int i = 0; i < DR_SIMD_W; i++)
            o[i] = lanes[i] ? (size_t)idx[k][i] * c : 0;
        dr_v3x8 t;
        if (lut) {
            const uint8_t *p = img->bytes;
#define CH(ch) (dr_f8){lut[p[o[0] + ch]], lut[p[o[1] + ch]], lut[p[o[2] + ch]], lut[p[o[3] + ch]], \
                       lut[p[o[4] + ch]], lut[p[o[5] + ch]], lut[p[o[6] + ch]], lut[p[o[7] + ch]]}
            t = (dr_v3x8){CH(0), CH(g), CH(b)};
#undef CH
        } else {
#define CH(ch) (dr_f8){pix[o[0] + ch], pix[o[1] + ch], pix[o[2] + ch], pix[o[3] + ch], \
                       pix[o[4] + ch], pix[o[5] + ch], pix[o[6] + ch], pix[o[7] + ch]}
            t = (dr_v3x8){CH(0), CH(g), CH(b)};
#undef CH
        }
        t = dr_v3x8_sel(lanes, t, zero);
        acc.x = acc.x + wt[k] * t.x;
        acc.y = acc.y + wt[k] * t.y;
        acc.z = acc.z + wt[k] * t.z;
    }
    return acc;
}

dr_v3x8 dr_texref8_rgb(const struct dr_scene *s, const struct dr_texref *const r[DR_SIMD_W], dr_m8 on,
                       const struct dr_uv8 *uv, bool use_linear)
{
    dr_v3x8 out = {dr_f8s(1.0), dr_f8s(1.0), dr_f8s(1.0)};
    dr_m8 pending = with_texref(r, on);
    while (dr_m8_any(pending)) {
        struct group8 g;
        next_group(s, r, &pending, uv, &g);
        out = dr_v3x8_sel(g.lanes, blend(g.img, g.lanes, g.idx, g.wt, use_linear), out);
    }
    return out;
}

dr_v3x8 dr_texture8_rgb(const struct dr_texture *tex, const struct dr_image *img, dr_m8 on, dr_f8 u, dr_f8 v,
                        bool use_linear)
{
    int64_t idx[4][DR_SIMD_W];
    dr_f8 wt[4];
    taps8(tex, img, u, v, idx, wt);
    return blend(img, on, idx, wt, use_linear);
}

void dr_texref8_prefetch(const struct dr_scene *s, const struct dr_texref *const r[DR_SIMD_W], dr_m8 on,
                         const struct dr_uv8 *uv, bool use_linear)
{
    dr_m8 pending = with_texref(r, on);
    while (dr_m8_any(pending)) {
        struct group8 g;
        next_group(s, r, &pending, uv, &g);
        const size_t c = (size_t)g.img->channels;
        const float *pix = use_linear && g.img->linear ? g.img->linear : g.img->data;   /* (blend's) */
        for (int k = 0; k < 4; k++)
            for (int i = 0; i < DR_SIMD_W; i++)
                if (g.lanes[i])
                    __builtin_prefetch(g.img->bytes ? (const void *)(g.img->bytes + (size_t)g.idx[k][i] * c)
                                                    : (const void *)(pix + (size_t)g.idx[k][i] * c));
    }
}
