/* The light table's per-triangle weights of textured emitters
 * (emission_grid.h): a sparse emissive texture (three lit spots on black)
 * on small triangles with texture coordinates inside and outside [0, 1],
 * under REPEAT, CLAMP and MIRROR, with and without a texture transform.
 *   - A triangle left out of the table emits exactly nothing anywhere on it
 *     (its vertices, edges and random points), so leaving it out changes
 *     no expected value; and some are left out, some kept.
 *   - Next-event estimation with these picks is unbiased: the irradiance at
 *     a point below the emitters, by dr_light_sample, matches an estimate
 *     from uniform points on all emitting area.
 *   - It is what the weights are for: light samples land on emitting texels
 *     far more often than uniform points on the emitters do (with the old
 *     whole-texture weights they did no better).
 *   - The grid's sums are the texels' (its mean against one read per texel
 *     channel through dr_image_value): images larger than the grid's cells,
 *     whose last cells are cut short, in float and eight-bit storage, with
 *     and without alpha. */
#include <math.h>
#include <stdlib.h>

#include "cdf.h"
#include "emission_grid.h"
#include "geometry.h"
#include "light_estimates.h"
#include "lights.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

#define TEX 64
#define PER_MATERIAL 300

/* Black but for a 3x3 spot, one texel with red only, one nearly black
 * (green 1e-7: a footprint's test for zero must count it), and the corner
 * texel (REPEAT's wrap reaches it from the opposite edges). */
static struct dr_image sparse_image(void)
{
    float *px = calloc((size_t)TEX * TEX * 3, sizeof(float));
    for (int y = 20; y < 23; y++)
        for (int x = 10; x < 13; x++)
            for (int c = 0; c < 3; c++)
                px[3 * (y * TEX + x) + c] = 1.0f;
    px[3 * (50 * TEX + 40)] = 0.5f;
    px[3 * (5 * TEX + 30) + 1] = 1e-7f;
    for (int c = 0; c < 3; c++)
        px[3 * (0 * TEX + 63) + c] = 2.0f;
    struct dr_image im = sb_image(TEX, TEX, 3, px, 0.0f, true);
    free(px);
    return im;
}

static struct dr_material glow(int texture, bool transformed)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.2));
    m.emissive_factor = dr_v3s(1.0);
    m.emissive_strength = 3.0;
    m.emissive_tex.texture = texture;
    if (transformed) {   /* rotated, scaled and offset: xf * (u, v, 1) */
        const double c = cos(0.7), s = sin(0.7);
        m.emissive_tex.transformed = true;
        const double xf[6] = {1.7 * c, -1.7 * s, 0.31, 1.7 * s, 1.7 * c, -0.45};
        for (int k = 0; k < 6; k++)
            m.emissive_tex.xf[k] = xf[k];
    }
    return m;
}

/* n small triangles of material mat in the plane y = 2, facing down, with
 * texture coordinates of size up to 0.2 anywhere in [-1.5, 2.5]. */
static void scatter(struct sb *b, struct dr_sampler *smp, int mat, int n)
{
    for (int i = 0; i < n; i++) {
        double x = 4.0 * dr_sampler_next(smp) - 2.0, z = 4.0 * dr_sampler_next(smp) - 2.0;
        double u = 4.0 * dr_sampler_next(smp) - 1.5, v = 4.0 * dr_sampler_next(smp) - 1.5;
        double size = 0.01 + 0.19 * dr_sampler_next(smp);
        uint32_t a = sb_vertex(b, dr_v3(x, 2, z), u, v);
        uint32_t c = sb_vertex(b, dr_v3(x + 0.2, 2, z), u + size * dr_sampler_next(smp), v);
        uint32_t d = sb_vertex(b, dr_v3(x, 2, z + 0.2), u, v + size * dr_sampler_next(smp));
        sb_triangle(b, a, c, d, mat);   /* (a, c, d): normal -y */
    }
}

/* Every triangle left out of the light table emits exactly 0 at its
 * vertices, edge midpoints and 64 random points. Counts left out and kept. */
static void left_out_emit_nothing(const struct dr_scene *s, struct dr_sampler *smp, int *out, int *kept)
{
    const double fixed[7][2] = {{0, 0}, {1, 0}, {0, 1}, {0.5, 0}, {0.5, 0.5}, {0, 0.5}, {1.0 / 3, 1.0 / 3}};
    int bad = 0;
    *out = *kept = 0;
    for (uint32_t t = 0; t < s->mesh.n_triangles; t++) {
        if (!material_emits(&s->materials[s->mesh.material[t]]))
            continue;
        if (dr_light_pdf_area_pick(s->light_sampler, t) > 0.0) {
            ++*kept;
            continue;
        }
        ++*out;
        for (int k = 0; k < 7 + 64; k++) {
            double b1 = k < 7 ? fixed[k][0] : dr_sampler_next(smp), b2 = k < 7 ? fixed[k][1] : dr_sampler_next(smp);
            if (b1 + b2 > 1.0)
                b1 = 1.0 - b1, b2 = 1.0 - b2;
            struct dr_hit h;
            dr_hit_at(&s->mesh, t, b1, b2, &h);
            h.front = true;
            if (!dr_is_black(dr_emission(s, &h)))
                bad++;
        }
    }
    CHECK(bad == 0, "%d points of triangles left out of the light table emit", bad);
}

/* Texels in [0, 1]: some zero, the rest varied (salt shifts the pattern). */
static float *texels(int w, int h, int c, int salt)
{
    float *px = malloc(sizeof(float) * (size_t)w * h * c);
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        px[i] = (i + (size_t)salt) % 7 == 0 ? 0.0f : (float)((i * 37 + (size_t)salt) % 251) / 250.0f;
    return px;
}

/* dr_emission_grid_mean against the texels' emission read one value at a
 * time (the mean of the colour channels' decoded magnitudes). */
static void grid_matches_texels(void)
{
    const int sizes[][3] = {{1100, 700, 3}, {600, 1030, 4}, {513, 5, 2}};
    for (int k = 0; k < 3; k++)
        for (int eight = 0; eight < 2; eight++) {
            const int w = sizes[k][0], h = sizes[k][1], c = sizes[k][2];
            float *px = texels(w, h, c, k);
            struct dr_image im = eight ? sb_image8(w, h, c, px) : sb_image(w, h, c, px, 0.0f, true);
            free(px);
            const int cc = c == 2 ? 1 : (c >= 4 ? 3 : c);
            double sum = 0.0;
            for (size_t t = 0; t < (size_t)w * h; t++) {
                double e = 0.0;
                for (int ch = 0; ch < cc; ch++)
                    e += fabs(dr_image_value(&im, t * (size_t)c + (size_t)ch, true));
                sum += e / cc;
            }
            struct dr_emission_grid *g = dr_emission_grid_create(&im);
            const double want = sum / ((double)w * h), got = dr_emission_grid_mean(g);
            CHECK(fabs(got - want) <= 1e-12 * want, "%dx%dx%d image (%s): grid mean %.15g, texels' %.15g", w, h, c,
                  eight ? "eight-bit" : "float", got, want);
            dr_emission_grid_destroy(g);
            dr_image_release(&im);
        }
}

int main(void)
{
    grid_matches_texels();
    struct sb b;
    sb_init(&b);
    struct dr_sampler smp;
    dr_sampler_init(&smp, 3, 0, 0);
    int floor = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), floor);
    const int mats[4] = {sb_material(&b, glow(0, false)), sb_material(&b, glow(1, false)),
                         sb_material(&b, glow(2, false)), sb_material(&b, glow(0, true))};
    for (int k = 0; k < 4; k++)
        scatter(&b, &smp, mats[k], PER_MATERIAL);
    struct dr_scene *s = b.s;
    s->n_images = 1;
    s->images = calloc(1, sizeof(struct dr_image));
    s->images[0] = sparse_image();
    s->n_textures = 3;
    s->textures = calloc(3, sizeof(struct dr_texture));
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    s->textures[1] = (struct dr_texture){0, DR_WRAP_CLAMP, DR_WRAP_CLAMP};
    s->textures[2] = (struct dr_texture){0, DR_WRAP_MIRROR, DR_WRAP_MIRROR};
    sb_finish(&b);

    int out, kept;
    left_out_emit_nothing(s, &smp, &out, &kept);
    printf("%d emitting triangles: %d left out of the light table, %d kept\n", 4 * PER_MATERIAL, out, kept);
    CHECK(out > PER_MATERIAL && kept > 20, "left out %d, kept %d: the test exercises both", out, kept);
    CHECK(dr_light_sampler_texture_averages(s->light_sampler) == 1, "one grid for the one image, not %d",
          dr_light_sampler_texture_averages(s->light_sampler));
    for (int k = 0; k < 4; k++)
        CHECK(!dr_light_material_emits(s->light_sampler, mats[k]),
              "material %d has triangles left out: its triangles are not all entries", k);
    CHECK(!dr_light_material_emits(s->light_sampler, floor), "the floor does not emit");

    const struct irradiance_pair e = irradiance_agrees(s, dr_v3(0.1, 0, -0.2), 7, 400000);
    CHECK(e.lit_nee > 5.0 * e.lit_area, "light samples carry light %.2f %% of the time, uniform points %.2f %%",
          100 * e.lit_nee, 100 * e.lit_area);
    dr_scene_destroy(s);
    return TEST_END();
}
