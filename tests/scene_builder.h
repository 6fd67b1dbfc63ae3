/* Builds small scenes in code for tests: quads and boxes with chosen
 * materials, optional environment and punctual lights. Everything is
 * malloc'd so dr_scene_destroy releases it. */
#ifndef DR_TEST_SCENE_BUILDER_H
#define DR_TEST_SCENE_BUILDER_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "scene.h"

struct sb {
    struct dr_scene *s;
    uint32_t cap_v, cap_t;
};

static inline struct dr_material sb_diffuse(dr_vec3 albedo)
{
    struct dr_material m;
    memset(&m, 0, sizeof m);
    strcpy(m.name, "diffuse");
    m.base_color = albedo;
    m.metallic = 0.0;
    m.roughness = 1.0;
    m.emissive_strength = 1.0;
    m.specular = 0.0;   /* pure Lambertian */
    m.specular_color = dr_v3s(1.0);
    m.base_color_tex.texture = m.metallic_roughness_tex.texture = m.emissive_tex.texture = -1;
    m.normal_tex.texture = -1;
    m.coat_tex.texture = m.coat_roughness_tex.texture = -1;
    m.anisotropy_tex.texture = m.specular_tex.texture = m.specular_color_tex.texture = -1;
    m.sheen_color_tex.texture = m.sheen_roughness_tex.texture = -1;
    m.normal_scale = 1.0;
    m.alpha = 1.0;
    m.alpha_cutoff = 0.5;
    return m;
}

static inline void sb_init(struct sb *b)
{
    b->s = calloc(1, sizeof *b->s);
    b->s->path = strdup("test-scene");
    b->cap_v = 1024;
    b->cap_t = 1024;
    struct dr_mesh *m = &b->s->mesh;
    m->positions = calloc(3 * b->cap_v + 1, sizeof(float));
    m->normals = calloc(3 * b->cap_v, sizeof(float));
    m->uvs = calloc(2 * b->cap_v, sizeof(float));
    m->indices = calloc(3 * b->cap_t, sizeof(uint32_t));
    m->material = calloc(b->cap_t, sizeof(int32_t));
    m->flags = calloc(b->cap_t, sizeof(uint8_t));
    b->s->bbox_min = dr_v3s(INFINITY);
    b->s->bbox_max = dr_v3s(-INFINITY);
}

static inline int sb_material(struct sb *b, struct dr_material mat)
{
    struct dr_scene *s = b->s;
    s->materials = realloc(s->materials, sizeof(struct dr_material) * (size_t)(s->n_materials + 1));
    s->materials[s->n_materials] = mat;
    return s->n_materials++;
}

/* Grows a zero-filled array from old_n to new_n elements of `size` bytes. */
static inline void *sb_grow(void *p, size_t old_n, size_t new_n, size_t size)
{
    char *q = realloc(p, new_n * size);
    if (!q) {
        fprintf(stderr, "scene_builder: out of memory\n");
        exit(2);
    }
    memset(q + old_n * size, 0, (new_n - old_n) * size);
    return q;
}

static inline uint32_t sb_vertex(struct sb *b, dr_vec3 p, double u, double v)
{
    struct dr_mesh *m = &b->s->mesh;
    if (m->n_vertices == b->cap_v) {   /* double the capacity (big test meshes) */
        uint32_t c = b->cap_v;
        m->positions = sb_grow(m->positions, 3 * (size_t)c + 1, 6 * (size_t)c + 1, sizeof(float));
        m->normals = sb_grow(m->normals, 3 * (size_t)c, 6 * (size_t)c, sizeof(float));
        m->uvs = sb_grow(m->uvs, 2 * (size_t)c, 4 * (size_t)c, sizeof(float));
        b->cap_v = 2 * c;
    }
    uint32_t i = m->n_vertices++;
    m->positions[3 * i] = (float)p.x;
    m->positions[3 * i + 1] = (float)p.y;
    m->positions[3 * i + 2] = (float)p.z;
    m->uvs[2 * i] = (float)u;
    m->uvs[2 * i + 1] = (float)v;
    b->s->bbox_min = dr_v3(fmin(b->s->bbox_min.x, p.x), fmin(b->s->bbox_min.y, p.y), fmin(b->s->bbox_min.z, p.z));
    b->s->bbox_max = dr_v3(fmax(b->s->bbox_max.x, p.x), fmax(b->s->bbox_max.y, p.y), fmax(b->s->bbox_max.z, p.z));
    return i;
}

static inline void sb_triangle(struct sb *b, uint32_t a, uint32_t c, uint32_t d, int material)
{
    struct dr_mesh *m = &b->s->mesh;
    if (m->n_triangles == b->cap_t) {
        uint32_t c = b->cap_t;
        m->indices = sb_grow(m->indices, 3 * (size_t)c, 6 * (size_t)c, sizeof(uint32_t));
        m->material = sb_grow(m->material, c, 2 * (size_t)c, sizeof(int32_t));
        m->flags = sb_grow(m->flags, c, 2 * (size_t)c, sizeof(uint8_t));
        b->cap_t = 2 * c;
    }
    uint32_t t = m->n_triangles++;
    m->indices[3 * t] = a;
    m->indices[3 * t + 1] = c;
    m->indices[3 * t + 2] = d;
    m->material[t] = material;
    m->flags[t] = DR_TRI_HAS_UVS;
}

/* Parallelogram p, p+e1, p+e1+e2, p+e2; front side = cross(e1, e2). */
static inline void sb_quad(struct sb *b, dr_vec3 p, dr_vec3 e1, dr_vec3 e2, int material)
{
    uint32_t a = sb_vertex(b, p, 0, 1), c = sb_vertex(b, dr_add(p, e1), 1, 1);
    uint32_t d = sb_vertex(b, dr_add(dr_add(p, e1), e2), 1, 0), e = sb_vertex(b, dr_add(p, e2), 0, 0);
    sb_triangle(b, a, c, d, material);
    sb_triangle(b, a, d, e, material);
}

/* Axis-aligned box with outward-facing fronts. */
static inline void sb_box(struct sb *b, dr_vec3 lo, dr_vec3 hi, int material)
{
    dr_vec3 dx = dr_v3(hi.x - lo.x, 0, 0), dy = dr_v3(0, hi.y - lo.y, 0), dz = dr_v3(0, 0, hi.z - lo.z);
    sb_quad(b, lo, dy, dx, material);                    /* z = lo, -z */
    sb_quad(b, dr_add(lo, dz), dx, dy, material);        /* z = hi, +z */
    sb_quad(b, lo, dz, dy, material);                    /* x = lo, -x */
    sb_quad(b, dr_add(lo, dx), dy, dz, material);        /* x = hi, +x */
    sb_quad(b, lo, dx, dz, material);                    /* y = lo, -y */
    sb_quad(b, dr_add(lo, dy), dz, dx, material);        /* y = hi, +y */
}

/* Box [-1,1] x [0,height] x [-1,1] without a top, fronts facing inside: an
 * enclosure whose only opening is the top (furnace and interreflection tests). */
static inline void sb_open_box(struct sb *b, double height, int material)
{
    dr_vec3 lo = dr_v3(-1, 0, -1);
    sb_quad(b, lo, dr_v3(0, 0, 2), dr_v3(2, 0, 0), material);                        /* floor, +y */
    sb_quad(b, lo, dr_v3(2, 0, 0), dr_v3(0, height, 0), material);                   /* z=-1, +z */
    sb_quad(b, dr_v3(-1, 0, 1), dr_v3(0, height, 0), dr_v3(2, 0, 0), material);      /* z=+1, -z */
    sb_quad(b, lo, dr_v3(0, height, 0), dr_v3(0, 0, 2), material);                   /* x=-1, +x */
    sb_quad(b, dr_v3(1, 0, -1), dr_v3(0, 0, 2), dr_v3(0, height, 0), material);      /* x=+1, -x */
}

/* A w x h x c image holding px (or filled with `fill` when px is NULL),
 * with an identical linear copy when `linear` (a colour texture as the
 * loader gives it). Released by dr_scene_destroy once in scene->images. */
static inline struct dr_image sb_image(int w, int h, int c, const float *px, float fill, bool linear)
{
    struct dr_image im;
    memset(&im, 0, sizeof im);
    im.width = w;
    im.height = h;
    im.channels = c;
    size_t n = (size_t)w * h * c;
    im.data = malloc(sizeof(float) * n);
    im.linear = linear ? malloc(sizeof(float) * n) : NULL;
    if (!im.data || (linear && !im.linear)) {
        fprintf(stderr, "scene_builder: out of memory\n");
        exit(2);
    }
    for (size_t i = 0; i < n; i++)
        im.data[i] = px ? px[i] : fill;
    if (linear)
        memcpy(im.linear, im.data, sizeof(float) * n);
    return im;
}

/* A w x h x c image of varied texels, both copies the same: multiples of
 * 2^-8 in [1/8, 3/4] (salt shifts the pattern), exact in float storage. */
static inline struct dr_image sb_varied_image(int w, int h, int c, int salt)
{
    struct dr_image im = sb_image(w, h, c, NULL, 0.0f, true);
    for (int i = 0; i < w * h * c; i++)
        im.data[i] = im.linear[i] = (float)((32 + (i * 37 + salt * 11) % 160) / 256.0);
    return im;
}

/* sb_image's pixels in eight-bit storage, as dr_image_read_memory8 leaves
 * an sRGB PNG's (values rounded to k / 255; the colour decoded through the
 * table): the kind the packet renderer looks up eight lanes at a time. */
static inline struct dr_image sb_image8(int w, int h, int c, const float *px)
{
    struct dr_image im;
    memset(&im, 0, sizeof im);
    im.width = w;
    im.height = h;
    im.channels = c;
    im.file_is_srgb = true;
    size_t n = (size_t)w * h * c;
    im.bytes = malloc(n);
    im.lut = malloc(512 * sizeof(float));   /* lut, then lut_linear */
    if (!im.bytes || !im.lut) {
        fprintf(stderr, "scene_builder: out of memory\n");
        exit(2);
    }
    for (size_t i = 0; i < n; i++) {
        float v = px[i] < 0.0f ? 0.0f : (px[i] > 1.0f ? 1.0f : px[i]);
        im.bytes[i] = (uint8_t)(v * 255.0f + 0.5f);
    }
    for (int k = 0; k < 256; k++)
        im.lut[k] = (float)(k / 255.0);
    if (dr_image_make_linear(&im) != 0) {
        fprintf(stderr, "scene_builder: cannot decode an eight-bit image\n");
        exit(2);
    }
    return im;
}

/* Adds im to the scene's images and a texture on it (clamped both ways);
 * returns the texture's index. */
static inline int sb_texture(struct sb *b, struct dr_image im)
{
    struct dr_scene *s = b->s;
    s->images = realloc(s->images, sizeof(struct dr_image) * (size_t)(s->n_images + 1));
    s->images[s->n_images] = im;
    s->textures = realloc(s->textures, sizeof(struct dr_texture) * (size_t)(s->n_textures + 1));
    s->textures[s->n_textures] = (struct dr_texture){s->n_images, DR_WRAP_CLAMP, DR_WRAP_CLAMP};
    s->n_images++;
    return s->n_textures++;
}

static inline void sb_environment(struct sb *b, dr_vec3 color)
{
    b->s->env.present = true;
    b->s->env.color = color;
    b->s->env.strength = 1.0;
}

/* The environment (sb_environment, colour 1) as a 16 x 8 map that brightens
 * left to right and downwards: 0.2 + 0.1 x + 0.05 y in every channel. */
static inline void sb_environment_ramp(struct sb *b)
{
    sb_environment(b, dr_v3s(1.0));
    struct dr_image *map = &b->s->env.map;
    *map = sb_image(16, 8, 3, NULL, 0.0f, false);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++)
            for (int k = 0; k < 3; k++)
                map->data[(y * 16 + x) * 3 + k] = (float)(0.2 + 0.1 * x + 0.05 * y);
}

static inline void sb_light(struct sb *b, struct dr_punctual l)
{
    struct dr_scene *s = b->s;
    /* builder scenes are written in watts (W/sr, W/m^2) */
    s->light_units = DR_LIGHT_UNITS_RADIOMETRIC;
    if (l.watts_per_unit == 0.0)
        l.watts_per_unit = 1.0;
    s->lights = realloc(s->lights, sizeof l * (size_t)(s->n_lights + 1));
    s->lights[s->n_lights++] = l;
}

static inline struct dr_camera sb_camera(dr_vec3 origin, dr_vec3 target, double yfov_deg)
{
    struct dr_camera c;
    memset(&c, 0, sizeof c);
    strcpy(c.name, "test");
    c.origin = origin;
    c.forward = dr_normalize(dr_sub(target, origin));
    dr_vec3 up = fabs(c.forward.y) > 0.99 ? dr_v3(0, 0, -1) : dr_v3(0, 1, 0);
    c.right = dr_normalize(dr_cross(c.forward, up));
    c.up = dr_cross(c.right, c.forward);
    c.yfov = yfov_deg * M_PI / 180.0;
    return c;
}

/* Builds acceleration structure and light tables. */
static inline struct dr_scene *sb_finish(struct sb *b)
{
    if (dr_scene_prepare(b->s) != 0) {
        fprintf(stderr, "dr_scene_prepare: %s\n", dr_last_error());
        exit(2);
    }
    return b->s;
}

/* The occluder-edge case (test_fdcheck.c, test_deriv_sampling.c): a glossy
 * metal floor (roughness 0.2, material 0) reflecting the edge of a dark
 * plate held above it, under a constant sky (so nothing else jumps: a
 * uniform light-sampling density keeps the MIS weights smooth). As the
 * roughness changes, reflected samples cross the plate's silhouette: attached
 * sampling drops that boundary term. The camera looks at the floor below the
 * edge. */
static inline struct dr_scene *sb_occluder_edge(struct dr_camera *cam)
{
    struct sb b;
    sb_init(&b);
    struct dr_material g = sb_diffuse(dr_v3(0.9, 0.9, 0.9));
    g.metallic = 1.0;
    g.roughness = 0.2;
    g.specular = 1.0;
    sb_quad(&b, dr_v3(-3, 0, 3), dr_v3(6, 0, 0), dr_v3(0, 0, -6), sb_material(&b, g));
    /* plate at y = 0.6 over x < 0 (its edge along z at x = 0), facing up;
     * double-sided, so it occludes from below too (a single-sided back is
     * culled, as glTF says) */
    struct dr_material plate = sb_diffuse(dr_v3s(0.05));
    plate.double_sided = true;
    sb_quad(&b, dr_v3(-2, 0.6, -2), dr_v3(0, 0, 4), dr_v3(2, 0, 0), sb_material(&b, plate));
    sb_environment(&b, dr_v3s(1.0));
    struct dr_scene *s = sb_finish(&b);
    if (s)
        s->n_file_materials = s->n_materials;
    *cam = sb_camera(dr_v3(0, 1.2, 1.5), dr_v3(0, 0, 0), 30);
    return s;
}

#endif
