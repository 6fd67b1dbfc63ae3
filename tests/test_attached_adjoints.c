/* The adjoints attached sampling adds, against central finite differences of
 * their primals: the hit point recomputed from a ray (point, shading normal,
 * uv w.r.t. origin and direction), the shading frame, texture lookups w.r.t.
 * uv (every wrap mode), materials and emission w.r.t. uv, environment
 * radiance w.r.t. the direction, a constant sky's density w.r.t. the
 * point's own, light samples w.r.t. the shading point
 * (area, point with a range, spot), the area-light pdf w.r.t. both end
 * points, and the BSDF pdf with the lobe probability held fixed.
 *
 * Each check writes the scalar J = adjoint . primal(x) for random adjoint
 * weights and compares dJ/dx from the adjoint with (J(x+h) - J(x-h)) / 2h. */
#include <stdlib.h>
#include <string.h>

#include "bsdf.h"
#include "error.h"
#include "geometry.h"
#include "lights.h"
#include "material.h"
#include "params.h"
#include "path.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

typedef double (*objective_fn)(void *ctx, const double *x);

/* Compares grad (n entries, from an adjoint) with central differences of fn at x. */
static void check_fd(const char *what, objective_fn fn, void *ctx, double *x, int n, const double *grad, double h,
                     double rtol)
{
    double worst = 0.0, scale = 0.0;
    for (int i = 0; i < n; i++) {
        double x0 = x[i];
        x[i] = x0 + h;
        double jp = fn(ctx, x);
        x[i] = x0 - h;
        double jm = fn(ctx, x);
        x[i] = x0;
        double fd = (jp - jm) / (2.0 * h);
        worst = fmax(worst, fabs(fd - grad[i]));
        scale = fmax(scale, fmax(fabs(fd), fabs(grad[i])));
    }
    CHECK(scale > 0.0, "%s: the objective does not depend on x", what);
    CHECK(worst <= rtol * (1e-12 + scale), "%s: adjoint vs central differences differ by %.3g (scale %.3g)", what,
          worst, scale);
    printf("%-34s worst |adjoint - fd| %.2g (scale %.3g)\n", what, worst, scale);
}

static struct dr_sampler rng;
static double rnd(void) { return 2.0 * dr_sampler_next(&rng) - 1.0; }
static dr_vec3 rnd3(void) { return dr_v3(rnd(), rnd(), rnd()); }
static dr_vec3 v3(const double *x) { return dr_v3(x[0], x[1], x[2]); }

/* A textured, smooth-normal quad, an emitter above it, a spot and a point light. */
static struct dr_scene *make_scene(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.6, 0.5, 0.4));
    m.metallic = 0.3;
    m.roughness = 0.45;
    m.specular = 1.0;
    m.emissive_factor = dr_v3(0.5, 0.75, 0.25);
    m.emissive_strength = 3.0;
    m.base_color_tex.texture = 0;
    m.metallic_roughness_tex.texture = 1;
    m.emissive_tex.texture = 2;
    m.double_sided = true;
    int mat = sb_material(&b, m);
    sb_quad(&b, dr_v3(-1, 0, 1), dr_v3(2, 0.3, 0), dr_v3(0, 0.2, -2), mat);   /* tris 0, 1 */
    struct dr_material e = sb_diffuse(dr_v3s(0.0));
    e.emissive_factor = dr_v3(4, 4, 4);
    sb_quad(&b, dr_v3(-0.3, 2, -0.3), dr_v3(0, 0, 0.6), dr_v3(0.6, 0.1, 0), sb_material(&b, e));   /* tris 2, 3 */
    struct dr_punctual l;
    memset(&l, 0, sizeof l);
    l.type = DR_LIGHT_SPOT;
    l.color = dr_v3(1.0, 0.8, 0.6);
    l.intensity = 5.0;
    l.position = dr_v3(0.1, 2, 0.2);
    l.direction = dr_normalize(dr_v3(0.1, -1, 0.05));
    l.cos_inner = cos(0.1);
    l.cos_outer = cos(0.9);
    sb_light(&b, l);
    l.type = DR_LIGHT_POINT;
    l.range = 4.0;
    l.position = dr_v3(-0.5, 1.5, 0.4);
    sb_light(&b, l);
    sb_environment(&b, dr_v3(0.8, 0.9, 1.1));
    b.s->env.map = sb_varied_image(8, 4, 3, 7);
    struct dr_scene *s = b.s;
    /* smooth normals on the quad's vertices, tilted differently */
    struct dr_mesh *mesh = &s->mesh;
    for (uint32_t v = 0; v < 4; v++) {
        dr_vec3 n = dr_normalize(dr_v3(0.2 * rnd(), 1.0, 0.2 * rnd()));
        mesh->normals[3 * v] = (float)n.x;
        mesh->normals[3 * v + 1] = (float)n.y;
        mesh->normals[3 * v + 2] = (float)n.z;
    }
    mesh->flags[0] |= DR_TRI_HAS_NORMALS;
    mesh->flags[1] |= DR_TRI_HAS_NORMALS;
    s->n_images = 3;
    s->images = calloc(3, sizeof(struct dr_image));
    s->images[0] = sb_varied_image(4, 3, 3, 1);
    s->images[1] = sb_varied_image(3, 3, 3, 2);
    s->images[2] = sb_varied_image(2, 4, 4, 3);
    s->n_textures = 3;
    s->textures = calloc(3, sizeof(struct dr_texture));
    s->textures[0] = (struct dr_texture){0, DR_WRAP_REPEAT, DR_WRAP_MIRROR};
    s->textures[1] = (struct dr_texture){1, DR_WRAP_CLAMP, DR_WRAP_REPEAT};
    s->textures[2] = (struct dr_texture){2, DR_WRAP_MIRROR, DR_WRAP_CLAMP};
    return sb_finish(&b);
}

/* ------------------------------------------------------------- hit point */

struct hit_ctx {
    const struct dr_scene *s;
    int64_t tri;
    struct dr_d_hit w;
};

static double hit_objective(void *c, const double *x)
{
    struct hit_ctx *k = c;
    struct dr_hit h;
    dr_hit_compute(&k->s->mesh, k->tri, v3(x), v3(x + 3), &h);
    return dr_dot(k->w.p, h.p) + dr_dot(k->w.ns, h.ns) + k->w.uv[0] * h.uv[0] + k->w.uv[1] * h.uv[1];
}

static void test_hit(const struct dr_scene *s)
{
    struct hit_ctx k = {s, 0, {rnd3(), rnd3(), {rnd(), rnd()}, {0, 0}, {0, 0, 0}, {0, 0, 0}}};
    dr_vec3 o = dr_v3(0.2, 1.5, 0.3);
    struct dr_hit target;
    dr_hit_at(&s->mesh, 0, 0.3, 0.4, &target);
    dr_vec3 d = dr_normalize(dr_sub(target.p, o));
    double x[6] = {o.x, o.y, o.z, d.x, d.y, d.z};
    struct dr_hit h;
    dr_hit_compute(&s->mesh, 0, o, d, &h);
    dr_vec3 d_o = dr_v3s(0), d_d = dr_v3s(0);
    d_hit_compute(&s->mesh, &h, o, d, &k.w, &d_o, &d_d);
    double g[6] = {d_o.x, d_o.y, d_o.z, d_d.x, d_d.y, d_d.z};
    check_fd("d_hit_compute (p, ns, uv)", hit_objective, &k, x, 6, g, 1e-6, 1e-6);
}

/* ----------------------------------------------------------------- frame */

struct frame_ctx {
    dr_frame w;
    dr_vec3 v, w_local, w_world;
};

static double frame_objective(void *c, const double *x)
{
    struct frame_ctx *k = c;
    dr_frame f = dr_frame_from_normal(v3(x));
    return dr_dot(k->w.s, f.s) + dr_dot(k->w.t, f.t) + dr_dot(k->w.n, f.n) +
           dr_dot(k->w_local, dr_frame_to_local(&f, k->v)) + dr_dot(k->w_world, dr_frame_to_world(&f, k->v));
}

static void test_frame(void)
{
    for (int sgn = -1; sgn <= 1; sgn += 2) {
        struct frame_ctx k = {{rnd3(), rnd3(), rnd3()}, rnd3(), rnd3(), rnd3()};
        dr_vec3 n = dr_normalize(dr_v3(0.3, -0.4, 0.8 * sgn));
        double x[3] = {n.x, n.y, n.z};
        dr_frame f = dr_frame_from_normal(n), df = k.w;
        d_frame_to_local(&f, k.v, k.w_local, NULL, &df);
        d_frame_to_world(&f, k.v, k.w_world, NULL, &df);
        dr_vec3 dn = dr_v3s(0);
        d_frame_from_normal(n, &df, &dn);
        double g[3] = {dn.x, dn.y, dn.z};
        check_fd(sgn > 0 ? "d_frame_from_normal (n.z > 0)" : "d_frame_from_normal (n.z < 0)", frame_objective, &k, x,
                 3, g, 1e-6, 1e-7);
        /* and the vector part of the frame maps */
        dr_vec3 dv = dr_v3s(0);
        d_frame_to_local(&f, k.v, k.w_local, &dv, NULL);
        d_frame_to_world(&f, k.v, k.w_world, &dv, NULL);
        dr_vec3 expect = dr_add(dr_frame_to_world(&f, k.w_local), dr_frame_to_local(&f, k.w_world));
        CHECK(dr_length(dr_sub(dv, expect)) < 1e-14, "frame maps: the vector adjoint is the transpose");
    }
}

/* ------------------------------------------------------- textures and uv */

struct uv_ctx {
    const struct dr_scene *s;
    int texture;          /* >= 0: a texture lookup; -1: material; -2: emission */
    struct dr_hit hit;
    double w[4];
    struct dr_d_bsdf wb;
};

static double uv_objective(void *c, const double *x)
{
    struct uv_ctx *k = c;
    struct dr_hit h = k->hit;
    h.uv[0] = x[0];
    h.uv[1] = x[1];
    if (k->texture >= 0) {
        const struct dr_texture *t = &k->s->textures[k->texture];
        double px[4];
        dr_texture_eval(t, &k->s->images[t->image], x[0], x[1], true, px);
        return k->w[0] * px[0] + k->w[1] * px[1] + k->w[2] * px[2] + k->w[3] * px[3];
    }
    if (k->texture == -1) {
        struct dr_bsdf b = {0};
        dr_material_eval(k->s, &h, &b);
        return dr_dot(k->wb.base_color, b.base_color) + k->wb.metallic * b.metallic + k->wb.roughness * b.roughness +
               k->wb.coat * b.coat + k->wb.coat_roughness * b.coat_roughness + k->wb.anisotropy * b.anisotropy +
               dr_dot(k->wb.sheen_color, b.sheen_color) + k->wb.sheen_roughness * b.sheen_roughness;
    }
    return dr_dot(v3(k->w), dr_emission(k->s, &h));
}

static void test_uv(const struct dr_scene *s)
{
    static const char *names[] = {"d_texture_eval_uv repeat/mirror", "d_texture_eval_uv clamp/repeat",
                                  "d_texture_eval_uv mirror/clamp (rgba)"};
    /* points away from texel centres, some outside [0, 1] to exercise the wraps */
    const double pts[][2] = {{0.37, 0.29}, {1.61, -0.43}, {-0.62, 0.71}};
    for (int t = 0; t < 3; t++)
        for (int p = 0; p < 3; p++) {
            struct uv_ctx k = {s, t, {0}, {rnd(), rnd(), rnd(), rnd()}, {dr_v3s(0), 0, 0, 0, 0, 0, dr_v3s(0), 0}};
            double x[2] = {pts[p][0], pts[p][1]}, g[2] = {0, 0};
            const struct dr_texture *tx = &s->textures[t];
            d_texture_eval_uv(tx, &s->images[tx->image], x[0], x[1], true, k.w, &g[0], &g[1]);
            check_fd(names[t], uv_objective, &k, x, 2, g, 1e-7, 1e-6);
        }
    struct uv_ctx k = {s, -1, {0}, {rnd(), rnd(), rnd(), 0}, {rnd3(), rnd(), rnd(), rnd(), rnd(), 0, dr_v3s(0), 0}};
    dr_hit_at(&s->mesh, 0, 0.3, 0.25, &k.hit);
    double x[2] = {k.hit.uv[0], k.hit.uv[1]};
    struct dr_d_hit dh = {0};
    d_material_eval_uv(s, &k.hit, &k.wb, &dh);
    check_fd("d_material_eval_uv", uv_objective, &k, x, 2, dh.uv, 1e-7, 1e-6);
    /* a clear coat whose factor and roughness come from texture 1's R and G
     * (clearcoatTexture, clearcoatRoughnessTexture; a transform on the
     * roughness's) */
    struct dr_material *m = &((struct dr_scene *)s)->materials[0];
    const struct dr_material saved = *m;
    m->coated = true;
    m->coat = 0.6;
    m->coat_roughness = 0.4;
    m->coat_tex = m->metallic_roughness_tex;
    m->coat_roughness_tex = m->metallic_roughness_tex;
    m->coat_roughness_tex.transformed = true;
    const double xf[6] = {0.8, 0.3, 0.05, -0.2, 1.1, 0.15};
    memcpy(m->coat_roughness_tex.xf, xf, sizeof xf);
    memset(&dh, 0, sizeof dh);
    d_material_eval_uv(s, &k.hit, &k.wb, &dh);
    check_fd("d_material_eval_uv, coat textures", uv_objective, &k, x, 2, dh.uv, 1e-7, 1e-6);
    *m = saved;
    /* KHR_materials_anisotropy's strength (B) and KHR_materials_sheen's colour
     * (RGB, sRGB-decoded) and roughness (A, a transform on it) from textures */
    m->anisotropic = true;
    m->anisotropy_strength = 0.7;
    m->anisotropy_tex = m->metallic_roughness_tex;
    m->sheened = true;
    m->sheen_color = dr_v3(0.8, 0.5, 0.3);
    m->sheen_roughness = 0.6;
    m->sheen_color_tex = m->base_color_tex;
    m->sheen_roughness_tex = m->emissive_tex;
    m->sheen_roughness_tex.transformed = true;
    memcpy(m->sheen_roughness_tex.xf, xf, sizeof xf);
    k.wb.anisotropy = rnd();
    k.wb.sheen_color = rnd3();
    k.wb.sheen_roughness = rnd();
    memset(&dh, 0, sizeof dh);
    d_material_eval_uv(s, &k.hit, &k.wb, &dh);
    check_fd("d_material_eval_uv, anisotropy and sheen textures", uv_objective, &k, x, 2, dh.uv, 1e-7, 1e-6);
    *m = saved;
    k.texture = -2;
    memset(&dh, 0, sizeof dh);
    d_emission_uv(s, &k.hit, v3(k.w), &dh);
    check_fd("d_emission_uv", uv_objective, &k, x, 2, dh.uv, 1e-7, 1e-6);
}

/* The hit's attributes the glTF features add, moved by the ray: COLOR_0
 * (base colour), TEXCOORD_1 and KHR_texture_transform (base-colour and
 * emissive lookups). J(o, d) = w . base_color + w' . emission at the hit. */
struct attr_ctx {
    const struct dr_scene *s;
    struct dr_d_bsdf wb;
    dr_vec3 we;
};

static double attr_objective(void *c, const double *x)
{
    struct attr_ctx *k = c;
    struct dr_hit h;
    dr_hit_compute(&k->s->mesh, 0, v3(x), v3(x + 3), &h);
    struct dr_bsdf b = {0};
    dr_material_eval(k->s, &h, &b);
    return dr_dot(k->wb.base_color, b.base_color) + k->wb.metallic * b.metallic + k->wb.roughness * b.roughness +
           dr_dot(k->we, dr_emission(k->s, &h));
}

static void test_hit_attributes(struct dr_scene *s)
{
    struct dr_mesh *m = &s->mesh;
    m->colors = malloc(sizeof(float) * 3 * m->n_vertices);
    m->uvs1 = malloc(sizeof(float) * 2 * m->n_vertices);
    for (uint32_t i = 0; i < 3 * m->n_vertices; i++)
        m->colors[i] = (float)(0.5 + 0.4 * rnd());
    for (uint32_t i = 0; i < 2 * m->n_vertices; i++)
        m->uvs1[i] = (float)(0.5 + 0.8 * rnd());
    struct dr_material *mat = &s->materials[0];
    const double xf[6] = {0.9, 0.4, 0.1, -0.3, 1.2, 0.25};
    mat->base_color_tex.texcoord = 1;
    mat->base_color_tex.transformed = true;
    memcpy(mat->base_color_tex.xf, xf, sizeof xf);
    mat->emissive_tex.transformed = true;
    memcpy(mat->emissive_tex.xf, xf, sizeof xf);
    mat->metallic_roughness_tex.texcoord = 1;
    struct attr_ctx k = {s, {rnd3(), rnd(), rnd(), 0, 0, 0, dr_v3s(0), 0}, rnd3()};
    dr_vec3 o = dr_v3(0.2, 1.5, 0.3);
    struct dr_hit target;
    dr_hit_at(m, 0, 0.3, 0.4, &target);
    dr_vec3 d = dr_normalize(dr_sub(target.p, o));
    double x[6] = {o.x, o.y, o.z, d.x, d.y, d.z};
    struct dr_hit h;
    dr_hit_compute(m, 0, o, d, &h);
    struct dr_d_hit dh;
    memset(&dh, 0, sizeof dh);
    d_material_eval_uv(s, &h, &k.wb, &dh);
    d_emission_uv(s, &h, k.we, &dh);
    CHECK(dh.color.x != 0.0 && dh.uv1[0] != 0.0 && dh.uv[0] != 0.0,
          "adjoints reach the colour (%g), TEXCOORD_1 (%g) and TEXCOORD_0 (%g)", dh.color.x, dh.uv1[0], dh.uv[0]);
    dr_vec3 d_o = dr_v3s(0), d_d = dr_v3s(0);
    d_hit_compute(m, &h, o, d, &dh, &d_o, &d_d);
    double g[6] = {d_o.x, d_o.y, d_o.z, d_d.x, d_d.y, d_d.z};
    check_fd("COLOR_0, TEXCOORD_1, transform", attr_objective, &k, x, 6, g, 1e-6, 1e-6);
}

/* ----------------------------------------------------------- environment */

struct env_ctx {
    const struct dr_scene *s;
    dr_vec3 w;
};

static double env_objective(void *c, const double *x)
{
    struct env_ctx *k = c;
    return dr_dot(k->w, dr_env_radiance(k->s, v3(x)));
}

static void test_env(const struct dr_scene *s)
{
    struct env_ctx k = {s, rnd3()};
    dr_vec3 dir = dr_normalize(dr_v3(0.3, 0.45, -0.7));
    double x[3] = {dir.x, dir.y, dir.z};
    dr_vec3 dd = dr_v3s(0);
    d_env_radiance_dir(s, dir, k.w, &dd);
    double g[3] = {dd.x, dd.y, dd.z};
    check_fd("d_env_radiance_dir", env_objective, &k, x, 3, g, 1e-7, 1e-6);
}

/* A constant sky's density from a surface, pick times the point's own
 * (lights.h's dr_sky_pdf), against its slope in that density (the escaped
 * vertex's MIS weight moves with it); a map's does not move. */
struct sky_pdf_ctx {
    const struct dr_scene *s;
    dr_vec3 dir;
};

static double sky_pdf_objective(void *c, const double *x)
{
    struct sky_pdf_ctx *k = c;
    return dr_light_pdf_env(k->s, k->s->light_sampler, k->dir, x[0]);
}

static void test_sky_pdf(const struct dr_scene *with_map)
{
    struct sb b;
    sb_init(&b);
    struct dr_material e = sb_diffuse(dr_v3s(0.0));
    e.emissive_factor = dr_v3(4, 4, 4);
    sb_quad(&b, dr_v3(-0.5, 2.0, 0.5), dr_v3(0, 0, -1), dr_v3(1, 0, 0), sb_material(&b, e));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.2));
    struct dr_scene *s = sb_finish(&b);
    struct sky_pdf_ctx k = {s, dr_normalize(dr_v3(0.3, 0.45, -0.7))};
    for (double density = 0.05; density < 3.0; density *= 3.0) {
        double x[1] = {density}, g[1] = {dr_light_pdf_env_dsky(s->light_sampler)};
        CHECK(g[0] > 0.0 && g[0] < 1.0, "the sky shares the light pick with the area light: slope %g", g[0]);
        check_fd("dr_light_pdf_env_dsky (constant sky)", sky_pdf_objective, &k, x, 1, g, 1e-6, 1e-9);
    }
    CHECK(dr_light_pdf_env_dsky(with_map->light_sampler) == 0.0, "a map's density does not move with the point's");
    dr_scene_destroy(s);
}

/* Next-event estimation of a constant sky at one vertex of a metal floor
 * (lobe probability 1) whose roughness 0.6 puts dr_bsdf_sky_share strictly
 * between 0 and 1: some light samples are drawn by the cosine about the
 * normal (a fixed direction), the others by the BSDF (moving with the
 * roughness, and with them their cosine to the normal); or, as mis
 * sampling draws it (sky_uniform), over the sphere (fixed, of constant
 * density). The vertex adjoint (d_path_vertex_attached, d_e only) against
 * the finite difference of the estimate f L |cos| mis / pdf made again from
 * the same numbers with the roughness moved and the share held, as
 * attached sampling holds it. */
struct sky_nee_ctx {
    struct dr_scene *s;
    const struct dr_path_vertex *v;
    double share;
    bool uniform;
};

static double sky_nee_objective(void *c, const double *x)
{
    struct sky_nee_ctx *k = c;
    const struct dr_path_vertex *v = k->v;
    k->s->materials[0].roughness = x[0];
    struct dr_bsdf b = {0};
    dr_material_eval(k->s, &v->hit, &b);
    const struct dr_sky_bsdf sky = {&b, v->frame, v->wo, v->ng, k->share};
    struct dr_light_sample ls;
    if (!dr_light_sample(k->s, k->s->light_sampler, v->hit.p, k->uniform ? NULL : &sky, v->u.light_pick,
                         v->u.light_u1, v->u.light_u2, &ls))
        return NAN;
    dr_vec3 wi = dr_frame_to_local(&v->frame, ls.wi);
    double pdf_b;
    dr_vec3 f = dr_bsdf_eval_pdf(&b, v->wo, wi, &pdf_b);
    dr_vec3 e = dr_scale(dr_mul(f, ls.radiance), fabs(wi.z) * dr_mis_power(ls.pdf, pdf_b) / ls.pdf);
    return e.x + e.y + e.z;
}

/* Six light samples of each kind the walk draws (uniform: over the sphere;
 * else by the BSDF and by the cosine), each checked. */
static void sky_nee_vertices(struct dr_scene *s, const struct dr_param_set *ps, bool uniform)
{
    const struct dr_path_opts po = {.max_depth = 2, .rr_depth = DR_RR_DEPTH_DEFAULT, .stages = dr_path_plan(s, ps),
                                    .params = ps, .sky_uniform = uniform};
    int by_bsdf = 0, other = 0;   /* (other: by the cosine, or over the sphere) */
    for (uint64_t i = 0; i < 400 && (by_bsdf < (uniform ? 0 : 6) || other < 6); i++) {
        struct dr_sampler smp;
        dr_sampler_init(&smp, 3, i, 0);
        struct dr_path_state st;
        struct dr_path_vertex v;
        struct dr_ray_counts rc = {0};
        dr_path_start(&st, dr_v3(0.2 * rnd() - 0.1, 1.0, 1.0), dr_normalize(dr_v3(0.1 * rnd(), -1.0, -1.0)));
        dr_path_step(s, &po, &st, &smp, &v, &rc);
        if (!v.nee || v.ls.type != DR_LS_ENV || (v.ls.lobe >= 0 ? by_bsdf : other) >= 6)
            continue;
        struct sky_nee_ctx k = {s, &v, dr_bsdf_sky_share(&v.bsdf, v.wo), uniform};
        CHECK(k.share > 0.1 && k.share < 0.9, "the share %g is strictly between 0 and 1", k.share);
        double grad = 0.0;
        struct dr_grad_sink sink = dr_sink_reverse(&grad);
        struct dr_d_path_state d_next, d_this;
        memset(&d_next, 0, sizeof d_next);
        d_path_vertex_attached(s, &po, &v, dr_v3s(1.0), dr_v3s(0.0), &d_next, &d_this, &sink);
        /* Without a sink (prb's Jacobian rows) the state's adjoint is the same,
         * bit for bit, for every seed: only the parameters' are left out. */
        {
            double g2 = 0.0;
            struct dr_grad_sink sink2 = dr_sink_reverse(&g2);
            struct dr_d_path_state dn = {.o = dr_v3(rnd(), rnd(), rnd()), .d = dr_v3(rnd(), rnd(), rnd()),
                                         .prev_pdf = rnd(), .prev_sky = rnd(), .prev_p = dr_v3(rnd(), 0.0, rnd())},
                                   with, without;
            const dr_vec3 d_e = dr_v3(rnd(), rnd(), rnd()), d_t = dr_v3(rnd(), rnd(), rnd());
            d_path_vertex_attached(s, &po, &v, d_e, d_t, &dn, &with, &sink2);
            d_path_vertex_attached(s, &po, &v, d_e, d_t, &dn, &without, NULL);
            CHECK(memcmp(&with, &without, sizeof with) == 0 && g2 != 0.0,
                  "the state adjoint without a sink is the one with (parameter adjoint %g)", g2);
        }
        double x[1] = {0.6};
        check_fd(v.ls.lobe >= 0 ? "sky by the BSDF: next-event adjoint"
                                : uniform ? "sky over the sphere: next-event adjoint"
                                          : "sky by the cosine: next-event adjoint",
                 sky_nee_objective, &k, x, 1, &grad, 1e-6, 1e-5);
        s->materials[0].roughness = 0.6;
        *(v.ls.lobe >= 0 ? &by_bsdf : &other) += 1;
    }
    CHECK(by_bsdf == (uniform ? 0 : 6) && other == 6, "%s light samples checked: %d by the BSDF, %d %s",
          uniform ? "sphere's" : "mixture's", by_bsdf, other, uniform ? "over the sphere" : "by the cosine");
}

static void test_sky_nee_vertex(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material metal = sb_diffuse(dr_v3(0.7, 0.5, 0.3));
    metal.metallic = 1.0;
    metal.roughness = 0.6;
    metal.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, metal));
    sb_environment(&b, dr_v3(0.9, 1.0, 1.2));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *ptr = "/materials/0/pbrMetallicRoughness/roughnessFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "sky nee: %s", dr_last_error());
    if (!ps)
        return;
    sky_nee_vertices(s, ps, false);
    sky_nee_vertices(s, ps, true);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* ---------------------------------------------------------------- lights */

struct light_ctx {
    const struct dr_scene *s;
    double pick, u1, u2;
    dr_vec3 w_wi, w_rad;
    double w_pdf;
};

static double light_objective(void *c, const double *x)
{
    struct light_ctx *k = c;
    struct dr_light_sample ls;
    if (!dr_light_sample(k->s, k->s->light_sampler, v3(x), NULL, k->pick, k->u1, k->u2, &ls))
        return NAN;
    return dr_dot(k->w_wi, ls.wi) + k->w_pdf * ls.pdf + dr_dot(k->w_rad, ls.radiance);
}

static void test_light_sample(const struct dr_scene *s)
{
    dr_vec3 p = dr_v3(0.1, 0.15, -0.2);
    int kinds[4] = {0, 0, 0, 0};   /* area, spot, environment, point */
    for (int i = 0; i < 40; i++) {
        struct light_ctx k = {s, (i + 0.5) / 40.0, 0.3, 0.6, rnd3(), rnd3(), rnd()};
        struct dr_light_sample ls;
        /* (no BSDF: a sky sample over the sphere; by a surface's it is as independent of p) */
        if (!dr_light_sample(s, s->light_sampler, p, NULL, k.pick, k.u1, k.u2, &ls))
            continue;
        int kind = ls.type == DR_LS_AREA ? 0 : (ls.type == DR_LS_PUNCTUAL ? 1 : 2);
        kinds[kind == 1 && ls.index == 1 ? 3 : kind]++;
        double x[3] = {p.x, p.y, p.z};
        dr_vec3 dp = dr_v3s(0);
        d_light_sample_point(s, p, &ls, k.w_wi, k.w_pdf, k.w_rad, &dp);
        double g[3] = {dp.x, dp.y, dp.z};
        if (kind == 2) {
            CHECK(dr_is_black(dp), "environment samples do not depend on the shading point");
            continue;
        }
        char what[64];
        snprintf(what, sizeof what, "d_light_sample_point %s", kind == 0 ? "area" : (ls.index == 0 ? "spot" : "point"));
        check_fd(what, light_objective, &k, x, 3, g, 1e-6, 1e-6);
    }
    CHECK(kinds[0] >= 1 && kinds[1] >= 1 && kinds[2] >= 1 && kinds[3] >= 1,
          "light kinds sampled: area %d, spot %d, environment %d, point %d", kinds[0], kinds[1], kinds[2], kinds[3]);
}

struct pdf_area_ctx {
    const struct dr_scene *s;
    struct dr_hit hit;
};

static double pdf_area_objective(void *c, const double *x)
{
    struct pdf_area_ctx *k = c;
    struct dr_hit h = k->hit;
    h.p = v3(x + 3);
    return dr_light_pdf_area(k->s, k->s->light_sampler, v3(x), &h);
}

static void test_pdf_area(const struct dr_scene *s)
{
    struct pdf_area_ctx k = {s, {0}};
    dr_hit_at(&s->mesh, 2, 0.3, 0.4, &k.hit);
    dr_vec3 from = dr_v3(0.1, 0.2, 0.05);
    double x[6] = {from.x, from.y, from.z, k.hit.p.x, k.hit.p.y, k.hit.p.z};
    dr_vec3 df = dr_v3s(0), dh = dr_v3s(0);
    d_light_pdf_area_points(s, s->light_sampler, from, &k.hit, 1.0, &df, &dh);
    double g[6] = {df.x, df.y, df.z, dh.x, dh.y, dh.z};
    check_fd("d_light_pdf_area_points", pdf_area_objective, &k, x, 6, g, 1e-6, 1e-6);
}

/* ------------------------------------------------ pdf with a fixed lobe P */

struct pdf_ctx {
    struct dr_bsdf b;
    double P0;
};

/* (1 - P0) cos/pi + P0 p_spec, p_spec recovered from the full pdf and P. */
static double pdf_fixed_objective(void *c, const double *x)
{
    struct pdf_ctx *k = c;
    struct dr_bsdf b = k->b;
    b.roughness = x[0];
    dr_vec3 wo = v3(x + 1), wi = v3(x + 4);
    double P = dr_bsdf_specular_prob(&b, wo), pd = wi.z * DR_INV_PI;
    double ps = (dr_bsdf_pdf(&b, wo, wi) - (1.0 - P) * pd) / P;
    return (1.0 - k->P0) * pd + k->P0 * ps;
}

static void test_pdf_fixed(void)
{
    const double roughs[] = {0.05, 0.3, 0.8};
    for (int r = 0; r < 3; r++) {
        struct pdf_ctx k;
        memset(&k, 0, sizeof k);
        k.b = (struct dr_bsdf){.base_color = dr_v3(0.5, 0.4, 0.3), .metallic = 0.4, .roughness = roughs[r], .specular = 1.0, .specular_color = dr_v3s(1.0)};
        dr_vec3 wo = dr_normalize(dr_v3(0.3, -0.2, 0.8));
        dr_vec3 wi = dr_normalize(dr_v3(-0.25, 0.15 + 0.05 * r, 0.9));
        k.P0 = dr_bsdf_specular_prob(&k.b, wo);
        double x[7] = {roughs[r], wo.x, wo.y, wo.z, wi.x, wi.y, wi.z};
        struct dr_d_bsdf db = {0};
        dr_vec3 dwo = dr_v3s(0), dwi = dr_v3s(0);
        d_bsdf_pdf_fixed_prob(&k.b, wo, wi, 1.0, &db, &dwo, &dwi);
        double g[7] = {db.roughness, dwo.x, dwo.y, dwo.z, dwi.x, dwi.y, dwi.z};
        check_fd("d_bsdf_pdf_fixed_prob", pdf_fixed_objective, &k, x, 7, g, 1e-7, 1e-5);
        CHECK(db.metallic == 0.0 && dr_is_black(db.base_color),
              "with P fixed the pdf does not depend on metallic or base colour");
    }
}

/* The same under a clear coat (bsdf_coat.c): both lobe choices held, the
 * coat's at P0c = c Fc(wo.z) and the base's at its P0, so the density is
 * P0c p_coat + (1 - P0c) [(1 - P0) cos/pi + P0 p_spec], each lobe's density
 * from the public functions on the coat lobe (the base BSDF with base 0,
 * metallic 0, specular 1) and on the uncoated base. Inputs: the base's and
 * the coat's roughness, wo, wi; the coat's factor has no derivative then. */
struct coat_pdf_ctx {
    struct dr_bsdf b;
    double P0c, P0;
};

static double coat_pdf_fixed_objective(void *c, const double *x)
{
    struct coat_pdf_ctx *k = c;
    struct dr_bsdf base = k->b;
    base.coated = false;
    base.roughness = x[0];
    const struct dr_bsdf lobe = {.roughness = x[1], .specular = 1.0, .specular_color = dr_v3s(1.0)};
    dr_vec3 wo = v3(x + 2), wi = v3(x + 5);
    double P = dr_bsdf_specular_prob(&base, wo), pd = wi.z * DR_INV_PI;
    double ps = (dr_bsdf_pdf(&base, wo, wi) - (1.0 - P) * pd) / P;
    return k->P0c * dr_bsdf_pdf(&lobe, wo, wi) + (1.0 - k->P0c) * ((1.0 - k->P0) * pd + k->P0 * ps);
}

static void test_coat_pdf_fixed(void)
{
    const double roughs[] = {0.05, 0.3, 0.8};
    for (int r = 0; r < 3; r++) {
        struct coat_pdf_ctx k;
        memset(&k, 0, sizeof k);
        k.b = (struct dr_bsdf){.base_color = dr_v3(0.5, 0.4, 0.3), .metallic = 0.4, .roughness = roughs[r],
                               .specular = 1.0, .specular_color = dr_v3s(1.0), .coated = true, .coat = 0.7,
                               .coat_roughness = roughs[2 - r]};
        dr_vec3 wo = dr_normalize(dr_v3(0.3, -0.2, 0.8 - 0.3 * r));
        dr_vec3 wi = dr_normalize(dr_v3(-0.25, 0.15 + 0.05 * r, 0.9));
        struct dr_bsdf base = k.b;
        base.coated = false;
        k.P0 = dr_bsdf_specular_prob(&base, wo);
        k.P0c = 0.7 * (0.04 + 0.96 * pow(1.0 - wo.z, 5.0));
        double x[8] = {roughs[r], roughs[2 - r], wo.x, wo.y, wo.z, wi.x, wi.y, wi.z};
        struct dr_d_bsdf db = {0};
        dr_vec3 dwo = dr_v3s(0), dwi = dr_v3s(0);
        d_bsdf_pdf_fixed_prob(&k.b, wo, wi, 1.0, &db, &dwo, &dwi);
        double g[8] = {db.roughness, db.coat_roughness, dwo.x, dwo.y, dwo.z, dwi.x, dwi.y, dwi.z};
        check_fd("d_bsdf_pdf_fixed_prob, coated", coat_pdf_fixed_objective, &k, x, 8, g, 1e-7, 1e-5);
        CHECK(db.coat == 0.0 && db.metallic == 0.0 && dr_is_black(db.base_color),
              "coated, with the lobes fixed the pdf does not depend on the coat's factor, metallic or base colour");
        CHECK(db.coat_roughness != 0.0, "coated: the coat's roughness moves its lobe's density");
    }
}

int main(void)
{
    dr_sampler_init(&rng, 11, 0, 0);
    struct dr_scene *s = make_scene();
    test_hit(s);
    test_frame();
    test_uv(s);
    test_env(s);
    test_light_sample(s);
    test_sky_pdf(s);
    test_sky_nee_vertex();
    test_pdf_area(s);
    test_pdf_fixed();
    test_coat_pdf_fixed();
    test_hit_attributes(s);   /* last: it adds vertex colours and uv transforms to s */
    dr_scene_destroy(s);
    return TEST_END();
}
