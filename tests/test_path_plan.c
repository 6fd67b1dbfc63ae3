/* The walker's optional stages follow the scene and the requested
 * parameters (dr_path_plan), and a stage that is not planned never runs: a
 * scene without lights casts no shadow ray, one without an environment sees
 * black where rays escape, a dark emitter counts only when its emission is
 * differentiated. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "path.h"
#include "render.h"
#include "scene_builder.h"
#include "test.h"

/* A 16x16 render of scene s; returns the stages it reports, and its shadow rays. */
static unsigned render_stages(const struct dr_scene *s, uint64_t *shadow, double *mean)
{
    struct dr_camera cam = sb_camera(dr_v3(0, 1, 3), dr_v3(0, 0, 0), 50);
    struct dr_render_opts o = {.width = 16, .height = 16, .spp = 2, .max_depth = 4,
                               .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 1, .threads = 1};
    float rgb[16 * 16 * 3];
    struct dr_render_stats st = {0};
    CHECK(dr_render(s, &cam, &o, rgb, &st) == 0, "render: %s", dr_last_error());
    double m = 0.0;
    for (int i = 0; i < 16 * 16 * 3; i++)
        m += rgb[i];
    *mean = m / (16 * 16 * 3);
    *shadow = st.rays.shadow;
    return st.stages;
}

int main(void)
{
    /* a diffuse floor and nothing that emits: no stage at all, black, no shadow ray */
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-5, 0, 5), dr_v3(10, 0, 0), dr_v3(0, 0, -10), sb_material(&b, sb_diffuse(dr_v3s(0.5))));
    struct dr_material dark = sb_diffuse(dr_v3s(0.5));
    sb_quad(&b, dr_v3(-1, 2, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, dark));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    uint64_t shadow;
    double mean;
    unsigned st = render_stages(s, &shadow, &mean);
    CHECK(dr_path_plan(s, NULL) == 0, "dark scene plans stages %#x", dr_path_plan(s, NULL));
    CHECK(st == 0 && shadow == 0 && mean == 0.0, "dark scene: stages %#x, %llu shadow rays, mean %g", st,
          (unsigned long long)shadow, mean);
    /* differentiating the dark quad's emission enters the emission stage, and only that */
    const char *ptr = "/materials/1/emissiveFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "param set: %s", dr_last_error());
    if (ps)
        CHECK(dr_path_plan(s, ps) == DR_STAGE_EMISSION, "emission differentiated: plan %#x", dr_path_plan(s, ps));
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);

    /* the same with an environment: environment lookups and next-event estimation */
    sb_init(&b);
    sb_quad(&b, dr_v3(-5, 0, 5), dr_v3(10, 0, 0), dr_v3(0, 0, -10), sb_material(&b, sb_diffuse(dr_v3s(0.5))));
    sb_environment(&b, dr_v3s(1.0));
    s = sb_finish(&b);
    st = render_stages(s, &shadow, &mean);
    CHECK(st == (DR_STAGE_ENV | DR_STAGE_NEE), "environment scene: stages %#x", st);
    CHECK(shadow > 0 && mean > 0.0, "environment scene: %llu shadow rays, mean %g", (unsigned long long)shadow, mean);
    char names[128];
    dr_path_stages_describe(st, names, sizeof names);
    CHECK(strcmp(names, "environment_lookup,next_event_estimation") == 0, "described as '%s'", names);
    dr_scene_destroy(s);

    /* an emitting quad and a point light: emission and next-event estimation, no environment */
    sb_init(&b);
    sb_quad(&b, dr_v3(-5, 0, 5), dr_v3(10, 0, 0), dr_v3(0, 0, -10), sb_material(&b, sb_diffuse(dr_v3s(0.5))));
    struct dr_material lamp = sb_diffuse(dr_v3s(0.0));
    lamp.emissive_factor = dr_v3s(2.0);
    sb_quad(&b, dr_v3(-1, 2, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, lamp));
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_POINT;
    l.color = dr_v3s(1.0);
    l.intensity = 3.0;
    l.position = dr_v3(0, 3, 0);
    sb_light(&b, l);
    s = sb_finish(&b);
    st = render_stages(s, &shadow, &mean);
    CHECK(st == (DR_STAGE_EMISSION | DR_STAGE_NEE), "lit scene: stages %#x", st);
    CHECK(shadow > 0 && mean > 0.0, "lit scene: %llu shadow rays, mean %g", (unsigned long long)shadow, mean);
    dr_scene_destroy(s);
    return TEST_END();
}
