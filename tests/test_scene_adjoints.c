/* The adjoint chains beside their primals (material.c, lights.c) and d_loss_eval against central finite
 * differences of their primal functions, for every scalar of every parameter
 * kind they reach: material factors and all three texture kinds (base colour,
 * metallic-roughness, emissive), emission factor and strength, environment
 * colour, strength and map texels, punctual light colour and intensity, area
 * lights through their emission. Also: the forward-mode sink (dot with a
 * direction) equals the reverse-mode gradient dotted with that direction. */
#include <stdlib.h>
#include <string.h>

#include "lights.h"
#include "error.h"
#include "loss.h"
#include "material.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

enum objective { OBJ_MATERIAL, OBJ_EMISSION, OBJ_ENV, OBJ_PUNCTUAL, OBJ_AREA };

struct fixture {
    struct dr_scene *s;
    struct dr_param_set *ps;
    struct dr_hit hit;
    dr_vec3 dir;                 /* environment direction */
    struct dr_light_sample lsp;  /* a punctual light sample */
    struct dr_light_sample lsa;  /* an area light sample */
    struct dr_d_bsdf d_b;        /* adjoints */
    dr_vec3 d_L;
};

/* The primal value each objective dots with its adjoint. */
static double objective(const struct fixture *f, enum objective o)
{
    const struct dr_scene *s = f->s;
    switch (o) {
    case OBJ_MATERIAL: {
        struct dr_bsdf b = {0};
        dr_material_eval(s, &f->hit, &b);
        return dr_dot(f->d_b.base_color, b.base_color) + f->d_b.metallic * b.metallic + f->d_b.roughness * b.roughness +
               f->d_b.coat * b.coat + f->d_b.coat_roughness * b.coat_roughness + f->d_b.anisotropy * b.anisotropy +
               dr_dot(f->d_b.sheen_color, b.sheen_color) + f->d_b.sheen_roughness * b.sheen_roughness;
    }
    case OBJ_EMISSION: return dr_dot(f->d_L, dr_emission(s, &f->hit));
    case OBJ_ENV: return dr_dot(f->d_L, dr_env_radiance(s, f->dir));
    case OBJ_PUNCTUAL: {
        const struct dr_punctual *l = &s->lights[f->lsp.index];
        return dr_dot(f->d_L, dr_scale(l->color, l->intensity * f->lsp.atten));
    }
    default: {
        struct dr_hit h;
        dr_hit_at(&s->mesh, f->lsa.index, f->lsa.b1, f->lsa.b2, &h);
        h.front = dr_dot(h.ng, f->lsa.wi) < 0.0;
        return dr_dot(f->d_L, dr_emission(s, &h));
    }
    }
}

static void adjoint(struct fixture *f, enum objective o, struct dr_grad_sink *k)
{
    switch (o) {
    case OBJ_MATERIAL: d_material_eval(f->s, f->ps, &f->hit, &f->d_b, k); break;
    case OBJ_EMISSION: d_emission(f->s, f->ps, &f->hit, f->d_L, k); break;
    case OBJ_ENV: d_env_radiance(f->s, f->ps, f->dir, f->d_L, k); break;
    case OBJ_PUNCTUAL: d_light_radiance(f->s, f->ps, &f->lsp, f->d_L, k); break;
    default: d_light_radiance(f->s, f->ps, &f->lsa, f->d_L, k); break;
    }
}

static void check_objective(struct fixture *f, enum objective o, const char *what)
{
    int64_t n = f->ps->total;
    double *grad = calloc((size_t)n, sizeof(double)), *theta = malloc(sizeof(double) * (size_t)n);
    struct dr_grad_sink k = dr_sink_reverse(grad);
    adjoint(f, o, &k);
    dr_param_set_get(f->s, f->ps, theta);
    const double h = 1.0 / 64.0;
    double worst = 0.0, norm = 0.0;
    for (int64_t i = 0; i < n; i++) {
        double t0 = theta[i];
        theta[i] = t0 + h;
        dr_param_set_put(f->s, f->ps, theta);
        double jp = objective(f, o);
        theta[i] = t0 - h;
        dr_param_set_put(f->s, f->ps, theta);
        double jm = objective(f, o);
        theta[i] = t0;
        dr_param_set_put(f->s, f->ps, theta);
        double fd = (jp - jm) / (2.0 * h);
        worst = fmax(worst, fabs(fd - grad[i]));
        norm = fmax(norm, fabs(fd));
    }
    CHECK(norm > 0.0, "%s: objective depends on no parameter", what);
    CHECK(worst <= 1e-9 * (1.0 + norm), "%s: adjoint vs central differences differ by %.3g (scale %.3g)", what, worst,
          norm);
    /* forward mode: the sink dotted with a direction equals grad . dir */
    struct dr_sampler r;
    dr_sampler_init(&r, 3, (uint64_t)o, 0);
    double *dir = malloc(sizeof(double) * (size_t)n), expect = 0.0;
    for (int64_t i = 0; i < n; i++) {
        dir[i] = dr_sampler_next(&r) - 0.5;
        expect += dir[i] * grad[i];
    }
    struct dr_grad_sink fk = dr_sink_forward(dir);
    adjoint(f, o, &fk);
    CHECK(fabs(fk.forward[0] - expect) <= 1e-12 * (1.0 + fabs(expect)), "%s: forward %.17g vs reverse . dir %.17g", what,
          fk.forward[0], expect);
    printf("%-22s %lld scalars, worst |adjoint - fd| %.2g (scale %.3g)\n", what, (long long)n, worst, norm);
    free(grad);
    free(theta);
    free(dir);
}

static void test_chains(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.6, 0.5, 0.4));
    m.metallic = 0.7;
    m.roughness = 0.45;
    m.emissive_factor = dr_v3(0.5, 0.75, 0.25);
    m.emissive_strength = 3.0;
    m.coated = true;   /* KHR_materials_clearcoat, its factor and roughness from texture 1's R and G */
    m.coat = 0.6;
    m.coat_roughness = 0.3;
    m.coat_tex.texture = 1;
    m.coat_roughness_tex.texture = 1;
    m.base_color_tex.texture = 0;
    m.metallic_roughness_tex.texture = 1;
    m.emissive_tex.texture = 2;
    /* KHR_materials_anisotropy's strength (texture 3's B) and KHR_materials_sheen's
     * colour and roughness (texture 3's RGB and A): factors times texels */
    m.anisotropic = true;
    m.anisotropy_strength = 0.55;
    m.anisotropy_tex.texture = 3;
    m.sheened = true;
    m.sheen_color = dr_v3(0.7, 0.4, 0.9);
    m.sheen_roughness = 0.6;
    m.sheen_color_tex.texture = 3;
    m.sheen_roughness_tex.texture = 3;
    m.double_sided = true;
    sb_quad(&b, dr_v3(-1, 0, 1), dr_v3(2, 0, 0), dr_v3(0, 0, -2), sb_material(&b, m));
    sb_environment(&b, dr_v3(0.8, 0.9, 1.1));
    b.s->env.strength = 1.5;
    b.s->env.map = sb_varied_image(8, 4, 3, 7);
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_SPOT;
    l.color = dr_v3(1.0, 0.8, 0.6);
    l.intensity = 5.0;
    l.position = dr_v3(0, 2, 0);
    l.direction = dr_v3(0, -1, 0);
    l.cos_inner = cos(0.2);
    l.cos_outer = cos(0.5);
    sb_light(&b, l);
    struct dr_scene *s = b.s;
    s->n_images = 4;
    s->images = calloc(4, sizeof(struct dr_image));
    s->images[0] = sb_varied_image(4, 3, 3, 1);
    s->images[1] = sb_varied_image(3, 3, 3, 2);
    s->images[2] = sb_varied_image(2, 4, 4, 3);
    s->images[3] = sb_varied_image(3, 2, 4, 4);
    s->n_textures = 4;
    s->textures = calloc(4, sizeof(struct dr_texture));
    s->textures[3] = (struct dr_texture){3, DR_WRAP_REPEAT, DR_WRAP_REPEAT};
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_MIRROR};
    s->textures[1] = (struct dr_texture){1, DR_WRAP_CLAMP, DR_WRAP_REPEAT};
    s->textures[2] = (struct dr_texture){2, DR_WRAP_MIRROR, DR_WRAP_CLAMP};
    sb_finish(&b);
    s->n_file_materials = s->n_materials;
    s->lights[0].gltf_index = 0;

    const char *ptrs[] = {
        "/materials/0/pbrMetallicRoughness/baseColorFactor",
        "/materials/0/pbrMetallicRoughness/metallicFactor",
        "/materials/0/pbrMetallicRoughness/roughnessFactor",
        "/materials/0/emissiveFactor",
        "/materials/0/extensions/KHR_materials_emissive_strength/emissiveStrength",
        "/materials/0/extensions/KHR_materials_clearcoat/clearcoatFactor",
        "/materials/0/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor",
        "/materials/0/extensions/KHR_materials_anisotropy/anisotropyStrength",
        "/materials/0/extensions/KHR_materials_sheen/sheenColorFactor",
        "/materials/0/extensions/KHR_materials_sheen/sheenRoughnessFactor",
        "/images/0",
        "/images/1",
        "/images/2",
        "/extensions/DR_environment/color",
        "/extensions/DR_environment/strength",
        "/extensions/DR_environment/uri",
        "/extensions/KHR_lights_punctual/lights/0/color",
        "/extensions/KHR_lights_punctual/lights/0/intensity",
    };
    struct fixture f;
    memset(&f, 0, sizeof f);
    f.s = s;
    f.ps = dr_param_set_create(s, ptrs, (int)(sizeof ptrs / sizeof ptrs[0]));
    CHECK(f.ps != NULL, "param set: %s", dr_last_error());
    if (!f.ps)
        return;
    dr_hit_at(&s->mesh, 1, 0.3, 0.25, &f.hit);   /* a point with uv away from texel centres */
    f.dir = dr_normalize(dr_v3(0.3, 0.5, -0.7));
    f.d_b = (struct dr_d_bsdf){dr_v3(0.7, -0.4, 0.9), -0.6, 0.8, 0.35, -0.45, 0.5, dr_v3(-0.3, 0.65, 0.2), -0.55};
    f.d_L = dr_v3(0.5, -1.2, 0.9);
    f.lsp.type = DR_LS_PUNCTUAL;
    f.lsp.index = 0;
    f.lsp.atten = 0.37;
    f.lsa.type = DR_LS_AREA;
    f.lsa.index = 0;
    f.lsa.b1 = 0.2;
    f.lsa.b2 = 0.55;
    f.lsa.wi = dr_v3(0, -1, 0);   /* arriving at the front (+y) face */
    check_objective(&f, OBJ_MATERIAL, "d_material_eval");
    check_objective(&f, OBJ_EMISSION, "d_emission");
    check_objective(&f, OBJ_ENV, "d_env_radiance");
    check_objective(&f, OBJ_PUNCTUAL, "d_light_radiance/spot");
    check_objective(&f, OBJ_AREA, "d_light_radiance/area");
    /* COLOR_0 multiplies the base colour, so d/d baseColorFactor and d/d
     * base-colour texels carry its factor; the lookups go through TEXCOORD_1
     * and a KHR_texture_transform */
    double g0[3] = {0, 0, 0}, *gfull = calloc((size_t)f.ps->total, sizeof(double));
    struct dr_grad_sink k0 = dr_sink_reverse(gfull);
    d_material_eval(s, f.ps, &f.hit, &f.d_b, &k0);
    memcpy(g0, gfull + f.ps->mat_base_color[0], sizeof g0);
    struct dr_mesh *mesh = &s->mesh;
    mesh->colors = malloc(sizeof(float) * 3 * mesh->n_vertices);
    mesh->uvs1 = malloc(sizeof(float) * 2 * mesh->n_vertices);
    for (uint32_t i = 0; i < 3 * mesh->n_vertices; i++)
        mesh->colors[i] = (float)((i * 7 % 11 + 2) / 16.0);
    for (uint32_t i = 0; i < 2 * mesh->n_vertices; i++)
        mesh->uvs1[i] = (float)((i * 5 % 9) / 8.0);
    const double xf[6] = {0.9, 0.4, 0.1, -0.3, 1.2, 0.25};
    s->materials[0].base_color_tex.texcoord = 1;
    s->materials[0].base_color_tex.transformed = true;
    memcpy(s->materials[0].base_color_tex.xf, xf, sizeof xf);
    s->materials[0].emissive_tex.transformed = true;
    memcpy(s->materials[0].emissive_tex.xf, xf, sizeof xf);
    check_objective(&f, OBJ_MATERIAL, "d_material_eval COLOR_0");
    check_objective(&f, OBJ_EMISSION, "d_emission transform");
    /* with the texture lookup unchanged (uv set 0, no transform) the factor's
     * gradient is the one without colours times the interpolated colour */
    s->materials[0].base_color_tex.texcoord = 0;
    s->materials[0].base_color_tex.transformed = false;
    memset(gfull, 0, sizeof(double) * (size_t)f.ps->total);
    d_material_eval(s, f.ps, &f.hit, &f.d_b, &k0);
    dr_vec3 vc = dr_hit_color(mesh, &f.hit);
    const double *g1 = gfull + f.ps->mat_base_color[0];
    CHECK(fabs(g1[0] - g0[0] * vc.x) < 1e-12 && fabs(g1[1] - g0[1] * vc.y) < 1e-12 && fabs(g1[2] - g0[2] * vc.z) < 1e-12,
          "d/d baseColorFactor with COLOR_0 (%g %g %g) = without (%g %g %g) * colour (%g %g %g)", g1[0], g1[1], g1[2],
          g0[0], g0[1], g0[2], vc.x, vc.y, vc.z);
    CHECK(fabs(vc.x - 1.0) > 0.05, "the test colour differs from 1 (%g)", vc.x);
    free(gfull);
    free(mesh->colors);
    free(mesh->uvs1);
    mesh->colors = NULL;
    mesh->uvs1 = NULL;
    /* the back of a single-sided emitter emits nothing, so no derivative either */
    s->materials[0].double_sided = false;
    f.hit.front = false;
    double *g = calloc((size_t)f.ps->total, sizeof(double));
    struct dr_grad_sink k = dr_sink_reverse(g);
    d_emission(s, f.ps, &f.hit, f.d_L, &k);
    double sum = 0;
    for (int64_t i = 0; i < f.ps->total; i++)
        sum += fabs(g[i]);
    CHECK(sum == 0.0, "back face of a single-sided emitter has a derivative (%g)", sum);
    free(g);
    dr_param_set_destroy(f.ps);
    dr_scene_destroy(s);
}

static void test_loss(void)
{
    const size_t n = 12;
    float img[12], tgt[12], d[12];
    for (size_t i = 0; i < n; i++) {
        img[i] = (float)((i * 29 % 13) / 8.0);
        tgt[i] = (float)((i * 17 % 11) / 8.0 + 1.0 / 16.0);   /* never equal: |x| is smooth there */
    }
    for (int k = DR_LOSS_L1; k <= DR_LOSS_L2; k++) {
        d_loss_eval((enum dr_loss_kind)k, img, tgt, n, 2.5, d);
        double worst = 0.0;
        for (size_t i = 0; i < n; i++) {
            float x = img[i], h = 1.0f / 64.0f;
            img[i] = x + h;
            double lp = dr_loss_eval((enum dr_loss_kind)k, img, tgt, n);
            img[i] = x - h;
            double lm = dr_loss_eval((enum dr_loss_kind)k, img, tgt, n);
            img[i] = x;
            worst = fmax(worst, fabs(2.5 * (lp - lm) / (2.0 * h) - d[i]));
        }
        CHECK(worst <= 1e-6, "d_loss_eval %s: worst |adjoint - fd| %.3g", dr_loss_name((enum dr_loss_kind)k), worst);
    }
    /* l1 at equality: the subgradient 0 */
    img[0] = tgt[0];
    d_loss_eval(DR_LOSS_L1, img, tgt, n, 1.0, d);
    CHECK(d[0] == 0.0f, "l1 derivative at I == T is %g", d[0]);
}

int main(void)
{
    test_chains();
    test_loss();
    return TEST_END();
}
