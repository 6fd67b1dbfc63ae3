/* Building the light sampler of a scene with textured emitters (issue 13's
 * load-time bug: a 2048^2 emissive texture on 15k triangles took ~145 s
 * because the texture was averaged once per triangle). Timing-free: the
 * number of whole-image averages is counted, and must be one per emissive
 * image, whatever the number of triangles or materials sharing it; the pick
 * probabilities still weight each emitter by its texture's mean. */
#include <math.h>
#include <stdlib.h>

#include "geometry.h"
#include "lights.h"
#include "params.h"
#include "scene_builder.h"
#include "test.h"

static struct dr_material emitter(int texture, double strength)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.5));
    m.emissive_factor = dr_v3s(1.0);
    m.emissive_strength = strength;
    m.emissive_tex.texture = texture;
    return m;
}

/* A grid of n x n quads (2 n^2 triangles) in the y = 0 plane, quads cycling
 * over materials mats[0..k). */
static void grid(struct sb *b, int n, const int *mats, int k)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            sb_quad(b, dr_v3(i, 0, j), dr_v3(0, 0, 1), dr_v3(1, 0, 0), mats[(i * n + j) % k]);
}

int main(void)
{
    struct sb b;
    sb_init(&b);
    /* two emitting materials share a 512^2 texture of mean 0.25, a third
     * uses a 256^2 texture of mean 0.5, a fourth has no texture, a fifth has a
     * texture but emits nothing (its factor is 0: nothing to average) */
    int mats[5] = {
        sb_material(&b, emitter(0, 1.0)), sb_material(&b, emitter(0, 2.0)), sb_material(&b, emitter(1, 1.0)),
        sb_material(&b, emitter(-1, 1.0)), sb_material(&b, emitter(2, 0.0)),
    };
    grid(&b, 60, mats, 5);   /* 7200 triangles, 1440 per material */
    struct dr_scene *s = b.s;
    s->n_images = 3;
    s->images = calloc(3, sizeof(struct dr_image));
    s->images[0] = sb_image(512, 512, 3, NULL, 0.25f, true);
    s->images[1] = sb_image(256, 256, 3, NULL, 0.5f, true);
    s->images[2] = sb_image(64, 64, 3, NULL, 1.0f, true);
    s->n_textures = 3;
    s->textures = calloc(3, sizeof(struct dr_texture));
    for (int i = 0; i < 3; i++)
        s->textures[i] = (struct dr_texture){i, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    sb_finish(&b);

    CHECK(s->mesh.n_triangles == 7200, "%u triangles", s->mesh.n_triangles);
    int averages = dr_light_sampler_texture_averages(s->light_sampler);
    CHECK(averages == 2, "%d whole-texture averages for 5760 emitting textured triangles (want 2: one per emissive image)",
          averages);

    /* pick probability per area: proportional to emission x texture mean */
    double density[5] = {0};
    for (uint32_t t = 0; t < s->mesh.n_triangles; t++) {
        int m = s->mesh.material[t];
        double p = dr_light_pdf_area_pick(s->light_sampler, t) / dr_triangle_area(&s->mesh, t);
        if (density[m] == 0.0)
            density[m] = p;
        CHECK_NEAR(p, density[m], 1e-12 * density[m] + 1e-300, "same density over one material");
    }
    CHECK_NEAR(density[0] / density[3], 0.25, 1e-6, "texture of mean 0.25 vs untextured");
    CHECK_NEAR(density[1] / density[3], 0.5, 1e-6, "strength 2 x mean 0.25 vs untextured");
    CHECK_NEAR(density[2] / density[3], 0.5, 1e-6, "texture of mean 0.5 vs untextured");
    CHECK(density[4] == 0.0, "a material that emits nothing is not an emitter (%g)", density[4]);

    /* a refresh (after parameters changed) averages again, once per image */
    CHECK(dr_scene_refresh(s) == 0, "refresh");
    CHECK(dr_light_sampler_texture_averages(s->light_sampler) == 2, "after refresh: %d",
          dr_light_sampler_texture_averages(s->light_sampler));

    /* dr_param_set_refresh after parameters changed: with BSDF parameters
     * only, the tables are kept (an emission changed behind the set's back
     * does not show); with an emission parameter they are built again */
    s->n_file_materials = s->n_materials;
    const char *bsdf_ptr = "/materials/3/pbrMetallicRoughness/baseColorFactor", *emit_ptr = "/materials/3/emissiveFactor";
    struct dr_param_set *bsdf = dr_param_set_create(s, &bsdf_ptr, 1), *emit = dr_param_set_create(s, &emit_ptr, 1);
    CHECK(bsdf && emit && !bsdf->radiance_active && emit->radiance_active, "param sets: %s", dr_last_error());
    uint32_t t3 = 0;
    while (t3 < s->mesh.n_triangles && s->mesh.material[t3] != mats[3])
        t3++;
    const double before = dr_light_pdf_area_pick(s->light_sampler, t3);
    s->materials[mats[3]].emissive_factor = dr_v3s(3.0);
    CHECK(bsdf && dr_param_set_refresh(s, bsdf) == 0, "refresh after a base colour: %s", dr_last_error());
    CHECK(dr_light_pdf_area_pick(s->light_sampler, t3) == before, "BSDF parameters rebuilt the light tables");
    CHECK(dr_light_sampler_texture_averages(s->light_sampler) == 2, "kept tables: %d averages",
          dr_light_sampler_texture_averages(s->light_sampler));
    CHECK(emit && dr_param_set_refresh(s, emit) == 0, "refresh after an emission: %s", dr_last_error());
    CHECK(dr_light_pdf_area_pick(s->light_sampler, t3) > 1.5 * before,
          "an emission parameter left the light tables as they were (pick %g, before %g)",
          dr_light_pdf_area_pick(s->light_sampler, t3), before);
    dr_param_set_destroy(bsdf);
    dr_param_set_destroy(emit);
    dr_scene_destroy(s);
    return TEST_END();
}
