/* --sampling derivative: reparametrize-then-differentiate-then-reparametrize
 * for the BSDF derivative term of a path vertex (the seed's open question).
 *
 * At a vertex whose BSDF has a requested parameter, the derivative term is
 *     T = integral of d f/d theta (wo, wi) [E(wi) + L_ind(wi)] |cos wi| dwi,
 * E the emission first seen along wi (an emitter or the environment), L_ind
 * the radiance that arrives along wi after further bounces. Detached
 * sampling estimates it with the forward path only, with densities made for
 * f: E by next-event estimation (light density p_l, power-heuristic weight
 * against the BSDF density p_f) and by the forward BSDF direction (the
 * complementary weight), L_ind by the forward direction alone. Derivative
 * sampling splits the BSDF derivative in two,
 *     d f/d theta = A + B,   A = the roughness derivative through the GGX
 *                                NDF alone (d_bsdf_eval_rough_ndf),
 *                            B = everything else (base colour, metallic, the
 *                                roughness derivative through G2),
 * and estimates each with strategies made for it (bsdf.h: dr_bsdf_deriv_*):
 *
 *  A (roughness requested; a clear coat's roughness is a second part with
 *    its own pair at the coat's alpha, the base's part under a coat is
 *    the base's times the coat's transmission): a signed integrand, d D/d alpha times smooth
 *    factors, whose positive and negative parts are each ~1 / alpha while
 *    their difference is ~1. Positivized and antithetic (Zeltner et al.
 *    2021, Belhe et al. 2024): one direction from the positive lobe p+ and
 *    one from the negative lobe p-, from the same random numbers (mirrored
 *    so both start at the sign change tan(theta_h) = alpha), each followed
 *    by a radiance path with the *same* random numbers, so the two radiance
 *    estimates nearly cancel where the light varies slowly:
 *        A(w+) L(w+) |cos| / p+(w+) + A(w-) L(w-) |cos| / p-(w-),
 *    L = E + L_ind unweighted: A is estimated by this pair alone (A / p+-
 *    is bounded), and removed from the forward strategies' terms.
 *
 *  B (base colour or metallic requested): a third strategy besides light
 *    and forward sampling, a direction from the mixture p_bm of the cosine
 *    lobe (base colour of the diffuse lobe; the negative part of metallic)
 *    and the GGX visible-normal lobe (base colour of a metal; the positive
 *    part of metallic), combined by one-sample-each MIS with the balance
 *    heuristic:
 *        E:     W_s = p_s / (p_l + p_f + p_bm)   s = light, forward, derivative
 *        L_ind: V_s = p_s / (p_f + p_bm)         s = forward, derivative
 *    (a delta light keeps weight 1). Without base colour or metallic, B
 *    keeps detached sampling's estimate (light + forward, the primal's
 *    weights); so does --sampling derivative-roughness with them
 *    (opts->deriv_params without their bits). That mode exists because
 *    the third strategy lost to detached sampling on every case measured
 *    (efficiency 0.36-0.8 x for base colours and metallic: p_bm is close to
 *    the forward density, and its radiance path costs as much as the
 *    forward one) while its path's time is charged to the roughness too.
 *
 * In the estimators (prb, tape) the forward strategies are detached sampling's
 * terms with corrections: the continuation's derivative becomes B only,
 * times V_f (d_path_deriv_continuation); next-event estimation's derivative
 * becomes B times W_l (d_path_deriv_nee, adding the difference); the
 * emission the forward direction sees at the next vertex moves from V_f
 * times the primal's MIS weight to W_f (d_path_deriv_emission); and
 * d_path_deriv_sample adds the new directions and their radiance paths, the
 * extra cost (one path for B, two for each part of A, per differentiated
 * vertex). The coat's factor has no strategy of its own: it is in B.
 *
 * In scenes with media the radiance walks are the medium walker's
 * (dr_path_step dispatches), each starting in the medium on the vertex's
 * side with a hero channel of its own; the derivative vertices are surface
 * vertices (a phase function has no parameter here), whose next-event
 * estimate and emission weights the medium walker forms as the surface
 * walker does (transmittance folded into the light's radiance).
 *
 * Nothing in the primal changes: the image, the path's continuation and
 * every other derivative term are detached sampling's. The new directions
 * and their paths draw from sub-streams of the path's key per vertex depth
 * (independent hashes), so replay and finite differences see the same
 * numbers. */
#ifndef DR_PATH_DERIV_H
#define DR_PATH_DERIV_H

#include "path.h"

/* The BSDF inputs of material m that requested parameters differentiate
 * (enum dr_bsdf_dparam bits; textures count for the inputs they feed). */
unsigned dr_path_material_dparams(const struct dr_scene *scene, const struct dr_param_set *params, int m);

/* An anisotropic material's roughness gets the stretched lobe's pair (bsdf.c)
 * only where its anisotropyStrength factor is at most this; above, it stays
 * with the forward strategies. Measured with `drender compare` (prb, forward
 * mode, the bundled box's gold sphere, 64x64, 16 spp x 8 or 16), the pair's
 * efficiency over detached sampling: 2.03, 1.97 and 0.93 at strength 0.1
 * and roughness 0.08, 0.15 and 0.3; 1.37 at strength 0.2 and 1.24-1.51 at
 * 0.3 (roughness 0.08); 0.93 and 0.69-0.97 at strength 0.6 (roughness 0.08,
 * 0.15). A strongly stretched lobe's d D / d alpha is mostly the lobe
 * widening along its narrow axis, a redistribution between azimuths that a
 * pair split azimuth by azimuth does not cancel. (The stretch alpha_x /
 * alpha_y predicted worse: 1.24-1.51 at 15, 0.69-0.97 at 16.6.) */
#define DR_DERIV_MAX_STRENGTH 0.4
bool dr_path_deriv_aniso_pair_ok(const struct dr_material *material);

/* In place of d_path_continuation at a differentiated vertex v (v->cont):
 * the derivative of B along v->wi times V_f, given d_f (detached sampling's
 * d loss / d f along v->wi). */
void d_path_deriv_continuation(const struct dr_scene *scene, const struct dr_path_opts *opts,
                               const struct dr_path_vertex *v, dr_vec3 d_f, struct dr_grad_sink *sink);

/* Next-event estimation at v (v->nee, v->diff_bsdf), after d_path_vertex_term:
 * turns its BSDF derivative (A + B with the primal's weight) into B with
 * weight W_l, given d_e = d loss / d e_v (as d_path_vertex_term). */
void d_path_deriv_nee(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                      dr_vec3 d_e, struct dr_grad_sink *sink);

/* The emission seen at `next`, reached from the differentiated vertex prev
 * along prev->wi: adds the derivative of B along prev->wi times
 * d_t * Le * (W_f - V_f * next->emit_w), d_t = d loss / d [true throughput
 * into prev] * prev->cos_pdf_q. Nothing without base colour or metallic. */
void d_path_deriv_emission(const struct dr_scene *scene, const struct dr_path_opts *opts,
                           const struct dr_path_vertex *prev, dr_vec3 d_t, const struct dr_path_vertex *next,
                           struct dr_grad_sink *sink);

/* The new directions at a shaded, differentiated vertex v (also where the
 * forward sample failed or Russian roulette ended the path): B's direction
 * from p_bm and A's antithetic pair, each with a radiance path, as above.
 * d_beta: d loss / d [true throughput into v], per channel (forward mode
 * splits channels as d_path_continuation does). smp: the path's sampler
 * (only its key is used). Counts the extra rays. */
void d_path_deriv_sample(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                         const struct dr_sampler *smp, dr_vec3 d_beta, struct dr_grad_sink *sink,
                         struct dr_ray_counts *counts);

/* The same in three parts, for a caller that walks the radiance paths of
 * many vertices at once (the tape, on the packet tracer's lanes): the new
 * directions (dr_path_deriv_rays), each one's radiance walk, and their
 * derivative terms (d_path_deriv_rays). d_path_deriv_sample is their
 * composition with one walk at a time (dr_path_deriv_radiance). */
#define DR_DERIV_RAYS 5   /* at most: B's direction, A's pair, the coat roughness's pair */
enum dr_deriv_kind { DR_DERIV_BM, DR_DERIV_POS, DR_DERIV_NEG, DR_DERIV_COAT_POS, DR_DERIV_COAT_NEG };
struct dr_deriv_ray {
    dr_vec3 wi;                /* local direction at the vertex */
    dr_vec3 o, d, prev_p;      /* the radiance walk's first ray and the vertex's point */
    double pf;                 /* the forward BSDF density of wi */
    double pd;                 /* its strategy's density: p_bm (B), p+ or p- (A) */
    double prev_sky;           /* the walk's start state (dr_path_deriv_start) */
    int medium;                /* ... the medium it starts in (scenes with media: the vertex's side,
                                  the one its ray arrived through) */
    struct dr_sampler rng;     /* the walk's random numbers */
    int depth;
    enum dr_deriv_kind kind;
};
/* What a radiance walk finds: the emission E first seen (unweighted) and
 * the light sampler's density pl of it, and the rest L_ind. */
struct dr_deriv_light {
    dr_vec3 E, L_ind;
    double pl;
};

/* The most new directions a vertex of the run draws (at most
 * DR_DERIV_RAYS): 1 with a base colour or metallic it samples for, 2 more
 * with a roughness, 2 more with a clear coat's roughness. */
int dr_path_deriv_max_rays(const struct dr_scene *scene, const struct dr_path_opts *opts);

/* The new directions at v (0 .. DR_DERIV_RAYS of them, into r), drawn from
 * the sub-streams of smp's key as d_path_deriv_sample draws them. */
int dr_path_deriv_rays(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                       const struct dr_sampler *smp, struct dr_deriv_ray r[DR_DERIV_RAYS]);
/* The state a ray's radiance walk begins in (with r->rng as its sampler, and
 * opts without parameters). With media (opts->stages): in r->medium, with
 * its own hero channel and spectral weights (a fresh estimate of the
 * radiance along the ray, as the medium walker starts a path). */
void dr_path_deriv_start(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_deriv_ray *r,
                         struct dr_path_state *st);
/* What the walk's first vertex w gives (whole: its emission unweighted, its
 * hit for the light density, and its next-event term); each later vertex
 * adds its dr_path_vertex_term times the throughput it was reached with to
 * out->L_ind. */
void dr_path_deriv_first(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *w,
                         struct dr_deriv_light *out);
/* One ray's radiance walk, one vertex at a time (counts its rays). */
void dr_path_deriv_radiance(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_deriv_ray *r,
                            struct dr_deriv_light *out, struct dr_ray_counts *counts);
/* The derivative terms of v's n new directions r, given what their walks
 * found, for d_beta as in d_path_deriv_sample (which skips a black d_beta). */
void d_path_deriv_rays(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                       const struct dr_deriv_ray *r, const struct dr_deriv_light *light, int n, dr_vec3 d_beta,
                       struct dr_grad_sink *sink);

#endif
