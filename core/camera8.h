/* dr_camera_ray (camera.h) for eight film positions at once (simd.h), with
 * its operations in its order: each lane gets the scalar ray's bits. */
#ifndef DR_CAMERA8_H
#define DR_CAMERA8_H

#include "camera.h"
#include "simd.h"

DR_SIMD_INLINE void dr_camera_ray8(const struct dr_camera_view *v, dr_f8 fx, dr_f8 fy, dr_v3x8 *o, dr_v3x8 *d)
{
    const dr_v3x8 film = dr_v3x8_add(dr_v3x8_scale(dr_v3x8_splat(v->step_x), fx),
                                     dr_v3x8_scale(dr_v3x8_splat(v->step_y), fy));
    if (v->orthographic) {
        *o = dr_v3x8_add(dr_v3x8_splat(v->origin), film);
        *d = dr_v3x8_splat(v->corner);
        return;
    }
    *o = dr_v3x8_splat(v->origin);
    const dr_v3x8 a = dr_v3x8_add(dr_v3x8_splat(v->corner), film);   /* dr_normalize(a) */
    const dr_f8 l = dr_f8_sqrt(dr_v3x8_dot(a, a));
    const dr_m8 pos = dr_f8_gt(l, dr_f8s(0.0));
    *d = dr_v3x8_sel(pos, dr_v3x8_scale(a, 1.0 / dr_f8_sel(pos, l, dr_f8s(1.0))), a);
}

#endif
