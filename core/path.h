/* The path walker: one vertex of a path at a time, with everything the
 * primal pass, the path-replay pass and the tape need. All three call
 * dr_path_step with the same random numbers and so make bit-identical
 * decisions (Russian roulette included).
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

#include "bsdf.h"
#include "geometry.h"
#include "integrator.h"
#include "lights.h"
#include "params.h"
#include "sampler.h"
#include "scene.h"

enum dr_vertex_kind {
    DR_VERTEX_SURFACE,   /* the ray hit a triangle */
    DR_VERTEX_ESCAPED    /* the ray left the scene (environment radiance, if any) */
};

struct dr_path_vertex {
    enum dr_vertex_kind kind;
    int depth;                 /* segments so far (1: the camera ray's hit) */
    dr_vec3 d;                 /* direction of the ray that arrived here */
    struct dr_hit hit;
    /* emission seen here (surface) or environment radiance (escaped) */
    bool emits;                /* Le is evaluated (and differentiable) here */
    dr_vec3 Le;
    double emit_w;             /* its MIS weight */
    /* shading */
    bool shaded;               /* the BSDF was evaluated (surface, depth < max) */
    bool diff_bsdf;            /* its material has a requested parameter */
    struct dr_bsdf bsdf;
    dr_frame frame;
    dr_vec3 wo;                /* local */
    /* next-event estimation */
    bool nee;                  /* a light sample contributes (unoccluded, f != 0 ...) */
    struct dr_light_sample ls;
    dr_vec3 nee_wi;            /* local */
    dr_vec3 nee_f;             /* BSDF value towards the light */
    double nee_scale;          /* |cos| * MIS weight / pdf */
    /* continuation */
    bool cont;                 /* the path goes on from here */
    dr_vec3 wi;                /* local, sampled */
    dr_vec3 f;                 /* BSDF value along wi */
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

struct dr_path_opts {
    int max_depth, rr_depth;
    const struct dr_param_set *params;   /* NULL: primal only (no substitution) */
};

struct dr_path_state {
    dr_vec3 o, d;            /* the next ray */
    double prev_pdf;         /* BSDF density of d (0: camera ray) */
    dr_vec3 prev_p;
    int depth;               /* segments traced so far */
    dr_vec3 beta;            /* tracing throughput (with substitutes) */
    dr_vec3 ratio;           /* true / tracing throughput, per channel: 1 or 0 */
};

void dr_path_start(struct dr_path_state *st, dr_vec3 o, dr_vec3 d);

/* Traces the next vertex into *v and advances st (beta, ratio, next ray).
 * Returns false when the path ends with this vertex (its terms still count). */
bool dr_path_step(const struct dr_scene *scene, const struct dr_path_opts *opts, struct dr_path_state *st,
                  struct dr_sampler *sampler, struct dr_path_vertex *v, struct dr_ray_counts *counts);

/* Substitute factor for zero BSDF channels at differentiated vertices. */
#define DR_PATH_SUBSTITUTE DR_INV_PI

#endif
