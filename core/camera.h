/* Camera rays: pinhole (perspective) or parallel (orthographic). */
#ifndef DR_CAMERA_H
#define DR_CAMERA_H

#include "scene.h"
#include "vec.h"

/* A camera set up for one film size: per-pixel steps precomputed. */
struct dr_camera_view {
    dr_vec3 origin;     /* the pinhole; orthographic: the film plane's point (0, 0) */
    dr_vec3 corner;     /* direction (unnormalised) through film point (0, 0); orthographic: forward */
    dr_vec3 step_x;     /* change of that direction (orthographic: of the origin) per pixel to the right */
    dr_vec3 step_y;     /* ... per pixel down */
    bool orthographic;
};

/* Perspective: the vertical field of view is cam->yfov; orthographic: the
 * view is 2 ymag high. The horizontal extent follows width/height (square pixels). */
struct dr_camera_view dr_camera_view(const struct dr_camera *cam, int width, int height);

/* The ray through film position (fx, fy) in pixels: (0,0) is the top-left
 * corner of the image, x right, y down. *d is unit. */
static inline void dr_camera_ray(const struct dr_camera_view *v, double fx, double fy, dr_vec3 *o, dr_vec3 *d)
{
    dr_vec3 film = dr_add(dr_scale(v->step_x, fx), dr_scale(v->step_y, fy));
    if (v->orthographic) {
        *o = dr_add(v->origin, film);
        *d = v->corner;
        return;
    }
    *o = v->origin;
    *d = dr_normalize(dr_add(v->corner, film));
}

/* A camera that frames the scene's bounding box from +Z (glTF's "front"),
 * for files that have none. */
struct dr_camera dr_camera_default(const struct dr_scene *scene);

#endif
