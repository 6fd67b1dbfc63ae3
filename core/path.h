/* The path walker: one vertex of a path at a time, with everything the
 * renderer, the path-replay pass and the tape need. All of them call
 * dr_path_step with the same random numbers and so make bit-identical
 * decisions (Russian roulette included).
 *
 * A step is a fixed sequence of stages, each ray query at a stage boundary
 * (the shape of pbrt-v4's wavefront integrator, so a packet tracer can batch
 * at the boundaries and media can add a segment stage after the trace):
 *
 *   trace      closest hit of the current ray                 (extension ray)
 *   escaped    environment radiance with its MIS weight        [DR_STAGE_ENV]
 *   emission   surface emission with its MIS weight            [DR_STAGE_EMISSION]
 *   material   shading frame, BSDF inputs, the vertex's random numbers
 *   nee        light sample + shadow ray (dr_path_nee)          [DR_STAGE_NEE]
 *   continue   BSDF sample, zero-BSDF substitution, Russian roulette, next ray
 *
 * Which optional stages exist is decided once per run from the scene's
 * effects and the requested parameters (dr_path_plan): a scene without lights
 * never samples one, a scene without an environment never looks one up.
 *
 * A path's estimate is L = sum_k beta_k * e_k, where e_k is what vertex k adds
 * (emission times its MIS weight, plus the next-event estimate) and
 * beta_{k+1} = beta_k * t_k with t_k = f_k |cos| / pdf / q (detached sampling:
 * pdfs, MIS weights and q are constants of the derivative).
 *
 * Zero-valued BSDFs at differentiated vertices: if f_k is exactly 0 in a
 * channel, the path would end there, yet d L / d f_k is not 0 (it is the light
 * arriving from the rest of the path). So at a vertex whose material has a
 * requested parameter, such a channel is traced on with a substitute factor
 * s (1/pi) instead of f; `ratio` (0 or 1 per channel) records that the true
 * throughput is 0 from there on. Each channel is substituted at most once:
 * a second zero in it makes everything after second order, hence 0. */
#ifndef DR_PATH_H
#define DR_PATH_H

#include <stdbool.h>
#include <stdint.h>

#include "bsdf.h"
#include "geometry.h"
#include "grad_sink.h"
#include "lights.h"
#include "params.h"
#include "sampler.h"
#include "scene.h"

/* Where the array tracer's time went (wave_soa.c), by the stages of its
 * loop: the seconds each thread spent in a stage (CLOCK_MONOTONIC read
 * between stages, a few reads per bounce of a wave of hundreds of paths),
 * summed over the threads. Wall time per thread, so CPU time only where
 * nothing else runs (a thread's CPU clock costs a system call a read:
 * ~2 % of a render). 0 where it did not run. */
struct dr_stage_seconds {
    double start;     /* new paths: samplers and camera rays */
    double queries;   /* ray queries: the closest hits and the shadow rays (Embree, and
                         accel.c's packets around it; in prb's replays, the logged answers
                         read back) */
    double ends;      /* paths whose rays left the scene ended, the others closed up */
    double shade;     /* the hit stage: hit points, materials, emission seen, light samples, the
                         vertices' random numbers (but for the shadow rays' queries) */
    double advance;   /* next-event estimates, continuations, roulette; ended paths written
                         out, the others closed up */
};

struct dr_ray_counts {
    uint64_t camera, extension, shadow;
    uint64_t simd_vertices;   /* path vertices shaded eight lanes at a time (path_simd.h) */
    uint64_t simd_replayed;   /* ... of them in replays (prb's second walks of its paths) */
    struct dr_stage_seconds cpu;
};

/* *sum += *x, count by count (a run's threads summed). */
static inline void dr_ray_counts_add(struct dr_ray_counts *sum, const struct dr_ray_counts *x)
{
    sum->camera += x->camera;
    sum->extension += x->extension;
    sum->shadow += x->shadow;
    sum->simd_vertices += x->simd_vertices;
    sum->simd_replayed += x->simd_replayed;
    sum->cpu.start += x->cpu.start;
    sum->cpu.queries += x->cpu.queries;
    sum->cpu.ends += x->cpu.ends;
    sum->cpu.shade += x->cpu.shade;
    sum->cpu.advance += x->cpu.advance;
}

/* Dimensions a path uses: 2 for the pixel position, then a fixed block per
 * vertex so each decision owns its own random numbers whatever came before. */
#define DR_DIMS_CAMERA 2
#define DR_DIMS_PER_VERTEX 8

/* Russian roulette starts at this depth (segments) unless told otherwise. */
#define DR_RR_DEPTH_DEFAULT 5

/* Power heuristic (beta = 2) weight of strategy a against b. */
static inline double dr_mis_power(double pdf_a, double pdf_b)
{
    if (!(pdf_a > 0.0))
        return 0.0;
    if (!(pdf_b > 0.0))
        return 1.0;
    double r = pdf_b / pdf_a;   /* ratio form stays finite for huge densities */
    return 1.0 / (1.0 + r * r);
}
/* Reverse mode of dr_mis_power: d_w = d loss / d w into d_pa, d_pb (+=; NULL: not needed). */
void d_mis_power(double pdf_a, double pdf_b, double d_w, double *d_pa, double *d_pb);

/* The optional stages (bits of dr_path_opts.stages). */
enum dr_path_stage {
    DR_STAGE_ENV = 1 << 0,        /* escaped rays see an environment */
    DR_STAGE_EMISSION = 1 << 1,   /* some surface emits, or its emission is differentiated */
    DR_STAGE_NEE = 1 << 2,        /* there is a light to sample */
    DR_STAGE_MEDIA = 1 << 3,      /* participating media: the medium walker (medium_path.c) */
    DR_STAGE_DIELECTRIC = 1 << 4  /* ... with dielectric medium boundaries: specular events there */
};

/* How derivatives of media parameters treat free-flight sampling (medium_grad.c). */
enum dr_medium_grad {
    DR_MEDIUM_GRAD_DRT,        /* differential ratio tracking: unbiased (the default) */
    DR_MEDIUM_GRAD_BASELINE    /* differentiate the sampled null collisions as they are: biased
                                  where the majorant is 0 or tight */
};

/* "drt" / "baseline": the command line's names (--medium-grad; medium_grad.c);
 * parse: -1 for another name. */
const char *dr_medium_grad_name(enum dr_medium_grad m);
int dr_medium_grad_parse(const char *name);

struct dr_path_opts {
    int max_depth, rr_depth;
    enum dr_medium_grad medium_grad;
    const unsigned char *collision_gain; /* per medium, DRT: take a thin homogeneous medium's sigma_t
                                            gain at the path's collisions (the pilot's choice,
                                            medium_grad.h); NULL: gain paths in every thin one */
    unsigned stages;                     /* enum dr_path_stage bits (dr_path_plan) */
    const struct dr_param_set *params;   /* NULL: primal only (no substitution) */
    unsigned deriv_params;               /* derivative sampling: the BSDF inputs it samples directions
                                            for (enum dr_bsdf_dparam bits; path_deriv.h): all of them,
                                            or the roughness alone; 0 otherwise */
    bool sky_uniform;                    /* sample a constant sky over the sphere, not by lights.h's
                                            mixture (dr_light_sample): mis sampling's choice
                                            (estimators/common.c), and the reference test_render
                                            holds the mixture to */
};

/* The stages a scene and a parameter set (NULL: none) call for. */
unsigned dr_path_plan(const struct dr_scene *scene, const struct dr_param_set *params);
/* Comma-separated names of stage bits, for --json and messages. */
void dr_path_stages_describe(unsigned stages, char *buf, int size);

/* The uniform numbers a vertex drew, in its fixed block of dimensions: kept
 * so a derivative pass can re-evaluate the sampling maps (attached sampling). */
struct dr_vertex_randoms {
    double light_pick, light_u1, light_u2;   /* next-event estimation */
    double lobe, bsdf_u1, bsdf_u2;           /* BSDF sample: lobe choice, direction */
    double rr;                               /* Russian roulette */
    uint64_t cover_key;                      /* shadow rays' key for BLEND surfaces (coverage.h) */
};

/* The stretch of one medium a ray crossed (for the derivatives of media
 * parameters: medium_grad.c replays or re-samples it). */
struct dr_medium_piece {
    int medium;
    uint32_t rng_dim;          /* the tracking stream's dimension when the piece began */
    dr_vec3 o;                 /* its start; the direction is the trace's */
    double len;                /* to the boundary, the collision, or the light */
};
#define DR_MEDIUM_PIECES 8
struct dr_medium_trace {
    uint64_t rng_key;          /* the tracking stream (sampler.h key) */
    int n;                     /* pieces recorded (a longer crossing keeps the first DR_MEDIUM_PIECES) */
    dr_vec3 o0, d;             /* the ray (free flight: from the previous vertex) */
    int medium0;               /* ... and the medium it starts in */
    struct dr_medium_piece p[DR_MEDIUM_PIECES];
};

/* What the medium walker records at a vertex for the derivatives of media
 * parameters (medium_grad.c): in the caller's storage, so a vertex stays small
 * where nothing is recorded (the tape keeps these only when media parameters
 * are requested). */
struct dr_medium_record {
    struct dr_medium_trace seg;      /* the free flight into the vertex */
    struct dr_medium_trace shadow;   /* the shadow ray of its next-event estimate */
};

enum dr_vertex_kind {
    DR_VERTEX_SURFACE,   /* the ray hit a triangle */
    DR_VERTEX_ESCAPED,   /* the ray left the scene (environment radiance, if any) */
    DR_VERTEX_MEDIUM,    /* a collision in a participating medium (hit.p; hit.tri = -1) */
    DR_VERTEX_DIELECTRIC /* a smooth dielectric medium boundary (medium_path.c): a specular
                            event, no emission, no next-event estimation, weight f = 1 or
                            1 / eta^2, continuation pdf infinite (delta) */
};

struct dr_path_vertex {
    enum dr_vertex_kind kind;
    int depth;                 /* segments so far (1: the camera ray's hit) */
    dr_vec3 d;                 /* direction of the ray that arrived here */
    dr_vec3 o;                 /* and its origin */
    double prev_pdf;           /* the walker's state on arrival (dr_path_state) */
    double prev_sky;
    dr_vec3 prev_p;
    bool media;                /* from the medium walker (medium_path.c): seg and nee_tr hold */
    dr_vec3 seg;               /* spectral MIS weight change over the segment that arrived
                                  here; already folded into Le and ls.radiance */
    int medium;                /* medium vertex: its medium; else the medium the ray came through (-1) */
    struct dr_hit hit;
    /* emission seen here (surface) or environment radiance (escaped) */
    bool emits;                /* Le is evaluated (and differentiable) here */
    dr_vec3 Le;
    double emit_w;             /* its MIS weight */
    struct dr_env_lookup env_at;   /* escaped: the map's lookup along d, where the eight-lane
                                      stage kept it (cleared by dr_path_step_begin) */
    /* shading */
    bool shaded;               /* the BSDF was evaluated (surface, depth < max) */
    bool diff_bsdf;            /* its material has a requested parameter */
    struct dr_bsdf bsdf;
    dr_frame frame;
    dr_vec3 ng;                /* geometric normal, towards the side the ray came from */
    dr_vec3 wo;                /* local */
    struct dr_vertex_randoms u;
    /* next-event estimation; the light chosen is ls.type / ls.index */
    bool nee;                  /* a light sample contributes (unoccluded, f != 0 ...) */
    struct dr_light_sample ls;
    dr_vec3 nee_wi;            /* local */
    dr_vec3 nee_f;             /* BSDF value towards the light */
    double nee_scale;          /* |cos| * MIS weight / pdf */
    double nee_bsdf_pdf;       /* the BSDF's density towards the light (its MIS weight's other side) */
    dr_vec3 nee_tr;            /* media: transmittance to the light times seg, folded into ls.radiance */
    struct dr_medium_record *mrec;   /* set by the caller: where the medium walker records
                                        (used only when media parameters are requested) */
    /* continuation */
    bool cont;                 /* the path goes on from here */
    dr_vec3 wi;                /* local, sampled */
    dr_vec3 f;                 /* BSDF value along wi */
    double pdf;                /* its solid-angle density */
    enum dr_bsdf_lobe lobe;    /* the lobe chosen (a discrete choice: stays detached) */
    double cos_pdf_q;          /* |cos| / pdf / (Russian roulette survival q) */
    dr_vec3 s;                 /* tracing factor: f, or the substitute where substituted */
    bool sub[3];               /* channel substituted here */
};

/* e_k: what the vertex adds, before multiplying by the throughput. */
static inline dr_vec3 dr_path_vertex_term(const struct dr_path_vertex *v)
{
    dr_vec3 e = v->emits ? dr_scale(v->Le, v->emit_w) : dr_v3s(0.0);
    if (v->nee)
        e = dr_add(e, dr_scale(dr_mul(v->nee_f, v->ls.radiance), v->nee_scale));
    return e;
}

/* Adjoint of e_k with respect to the parameters (emission, environment, the
 * light sampled and the BSDF towards it), given d_e = d loss / d e_k. In
 * forward mode the channels of d_e land in the sink's channels. */
void d_path_vertex_term(const struct dr_scene *scene, const struct dr_param_set *params,
                        const struct dr_path_vertex *v, dr_vec3 d_e, struct dr_grad_sink *sink);
/* Does vertex v have a derivative term under detached sampling (its BSDF,
 * the emission or environment it sees, or the light its next-event estimate
 * sampled has a requested parameter; or it is a medium vertex)? False: the
 * vertex's d_path_vertex_term and d_path_continuation add nothing, so a
 * path's derivative work can end at its last vertex with a term. Reads
 * v->diff_bsdf and v->media, and the rest of v only where some light's
 * radiance has a parameter (params->radiance_active). */
/* Does a light sample of this type (DR_LS_*) have a derivative term: is its
 * light's radiance a parameter (material: the emitting triangle's, for an
 * area light)? dr_path_vertex_has_derivative's next-event case, shared with
 * the eight-lane stages' marks (path_simd.c). */
static inline bool dr_path_light_differentiated(const struct dr_param_set *ps, int type, int material)
{
    return type == DR_LS_AREA ? ps->mat_emission_active[material] : type == DR_LS_ENV ? ps->env_active
                                                                                       : ps->lights_active;
}
/* Is light sample ls (dr_light_sample's answer: carries) kept for next-event
 * estimation? Where it carries light; and where it carries none but is a
 * sample (a black texel of an emissive texture, a dark environment or
 * emitter) of a light whose radiance has a parameter: its term is 0, its
 * derivative need not be, and dropping it biased the gradient (an emissive
 * texture's black texels, one of them raised: the next-event share of the
 * light it would add was never counted). */
static inline bool dr_path_light_kept(const struct dr_scene *s, const struct dr_param_set *ps, bool carries,
                                      const struct dr_light_sample *ls)
{
    if (carries || !ls->valid || !ps || !ps->radiance_active)
        return carries;
    return dr_path_light_differentiated(ps, ls->type, ls->type == DR_LS_AREA ? s->mesh.material[ls->index] : -1);
}

bool dr_path_vertex_has_derivative(const struct dr_scene *scene, const struct dr_param_set *params,
                                   const struct dr_path_vertex *v);
/* ... but for the media: its BSDF, emission or light sample (a vertex of the
 * medium walker, v->media, may have these and a media term besides:
 * medium_grad.h's dr_medium_vertex_has_derivative). */
bool dr_path_vertex_has_surface_derivative(const struct dr_scene *scene, const struct dr_param_set *params,
                                           const struct dr_path_vertex *v);
/* Adjoint of the continuation's BSDF value f along v->wi, given d_f. */
void d_path_continuation(const struct dr_scene *scene, const struct dr_param_set *params,
                         const struct dr_path_vertex *v, dr_vec3 d_f, struct dr_grad_sink *sink);
/* Both at once: d_path_vertex_term's d_e and d_path_continuation's d_f
 * (black: that part adds nothing; d_f only where v->cont and v->diff_bsdf),
 * with one material adjoint for the two BSDF values (the same sums, added
 * to the sink once). */
void d_path_vertex(const struct dr_scene *scene, const struct dr_param_set *params, const struct dr_path_vertex *v,
                   dr_vec3 d_e, dr_vec3 d_f, struct dr_grad_sink *sink);

/* What the adjoint of a vertex's term reads where the term's derivative is
 * all in its light terms (no BSDF parameter, not the medium walker's
 * vertex): the emission it sees (the emitter's hit, or the environment's
 * lookup along d) and its next-event estimate's light sample. 448 bytes
 * against the vertex's 1032: where a light has a parameter most vertices
 * have such a term, and a tape records this instead of the vertex
 * (estimators/tape.c). */
struct dr_path_light_terms {
    enum dr_vertex_kind kind;
    bool emits, nee;
    double emit_w;
    dr_vec3 d;                     /* escaped: the ray's direction */
    struct dr_env_lookup env_at;   /* ... and the map's lookup along it, where kept */
    struct dr_hit hit;             /* surface, emitting: the emitter's hit */
    dr_vec3 nee_f;
    double nee_scale;
    struct dr_light_sample ls;
};
/* Does v's derivative term lie in its light terms alone? */
static inline bool dr_path_light_terms_hold(const struct dr_path_vertex *v)
{
    return !v->diff_bsdf && !v->media;
}
/* Where they do: *t takes them (the fields above that their adjoint reads). */
void dr_path_light_terms_take(const struct dr_path_vertex *v, struct dr_path_light_terms *t);
/* d_path_vertex_term of the vertex t was taken from: the same sums, in the
 * same order, so the same bits. */
void d_path_light_terms(const struct dr_scene *scene, const struct dr_param_set *params,
                        const struct dr_path_light_terms *t, dr_vec3 d_e, struct dr_grad_sink *sink);

/* ---- attached sampling (reparametrize-then-differentiate) ----
 *
 * The sampled directions, the hit points, the pdfs and the MIS weights move
 * with the parameters. The discrete choices stay as the primal made them
 * (which light, which environment cell, Russian roulette, zero-channel
 * substitution) and their probabilities are constants of the derivative; so
 * is the lobe-selection probability P (a lobe chosen with a P that moved
 * with the parameter would need the boundary term of the lobe threshold; a
 * fixed P makes the strategy a fixed mixture, whose density the pdf is).
 * With P fixed, the only parameter that enters the sampling (the GGX
 * visible-normal map and its density) is roughness: a path differs from its
 * detached derivative only from the first vertex whose material has a
 * requested roughness, and for every other parameter attached equals
 * detached exactly. Visibility is
 * not differentiated: a sample that crosses an occluder's edge drops a
 * boundary term, so the estimate is biased there (see the manual). */

/* Adjoint of the walker's state as a vertex receives it. */
struct dr_d_path_state {
    dr_vec3 o, d;        /* of the arriving ray */
    double prev_pdf;     /* of the BSDF density that sampled d */
    double prev_sky;     /* of the density with which the point d left samples a
                            constant sky along d (at a surface lights.h's
                            dr_sky_pdf, which moves with d and with the BSDF's pdf) */
    dr_vec3 prev_p;      /* of the point that ray left */
};

/* Does a requested parameter move material m's sampling map (its roughness
 * factor, or the image of its metallic-roughness texture)? */
bool dr_path_material_sampling_moves(const struct dr_scene *scene, const struct dr_param_set *params, int m);
/* Does any requested parameter enter a sampling map? False: attached
 * sampling is detached sampling, and runs as such. */
bool dr_path_params_enter_sampling(const struct dr_scene *scene, const struct dr_param_set *params);
/* Does vertex v's BSDF sampling depend on a requested parameter? Then its
 * BSDF density (hence its continuation's 1/pdf and the MIS weights that use
 * it) does, whichever lobe it chose, and a specular sample's direction too:
 * from this vertex on the path is attached. */
bool dr_path_vertex_sampling_moves(const struct dr_scene *scene, const struct dr_param_set *params,
                                   const struct dr_path_vertex *v);

/* Reverse mode of one vertex under attached sampling. Given d_e (adjoint of
 * the vertex term e_k, as d_path_vertex_term), d_t (adjoint of the
 * continuation factor t_k = f |cos| / pdf / q, per channel) and d_next (the
 * adjoint of the state the vertex hands on: next ray, its pdf, this point),
 * sends every parameter adjoint of the vertex to the sink (emission, lights,
 * BSDF values, pdfs, the sampling map, textures through the moving uv) and
 * sets *d_this to the adjoint of the state it received. Forward mode: d_e
 * and d_t carry one image channel, the caller sets sink->channel. opts:
 * the walk's (its params, and how it sampled a constant sky). sink NULL:
 * only *d_this is wanted (prb's Jacobian rows), the parameters' adjoints
 * are not computed. */
void d_path_vertex_attached(const struct dr_scene *scene, const struct dr_path_opts *opts,
                            const struct dr_path_vertex *v, dr_vec3 d_e, dr_vec3 d_t,
                            const struct dr_d_path_state *d_next, struct dr_d_path_state *d_this,
                            struct dr_grad_sink *sink);

struct dr_path_state {
    dr_vec3 o, d;            /* the next ray */
    double prev_pdf;         /* BSDF density of d (0: camera ray) */
    double prev_sky;         /* the density with which the point d left samples a constant sky
                                along d (at a surface lights.h's dr_sky_pdf of d's cosine to ng
                                and prev_pdf; DR_SKY_SPHERE: the camera, a point in a medium,
                                sky_uniform, a scene without an environment) */
    dr_vec3 prev_p;
    int depth;               /* segments traced so far */
    dr_vec3 beta;            /* tracing throughput (with substitutes) */
    dr_vec3 ratio;           /* true / tracing throughput, per channel: 1 or 0 */
    /* media scenes only (medium_path.c): */
    int medium;              /* the medium the ray travels in */
    int hero;                /* spectral MIS: the channel deciding collisions */
    double mis_r[3];         /* ... and each channel's event probability so far (relative) */
};

void dr_path_start(struct dr_path_state *st, dr_vec3 o, dr_vec3 d);

/* Traces the next vertex into *v and advances st (beta, ratio, next ray).
 * Returns false when the path ends with this vertex (its terms still count). */
bool dr_path_step(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_state *st,
                  struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts);

/* Next-event estimation at a shaded surface vertex: samples a light with the
 * vertex's random numbers, casts the shadow ray, and fills v->nee, v->ls,
 * v->nee_wi, v->nee_f, v->nee_scale. */
void dr_path_nee(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_vertex *v,
                 struct dr_ray_counts *counts);

/* ---- the step cut at its ray queries (for a packet tracer: render.c) ----
 *
 * dr_path_step is exactly
 *   dr_path_step_begin; trace (st->o, st->d) with dr_path_trace_key;
 *   dr_path_step_hit;  [DR_STEP_SHADOW: test the shadow ray, dr_path_nee_end];
 *   [unless DR_STEP_END: dr_path_stage_continue (below)]
 * so a caller that batches the two queries of many paths makes the same
 * decisions with the same numbers as the one-path walker. */
struct dr_shadow_ray {
    dr_vec3 o, d;
    double tmax;      /* not > 0: nothing to trace, and no contribution */
    uint64_t key;     /* coverage key (coverage.h) */
};
enum dr_step_next {
    DR_STEP_END,        /* the path ends with this vertex (its terms still count) */
    DR_STEP_SHADOW,     /* test *shadow, then dr_path_nee_end, then continue */
    DR_STEP_CONTINUE    /* go on to dr_path_step_continue */
};
/* The vertex's bookkeeping before its trace (depth, arriving ray). */
void dr_path_step_begin(struct dr_path_state *st, struct dr_path_vertex *v);
/* The coverage key of the trace at st->depth (0 without BLEND surfaces). */
uint64_t dr_path_trace_key(const struct dr_scene *scene, const struct dr_path_state *st,
                           const struct dr_sampler *sampler);
/* Counts the trace as a camera or extension ray. */
void dr_path_count_trace(const struct dr_path_state *st, struct dr_ray_counts *counts);
/* Everything between the trace (tri: its result, -1 none) and the shadow ray. */
enum dr_step_next dr_path_step_hit(const struct dr_scene *scene, const struct dr_path_opts *opts,
                                   const struct dr_path_state *st, struct dr_sampler *sampler,
                                   struct dr_path_vertex *v, int64_t tri, struct dr_shadow_ray *shadow);
/* dr_path_step_hit in two halves, for a packet tracer that prefetches what
 * shading its hits will read (dr_material_prefetch) once it knows where
 * they are: locate computes v->hit of a surface hit (nothing when tri < 0),
 * shade is the rest. */
void dr_path_step_locate(const struct dr_scene *scene, const struct dr_path_state *st, struct dr_path_vertex *v,
                         int64_t tri);
enum dr_step_next dr_path_step_shade(const struct dr_scene *scene, const struct dr_path_opts *opts,
                                     const struct dr_path_state *st, struct dr_sampler *sampler,
                                     struct dr_path_vertex *v, int64_t tri, struct dr_shadow_ray *shadow);
/* Next-event estimation in two halves around the shadow ray's query. begin:
 * false when no ray is needed (and nothing contributes). */
bool dr_path_nee_begin(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_vertex *v,
                       struct dr_shadow_ray *shadow);
void dr_path_nee_end(const struct dr_scene *scene, struct dr_path_vertex *v, const struct dr_shadow_ray *shadow,
                     bool occluded);

/* Radiance arriving at o from direction d (unit): the walker with nothing to
 * differentiate, which is what `render` computes. */
dr_vec3 dr_path_radiance(const struct dr_scene *scene, const struct dr_path_opts *opts, dr_vec3 o, dr_vec3 d,
                         struct dr_sampler *sampler, struct dr_ray_counts *counts);

/* What a ray leaving the scene at vertex `depth` sees along d: the
 * environment's radiance, and in emit_w its MIS weight against next-event
 * estimation of the environment (prev_pdf: the BSDF's pdf of d; prev_sky:
 * dr_path_state's). The escaped stage's maths; the arrays' escaped paths
 * call it directly (wave_soa.c). */
dr_vec3 dr_path_escaped_radiance(const struct dr_scene *scene, int depth, double prev_pdf, double prev_sky, dr_vec3 d,
                                 double *emit_w);
/* The prev_sky a ray sampled by a surface's BSDF with density pdf, at
 * cosine cos_g to the geometric normal, hands on, and the scattering by
 * which next-event estimation samples a constant sky at surface vertex v
 * (into *sky; NULL where it samples it uniformly). */
static inline double dr_path_leaving_sky(const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                                         double cos_g, double pdf)
{
    if (opts->sky_uniform || !(opts->stages & DR_STAGE_ENV))   /* (no sky: never read) */
        return DR_SKY_SPHERE;
    return dr_sky_pdf(dr_bsdf_sky_share(&v->bsdf, v->wo), cos_g, pdf);
}
static inline const struct dr_sky_bsdf *dr_path_sky_bsdf(const struct dr_path_opts *opts,
                                                         const struct dr_path_vertex *v, struct dr_sky_bsdf *sky)
{
    if (opts->sky_uniform)
        return NULL;
    *sky = (struct dr_sky_bsdf){&v->bsdf, v->frame, v->wo, v->ng, dr_bsdf_sky_share(&v->bsdf, v->wo)};
    return sky;
}

/* The stages, for the medium walker (medium_path.c), which strings them
 * together with free-flight sampling and boundary crossings. */
void dr_path_stage_escaped(const struct dr_scene *scene, const struct dr_path_opts *opts,
                           const struct dr_path_state *st, struct dr_path_vertex *v);
/* (located: dr_hit_locate's hit of the current ray, st->o along st->d) */
void dr_path_stage_surface_hit(const struct dr_scene *scene, const struct dr_path_opts *opts,
                               const struct dr_path_state *st, const struct dr_hit *located,
                               struct dr_path_vertex *v);
bool dr_path_stage_material(const struct dr_scene *scene, const struct dr_path_opts *opts,
                            const struct dr_path_state *st, struct dr_sampler *sampler, struct dr_path_vertex *v);
bool dr_path_stage_continue(const struct dr_path_opts *opts, struct dr_path_state *st, struct dr_path_vertex *v);
/* dr_path_step for scenes with media (medium_path.c). */
bool dr_medium_path_step(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_state *st,
                         struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts);
/* ... whose first ray query the caller has made (traced, not NULL: its
 * answer, the closest hit from st->o along st->d, unbounded, with the
 * step's coverage key; counted by the caller). */
bool dr_medium_path_step_traced(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_state *st,
                                struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts,
                                const int64_t *traced);
/* A path that has met no medium yet, handed to dr_medium_path_step after
 * st->depth segments in vacuum (the packet tracer's, wave_soa.c): its
 * medium (the global one: vacuum in the scenes it hands over from), hero
 * channel and spectral weights as if the walker had taken it from the
 * start. */
void dr_medium_path_resume(const struct dr_scene *scene, struct dr_path_state *st, const struct dr_sampler *sampler);
/* The transmittance media_nee (medium_path.c) finds for the shadow ray from
 * so along sd (unit) up to tmax of the vertex at `depth` of the path whose
 * sampler key is `key`, the vertex outside every medium (in the global one):
 * the same stream and operations, for the packet tracer's shadow rays that
 * cross a medium's box (wave_soa.c). *rays counts the queries. */
dr_vec3 dr_medium_shadow_transmittance(const struct dr_scene *scene, uint64_t key, int depth, dr_vec3 so, dr_vec3 sd,
                                       double tmax, uint64_t *rays);

/* Substitute factor for zero BSDF channels at differentiated vertices. */
#define DR_PATH_SUBSTITUTE DR_INV_PI

#endif
