/* The walker's stages for eight lanes at once (simd.h): the surface hits of
 * `render`, the bulk of its work.
 *
 * dr_path8_shade is dr_path_step_hit and dr_path8_continue is dr_path_nee_end
 * + dr_path_stage_continue for a group of eight lanes: the hit point, the
 * emission seen there and its MIS weight, the shading frame, the glTF BSDF
 * (Lambertian or with its GGX lobe; under a clear coat, composed as
 * bsdf_coat.c composes it), the light sample (area, punctual, constant sky,
 * environment map: env8.h), the shadow ray, the BSDF's continuation and
 * Russian roulette, in vector registers; eight-bit
 * textures through texture8.h. Per lane inside a group: the search of a
 * long light table, the lookups of textures texture8.h does not take (the
 * scalar material, emission and normal-map functions with the lane's hit),
 * the gathers of each lane's triangle, material and light, and the
 * stratified sampler's numbers (sampler.h: the independent and Sobol
 * samplers' are vector code). Every operation is the scalar code's, in its order, so each lane gets the
 * scalar walker's bits (test_render compares radiance in double); what the
 * kernels mirror is named beside each step. Alpha (MASK, BLEND) is the
 * queries' filters' business but for a light point's coverage (light_sample)
 * and the shadow rays' coverage keys (skey). Media stay with the
 * scalar stages, and so do vertices with a BSDF derivative term but for
 * prb's walks (dr_wave_ops.bsdf_terms): the packet tracer (wavefront.c)
 * sends each lane one way or the other.
 *
 * The kernels themselves (dr_path8_shade_lanes, dr_path8_continue_lanes)
 * take and give vectors; dr_path8_shade and dr_path8_continue gather them
 * from the lanes' structures and scatter the results back (wavefront.c),
 * wave_soa.c loads them from its arrays.
 *
 * The vertex the caller receives holds what dr_path_vertex_term reads
 * (emission, next-event estimate), what dr_path_vertex_has_derivative reads
 * and the continuation's factor (cont, f, cos_pdf_q): the eight-lane
 * stages serve `render`, prb's walks and the tape's compact steps
 * (dr_wave_ops.partial_vertices). In a run with a light parameter
 * (dr_path8_walks_apply) it also holds what d_path_vertex_term reads of a
 * vertex without a BSDF parameter: the hit of a differentiated emitter and
 * the light sample's record (dr_wave_ops.light_terms: prb's replays). */
#ifndef DR_PATH_SIMD_H
#define DR_PATH_SIMD_H

#include <stdbool.h>
#include <stdint.h>

#include "env8.h"
#include "path.h"
#include "simd.h"
#include "texture8.h"

/* A group's inputs: each lane's path state as the hit stage reads it
 * (dr_path_state's fields in vector form; lanes past n repeat lane 0). */
struct dr_path8_in {
    int n;                        /* lanes in the group */
    int64_t tri[DR_SIMD_W];       /* the triangle hit */
    dr_v3x8 o, d;                 /* the ray that hit it */
    dr_v3x8 prev_p;               /* the point that ray left */
    dr_f8 prev_pdf;               /* the BSDF density that sampled it (0: camera ray) */
    dr_f8 depth;                  /* segments so far, this one included */
    dr_u8 key;                    /* the sampler's key (independent sampler) */
    const struct dr_sampler *sampler[DR_SIMD_W];   /* each lane's sampler where it is a structured one (sobol,
                                                      stratified: its draws are taken lane by lane); NULL: key's */
    const struct dr_hit *hit[DR_SIMD_W];   /* a lane that needs the scalar hit: its hit if located (NULL: computed) */
    struct dr_hit *const *diff_hit;   /* NULL, or where each differentiated lane's hit goes (dr_path8_shade) */
    const struct dr_path8_located *located;   /* the group's hit points, if located before (NULL: computed) */
    const struct dr_path8_ahead *ahead;       /* its random numbers and light picks, if taken ahead (NULL) */
};

/* A group's hit points as the hit stage's locate finds them (the tracer
 * that locates textured hits before shading keeps them, so that shading
 * does not solve the same triangles again). */
struct dr_path8_located {
    dr_v3x8 p, ng, ns;            /* hit point, geometric and shading normal (not yet towards the ray) */
    dr_f8 eps, b1, b2;
    dr_m8 front;
    bool has_uv;                  /* uv holds the texture coordinates (the group has eight-lane lookups) */
    struct dr_uv8 uv;
};

/* A group's vertex random numbers and light-table entries, found before
 * any group of the wave is shaded (dr_path8_ahead_stage). */
struct dr_path8_ahead {
    dr_f8 u[7];                   /* the vertex's random numbers, in dr_path_step_hit's order */
    int64_t entry[DR_SIMD_W];     /* each lane's light-table entry (stage 2 on) */
    int64_t bucket[DR_SIMD_W];    /* ... its guide bucket (stages 0 and 1; -1: none) */
};

/* One GGX layer of the glTF BSDF, eight lanes of the dr_bsdf fields bsdf.c
 * reads, with what it derives from them (bsdf_alpha, dielectric_f0): the
 * base, or a clear coat's lobe (bsdf_coat.c's coat_lobe). alpha and f0 are
 * set only where the layer has a specular lobe. An anisotropic lane
 * (KHR_materials_anisotropy, aniso) stretches the lobe along the frame's
 * first axis: alpha_x = alpha + (1 - alpha) s^2 there, alpha elsewhere
 * (bsdf.c's alpha_x_of); any_aniso says whether some lane is. */
struct dr_lobe8 {
    dr_v3x8 base;                 /* base colour */
    dr_v3x8 f0;                   /* the dielectric f0 */
    dr_f8 metallic, specular, alpha, alpha_x;
    dr_m8 aniso;
    bool any_aniso;
};

/* What the two halves of a group's vertex share, lane by lane. */
struct dr_path8 {
    int n;                        /* lanes in the group (the rest repeat lane 0) */
    dr_m8 emits;                  /* the hit emits towards the ray: Le, with MIS weight emit_w */
    dr_v3x8 Le;
    dr_f8 emit_w;
    dr_m8 shadow;                 /* a shadow ray was cast (DR_STEP_SHADOW): so + t sd, t < tmax */
    dr_v3x8 so, sd;
    dr_m8 go_on;                  /* the continuation runs (not DR_STEP_END) */
    dr_m8 diff;                   /* a differentiated vertex (dr_path_vertex's diff_bsdf): its
                                     shadow ray is cast even where the BSDF towards the light is
                                     0, its zero channels are substituted (path.h) */
    dr_m8 diff_emit, diff_nee;    /* in a run with a light parameter (dr_path8_walks_apply): the
                                     emission seen here, and the light sample (where it counts:
                                     dr_path8_out's nee), have a derivative term
                                     (dr_path_vertex_has_derivative's radiance cases) */
    dr_v3x8 p, ng;                /* hit point; geometric normal on the ray's side */
    dr_v3x8 fs, ft, fn;           /* shading frame */
    dr_f8 eps, wo_z, depth;
    struct dr_lobe8 b;            /* the BSDF's base layer (base colour; the rest where glossy) */
    dr_f8 roughness;              /* the material's roughness (factor x texture; alpha is its square) */
    dr_v3x8 specular_color;       /* ... its specular colour (factor x KHR_materials_specular's texture) */
    dr_f8 bsdf_u1, bsdf_u2, rr;   /* the vertex's random numbers still to use */
    dr_f8 tmax, nee_cos, ls_pdf, bsdf_pdf;   /* next-event estimate, for its end */
    dr_m8 delta;                  /* ... from a punctual light (no MIS) */
    dr_m8 hole;                   /* ... whose light point is a hole of a cut-out emitter (no estimate) */
    uint64_t skey[DR_SIMD_W];     /* the shadow rays' coverage keys (coverage.h; 0 without alpha) */
    dr_v3x8 nee_f, ls_radiance;
    dr_v3x8 nee_wi;               /* the light's direction, local (for a differentiated vertex) */
    /* in a run with a light parameter or a differentiated vertex only:
     * which light each lane's sample took, as dr_light_sample's record
     * names it (type, index, b1, b2, atten, wi), for d_light_radiance
     * (dr_path8_continue copies it into the vertex's ls) */
    int32_t ls_type[DR_SIMD_W];
    int64_t ls_index[DR_SIMD_W];
    dr_f8 ls_b1, ls_b2, ls_atten;
    dr_v3x8 ls_wi;
    dr_m8 ls_env_valid;                 /* ... and the map's lookup at wi (lanes that sampled it) */
    struct dr_env8_lookup ls_env_at;
    /* the BSDF (bsdf.h) where some lane has a specular lobe (glossy) */
    bool glossy;
    dr_m8 lambert;                /* lanes without one */
    dr_v3x8 wo;                   /* wo local */
    dr_f8 spec_p, lobe_u;         /* the base's specular_prob at wo; the lobe's random number */
    dr_f8 anisotropy;             /* the base's anisotropy strength (dr_bsdf.anisotropy; 0 where isotropic) */
    /* the clear coat (bsdf_coat.c) where some lane has one (coated) */
    bool coated;
    dr_m8 coat_on;                /* lanes with a coat (dr_bsdf.coated) */
    dr_f8 coat, coat_roughness;   /* its factor and roughness (factor x texture); 0 and 0 on other lanes */
    dr_f8 coat_p;                 /* c Fc(wo.z): the share of samples its lobe takes (0 on other lanes) */
    struct dr_lobe8 coat_lobe;    /* its lobe: base colour 0, metallic 0, specular 1, f0 0.04 */
    /* KHR_materials_sheen's lanes (any_sheen): the base beneath the sheen
     * is the vectors' (eight-wide, the scalar base's bits), the sheen's own
     * layer bsdf.c's dr_sheen_layer_* and dr_sheen_lobe_prob lane by lane on
     * dr_material_eval's record (sheen_bsdf, the anisotropy as the frame
     * left it; a differentiated vertex's record too), composed in the
     * scalar functions' order: the bits are the one-path walker's */
    bool any_sheen;
    dr_m8 sheen_on;
    struct dr_bsdf sheen_bsdf[DR_SIMD_W];
};

/* Can this run use the eight-lane stages for every walker (no light whose
 * radiance has a parameter, no media or dielectric boundaries; some
 * light)? */
bool dr_path8_applies(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* ... for a radiance run (no parameters) in a scene with media, whose
 * paths the caller hands to the one-path walker where they could meet a
 * medium (wave_soa.c): the rest as dr_path8_applies. */
bool dr_path8_applies_outside_media(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* Can path replay's walks use them (wave_soa.h's primal walks that give
 * sums and where the derivative terms are, no vertices; its replays, whose
 * vertices then carry their light terms)? Also where a light's radiance has
 * a parameter: the stages then mark the vertices whose emission or light
 * sample has a term (dr_path8's diff_emit, diff_nee) and fill what their
 * adjoints read; not where such a light is dark (a power of 0: path_simd.c
 * says why). */
bool dr_path8_walks_apply(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* ... in a scene with media, for path replay's walks of the paths that
 * meet none, which the caller hands to the one-path walker where they could
 * (wave_soa.c): media parameters allowed (such a path has no media term),
 * the rest as dr_path8_walks_apply. */
bool dr_path8_walks_apply_outside_media(const struct dr_scene *scene, const struct dr_path_opts *opts);
/* Can a vertex on triangle tri use them without its derivative term's
 * bookkeeping (a hit, on a material without a BSDF parameter)? Such a
 * vertex has no derivative term in a run dr_path8_applies to. The arrays'
 * primal walks for path replay (wave_soa.c) and prb's walks and replays
 * in the lanes take the others too: the stages mark them (dr_path8's
 * diff), a walk's sums follow, and dr_path8_shade and dr_path8_continue
 * fill their vertices for the adjoints. */
bool dr_path8_hit(const struct dr_scene *scene, const struct dr_path_opts *opts, int64_t tri);

/* Does shading a hit on triangle tri read textures? Eight-bit base colour,
 * metallic-roughness and emissive textures are looked up eight lanes at a
 * time (texture8.h); the other lanes call the scalar material, emission and
 * normal-map functions with a scalar hit. (Vertex colours alone are no
 * texture.) */
bool dr_path8_reads_textures(const struct dr_scene *scene, int64_t tri);
/* For a tracer that locates textured hits before shading, to prefetch their
 * texels: every lane's hit point into loc, eight-wide as the hit stage's own
 * locate computes it, which shading then takes instead of solving again
 * (dr_path8_in's located); of the lanes i with want[i], the ones that need
 * the scalar hit get dr_hit_compute's (the same values) in hit[i], and
 * every lane with want[i] has the texels it will read prefetched. Every
 * lane's tri must be a triangle. */
void dr_path8_locate_hits(const struct dr_scene *scene, const int64_t *tri, dr_v3x8 o, dr_v3x8 d,
                          const bool *want, struct dr_hit *hit, struct dr_path8_located *loc);
/* dr_path_step_hit of n <= DR_SIMD_W lanes that hit a triangle: fills
 * next[i], *shadow[i] when next[i] is DR_STEP_SHADOW, the vertex term's
 * emission in *v[i], the sampler's position, and g for dr_path8_continue;
 * in a run with a light parameter also v[i]->hit's material, and the whole
 * hit (dr_hit_compute's) where the emission seen there has a term. A lane
 * on a material with a BSDF parameter (one dr_path8_hit refuses: g->diff)
 * gets what the adjoints of its terms read, as the scalar stages set it:
 * diff_bsdf, shaded, the hit (dr_hit_compute's with the normal map
 * applied, but for t, here the distance to p: nothing reads it), ng, frame, wo,
 * bsdf, and for its light sample nee_wi and nee_bsdf_pdf (dr_path8_continue
 * adds the record and the continuation's wi, pdf, s and sub); not its
 * random numbers u or lobe, which only attached and derivative sampling
 * read, and those walk one path at a time.
 * located: v[i]->hit already holds the hit of each lane that reads textures
 * (dr_path_step_locate, so that its texels could be prefetched). */
void dr_path8_shade(const struct dr_scene *scene, const struct dr_path_opts *opts, int n,
                    struct dr_path_state *const *st, struct dr_sampler *const *sampler,
                    struct dr_path_vertex *const *v, const int64_t *tri, struct dr_shadow_ray *const *shadow,
                    enum dr_step_next *next, bool located, struct dr_path8 *g);
/* Light picks ahead. In a scene with many emitting triangles (thousands:
 * an emissive texture on a mesh) each lane's light sample follows a chain
 * of dependent reads (guide table, CDF, entry, triangle, its vertices),
 * each likely a cache miss. A tracer with a wave of
 * groups runs stage k (0 .. DR_PATH8_AHEAD_STAGES - 1) of every group
 * before stage k + 1 of any, so that the misses of a stage overlap and have
 * arrived when the next stage reads them; shading then takes the result
 * (dr_path8_in's ahead) and finds the same entries with the same random
 * numbers as it would have itself, so no result changes. The function
 * says whether the light table is long enough for this to pay (else
 * nothing is taken ahead). */
#define DR_PATH8_AHEAD_STAGES 5
bool dr_path8_picks_ahead(const struct dr_scene *scene);
void dr_path8_ahead_stage(const struct dr_scene *scene, const struct dr_path8_in *in, int stage,
                          struct dr_path8_ahead *a);
/* Rays leaving the scene: dr_path8_escaped_term gives the terms of the
 * lanes of on at once (0 in the others), the escaped vertex's radiance
 * times its MIS weight (dr_path_escaped_radiance), zero without the
 * environment stage, with the scalar code's operations: a constant
 * environment's, or a map's through env8.h. d, depth, prev_pdf and
 * prev_sky: the path state's after the ray was traced. dr_path8_env_eight says whether
 * the scene's environment is one of those two (an environment map's light
 * tables exist whenever the scene has one). */
bool dr_path8_env_eight(const struct dr_scene *scene);
/* The same lanes' radiance and MIS weight apart (stage_escaped's Le and
 * emit_w, for a vertex), where the environment stage runs; true when the
 * map's lookup is in *at (an environment map; at not NULL). */
bool dr_path8_escaped(const struct dr_scene *scene, dr_m8 on, dr_v3x8 d, dr_f8 depth, dr_f8 prev_pdf,
                      dr_f8 prev_sky, dr_v3x8 *Le, dr_f8 *emit_w, struct dr_env8_lookup *at);
dr_v3x8 dr_path8_escaped_term(const struct dr_scene *scene, const struct dr_path_opts *opts, dr_m8 on, dr_v3x8 d,
                              dr_f8 depth, dr_f8 prev_pdf, dr_f8 prev_sky);
/* The hit stage of a group from its inputs, into g (the same as
 * dr_path8_shade, for a caller that keeps its paths' state in arrays). */
void dr_path8_shade_lanes(const struct dr_scene *scene, const struct dr_path_opts *opts,
                          const struct dr_path8_in *in, struct dr_path8 *g);

/* What dr_path8_continue_lanes gives each lane. */
struct dr_path8_out {
    dr_m8 nee;                    /* the next-event estimate counts (dr_path_vertex's nee) */
    dr_f8 nee_scale;
    dr_m8 more;                   /* the path goes on; then: */
    dr_v3x8 wi;                   /* the continuation's direction, local */
    dr_v3x8 f;                    /* ... its BSDF value */
    dr_m8 sub[3];                 /* ... channels substituted here (path.h; differentiated vertices) */
    dr_f8 cos_pdf_q;              /* ... and |cos| / pdf / q */
    dr_v3x8 beta;                 /* the next throughput (with substitutes) */
    dr_v3x8 ratio;                /* the next true / tracing throughput ratio (0 where substituted) */
    dr_v3x8 o, d;                 /* the next ray */
    dr_f8 prev_pdf;               /* its density (the next prev_p is g->p) */
    dr_f8 prev_sky;               /* a constant sky's density along it from here (dr_path_state's) */
};
/* dr_path8_continue from the arriving throughput beta, ratio (NULL: 1, no
 * channel substituted yet; a walk with parameters passes its paths') and
 * the shadow rays' answers, into out. */
void dr_path8_continue_lanes(const struct dr_path_opts *opts, const struct dr_path8 *g, dr_v3x8 beta,
                             const dr_v3x8 *ratio, dr_m8 occluded, struct dr_path8_out *out);
/* Each lane's vertex term e_k (dr_path_vertex_term) after the continuation. */
dr_v3x8 dr_path8_term(const struct dr_path8 *g, const struct dr_path8_out *out);

/* Lane i's vertex as dr_path8_shade and dr_path8_continue leave it, for a
 * caller that keeps its paths in arrays (wave_soa.c's replays): v begun as
 * dr_path_step_begin begins it, where g->diff[i] its hit already in v->hit
 * (dr_path8_in's diff_hit); o, d: the ray that hit tri (v's o and d,
 * passed on so that they are not read back just after being written). */
void dr_path8_vertex(const struct dr_scene *scene, const struct dr_path_opts *opts, const struct dr_path8 *g,
                     const struct dr_path8_out *out, int i, int64_t tri, dr_vec3 o, dr_vec3 d,
                     struct dr_path_vertex *v);

/* dr_path_nee_end (occluded[i]: the shadow ray's answer) and
 * dr_path_stage_continue of the same lanes: the next-event estimate in
 * *v[i], the next ray and throughput in *st[i]; more[i]: the path goes on.
 * Where a lane is differentiated (g->diff) also st[i]->ratio, and in v[i]
 * the light sample's record and the continuation's wi, pdf, s and sub. */
void dr_path8_continue(const struct dr_path_opts *opts, const struct dr_path8 *g, struct dr_path_state *const *st,
                       struct dr_path_vertex *const *v, const bool *occluded, bool *more);

#endif
