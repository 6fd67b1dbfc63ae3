#include "material.h"

void dr_material_eval(const struct dr_scene *s, const struct dr_hit *hit, struct dr_bsdf *b)
{
    const struct dr_material *m = &s->materials[hit->material];
    b->base_color = m->base_color;
    b->metallic = m->metallic;
    b->roughness = m->roughness;
    b->specular = m->specular;
    b->specular_color = m->specular_color;
    double px[4];
    if (m->base_color_tex.texture >= 0) {
        const struct dr_texture *t = &s->textures[m->base_color_tex.texture];
        dr_texture_eval(t, &s->images[t->image], hit->uv[0], hit->uv[1], true, px);
        b->base_color = dr_mul(b->base_color, dr_v3(px[0], px[1], px[2]));
    }
    if (m->metallic_roughness_tex.texture >= 0) {
        const struct dr_texture *t = &s->textures[m->metallic_roughness_tex.texture];
        dr_texture_eval(t, &s->images[t->image], hit->uv[0], hit->uv[1], false, px);
        b->roughness *= px[1];
        b->metallic *= px[2];
    }
}
