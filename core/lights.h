/* Light sources and next-event estimation: one discrete distribution over all
 * of them (emissive triangles, punctual lights, the environment), chosen by
 * estimated power, plus the densities MIS needs when a BSDF-sampled ray
 * reaches an emitter or escapes. */
#ifndef DR_LIGHTS_H
#define DR_LIGHTS_H

#include <stdbool.h>

#include "bsdf.h"
#include "geometry.h"
#include "grad_sink.h"
#include "params.h"
#include "scene.h"
#include "vec.h"

struct dr_light_sampler;

enum { DR_LS_AREA, DR_LS_PUNCTUAL, DR_LS_ENV };

/* An environment map's lookup along a direction, kept by whoever made it so
 * that the adjoint need not make it again (d_env_radiance_at): the map
 * coordinates dr_env_dir_to_uv gives and dr_texture_eval's texel blend
 * there, as doubles (valid: they are there; never with a constant sky). */
struct dr_env_lookup {
    bool valid;
    double u, v;
    dr_vec3 map;
};

struct dr_light_sample {
    dr_vec3 wi;        /* unit direction from the shading point towards the light */
    double dist;       /* distance to the light point (INFINITY: environment/directional) */
    dr_vec3 radiance;  /* radiance (area, environment) or irradiance-like value
                          (punctual: intensity / dist^2 with falloff) arriving along wi */
    double pdf;        /* solid-angle density including the choice of light;
                          for delta lights, the probability of choosing it */
    bool delta;        /* punctual: no MIS, no BSDF-sampled counterpart */
    /* which light, for derivatives: */
    int type;          /* DR_LS_AREA, DR_LS_PUNCTUAL, DR_LS_ENV */
    int64_t index;     /* emissive triangle, or index into scene->lights */
    double b1, b2;     /* area: barycentrics of the light point */
    double atten;      /* punctual: radiance = color * intensity * atten */
    int lobe;          /* a constant sky sampled by the BSDF half of dr_sky_pdf: its
                          lobe (attached sampling moves that sample as the
                          continuation's; the scalar walker's record, which those
                          adjoints read); else -1 */
    dr_vec3 target;    /* finite lights: the light point, pushed off the light's
                          surface towards the shading point (see dr_offset_origin);
                          shadow rays end here */
    struct dr_env_lookup env_at;   /* environment map: the lookup at wi, where the eight-lane
                                      stages kept it (dr_light_sample clears it) */
    bool valid;        /* the fields above are set, even where the sample carries no light
                          (black radiance: its derivative need not be 0, dr_path_light_kept) */
};

/* Builds the tables; scene->accel need not exist. NULL + dr_last_error. */
struct dr_light_sampler *dr_light_sampler_create(const struct dr_scene *scene);
void dr_light_sampler_destroy(struct dr_light_sampler *ls);
/* How many whole-image passes (emissive textures' grids, emission_grid.h)
 * building ls took: at most one per image, whatever the number of emitting
 * triangles. */
int dr_light_sampler_texture_averages(const struct dr_light_sampler *ls);
bool dr_light_sampler_empty(const struct dr_light_sampler *ls);

/* A surface point's scattering (its BSDF, shading frame and wo, local) and
 * geometric normal on wo's side, by which next-event estimation samples a
 * constant sky there. */
struct dr_sky_bsdf {
    const struct dr_bsdf *bsdf;
    dr_frame frame;
    dr_vec3 wo, ng;
    double share;   /* dr_bsdf_sky_share(bsdf, wo) */
};

/* The density with which a constant sky is sampled from a surface point
 * along a direction with cosine cos_g to its geometric normal, where its
 * BSDF's density is pdf_b: a share (dr_bsdf_sky_share) by the BSDF, the
 * rest by the cosine (cos / pi). The cosine makes a diffuse surface open to
 * the sky exact and suits broad lobes; a sharp glossy lobe needs the BSDF's
 * own samples (measured: bench part o and the note of this change). */
static inline double dr_sky_pdf(double share, double cos_g, double pdf_b)
{
    return (1.0 - share) * ((cos_g > 0.0 ? cos_g : 0.0) * (1.0 / M_PI)) + share * pdf_b;
}

/* Samples a light as seen from point p with three uniforms. False when there
 * is nothing to sample or the sample carries no light (out->valid tells the
 * two apart). A constant sky is sampled from a surface by sky's mixture
 * (dr_sky_pdf; u_pick rescaled within the sky's share of the pick chooses
 * the half and the BSDF's lobe); sky NULL (a point in a medium): over the
 * sphere. */
bool dr_light_sample(const struct dr_scene *scene, const struct dr_light_sampler *ls, dr_vec3 p,
                     const struct dr_sky_bsdf *sky, double u_pick, double u1, double u2,
                     struct dr_light_sample *out);
/* Adjoint of the radiance a light sample carries (area, punctual or
 * environment) into that light's requested parameters; none requested: no work. */
void d_light_radiance(const struct dr_scene *scene, const struct dr_param_set *params,
                      const struct dr_light_sample *ls, dr_vec3 d_L, struct dr_grad_sink *sink);

/* Solid-angle density with which dr_light_sample would produce the point
 * `hit` on an emissive triangle as seen from `from`. */
double dr_light_pdf_area(const struct dr_scene *scene, const struct dr_light_sampler *ls, dr_vec3 from,
                         const struct dr_hit *hit);
/* Are all of material's triangles entries of ls? Not where it emits
 * nothing (factor x strength black), nor where some of its triangles can
 * read only black texels of its emissive texture (emission_grid.h: left out
 * of the table). The one-path walker still counts such triangles' hits as
 * emitting where the emission has a parameter (path.c's surface_emits). */
bool dr_light_material_emits(const struct dr_light_sampler *ls, int material);
/* Probability that NEE picks triangle tri (0: it does not emit). */
double dr_light_pdf_area_pick(const struct dr_light_sampler *ls, int64_t tri);
/* The sampler's tables, for a packet tracer that samples many lanes' lights
 * at once (path_simd.c does what dr_light_sample and dr_light_pdf_area do for
 * emitting triangles and a constant environment with these, env8.c for an
 * environment map; punctual lights go through dr_light_sample).
 * False when there is nothing to sample. */
struct dr_light_tables {
    int64_t n_entries;
    int64_t n_emitters;             /* entries below this are emitting triangles */
    const double *cdf;              /* n_entries + 1, and its guide table (cdf.h) */
    const uint32_t *cdf_guide;
    const double *pick;             /* per entry: its probability */
    const int64_t *emitter_tri;     /* per entry: its triangle */
    const double *emitter_area;     /* per entry */
    const uint32_t *emitter_sub;    /* per entry: 0, or the part of its triangle (dr_light_part_point) */
    bool any_parts;                 /* some entry is a part */
    const double *tri_pick;         /* per triangle, as dr_light_pdf_area_pick */
    const double *tri_pick_density; /* per triangle: pick probability / area; -1 where its
                                       parts are entries (dr_light_area_density) */
    int64_t env_uniform_entry;      /* the environment's entry when it is constant (sampled
                                       uniformly over the sphere, dr_light_sample's
                                       sample_env), else -1 */
    int64_t env_map_entry;          /* the environment's entry when it has a map (env8.h), else -1 */
};
bool dr_light_tables(const struct dr_light_sampler *ls, struct dr_light_tables *t);

/* Parts of emitting triangles. A large emitter whose emissive texture holds
 * black texels over it is divided for the light table (midpoint
 * subdivision, up to DR_LIGHT_MAX_LEVEL times), and each part is an entry
 * weighted by its own footprint (emission_grid.h): next-event estimation
 * then draws the light points among the texels that glow, and leaves out
 * parts that can only read black ones. A part is sampled uniformly, so the
 * density at a point is its part's pick over its area. */
#define DR_LIGHT_MAX_LEVEL 6
/* All triangles' parts together at most this many (each costs an entry,
 * about 60 bytes with its build): a texture tiled over many large
 * triangles divides the first ones only. */
#define DR_LIGHT_MAX_PARTS (1 << 18)
/* Maps (b1, b2) in part `sub` (an entry's emitter_sub, not 0) to its triangle's. */
void dr_light_part_point(uint32_t sub, double *b1, double *b2);
/* The part of the triangle's 4^level that holds (b1, b2), as a code (sub >> 3). */
uint32_t dr_light_part_locate(unsigned level, double b1, double b2);
/* Pick probability per area at the point (b1, b2) of triangle tri (0: not an entry there). */
double dr_light_area_density(const struct dr_light_sampler *ls, int64_t tri, double b1, double b2);
/* The environment map's sampling tables, for env8.c's eight-lane copies of
 * its sampling and density: piecewise constant over the w x h texels, rows
 * by the marginal cdf, columns by each row's conditional one. False when
 * the sampler has no environment map (or no environment entry). */
struct dr_env_tables {
    int w, h;
    const double *marginal;             /* h + 1, and its guide table (cdf.h) */
    const uint32_t *marginal_guide;
    const double *conditional;          /* h rows of w + 1, and their guide tables */
    const uint32_t *conditional_guide;
    const double *row_sin;              /* h: each row's centre sine, the density's factor */
    double pick;                        /* the environment entry's probability */
};
bool dr_light_env_tables(const struct dr_light_sampler *ls, struct dr_env_tables *t);
/* The density per solid angle with which a point's next-event estimation
 * draws a constant sky along a direction, before the light pick: at a
 * surface dr_sky_pdf, at a point in a medium (or where a path starts)
 * this, the sphere's. */
#define DR_SKY_SPHERE (1.0 / (4.0 * M_PI))
/* Density with which dr_light_sample would give direction dir (the
 * environment) from a point whose own density for a constant sky along dir
 * is sky_pdf (DR_SKY_SPHERE: none). */
double dr_light_pdf_env(const struct dr_scene *scene, const struct dr_light_sampler *ls, dr_vec3 dir,
                        double sky_pdf);
/* Its derivative with respect to sky_pdf (the sky's pick; a map's density
 * does not depend on it). */
double dr_light_pdf_env_dsky(const struct dr_light_sampler *ls);

/* Radiance emitted by the surface at hit towards the side the ray came from
 * (zero on the back of single-sided materials). */
dr_vec3 dr_emission(const struct dr_scene *scene, const struct dr_hit *hit);
/* Asks the cache for the texels dr_emission(scene, hit) will read (none
 * without an emissive texture). Changes no result. */
void dr_emission_prefetch(const struct dr_scene *scene, const struct dr_hit *hit);
/* Adjoint: d_Le into the hit material's requested emission parameters. */
void d_emission(const struct dr_scene *scene, const struct dr_param_set *params, const struct dr_hit *hit,
                dr_vec3 d_Le, struct dr_grad_sink *sink);
/* Environment radiance arriving from direction -dir... i.e. seen along dir. */
dr_vec3 dr_env_radiance(const struct dr_scene *scene, dr_vec3 dir);
/* dr_env_radiance(dir), and dr_light_pdf_env(dir) into *pdf unless pdf is
 * NULL, with the direction's map coordinates computed once (the same values
 * as the two calls: a ray leaving the scene needs both). */
dr_vec3 dr_env_radiance_pdf(const struct dr_scene *scene, const struct dr_light_sampler *ls, dr_vec3 dir,
                            double sky_pdf, double *pdf);
/* Adjoint: d_L into the requested environment colour, strength and texels. */
void d_env_radiance(const struct dr_scene *scene, const struct dr_param_set *params, dr_vec3 dir, dr_vec3 d_L,
                    struct dr_grad_sink *sink);
/* The same with the map's lookup along dir given (at->valid; the same
 * result as d_env_radiance(dir) when at holds dir's lookup). */
void d_env_radiance_at(const struct dr_scene *scene, const struct dr_param_set *params,
                       const struct dr_env_lookup *at, dr_vec3 d_L, struct dr_grad_sink *sink);

/* ---- adjoints with respect to points and directions (attached sampling) ---- */

/* Reverse mode of dr_light_sample with respect to the shading point p, for
 * the sample *ls it returned (the light, the point on it and the environment
 * cell are discrete choices and stay fixed): d_wi, d_pdf and d_radiance of
 * the sample into *d_p (+=). Environment and directional samples do not
 * depend on p (zero). */
void d_light_sample_point(const struct dr_scene *scene, dr_vec3 p, const struct dr_light_sample *ls, dr_vec3 d_wi,
                          double d_pdf, dr_vec3 d_radiance, dr_vec3 *d_p);
/* Reverse mode of dr_light_pdf_area with respect to `from` and hit->p (the
 * emitter's ng is constant). */
void d_light_pdf_area_points(const struct dr_scene *scene, const struct dr_light_sampler *ls, dr_vec3 from,
                             const struct dr_hit *hit, double d_pdf, dr_vec3 *d_from, dr_vec3 *d_hit_p);
/* Reverse mode of dr_emission with respect to the hit's uv sets (an emissive
 * texture, through its transform): into d_hit->uv or uv1 (+=). */
void d_emission_uv(const struct dr_scene *scene, const struct dr_hit *hit, dr_vec3 d_Le, struct dr_d_hit *d_hit);
/* Reverse mode of dr_env_radiance with respect to the direction (bilinear
 * map lookup through the equirectangular mapping). dr_light_pdf_env is
 * piecewise constant in the direction (per map cell): no adjoint. */
void d_env_radiance_dir(const struct dr_scene *scene, dr_vec3 dir, dr_vec3 d_L, dr_vec3 *d_dir);
/* Reverse mode of dr_env_dir_to_uv (zero at the poles, where u is undefined). */
void d_env_dir_to_uv(dr_vec3 dir, double d_u, double d_v, dr_vec3 *d_dir);

/* Equirectangular mapping (+Y up; u = 0.5 looks down -Z, u grows towards +X;
 * v = 0 is straight up). */
void dr_env_dir_to_uv(dr_vec3 dir, double *u, double *v);
dr_vec3 dr_env_uv_to_dir(double u, double v);

#endif
