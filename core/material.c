/* A glTF material at a surface point: factors times textures (times the
 * vertex colour for the base colour), and the adjoint of that evaluation down
 * to the requested parameters. */
#include "material.h"

#include "lights.h"

/* The texture a texref points at, or NULL. */
static const struct dr_texture *texref_texture(const struct dr_scene *s, const struct dr_texref *r)
{
    return r->texture >= 0 ? &s->textures[r->texture] : NULL;
}

/* Texture t of texref r at hit (through r's uv set and transform); the uv
 * looked up goes to uv. */
static void texref_eval(const struct dr_scene *s, const struct dr_texture *t, const struct dr_texref *r,
                        const struct dr_hit *hit, bool use_linear, double uv[2], double px[4])
{
    dr_texref_uv(&s->mesh, r, hit, uv);
    dr_texture_eval(t, &s->images[t->image], uv[0], uv[1], use_linear, px);
}

/* base_color = factor * texture rgb (sRGB-decoded) * COLOR_0; roughness =
 * factor * G, metallic = factor * B of the metallic-roughness texture (linear). */
void dr_material_eval(const struct dr_scene *s, const struct dr_hit *hit, struct dr_bsdf *b)
{
    const struct dr_material *m = &s->materials[hit->material];
    b->base_color = m->base_color;
    b->metallic = m->metallic;
    b->roughness = m->roughness;
    b->specular = m->specular;
    b->specular_color = m->specular_color;
    b->coated = m->coated;
    b->coat = m->coat;
    b->coat_roughness = m->coat_roughness;
    double px[4], uv[2];
    const struct dr_texture *t = texref_texture(s, &m->base_color_tex);
    if (t) {
        texref_eval(s, t, &m->base_color_tex, hit, true, uv, px);
        b->base_color = dr_mul(b->base_color, dr_v3(px[0], px[1], px[2]));
    }
    if (s->mesh.colors)
        b->base_color = dr_mul(b->base_color, dr_hit_color(&s->mesh, hit));
    t = texref_texture(s, &m->metallic_roughness_tex);
    if (t) {
        texref_eval(s, t, &m->metallic_roughness_tex, hit, false, uv, px);
        b->roughness *= px[1];
        b->metallic *= px[2];
    }
    /* KHR_materials_specular's textures: A of one, the (sRGB-decoded) RGB of the other */
    t = texref_texture(s, &m->specular_tex);
    if (t) {
        texref_eval(s, t, &m->specular_tex, hit, false, uv, px);
        b->specular *= px[3];
    }
    t = texref_texture(s, &m->specular_color_tex);
    if (t) {
        texref_eval(s, t, &m->specular_color_tex, hit, true, uv, px);
        b->specular_color = dr_mul(b->specular_color, dr_v3(px[0], px[1], px[2]));
    }
    /* the coat: clearcoatTexture's R, clearcoatRoughnessTexture's G */
    for (int which = 0; which < 2; which++) {
        const struct dr_texref *r = dr_material_coat_tex(m, which);
        if (r) {
            texref_eval(s, texref_texture(s, r), r, hit, false, uv, px);
            *(which ? &b->coat_roughness : &b->coat) *= px[which];
        }
    }
    /* the anisotropy's strength: anisotropyStrength x B of its texture (its
     * direction, RG, is the shading frame's business: anisotropy.h) */
    b->anisotropy = m->anisotropic ? m->anisotropy_strength : 0.0;
    const struct dr_texref *r = dr_material_anisotropy_tex(m);
    if (r) {
        texref_eval(s, texref_texture(s, r), r, hit, false, uv, px);
        b->anisotropy *= px[2];
    }
    /* the sheen: sheenColorTexture's RGB (sRGB-decoded), sheenRoughnessTexture's A */
    b->sheened = m->sheened;
    b->sheen_color = m->sheen_color;
    b->sheen_roughness = m->sheen_roughness;
    for (int which = 0; which < 2; which++) {
        r = dr_material_sheen_tex(m, which);
        if (!r)
            continue;
        texref_eval(s, texref_texture(s, r), r, hit, which == 0, uv, px);
        if (which == 0)
            b->sheen_color = dr_mul(b->sheen_color, dr_v3(px[0], px[1], px[2]));
        else
            b->sheen_roughness *= px[3];
    }
}

static void texref_prefetch(const struct dr_scene *s, const struct dr_texref *r, const struct dr_hit *hit,
                            bool use_linear)
{
    const struct dr_texture *t = texref_texture(s, r);
    if (!t)
        return;
    double uv[2];
    dr_texref_uv(&s->mesh, r, hit, uv);
    dr_texture_prefetch(t, &s->images[t->image], uv[0], uv[1], use_linear);
}

/* The same lookups as dr_material_eval, dr_emission and dr_normal_map_apply. */
void dr_material_prefetch(const struct dr_scene *s, const struct dr_hit *hit)
{
    const struct dr_material *m = &s->materials[hit->material];
    texref_prefetch(s, &m->base_color_tex, hit, true);
    texref_prefetch(s, &m->metallic_roughness_tex, hit, false);
    texref_prefetch(s, &m->specular_tex, hit, false);
    texref_prefetch(s, &m->specular_color_tex, hit, true);
    dr_emission_prefetch(s, hit);
    texref_prefetch(s, &m->normal_tex, hit, false);
    for (int which = 0; which < 2; which++)
        if (dr_material_coat_tex(m, which))
            texref_prefetch(s, dr_material_coat_tex(m, which), hit, false);
    if (dr_material_anisotropy_tex(m))
        texref_prefetch(s, dr_material_anisotropy_tex(m), hit, false);
    for (int which = 0; which < 2; which++)
        if (dr_material_sheen_tex(m, which))
            texref_prefetch(s, dr_material_sheen_tex(m, which), hit, which == 0);
}

void d_material_eval(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_hit *hit,
                     const struct dr_d_bsdf *d_b, struct dr_grad_sink *k)
{
    const int mi = hit->material;
    const struct dr_material *m = &s->materials[mi];
    /* base_color = factor * texture rgb * vertex colour */
    dr_vec3 tex_rgb = dr_v3s(1.0);
    const dr_vec3 vcol = dr_hit_color(&s->mesh, hit);
    double buv[2] = {0.0, 0.0}, px[4];
    const struct dr_texture *bt = texref_texture(s, &m->base_color_tex);
    if (bt) {
        texref_eval(s, bt, &m->base_color_tex, hit, true, buv, px);
        tex_rgb = dr_v3(px[0], px[1], px[2]);
    }
    if (ps->mat_base_color[mi] >= 0)
        dr_sink_add3(k, ps->mat_base_color[mi], dr_mul(d_b->base_color, dr_mul(tex_rgb, vcol)));
    if (bt && ps->image[bt->image] >= 0) {
        dr_vec3 g = dr_mul(d_b->base_color, dr_mul(m->base_color, vcol));
        double d_out[4] = {g.x, g.y, g.z, 0.0};
        d_texture_eval(bt, &s->images[bt->image], buv[0], buv[1], d_out, ps->image[bt->image], k);
    }
    /* roughness = factor * texture G, metallic = factor * texture B */
    double tex_g = 1.0, tex_b = 1.0, muv[2] = {0.0, 0.0};
    const struct dr_texture *mt = texref_texture(s, &m->metallic_roughness_tex);
    if (mt) {
        texref_eval(s, mt, &m->metallic_roughness_tex, hit, false, muv, px);
        tex_g = px[1];
        tex_b = px[2];
    }
    if (ps->mat_roughness[mi] >= 0)
        dr_sink_add(k, ps->mat_roughness[mi], d_b->roughness * tex_g);
    if (ps->mat_metallic[mi] >= 0)
        dr_sink_add(k, ps->mat_metallic[mi], d_b->metallic * tex_b);
    /* the coat: factor x R of its texture, roughness factor x G of its own */
    for (int which = 0; which < 2; which++) {
        const int64_t factor = which ? ps->mat_coat_roughness[mi] : ps->mat_coat[mi];
        const double d = which ? d_b->coat_roughness : d_b->coat;
        const struct dr_texref *r = dr_material_coat_tex(m, which);
        double texel = 1.0, cuv[2] = {0.0, 0.0};
        if (r) {
            texref_eval(s, texref_texture(s, r), r, hit, false, cuv, px);
            texel = px[which];
        }
        if (factor >= 0)
            dr_sink_add(k, factor, d * texel);
        const struct dr_texture *ct = r ? texref_texture(s, r) : NULL;
        if (ct && ps->image[ct->image] >= 0) {
            double d_out[4] = {0.0, 0.0, 0.0, 0.0};
            d_out[which] = d * (which ? m->coat_roughness : m->coat);
            d_texture_eval(ct, &s->images[ct->image], cuv[0], cuv[1], d_out, ps->image[ct->image], k);
        }
    }
    if (mt && ps->image[mt->image] >= 0) {
        double d_out[4] = {0.0, d_b->roughness * m->roughness, d_b->metallic * m->metallic, 0.0};
        d_texture_eval(mt, &s->images[mt->image], muv[0], muv[1], d_out, ps->image[mt->image], k);
    }
    /* the anisotropy's strength = factor x B of its texture (whose texels
     * are no parameter: they also turn the frame, anisotropy.h) */
    if (ps->mat_anisotropy[mi] >= 0) {
        const struct dr_texref *r = dr_material_anisotropy_tex(m);
        double texel = 1.0, auv[2];
        if (r) {
            texref_eval(s, texref_texture(s, r), r, hit, false, auv, px);
            texel = px[2];
        }
        dr_sink_add(k, ps->mat_anisotropy[mi], d_b->anisotropy * texel);
    }
    /* the sheen: colour = factor x RGB of its texture, roughness = factor x
     * A of its own (the texels are no parameter, as the specular ones) */
    for (int which = 0; which < 2; which++) {
        const int64_t factor = which ? ps->mat_sheen_roughness[mi] : ps->mat_sheen_color[mi];
        if (factor < 0)
            continue;
        const struct dr_texref *r = dr_material_sheen_tex(m, which);
        double suv[2];
        px[0] = px[1] = px[2] = px[3] = 1.0;
        if (r)
            texref_eval(s, texref_texture(s, r), r, hit, which == 0, suv, px);
        if (which)
            dr_sink_add(k, factor, d_b->sheen_roughness * px[3]);
        else
            dr_sink_add3(k, factor, dr_mul(d_b->sheen_color, dr_v3(px[0], px[1], px[2])));
    }
}

void d_material_eval_uv(const struct dr_scene *s, const struct dr_hit *hit, const struct dr_d_bsdf *d_b,
                        struct dr_d_hit *d_hit)
{
    const struct dr_material *m = &s->materials[hit->material];
    const dr_vec3 vcol = dr_hit_color(&s->mesh, hit);
    dr_vec3 tex_rgb = dr_v3s(1.0);
    double uv[2], px[4];
    const struct dr_texture *bt = texref_texture(s, &m->base_color_tex);
    if (bt) {   /* base_color = factor * rgb(uv) * colour */
        dr_texref_uv(&s->mesh, &m->base_color_tex, hit, uv);
        dr_vec3 g = dr_mul(d_b->base_color, dr_mul(m->base_color, vcol));
        double d_out[4] = {g.x, g.y, g.z, 0.0}, d_uv[2] = {0.0, 0.0};
        d_texture_eval_uv(bt, &s->images[bt->image], uv[0], uv[1], true, d_out, &d_uv[0], &d_uv[1]);
        d_texref_uv(&m->base_color_tex, d_uv, d_hit);
        if (s->mesh.colors) {
            dr_texture_eval(bt, &s->images[bt->image], uv[0], uv[1], true, px);
            tex_rgb = dr_v3(px[0], px[1], px[2]);
        }
    }
    if (s->mesh.colors)   /* ... and the colour moves with the hit too */
        d_hit->color = dr_add(d_hit->color, dr_mul(d_b->base_color, dr_mul(m->base_color, tex_rgb)));
    const struct dr_texture *mt = texref_texture(s, &m->metallic_roughness_tex);
    if (mt) {   /* roughness = factor * G(uv), metallic = factor * B(uv) */
        dr_texref_uv(&s->mesh, &m->metallic_roughness_tex, hit, uv);
        double d_out[4] = {0.0, d_b->roughness * m->roughness, d_b->metallic * m->metallic, 0.0};
        double d_uv[2] = {0.0, 0.0};
        d_texture_eval_uv(mt, &s->images[mt->image], uv[0], uv[1], false, d_out, &d_uv[0], &d_uv[1]);
        d_texref_uv(&m->metallic_roughness_tex, d_uv, d_hit);
    }
    for (int which = 0; which < 2; which++) {   /* the coat's textures (R, G) */
        const struct dr_texref *r = dr_material_coat_tex(m, which);
        if (!r)
            continue;
        const struct dr_texture *ct = texref_texture(s, r);
        dr_texref_uv(&s->mesh, r, hit, uv);
        double d_out[4] = {0.0, 0.0, 0.0, 0.0}, d_uv[2] = {0.0, 0.0};
        d_out[which] = (which ? d_b->coat_roughness * m->coat_roughness : d_b->coat * m->coat);
        d_texture_eval_uv(ct, &s->images[ct->image], uv[0], uv[1], false, d_out, &d_uv[0], &d_uv[1]);
        d_texref_uv(r, d_uv, d_hit);
    }
    const struct dr_texref *ar = dr_material_anisotropy_tex(m);
    if (ar) {   /* the anisotropy's strength = factor x B(uv) (its RG turn the frame: anisotropy.h) */
        const struct dr_texture *at = texref_texture(s, ar);
        dr_texref_uv(&s->mesh, ar, hit, uv);
        const double d_out[4] = {0.0, 0.0, d_b->anisotropy * m->anisotropy_strength, 0.0};
        double d_uv[2] = {0.0, 0.0};
        d_texture_eval_uv(at, &s->images[at->image], uv[0], uv[1], false, d_out, &d_uv[0], &d_uv[1]);
        d_texref_uv(ar, d_uv, d_hit);
    }
    for (int which = 0; which < 2; which++) {   /* the sheen's: colour RGB (sRGB), roughness A */
        const struct dr_texref *r = dr_material_sheen_tex(m, which);
        if (!r)
            continue;
        const struct dr_texture *st = texref_texture(s, r);
        dr_texref_uv(&s->mesh, r, hit, uv);
        double d_out[4] = {0.0, 0.0, 0.0, 0.0}, d_uv[2] = {0.0, 0.0};
        if (which) {
            d_out[3] = d_b->sheen_roughness * m->sheen_roughness;
        } else {
            const dr_vec3 g = dr_mul(d_b->sheen_color, m->sheen_color);
            d_out[0] = g.x, d_out[1] = g.y, d_out[2] = g.z;
        }
        d_texture_eval_uv(st, &s->images[st->image], uv[0], uv[1], which == 0, d_out, &d_uv[0], &d_uv[1]);
        d_texref_uv(r, d_uv, d_hit);
    }
}
