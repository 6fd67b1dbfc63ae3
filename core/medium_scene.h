/* Participating media in a scene: preparation, checks, and the queries the
 * path walker makes where media exist (medium_path.c). Nothing here runs for
 * a scene without media (dr_path_plan leaves DR_STAGE_MEDIA unset). */
#ifndef DR_MEDIUM_SCENE_H
#define DR_MEDIUM_SCENE_H

#include "medium.h"
#include "sampler.h"
#include "scene.h"

/* After loading: grid boxes of mesh media (the mesh's bounds unless given),
 * closedness of every medium boundary. 0 or DR_ERR_* naming file and JSON path. */
int dr_media_prepare(struct dr_scene *scene);
/* After parameters changed: majorants, effect flags. 0 or DR_ERR_NOMEM. */
int dr_media_refresh(struct dr_scene *scene);
void dr_media_release(struct dr_scene *scene);

/* The medium bounded by triangle tri's material, -1: an ordinary surface. */
static inline int dr_boundary_medium(const struct dr_scene *s, int64_t tri)
{
    return s->material_medium[s->mesh.material[tri]];
}

/* Is medium med (>= 0) bounded by a dielectric? Only scenes with the effect
 * look at the medium: the others run as before. */
static inline bool dr_boundary_dielectric(const struct dr_scene *s, int med)
{
    return (s->effects & DR_FX_DIELECTRIC_BOUNDARIES) && s->media[med].ior > 0.0;
}

/* The packet tracer's tests (wave_soa.c), which keep the paths that meet
 * no medium on its eight-lane stages: every medium bounded by a mesh (no
 * global medium: each then has a box, dr_medium's bmin, bmax); point p in
 * some medium's box, where a path could start in a medium. Conservative:
 * the box holds the boundary. */
bool dr_media_all_bounded(const struct dr_scene *scene);
bool dr_media_box_holds(const struct dr_scene *scene, dr_vec3 p);

/* The medium containing point o (-1: vacuum): the first medium boundary along
 * direction d says (its back seen: inside it). */
int dr_medium_at(const struct dr_scene *scene, dr_vec3 o, dr_vec3 d);

/* Transmittance from o along d (unit) over distance tmax (INFINITY: to the
 * environment) starting in medium `medium`, through index-matched
 * boundaries; 0 when an ordinary surface or a dielectric boundary (a
 * specular interface, which no straight shadow ray crosses) is in the way. *rays counts the
 * ray queries. Unbiased, not always exact: a ray that starts deep in a
 * homogeneous medium plays Russian roulette (medium_scene.c). */
struct dr_medium_trace;
/* The key a shadow ray with tracking stream rng decides coverage by (BLEND
 * surfaces crossed, a cut-out emitter's light point: coverage.h). */
static inline uint64_t dr_media_shadow_key(const struct dr_sampler *rng)
{
    return dr_hash64(rng->key ^ 0x5851f42d4c957f2dULL);
}
/* rec (may be NULL): records the medium pieces crossed, for derivatives. */
dr_vec3 dr_media_transmittance(const struct dr_scene *scene, dr_vec3 o, dr_vec3 d, double tmax, int medium,
                               struct dr_sampler *rng, uint64_t *rays, struct dr_medium_trace *rec);
/* Appends a piece to rec (if there is room). */
void dr_medium_trace_add(struct dr_medium_trace *rec, int medium, uint32_t rng_dim, dr_vec3 o, double len);

#endif
