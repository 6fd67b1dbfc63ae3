/* Pinhole camera rays. */
#ifndef DR_CAMERA_H
#define DR_CAMERA_H

#include "scene.h"
#include "vec.h"

/* Unit direction through film position (fx, fy) in pixels (0,0 = top-left
 * corner of the image, x right, y down) for a width x height film: the
 * vertical field of view is cam->yfov, the horizontal one follows width/height. */
dr_vec3 dr_camera_direction(const struct dr_camera *cam, int width, int height, double fx, double fy);

/* A camera that frames the scene's bounding box from +Z (glTF's "front"),
 * for files that have none. */
struct dr_camera dr_camera_default(const struct dr_scene *scene);

#endif
