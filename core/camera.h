/* Pinhole camera rays. */
#ifndef DR_CAMERA_H
#define DR_CAMERA_H

#include "scene.h"
#include "vec.h"

/* A camera set up for one film size: per-pixel steps precomputed. */
struct dr_camera_view {
    dr_vec3 origin;
    dr_vec3 corner;     /* direction (unnormalised) through film point (0, 0) */
    dr_vec3 step_x;     /* change of that direction per pixel to the right */
    dr_vec3 step_y;     /* ... per pixel down */
};

/* The vertical field of view is cam->yfov; the horizontal one follows
 * width/height (square pixels). */
struct dr_camera_view dr_camera_view(const struct dr_camera *cam, int width, int height);

/* Unit direction through film position (fx, fy) in pixels: (0,0) is the
 * top-left corner of the image, x right, y down. */
static inline dr_vec3 dr_camera_direction(const struct dr_camera_view *v, double fx, double fy)
{
    return dr_normalize(dr_add(v->corner, dr_add(dr_scale(v->step_x, fx), dr_scale(v->step_y, fy))));
}

/* A camera that frames the scene's bounding box from +Z (glTF's "front"),
 * for files that have none. */
struct dr_camera dr_camera_default(const struct dr_scene *scene);

#endif
