/* The walker's stages for eight lanes at once (path_simd.h). Each step names
 * the scalar function it mirrors; keep them in step when either changes
 * (test_render's bit-for-bit comparison fails otherwise). */
#include "path_simd.h"

#include <stddef.h>
#include <string.h>
#if defined(__AVX__)
#include <immintrin.h>   /* gather_vertex's loads */
#endif

#include "anisotropy.h"
#include "bsdf.h"
#include "cdf.h"
#include "env8.h"
#include "lights.h"
#include "material.h"
#include "coverage.h"
#include "normal_map.h"
#include "sampler8.h"
#include "simd_trig.h"
#include "texture8.h"

#define COS_EPS DR_BSDF_COS_EPS

/* ------------------------------------------------------- loads and stores */

/* The double at byte offset off of each lane's structure b[i]. */
DR_SIMD_INLINE dr_f8 gather(const void *const *b, size_t off)
{
#define G(i) (*(const double *)((const char *)b[i] + off))
    return (dr_f8){G(0), G(1), G(2), G(3), G(4), G(5), G(6), G(7)};
#undef G
}
DR_SIMD_INLINE dr_v3x8 gather3(const void *const *b, size_t off)
{
    return (dr_v3x8){gather(b, off), gather(b, off + sizeof(double)), gather(b, off + 2 * sizeof(double))};
}
/* Vertex vi[i]'s four floats (tangents: xyz and the handedness w) for each
 * lane, widened to double (exact). */
DR_SIMD_INLINE void gather_vertex4(const float *a, const uint32_t *vi, dr_f8 out[4])
{
#define G(i, c) (double)a[4 * (size_t)vi[i] + c]
#define V(c) (dr_f8){G(0, c), G(1, c), G(2, c), G(3, c), G(4, c), G(5, c), G(6, c), G(7, c)}
    out[0] = V(0), out[1] = V(1), out[2] = V(2), out[3] = V(3);
#undef V
#undef G
}
/* Vertex vi[i]'s two floats (texture coordinates) for each lane, into u
 * and v. With AVX-512 each pair is read as one 64-bit word, the eight words
 * widened to doubles in two halves and split into u and v by two-source
 * permutes: 8 loads and 6 shuffles instead of 16 scalar loads, conversions
 * and inserts (texcoords was 2.6 % of a textured render). Exact: float to
 * double is. */
DR_SIMD_INLINE void gather_pair(const float *a, const uint32_t *vi, dr_f8 *u, dr_f8 *v)
{
#if defined(__AVX512F__)
    long long w[DR_SIMD_W];
    for (int i = 0; i < DR_SIMD_W; i++)
        memcpy(&w[i], a + 2 * (size_t)vi[i], sizeof w[i]);
    const __m512i words = _mm512_set_epi64(w[7], w[6], w[5], w[4], w[3], w[2], w[1], w[0]);
    const __m512d lo = _mm512_cvtps_pd(_mm256_castsi256_ps(_mm512_castsi512_si256(words)));   /* u0 v0 .. u3 v3 */
    const __m512d hi = _mm512_cvtps_pd(_mm256_castsi256_ps(_mm512_extracti64x4_epi64(words, 1)));
    *u = (dr_f8)_mm512_permutex2var_pd(lo, _mm512_setr_epi64(0, 2, 4, 6, 8, 10, 12, 14), hi);
    *v = (dr_f8)_mm512_permutex2var_pd(lo, _mm512_setr_epi64(1, 3, 5, 7, 9, 11, 13, 15), hi);
#else
#define G(i, c) (double)a[2 * (size_t)vi[i] + c]
#define V(c) (dr_f8){G(0, c), G(1, c), G(2, c), G(3, c), G(4, c), G(5, c), G(6, c), G(7, c)}
    *u = V(0), *v = V(1);
#undef V
#undef G
#endif
}
/* Element k * stride + c of array a for each lane's index k[i]. */
DR_SIMD_INLINE dr_f8 gather_at(const double *a, const int64_t *k, int stride, int c)
{
#define G(i) a[(size_t)k[i] * (size_t)stride + (size_t)c]
    return (dr_f8){G(0), G(1), G(2), G(3), G(4), G(5), G(6), G(7)};
#undef G
}
/* Vertex vi[i]'s three floats (positions, normals) for each lane. The
 * arrays carry a padding float after the last vertex, so each vertex can be
 * read as four floats: with AVX (and not AVX-512, whose registers hold the
 * eight lanes), eight such loads widened to doubles and transposed, 4 x 4
 * at a time, instead of 72 scalar loads and inserts (the gathers were a
 * seventh of the shading kernel). Exact: float to double is. */
#if defined(__AVX__) && !defined(__AVX512F__)
DR_SIMD_INLINE void transpose_rows(const __m256d r[4], __m256d *x, __m256d *y, __m256d *z)
{
    __m256d t0 = _mm256_unpacklo_pd(r[0], r[1]), t1 = _mm256_unpackhi_pd(r[0], r[1]);   /* x0 x1 z0 z1, y0 y1 . . */
    __m256d t2 = _mm256_unpacklo_pd(r[2], r[3]), t3 = _mm256_unpackhi_pd(r[2], r[3]);
    *x = _mm256_permute2f128_pd(t0, t2, 0x20);
    *y = _mm256_permute2f128_pd(t1, t3, 0x20);
    *z = _mm256_permute2f128_pd(t0, t2, 0x31);
}
DR_SIMD_INLINE dr_v3x8 gather_vertex(const float *a, const uint32_t *vi)
{
    __m256d r[8];
    for (int i = 0; i < DR_SIMD_W; i++)
        r[i] = _mm256_cvtps_pd(_mm_loadu_ps(a + 3 * (size_t)vi[i]));
    union dr_f8_halves x, y, z;
    __m256d hx, hy, hz;
    for (int k = 0; k < 2; k++) {
        transpose_rows(r + 4 * k, &hx, &hy, &hz);
        x.h[k] = (dr_f4)hx, y.h[k] = (dr_f4)hy, z.h[k] = (dr_f4)hz;
    }
    return (dr_v3x8){x.v, y.v, z.v};
}
#elif defined(__AVX512F__)
/* With AVX-512: two vertices' four floats widened into one register, the
 * four such registers transposed by two-source permutes (x0..x3 y0..y3 from
 * a pair, then the pairs' halves joined): 8 loads and 11 shuffles, where the
 * lane-by-lane initialiser below compiled to 24 scalar loads, conversions
 * and inserts (its line was the shading's hottest, 2.4 % of a peer-box
 * render). Exact as above. */
DR_SIMD_INLINE dr_v3x8 gather_vertex(const float *a, const uint32_t *vi)
{
    __m512d r[4];   /* r[k]: x y z w of vertex 2k, then of vertex 2k + 1 */
    for (int k = 0; k < 4; k++)
        r[k] = _mm512_cvtps_pd(_mm256_set_m128(_mm_loadu_ps(a + 3 * (size_t)vi[2 * k + 1]),
                                               _mm_loadu_ps(a + 3 * (size_t)vi[2 * k])));
    const __m512i xy = _mm512_set_epi64(13, 9, 5, 1, 12, 8, 4, 0);    /* x of 4 vertices, then y */
    const __m512i zw = _mm512_set_epi64(15, 11, 7, 3, 14, 10, 6, 2);  /* z, then w */
    __m512d xy01 = _mm512_permutex2var_pd(r[0], xy, r[1]), xy23 = _mm512_permutex2var_pd(r[2], xy, r[3]);
    __m512d zw01 = _mm512_permutex2var_pd(r[0], zw, r[1]), zw23 = _mm512_permutex2var_pd(r[2], zw, r[3]);
    return (dr_v3x8){(dr_f8)_mm512_shuffle_f64x2(xy01, xy23, 0x44), (dr_f8)_mm512_shuffle_f64x2(xy01, xy23, 0xEE),
                     (dr_f8)_mm512_shuffle_f64x2(zw01, zw23, 0x44)};
}
#else
DR_SIMD_INLINE dr_v3x8 gather_vertex(const float *a, const uint32_t *vi)
{
#define G(i, c) (double)a[3 * (size_t)vi[i] + c]
#define V(c) (dr_f8){G(0, c), G(1, c), G(2, c), G(3, c), G(4, c), G(5, c), G(6, c), G(7, c)}
    return (dr_v3x8){V(0), V(1), V(2)};
#undef V
#undef G
}
#endif
DR_SIMD_INLINE dr_m8 mask_of(const bool *b)
{
    return dr_m8_from_bools(b);
}

/* Each lane's hit and material, and the light sample's triangle and entry. */
struct lanes {
    const void *mat[DR_SIMD_W], *lmat[DR_SIMD_W];
    int64_t tri[DR_SIMD_W], ltri[DR_SIMD_W];
    uint32_t v0[DR_SIMD_W], v1[DR_SIMD_W], v2[DR_SIMD_W];
    bool double_sided[DR_SIMD_W], ldouble_sided[DR_SIMD_W], has_normals[DR_SIMD_W];
    /* Textures: the eight-lane lookups' texrefs (texture8.h; NULL: none), and
     * where the scalar functions read them lane by lane, from a scalar hit */
    const struct dr_texref *base_tex[DR_SIMD_W], *mr_tex[DR_SIMD_W], *emissive_tex[DR_SIMD_W];
    const struct dr_texref *normal_tex[DR_SIMD_W];      /* (normal_map8's) */
    const struct dr_texref *lemissive_tex[DR_SIMD_W];   /* the light's */
    const struct dr_texref *coat_tex[2][DR_SIMD_W];     /* the coat's and its roughness's (coat_eval) */
    bool any_tex8, any_ltex8, any_normal8, any_coat_tex8;
    bool coated[DR_SIMD_W], any_coated;   /* the material has a clear coat */
    bool textured[DR_SIMD_W];         /* the scalar hit is needed (mat_textures' scalar_hit) */
    bool scalar_material[DR_SIMD_W];  /* dr_material_eval reads the BSDF's textures */
    bool scalar_emission[DR_SIMD_W];  /* dr_emission reads the emissive texture */
    bool ltextured[DR_SIMD_W];        /* the light's emissive texture is dr_emission's */
    bool normal_mapped[DR_SIMD_W];    /* the material has a normal map (eight-lane or scalar) */
    bool anisotropic[DR_SIMD_W], any_anisotropic;   /* the material is (dr_material.anisotropic) */
    bool aniso_scalar[DR_SIMD_W];     /* ... read lane by lane (scalar_material: dr_material_eval and
                                         dr_anisotropy_frame on the scalar hit); the others eight wide
                                         (anisotropy8), any_aniso8 */
    bool any_aniso8;
    const struct dr_texref *aniso_tex[DR_SIMD_W];   /* (anisotropy8's eight-lane lookup; NULL: none) */
    bool no_direction[DR_SIMD_W];     /* the surface gives no direction here (dr_anisotropy_frame) */
    bool sheened[DR_SIMD_W], any_sheened;   /* the material has a sheen (shaded lane by lane: dr_path8.sheen_bsdf) */
    bool may_emit[DR_SIMD_W];         /* the material's factor x strength is not black */
    bool any_textured, any_ltextured;
    struct dr_hit hit[DR_SIMD_W];   /* the hits of textured lanes, as dr_hit_compute fills them */
    uint32_t dim[DR_SIMD_W];   /* the vertex's first sampler dimension */
};

DR_SIMD_INLINE void set_lane(dr_v3x8 *a, int i, dr_vec3 v)
{
    a->x[i] = v.x, a->y[i] = v.y, a->z[i] = v.z;
}

/* ------------------------------------------------------------ the maths */

/* b0 a0 + b1 a1 + b2 a2 per coordinate, as attributes() and dr_hit_at. */
DR_SIMD_INLINE dr_v3x8 interp(dr_f8 b0, dr_f8 b1, dr_f8 b2, dr_v3x8 a0, dr_v3x8 a1, dr_v3x8 a2)
{
    return (dr_v3x8){b0 * a0.x + b1 * a1.x + b2 * a2.x, b0 * a0.y + b1 * a1.y + b2 * a2.y,
                     b0 * a0.z + b1 * a1.z + b2 * a2.z};
}

/* dr_mis_power */
DR_SIMD_INLINE dr_f8 mis_power(dr_f8 a, dr_f8 b)
{
    dr_m8 a_pos = dr_f8_gt(a, dr_f8s(0.0));
    dr_f8 r = b / dr_f8_sel(a_pos, a, dr_f8s(1.0));
    dr_f8 w = dr_f8_sel(dr_f8_gt(b, dr_f8s(0.0)), 1.0 / (1.0 + r * r), dr_f8s(1.0));
    return dr_f8_sel(a_pos, w, dr_f8s(0.0));
}

/* dr_offset_origin: p + ng (d . ng >= 0 ? eps : -eps) */
DR_SIMD_INLINE dr_v3x8 offset_origin(dr_v3x8 p, dr_v3x8 ng, dr_f8 eps, dr_v3x8 d)
{
    return dr_v3x8_madd(p, ng, dr_f8_sel(dr_f8_ge(dr_v3x8_dot(d, ng), dr_f8s(0.0)), eps, -eps));
}

/* dr_frame_from_normal and dr_frame_to_local / _to_world */
DR_SIMD_INLINE void frame_from_normal(dr_v3x8 n, dr_v3x8 *s, dr_v3x8 *t)
{
    dr_f8 sign = dr_f8_sign1(n.z);
    dr_f8 a = -1.0 / (sign + n.z);
    dr_f8 b = n.x * n.y * a;
    *s = (dr_v3x8){1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x};
    *t = (dr_v3x8){b, sign + n.y * n.y * a, -n.y};
}
DR_SIMD_INLINE dr_v3x8 to_local(dr_v3x8 s, dr_v3x8 t, dr_v3x8 n, dr_v3x8 v)
{
    return (dr_v3x8){dr_v3x8_dot(v, s), dr_v3x8_dot(v, t), dr_v3x8_dot(v, n)};
}
DR_SIMD_INLINE dr_v3x8 to_world(dr_v3x8 s, dr_v3x8 t, dr_v3x8 n, dr_v3x8 v)
{
    return dr_v3x8_add(dr_v3x8_add(dr_v3x8_scale(s, v.x), dr_v3x8_scale(t, v.y)), dr_v3x8_scale(n, v.z));
}

/* bsdf.c's sample_cosine: the concentric disk, lifted. */
DR_SIMD_INLINE dr_v3x8 sample_cosine(dr_f8 u1, dr_f8 u2)
{
    dr_f8 a = 2.0 * u1 - 1.0, c = 2.0 * u2 - 1.0;
    dr_m8 centre = dr_f8_eq(a, dr_f8s(0.0)) & dr_f8_eq(c, dr_f8s(0.0));
    dr_m8 wide = dr_f8_gt(dr_f8_abs(a), dr_f8_abs(c));
    dr_f8 r = dr_f8_sel(wide, a, c);
    dr_f8 t = (M_PI / 4.0) * (dr_f8_sel(wide, c, a) / dr_f8_sel(centre, dr_f8s(1.0), r));
    dr_f8 t2 = t * t;
    dr_f8 sn = t + t * t2 * dr_f8_horner(t2, DR_SIN_SERIES, 8);
    dr_f8 cs = 1.0 - t2 * dr_f8_horner(t2, DR_COS_SERIES, 9);
    dr_f8 x = dr_f8_sel(wide, cs, sn) * r, y = dr_f8_sel(wide, sn, cs) * r;
    dr_f8 z = dr_f8_sqrt(dr_f8_max(dr_f8s(0.0), 1.0 - x * x - y * y));
    return dr_v3x8_sel(centre, (dr_v3x8){dr_f8s(0.0), dr_f8s(0.0), dr_f8s(1.0)}, (dr_v3x8){x, y, z});
}

/* -------------------------------------------------------------- the BSDF */

/* bsdf.c's helpers */
DR_SIMD_INLINE dr_f8 pow5(dr_f8 s)
{
    dr_f8 s2 = s * s;
    return s2 * s2 * s;
}
DR_SIMD_INLINE dr_f8 max3(dr_v3x8 a) { return dr_f8_max(a.x, dr_f8_max(a.y, a.z)); }
DR_SIMD_INLINE dr_f8 luminance(dr_v3x8 c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }
DR_SIMD_INLINE dr_f8 smith_lambda(dr_f8 a2, dr_v3x8 w)
{
    dr_f8 x = a2 * (w.x * w.x + w.y * w.y) / (w.z * w.z);
    return 0.5 * x / (1.0 + dr_f8_sqrt(1.0 + x));
}
DR_SIMD_INLINE dr_v3x8 normalize(dr_v3x8 a)   /* dr_normalize */
{
    dr_f8 l = dr_f8_sqrt(dr_v3x8_dot(a, a));
    dr_m8 pos = dr_f8_gt(l, dr_f8s(0.0));
    return dr_v3x8_sel(pos, dr_v3x8_scale(a, 1.0 / dr_f8_sel(pos, l, dr_f8s(1.0))), a);
}

/* dielectric_f0 of a layer with specular colour sc and weight specular */
DR_SIMD_INLINE dr_v3x8 dielectric_f0(dr_v3x8 sc, dr_f8 specular)
{
    return (dr_v3x8){dr_f8_min(0.04 * sc.x, dr_f8s(1.0)) * specular, dr_f8_min(0.04 * sc.y, dr_f8s(1.0)) * specular,
                     dr_f8_min(0.04 * sc.z, dr_f8s(1.0)) * specular};
}
/* bsdf_alpha of roughness r */
DR_SIMD_INLINE dr_f8 bsdf_alpha(dr_f8 r)
{
    dr_f8 a = r * r;
    return dr_f8_sel(dr_f8_gt(a, dr_f8s(DR_BSDF_MIN_ALPHA)), a, dr_f8s(DR_BSDF_MIN_ALPHA));
}

/* The clear coat's inputs (dr_material_eval's last step: the factors times
 * the R and G of their textures) and bsdf_coat.c's coat_lobe; coat 0 on
 * the lanes without one, so that its share of the samples is 0 there. */
static void coat_eval(const struct dr_scene *s, struct dr_path8 *g, const struct lanes *L, dr_m8 end,
                      const struct dr_uv8 *uv, const double *lane_coat, const double *lane_coat_r)
{
    const void *const *mat = L->mat;
    dr_f8 c = gather(mat, offsetof(struct dr_material, coat));
    dr_f8 r = gather(mat, offsetof(struct dr_material, coat_roughness));
    if (L->any_coat_tex8) {
        c = c * dr_texref8_rgb(s, L->coat_tex[0], ~end, uv, false).x;
        r = r * dr_texref8_rgb(s, L->coat_tex[1], ~end, uv, false).y;
    }
    for (int i = 0; L->any_textured && i < g->n; i++)
        if (L->scalar_material[i] && !end[i])   /* (material_eval's dr_material_eval) */
            c[i] = lane_coat[i], r[i] = lane_coat_r[i];
    g->coat_on = mask_of(L->coated);
    const dr_f8 zero = dr_f8s(0.0);
    g->coat = dr_f8_sel(g->coat_on, c, zero);
    g->coat_roughness = dr_f8_sel(g->coat_on, r, zero);
    g->coat_lobe = (struct dr_lobe8){.base = {zero, zero, zero}, .metallic = zero, .specular = dr_f8s(1.0),
                                     .alpha = bsdf_alpha(g->coat_roughness)};
    g->coat_lobe.alpha_x = g->coat_lobe.alpha;   /* (isotropic) */
    g->coat_lobe.f0 = dielectric_f0((dr_v3x8){dr_f8s(1.0), dr_f8s(1.0), dr_f8s(1.0)}, g->coat_lobe.specular);
}

/* Lane i's dr_material_eval record from the vectors (material_eval's and
 * coat_eval's, which hold its bits) where the scalar code did not make it:
 * the groups keep its fields but an uncoated material's coat factors (read
 * by nothing, copied as it copies them) and a sheen without textures (its
 * factors, as it copies them). */
static struct dr_bsdf lane_record(const struct dr_path8 *g, int i, const struct dr_material *m)
{
    return (struct dr_bsdf){.base_color = dr_v3x8_get(&g->b.base, i), .metallic = g->b.metallic[i],
                            .roughness = g->roughness[i], .specular = g->b.specular[i],
                            .specular_color = dr_v3x8_get(&g->specular_color, i), .coated = m->coated,
                            .coat = m->coated ? g->coat[i] : m->coat,
                            .coat_roughness = m->coated ? g->coat_roughness[i] : m->coat_roughness,
                            .anisotropy = g->anisotropy[i], .sheened = m->sheened, .sheen_color = m->sheen_color,
                            .sheen_roughness = m->sheen_roughness};
}

/* dr_material_eval (the factors times the textures at the coordinates uv,
 * times the vertex colour; lanes with a texture texture8.h does not read
 * call it), and what bsdf.c derives from the material alone (bsdf_alpha,
 * dielectric_f0, no_specular_lobe). */
static void material_eval(const struct dr_scene *s, struct dr_path8 *g, const struct lanes *L, dr_m8 end,
                          const dr_v3x8 *colour, const struct dr_uv8 *uv, dr_f8 aniso)
{
    const void *const *mat = L->mat;
    struct dr_lobe8 *b = &g->b;
    b->base = gather3(mat, offsetof(struct dr_material, base_color));
    b->metallic = gather(mat, offsetof(struct dr_material, metallic));
    b->specular = gather(mat, offsetof(struct dr_material, specular));
    /* the specular colour: gathered here where the scalar lanes or a
     * differentiated vertex's record read it, else only for a glossy f0 */
    const bool colour_now = L->any_textured || dr_m8_any(g->diff) || L->any_sheened;
    dr_v3x8 spec_colour = b->base;
    if (colour_now)
        spec_colour = gather3(mat, offsetof(struct dr_material, specular_color));
    dr_f8 r = gather(mat, offsetof(struct dr_material, roughness));
    if (L->any_tex8) {   /* factor x texture (1 where a lane has none), in dr_material_eval's order */
        b->base = dr_v3x8_mul(b->base, dr_texref8_rgb(s, L->base_tex, ~end, uv, true));
        dr_v3x8 mr = dr_texref8_rgb(s, L->mr_tex, ~end, uv, false);
        r = r * mr.y;
        b->metallic = b->metallic * mr.z;
    }
    if (colour)   /* times COLOR_0 (scalar_material lanes: dr_material_eval's, below) */
        b->base = dr_v3x8_mul(b->base, *colour);
    double lane_coat[DR_SIMD_W], lane_coat_r[DR_SIMD_W];   /* (aniso: anisotropy8's, 0 elsewhere) */
    for (int i = 0; L->any_textured && i < g->n; i++)
        if (L->scalar_material[i] && !end[i]) {   /* textures (and the vertex colour): dr_material_eval itself */
            struct dr_bsdf lb;
            dr_material_eval(s, &L->hit[i], &lb);
            set_lane(&b->base, i, lb.base_color);
            b->metallic[i] = lb.metallic;
            b->specular[i] = lb.specular;   /* (times KHR_materials_specular's textures) */
            set_lane(&spec_colour, i, lb.specular_color);
            r[i] = lb.roughness;
            lane_coat[i] = lb.coat, lane_coat_r[i] = lb.coat_roughness;
            aniso[i] = L->no_direction[i] ? 0.0 : lb.anisotropy;   /* (stage_material's fallback) */
            if (L->sheened[i]) {   /* (the record the scalar functions shade this lane with: a sheen's textures) */
                lb.anisotropy = aniso[i];
                g->sheen_bsdf[i] = lb;
            }
        }
    g->any_sheen = L->any_sheened;
    g->sheen_on = L->any_sheened ? mask_of(L->sheened) & ~end : (dr_m8){0};
    g->anisotropy = aniso;
    g->roughness = r;   /* (a differentiated vertex's dr_bsdf: dr_path8_shade) */
    g->specular_color = spec_colour;   /* (read for differentiated lanes only: gathered then) */
    g->coated = L->any_coated;
    if (g->coated)
        coat_eval(s, g, L, end, uv, lane_coat, lane_coat_r);
    for (int i = 0; L->any_sheened && i < g->n; i++)   /* (the rest: dr_material_eval's record, above) */
        if (L->sheened[i] && !L->scalar_material[i] && !end[i])
            g->sheen_bsdf[i] = lane_record(g, i, L->mat[i]);
    g->lambert = dr_f8_eq(b->metallic, dr_f8s(0.0)) & dr_f8_eq(b->specular, dr_f8s(0.0));
    g->glossy = dr_m8_any(~g->lambert);
    b->any_aniso = false;
    b->aniso = (dr_m8){0};
    if (!g->glossy) {   /* (spec_p is 0: alpha is read, not used, by bsdf_sample and sky_share) */
        b->alpha = b->alpha_x = dr_f8s(1.0);
        return;
    }
    b->alpha = b->alpha_x = bsdf_alpha(r);
    if (L->any_anisotropic) {   /* bsdf.c's alpha_x_of on the stretched lanes */
        b->aniso = ~dr_f8_eq(aniso, dr_f8s(0.0));
        b->any_aniso = dr_m8_any(b->aniso);
        b->alpha_x = dr_f8_sel(b->aniso, b->alpha + (1.0 - b->alpha) * (aniso * aniso), b->alpha);
    }
    b->f0 = dielectric_f0(colour_now ? spec_colour : gather3(mat, offsetof(struct dr_material, specular_color)),
                          b->specular);
}

/* specular_prob_glossy of layer b, 0 on the lanes without a specular lobe
 * (lambert) */
DR_SIMD_INLINE dr_f8 specular_prob(const struct dr_lobe8 *b, dr_m8 lambert, dr_f8 cos_o)
{
    dr_f8 m = b->metallic;
    dr_f8 s5 = pow5(1.0 - dr_f8_clamp(cos_o, 0.0, 1.0));
    dr_f8 f0max = max3(b->f0);
    dr_f8 fd = f0max + (b->specular - f0max) * s5;
    dr_v3x8 c = b->base;
    dr_v3x8 fm = {c.x + (1.0 - c.x) * s5, c.y + (1.0 - c.y) * s5, c.z + (1.0 - c.z) * s5};
    dr_f8 w_spec = (1.0 - m) * fd + m * luminance(fm);
    dr_f8 w_diff = (1.0 - m) * (1.0 - fd) * luminance(c);
    dr_f8 p = w_spec / (w_spec + w_diff);
    p = dr_f8_sel(dr_f8_gt(w_spec, dr_f8s(0.0)), p, dr_f8s(0.0));
    p = dr_f8_sel(dr_f8_gt(w_diff, dr_f8s(0.0)), p, dr_f8s(1.0));
    return dr_f8_sel(lambert, dr_f8s(0.0), p);
}

/* bsdf.c's smith_lambda_aniso and ggx_aniso, the same operations: the
 * stretched lobe's D, |H|^2 and Lambdas, put on the lanes of b->aniso. */
DR_SIMD_INLINE dr_f8 smith_lambda_aniso(dr_f8 ax, dr_f8 ay, dr_v3x8 w)
{
    dr_f8 iz2 = 1.0 / (w.z * w.z);
    dr_f8 tx = w.x * w.x * iz2, ty = w.y * w.y * iz2;
    dr_f8 x = ax * ax * tx + ay * ay * ty, sq = dr_f8_sqrt(1.0 + x);
    return 0.5 * x / (1.0 + sq);
}
DR_SIMD_INLINE void stretched_lanes(const struct dr_lobe8 *b, dr_v3x8 H, dr_v3x8 wo, dr_v3x8 wi, dr_f8 *D, dr_f8 *H2,
                                    dr_f8 *lo, dr_f8 *li)
{
    const dr_f8 ax = b->alpha_x, ay = b->alpha;
    dr_f8 hx2 = H.x * H.x, hy2 = H.y * H.y, hz2 = H.z * H.z;
    dr_f8 h2 = hx2 + hy2 + hz2;
    dr_f8 q = hx2 * (ay / ax) + hy2 * (ax / ay) + ax * ay * hz2;
    dr_f8 r = h2 / q;
    *D = dr_f8_sel(b->aniso, ax * ay * r * r * DR_INV_PI, *D);
    *H2 = dr_f8_sel(b->aniso, h2, *H2);
    *lo = dr_f8_sel(b->aniso, smith_lambda_aniso(ax, ay, wo), *lo);
    *li = dr_f8_sel(b->aniso, smith_lambda_aniso(ax, ay, wi), *li);
}

/* eval_pdf_glossy of layer b */
DR_SIMD_INLINE dr_v3x8 eval_pdf_glossy(const struct dr_lobe8 *b, dr_v3x8 wo, dr_v3x8 wi, dr_f8 p, dr_f8 *pdf)
{
    dr_f8 cos_pdf = wi.z * DR_INV_PI;
    dr_f8 a = b->alpha, a2 = a * a;
    dr_v3x8 H = dr_v3x8_add(wo, wi);
    dr_f8 hxy2 = H.x * H.x + H.y * H.y;
    dr_f8 H2 = hxy2 + H.z * H.z;
    dr_f8 q = hxy2 + a2 * H.z * H.z;
    dr_f8 r = H2 / q;
    dr_f8 D = a2 * r * r * DR_INV_PI;
    dr_f8 lo = smith_lambda(a2, wo), li = smith_lambda(a2, wi);
    if (b->any_aniso)
        stretched_lanes(b, H, wo, wi, &D, &H2, &lo, &li);
    dr_f8 dq = D / (4.0 * wo.z);
    dr_f8 pdf_spec = dq / (1.0 + lo);
    dr_f8 spec = dq / ((1.0 + lo + li) * wi.z);
    *pdf = (1.0 - p) * cos_pdf + p * pdf_spec;

    dr_f8 c = 0.5 * dr_f8_sqrt(H2);
    dr_f8 s5 = pow5(1.0 - dr_f8_clamp(c, 0.0, 1.0));
    dr_f8 m = b->metallic;
    dr_v3x8 f0 = b->f0, base = b->base;
    dr_f8 f90 = b->specular;
    dr_v3x8 fd = {f0.x + (f90 - f0.x) * s5, f0.y + (f90 - f0.y) * s5, f0.z + (f90 - f0.z) * s5};
    dr_v3x8 fm = {base.x + (1.0 - base.x) * s5, base.y + (1.0 - base.y) * s5, base.z + (1.0 - base.z) * s5};
    dr_f8 f0max = max3(f0);
    dr_f8 fo = f0max + (f90 - f0max) * pow5(1.0 - wo.z), fi = f0max + (f90 - f0max) * pow5(1.0 - wi.z);
    dr_f8 kd = (1.0 - m) * dr_f8_max(dr_f8s(0.0), 1.0 - fo) * dr_f8_max(dr_f8s(0.0), 1.0 - fi) * DR_INV_PI;
    dr_f8 ks = (1.0 - m) * spec, km = m * spec;
    return (dr_v3x8){base.x * kd + fd.x * ks + fm.x * km, base.y * kd + fd.y * ks + fm.y * km,
                     base.z * kd + fd.z * ks + fm.z * km};
}

/* bsdf.c's eval_pdf_above of the base layer: wo.z, wi.z > COS_EPS, with
 * its specular_prob spec_p */
DR_SIMD_INLINE dr_v3x8 eval_pdf_base(const struct dr_path8 *g, dr_v3x8 wo, dr_v3x8 wi, dr_f8 *pdf)
{
    dr_f8 pdf_l = wi.z * DR_INV_PI;
    dr_v3x8 f_l = dr_v3x8_scale(g->b.base, dr_f8s(DR_INV_PI));
    if (!g->glossy) {
        *pdf = pdf_l;
        return f_l;
    }
    dr_f8 pdf_g;
    dr_v3x8 f_g = eval_pdf_glossy(&g->b, wo, wi, g->spec_p, &pdf_g);
    *pdf = dr_f8_sel(g->lambert, pdf_l, pdf_g);
    return dr_v3x8_sel(g->lambert, f_l, f_g);
}

/* bsdf_coat.c's Fresnel of the coat (Schlick, f0 0.04) at cosine x */
DR_SIMD_INLINE dr_f8 coat_fresnel(dr_f8 x)
{
    return 0.04 + 0.96 * pow5(1.0 - dr_f8_clamp(x, 0.0, 1.0));
}

/* The sheen over the base on the sheened lanes: fb and pdf, the base's
 * (eight-wide: the bits of the scalar base's), become dr_bsdf_eval_pdf's
 * of the sheened record without its coat, by bsdf.h's dr_sheen_layer_*
 * (the sheen's own terms lane by lane, the composition the scalar one's);
 * 0 where wo or wi is at or below the surface, as there. */
static void __attribute__((noinline)) sheen_layer(const struct dr_path8 *g, dr_v3x8 wo, dr_v3x8 wi, dr_v3x8 *fb,
                                                  dr_f8 *pdf)
{
    for (int i = 0; i < DR_SIMD_W; i++) {
        if (!g->sheen_on[i])
            continue;
        const dr_vec3 o = dr_v3x8_get(&wo, i), in = dr_v3x8_get(&wi, i);
        if (!(o.z > COS_EPS) || !(in.z > COS_EPS)) {
            set_lane(fb, i, dr_v3s(0.0));
            (*pdf)[i] = 0.0;
            continue;
        }
        const struct dr_sheen_layer l = dr_sheen_layer_at(&g->sheen_bsdf[i], o, in);
        set_lane(fb, i, dr_sheen_layer_f(&l, dr_v3x8_get(fb, i)));
        (*pdf)[i] = dr_sheen_layer_pdf(&l, in, (*pdf)[i]);
    }
}

/* dr_bsdf_eval_pdf for wo.z, wi.z > COS_EPS: the base's (eval_pdf_base),
 * under the sheen on sheened lanes (sheen_layer), and on coated lanes
 * dr_coat_eval_pdf's composition of that with the coat's lobe (whose
 * specular_prob is 1: no diffuse part), in its order. */
DR_SIMD_INLINE dr_v3x8 eval_pdf_above(const struct dr_path8 *g, dr_v3x8 wo, dr_v3x8 wi, dr_f8 *pdf)
{
    dr_f8 pb;
    dr_v3x8 fb = eval_pdf_base(g, wo, wi, &pb);
    if (g->any_sheen)
        sheen_layer(g, wo, wi, &fb, &pb);
    if (!g->coated) {
        *pdf = pb;
        return fb;
    }
    dr_f8 pl;
    const dr_v3x8 fl = eval_pdf_glossy(&g->coat_lobe, wo, wi, dr_f8s(1.0), &pl);
    const dr_f8 c = g->coat, tt = (1.0 - c * coat_fresnel(wo.z)) * (1.0 - c * coat_fresnel(wi.z));
    const dr_f8 p = g->coat_p;
    *pdf = dr_f8_sel(g->coat_on, p * pl + (1.0 - p) * pb, pb);
    const dr_v3x8 f = {fb.x * tt + fl.x * c, fb.y * tt + fl.y * c, fb.z * tt + fl.z * c};
    return dr_v3x8_sel(g->coat_on, f, fb);
}

/* sample_specular_dir: GGX visible normals (sample_vndf) of alphas (ax, ay),
 * reflected; the azimuth's cosine and sine from dr_f8_sincos_turn, as in
 * the scalar map. */
DR_SIMD_INLINE dr_v3x8 sample_specular_dir(dr_f8 ax, dr_f8 ay, dr_v3x8 wo, dr_f8 u1, dr_f8 u2)
{
    dr_v3x8 vh = normalize((dr_v3x8){ax * wo.x, ay * wo.y, wo.z});
    dr_f8 lensq = vh.x * vh.x + vh.y * vh.y;
    dr_m8 tilted = dr_f8_gt(lensq, dr_f8s(0.0));
    dr_f8 k = 1.0 / dr_f8_sqrt(dr_f8_sel(tilted, lensq, dr_f8s(1.0)));
    dr_v3x8 t1 = dr_v3x8_sel(tilted, (dr_v3x8){-vh.y * k, vh.x * k, 0.0 * k},
                             (dr_v3x8){dr_f8s(1.0), dr_f8s(0.0), dr_f8s(0.0)});
    dr_v3x8 t2 = dr_v3x8_cross(vh, t1);
    dr_f8 r = dr_f8_sqrt(u1), cos_phi, sin_phi;
    dr_f8_sincos_turn(u2, &sin_phi, &cos_phi);   /* phi = 2 pi u2 */
    dr_f8 p1 = r * cos_phi, p2 = r * sin_phi;
    dr_f8 s = 0.5 * (1.0 + vh.z);
    dr_f8 c = dr_f8_sqrt(dr_f8_max(dr_f8s(0.0), 1.0 - p1 * p1));
    dr_f8 p2s = (1.0 - s) * c + s * p2;
    dr_f8 n3 = dr_f8_sqrt(dr_f8_max(dr_f8s(0.0), 1.0 - p1 * p1 - p2s * p2s));
    dr_v3x8 nh = dr_v3x8_add(dr_v3x8_add(dr_v3x8_scale(t1, p1), dr_v3x8_scale(t2, p2s)), dr_v3x8_scale(vh, n3));
    dr_v3x8 h = normalize((dr_v3x8){ax * nh.x, ay * nh.y, dr_f8_max(dr_f8s(0.0), nh.z)});
    return dr_v3x8_sub(dr_v3x8_scale(h, 2.0 * dr_v3x8_dot(wo, h)), wo);
}

/* dr_bsdf_sample on the lanes of on (the continuation's, and next-event
 * estimation's of a constant sky): the lobe by u_lobe (dr_coat_sample's
 * choice: the coat's lobe below coat_p, else the base's lobes with u_lobe
 * rescaled, which is u_lobe itself where coat_p is 0), the local direction
 * *wi, its BSDF value and density; returns the lanes where wo and wi are
 * above the surface and the density is finite and positive. */
/* dr_sheen_pick_lobe on the sheened lanes of on (wo above the surface):
 * the lanes whose u_lobe falls below P(wo) take the sheen's lobe (*sheen),
 * the others' u_lobe is rescaled for the base's lobes, as there. */
static void __attribute__((noinline)) sheen_pick(const struct dr_path8 *g, dr_m8 on, dr_f8 *u_lobe, dr_m8 *sheen)
{
    for (int i = 0; i < DR_SIMD_W; i++)
        if (on[i] && g->sheen_on[i]) {
            const double p = dr_sheen_lobe_prob(&g->sheen_bsdf[i], dr_v3x8_get(&g->wo, i));
            if ((*u_lobe)[i] < p)
                (*sheen)[i] = -1;
            else   /* (p <= u_lobe < 1: 1 - p > 0) */
                (*u_lobe)[i] = ((*u_lobe)[i] - p) / (1.0 - p);
        }
}

/* dr_bsdf_sample on the lanes of on (the continuation's, and next-event
 * estimation's of a constant sky): the lobe by u_lobe (dr_coat_sample's
 * choice: the coat's lobe below coat_p, else, with u_lobe rescaled, the
 * sheen's below its P on sheened lanes (sheen_pick: the cosine map), else
 * the base's lobes with u_lobe rescaled again; a rescale by a share of 0
 * is u_lobe itself), the local direction *wi, its BSDF value and density;
 * returns the lanes where wo and wi are above the surface and the density
 * is finite and positive. */
DR_SIMD_INLINE dr_m8 bsdf_sample(const struct dr_path8 *g, dr_m8 on, dr_f8 u_lobe, dr_f8 u1, dr_f8 u2, dr_v3x8 *wi,
                                 dr_v3x8 *f, dr_f8 *pdf)
{
    dr_m8 ok = on & dr_f8_gt(g->wo_z, dr_f8s(COS_EPS));
    *wi = sample_cosine(u1, u2);
    dr_m8 coat = (dr_m8){0}, sheen = (dr_m8){0};
    if (g->coated) {
        coat = ok & dr_f8_lt(u_lobe, g->coat_p);
        u_lobe = (u_lobe - g->coat_p) / (1.0 - g->coat_p);
    }
    if (g->any_sheen && dr_m8_any(ok & ~coat & g->sheen_on))
        sheen_pick(g, ok & ~coat, &u_lobe, &sheen);
    dr_m8 specular = ok & ~coat & ~sheen & dr_f8_lt(u_lobe, g->spec_p);
    if (dr_m8_any(specular | coat))
        *wi = dr_v3x8_sel(specular | coat,
                          sample_specular_dir(dr_f8_sel(coat, g->coat_lobe.alpha, g->b.alpha_x),
                                              dr_f8_sel(coat, g->coat_lobe.alpha, g->b.alpha), g->wo, u1, u2),
                          *wi);
    ok &= dr_f8_gt(wi->z, dr_f8s(COS_EPS));
    *f = eval_pdf_above(g, g->wo, *wi, pdf);
    ok &= dr_f8_gt(*pdf, dr_f8s(0.0)) & dr_f8_lt(*pdf, dr_f8s(INFINITY));
    return ok;
}

/* ----------------------------------------------------------- eligibility */

/* The run's effects and stages are all the eight-lane stages' (whatever
 * its parameters); with `media`, media and dielectric boundaries too (the
 * caller hands each path that could enter a medium to the one-path walker:
 * dr_path8_applies_outside_media). */
static bool eight_lane_run(const struct dr_scene *s, const struct dr_path_opts *opts, bool media)
{
    /* (alphaMode MASK and BLEND: the surfaces a ray passes are Embree's
     * filters' business, which every query applies with the ray's coverage
     * key; the stages make the shadow rays' keys and test a light point,
     * light_sample) */
    const unsigned allowed = DR_FX_AREA_LIGHTS | DR_FX_PUNCTUAL_LIGHTS | DR_FX_ENV_CONSTANT | DR_FX_ENV_MAP |
                             DR_FX_SHADING_NORMALS | DR_FX_SINGLE_SIDED | DR_FX_SPECULAR | DR_FX_TEXTURES |
                             DR_FX_VERTEX_COLORS | DR_FX_NORMAL_MAPS | DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND |
                             DR_FX_THIN_TRANSMISSION | DR_FX_CLEARCOAT | DR_FX_ANISOTROPY | DR_FX_SHEEN;
    const unsigned media_fx = DR_FX_MEDIA | DR_FX_HETEROGENEOUS_MEDIA | DR_FX_DIELECTRIC_BOUNDARIES;
    const unsigned media_stages = DR_STAGE_MEDIA | DR_STAGE_DIELECTRIC;
    struct dr_light_tables t;
    return !(s->effects & ~(allowed | (media ? media_fx : 0))) && (opts->stages & DR_STAGE_NEE) &&
           !(opts->stages & (media ? 0 : media_stages)) && dr_light_tables(s->light_sampler, &t);
}

bool dr_path8_applies_outside_media(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    return !opts->params && eight_lane_run(s, opts, true);
}

bool dr_path8_applies(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    /* A light whose radiance has a parameter gives any vertex's emission or
     * next-event estimate a derivative term, whose inputs the vertices these
     * stages hand over carry only for the walkers that ask
     * (dr_path8_walks_apply: prb's walks, which need to know where the terms
     * are, and its replays, dr_wave_ops.light_terms). */
    const struct dr_param_set *ps = opts->params;
    return !(ps && (ps->radiance_active || ps->media_active)) && eight_lane_run(s, opts, false);
}

/* A dark emitter whose emission has a parameter: the one-path walker
 * counts its hits as emitting (path.c's surface_emits) where these stages
 * see no emitter; its radiance would be the same 0 but for an emission
 * whose factors cancel in the power weight, so such runs stay with the
 * scalar stages. */
static bool dark_emitter_param(const struct dr_scene *s, const struct dr_param_set *ps)
{
    for (int m = 0; ps && ps->radiance_active && m < s->n_materials; m++)
        if (ps->mat_emission_active[m] && !dr_light_material_emits(s->light_sampler, m))
            return true;
    return false;
}

bool dr_path8_walks_apply(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    const struct dr_param_set *ps = opts->params;
    if (!ps || !ps->radiance_active)
        return dr_path8_applies(s, opts);
    return !ps->media_active && eight_lane_run(s, opts, false) && !dark_emitter_param(s, ps);
}

bool dr_path8_walks_apply_outside_media(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    return eight_lane_run(s, opts, true) && !dark_emitter_param(s, opts->params);
}

/* A material with a BSDF parameter stays scalar: its vertex substitutes zero
 * channels (path.h) and has a derivative term (dr_path_vertex_has_derivative). */
bool dr_path8_hit(const struct dr_scene *s, const struct dr_path_opts *opts, int64_t tri)
{
    return tri >= 0 && !(opts->params && opts->params->mat_bsdf_active[s->mesh.material[tri]]);
}

/* Does shading a hit on material m read a texture (mat_textures says how). */
static bool reads_textures(const struct dr_material *m)
{
    return dr_material_sheen_tex(m, 0) || dr_material_sheen_tex(m, 1) || m->base_color_tex.texture >= 0 || m->metallic_roughness_tex.texture >= 0 || m->emissive_tex.texture >= 0 ||
           m->normal_tex.texture >= 0 || dr_material_coat_tex(m, 0) || dr_material_coat_tex(m, 1) ||
           dr_material_anisotropy_tex(m) || m->specular_tex.texture >= 0 || m->specular_color_tex.texture >= 0;
}

/* How the stages read material m's textures. The base colour, metallic-
 * roughness, clear coat and emissive textures that texture8.h accepts (any
 * image of up to four channels read through TEXCOORD_0 or _1: PNG and JPEG
 * files, float parameters) are looked up eight lanes at a time.
 * The rest (images of more channels, such as a five-channel EXR) go through
 * the scalar functions lane by lane, which read a scalar hit:
 * dr_material_eval for all BSDF textures when one is not accepted,
 * dr_emission for an emissive texture that is not. An anisotropy texture
 * texture8.h accepts is read eight lanes at a time (anisotropy8); one it does
 * not, with the material's other textures, by dr_material_eval and
 * dr_anisotropy_frame on the scalar hit. KHR_materials_specular's textures
 * (an alpha channel texture8.h does not read) make the material's lookups
 * dr_material_eval's. A normal map
 * texture8.h accepts is applied eight lanes at a time (normal_map8) where
 * the lane needs no scalar hit for the rest; otherwise dr_normal_map_apply
 * applies it to the scalar hit. */
struct mat_textures {
    const struct dr_texref *base, *mr, *emissive, *normal, *aniso;   /* the eight-lane lookups (NULL: none) */
    const struct dr_texref *coat[2];                         /* (dr_material_coat_tex's) */
    bool scalar_material, scalar_emission, scalar_hit;
};

static void mat_textures(const struct dr_scene *s, const struct dr_material *m, struct mat_textures *t)
{
    *t = (struct mat_textures){0};
    if (!reads_textures(m))
        return;
    const struct dr_texref *b = &m->base_color_tex, *mr = &m->metallic_roughness_tex, *e = &m->emissive_tex;
    const struct dr_texref *coat[2] = {dr_material_coat_tex(m, 0), dr_material_coat_tex(m, 1)};
    const struct dr_texref *aniso = dr_material_anisotropy_tex(m);
    t->scalar_material = (b->texture >= 0 && !dr_texref8_accepts(s, b)) ||
                         (mr->texture >= 0 && !dr_texref8_accepts(s, mr)) ||
                         (coat[0] && !dr_texref8_accepts(s, coat[0])) || (coat[1] && !dr_texref8_accepts(s, coat[1])) ||
                         (aniso && !dr_texref8_accepts(s, aniso)) || m->specular_tex.texture >= 0 ||
                         m->specular_color_tex.texture >= 0 || dr_material_sheen_tex(m, 0) ||
                         dr_material_sheen_tex(m, 1);
    if (!t->scalar_material) {
        t->base = b->texture >= 0 ? b : NULL;
        t->mr = mr->texture >= 0 ? mr : NULL;
        t->coat[0] = coat[0], t->coat[1] = coat[1];
        t->aniso = aniso;
    }
    if (e->texture >= 0)
        t->scalar_emission = !dr_texref8_accepts(s, e);
    if (e->texture >= 0 && !t->scalar_emission)
        t->emissive = e;
    t->scalar_hit = t->scalar_material || t->scalar_emission;
    if (m->normal_tex.texture >= 0 && !t->scalar_hit && dr_texref8_accepts(s, &m->normal_tex))
        t->normal = &m->normal_tex;
    else if (m->normal_tex.texture >= 0)
        t->scalar_hit = true;
}

bool dr_path8_reads_textures(const struct dr_scene *s, int64_t tri)
{
    return reads_textures(&s->materials[s->mesh.material[tri]]);
}

/* dr_hit_color for every lane at barycentrics (b1, b2): the same operations
 * (COLOR_0 has three floats a vertex and no padding: read lane by lane). */
static dr_v3x8 vertex_colours(const struct dr_mesh *m, const struct lanes *L, dr_f8 b1, dr_f8 b2)
{
    const uint32_t *v[3] = {L->v0, L->v1, L->v2};
    dr_v3x8 c[3];
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < DR_SIMD_W; i++) {
            const float *p = m->colors + 3 * (size_t)v[k][i];
            c[k].x[i] = p[0], c[k].y[i] = p[1], c[k].z[i] = p[2];
        }
    return interp(1.0 - b1 - b2, b1, b2, c[0], c[1], c[2]);
}

/* TEXCOORD_0 and _1 at barycentrics (b1, b2) of each lane's triangle tri[i]
 * (vertices v0..v2). Set 0: the sums of attributes() and dr_hit_at, 0 where
 * the triangle has none; set 1: dr_hit_uv1's, read only where the mesh has
 * the set (some texture reads it), 0 elsewhere, as there. */
static void texcoords(const struct dr_mesh *m, const int64_t *tri, const uint32_t *v0, const uint32_t *v1,
                      const uint32_t *v2, dr_f8 b1, dr_f8 b2, struct dr_uv8 *uv)
{
    const uint32_t *vk[3] = {v0, v1, v2};
    dr_f8 tu[3], tv[3];
    dr_m8 has;
    for (int i = 0; i < DR_SIMD_W; i++)
        has[i] = m->uvs && (m->flags[tri[i]] & DR_TRI_HAS_UVS) ? -1 : 0;
    dr_f8 b0 = 1.0 - b1 - b2;
    uv->u[0] = uv->v[0] = uv->u[1] = uv->v[1] = dr_f8s(0.0);
    if (dr_m8_any(has)) {   /* (every vertex has a pair where the mesh has uvs: zeros where it had none) */
        for (int k = 0; k < 3; k++)
            gather_pair(m->uvs, vk[k], &tu[k], &tv[k]);
        uv->u[0] = dr_f8_sel(has, b0 * tu[0] + b1 * tu[1] + b2 * tu[2], dr_f8s(0.0));
        uv->v[0] = dr_f8_sel(has, b0 * tv[0] + b1 * tv[1] + b2 * tv[2], dr_f8s(0.0));
    }
    if (!m->uvs1)
        return;
    for (int k = 0; k < 3; k++)
        gather_pair(m->uvs1, vk[k], &tu[k], &tv[k]);
    uv->u[1] = b0 * tu[0] + b1 * tu[1] + b2 * tu[2];
    uv->v[1] = b0 * tv[0] + b1 * tv[1] + b2 * tv[2];
}

/* ------------------------------------------------------------ the stages */


static void triangle_vertices(const struct dr_mesh *m, int64_t tri, uint32_t *v0, uint32_t *v1, uint32_t *v2)
{
    const uint32_t *ix = m->indices + 3 * (size_t)tri;
    *v0 = ix[0], *v1 = ix[1], *v2 = ix[2];
}

/* stage_locate (dr_hit_compute and attributes(), without t and uv, which
 * the eight-lane stages do not use): the hit point p, the geometric normal
 * ng, the shading normal ns; returns the front mask. */
DR_SIMD_INLINE dr_m8 locate(const struct dr_mesh *m, const struct lanes *L, dr_v3x8 o, dr_v3x8 d, dr_v3x8 *p, dr_v3x8 *ng,
                    dr_v3x8 *ns, dr_f8 *eps, dr_f8 *b1_out, dr_f8 *b2_out)
{
    dr_v3x8 p0 = gather_vertex(m->positions, L->v0), p1 = gather_vertex(m->positions, L->v1),
            p2 = gather_vertex(m->positions, L->v2);
    dr_v3x8 e1 = dr_v3x8_sub(p1, p0), e2 = dr_v3x8_sub(p2, p0);
    dr_v3x8 pv = dr_v3x8_cross(d, e2);
    dr_f8 det = dr_v3x8_dot(e1, pv);
    dr_m8 solvable = dr_f8_ne(det, dr_f8s(0.0));
    dr_f8 inv = 1.0 / dr_f8_sel(solvable, det, dr_f8s(1.0));
    dr_v3x8 tv = dr_v3x8_sub(o, p0);
    dr_f8 b1 = dr_f8_sel(solvable, dr_v3x8_dot(tv, pv) * inv, dr_f8s(0.0));
    dr_v3x8 qv = dr_v3x8_cross(tv, e1);
    dr_f8 b2 = dr_f8_sel(solvable, dr_v3x8_dot(d, qv) * inv, dr_f8s(0.0));
    b1 = dr_f8_clamp(b1, 0.0, 1.0);
    b2 = dr_f8_clamp(b2, 0.0, 1.0);
    dr_f8 sum = b1 + b2;
    dr_m8 over = dr_f8_gt(sum, dr_f8s(1.0));
    if (dr_m8_any(over)) {   /* (rare: two vector divisions saved) */
        b1 = dr_f8_sel(over, b1 / sum, b1);
        b2 = dr_f8_sel(over, b2 / sum, b2);
    }

    *b1_out = b1;
    *b2_out = b2;
    dr_f8 b0 = 1.0 - b1 - b2;
    *p = interp(b0, b1, b2, p0, p1, p2);
    *ng = (dr_v3x8){gather_at(m->tri_normal_eps, L->tri, 4, 0), gather_at(m->tri_normal_eps, L->tri, 4, 1),
                    gather_at(m->tri_normal_eps, L->tri, 4, 2)};
    *eps = gather_at(m->tri_normal_eps, L->tri, 4, 3);
    *ns = *ng;
    dr_m8 has_n = mask_of(L->has_normals);
    if (m->normals && dr_m8_any(has_n)) {
        dr_v3x8 n = interp(b0, b1, b2, gather_vertex(m->normals, L->v0), gather_vertex(m->normals, L->v1),
                           gather_vertex(m->normals, L->v2));
        dr_f8 l2 = dr_v3x8_dot(n, n);
        dr_m8 use = has_n & dr_f8_gt(l2, dr_f8s(0.0));
        n = dr_v3x8_scale(n, 1.0 / dr_f8_sqrt(dr_f8_sel(use, l2, dr_f8s(1.0))));
        n = dr_v3x8_sel(dr_f8_lt(dr_v3x8_dot(n, *ng), dr_f8s(0.0)), dr_v3x8_neg(n), n);
        *ns = dr_v3x8_sel(use, n, *ng);
    }
    return dr_f8_lt(dr_v3x8_dot(d, *ng), dr_f8s(0.0));
}

/* Lane i's hit as dr_hit_compute fills it, from locate's results: only the
 * texture coordinates are new (attributes()'s sums, the same operations),
 * so a textured lane no longer solves its triangle a second time in scalar
 * code. t is the distance to p (dr_hit_compute's fallback; nothing reads a
 * hit's t). */
DR_SIMD_INLINE void hit_of_lane(const struct dr_mesh *m, const struct lanes *L, int i, dr_vec3 o, dr_vec3 p,
                                dr_vec3 ng, dr_vec3 ns, double eps, double b1, double b2, bool front, struct dr_hit *hit)
{
    const int64_t tri = L->tri[i];
    *hit = (struct dr_hit){.tri = tri, .p = p, .ng = ng, .ns = ns, .b1 = b1, .b2 = b2, .front = front,
                           .material = m->material[tri], .eps = eps};
    hit->t = dr_length(dr_sub(p, o));
    if (m->flags[tri] & DR_TRI_HAS_UVS) {
        const double b0 = 1.0 - b1 - b2;
        const float *t0 = m->uvs + 2 * (size_t)L->v0[i], *t1 = m->uvs + 2 * (size_t)L->v1[i],
                    *t2 = m->uvs + 2 * (size_t)L->v2[i];
        hit->uv[0] = b0 * t0[0] + b1 * t1[0] + b2 * t2[0];
        hit->uv[1] = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
    }
}

void dr_path8_locate_hits(const struct dr_scene *s, const int64_t *tri, dr_v3x8 o, dr_v3x8 d, const bool *want,
                          struct dr_hit *hit, struct dr_path8_located *loc)
{
    const struct dr_mesh *m = &s->mesh;
    struct lanes L;
    const struct dr_texref *tex[6][DR_SIMD_W];   /* base, metallic-roughness, emissive, normal, coat, coat
                                                    roughness: the eight-lane lookups' */
    bool any_tex8 = false;
    const struct dr_material *prev_mat = NULL;
    struct mat_textures t = {0};
    for (int i = 0; i < DR_SIMD_W; i++) {
        L.tri[i] = tri[i];
        triangle_vertices(m, tri[i], &L.v0[i], &L.v1[i], &L.v2[i]);
        L.has_normals[i] = m->flags[tri[i]] & DR_TRI_HAS_NORMALS;
        const struct dr_material *mat = want[i] ? &s->materials[m->material[tri[i]]] : NULL;
        if (mat != prev_mat && mat)   /* (neighbouring lanes mostly share a material) */
            mat_textures(s, mat, &t);
        else if (!mat)
            t = (struct mat_textures){0};
        prev_mat = mat;
        L.textured[i] = t.scalar_hit;
        tex[0][i] = t.base, tex[1][i] = t.mr, tex[2][i] = t.emissive, tex[3][i] = t.normal;
        tex[4][i] = t.coat[0], tex[5][i] = t.coat[1];
        any_tex8 |= t.base || t.mr || t.emissive || t.normal || t.coat[0] || t.coat[1];
    }
    loc->front = locate(m, &L, o, d, &loc->p, &loc->ng, &loc->ns, &loc->eps, &loc->b1, &loc->b2);
    for (int i = 0; i < DR_SIMD_W; i++)
        if (L.textured[i]) {
            hit_of_lane(m, &L, i, dr_v3x8_get(&o, i), dr_v3x8_get(&loc->p, i), dr_v3x8_get(&loc->ng, i),
                        dr_v3x8_get(&loc->ns, i), loc->eps[i], loc->b1[i], loc->b2[i], loc->front[i] != 0, &hit[i]);
            dr_material_prefetch(s, &hit[i]);
        }
    loc->has_uv = any_tex8;
    if (!any_tex8)
        return;
    texcoords(m, L.tri, L.v0, L.v1, L.v2, loc->b1, loc->b2, &loc->uv);
    const dr_m8 vector_only = ~mask_of(L.textured);   /* (the others' texels: dr_material_prefetch's) */
    for (int k = 0; k < 6; k++)   /* (the colours decoded: base and emissive) */
        dr_texref8_prefetch(s, tex[k], vector_only, &loc->uv, k == 0 || k == 2);
    for (int i = 0; m->tangents && i < DR_SIMD_W; i++)   /* normal_map8's tangent frames */
        if (tex[3][i] && !L.textured[i]) {
            __builtin_prefetch(m->tangents + 4 * (size_t)L.v0[i]);
            __builtin_prefetch(m->tangents + 4 * (size_t)L.v1[i]);
            __builtin_prefetch(m->tangents + 4 * (size_t)L.v2[i]);
        }
}

/* dr_hit_tangent_frame (normal_map.c) on the lanes of *on, the same
 * operations: the mesh's tangent interpolated at (b1, b2) and made
 * orthonormal to ns (Gram-Schmidt), its handedness w (the interpolated w's
 * sign) and the authored side (-1 where the interpolated vertex normal lies
 * on the far side of ng). Clears the lanes without a frame (a vertex's w 0:
 * none generated there; a degenerate tangent); false when none is left.
 * Shared by normal_map8 and anisotropy8. */
static bool tangent_frame8(const struct dr_mesh *m, const struct lanes *L, dr_m8 *on, dr_f8 b1, dr_f8 b2, dr_v3x8 ns,
                           dr_v3x8 ng, dr_v3x8 *t_out, dr_f8 *w_out, dr_f8 *side_out)
{
    const dr_f8 zero = dr_f8s(0.0), one = dr_f8s(1.0);
    dr_f8 t0[4], t1[4], t2[4];
    gather_vertex4(m->tangents, L->v0, t0);
    gather_vertex4(m->tangents, L->v1, t1);
    gather_vertex4(m->tangents, L->v2, t2);
    *on &= dr_f8_ne(t0[3], zero) & dr_f8_ne(t1[3], zero) & dr_f8_ne(t2[3], zero);   /* (no frame here) */
    if (!dr_m8_any(*on))
        return false;
    const dr_f8 b0 = 1.0 - b1 - b2;
    dr_v3x8 t = {b0 * t0[0] + b1 * t1[0] + b2 * t2[0], b0 * t0[1] + b1 * t1[1] + b2 * t2[1],
                 b0 * t0[2] + b1 * t1[2] + b2 * t2[2]};
    *w_out = dr_f8_sel(dr_f8_lt(b0 * t0[3] + b1 * t1[3] + b2 * t2[3], zero), -one, one);
    t = dr_v3x8_sub(t, dr_v3x8_scale(ns, dr_v3x8_dot(ns, t)));   /* Gram-Schmidt against the normal */
    const dr_f8 tl = dr_f8_sqrt(dr_v3x8_dot(t, t));
    *on &= dr_f8_gt(tl, dr_f8s(1e-6));   /* (degenerate UVs: no frame) */
    if (!dr_m8_any(*on))
        return false;
    *t_out = dr_v3x8_scale(t, 1.0 / dr_f8_sel(*on, tl, one));
    dr_f8 side = one;   /* (authored_side) */
    const dr_m8 has_n = mask_of(L->has_normals) & *on;
    if (m->normals && dr_m8_any(has_n)) {
        dr_v3x8 n = interp(b0, b1, b2, gather_vertex(m->normals, L->v0), gather_vertex(m->normals, L->v1),
                           gather_vertex(m->normals, L->v2));
        side = dr_f8_sel(has_n & dr_f8_lt(dr_v3x8_dot(n, ng), zero), -one, one);
    }
    *side_out = side;
    return true;
}

/* dr_normal_map_apply (normal_map.c) for the lanes with an eight-lane normal
 * map (L->normal_tex): the tangent frame at the hit, the map's texel through
 * its coordinates in uv, the perturbed normal, with the scalar function's
 * operations in its order, so each lane gets its bits. ng: the triangle's
 * normal, ns: the interpolated one (both not yet towards the ray). Returns
 * ns with those lanes' mapped; lanes where the scalar function changes
 * nothing (no tangents or UVs, a degenerate frame) keep theirs. */
static dr_v3x8 normal_map8(const struct dr_scene *s, const struct lanes *L, dr_v3x8 ng, dr_v3x8 ns, dr_f8 b1,
                           dr_f8 b2, const struct dr_uv8 *uv)
{
    const struct dr_mesh *m = &s->mesh;
    if (!m->tangents)
        return ns;
    dr_m8 on;
    for (int i = 0; i < DR_SIMD_W; i++)
        on[i] = L->normal_tex[i] && (m->flags[L->tri[i]] & DR_TRI_HAS_UVS) ? -1 : 0;
    dr_v3x8 t;
    dr_f8 w, side;
    if (!tangent_frame8(m, L, &on, b1, b2, ns, ng, &t, &w, &side))
        return ns;
    const dr_f8 zero = dr_f8s(0.0);
    const dr_v3x8 px = dr_texref8_rgb(s, L->normal_tex, on, uv, false);
    const dr_f8 k = gather(L->mat, offsetof(struct dr_material, normal_scale));
    const dr_f8 x = (2.0 * px.x - 1.0) * k, y = (2.0 * px.y - 1.0) * k, z = 2.0 * px.z - 1.0;
    const dr_v3x8 p = dr_v3x8_add(dr_v3x8_add(dr_v3x8_scale(t, side * x), dr_v3x8_scale(dr_v3x8_cross(ns, t), w * y)),
                                  dr_v3x8_scale(ns, z));
    const dr_f8 pl = dr_f8_sqrt(dr_v3x8_dot(p, p));
    on &= dr_f8_gt(pl, zero) & dr_f8_eq(pl - pl, zero);   /* (positive and finite) */
    return dr_v3x8_sel(on, dr_v3x8_scale(p, 1.0 / pl), ns);
}

/* A group's hits as locate_stage leaves them. */
struct hit8 {
    dr_v3x8 ng, ns;
    dr_f8 b1, b2;
    struct dr_uv8 uv;
    dr_m8 front;
};

/* stage_material's anisotropic frame and dr_material_eval's anisotropy on
 * the eight-wide anisotropic lanes (lanes->any_aniso8), the same operations
 * as normal_map.c's dr_hit_tangent_frame, anisotropy.c's
 * dr_anisotropy_direction and dr_anisotropy_frame: the tangent frame at the
 * hit made orthonormal to ns (the mapped normal), the direction (the
 * texture's RG or (1, 0), turned by the rotation, cos and sin from libm as
 * there) in it, projected onto the shading normal fn's plane, on the frame's
 * first axis (fs, ft); the strength (factor x the texel's B) returned, 0
 * where there is no direction (L->no_direction: the scalar fallback). */
static dr_f8 anisotropy8(const struct dr_scene *s, struct lanes *L, const struct hit8 *h, dr_m8 end, dr_v3x8 fn,
                         dr_v3x8 *fs, dr_v3x8 *ft)
{
    const struct dr_mesh *m = &s->mesh;
    const dr_f8 zero = dr_f8s(0.0), one = dr_f8s(1.0);
    dr_m8 lanes, on;
    for (int i = 0; i < DR_SIMD_W; i++) {
        lanes[i] = L->anisotropic[i] && !L->aniso_scalar[i] && !end[i] ? -1 : 0;
        on[i] = lanes[i] && m->tangents && (m->flags[L->tri[i]] & DR_TRI_HAS_UVS) ? -1 : 0;
    }
    dr_v3x8 px = {one, one, one};   /* (no texture: the direction (1, 0), the factor alone) */
    dr_m8 textured = (dr_m8){0};
    for (int i = 0; i < DR_SIMD_W; i++)
        textured[i] = lanes[i] && L->aniso_tex[i] ? -1 : 0;
    if (dr_m8_any(textured))
        px = dr_v3x8_sel(textured, dr_texref8_rgb(s, L->aniso_tex, textured, &h->uv, false), px);
    const dr_f8 factor = gather(L->mat, offsetof(struct dr_material, anisotropy_strength));
    const dr_f8 strength = dr_f8_sel(textured, factor * px.z, factor);
    /* the tangent frame (dr_hit_tangent_frame) */
    dr_v3x8 t;
    dr_f8 w, side;
    if (!dr_m8_any(on) || !tangent_frame8(m, L, &on, h->b1, h->b2, h->ns, h->ng, &t, &w, &side))
        goto none;
    const dr_v3x8 ns = h->ns;
    const dr_v3x8 b = dr_v3x8_scale(dr_v3x8_cross(ns, t), w * side);
    /* the direction (dr_anisotropy_direction) */
    dr_f8 x = dr_f8_sel(textured, 2.0 * px.x - 1.0, one), y = dr_f8_sel(textured, 2.0 * px.y - 1.0, zero);
    double rot_last = 0.0, c_last = 1.0, s_last = 0.0;
    for (int i = 0; i < DR_SIMD_W; i++) {
        const double rot = on[i] ? ((const struct dr_material *)L->mat[i])->anisotropy_rotation : 0.0;
        if (rot == 0.0)
            continue;
        if (rot != rot_last)   /* (neighbouring lanes mostly share a material) */
            rot_last = rot, c_last = cos(rot), s_last = sin(rot);
        const double xr = c_last * x[i] - s_last * y[i];
        y[i] = s_last * x[i] + c_last * y[i];
        x[i] = xr;
    }
    dr_v3x8 d = dr_v3x8_add(dr_v3x8_scale(t, x), dr_v3x8_scale(b, y));
    dr_f8 l = dr_f8_sqrt(dr_v3x8_dot(d, d));
    on &= dr_f8_gt(l, dr_f8s(1e-9)) & dr_f8_eq(l - l, zero);
    d = dr_v3x8_scale(d, 1.0 / dr_f8_sel(on, l, one));
    /* on the shading plane (dr_anisotropy_frame) */
    d = dr_v3x8_sub(d, dr_v3x8_scale(fn, dr_v3x8_dot(fn, d)));
    l = dr_f8_sqrt(dr_v3x8_dot(d, d));
    on &= dr_f8_gt(l, dr_f8s(1e-6));
    const dr_v3x8 fx = dr_v3x8_scale(d, 1.0 / dr_f8_sel(on, l, one));
    *fs = dr_v3x8_sel(on, fx, *fs);
    *ft = dr_v3x8_sel(on, dr_v3x8_cross(fn, fx), *ft);
none:
    for (int i = 0; i < DR_SIMD_W; i++)
        if (lanes[i])
            L->no_direction[i] = !on[i];
    return dr_f8_sel(on, strength, zero);
}

/* dr_emission of a material without an emissive texture: factor x strength,
 * on the front (or both sides). */
DR_SIMD_INLINE dr_v3x8 emission(const void *const *mat, dr_m8 seen)
{
    dr_v3x8 e = dr_v3x8_scale(gather3(mat, offsetof(struct dr_material, emissive_factor)),
                              gather(mat, offsetof(struct dr_material, emissive_strength)));
    return dr_v3x8_sel(seen, e, (dr_v3x8){dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)});
}

/* a[k[i]] for the lanes of on, 0 for the others (which read a[0]) */
DR_SIMD_INLINE dr_f8 gather_where(const double *a, const int64_t *k, dr_m8 on)
{
#define AT(i) a[on[i] ? k[i] : 0]
    return dr_f8_sel(on, DR_LANES8(dr_f8, AT), dr_f8s(0.0));
#undef AT
}

/* stage_emission: what the hit emits towards the ray and its MIS weight
 * against next-event estimation (dr_light_pdf_area, dr_mis_power), where
 * the lane's triangle emits (g->emits, g->Le, g->emit_w). */
static void emission_seen(const struct dr_scene *s, const struct dr_light_tables *lt, const struct lanes *L,
                          const struct dr_path8_in *in, dr_v3x8 ng, dr_m8 front, dr_f8 b1, dr_f8 b2,
                          const struct dr_uv8 *uv, struct dr_path8 *g)
{
    /* Only a material whose factor x strength is not black has emitting
     * triangles (the light sampler's emitter_power_weight): the per-triangle
     * table, a cache miss a lane on a large mesh, is read for those lanes. */
    const dr_m8 may_emit = mask_of(L->may_emit);
    g->emits = (dr_m8){0};
    if (!dr_m8_any(may_emit))
        return;
    g->emits = dr_f8_gt(gather_where(lt->tri_pick, L->tri, may_emit), dr_f8s(0.0));
    if (!dr_m8_any(g->emits))
        return;
    const dr_m8 seen = front | mask_of(L->double_sided);
    dr_v3x8 Le = emission(L->mat, seen);
    if (L->any_tex8)   /* dr_emission's factor x strength x texture, where seen */
        Le = dr_v3x8_mul(Le, dr_texref8_rgb(s, L->emissive_tex, g->emits & seen, uv, true));
    for (int i = 0; L->any_textured && i < in->n; i++)
        if (g->emits[i] && L->scalar_emission[i])
            set_lane(&Le, i, dr_emission(s, &L->hit[i]));
    dr_f8 density = gather_where(lt->tri_pick_density, L->tri, g->emits);
    for (int i = 0; lt->any_parts && i < DR_SIMD_W; i++)   /* a triangle with parts: the hit's part's */
        if (g->emits[i] && density[i] < 0.0 && in->depth[i] > 1.0)   /* (a camera ray's weight is 1) */
            density[i] = dr_light_area_density(s->light_sampler, L->tri[i], b1[i], b2[i]);
    dr_v3x8 dd = dr_v3x8_sub(g->p, in->prev_p);
    dr_f8 d2 = dr_v3x8_dot(dd, dd);
    dr_f8 cos_l = dr_f8_abs(dr_v3x8_dot(ng, dd)) / dr_f8_sqrt(d2);
    dr_f8 pdf = dr_f8_sel(dr_f8_gt(cos_l, dr_f8s(0.0)), density * d2 / cos_l, dr_f8s(0.0));
    pdf = dr_f8_sel(dr_f8_le(density, dr_f8s(0.0)), dr_f8s(0.0), pdf);
    dr_f8 w = mis_power(in->prev_pdf, pdf);
    g->emit_w = dr_f8_sel(dr_f8_eq(in->depth, dr_f8s(1.0)), dr_f8s(1.0), w);
    g->Le = Le;
}

bool dr_path8_env_eight(const struct dr_scene *s)
{
    struct dr_env_tables t;
    return !s->env.map.data || dr_light_env_tables(s->light_sampler, &t);
}

bool dr_path8_escaped(const struct dr_scene *s, dr_m8 on, dr_v3x8 d, dr_f8 depth, dr_f8 prev_pdf,
                      dr_f8 prev_sky, dr_v3x8 *Le, dr_f8 *emit_w, struct dr_env8_lookup *at)
{
    const dr_m8 first = dr_f8_eq(depth, dr_f8s(1.0));   /* (the camera ray's: weight 1, no density) */
    struct dr_env_tables t;
    if (s->env.map.data && dr_light_env_tables(s->light_sampler, &t)) {
        dr_f8 pdf = dr_f8s(0.0);
        *Le = dr_env8_radiance_pdf(s, &t, on, d, dr_m8_any(on & ~first) ? &pdf : NULL, at);
        *emit_w = dr_f8_sel(first, dr_f8s(1.0), mis_power(prev_pdf, pdf));
        return at != NULL;
    }
    /* without a map the radiance is the same in every direction, and the
     * density dr_light_pdf_env's: pick times the point's own (its BSDF's, or
     * the sphere's) */
    const dr_vec3 up = dr_v3(0.0, 0.0, 1.0), L = dr_env_radiance(s, up);
    struct dr_light_tables lt;
    const double pick = dr_light_tables(s->light_sampler, &lt) && lt.env_uniform_entry >= 0
                            ? lt.pick[lt.env_uniform_entry] : 0.0;
    const dr_f8 pdf = pick * prev_sky;
    *Le = (dr_v3x8){dr_f8s(L.x), dr_f8s(L.y), dr_f8s(L.z)};
    *emit_w = dr_f8_sel(first, dr_f8s(1.0), mis_power(prev_pdf, pdf));
    return false;
}

dr_v3x8 dr_path8_escaped_term(const struct dr_scene *s, const struct dr_path_opts *opts, dr_m8 on, dr_v3x8 d,
                              dr_f8 depth, dr_f8 prev_pdf, dr_f8 prev_sky)
{
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    if (!(opts->stages & DR_STAGE_ENV))
        return zero;
    dr_v3x8 Le;
    dr_f8 w;
    dr_path8_escaped(s, on, d, depth, prev_pdf, prev_sky, &Le, &w, NULL);
    return dr_v3x8_sel(on, (dr_v3x8){Le.x * w, Le.y * w, Le.z * w}, zero);   /* (dr_path_vertex_term's) */
}

/* A light sample for each lane of a group (dr_light_sample's out). */
struct light8 {
    dr_v3x8 wi, target, radiance;
    dr_f8 pdf;
    dr_m8 infinite, delta;   /* at no finite distance (environment, directional); no MIS (punctual) */
    dr_m8 diff;              /* the light's radiance has a parameter (only with ps: light_sample's) */
    /* which light (dr_light_sample's record; only with light_sample's
     * record, and the punctual lanes' always) */
    int32_t type[DR_SIMD_W];
    int64_t index[DR_SIMD_W];
    dr_f8 b1, b2, atten;
    dr_m8 hole;                     /* the light point is a hole of a cut-out (alphaMode MASK) emitter */
    dr_m8 env_map;                  /* lanes that sampled the environment map, whose radiance's */
    struct dr_env8_lookup env_at;   /* lookup this is (env_map_samples) */
};

/* Tables at most this long are searched all eight lanes at once. */
#define SHORT_TABLE 16

/* Each lane's entry of the light table: dr_cdf_find_guided's answer, the
 * largest i with cdf[i] <= u. In a short table that is the number of
 * entries j >= 1 with cdf[j] <= u (the cdf rises; a NaN u counts none,
 * as the search answers 0), counted for the eight lanes together. */
static void find_entries(const struct dr_light_tables *lt, dr_f8 u, int64_t e[DR_SIMD_W])
{
    if (lt->n_entries > SHORT_TABLE) {   /* the lanes' cache misses overlapped (cdf.h) */
        int64_t j[DR_SIMD_W];
        for (int i = 0; i < DR_SIMD_W; i++)
            if ((j[i] = dr_cdf_guide_bucket(lt->n_entries, u[i])) >= 0)
                __builtin_prefetch(lt->cdf_guide + j[i]);
        for (int i = 0; i < DR_SIMD_W; i++)
            if (j[i] >= 0)
                __builtin_prefetch(lt->cdf + lt->cdf_guide[j[i]]);
        for (int i = 0; i < DR_SIMD_W; i++)
            e[i] = dr_cdf_find_guided(lt->cdf, lt->n_entries, lt->cdf_guide, lt->n_entries, u[i]);
        return;
    }
    dr_m8 count = {0};
    for (int64_t j = 1; j < lt->n_entries; j++)
        count -= dr_f8_le(dr_f8s(lt->cdf[j]), u);   /* (a mask is -1 where true) */
    for (int i = 0; i < DR_SIMD_W; i++)
        e[i] = count[i];
}

/* Each lane's light-table entry; env: it is a constant environment
 * (env_light_samples); env_map: an environment map (dr_env8_sample);
 * other[i]: a punctual light, s->lights[punctual[i]] (punctual_samples; 0
 * in the other lanes) (for all three the area arithmetic runs on a
 * stand-in). */
static void pick_lights(const struct dr_scene *s, const struct dr_light_tables *lt, struct lanes *L,
                        const struct dr_path8_ahead *ahead, dr_f8 u_pick, dr_f8 *pick, dr_f8 *area,
                        uint32_t v[3][DR_SIMD_W], uint32_t sub[DR_SIMD_W], dr_m8 *env, dr_m8 *env_map, bool *other,
                        int64_t punctual[DR_SIMD_W])
{
    const struct dr_mesh *m = &s->mesh;
    int64_t entry[DR_SIMD_W];
    if (ahead)   /* (found ahead from the same u_pick: dr_path8_ahead_stage) */
        memcpy(entry, ahead->entry, sizeof entry);
    else
        find_entries(lt, u_pick, entry);
#define ENV(i) (entry[i] == lt->env_uniform_entry ? -1 : 0)
#define ENV_MAP(i) (entry[i] == lt->env_map_entry ? -1 : 0)
    *env = DR_LANES8(dr_m8, ENV), *env_map = DR_LANES8(dr_m8, ENV_MAP);
#undef ENV
#undef ENV_MAP
    for (int i = 0; i < DR_SIMD_W; i++) {
        other[i] = entry[i] >= lt->n_emitters && !(*env)[i] && !(*env_map)[i];
        punctual[i] = other[i] ? entry[i] - lt->n_emitters : 0;   /* (dr_light_sample's light index) */
        if (entry[i] >= lt->n_emitters)
            entry[i] = lt->n_emitters > 0 ? 0 : -1;
        else if (lt->any_parts)
            sub[i] = lt->emitter_sub[entry[i]];   /* (a stand-in's stays 0: the whole triangle) */
    }
    /* Each lane's reads depend on the one before (entry, its triangle, the
     * triangle's vertices); on a scene with thousands of emitters each is a
     * cache miss. Asked for stage by stage for all lanes first, the lanes'
     * misses overlap instead of following one another. */
    if (lt->n_emitters > SHORT_TABLE && !ahead) {
        for (int i = 0; i < DR_SIMD_W; i++)
            if (entry[i] >= 0) {
                __builtin_prefetch(lt->emitter_tri + entry[i]);
                __builtin_prefetch(lt->pick + entry[i]);
                __builtin_prefetch(lt->emitter_area + entry[i]);
                if (lt->any_parts)
                    __builtin_prefetch(lt->emitter_sub + entry[i]);
            }
        for (int i = 0; i < DR_SIMD_W; i++)
            if (entry[i] >= 0)
                dr_mesh_prefetch_triangle(m, lt->emitter_tri[entry[i]]);
        for (int i = 0; i < DR_SIMD_W; i++)
            if (entry[i] >= 0)
                dr_mesh_prefetch_positions(m, lt->emitter_tri[entry[i]]);
    }
#define PICK(i) (entry[i] < 0 ? 0.0 : lt->pick[entry[i]])
#define AREA(i) (entry[i] < 0 ? 1.0 : lt->emitter_area[entry[i]])
    *pick = DR_LANES8(dr_f8, PICK), *area = DR_LANES8(dr_f8, AREA);
#undef PICK
#undef AREA
    for (int i = 0; i < DR_SIMD_W; i++) {
        int64_t e = entry[i];
        if (e < 0) {   /* no emitting triangle at all: triangle 0 stands in */
            L->ltri[i] = 0;
            L->lmat[i] = &s->materials[m->material[0]];
            L->ldouble_sided[i] = true;
            L->ltextured[i] = false;
            L->lemissive_tex[i] = NULL;
        } else {
            L->ltri[i] = lt->emitter_tri[e];
            const struct dr_material *lm = &s->materials[m->material[L->ltri[i]]];
            L->lmat[i] = lm;
            L->ldouble_sided[i] = lm->double_sided;
            const bool tex = lm->emissive_tex.texture >= 0, tex8 = tex && dr_texref8_accepts(s, &lm->emissive_tex);
            L->lemissive_tex[i] = tex8 ? &lm->emissive_tex : NULL;
            L->any_ltex8 |= tex8;
            L->ltextured[i] = tex && !tex8;
            L->any_ltextured |= L->ltextured[i];
        }
        triangle_vertices(m, L->ltri[i], &v[0][i], &v[1][i], &v[2][i]);
    }
}

/* lights.h's dr_sky_pdf and bsdf.c's dr_bsdf_sky_share, the same operations. */
DR_SIMD_INLINE dr_f8 sky_pdf(dr_f8 share, dr_f8 cos_g, dr_f8 pdf_b)
{
    return (1.0 - share) * (dr_f8_max(cos_g, dr_f8s(0.0)) * (1.0 / M_PI)) + share * pdf_b;
}
DR_SIMD_INLINE dr_f8 sharpness(dr_f8 alpha)
{
    const dr_f8 sharp = (0.45 - alpha) * (1.0 / 0.15);
    return dr_f8_min(dr_f8_max(sharp, dr_f8s(0.0)), dr_f8s(1.0));
}
DR_SIMD_INLINE dr_f8 sky_share(const struct dr_path8 *g)
{
    dr_f8 a = g->b.alpha;
    if (g->b.any_aniso)   /* a stretched lobe's sharpness: the geometric mean of its alphas */
        a = dr_f8_sel(g->b.aniso, dr_f8_sqrt(g->b.alpha_x * g->b.alpha), a);
    dr_f8 s = g->spec_p * sharpness(a);
    for (int i = 0; g->any_sheen && i < DR_SIMD_W; i++)   /* (dr_sheen_sky_share: the base's times 1 - P) */
        if (g->sheen_on[i] && g->wo_z[i] > COS_EPS)
            s[i] = (1.0 - dr_sheen_lobe_prob(&g->sheen_bsdf[i], dr_v3x8_get(&g->wo, i))) * s[i];
    if (g->coated)   /* dr_coat_sky_share: the coat lobe's share (its specular_prob is 1) and the base's */
        s = dr_f8_sel(g->coat_on, g->coat_p * sharpness(g->coat_lobe.alpha) + (1.0 - g->coat_p) * s, s);
    return dr_f8_sel(dr_f8_gt(g->wo_z, dr_f8s(COS_EPS)), s, dr_f8s(0.0));
}

/* The lanes that picked a constant environment: lights.c's sample_env
 * eight-wide, the same operations: dr_sky_pdf's mixture of the cosine about
 * the geometric normal and the BSDF (bsdf_sample), chosen, with the lobe,
 * by u_pick rescaled within the sky's share; or with uniform over the
 * sphere. The radiance is the same in every direction. */
static void env_light_samples(const struct dr_scene *s, const struct dr_light_tables *lt, dr_m8 env,
                              const struct dr_path8 *g, bool uniform, dr_f8 u_pick, dr_f8 u1, dr_f8 u2, dr_m8 *ok,
                              struct light8 *out)
{
    const double pick = lt->pick[lt->env_uniform_entry], lo = lt->cdf[lt->env_uniform_entry];
    dr_v3x8 wi;
    dr_f8 pdf;
    dr_m8 made = env;
    if (uniform) {
        dr_f8 z = 1.0 - 2.0 * u1, r = dr_f8_sqrt(dr_f8_max(dr_f8s(0.0), 1.0 - z * z)), cos_phi, sin_phi;
        dr_f8_sincos_turn(u2, &sin_phi, &cos_phi);   /* phi = 2 pi u2 */
        wi = (dr_v3x8){r * cos_phi, r * sin_phi, z};
        pdf = dr_f8s(DR_SKY_SPHERE);
    } else {
        const dr_f8 u_sel = dr_f8_min(dr_f8_max((u_pick - lo) / pick, dr_f8s(0.0)), dr_f8s(1.0));   /* (dr_clamp) */
        const dr_f8 share = sky_share(g);
        const dr_m8 by_cos = dr_f8_ge(u_sel, share);
        dr_v3x8 fs, ft, local, f;
        frame_from_normal(g->ng, &fs, &ft);
        const dr_v3x8 cos_local = sample_cosine(u1, u2), cos_wi = to_world(fs, ft, g->ng, cos_local);
        dr_f8 pdf_b, cos_pdf_b;
        made &= by_cos | bsdf_sample(g, env & ~by_cos, u_sel / share, u1, u2, &local, &f, &pdf_b);
        wi = dr_v3x8_sel(by_cos, cos_wi, to_world(g->fs, g->ft, g->fn, local));
        if (dr_m8_any(env & by_cos)) {   /* (dr_bsdf_pdf: 0 below the shading surface) */
            const dr_v3x8 at = to_local(g->fs, g->ft, g->fn, cos_wi);
            eval_pdf_above(g, g->wo, at, &cos_pdf_b);
            const dr_m8 above = dr_f8_gt(g->wo_z, dr_f8s(COS_EPS)) & dr_f8_gt(at.z, dr_f8s(COS_EPS));
            pdf_b = dr_f8_sel(by_cos, dr_f8_sel(above, cos_pdf_b, dr_f8s(0.0)), pdf_b);
        }
        const dr_f8 cos_g = dr_f8_sel(by_cos, cos_local.z, dr_v3x8_dot(wi, g->ng));
        pdf = dr_f8_sel(made, sky_pdf(share, cos_g, pdf_b), dr_f8s(0.0));
    }
    const dr_vec3 Le = dr_env_radiance(s, dr_v3(0.0, 0.0, 1.0));   /* (any direction: no map) */
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    out->wi = dr_v3x8_sel(env, wi, out->wi);
    out->radiance = dr_v3x8_sel(env, (dr_v3x8){dr_f8s(Le.x), dr_f8s(Le.y), dr_f8s(Le.z)}, out->radiance);
    out->target = dr_v3x8_sel(env, zero, out->target);
    out->pdf = dr_f8_sel(env, pdf * pick, out->pdf);
    out->infinite |= env;
    out->delta &= ~env;
    /* dr_light_sample's checks: a zero pick (a zero-strength environment),
     * a failed BSDF sample or a zero density samples nothing; black
     * radiance carries no light (the fields are then not read) unless its
     * derivative is asked (dr_path_light_kept) */
    made &= dr_f8_gt(pdf, dr_f8s(0.0));
    const dr_m8 keep = dr_is_black(Le) ? out->diff & made : made;
    *ok = pick > 0.0 ? (*ok & ~env) | keep : *ok & ~env;
}

/* The lanes that picked an environment map: dr_light_sample's sample_env
 * (dr_env8_sample). */
static void env_map_samples(const struct dr_scene *s, dr_m8 env_map, dr_f8 u1, dr_f8 u2, dr_m8 *ok,
                            struct light8 *out)
{
    struct dr_env_tables t;
    if (!dr_light_env_tables(s->light_sampler, &t)) {   /* (the entry exists only with them) */
        *ok &= ~env_map;
        return;
    }
    dr_v3x8 wi, radiance;
    dr_f8 pdf;
    out->env_at = (struct dr_env8_lookup){0};   /* (defined where no sample is made) */
    const dr_m8 carries = dr_env8_sample(s, &t, env_map, u1, u2, out->diff, &wi, &radiance, &pdf, &out->env_at);
    out->env_map = env_map;
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    out->wi = dr_v3x8_sel(env_map, wi, out->wi);
    out->radiance = dr_v3x8_sel(env_map, radiance, out->radiance);
    out->target = dr_v3x8_sel(env_map, zero, out->target);
    out->pdf = dr_f8_sel(env_map, pdf, out->pdf);
    out->infinite |= env_map;
    out->delta &= ~env_map;
    *ok = (*ok & ~env_map) | carries;
}

/* The lanes `on` that picked a punctual light, s->lights[light[i]]
 * (table entry n_emitters + light[i]): dr_light_sample's punctual branch
 * eight lanes at a time, its operations in its order (range_window,
 * spot_falloff: lights.c), so each lane gets its bits. Lane by lane, through
 * dr_light_sample (which searched the table again), a box lit by a point
 * light took 1.5 x the shading time of the same box under an area light. */
static void punctual_samples(const struct dr_scene *s, const struct dr_light_tables *lt, dr_m8 on,
                             const int64_t *light, dr_v3x8 p, dr_m8 *ok, struct light8 *out)
{
    const void *l[DR_SIMD_W];
    for (int i = 0; i < DR_SIMD_W; i++)
        l[i] = &s->lights[light[i]];   /* (lanes not on: light 0, unread) */
#define RADIANT(i) dr_punctual_radiant(l[i])
#define PICK(i) lt->pick[lt->n_emitters + light[i]]
#define TYPE_IS(i, t) (((const struct dr_punctual *)l[i])->type == (t) ? -1 : 0)
#define DIRECTIONAL(i) TYPE_IS(i, DR_LIGHT_DIRECTIONAL)
#define SPOT(i) TYPE_IS(i, DR_LIGHT_SPOT)
    const dr_f8 radiant = DR_LANES8(dr_f8, RADIANT), pick = DR_LANES8(dr_f8, PICK);
    const dr_m8 directional = on & DR_LANES8(dr_m8, DIRECTIONAL), spot = DR_LANES8(dr_m8, SPOT);
#undef RADIANT
#undef PICK
#undef TYPE_IS
#undef DIRECTIONAL
#undef SPOT
    const dr_v3x8 colour = gather3(l, offsetof(struct dr_punctual, color));
    const dr_v3x8 position = gather3(l, offsetof(struct dr_punctual, position));
    const dr_v3x8 direction = gather3(l, offsetof(struct dr_punctual, direction));
    const dr_f8 range = gather(l, offsetof(struct dr_punctual, range));
    const dr_v3x8 I = dr_v3x8_scale(colour, radiant);
    /* point and spot lights */
    const dr_v3x8 d = dr_v3x8_sub(position, p);
    const dr_f8 d2 = dr_v3x8_dot(d, d), dist = dr_f8_sqrt(d2);
    dr_v3x8 wi = dr_v3x8_scale(d, 1.0 / dist);
    const dr_m8 ranged = ~dr_f8_le(range, dr_f8s(0.0));   /* range_window: 1 without a range */
    const dr_f8 r = dist / dr_f8_sel(ranged, range, dr_f8s(1.0));
    const dr_f8 win = dr_f8_clamp(1.0 - r * r * r * r, 0.0, 1.0);
    dr_f8 atten = dr_f8_sel(ranged, win * win, dr_f8s(1.0)) / d2;
    if (dr_m8_any(spot & on)) {   /* spot_falloff at the angle -wi . direction */
        const dr_f8 ci = gather(l, offsetof(struct dr_punctual, cos_inner));
        const dr_f8 co = gather(l, offsetof(struct dr_punctual, cos_outer));
        const dr_f8 scale = 1.0 / dr_f8_max(ci - co, dr_f8s(1e-3));   /* (fmax(1e-3, ci - co)) */
        const dr_f8 t = dr_f8_clamp((-dr_v3x8_dot(wi, direction) - co) * scale, 0.0, 1.0);
        atten = dr_f8_sel(spot, atten * (t * t), atten);
    }
    dr_v3x8 radiance = dr_v3x8_scale(I, atten);
    dr_m8 carries = dr_f8_gt(d2, dr_f8s(0.0)) & dr_f8_gt(atten, dr_f8s(0.0));
    /* directional lights: along -direction, unattenuated */
    wi = dr_v3x8_sel(directional, dr_v3x8_neg(direction), wi);
    atten = dr_f8_sel(directional, dr_f8s(1.0), atten);
    radiance = dr_v3x8_sel(directional, I, radiance);
    carries = (carries | directional) & dr_f8_gt(pick, dr_f8s(0.0));   /* (a zero pick samples nothing) */
    out->wi = dr_v3x8_sel(on, wi, out->wi);
    out->target = dr_v3x8_sel(on, position, out->target);
    out->radiance = dr_v3x8_sel(on, radiance, out->radiance);
    out->pdf = dr_f8_sel(on, pick, out->pdf);
    out->infinite = (out->infinite & ~on) | directional;
    out->delta |= on;
    out->atten = dr_f8_sel(on, atten, out->atten);
    for (int i = 0; i < DR_SIMD_W; i++)
        if (on[i])
            out->index[i] = light[i];
    /* dr_light_sample's answer; a punctual sample is valid exactly where
     * it carries light (out of range or cone: no light, and none for any
     * parameter), so dr_path_light_kept keeps no other */
    *ok = (*ok & ~on) | (on & carries);
}

/* dr_light_sample from the points p: its area-light branch (dr_hit_at,
 * dr_emission, dr_offset_origin) eight-wide, texel reads of textured
 * emitters and the other kinds of light lane by lane. Returns where a light
 * sample carries light. */
/* The emitting triangles' radiance at their light points (lanes `on`:
 * the area samples that have not failed, so that no texel is read for a
 * failed one): the material's emission towards the side seen (cos_l < 0:
 * the front, or double-sided), times its emissive texture, looked up eight
 * lanes at a time, or through a scalar hit (dr_emission, the light point as
 * dr_light_sample makes it) for an image the eight-lane lookup does not
 * take. */
static dr_v3x8 area_radiance(const struct dr_scene *s, const struct lanes *L, uint32_t v[3][DR_SIMD_W], dr_f8 b1,
                             dr_f8 b2, dr_m8 on, dr_f8 cos_l)
{
    const struct dr_mesh *m = &s->mesh;
    const dr_m8 seen = dr_f8_lt(cos_l, dr_f8s(0.0)) | mask_of(L->ldouble_sided);
    dr_v3x8 radiance = emission(L->lmat, seen);
    if (L->any_ltex8) {
        struct dr_uv8 uv;
        texcoords(m, L->ltri, v[0], v[1], v[2], b1, b2, &uv);
        radiance = dr_v3x8_mul(radiance, dr_texref8_rgb(s, L->lemissive_tex, on & seen, &uv, true));
    }
    for (int i = 0; L->any_ltextured && i < DR_SIMD_W; i++)
        if (on[i] && L->ltextured[i]) {
            struct dr_hit h;
            dr_hit_at(m, L->ltri[i], b1[i], b2[i], &h);
            h.front = cos_l[i] < 0.0;
            set_lane(&radiance, i, dr_emission(s, &h));
        }
    return radiance;
}

static dr_m8 light_sample(const struct dr_scene *s, const struct dr_light_tables *lt, struct lanes *L,
                          const struct dr_path8_ahead *ahead, const struct dr_param_set *ps, bool record,
                          const struct dr_path8 *g, bool sky_uniform, dr_f8 u_pick, dr_f8 u1, dr_f8 u2,
                          struct light8 *out)
{
    const struct dr_mesh *m = &s->mesh;
    dr_f8 pick, area;
    uint32_t v[3][DR_SIMD_W];
    bool other[DR_SIMD_W];
    int64_t punctual[DR_SIMD_W];
    dr_m8 env, env_map;
    uint32_t sub[DR_SIMD_W] = {0};
    pick_lights(s, lt, L, ahead, u_pick, &pick, &area, v, sub, &env, &env_map, other, punctual);
    out->diff = (dr_m8){0};
    for (int i = 0; record && i < DR_SIMD_W; i++) {   /* (dr_path_vertex_has_derivative's switch) */
        const int type = env[i] || env_map[i] ? DR_LS_ENV : other[i] ? DR_LS_PUNCTUAL : DR_LS_AREA;
        out->diff[i] = ps->radiance_active && dr_path_light_differentiated(ps, type, m->material[L->ltri[i]]) ? -1 : 0;
        out->type[i] = type;
        out->index[i] = type == DR_LS_AREA ? L->ltri[i] : -1;   /* (a punctual lane's: punctual_samples) */
    }
    dr_m8 ok = ~dr_f8_le(pick, dr_f8s(0.0));
    dr_f8 su = dr_f8_sqrt(u1);
    dr_f8 b1 = 1.0 - su, b2 = u2 * su;
    for (int i = 0; lt->any_parts && i < DR_SIMD_W; i++)   /* a part of its triangle: its point there */
        if (sub[i] != 0) {
            double x = b1[i], y = b2[i];
            dr_light_part_point(sub[i], &x, &y);
            b1[i] = x, b2[i] = y;
        }
    dr_f8 b0 = 1.0 - b1 - b2;
    out->b1 = b1, out->b2 = b2, out->atten = dr_f8s(0.0);   /* (atten: a punctual lane's, punctual_samples) */
    out->env_map = (dr_m8){0};
    dr_v3x8 lp = interp(b0, b1, b2, gather_vertex(m->positions, v[0]), gather_vertex(m->positions, v[1]),
                        gather_vertex(m->positions, v[2]));
    dr_v3x8 lng = {gather_at(m->tri_normal_eps, L->ltri, 4, 0), gather_at(m->tri_normal_eps, L->ltri, 4, 1),
                   gather_at(m->tri_normal_eps, L->ltri, 4, 2)};
    dr_f8 leps = gather_at(m->tri_normal_eps, L->ltri, 4, 3);
    dr_v3x8 d = dr_v3x8_sub(lp, g->p);
    dr_f8 d2 = dr_v3x8_dot(d, d);
    ok &= dr_f8_gt(d2, dr_f8s(0.0));
    dr_f8 dist = dr_f8_sqrt(d2);
    out->wi = dr_v3x8_scale(d, 1.0 / dist);
    dr_f8 cos_l = dr_v3x8_dot(lng, out->wi);
    ok &= ~dr_f8_eq(cos_l, dr_f8s(0.0)) & dr_f8_gt(area, dr_f8s(0.0));
    out->radiance = area_radiance(s, L, v, b1, b2, ok & ~mask_of(other) & ~env & ~env_map, cos_l);
    out->target = offset_origin(lp, lng, leps, dr_v3x8_neg(out->wi));
    out->pdf = pick * d2 / (dr_f8_abs(cos_l) * area);
    ok &= ~dr_v3x8_is_black(out->radiance) | out->diff;   /* (dr_path_light_kept) */
    /* dr_path_nee_end's test, here where the point is: a point in a hole of
     * a cut-out emitter, or on a BLEND emitter that lets the shadow ray's key
     * through, emits nothing (its shadow ray is still cast, as the one-path
     * walker casts it) */
    out->hole = (dr_m8){0};
    for (int i = 0; (s->effects & (DR_FX_ALPHA_MASK | DR_FX_ALPHA_BLEND)) && i < DR_SIMD_W; i++)
        if (ok[i] && !env[i] && !env_map[i] && !other[i])
            out->hole[i] = dr_coverage_point_present(s, L->ltri[i], b1[i], b2[i], g->skey[i]) ? 0 : -1;
    out->infinite = out->delta = (dr_m8){0};
    if (dr_m8_any(env))
        env_light_samples(s, lt, env, g, sky_uniform, u_pick, u1, u2, &ok, out);
    if (dr_m8_any(env_map))
        env_map_samples(s, env_map, u1, u2, &ok, out);
    const dr_m8 on_punctual = mask_of(other);
    if (dr_m8_any(on_punctual))
        punctual_samples(s, lt, on_punctual, punctual, g->p, &ok, out);
    return ok;
}

/* The first sampler dimension of a vertex at depth (segments so far). */
static inline uint32_t vertex_dim(double depth)
{
    return DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(depth - 1.0);
}

/* Each lane's triangle, its vertices and material, and the vertex's first
 * sampler dimension. */
static void lanes_of(const struct dr_scene *s, const struct dr_path8_in *in, struct lanes *L)
{
    const struct dr_mesh *m = &s->mesh;
    L->any_textured = L->any_ltextured = L->any_tex8 = L->any_ltex8 = L->any_normal8 = false;
    L->any_coat_tex8 = L->any_coated = L->any_anisotropic = L->any_aniso8 = L->any_sheened = false;
    const struct dr_material *prev_mat = NULL;
    struct mat_textures t = {0};
    bool may_emit = false;
    const bool textures = s->n_textures > 0;   /* (else only textured[] is read: all false) */
    for (int i = 0; i < DR_SIMD_W; i++) {
        int64_t tri = in->tri[i];
        L->tri[i] = tri;
        triangle_vertices(m, tri, &L->v0[i], &L->v1[i], &L->v2[i]);
        const struct dr_material *mat = &s->materials[m->material[tri]];
        L->mat[i] = mat;
        if (mat != prev_mat) {   /* (neighbouring lanes mostly share a material) */
            if (textures)
                mat_textures(s, mat, &t);
            may_emit = !dr_is_black(dr_scale(mat->emissive_factor, mat->emissive_strength));
        }
        prev_mat = mat;
        L->may_emit[i] = may_emit;
        L->textured[i] = t.scalar_hit;
        if (textures) {
            L->base_tex[i] = t.base, L->mr_tex[i] = t.mr, L->emissive_tex[i] = t.emissive;
            L->normal_tex[i] = t.normal;
            L->any_tex8 |= t.base || t.mr || t.emissive || t.normal || t.coat[0] || t.coat[1] || t.aniso;
            L->any_normal8 |= t.normal != NULL;
            L->coat_tex[0][i] = t.coat[0], L->coat_tex[1][i] = t.coat[1];
            L->any_coat_tex8 |= t.coat[0] || t.coat[1];
            L->scalar_emission[i] = t.scalar_emission;
            L->normal_mapped[i] = mat->normal_tex.texture >= 0;
        }
        L->coated[i] = mat->coated;
        L->any_coated |= mat->coated;
        L->anisotropic[i] = mat->anisotropic;
        L->scalar_material[i] = textures && t.scalar_material;
        L->sheened[i] = mat->sheened;
        L->any_sheened |= mat->sheened;
        L->aniso_scalar[i] = mat->anisotropic && L->scalar_material[i];
        L->any_aniso8 |= mat->anisotropic && !L->aniso_scalar[i];
        L->aniso_tex[i] = textures ? t.aniso : NULL;
        L->no_direction[i] = false;
        L->any_anisotropic |= mat->anisotropic;
        L->double_sided[i] = mat->double_sided;
        L->has_normals[i] = m->flags[tri] & DR_TRI_HAS_NORMALS;
        L->dim[i] = vertex_dim(in->depth[i]);
    }
}

/* dr_path_nee_begin after the light sample: the BSDF towards the light
 * (dr_bsdf_eval_pdf) and the shadow ray; returns where one is cast. */
DR_SIMD_INLINE dr_m8 nee_begin(struct dr_path8 *g, dr_m8 ok, const struct light8 *ls, dr_v3x8 *so, dr_v3x8 *sd)
{
    ok &= ~dr_f8_le(dr_v3x8_dot(ls->wi, g->ng), dr_f8s(0.0));
    dr_v3x8 nee_wi = to_local(g->fs, g->ft, g->fn, ls->wi);
    dr_m8 above = dr_f8_gt(g->wo_z, dr_f8s(COS_EPS)) & dr_f8_gt(nee_wi.z, dr_f8s(COS_EPS));
    dr_f8 pdf;
    dr_v3x8 f = eval_pdf_above(g, g->wo, nee_wi, &pdf);
    g->bsdf_pdf = dr_f8_sel(above, pdf, dr_f8s(0.0));
    g->nee_f = dr_v3x8_sel(above, f, (dr_v3x8){dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)});
    g->nee_cos = nee_wi.z;
    g->nee_wi = nee_wi;
    g->ls_radiance = ls->radiance;
    g->ls_pdf = ls->pdf;
    g->delta = ls->delta;
    ok &= ~(dr_v3x8_is_black(g->nee_f) & ~g->diff);   /* (a zero BSDF's derivative may not be zero) */
    *so = offset_origin(g->p, g->ng, g->eps, ls->wi);
    *sd = dr_v3x8_sub(ls->target, *so);
    g->tmax = dr_f8_sqrt(dr_v3x8_dot(*sd, *sd));
    *sd = dr_v3x8_sel(ls->infinite, ls->wi, dr_v3x8_scale(*sd, 1.0 / g->tmax));   /* environment, directional: along wi */
    g->tmax = dr_f8_sel(ls->infinite, dr_f8s(INFINITY), g->tmax);
    return ok;
}

/* The vertex's seven numbers in dr_path_step_hit's order (light pick, light
 * point, lobe, direction, roulette) from its first dimension dim: the
 * independent and Sobol samplers' in vector form, the stratified sampler's
 * lane by lane with the scalar draws (their 2D pairs belong together). */
static void vertex_randoms(const struct dr_path8_in *in, const uint32_t *dim, dr_f8 u[7])
{
    dr_u8 d = {dim[0], dim[1], dim[2], dim[3], dim[4], dim[5], dim[6], dim[7]};
    bool sobol = true;   /* every lane's (padding lanes repeat lane 0) */
    for (int i = 0; i < DR_SIMD_W; i++)
        sobol = sobol && in->sampler[i] && in->sampler[i]->kind == DR_SAMPLER_SOBOL;
    if (sobol) {   /* the draws of dr_sampler_next and next2 (sampler.c) in vector form */
#define PKEY(i) in->sampler[i]->pkey
#define INDEX(i) in->sampler[i]->index
        const dr_u8 pkey = DR_LANES8(dr_u8, PKEY);
        const dr_u32x8 rindex = dr_reverse_bits8(DR_LANES8(dr_u32x8, INDEX));
#undef PKEY
#undef INDEX
        dr_sobol_vertex8(pkey, rindex, d, u);
        return;
    }
    for (int k = 0; k < 7; k++)
        u[k] = dr_independent8(in->key, d + (uint64_t)(k + 1));
    for (int i = 0; i < DR_SIMD_W; i++) {
        const struct dr_sampler *p = in->sampler[i];
        if (!p || p->kind == DR_SAMPLER_INDEPENDENT)
            continue;
        struct dr_sampler smp = *p;
        smp.dim = dim[i];
        double r[7];
        r[0] = dr_sampler_next(&smp);
        dr_sampler_next2(&smp, &r[1], &r[2]);
        r[3] = dr_sampler_next(&smp);
        dr_sampler_next2(&smp, &r[4], &r[5]);
        r[6] = dr_sampler_next(&smp);
        for (int k = 0; k < 7; k++)
            u[k][i] = r[k];
    }
}

/* ------------------------------------------------- light picks ahead */

bool dr_path8_picks_ahead(const struct dr_scene *s)
{
    struct dr_light_tables lt;
    return dr_light_tables(s->light_sampler, &lt) && lt.n_entries > SHORT_TABLE;
}

/* Does the lane's light-table entry e name an emitting triangle (not a
 * punctual light or the environment, which dr_light_sample handles)? */
static inline bool emitter_entry(const struct dr_light_tables *lt, int64_t e)
{
    return e >= 0 && e < lt->n_emitters;
}

/* Stage 4's: does emitting triangle tri read an emissive texture? */
static inline bool emissive_textured(const struct dr_scene *s, int64_t tri)
{
    return s->materials[s->mesh.material[tri]].emissive_tex.texture >= 0;
}

/* Each stage reads what the one before asked the cache for, and asks for
 * what the next one reads. Stage 2 finds the entries exactly as
 * find_entries does (its long-table branch). (A sixth stage, the emissive
 * texels at the light points, made each light point in scalar code to ask
 * for them: once the lookups were eight lanes wide it cost more than it
 * saved, 0.96 x the big textured scene's time without it.) */
void dr_path8_ahead_stage(const struct dr_scene *s, const struct dr_path8_in *in, int stage, struct dr_path8_ahead *a)
{
    struct dr_light_tables lt;
    if (!dr_light_tables(s->light_sampler, &lt))
        return;
    const struct dr_mesh *m = &s->mesh;
    switch (stage) {
    case 0: {   /* the random numbers; the guide entries */
        uint32_t dim[DR_SIMD_W];
        for (int i = 0; i < DR_SIMD_W; i++)
            dim[i] = vertex_dim(in->depth[i]);
        vertex_randoms(in, dim, a->u);
        for (int i = 0; i < DR_SIMD_W; i++)
            if ((a->bucket[i] = dr_cdf_guide_bucket(lt.n_entries, a->u[0][i])) >= 0)
                __builtin_prefetch(lt.cdf_guide + a->bucket[i]);
        break;
    }
    case 1:   /* the CDF at both ends of each lane's search (dr_cdf_find_guided checks both) */
        for (int i = 0; i < DR_SIMD_W; i++)
            if (a->bucket[i] >= 0) {
                __builtin_prefetch(lt.cdf + lt.cdf_guide[a->bucket[i]]);
                __builtin_prefetch(lt.cdf + lt.cdf_guide[a->bucket[i] + 1] + 1);
            }
        break;
    case 2:   /* the entries; their records */
        for (int i = 0; i < DR_SIMD_W; i++) {
            int64_t e = a->entry[i] = dr_cdf_find_guided(lt.cdf, lt.n_entries, lt.cdf_guide, lt.n_entries, a->u[0][i]);
            if (emitter_entry(&lt, e)) {
                __builtin_prefetch(lt.emitter_tri + e);
                __builtin_prefetch(lt.pick + e);
                __builtin_prefetch(lt.emitter_area + e);
                if (lt.any_parts)
                    __builtin_prefetch(lt.emitter_sub + e);
            }
        }
        break;
    case 3:   /* the emitting triangles' records */
        for (int i = 0; i < DR_SIMD_W; i++)
            if (emitter_entry(&lt, a->entry[i]))
                dr_mesh_prefetch_triangle(m, lt.emitter_tri[a->entry[i]]);
        break;
    case 4:   /* their vertices (texture coordinates too where the emission is textured) */
        for (int i = 0; i < DR_SIMD_W; i++) {
            if (!emitter_entry(&lt, a->entry[i]))
                continue;
            int64_t tri = lt.emitter_tri[a->entry[i]];
            dr_mesh_prefetch_positions(m, tri);
            if (emissive_textured(s, tri))
                dr_mesh_prefetch_uvs(m, tri);
        }
        break;
    default:
        break;
    }
}

/* Each differentiated lane's scalar hit into in->diff_hit[i], as stage_locate
 * and stage_emission leave it (the normal map applied: a textured lane's
 * L->hit has it); ng, ns: the triangle's, not yet towards the ray. */
static void differentiated_hits(const struct dr_mesh *m, const struct dr_path8_in *in, const struct lanes *L,
                                const struct dr_path8 *g, dr_v3x8 ng, dr_v3x8 ns, dr_f8 b1, dr_f8 b2, dr_m8 front)
{
    for (int i = 0; i < in->n; i++) {
        if (!g->diff[i])
            continue;
        if (L->textured[i])
            *in->diff_hit[i] = L->hit[i];
        else
            hit_of_lane(m, L, i, dr_v3x8_get(&in->o, i), dr_v3x8_get(&g->p, i), dr_v3x8_get(&ng, i),
                        dr_v3x8_get(&ns, i), g->eps[i], b1[i], b2[i], front[i] != 0, in->diff_hit[i]);
    }
}

/* The vertex's seven random numbers (taken ahead, or drawn now), in
 * dr_path_step_hit's order: the light's three out, the rest kept in g. */
static void take_randoms(const struct dr_path8_in *in, const struct lanes *L, struct dr_path8 *g, dr_f8 *u_pick,
                         dr_f8 *u1, dr_f8 *u2)
{
    dr_f8 u[7];
    if (in->ahead)
        memcpy(u, in->ahead->u, sizeof u);
    else
        vertex_randoms(in, L->dim, u);
    *u_pick = u[0], *u1 = u[1], *u2 = u[2];
    g->lobe_u = u[3];
    g->bsdf_u1 = u[4];
    g->bsdf_u2 = u[5];
    g->rr = u[6];
}

/* Which light each lane's sample took, for d_light_radiance (dr_path8_continue
 * copies it into the vertex's ls). */
static void keep_light_record(const struct light8 *ls, struct dr_path8 *g)
{
    memcpy(g->ls_type, ls->type, sizeof g->ls_type);
    memcpy(g->ls_index, ls->index, sizeof g->ls_index);
    g->ls_b1 = ls->b1, g->ls_b2 = ls->b2, g->ls_atten = ls->atten, g->ls_wi = ls->wi;
    g->ls_env_valid = ls->env_map, g->ls_env_at = ls->env_at;
}

/* A group whose every path ends at this vertex (its last segment, or the
 * back of a single-sided surface; at most a term for the emission seen):
 * no material, random numbers, light sample or continuation to make. The
 * fields the callers read where no lane goes on and none casts a shadow
 * ray (dr_path8_continue_lanes returns early then). At max depth 4 on the
 * peer's box that is 18 % of the vertices. */
static void ended_group(struct dr_path8 *g, dr_f8 depth)
{
    g->shadow = g->go_on = g->diff_nee = g->hole = (dr_m8){0};
    memset(g->skey, 0, sizeof g->skey);
    g->tmax = dr_f8s(0.0);
    g->depth = depth;
}

/* The hit as the stages read it: stage_locate's geometry (ng, ns: the
 * triangle's, not yet towards the ray), the texture coordinates for the
 * eight-lane lookups, and the textured lanes' scalar hits. */
/* stage_locate, and stage_emission's normal map (the hit point and eps into
 * g): from the group's located hits where the caller has them. */
static void locate_stage(const struct dr_scene *s, const struct dr_path8_in *in, struct lanes *L, struct dr_path8 *g,
                         struct hit8 *h)
{
    const struct dr_mesh *m = &s->mesh;
    if (in->located) {   /* (the same operations on the same inputs: the same bits) */
        const struct dr_path8_located *l = in->located;
        g->p = l->p, h->ng = l->ng, h->ns = l->ns, g->eps = l->eps, h->b1 = l->b1, h->b2 = l->b2, h->front = l->front;
    } else
        h->front = locate(m, L, in->o, in->d, &g->p, &h->ng, &h->ns, &g->eps, &h->b1, &h->b2);
    if (L->any_tex8 && in->located && in->located->has_uv)
        h->uv = in->located->uv;
    else if (L->any_tex8)
        texcoords(m, L->tri, L->v0, L->v1, L->v2, h->b1, h->b2, &h->uv);
    else
        h->uv = (struct dr_uv8){0};   /* (no lookup reads them) */
    for (int i = 0; i < in->n; i++) {
        if (!L->textured[i])
            continue;
        L->any_textured = true;
        if (in->hit[i])
            L->hit[i] = *in->hit[i];
        else   /* the scalar hit the lookups read */
            hit_of_lane(m, L, i, dr_v3x8_get(&in->o, i), dr_v3x8_get(&g->p, i), dr_v3x8_get(&h->ng, i),
                        dr_v3x8_get(&h->ns, i), g->eps[i], h->b1[i], h->b2[i], h->front[i] != 0, &L->hit[i]);
        if (L->normal_mapped[i]) {   /* stage_emission's dr_normal_map_apply */
            dr_normal_map_apply(s, &L->hit[i]);
            set_lane(&h->ns, i, L->hit[i].ns);
        }
    }
    if (L->any_normal8)   /* ... eight lanes at a time (lanes without a scalar hit) */
        h->ns = normal_map8(s, L, h->ng, h->ns, h->b1, h->b2, &h->uv);
}

/* The shadow rays' coverage keys: dr_path_step_begin's cover_key where the
 * scene has alpha (coverage.h), 0 elsewhere. */
static void shadow_keys(const struct dr_scene *s, const struct dr_path8_in *in, struct dr_path8 *g)
{
    if (!(s->effects & DR_FX_KEYED_SHADOWS)) {
        memset(g->skey, 0, sizeof g->skey);
        return;
    }
    for (int i = 0; i < DR_SIMD_W; i++)
        g->skey[i] = dr_coverage_key(in->key[i], (int)in->depth[i], DR_RAY_SHADOW);
}

void dr_path8_shade_lanes(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path8_in *in,
                          struct dr_path8 *g)
{
    const struct dr_mesh *m = &s->mesh;
    struct dr_light_tables lt;
    dr_light_tables(s->light_sampler, &lt);
    struct lanes L;
    lanes_of(s, in, &L);
    const int n = in->n;
    g->n = n;
    const dr_v3x8 d = in->d;
    const dr_f8 depth = in->depth;

    /* stage_locate, stage_emission */
    struct hit8 h;
    locate_stage(s, in, &L, g, &h);
    const dr_v3x8 ng = h.ng, ns = h.ns;
    const dr_f8 b1 = h.b1, b2 = h.b2;
    const dr_m8 front = h.front;
    g->emits = (dr_m8){0};
    if (opts->stages & DR_STAGE_EMISSION)
        emission_seen(s, &lt, &L, in, ng, front, b1, b2, &h.uv, g);
    g->diff_emit = (dr_m8){0};
    const struct dr_param_set *ps = opts->params;
    for (int i = 0; ps && ps->radiance_active && (opts->stages & DR_STAGE_EMISSION) && i < n; i++)
        g->diff_emit[i] = ps->mat_emission_active[m->material[L.tri[i]]] ? -1 : 0;   /* (surface_emits and the predicate) */

    /* stage_material: the frame towards the ray, the BSDF, the random numbers */
    dr_m8 end = dr_f8_ge(depth, dr_f8s(opts->max_depth)) | (~front & ~mask_of(L.double_sided));
    g->diff = (dr_m8){0};
    for (int i = 0; opts->params && i < DR_SIMD_W; i++)   /* (stage_material's diff_bsdf, where it runs) */
        g->diff[i] = !end[i] && opts->params->mat_bsdf_active[m->material[L.tri[i]]] ? -1 : 0;
    if (in->diff_hit)
        differentiated_hits(m, in, &L, g, ng, ns, b1, b2, front);
    if (!dr_m8_any(~end)) {   /* (the padding lanes repeat lane 0) */
        ended_group(g, depth);
        return;
    }
    g->ng = dr_v3x8_sel(front, ng, dr_v3x8_neg(ng));
    g->fn = dr_v3x8_sel(front, ns, dr_v3x8_neg(ns));
    for (int i = 0; (L.any_textured || L.any_normal8) && i < n; i++)   /* a mapped normal may face away from wo */
        if (L.normal_mapped[i])
            set_lane(&g->fn, i,
                     dr_shading_normal_valid(dr_v3x8_get(&g->ng, i), dr_neg(dr_v3x8_get(&d, i)), dr_v3x8_get(&g->fn, i)));
    frame_from_normal(g->fn, &g->fs, &g->ft);
    for (int i = 0; L.any_anisotropic && i < n; i++)   /* ... whose first axis an anisotropy turns (anisotropy.h) */
        if (L.aniso_scalar[i] && !end[i]) {
            dr_frame f;
            L.no_direction[i] = !dr_anisotropy_frame(s, &L.hit[i], dr_v3x8_get(&g->fn, i), &f);
            set_lane(&g->fs, i, f.s);
            set_lane(&g->ft, i, f.t);
        }
    const dr_f8 aniso = L.any_aniso8 ? anisotropy8(s, &L, &h, end, g->fn, &g->fs, &g->ft) : dr_f8s(0.0);
    g->wo = to_local(g->fs, g->ft, g->fn, dr_v3x8_neg(d));
    g->wo_z = g->wo.z;
    dr_v3x8 colour;
    if (m->colors)
        colour = vertex_colours(m, &L, b1, b2);
    material_eval(s, g, &L, end, m->colors ? &colour : NULL, &h.uv, aniso);
    /* (wo.z <= COS_EPS: unused) */
    g->spec_p = g->glossy ? specular_prob(&g->b, g->lambert, g->wo_z) : dr_f8s(0.0);
    if (g->coated)   /* (dr_coat_sample's P; 0 where the coat is) */
        g->coat_p = g->coat * coat_fresnel(g->wo_z);
    dr_f8 u_pick, u1, u2;
    take_randoms(in, &L, g, &u_pick, &u1, &u2);
    shadow_keys(s, in, g);

    /* dr_path_nee_begin */
    struct light8 ls;
    /* the record of which light: where d_light_radiance may read it (dr_path8_continue; a
     * differentiated vertex's only where the caller takes the vertex whole: diff_hit) */
    const bool record = ps && (ps->radiance_active || (in->diff_hit && dr_m8_any(g->diff)));
    dr_m8 ok = light_sample(s, &lt, &L, in->ahead, opts->params, record, g, opts->sky_uniform, u_pick,
                            u1, u2, &ls);
    g->shadow = nee_begin(g, ok, &ls, &g->so, &g->sd) & ~end;
    g->hole = ls.hole;
    g->diff_nee = ls.diff;
    if (record)
        keep_light_record(&ls, g);
    g->go_on = ~end;
    g->depth = depth;
}

/* Lane i's vertex as the scalar stages leave it where the adjoints of a
 * BSDF parameter read it (d_path_vertex_term, d_path_continuation,
 * d_material_eval: path_simd.h lists the fields), from the vectors, which
 * hold the scalar code's bits (the hit is already in v->hit: dr_path8_in's
 * diff_hit). */
static void differentiated_vertex(const struct dr_scene *s, const struct dr_path8 *g, int i,
                                  struct dr_path_vertex *v)
{
    v->shaded = v->diff_bsdf = true;
    v->ng = dr_v3x8_get(&g->ng, i);
    v->frame = (dr_frame){dr_v3x8_get(&g->fs, i), dr_v3x8_get(&g->ft, i), dr_v3x8_get(&g->fn, i)};
    v->wo = dr_v3x8_get(&g->wo, i);
    v->bsdf = g->any_sheen && g->sheen_on[i] ? g->sheen_bsdf[i] : lane_record(g, i, &s->materials[v->hit.material]);
    v->nee_wi = dr_v3x8_get(&g->nee_wi, i);
    v->nee_bsdf_pdf = g->bsdf_pdf[i];
}

/* Lane i's vertex as the hit stage leaves it (dr_path8_shade): the
 * emission seen there, and what dr_path_vertex_has_derivative and the
 * adjoints read: a differentiated lane's (its hit already in v->hit), a
 * differentiated emitter's scalar hit (o, d: the ray that hit), the
 * material. */
static void shaded_vertex(const struct dr_scene *s, bool light_terms, const struct dr_path8 *g, int i, int64_t tri,
                          dr_vec3 o, dr_vec3 d, struct dr_path_vertex *v)
{
    v->kind = DR_VERTEX_SURFACE;
    if (g->emits[i]) {
        v->emits = true;
        v->Le = dr_v3x8_get(&g->Le, i);
        v->emit_w = g->emit_w[i];
    }
    if (g->diff[i])
        differentiated_vertex(s, g, i, v);
    else if (light_terms && g->emits[i] && g->diff_emit[i])
        dr_hit_compute(&s->mesh, tri, o, d, &v->hit);
    else if (light_terms)
        v->hit.material = s->mesh.material[tri];
}

void dr_path8_shade(const struct dr_scene *s, const struct dr_path_opts *opts, int n,
                    struct dr_path_state *const *st, struct dr_sampler *const *smp, struct dr_path_vertex *const *v,
                    const int64_t *tri, struct dr_shadow_ray *const *shadow, enum dr_step_next *next,
                    bool located, struct dr_path8 *g)
{
    struct dr_path8_in in = {.n = n};
    struct dr_hit *diff_hit[DR_SIMD_W];
    const void *S[DR_SIMD_W];
    for (int i = 0; i < DR_SIMD_W; i++) {
        int k = i < n ? i : 0;
        S[i] = st[k];
        in.tri[i] = tri[k];
        in.depth[i] = st[k]->depth;
        in.key[i] = smp[k]->key;
        in.sampler[i] = smp[k];
        in.hit[i] = located && i < n ? &v[i]->hit : NULL;
        diff_hit[i] = &v[k]->hit;
    }
    in.diff_hit = opts->params ? diff_hit : NULL;
    in.o = gather3(S, offsetof(struct dr_path_state, o));
    in.d = gather3(S, offsetof(struct dr_path_state, d));
    in.prev_p = gather3(S, offsetof(struct dr_path_state, prev_p));
    in.prev_pdf = gather(S, offsetof(struct dr_path_state, prev_pdf));
    dr_path8_shade_lanes(s, opts, &in, g);
    const bool light_terms = opts->params && opts->params->radiance_active;
    for (int i = 0; i < n; i++) {
        shaded_vertex(s, light_terms, g, i, tri[i], st[i]->o, st[i]->d, v[i]);
        if (g->go_on[i])
            smp[i]->dim = DR_DIMS_CAMERA + DR_DIMS_PER_VERTEX * (uint32_t)(st[i]->depth - 1) + 7;
        next[i] = !g->go_on[i] ? DR_STEP_END : g->shadow[i] ? DR_STEP_SHADOW : DR_STEP_CONTINUE;
        if (next[i] == DR_STEP_SHADOW)
            *shadow[i] = (struct dr_shadow_ray){.o = dr_v3x8_get(&g->so, i), .d = dr_v3x8_get(&g->sd, i),
                                                .tmax = g->tmax[i], .key = g->skey[i]};
    }
}

struct mask3 { dr_m8 x, y, z; };   /* a mask per colour channel */

/* substitute_zero_channels (path.c): at a differentiated vertex, a channel
 * whose BSDF value is exactly 0 and not yet substituted on this path is
 * traced on with the substitute factor; *sub marks those channels. */
DR_SIMD_INLINE dr_v3x8 substitute_zero_channels(const struct dr_path8 *g, dr_v3x8 f, dr_v3x8 ratio, struct mask3 *sub)
{
    const dr_f8 zero = dr_f8s(0.0), substitute = dr_f8s(DR_PATH_SUBSTITUTE);
    sub->x = g->diff & dr_f8_eq(f.x, zero) & ~dr_f8_eq(ratio.x, zero);
    sub->y = g->diff & dr_f8_eq(f.y, zero) & ~dr_f8_eq(ratio.y, zero);
    sub->z = g->diff & dr_f8_eq(f.z, zero) & ~dr_f8_eq(ratio.z, zero);
    return (dr_v3x8){dr_f8_sel(sub->x, substitute, f.x), dr_f8_sel(sub->y, substitute, f.y),
                     dr_f8_sel(sub->z, substitute, f.z)};
}

void dr_path8_continue_lanes(const struct dr_path_opts *opts, const struct dr_path8 *g, dr_v3x8 beta_in,
                             const dr_v3x8 *ratio_in, dr_m8 occluded, struct dr_path8_out *out)
{
    const dr_v3x8 one = {dr_f8s(1.0), dr_f8s(1.0), dr_f8s(1.0)};
    if (!dr_m8_any(g->go_on | g->shadow)) {   /* (no lane's next-event estimate or continuation: an ended group's) */
        *out = (struct dr_path8_out){.ratio = ratio_in ? *ratio_in : one};
        return;
    }
    /* dr_path_nee_end */
    out->nee = g->shadow & dr_f8_gt(g->tmax, dr_f8s(0.0)) & ~occluded & ~g->hole;
    dr_f8 w = dr_f8_sel(g->delta, dr_f8s(1.0), mis_power(g->ls_pdf, g->bsdf_pdf));
    out->nee_scale = dr_f8_abs(g->nee_cos) * w / g->ls_pdf;

    /* stage_continue: dr_bsdf_sample, Russian roulette, the next ray */
    dr_v3x8 wi, f;
    dr_f8 pdf;
    dr_m8 ok = bsdf_sample(g, g->go_on, g->lobe_u, g->bsdf_u1, g->bsdf_u2, &wi, &f, &pdf);
    dr_v3x8 wiw = to_world(g->fs, g->ft, g->fn, wi);
    ok &= ~dr_f8_le(dr_v3x8_dot(wiw, g->ng), dr_f8s(0.0));
    dr_f8 cos_pdf = dr_f8_abs(wi.z) / pdf;
    dr_v3x8 ratio = ratio_in ? *ratio_in : one, fs = f;
    struct mask3 sub = {{0}, {0}, {0}};
    if (dr_m8_any(g->diff))
        fs = substitute_zero_channels(g, f, ratio, &sub);
    dr_v3x8 beta = dr_v3x8_mul(beta_in, dr_v3x8_scale(fs, cos_pdf));
    ok &= ~dr_v3x8_is_black(beta);
    dr_m8 roulette = dr_f8_ge(g->depth, dr_f8s(opts->rr_depth));
    dr_f8 q = dr_f8_sel(roulette, dr_f8_min(dr_f8_max(beta.x, dr_f8_max(beta.y, beta.z)), dr_f8s(0.95)),
                        dr_f8s(1.0));
    ok &= ~(roulette & dr_f8_ge(g->rr, q));
    out->more = ok;
    out->beta = dr_v3x8_scale(beta, 1.0 / q);
    const dr_f8 zero = dr_f8s(0.0);
    out->ratio = (dr_v3x8){dr_f8_sel(sub.x, zero, ratio.x), dr_f8_sel(sub.y, zero, ratio.y),
                           dr_f8_sel(sub.z, zero, ratio.z)};
    out->wi = wi;
    out->f = f;
    out->sub[0] = sub.x, out->sub[1] = sub.y, out->sub[2] = sub.z;
    out->cos_pdf_q = cos_pdf / q;
    out->o = offset_origin(g->p, g->ng, g->eps, wiw);
    out->d = wiw;
    out->prev_pdf = pdf;
    const bool sky = !opts->sky_uniform && (opts->stages & DR_STAGE_ENV);   /* (dr_path_leaving_sky) */
    out->prev_sky = sky ? sky_pdf(sky_share(g), dr_v3x8_dot(wiw, g->ng), pdf) : dr_f8s(DR_SKY_SPHERE);
}

dr_v3x8 dr_path8_term(const struct dr_path8 *g, const struct dr_path8_out *out)
{
    const dr_v3x8 zero = {dr_f8s(0.0), dr_f8s(0.0), dr_f8s(0.0)};
    dr_v3x8 e = dr_v3x8_sel(g->emits, dr_v3x8_scale(g->Le, g->emit_w), zero);
    if (!dr_m8_any(out->nee))
        return e;
    dr_v3x8 nee = dr_v3x8_scale(dr_v3x8_mul(g->nee_f, g->ls_radiance), out->nee_scale);
    return dr_v3x8_sel(out->nee, dr_v3x8_add(e, nee), e);
}

/* Lane i's vertex as the continuation leaves it (dr_path8_continue): the
 * next-event estimate (with the light sample's record where
 * d_light_radiance may read it) and, where the path goes on, the
 * continuation's factor (a tape's step, tape.c) and a differentiated
 * lane's d_path_continuation inputs. */
static void continued_vertex(bool light_terms, const struct dr_path8 *g, const struct dr_path8_out *out, int i,
                             struct dr_path_vertex *v)
{
    if (out->nee[i]) {
        v->nee = true;
        v->nee_f = dr_v3x8_get(&g->nee_f, i);
        v->ls.radiance = dr_v3x8_get(&g->ls_radiance, i);
        v->nee_scale = out->nee_scale[i];
        if (light_terms || g->diff[i]) {   /* (d_light_radiance's inputs) */
            struct dr_light_sample *ls = &v->ls;
            ls->type = g->ls_type[i], ls->index = g->ls_index[i];
            ls->b1 = g->ls_b1[i], ls->b2 = g->ls_b2[i], ls->atten = g->ls_atten[i];
            ls->wi = dr_v3x8_get(&g->ls_wi, i);
            ls->env_at = (struct dr_env_lookup){g->ls_env_valid[i] != 0, g->ls_env_at.u[i], g->ls_env_at.v[i],
                                                dr_v3x8_get(&g->ls_env_at.map, i)};
        }
    }
    if (!out->more[i])
        return;
    v->cont = true;
    v->f = dr_v3x8_get(&out->f, i);
    v->cos_pdf_q = out->cos_pdf_q[i];
    if (g->diff[i]) {
        v->wi = dr_v3x8_get(&out->wi, i);
        v->pdf = out->prev_pdf[i];
        v->s = v->f;
        for (int c = 0; c < 3; c++)
            if ((v->sub[c] = out->sub[c][i] != 0))
                dr_v3_set(&v->s, c, DR_PATH_SUBSTITUTE);
    }
}

void dr_path8_vertex(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path8 *g,
                     const struct dr_path8_out *out, int i, int64_t tri, dr_vec3 o, dr_vec3 d, struct dr_path_vertex *v)
{
    const bool light_terms = opts->params && opts->params->radiance_active;
    shaded_vertex(s, light_terms, g, i, tri, o, d, v);
    continued_vertex(light_terms, g, out, i, v);
}

void dr_path8_continue(const struct dr_path_opts *opts, const struct dr_path8 *g, struct dr_path_state *const *st,
                       struct dr_path_vertex *const *v, const bool *occluded, bool *more)
{
    const int n = g->n;
    const void *S[DR_SIMD_W];
    bool occ[DR_SIMD_W];
    for (int i = 0; i < DR_SIMD_W; i++) {
        S[i] = st[i < n ? i : 0];
        occ[i] = occluded[i < n ? i : 0];
    }
    struct dr_path8_out out;
    const bool diff = dr_m8_any(g->diff);   /* (then the paths' ratios: substitution) */
    const dr_v3x8 ratio = diff ? gather3(S, offsetof(struct dr_path_state, ratio)) : (dr_v3x8){{0}, {0}, {0}};
    dr_path8_continue_lanes(opts, g, gather3(S, offsetof(struct dr_path_state, beta)), diff ? &ratio : NULL,
                            mask_of(occ), &out);
    const bool light_terms = opts->params && opts->params->radiance_active;
    for (int i = 0; i < n; i++) {
        continued_vertex(light_terms, g, &out, i, v[i]);
        more[i] = out.more[i] != 0;
        if (!more[i])
            continue;
        if (g->diff[i])   /* (the substitution's: stage_continue's) */
            st[i]->ratio = dr_v3x8_get(&out.ratio, i);
        /* the path's next state: one test per lane, not one per field */
        st[i]->beta = dr_v3x8_get(&out.beta, i);
        st[i]->prev_pdf = out.prev_pdf[i];
        st[i]->prev_sky = out.prev_sky[i];
        st[i]->prev_p = dr_v3x8_get(&g->p, i);
        st[i]->o = dr_v3x8_get(&out.o, i);
        st[i]->d = dr_v3x8_get(&out.d, i);
    }
}
