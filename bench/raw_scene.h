/* The Embree scene the bench's raw ceilings trace (raw_embree.c,
 * path_rays.c): the scene's triangles in one geometry, built as drender
 * builds its own (core/accel_build.h) but without its coverage filter. */
#ifndef DR_BENCH_RAW_SCENE_H
#define DR_BENCH_RAW_SCENE_H

#include <embree3/rtcore.h>

#include "accel_build.h"
#include "scene.h"

static inline RTCScene bench_raw_scene(RTCDevice dev, const struct dr_scene *scene)
{
    RTCScene es = rtcNewScene(dev);
    rtcSetSceneFlags(es, DR_ACCEL_SCENE_FLAGS);
    rtcSetSceneBuildQuality(es, DR_ACCEL_BUILD_QUALITY);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, scene->mesh.positions, 0,
                               3 * sizeof(float), scene->mesh.n_vertices);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, scene->mesh.indices, 0,
                               3 * sizeof(uint32_t), scene->mesh.n_triangles);
    rtcCommitGeometry(g);
    rtcAttachGeometry(es, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(es);
    return es;
}

#endif
