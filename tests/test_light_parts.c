/* Emitting triangles sampled part by part (lights.h: a large emitter whose
 * emissive texture holds black texels is divided for the light table, each
 * part an entry weighted by its own footprint).
 *   - The parts' maps: a point mapped into a part is located in it again,
 *     and every part is a quarter of its parent, level by level.
 *   - A part left out of the table emits exactly nothing anywhere on it.
 *   - The density dr_light_sample reports for a point is the one
 *     dr_light_pdf_area gives for the same point (what MIS relies on), and
 *     the pick probabilities of a triangle's parts add up to its own.
 *   - Next-event estimation stays unbiased: irradiance below a spotted
 *     panel (two triangles, one of them under a texture transform with
 *     REPEAT) matches uniform points on the emitters, and it is what the
 *     parts are for: far more light samples land on texels that glow.
 *   - The parts of all triangles stay within DR_LIGHT_MAX_PARTS: a texture
 *     tiled over many large triangles divides the first ones only. */
#include <math.h>
#include <stdlib.h>

#include "cdf.h"
#include "geometry.h"
#include "light_estimates.h"
#include "lights.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

#define TEX 256

static void part_maps(void)
{
    struct dr_sampler smp;
    dr_sampler_init(&smp, 11, 0, 0);
    int lost = 0, bad_area = 0, n = 0;
    for (unsigned level = 1; level <= DR_LIGHT_MAX_LEVEL; level++)
        for (int k = 0; k < 400; k++, n++) {
            const uint32_t code = (uint32_t)(dr_sampler_next(&smp) * (double)(1u << (2 * level)));
            const uint32_t sub = code << 3 | level;
            double c1 = 0.02 + 0.94 * dr_sampler_next(&smp), c2 = 0.02 + 0.94 * dr_sampler_next(&smp);
            if (c1 + c2 > 0.96)   /* (strictly inside the part: off its edges) */
                c1 = 0.98 - c1, c2 = 0.98 - c2;
            dr_light_part_point(sub, &c1, &c2);
            lost += dr_light_part_locate(level, c1, c2) != code;
            double q[3][2] = {{0, 0}, {1, 0}, {0, 1}};
            for (int i = 0; i < 3; i++)
                dr_light_part_point(sub, &q[i][0], &q[i][1]);
            const double det = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
            bad_area += fabs(fabs(det) - ldexp(1.0, -2 * (int)level)) > 1e-15;
        }
    CHECK(lost == 0, "%d of %d points mapped into a part are located in another", lost, n);
    CHECK(bad_area == 0, "%d of %d parts are not a quarter of their parent per level", bad_area, n);
}

/* Black but for three spots of different colours and sizes. */
static struct dr_image spotted_image(void)
{
    float *px = calloc((size_t)TEX * TEX * 3, sizeof(float));
    const int spot[3][4] = {{20, 30, 12, 10}, {180, 60, 6, 6}, {100, 200, 20, 4}};   /* x, y, w, h */
    const float colour[3][3] = {{1.0f, 0.9f, 0.6f}, {0.3f, 0.7f, 1.0f}, {2.0f, 2.0f, 2.0f}};
    for (int k = 0; k < 3; k++)
        for (int y = spot[k][1]; y < spot[k][1] + spot[k][3]; y++)
            for (int x = spot[k][0]; x < spot[k][0] + spot[k][2]; x++)
                for (int c = 0; c < 3; c++)
                    px[3 * (y * TEX + x) + c] = colour[k][c];
    struct dr_image im = sb_image(TEX, TEX, 3, px, 0.0f, true);
    free(px);
    return im;
}

/* The scene's one image, spotted_image(), and n textures on it, texture k
 * wrapping both ways by wraps[k]. */
static void spotted_textures(struct dr_scene *s, const enum dr_wrap *wraps, int n)
{
    s->n_images = 1;
    s->images = calloc(1, sizeof(struct dr_image));
    s->images[0] = spotted_image();
    s->n_textures = n;
    s->textures = calloc((size_t)n, sizeof(struct dr_texture));
    for (int k = 0; k < n; k++)
        s->textures[k] = (struct dr_texture){0, wraps[k], wraps[k]};
}

static struct dr_material panel_material(int texture, bool transformed)
{
    struct dr_material m = sb_diffuse(dr_v3s(0.2));
    m.emissive_factor = dr_v3s(1.0);
    m.emissive_strength = 5.0;
    m.emissive_tex.texture = texture;
    if (transformed) {   /* scaled and offset: under REPEAT the spots tile */
        m.emissive_tex.transformed = true;
        const double xf[6] = {1.6, 0.0, 0.23, 0.0, 1.3, -0.41};
        for (int k = 0; k < 6; k++)
            m.emissive_tex.xf[k] = xf[k];
    }
    return m;
}

/* A floor, a two-triangle panel in y = 2 facing down (one triangle plain,
 * the other under a texture transform), a small untextured lamp. */
static struct dr_scene *panel_scene(void)
{
    struct sb b;
    sb_init(&b);
    int floor = sb_material(&b, sb_diffuse(dr_v3s(0.5)));
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), floor);
    const int plain = sb_material(&b, panel_material(0, false)), moved = sb_material(&b, panel_material(1, true));
    uint32_t a = sb_vertex(&b, dr_v3(-1.5, 2, -1.5), 0, 0), c = sb_vertex(&b, dr_v3(1.5, 2, -1.5), 1, 0);
    uint32_t d = sb_vertex(&b, dr_v3(-1.5, 2, 1.5), 0, 1), e = sb_vertex(&b, dr_v3(1.5, 2, 1.5), 1, 1);
    sb_triangle(&b, a, c, d, plain);   /* normal -y */
    sb_triangle(&b, c, e, d, moved);
    struct dr_material lamp = sb_diffuse(dr_v3s(0.0));
    lamp.emissive_factor = dr_v3s(0.5);
    sb_quad(&b, dr_v3(2.0, 1.5, -0.1), dr_v3(0.2, 0, 0), dr_v3(0, 0, 0.2), sb_material(&b, lamp));
    const enum dr_wrap wraps[2] = {DR_WRAP_CLAMP, DR_WRAP_REPEAT};
    spotted_textures(b.s, wraps, 2);
    return sb_finish(&b);
}

/* The level of triangle t's parts in the light table (0: none). */
static unsigned part_level_of(const struct dr_light_tables *lt, int64_t t)
{
    for (int64_t e = 0; e < lt->n_emitters; e++)
        if (lt->emitter_tri[e] == t && lt->emitter_sub[e] != 0)
            return lt->emitter_sub[e] & 7u;
    return 0;
}

/* The panel's triangles (after the floor's two). */
#define PANEL0 2
#define PANEL1 3

/* Every part whose density is 0 emits exactly nothing at its corners,
 * edge midpoints, centre and 32 random points. Counts parts out and in. */
static void parts_left_out_emit_nothing(const struct dr_scene *s, int *out, int *in)
{
    const double fixed[7][2] = {{0, 0}, {1, 0}, {0, 1}, {0.5, 0}, {0.5, 0.5}, {0, 0.5}, {1.0 / 3, 1.0 / 3}};
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt), "the scene has lights");
    struct dr_sampler smp;
    dr_sampler_init(&smp, 5, 0, 0);
    int bad = 0;
    *out = *in = 0;
    for (uint32_t t = PANEL0; t <= PANEL1; t++) {
        const unsigned level = part_level_of(&lt, t);
        CHECK(level >= 4, "panel triangle %u: parts of level %u", t, level);
        for (uint32_t j = 0; level > 0 && j < 1u << (2 * level); j++) {
            double x = 1.0 / 3, y = 1.0 / 3;
            dr_light_part_point(j << 3 | level, &x, &y);
            if (dr_light_area_density(s->light_sampler, t, x, y) > 0.0) {
                ++*in;
                continue;
            }
            ++*out;
            for (int k = 0; k < 7 + 32; k++) {
                double b1 = k < 7 ? fixed[k][0] : dr_sampler_next(&smp), b2 = k < 7 ? fixed[k][1] : dr_sampler_next(&smp);
                if (b1 + b2 > 1.0)
                    b1 = 1.0 - b1, b2 = 1.0 - b2;
                dr_light_part_point(j << 3 | level, &b1, &b2);
                struct dr_hit h;
                dr_hit_at(&s->mesh, t, b1, b2, &h);
                h.front = true;
                bad += !dr_is_black(dr_emission(s, &h));
            }
        }
    }
    CHECK(bad == 0, "%d points of parts left out of the light table emit", bad);
}

/* The density of each light sample against dr_light_pdf_area at its point,
 * and the triangles' picks against their parts' (density x area). */
static void densities_agree(const struct dr_scene *s)
{
    const dr_vec3 p = dr_v3(0.3, 0.0, -0.4);
    struct dr_sampler smp;
    dr_sampler_init(&smp, 9, 0, 0);
    int n = 0, bad = 0;
    for (int i = 0; i < 100000; i++) {
        struct dr_light_sample ls;
        double u0 = dr_sampler_next(&smp), u1 = dr_sampler_next(&smp), u2 = dr_sampler_next(&smp);
        if (!dr_light_sample(s, s->light_sampler, p, NULL, u0, u1, u2, &ls) || ls.type != DR_LS_AREA)
            continue;
        struct dr_hit h;
        dr_hit_at(&s->mesh, ls.index, ls.b1, ls.b2, &h);
        const double pdf = dr_light_pdf_area(s, s->light_sampler, p, &h);
        bad += !(fabs(pdf - ls.pdf) <= 1e-12 * ls.pdf);
        n++;
    }
    CHECK(n > 40000 && bad == 0, "%d of %d light samples' densities differ from dr_light_pdf_area's", bad, n);
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt) && lt.any_parts, "the panel is sampled part by part");
    for (uint32_t t = PANEL0; t <= PANEL1; t++) {
        double sum = 0.0;
        for (int64_t e = 0; e < lt.n_emitters; e++)
            sum += lt.emitter_tri[e] == t ? lt.pick[e] : 0.0;
        CHECK(lt.tri_pick_density[t] == -1.0, "triangle %u's density is looked up by part", t);
        CHECK(fabs(sum - lt.tri_pick[t]) <= 1e-12 && sum > 0.0, "triangle %u: pick %.15g, its parts' %.15g", t,
              lt.tri_pick[t], sum);
    }
}

/* 300 large triangles each reading the whole texture: parts for the first
 * DR_LIGHT_MAX_PARTS / 4^level of them, whole entries for the rest. */
static void parts_budget(void)
{
    struct sb b;
    sb_init(&b);
    const int mat = sb_material(&b, panel_material(0, false));
    for (int i = 0; i < 300; i++) {
        uint32_t a = sb_vertex(&b, dr_v3(i, 2, 0), 0, 0), c = sb_vertex(&b, dr_v3(i + 1, 2, 0), 1, 0);
        uint32_t d = sb_vertex(&b, dr_v3(i, 2, 1), 0, 1);
        sb_triangle(&b, a, c, d, mat);
    }
    struct dr_scene *s = b.s;
    const enum dr_wrap clamp = DR_WRAP_CLAMP;
    spotted_textures(s, &clamp, 1);
    sb_finish(&b);
    struct dr_light_tables lt;
    CHECK(dr_light_tables(s->light_sampler, &lt) && lt.any_parts, "the tiled triangles have parts");
    int64_t whole = 0;
    for (int64_t e = 0; e < lt.n_emitters; e++)
        whole += lt.emitter_sub[e] == 0;
    printf("300 triangles tiled with the texture: %lld entries, %lld of them whole triangles\n",
           (long long)lt.n_emitters, (long long)whole);
    /* each triangle's footprint is the whole texture, 65536 texels: level 5,
     * 1024 parts, so the budget holds the parts of its first 256 */
    const unsigned level = part_level_of(&lt, 0);
    const int64_t divided = DR_LIGHT_MAX_PARTS >> (2 * level);
    CHECK(level == 5 && part_level_of(&lt, divided - 1) == level && part_level_of(&lt, divided) == 0,
          "levels %u, %u, %u: the budget's triangles divided, the next whole", level,
          part_level_of(&lt, divided - 1), part_level_of(&lt, divided));
    CHECK(whole == 300 - divided, "%lld of 300 triangles whole, want %lld", (long long)whole,
          (long long)(300 - divided));
    dr_scene_destroy(s);
}

int main(void)
{
    part_maps();
    struct dr_scene *s = panel_scene();
    int out, in;
    parts_left_out_emit_nothing(s, &out, &in);
    printf("the panel's parts: %d in the light table, %d left out\n", in, out);
    CHECK(out > 100 && in > 10, "parts left out %d, kept %d: the test exercises both", out, in);
    CHECK(!dr_light_material_emits(s->light_sampler, s->mesh.material[PANEL0]),
          "a material with parts left out does not have all its triangles' area in the table");
    densities_agree(s);

    const struct irradiance_pair e = irradiance_agrees(s, dr_v3(0.3, 0.0, -0.4), 13, 400000);
    CHECK(e.lit_nee > 0.3 && e.lit_nee > 10.0 * e.lit_area, "light samples on glowing texels: %.3f, uniform points %.3f",
          e.lit_nee, e.lit_area);
    CHECK(e.se_nee < 0.25 * e.se_area, "next-event estimation's error %.5f against uniform points' %.5f", e.se_nee,
          e.se_area);
    dr_scene_destroy(s);
    parts_budget();
    return TEST_END();
}
