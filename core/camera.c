#include "camera.h"

#include <string.h>

struct dr_camera_view dr_camera_view(const struct dr_camera *cam, int width, int height)
{
    struct dr_camera_view v;
    if (cam->orthographic) {
        /* film point (fx, fy) -> origin + (2 fx / w - 1) xm right + (1 - 2 fy / h) ym up */
        double ym = cam->ymag, xm = ym * ((double)width / height);
        v.orthographic = true;
        v.origin = dr_add(cam->origin, dr_sub(dr_scale(cam->up, ym), dr_scale(cam->right, xm)));
        v.corner = cam->forward;
        v.step_x = dr_scale(cam->right, 2.0 * xm / width);
        v.step_y = dr_scale(cam->up, -2.0 * ym / height);
        return v;
    }
    double th = tan(0.5 * cam->yfov), tw = th * ((double)width / height);
    v.orthographic = false;
    v.origin = cam->origin;
    /* film point (fx, fy) -> forward + (2 fx / w - 1) tw right + (1 - 2 fy / h) th up */
    v.corner = dr_add(cam->forward, dr_sub(dr_scale(cam->up, th), dr_scale(cam->right, tw)));
    v.step_x = dr_scale(cam->right, 2.0 * tw / width);
    v.step_y = dr_scale(cam->up, -2.0 * th / height);
    return v;
}

struct dr_camera dr_camera_default(const struct dr_scene *scene)
{
    struct dr_camera c;
    memset(&c, 0, sizeof c);
    strcpy(c.name, "default");
    c.gltf_index = -1;
    dr_vec3 center = dr_scale(dr_add(scene->bbox_min, scene->bbox_max), 0.5);
    double radius = 0.5 * dr_length(dr_sub(scene->bbox_max, scene->bbox_min));
    if (!(radius > 0.0))
        radius = 1.0;
    c.yfov = 45.0 * M_PI / 180.0;
    /* distance at which the bounding sphere fits the vertical field of view */
    double dist = radius / sin(0.5 * c.yfov);
    c.origin = dr_add(center, dr_v3(0, 0, dist));
    c.forward = dr_v3(0, 0, -1);
    c.up = dr_v3(0, 1, 0);
    c.right = dr_v3(1, 0, 0);
    return c;
}
