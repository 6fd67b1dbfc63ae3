#include "accel.h"

#include <embree3/rtcore.h>
#include <float.h>
#include <stdio.h>
#include <stdlib.h>

#include "error.h"

struct dr_accel {
    RTCDevice device;
    RTCScene scene;
};

static void embree_error(void *user, enum RTCError code, const char *msg)
{
    (void)user;
    dr_set_error("Embree error %d: %s", (int)code, msg ? msg : "");
}

struct dr_accel *dr_accel_create(const struct dr_mesh *mesh)
{
    struct dr_accel *a = calloc(1, sizeof *a);
    if (!a) {
        dr_set_error("out of memory");
        return NULL;
    }
    a->device = rtcNewDevice(NULL);
    if (!a->device) {
        dr_set_error("cannot create the Embree device");
        free(a);
        return NULL;
    }
    rtcSetDeviceErrorFunction(a->device, embree_error, NULL);
    a->scene = rtcNewScene(a->device);
    /* Robust mode: no missed hits on shared edges, which would leak light. */
    rtcSetSceneFlags(a->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(a->scene, RTC_BUILD_QUALITY_HIGH);
    if (mesh->n_triangles > 0) {
        RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_TRIANGLE);
        /* Shared buffers: the mesh arrays are used in place (positions carry
         * the one float of padding Embree's 16-byte loads need). */
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, mesh->positions, 0,
                                   3 * sizeof(float), mesh->n_vertices);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, mesh->indices, 0,
                                   3 * sizeof(uint32_t), mesh->n_triangles);
        rtcCommitGeometry(g);
        rtcAttachGeometry(a->scene, g);
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(a->scene);
    if (rtcGetDeviceError(a->device) != RTC_ERROR_NONE) {
        dr_accel_destroy(a);
        return NULL;
    }
    return a;
}

void dr_accel_destroy(struct dr_accel *a)
{
    if (!a)
        return;
    if (a->scene)
        rtcReleaseScene(a->scene);
    if (a->device)
        rtcReleaseDevice(a->device);
    free(a);
}

static void fill_ray(struct RTCRay *r, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    r->org_x = (float)o.x;
    r->org_y = (float)o.y;
    r->org_z = (float)o.z;
    r->dir_x = (float)d.x;
    r->dir_y = (float)d.y;
    r->dir_z = (float)d.z;
    r->tnear = (float)tmin;
    r->tfar = tmax >= FLT_MAX ? INFINITY : (float)tmax;
    r->time = 0.0f;
    r->mask = 0xFFFFFFFFu;
    r->id = 0;
    r->flags = 0;
}

int64_t dr_accel_intersect(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    struct RTCRayHit rh;
    fill_ray(&rh.ray, o, d, tmin, tmax);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(a->scene, &ctx, &rh);
    return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int64_t)rh.hit.primID;
}

bool dr_accel_occluded(const struct dr_accel *a, dr_vec3 o, dr_vec3 d, double tmin, double tmax)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    struct RTCRay r;
    fill_ray(&r, o, d, tmin, tmax);
    rtcOccluded1(a->scene, &ctx, &r);
    return r.tfar < 0.0f;  /* Embree sets tfar = -inf on a hit */
}
