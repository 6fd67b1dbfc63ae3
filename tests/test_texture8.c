/* Tests of core/texture8.c: the eight-lane texture lookup against the
 * scalar one (dr_texref_uv + dr_texture_eval) bit for bit, over eight-bit
 * and float RGB and RGBA images of awkward sizes, every pair of wrap modes, texture
 * transforms, both TEXCOORD sets, coordinates far outside [0, 1] and not
 * finite at all, lanes of different textures in one call and lanes left out; and which texrefs
 * the lookup accepts; and the one-texture lookup (the environment map's)
 * over images of either storage and any channel count. Deterministic:
 * fixed seeds. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "geometry.h"
#include "image.h"
#include "sampler.h"
#include "scene.h"
#include "test.h"
#include "texture8.h"

struct rng { uint64_t s; };
static double rng_next(struct rng *r)
{
    r->s += 0x9e3779b97f4a7c15ULL;
    return (double)(dr_hash64(r->s) >> 11) * (1.0 / 9007199254740992.0);
}

/* A w x h image of c channels in eight-bit storage with random bytes, as
 * dr_image_read_memory8 leaves a PNG's: the lut holds k / 255, and
 * make_linear (or _in_place) decodes its colour channels. */
static struct dr_image image8(struct rng *r, int w, int h, int c, bool in_place)
{
    struct dr_image im;
    memset(&im, 0, sizeof im);
    im.width = w, im.height = h, im.channels = c;
    im.file_is_srgb = true;
    im.bytes = malloc((size_t)w * h * c);
    im.lut = malloc(512 * sizeof(float));
    if (!im.bytes || !im.lut)
        exit(2);
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        im.bytes[i] = (uint8_t)(rng_next(r) * 256.0);
    for (int k = 0; k < 256; k++)
        im.lut[k] = (float)(k / 255.0);
    int rc = in_place ? dr_image_make_linear_in_place(&im) : dr_image_make_linear(&im);
    CHECK(rc == 0 && im.lut_linear, "decode a %dx%dx%d eight-bit image", w, h, c);
    return im;
}

/* The scene's one triangle, whose TEXCOORD_1 is (0, 0), (1, 0), (0, 1):
 * at barycentrics (b1, b2) dr_hit_uv1 interpolates to (b1, b2) (NaN where
 * b0 = 1 - b1 - b2 is not finite). */
static void one_triangle_with_uv1(struct dr_scene *s)
{
    static uint32_t indices[3] = {0, 1, 2};
    static float uvs1[6] = {0, 0, 1, 0, 0, 1};
    s->mesh.n_triangles = 1, s->mesh.n_vertices = 3;
    s->mesh.indices = indices;
    s->mesh.uvs1 = uvs1;
}

/* A hit on that triangle with TEXCOORD_0 (u, v) at barycentrics (b1, b2). */
static struct dr_hit hit_at(double u, double v, double b1, double b2)
{
    struct dr_hit hit;
    memset(&hit, 0, sizeof hit);
    hit.uv[0] = u, hit.uv[1] = v;
    hit.b1 = b1, hit.b2 = b2;
    return hit;
}

/* The scalar lookup a lane stands for: dr_texref_uv of the hit (its set),
 * then dr_texture_eval's colour channels. */
static dr_vec3 scalar_rgb(const struct dr_scene *s, const struct dr_texref *r, struct dr_hit hit, bool use_linear)
{
    double uv[2], px[4];
    dr_texref_uv(&s->mesh, r, &hit, uv);
    const struct dr_texture *t = &s->textures[r->texture];
    dr_texture_eval(t, &s->images[t->image], uv[0], uv[1], use_linear, px);
    return dr_v3(px[0], px[1], px[2]);
}

static bool same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

/* A coordinate: mostly in [-3, 3], sometimes a value the wrap modes must
 * handle exactly (texel centres and edges, just below 0, huge, not finite). */
static double coord(struct rng *r, int size)
{
    const double special[] = {0.0, -0.0, 1.0, 0.5, -1e-17, 1.0 - 1e-16, 2.0, -1.0, 1e20, -1e300,
                              NAN, INFINITY, -INFINITY, 0.5 / size, 1.0 / size, 3.0 - 0.5 / size};
    if (rng_next(r) < 0.15)
        return special[(int)(rng_next(r) * (sizeof special / sizeof special[0]))];
    return -3.0 + 6.0 * rng_next(r);
}

/* Every lane of many calls, textures drawn per lane from refs (NULL among
 * them), some lanes left out: the same bits as the scalar lookup, 1 where a
 * lane has no lookup. Each lane's TEXCOORD_1 is dr_hit_uv1's at random
 * barycentrics, as the stages hand it over. Returns the lanes compared. */
static long compare_lanes(struct dr_scene *s, const struct dr_texref *refs, int n_refs, bool use_linear,
                          struct rng *r, int calls)
{
    long compared = 0, differ = 0, left_alone = 0;
    for (int call = 0; call < calls; call++) {
        const struct dr_texref *lane_ref[DR_SIMD_W];
        dr_m8 on;
        struct dr_uv8 uv;
        struct dr_hit hit[DR_SIMD_W];
        for (int i = 0; i < DR_SIMD_W; i++) {
            int k = (int)(rng_next(r) * (n_refs + 1));
            lane_ref[i] = k < n_refs ? &refs[k] : NULL;
            on[i] = rng_next(r) < 0.85 ? -1 : 0;
            int size = lane_ref[i] ? s->images[s->textures[lane_ref[i]->texture].image].width : 4;
            double u = coord(r, size), v = coord(r, size), uv1[2];
            hit[i] = hit_at(u, v, coord(r, size), coord(r, size));
            dr_hit_uv1(&s->mesh, &hit[i], uv1);
            uv.u[0][i] = u, uv.v[0][i] = v, uv.u[1][i] = uv1[0], uv.v[1][i] = uv1[1];
        }
        dr_v3x8 got = dr_texref8_rgb(s, lane_ref, on, &uv, use_linear);
        dr_texref8_prefetch(s, lane_ref, on, &uv, use_linear);   /* (no result: must not fault) */
        for (int i = 0; i < DR_SIMD_W; i++) {
            dr_vec3 want = on[i] && lane_ref[i] ? scalar_rgb(s, lane_ref[i], hit[i], use_linear) : dr_v3s(1.0);
            bool same = same_bits(got.x[i], want.x) && same_bits(got.y[i], want.y) && same_bits(got.z[i], want.z);
            if (!same && differ++ < 5)
                CHECK(same, "lane %d, set %d, uv (%.17g, %.17g): (%.17g %.17g %.17g), the scalar lookup (%.17g %.17g %.17g)",
                      i, lane_ref[i]->texcoord, uv.u[lane_ref[i]->texcoord][i], uv.v[lane_ref[i]->texcoord][i],
                      got.x[i], got.y[i], got.z[i], want.x, want.y, want.z);
            compared += on[i] && lane_ref[i];
            left_alone += !(on[i] && lane_ref[i]);
        }
    }
    CHECK(differ == 0, "%ld of %ld lanes differ from the scalar lookup", differ, compared);
    CHECK(left_alone > 0 && compared > 0, "both kinds of lane were drawn");
    return compared;
}

/* A w x h image of c channels in float storage with random values (up to
 * 50: an HDR map's range), with a decoded copy beside it or not. */
static struct dr_image image_float(struct rng *r, int w, int h, int c, bool with_linear)
{
    struct dr_image im;
    memset(&im, 0, sizeof im);
    im.width = w, im.height = h, im.channels = c;
    size_t n = (size_t)w * h * c;
    im.data = malloc(n * sizeof(float));
    im.linear = with_linear ? malloc(n * sizeof(float)) : NULL;
    if (!im.data || (with_linear && !im.linear))
        exit(2);
    for (size_t i = 0; i < n; i++) {
        im.data[i] = (float)(50.0 * rng_next(r) * rng_next(r));
        if (with_linear)
            im.linear[i] = (float)rng_next(r);   /* (unrelated: which array was read shows) */
    }
    return im;
}

static void test_matches_scalar_lookup(void)
{
    struct rng r = {7};
    static struct dr_scene s;
    const int sizes[][3] = {{5, 3, 3}, {1, 1, 3}, {7, 1, 4}, {1, 6, 3}, {64, 64, 4}, {33, 17, 3}};
    const int n_img = sizeof sizes / sizeof sizes[0];
    one_triangle_with_uv1(&s);
    s.images = calloc((size_t)n_img, sizeof *s.images);
    s.textures = calloc((size_t)n_img * 9, sizeof *s.textures);
    struct dr_texref refs[2 * 9 * 6];
    int n_refs = 0;
    for (int k = 0; k < n_img; k++) {   /* the last two in float storage (texture parameters, HDR files) */
        s.images[k] = k < 4 ? image8(&r, sizes[k][0], sizes[k][1], sizes[k][2], k % 2 == 1)
                            : image_float(&r, sizes[k][0], sizes[k][1], sizes[k][2], k == 5);
        s.n_images++;
        for (int ws = 0; ws < 3; ws++)
            for (int wt = 0; wt < 3; wt++) {   /* every pair of wrap modes, each with and without a transform,
                                                  through either TEXCOORD set */
                s.textures[s.n_textures] = (struct dr_texture){k, (enum dr_wrap)ws, (enum dr_wrap)wt};
                struct dr_texref plain = {.texture = s.n_textures, .texcoord = (ws + wt + k) % 2, .transformed = false,
                                          .xf = {1, 0, 0, 0, 1, 0}};
                struct dr_texref moved = plain;
                moved.transformed = true;
                moved.texcoord = 1 - plain.texcoord;
                for (int j = 0; j < 6; j++)
                    moved.xf[j] = -2.0 + 4.0 * rng_next(&r);
                refs[n_refs++] = plain;
                refs[n_refs++] = moved;
                s.n_textures++;
            }
    }
    for (int k = 0; k < n_refs; k++)
        CHECK(dr_texref8_accepts(&s, &refs[k]), "texref %d is accepted", k);
    long n = 0;
    for (int lin = 0; lin < 2; lin++)
        for (int start = 0; start < n_refs; start += 12)   /* a dozen texrefs at a time: several in one call */
            n += compare_lanes(&s, refs + start, n_refs - start < 12 ? n_refs - start : 12, lin == 1, &r, 1000);
    CHECK(n > 100000, "only %ld lanes compared", n);

    /* what is left to the scalar lookup */
    struct dr_texref t2 = refs[0];
    t2.texcoord = 2;
    CHECK(!dr_texref8_accepts(&s, &t2), "no TEXCOORD_2 (the loader drops such textures)");
    struct dr_texref none = {.texture = -1};
    CHECK(!dr_texref8_accepts(&s, &none), "no texture, no lookup");
    struct dr_image keep = s.images[0];
    s.images[0].channels = 5;   /* (a five-channel EXR's) */
    CHECK(!dr_texref8_accepts(&s, &refs[0]), "an image of five channels is the scalar lookup's");
    s.images[0] = keep;
    for (int c = 1; c <= 2; c++) {   /* grey, and grey with alpha: image 0's bytes read as fewer channels */
        s.images[0].channels = c;
        CHECK(dr_texref8_accepts(&s, &refs[0]), "a grey image (%d channels) is accepted", c);
        for (int lin = 0; lin < 2; lin++)
            compare_lanes(&s, refs, 12, lin == 1, &r, 1000);
    }
    s.images[0] = keep;
    CHECK(dr_image_expand(&s.images[0]) == 0 && !s.images[0].bytes, "expand image 0 to floats");
    CHECK(dr_texref8_accepts(&s, &refs[0]), "an eight-bit image expanded to floats (a parameter's) is accepted");
    for (int lin = 0; lin < 2; lin++)
        compare_lanes(&s, refs, 12, lin == 1, &r, 1000);

    for (int k = 0; k < n_img; k++)
        dr_image_release(&s.images[k]);
    free(s.images);
    free(s.textures);
}

/* dr_texture8_rgb (one texture for all lanes, any storage and channel
 * count: the environment map's lookup) against dr_texture_eval bit for bit,
 * every pair of wrap modes, both use_linear; lanes left out get 0. */
static void test_any_image(void)
{
    struct rng r = {99};
    long compared = 0, differ = 0, left = 0;
    for (int kind = 0; kind < 12; kind++) {
        const int c = 1 + kind % 4, w = 1 + (int)(rng_next(&r) * 40.0), h = 1 + (int)(rng_next(&r) * 20.0);
        struct dr_image img = kind < 4 ? image8(&r, w, h, c, false) : image_float(&r, w, h, c, kind >= 8);
        for (int ws = 0; ws < 3; ws++)
            for (int wt = 0; wt < 3; wt++) {
                const struct dr_texture tex = {0, (enum dr_wrap)ws, (enum dr_wrap)wt};
                for (int call = 0; call < 400; call++) {
                    const bool use_linear = call % 2;
                    dr_m8 on;
                    dr_f8 u, v;
                    for (int i = 0; i < DR_SIMD_W; i++) {
                        on[i] = rng_next(&r) < 0.85 ? -1 : 0;
                        u[i] = coord(&r, w);
                        v[i] = coord(&r, h);
                    }
                    dr_v3x8 got = dr_texture8_rgb(&tex, &img, on, u, v, use_linear);
                    for (int i = 0; i < DR_SIMD_W; i++) {
                        double px[4] = {0.0, 0.0, 0.0, 0.0};
                        if (on[i])
                            dr_texture_eval(&tex, &img, u[i], v[i], use_linear, px);
                        bool same = same_bits(got.x[i], px[0]) && same_bits(got.y[i], px[1]) &&
                                    same_bits(got.z[i], px[2]);
                        if (!same && differ++ < 5)
                            CHECK(same, "%dx%dx%d %s image, wrap %d/%d, uv (%.17g, %.17g): (%.17g %.17g %.17g), "
                                  "the scalar lookup (%.17g %.17g %.17g)", w, h, c, img.bytes ? "eight-bit" : "float",
                                  ws, wt, u[i], v[i], got.x[i], got.y[i], got.z[i], px[0], px[1], px[2]);
                        compared += on[i] != 0;
                        left += !on[i];
                    }
                }
            }
        dr_image_release(&img);
    }
    CHECK(differ == 0, "%ld of %ld lanes differ from the scalar lookup", differ, compared);
    CHECK(compared > 200000 && left > 0, "only %ld lanes compared", compared);
}

int main(void)
{
    test_matches_scalar_lookup();
    test_any_image();
    return TEST_END();
}
