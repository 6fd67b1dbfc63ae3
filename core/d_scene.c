#include "d_scene.h"

/* Texture adjoint d_out (rgba) into the parameter slots of image texels. */
static void sink_texture(struct dr_grad_sink *k, int64_t offset, const struct dr_texture *tex,
                         const struct dr_image *img, double u, double v, const double d_out[4])
{
    if (!k->dir) {
        d_texture_eval(tex, img, u, v, d_out, k->grad + offset);
        return;
    }
    /* forward mode: the same taps and channel rules, dotted with dir */
    int64_t idx[4];
    double w[4], g[4];
    dr_texture_taps(tex, img, u, v, idx, w);
    int c = dr_texture_channel_adjoint(img->channels, d_out, g);
    for (int i = 0; i < 4; i++)
        for (int ch = 0; ch < c; ch++)
            k->forward += k->dir[offset + idx[i] * img->channels + ch] * w[i] * g[ch];
}

void d_material_eval(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_hit *hit,
                     const struct dr_d_bsdf *d_b, struct dr_grad_sink *k)
{
    const int mi = hit->material;
    const struct dr_material *m = &s->materials[mi];
    /* base_color = factor * texture rgb */
    dr_vec3 tex_rgb = dr_v3s(1.0);
    const struct dr_texture *bt = m->base_color_tex.texture >= 0 ? &s->textures[m->base_color_tex.texture] : NULL;
    if (bt) {
        double px[4];
        dr_texture_eval(bt, &s->images[bt->image], hit->uv[0], hit->uv[1], true, px);
        tex_rgb = dr_v3(px[0], px[1], px[2]);
    }
    if (ps->mat_base_color[mi] >= 0) {
        int64_t o = ps->mat_base_color[mi];
        dr_sink_add(k, o + 0, d_b->base_color.x * tex_rgb.x);
        dr_sink_add(k, o + 1, d_b->base_color.y * tex_rgb.y);
        dr_sink_add(k, o + 2, d_b->base_color.z * tex_rgb.z);
    }
    if (bt && ps->image[bt->image] >= 0) {
        double d_out[4] = {d_b->base_color.x * m->base_color.x, d_b->base_color.y * m->base_color.y,
                           d_b->base_color.z * m->base_color.z, 0.0};
        sink_texture(k, ps->image[bt->image], bt, &s->images[bt->image], hit->uv[0], hit->uv[1], d_out);
    }
    /* roughness = factor * texture G, metallic = factor * texture B */
    double tex_g = 1.0, tex_b = 1.0;
    const struct dr_texture *mt =
        m->metallic_roughness_tex.texture >= 0 ? &s->textures[m->metallic_roughness_tex.texture] : NULL;
    if (mt) {
        double px[4];
        dr_texture_eval(mt, &s->images[mt->image], hit->uv[0], hit->uv[1], false, px);
        tex_g = px[1];
        tex_b = px[2];
    }
    if (ps->mat_roughness[mi] >= 0)
        dr_sink_add(k, ps->mat_roughness[mi], d_b->roughness * tex_g);
    if (ps->mat_metallic[mi] >= 0)
        dr_sink_add(k, ps->mat_metallic[mi], d_b->metallic * tex_b);
    if (mt && ps->image[mt->image] >= 0) {
        double d_out[4] = {0.0, d_b->roughness * m->roughness, d_b->metallic * m->metallic, 0.0};
        sink_texture(k, ps->image[mt->image], mt, &s->images[mt->image], hit->uv[0], hit->uv[1], d_out);
    }
}

void d_emission(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_hit *hit, dr_vec3 d_Le,
                struct dr_grad_sink *k)
{
    const int mi = hit->material;
    const struct dr_material *m = &s->materials[mi];
    if (!ps->mat_emission_active[mi] || (!hit->front && !m->double_sided))
        return;
    /* Le = factor * strength * texture rgb */
    dr_vec3 tex_rgb = dr_v3s(1.0);
    const struct dr_texture *et = m->emissive_tex.texture >= 0 ? &s->textures[m->emissive_tex.texture] : NULL;
    if (et) {
        double px[4];
        dr_texture_eval(et, &s->images[et->image], hit->uv[0], hit->uv[1], true, px);
        tex_rgb = dr_v3(px[0], px[1], px[2]);
    }
    double st = m->emissive_strength;
    if (ps->mat_emissive_factor[mi] >= 0) {
        int64_t o = ps->mat_emissive_factor[mi];
        dr_sink_add(k, o + 0, d_Le.x * st * tex_rgb.x);
        dr_sink_add(k, o + 1, d_Le.y * st * tex_rgb.y);
        dr_sink_add(k, o + 2, d_Le.z * st * tex_rgb.z);
    }
    if (ps->mat_emissive_strength[mi] >= 0)
        dr_sink_add(k, ps->mat_emissive_strength[mi], dr_dot(d_Le, dr_mul(m->emissive_factor, tex_rgb)));
    if (et && ps->image[et->image] >= 0) {
        dr_vec3 g = dr_scale(dr_mul(d_Le, m->emissive_factor), st);
        double d_out[4] = {g.x, g.y, g.z, 0.0};
        sink_texture(k, ps->image[et->image], et, &s->images[et->image], hit->uv[0], hit->uv[1], d_out);
    }
}

void d_env_radiance(const struct dr_scene *s, const struct dr_param_set *ps, dr_vec3 dir, dr_vec3 d_L,
                    struct dr_grad_sink *k)
{
    if (!ps->env_active)
        return;
    /* L = color * strength * map(dir) */
    dr_vec3 map = dr_v3s(1.0);
    struct dr_texture tex = {0, DR_WRAP_REPEAT, DR_WRAP_CLAMP};   /* as dr_env_radiance */
    double u = 0.0, v = 0.0;
    if (s->env.map.data) {
        double px[4];
        dr_env_dir_to_uv(dir, &u, &v);
        dr_texture_eval(&tex, &s->env.map, u, v, true, px);
        map = dr_v3(px[0], px[1], px[2]);
    }
    if (ps->env_color >= 0) {
        dr_vec3 g = dr_scale(dr_mul(d_L, map), s->env.strength);
        dr_sink_add(k, ps->env_color + 0, g.x);
        dr_sink_add(k, ps->env_color + 1, g.y);
        dr_sink_add(k, ps->env_color + 2, g.z);
    }
    if (ps->env_strength >= 0)
        dr_sink_add(k, ps->env_strength, dr_dot(d_L, dr_mul(s->env.color, map)));
    if (ps->env_map >= 0 && s->env.map.data) {
        dr_vec3 g = dr_scale(dr_mul(d_L, s->env.color), s->env.strength);
        double d_out[4] = {g.x, g.y, g.z, 0.0};
        sink_texture(k, ps->env_map, &tex, &s->env.map, u, v, d_out);
    }
}

void d_light_radiance(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_light_sample *ls,
                      dr_vec3 d_L, struct dr_grad_sink *k)
{
    /* nothing about this light is requested: no derivative work at all */
    if ((ls->type == DR_LS_AREA && !ps->mat_emission_active[s->mesh.material[ls->index]]) ||
        (ls->type == DR_LS_ENV && !ps->env_active) || (ls->type == DR_LS_PUNCTUAL && !ps->lights_active))
        return;
    switch (ls->type) {
    case DR_LS_AREA: {
        struct dr_hit h;
        dr_hit_at(&s->mesh, ls->index, ls->b1, ls->b2, &h);
        h.front = dr_dot(h.ng, ls->wi) < 0.0;
        d_emission(s, ps, &h, d_L, k);
        return;
    }
    case DR_LS_ENV: d_env_radiance(s, ps, ls->wi, d_L, k); return;
    default: {
        /* radiance = color * intensity * atten */
        const struct dr_punctual *l = &s->lights[ls->index];
        int64_t oc = ps->light_color[ls->index], oi = ps->light_intensity[ls->index];
        if (oc >= 0) {
            dr_vec3 g = dr_scale(d_L, l->intensity * ls->atten);
            dr_sink_add(k, oc + 0, g.x);
            dr_sink_add(k, oc + 1, g.y);
            dr_sink_add(k, oc + 2, g.z);
        }
        if (oi >= 0)
            dr_sink_add(k, oi, dr_dot(d_L, l->color) * ls->atten);
        return;
    }
    }
}
