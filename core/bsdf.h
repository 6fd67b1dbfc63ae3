/* The glTF metallic-roughness BSDF (reflection only):
 *   f = (1-metallic) * [ (1 - F_o)(1 - F_i) base/pi + F_d * D G / (4 |wo.n| |wi.n|) ]
 *     +    metallic  * [ F_m * D G / (4 |wo.n| |wi.n|) ]
 * D: GGX / Trowbridge-Reitz with alpha = roughness^2 (floored at DR_BSDF_MIN_ALPHA),
 * stretched along the local +x axis by KHR_materials_anisotropy (anisotropy
 * below: Heitz 2014's anisotropic GGX, D, Smith Lambda and the visible-normal
 * sampler with alpha_x, alpha_y),
 * G: Smith height-correlated masking-shadowing, F: Schlick.
 * Dielectric Fresnel follows KHR_materials_specular:
 *   F_d = f0 + (specular - f0) (1 - |wo.h|)^5, f0 = min(0.04 * specular_color, 1) * specular,
 * so specular = 0 gives a pure Lambertian surface. Metal: F_m = base + (1 - base)(1 - |wo.h|)^5.
 * The diffuse lobe is weighted by F_o, F_i = max over channels of the dielectric
 * Fresnel at wo.n and wi.n (not glTF's 1 - F(wo.h), which creates energy at
 * grazing angles): reciprocal, and a white dielectric's albedo stays <= 1.
 *
 * A clear coat (KHR_materials_clearcoat, coated) layers a second GGX lobe
 * over all of this (bsdf_coat.c, which the functions below call for it):
 *   f = T(wo) T(wi) f_base + coat Fc(wo.h) D_c G2_c / (4 |wo.n| |wi.n|),
 *   T(w) = 1 - coat Fc(w.n),  Fc = 0.04 + 0.96 (1 - cos)^5  (index 1.5).
 *
 * A sheen (KHR_materials_sheen, sheened) layers the Estevez-Kulla "Charlie"
 * lobe between the coat and the base (bsdf_sheen.c; coat over sheen over
 * base):
 *   f_sheened = T_s(wo) T_s(wi) f_base + C D_s G_s / (4 |wo.n| |wi.n|),
 *   T_s(w) = max(0, 1 - max(C) E(w.n, r)),  E the lobe's white albedo
 *   (a table, sheen_albedo.h), r = max(sheen_roughness, DR_SHEEN_MIN_ROUGHNESS).
 *
 * All directions are unit vectors in the local shading frame (normal = +z),
 * both pointing away from the surface: wo towards the viewer, wi towards the
 * light. Below the surface (z <= 0) on either side, f = 0 and pdf = 0. */
#ifndef DR_BSDF_H
#define DR_BSDF_H

#include <stdbool.h>

#include "vec.h"

/* Cosines at or below this count as below the surface (f = pdf = 0). */
#define DR_BSDF_COS_EPS 1e-12
#define DR_BSDF_MIN_ALPHA 1e-7   /* roughness ~0.0003: below the smallest roughness parameter (0.001) */
/* The sheen roughness's floor: at 0.07 the lobe's exponent 1/r^2 is ~200
 * already (and its albedo table starts there); below it sheen_roughness has
 * no effect and zero derivative; at it, the slope from above (the
 * parameter's range starts there: params.c). */
#define DR_SHEEN_MIN_ROUGHNESS 0.07

/* The material evaluated at one shading point (textures already applied). */
struct dr_bsdf {
    dr_vec3 base_color;
    double metallic, roughness;
    double specular;
    dr_vec3 specular_color;
    /* KHR_materials_clearcoat (bsdf_coat.c): coated says the layer is there,
     * so that a factor a fit moves to 0 keeps its derivative (false: the
     * factors are unused and nothing of the coat is computed) */
    double coat, coat_roughness;   /* clearcoatFactor, clearcoatRoughnessFactor */
    bool coated;
    /* KHR_materials_anisotropy: the strength s in [0, 1] (anisotropyStrength
     * x the texture's B). The base's GGX lobe stretches along the local +x
     * axis (the caller's frame puts the anisotropy direction there):
     * alpha_x = alpha + (1 - alpha) s^2, alpha_y = alpha (alpha = roughness^2
     * above its floor). 0: isotropic, bit for bit the model without it. The
     * coat's lobe stays isotropic. */
    double anisotropy;
    /* KHR_materials_sheen (bsdf_sheen.c): a layer of fibres over the base and
     * under the coat; sheened says it is there (as coated: a colour a fit
     * moves to 0 keeps its derivative; false: the fields are unused). The
     * sheen's colour (linear RGB, sheenColorFactor x texture) and its
     * perceptual roughness (sheenRoughnessFactor x texture's A). */
    dr_vec3 sheen_color;
    double sheen_roughness;
    bool sheened;
};

/* The lobes dr_bsdf_sample chooses between (the coat's only when coated, the
 * sheen's only when sheened: its map is the diffuse lobe's cosine map). */
enum dr_bsdf_lobe { DR_BSDF_LOBE_DIFFUSE, DR_BSDF_LOBE_SPECULAR, DR_BSDF_LOBE_COAT, DR_BSDF_LOBE_SHEEN };

struct dr_bsdf_sample {
    dr_vec3 wi;     /* sampled direction, local frame */
    dr_vec3 f;      /* BSDF value (without the cosine) */
    double pdf;     /* solid-angle pdf of wi, the same value dr_bsdf_pdf returns */
    enum dr_bsdf_lobe lobe;  /* the lobe whose map produced wi (dr_bsdf_sample_dir) */
};

/* BSDF value f(wo, wi) (no cosine factor). */
dr_vec3 dr_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi);
/* Solid-angle density with which dr_bsdf_sample produces wi. */
double dr_bsdf_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi);
/* Both at once (shares the microfacet terms); *pdf receives the density. */
dr_vec3 dr_bsdf_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf);
/* Chooses a lobe with u_lobe (probability dr_bsdf_specular_prob), then samples
 * it: cosine-weighted hemisphere for the diffuse lobe, GGX visible normals
 * (Heitz 2018) for the specular lobe, from (u1, u2). A coated BSDF first
 * picks its coat's lobe (GGX visible normals of the coat's roughness) with
 * probability coat Fc(wo.n), else the base's lobes with u_lobe rescaled. A
 * sheened BSDF (or the base under a coat) first picks its sheen's lobe
 * (DR_BSDF_LOBE_SHEEN, the cosine map) with probability
 * P = clamp(max(C) E(wo.n, r), 0, 1), else the base's lobes likewise.
 * Returns false when no
 * valid direction results (wo below the surface, sample below it); the path
 * then ends. */
bool dr_bsdf_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1,
                    double u2, struct dr_bsdf_sample *out);
/* The share of a constant sky's next-event samples drawn by this BSDF at wo
 * (a sheened BSDF: (1 - P) times its base's, the sheen's cosine samples
 * being the sky's other half)
 * (lights.h's dr_sky_pdf; the rest by the cosine about the normal): its
 * specular lobe's probability where that lobe is sharp (alpha <= 0.3,
 * roughness 0.55), falling to none where it is broad (alpha >= 0.45,
 * roughness 0.67: there the cosine's samples were the better ones on the
 * sample Box as metal); 0 for wo at or below the surface. A stretched lobe
 * counts with the geometric mean sqrt(alpha_x alpha_y) (a heuristic: any
 * share is unbiased). */
double dr_bsdf_sky_share(const struct dr_bsdf *b, dr_vec3 wo);
/* Probability of choosing a microfacet lobe (specular or coat) for this wo
 * (0 for a pure Lambertian, 1 for a BSDF with no diffuse part): the share of
 * samples drawn by a GGX visible-normal map rather than the cosine map. A
 * sheen's lobe is sampled with the cosine map, so it counts with the
 * diffuse side: (1 - P) p_base, P = the sheen's lobe probability. */
double dr_bsdf_specular_prob(const struct dr_bsdf *b, dr_vec3 wo);
/* The sheen's layer alone, for a caller that evaluates the base beneath it
 * itself (path_simd.c's eight-lane stages, whose base is eight-wide): at
 * wo, wi (wo.z, wi.z > DR_BSDF_COS_EPS) a sheened BSDF's f and density are
 * dr_sheen_layer_f and dr_sheen_layer_pdf of its base's (the BSDF without
 * the sheen, nor a coat: a coat composes over the result), the same
 * operations as dr_bsdf_eval_pdf, which uses them: t = T(wo) T(wi), s = C
 * times the sheen's lobe, p = P(wo), the sheen's lobe probability. */
struct dr_sheen_layer {
    double t, p;
    dr_vec3 s;
};
struct dr_sheen_layer dr_sheen_layer_at(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi);
static inline dr_vec3 dr_sheen_layer_f(const struct dr_sheen_layer *l, dr_vec3 f_base)
{
    return dr_add(dr_scale(f_base, l->t), l->s);
}
static inline double dr_sheen_layer_pdf(const struct dr_sheen_layer *l, dr_vec3 wi, double pdf_base)
{
    return l->p * (wi.z * DR_INV_PI) + (1.0 - l->p) * pdf_base;
}
/* P(wo) alone (wo.z > DR_BSDF_COS_EPS): dr_bsdf_sample's sheened BSDF takes
 * the sheen's lobe where u_lobe < P, else its base's lobes with
 * (u_lobe - P) / (1 - P); its sky share is (1 - P) times the base's. */
double dr_sheen_lobe_prob(const struct dr_bsdf *b, dr_vec3 wo);
/* The sampling map of one lobe: the direction dr_bsdf_sample returns for
 * (u1, u2) once it has chosen `lobe` (bit for bit the same). The diffuse map
 * ignores b and wo; the specular map needs wo.z > 0. The result may lie below
 * the surface (dr_bsdf_sample then rejects it). */
dr_vec3 dr_bsdf_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2);
/* The diffuse lobe's map alone: the cosine-weighted hemisphere about +z
 * (density z / pi), as dr_bsdf_sample_dir gives it (lights.c samples a
 * constant sky with it). */
dr_vec3 dr_bsdf_cosine_dir(double u1, double u2);

/* The cosine sampler's sine and cosine series (bsdf.c: sin t = t + t^3 P(t^2),
 * cos t = 1 - t^2 Q(t^2), coefficients from the highest power), shared with
 * the eight-lane sampler of path_simd.c so both give the same bits. */
extern const double DR_SIN_SERIES[8], DR_COS_SERIES[9];
/* c[0] x^(n-1) + ... + c[n-1], by Horner's rule (the series' evaluation;
 * simd_trig.h's dr_f8_horner is its eight-lane twin). */
static inline double dr_horner(double x, const double *c, int n)
{
    double p = c[0];
    for (int i = 1; i < n; i++)
        p = p * x + c[i];
    return p;
}

/* sin and cos of the angle 2 pi u (u turns; the azimuth of the GGX and
 * environment samplers), without libm: the nearest quarter turn m / 4 is
 * taken off u exactly (for u in [0, 1], u - m/4 is exact by Sterbenz's
 * lemma), the rest r = 2 pi (u - m/4), |r| <= pi/4, goes through the series
 * above, and the quarter turns are sign changes and swaps. As accurate as
 * libm's cos(2 pi u) (r carries the one rounding phi = 2 pi u did); the
 * eight-lane samplers (path_simd.c) do the same operations, so scalar and
 * vector paths choose the same directions to the bit. NaN gives NaN. */
void dr_sincos_turn(double u, double *s, double *c);

/* Adjoint of the differentiable BSDF inputs (same field names as struct dr_bsdf). */
struct dr_d_bsdf {
    dr_vec3 base_color;
    double metallic, roughness;
    double coat, coat_roughness;
    double anisotropy;
    dr_vec3 sheen_color;
    double sheen_roughness;
};

/* Reverse-mode adjoints (redner style): each takes the primal's inputs and
 * d loss / d output, and accumulates (+=) d loss / d input into every output
 * pointer that is not NULL (NULL = not needed). Directions count as three
 * independent components each, in the formula as written (the caller handles
 * normalisation and frames). Where the primal is zero or rejected by
 * construction (below the surface) the adjoints are zero and nothing is
 * touched. The roughness floor (DR_BSDF_MIN_ALPHA) has zero derivative below
 * it. The specular and specular_color inputs are not differentiated.
 * A sheen: sheen_color (max(C) of T and P to the first maximal channel;
 * C = 0 keeps d f / d C = D G / (4 cos cos)), sheen_roughness (zero below
 * DR_SHEEN_MIN_ROUGHNESS, from above at it; through D, G's fit and E) and the cosines
 * (through E's and Lambda's arguments). Where T or P clamps (max(C) E >= 1)
 * their derivative is 0; at a cosine of exactly 1 Lambda's fit has an
 * infinite slope ((1 - x)^(c-1)), taken as the clamp's 0 there. */

/* Reverse mode of dr_bsdf_eval: d_out = d loss / d f (per channel). The
 * parameter part (*d) does not depend on whether d_wo, d_wi are requested.
 * With anisotropy, roughness flows through both alphas (d alpha_x / d rough =
 * (1 - s^2) 2 rough, d alpha_y / d rough = 2 rough, none below the floor) and
 * d->anisotropy receives d alpha_x / d s = 2 s (1 - alpha) (0 at s = 0; it
 * stays live below the roughness floor). Likewise d_bsdf_pdf and
 * d_bsdf_pdf_fixed_prob. */
void d_bsdf_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi);
/* Reverse mode of dr_bsdf_pdf, including the lobe-selection probability's
 * dependence on the parameters and on wo. */
void d_bsdf_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, struct dr_d_bsdf *d,
                dr_vec3 *d_wo, dr_vec3 *d_wi);
/* The same with the lobe-selection probability P held at its value (attached
 * sampling): a discrete choice made with a probability that moved with the
 * parameter would need the boundary term of the lobe threshold; with P a
 * constant the sampling strategy is a fixed mixture whose density,
 * P p_spec + (1 - P) p_diff, is what this differentiates. */
void d_bsdf_pdf_fixed_prob(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, struct dr_d_bsdf *d,
                           dr_vec3 *d_wo, dr_vec3 *d_wi);
/* Reverse mode of dr_bsdf_specular_prob. */
void d_bsdf_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo);
/* Reverse mode of dr_bsdf_sample_dir: d_wi = d loss / d wi. The lobe and
 * (u1, u2) are constants. The diffuse map depends on nothing differentiable
 * (zero), nor does the sheen lobe's (the same map); the specular map
 * depends on roughness and wo. Zero for
 * wo.z <= 0 (dr_bsdf_sample rejects the sample before mapping).
 * With anisotropy, the stretched lobe's map: roughness and anisotropy as in
 * d_bsdf_eval (the estimators nevertheless refuse attached sampling on an
 * anisotropic material). */
void d_bsdf_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                       dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo);

/* ---- derivative sampling (--sampling derivative; the maths beside the code in bsdf.c) ----
 *
 * Densities made for d f / d theta rather than for f: a mixture of lobes
 * whose weights follow the requested parameters. Under a clear coat the
 * base's lobes are the base BSDF's (the coat's transmission is a smooth
 * factor of their integrands) and the coat's roughness has a pair of its own
 * at the coat's alpha; the coat's factor is left to the forward sampler.
 * Under a sheen likewise: the base's lobes (T_s(wo) T_s(wi) is a smooth
 * factor); the sheen's own parameters are left to the forward sampler. */

/* The BSDF inputs a derivative is taken with respect to (bits). */
enum dr_bsdf_dparam {
    DR_BSDF_D_BASE = 1u,
    DR_BSDF_D_METALLIC = 2u,
    DR_BSDF_D_ROUGHNESS = 4u,
    DR_BSDF_D_COAT_ROUGHNESS = 8u   /* a coated BSDF's clearcoatRoughness */
};

/* The lobes of the derivative mixture: cosine (base colour of the diffuse
 * lobe, the negative part of metallic), the forward GGX visible-normal map
 * (base colour of a metal, the positive part of metallic), the positive
 * and negative parts of d D / d alpha (roughness), and the same at the
 * coat's alpha (a coated BSDF's coat roughness; density 0 uncoated). */
enum dr_bsdf_dlobe {
    DR_BSDF_DLOBE_COSINE,
    DR_BSDF_DLOBE_VNDF,
    DR_BSDF_DLOBE_ROUGH_POS,
    DR_BSDF_DLOBE_ROUGH_NEG,
    DR_BSDF_DLOBE_COAT_POS,
    DR_BSDF_DLOBE_COAT_NEG,
    DR_BSDF_DLOBE_COUNT
};

/* Mixture weights of the lobes for the parameters `params` (dr_bsdf_dparam
 * bits; each requested kind gets an equal share): sum 1, or all 0 if none. */
void dr_bsdf_deriv_weights(const struct dr_bsdf *b, unsigned params, double w[DR_BSDF_DLOBE_COUNT]);
/* Solid-angle density of wi under one lobe (0 below the surface). The VNDF
 * lobe is the forward specular map's, stretched with the lobe (anisotropic
 * visible normals). The roughness lobes (ROUGH_POS/NEG, and their maps) are
 * the positive and negative parts of d D / d alpha, made densities; for a
 * stretched lobe (b->anisotropy != 0), whose derivative's sign also turns
 * with the azimuth, split azimuth by azimuth (bsdf.c's rough_split). */
double dr_bsdf_deriv_lobe_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, enum dr_bsdf_dlobe lobe);
/* ... and under the mixture for `params`. */
double dr_bsdf_deriv_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, unsigned params);
/* The sampling map of one lobe (u1, u2) -> wi; may lie below the surface
 * (rejected by dr_bsdf_deriv_sample). wo.z > 0. */
dr_vec3 dr_bsdf_deriv_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_dlobe lobe, double u1, double u2);
/* The part of d_bsdf_eval's roughness adjoint that comes through the NDF D
 * alone (G2 and Fresnel held): d f / d rough |_D = f_spec d lnD/d rough.
 * Its integrand, d D / d alpha times smooth factors, is what the roughness
 * lobes are made for (the antithetic pair of path_deriv.c estimates it;
 * the rest of d f / d rough is left to the forward sampler). parts:
 * DR_BSDF_D_ROUGHNESS adds the base's to d->roughness (under a coat, times
 * the coat's transmission both ways; under a sheen, times T_s(wo) T_s(wi)),
 * DR_BSDF_D_COAT_ROUGHNESS the coat
 * lobe's to d->coat_roughness (times the coat's factor; 0 uncoated).
 * A stretched base lobe (b->anisotropy != 0): the roughness's share of its
 * D's derivative through both alphas (the strength's share is the forward
 * sampler's). */
void d_bsdf_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                           struct dr_d_bsdf *d);
/* Chooses a lobe with u_lobe by the weights, maps (u1, u2), and returns the
 * mixture density in *pdf. False: no valid direction (the estimate is 0). */
bool dr_bsdf_deriv_sample(const struct dr_bsdf *b, dr_vec3 wo, unsigned params, double u_lobe, double u1, double u2,
                          dr_vec3 *wi, double *pdf);

#endif
