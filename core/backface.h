/* Single-sided triangles whose backs no ray can reach.
 *
 * glTF's default material is single-sided: its back face is culled, so a
 * ray that meets a triangle from behind passes through. Embree cannot cull
 * by material, so accel.c tests such hits in a filter callback or after the
 * query, which costs on every hit and every blocked shadow ray (the peer's
 * box, all single-sided: 6 % of a render). Many of those tests can never
 * fail: every ray drender traces starts at a camera or at a surface point
 * it reached, lifted to the side it leaves from. A triangle whose back lies
 * where no such origin can be is never met from behind. Two sufficient
 * conditions are proved here, once per scene:
 *
 *  - the room: every vertex of the scene (so every surface point) and every
 *    viewpoint lie in front of the triangle's plane; a ray starting in front
 *    of a plane can meet it only from the front (the walls, floor and
 *    ceiling of a box seen from inside);
 *  - the closed surface: the triangle belongs to a watertight, consistently
 *    oriented, opaque (no MASK or BLEND) component, and every viewpoint is
 *    on its front side (winding number). A ray from the front side cannot
 *    cross into the back side without first stopping at one of the
 *    component's front faces, so no origin ever gets there (induction over
 *    a path's vertices).
 *
 * Both assume no ray crosses a surface: they are not applied to scenes with
 * participating media (medium boundaries are crossed) or orthographic
 * cameras (their rays start across a film plane whose size is set by the
 * render's resolution). Rays that slip through a shared edge by rounding
 * (one in ~10^7, accel.c) may meet such a back; they then stop there (a path
 * ends at a culled back face) instead of passing on: no brighter, only as
 * dark as that one path.
 *
 * The viewpoints are the scene's cameras (its default view when it has
 * none). A render from any other camera must first be admitted
 * (dr_backface_admits) or added (dr_scene_add_viewpoint). */
#ifndef DR_BACKFACE_H
#define DR_BACKFACE_H

#include <stdbool.h>
#include <stdint.h>

#include "scene.h"
#include "vec.h"

struct dr_backface;

/* The analysis of s (after dr_mesh_derive) for the viewpoints of its
 * cameras (its default view without any), those prev was made for beyond
 * them (NULL: none) and camera add (NULL: none). NULL + dr_set_error only
 * when out of memory; a scene where nothing is proved gets an analysis
 * that marks nothing. */
struct dr_backface *dr_backface_analyse(const struct dr_scene *s, const struct dr_backface *prev,
                                        const struct dr_camera *add);
void dr_backface_destroy(struct dr_backface *b);

/* Per triangle of s->mesh: nonzero where the back is unreachable (NULL:
 * none is). */
const uint8_t *dr_backface_marks(const struct dr_backface *b);
int64_t dr_backface_count(const struct dr_backface *b);
/* How many viewpoints were analysed, and the i-th. */
int dr_backface_n_viewpoints(const struct dr_backface *b);
dr_vec3 dr_backface_viewpoint(const struct dr_backface *b, int i);

/* True when rays from camera keep every marked back unreachable: it is one
 * of the analysed viewpoints, or it passes the same tests; always true when
 * nothing is marked. */
bool dr_backface_admits(const struct dr_backface *b, const struct dr_scene *s, const struct dr_camera *camera);

#endif
