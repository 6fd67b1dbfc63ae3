#include "lights.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "bsdf.h"
#include "cdf.h"
#include "emission_grid.h"
#include "env8.h"
#include "error.h"
#include "simd_trig.h"

/* Discrete distribution over: [0, n_emitters) emissive triangles, then the
 * punctual lights, then (if present) the environment. */
struct dr_light_sampler {
    int64_t n_emitters;
    int64_t *emitter_tri;      /* triangle of each emitter entry */
    double *tri_pick;          /* per triangle: probability of picking it (0: not an emitter) */
    double *tri_pick_density;  /* per triangle: pick probability / area (area density) */
    double *emitter_area;      /* per emitter entry */
    uint32_t *emitter_sub;     /* per emitter entry: 0, the whole triangle; else one of its parts
                                  (dr_light_part_point) */
    /* Triangles with parts (a large emissive texture's footprint with black
     * texels, emitter_weights): their tri_pick_density is -1 and the
     * density at a point is its part's (area_density). NULL: none has. */
    uint8_t *tri_level;        /* per triangle: 0, or the levels of its 4^level parts */
    int64_t *tri_part_first;   /* per triangle with parts: its first in part_density */
    double *part_density;      /* per part: pick probability / area (0: not an entry) */
    int64_t n_parts;
    int n_punctual;
    int env_entry;             /* index of the environment in cdf, -1 if none */
    int64_t n_entries;
    double *cdf;               /* n_entries + 1 */
    uint32_t *cdf_guide;       /* n_entries + 1: its guide table (cdf.h) */
    double *pick;              /* n_entries: probability of each entry */
    double scene_radius;
    dr_vec3 scene_center;
    /* environment map importance sampling: piecewise constant over texels */
    int env_w, env_h;
    double *env_marginal;      /* env_h + 1: cdf over rows */
    double *env_conditional;   /* env_h * (env_w + 1): cdf over columns per row */
    uint32_t *env_marginal_guide;      /* env_h + 1: their guide tables (cdf.h) */
    uint32_t *env_conditional_guide;   /* env_h * (env_w + 1) */
    double *env_row_sin;       /* env_h: sin of each row's centre angle, the weights' factor (libm's sin
                                  per sample and per escaped ray was 3 % of a render under a map) */
    double env_integral;       /* sum of texel weights / (w h), for the pdf */
    int texture_averages;      /* whole-image passes the build made (one per emissive image) */
    int n_materials;
    bool *mat_emits;           /* n_materials: every one of its triangles is an entry */
};

/* A material's emitted power per unit area (up to pi) before its emissive
 * texture: factor x strength, both sides' where it is double-sided. */
static double emitter_power_weight(const struct dr_material *m)
{
    dr_vec3 e = dr_scale(m->emissive_factor, m->emissive_strength);
    double w = (e.x + e.y + e.z) / 3.0;
    return m->double_sided ? 2.0 * w : w;
}

/* The emissive texture of material m where the light table weights its
 * triangles by their footprints (emission_grid.h): it emits and its
 * texture has pixels. NULL otherwise. */
static const struct dr_texref *footprint_texture(const struct dr_scene *s, const struct dr_material *m)
{
    const struct dr_texref *r = &m->emissive_tex;
    if (emitter_power_weight(m) <= 0.0 || r->texture < 0)
        return NULL;
    return dr_image_has_pixels(&s->images[s->textures[r->texture].image]) ? r : NULL;
}

/* ---- a triangle's parts ----
 * Midpoint subdivision in barycentric space: part d of a triangle is the
 * one at corner d (0: b0's, 1: b1's, 2: b2's) or the middle one (3,
 * upside down), each a quarter of it. Level L divides L times; a part's
 * code holds its digits, the top level's highest. The maps are exact
 * halvings and unit shifts, so a point mapped into a part is located in it
 * again (dr_light_part_locate) but on a part's edge. */

/* (b1, b2) of the point with (b1, b2) in part d, in its parent. */
static inline void part_to_parent(unsigned d, double *b1, double *b2)
{
    const double x = 0.5 * *b1, y = 0.5 * *b2;
    *b1 = d == 1 ? 0.5 + x : d == 3 ? 0.5 - x : x;
    *b2 = d == 2 ? 0.5 + y : d == 3 ? 0.5 - y : y;
}

void dr_light_part_point(uint32_t sub, double *b1, double *b2)
{
    const unsigned level = sub & 7u;
    uint32_t code = sub >> 3;
    for (unsigned l = 0; l < level; l++, code >>= 2)   /* the deepest digit first */
        part_to_parent(code & 3u, b1, b2);
}

uint32_t dr_light_part_locate(unsigned level, double b1, double b2)
{
    uint32_t code = 0;
    for (unsigned l = 0; l < level; l++) {
        unsigned d;
        if (b1 >= 0.5)
            d = 1, b1 = 2.0 * b1 - 1.0, b2 = 2.0 * b2;
        else if (b2 >= 0.5)
            d = 2, b1 = 2.0 * b1, b2 = 2.0 * b2 - 1.0;
        else if (b1 + b2 <= 0.5)
            d = 0, b1 = 2.0 * b1, b2 = 2.0 * b2;
        else
            d = 3, b1 = 1.0 - 2.0 * b1, b2 = 1.0 - 2.0 * b2;
        code = 4u * code + d;
    }
    return code;
}

/* How many times to divide a textured emitter whose footprint is f: not
 * at all where it holds no black texel (its parts would be picked by
 * nearly the same weights), else until a part's share of the footprint is
 * at most 64 texels (8 x 8), at most DR_LIGHT_MAX_LEVEL times (4096 parts).
 * Measured on bench part n's panel as two triangles: parts of up to 256
 * texels left 2.2 x the variance of these. */
static unsigned part_level(const struct dr_footprint *f)
{
    unsigned level = 0;
    if (f->lit >= f->texels)
        return 0;
    while (level < DR_LIGHT_MAX_LEVEL && f->texels > 64.0 * (double)(1u << (2 * level)))
        level++;
    return level;
}

/* The parts' weights of triangle t (a whole triangle's weight w, its
 * footprint's texture r through grid g) into part_w[0 .. 4^level), -1 for
 * a part whose footprint holds only black texels. Returns whether any part
 * was left out. */
static bool part_weights(const struct dr_scene *s, const struct dr_emission_grid *g, const struct dr_texref *r,
                         uint32_t t, unsigned level, double w, double *part_w)
{
    const struct dr_texture *tex = &s->textures[r->texture];
    const uint32_t n = 1u << (2 * level);
    bool dropped = false;
    for (uint32_t j = 0; j < n; j++) {
        double corner[3][2] = {{0.0, 0.0}, {1.0, 0.0}, {0.0, 1.0}};
        for (int k = 0; k < 3; k++)
            dr_light_part_point(j << 3 | level, &corner[k][0], &corner[k][1]);
        struct dr_footprint f;
        if (dr_emission_footprint_part(g, &s->mesh, r, tex, t, corner, &f)) {
            part_w[j] = w / (double)n * fmax(f.mean, 1e-6 * dr_emission_grid_mean(g));
        } else {
            part_w[j] = -1.0;
            dropped = true;
        }
    }
    return dropped;
}

/* Room for the parts of one more triangle: ls->tri_level and
 * tri_part_first on the first, part_w grown to hold n more. */
static int reserve_parts(const struct dr_mesh *m, struct dr_light_sampler *ls, double **part_w, int64_t *cap,
                         uint32_t n)
{
    if (!ls->tri_level) {
        ls->tri_level = calloc((size_t)m->n_triangles + 1, 1);
        ls->tri_part_first = calloc((size_t)m->n_triangles + 1, sizeof(int64_t));
        if (!ls->tri_level || !ls->tri_part_first)
            return DR_ERR_NOMEM;
    }
    if (ls->n_parts + n > *cap) {
        int64_t c = 2 * (ls->n_parts + n);
        double *p = realloc(*part_w, sizeof(double) * (size_t)c);
        if (!p)
            return DR_ERR_NOMEM;
        *part_w = p, *cap = c;
    }
    return 0;
}

static inline unsigned tri_level(const struct dr_light_sampler *ls, uint32_t t)
{
    return ls->tri_level ? ls->tri_level[t] : 0u;
}

/* The emitter weights of every triangle (power: pi x weight x area) into
 * tri_w, -1 for a triangle that is not an entry; which materials have all
 * their triangles entries into ls->mat_emits. A textured emitter's triangle
 * is weighted by the mean of its texture's footprint, and left out where
 * that holds only black texels (it emits nothing anywhere); one grid per
 * image, built when its first triangle asks (ls->texture_averages: a
 * per-triangle pass over a 2048^2 texture made loading a helmet-class model
 * take minutes, issue 13). A large one with black texels in its footprint
 * is divided (part_level): its parts' weights go to *part_w, from
 * ls->tri_part_first[t], the same way. Returns 0 or DR_ERR_NOMEM. */

static int emitter_weights(const struct dr_scene *s, struct dr_light_sampler *ls, double *tri_w, double **part_w)
{
    int64_t part_cap = 0;
    const struct dr_mesh *m = &s->mesh;
    struct dr_emission_grid **grid = calloc((size_t)s->n_images + 1, sizeof *grid);
    if (!grid || !(ls->mat_emits = malloc((size_t)s->n_materials + 1))) {
        free(grid);
        return DR_ERR_NOMEM;
    }
    for (int i = 0; i < s->n_materials; i++)
        ls->mat_emits[i] = emitter_power_weight(&s->materials[i]) > 0.0;
    int rc = 0;
    for (uint32_t t = 0; t < m->n_triangles && rc == 0; t++) {
        const struct dr_material *mat = &s->materials[m->material[t]];
        const double w = emitter_power_weight(mat);
        tri_w[t] = w > 0.0 ? M_PI * w * dr_triangle_area(m, t) : -1.0;
        const struct dr_texref *r = footprint_texture(s, mat);
        if (!r)
            continue;
        const struct dr_texture *tex = &s->textures[r->texture];
        struct dr_emission_grid **g = &grid[tex->image];
        if (!*g && !(*g = dr_emission_grid_create(&s->images[tex->image]))) {
            rc = DR_ERR_NOMEM;
            break;
        }
        double corner[3][2] = {{0.0, 0.0}, {1.0, 0.0}, {0.0, 1.0}};
        struct dr_footprint f;
        unsigned level = dr_emission_footprint_part(*g, m, r, tex, t, corner, &f) ? part_level(&f) : 0;
        while (level > 0 && ls->n_parts + (1 << (2 * level)) > DR_LIGHT_MAX_PARTS)
            level--;   /* (a texture tiled over many large triangles: the first get parts) */
        if (level > 0) {   /* sampled part by part, each weighted by its own footprint */
            const uint32_t n = 1u << (2 * level);
            if ((rc = reserve_parts(m, ls, part_w, &part_cap, n)) != 0)
                break;
            ls->tri_level[t] = (uint8_t)level;
            ls->tri_part_first[t] = ls->n_parts;
            if (part_weights(s, *g, r, t, level, tri_w[t], *part_w + ls->n_parts))
                ls->mat_emits[m->material[t]] = false;
            ls->n_parts += n;
        } else if (f.lit > 0.0) {
            /* (a footprint with a texel that is not zero stays an entry of
             * weight above 0, however small its mean: a triangle of pick 0
             * counts as not emitting) */
            tri_w[t] *= fmax(f.mean, 1e-6 * dr_emission_grid_mean(*g));
        } else {
            tri_w[t] = -1.0;
            ls->mat_emits[m->material[t]] = false;
        }
    }
    for (int i = 0; i < s->n_images; i++) {
        ls->texture_averages += grid[i] != NULL;
        dr_emission_grid_destroy(grid[i]);
    }
    free(grid);
    return rc;
}

int dr_light_sampler_texture_averages(const struct dr_light_sampler *ls) { return ls->texture_averages; }

static int build_env_tables(const struct dr_scene *s, struct dr_light_sampler *ls)
{
    const struct dr_image *img = &s->env.map;
    int w = img->width, h = img->height, c = img->channels;
    ls->env_w = w;
    ls->env_h = h;
    ls->env_marginal = malloc(sizeof(double) * (size_t)(h + 1));
    /* (the two per-texel tables in huge pages where they are big: a map's
     * lookups land anywhere in them, and in 4 KiB pages most missed the TLB) */
    ls->env_conditional = dr_alloc_big(sizeof(double) * (size_t)h * (size_t)(w + 1));
    ls->env_row_sin = malloc(sizeof(double) * (size_t)h);
    if (!ls->env_marginal || !ls->env_conditional || !ls->env_row_sin)
        return DR_ERR_NOMEM;
    double total = 0.0;
    ls->env_marginal[0] = 0.0;
    const float *texels = img->linear ? img->linear : img->data;
    for (int y = 0; y < h; y++) {
        /* texel weight: mean radiance times the solid angle of its row */
        double sin_theta = ls->env_row_sin[y] = sin(M_PI * (y + 0.5) / h);
        double *row = ls->env_conditional + (size_t)y * (w + 1);
        row[0] = 0.0;
        for (int x = 0; x < w; x++) {
            const float *p = texels + ((size_t)y * w + x) * c;
            double v = c >= 3 ? (fabs(p[0]) + fabs(p[1]) + fabs(p[2])) / 3.0 : fabs(p[0]);
            if (!isfinite(v))
                v = 0.0;
            row[x + 1] = row[x] + v * sin_theta;
        }
        double row_sum = row[w];
        if (row_sum > 0.0)
            for (int x = 1; x <= w; x++)
                row[x] /= row_sum;
        else
            for (int x = 1; x <= w; x++)
                row[x] = (double)x / w;
        total += row_sum;
        ls->env_marginal[y + 1] = total;
    }
    if (total > 0.0) {
        for (int y = 1; y <= h; y++)
            ls->env_marginal[y] /= total;
    } else {
        for (int y = 1; y <= h; y++)
            ls->env_marginal[y] = (double)y / h;
    }
    ls->env_integral = total / ((double)w * h);
    ls->env_marginal_guide = malloc(sizeof(uint32_t) * (size_t)(h + 1));
    ls->env_conditional_guide = dr_alloc_big(sizeof(uint32_t) * (size_t)h * (size_t)(w + 1));
    if (!ls->env_marginal_guide || !ls->env_conditional_guide)
        return DR_ERR_NOMEM;
    dr_cdf_guide_build(ls->env_marginal, h, ls->env_marginal_guide, h);
    for (int y = 0; y < h; y++)
        dr_cdf_guide_build(ls->env_conditional + (size_t)y * (w + 1), w,
                           ls->env_conditional_guide + (size_t)y * (w + 1), w);
    return 0;
}

/* Flux-like power of a punctual light, comparable with emitters' pi * L * A. */
static double punctual_power(const struct dr_punctual *l, double scene_radius)
{
    double I = dr_punctual_radiant(l) * (l->color.x + l->color.y + l->color.z) / 3.0, p;
    switch (l->type) {
    case DR_LIGHT_POINT: p = 4.0 * M_PI * I; break;
    case DR_LIGHT_SPOT: p = 2.0 * M_PI * (1.0 - 0.5 * (l->cos_inner + l->cos_outer)) * I; break;
    default: p = M_PI * scene_radius * scene_radius * I; break;
    }
    return fmax(p, 0.0);
}

/* Turns the power weights in ls->pick into probabilities, the cdf and the
 * per-triangle tables; returns the total weight (0: nothing emits). */
static double normalise_picks(struct dr_light_sampler *ls)
{
    double *w = ls->pick;
    /* Punctual lights and the environment keep a small floor of probability
     * even when dark: otherwise a light at intensity 0 would never be
     * sampled and its intensity could get no gradient. */
    double wmax = 0.0;
    for (int64_t i = 0; i < ls->n_entries; i++)
        wmax = dr_max(wmax, w[i]);
    for (int64_t i = ls->n_emitters; i < ls->n_entries; i++)
        w[i] = dr_max(w[i], wmax > 0.0 ? 1e-3 * wmax : 1.0);
    double total = 0.0;
    ls->cdf[0] = 0.0;
    for (int64_t i = 0; i < ls->n_entries; i++) {
        total += w[i];
        ls->cdf[i + 1] = total;
    }
    for (int64_t i = 0; i < ls->n_entries; i++) {
        ls->pick[i] = total > 0.0 ? w[i] / total : 0.0;
        ls->cdf[i + 1] = total > 0.0 ? ls->cdf[i + 1] / total : 0.0;
    }
    for (int64_t i = 0; i < ls->n_emitters; i++) {
        const int64_t t = ls->emitter_tri[i];
        const uint32_t sub = ls->emitter_sub[i];
        const double density = ls->emitter_area[i] > 0.0 ? ls->pick[i] / ls->emitter_area[i] : 0.0;
        ls->tri_pick[t] += ls->pick[i];   /* (a triangle's parts: the sum) */
        if (sub == 0) {
            ls->tri_pick_density[t] = density;
        } else {   /* looked up by the point's part (area_density) */
            ls->tri_pick_density[t] = -1.0;
            ls->part_density[ls->tri_part_first[t] + (sub >> 3)] = density;
        }
    }
    return total;
}

/* The tables sized by the counts (n_emitters, n_entries, n_parts) and the
 * mesh's triangles; false when out of memory. */
static bool alloc_tables(struct dr_light_sampler *ls, const struct dr_mesh *m)
{
    ls->emitter_tri = malloc(sizeof(int64_t) * (size_t)(ls->n_emitters + 1));
    ls->emitter_sub = malloc(sizeof(uint32_t) * (size_t)(ls->n_emitters + 1));
    ls->tri_pick = calloc((size_t)m->n_triangles + 1, sizeof(double));
    ls->tri_pick_density = calloc((size_t)m->n_triangles + 1, sizeof(double));
    ls->part_density = calloc((size_t)ls->n_parts + 1, sizeof(double));
    ls->emitter_area = malloc(sizeof(double) * (size_t)(ls->n_emitters + 1));
    ls->cdf = malloc(sizeof(double) * (size_t)(ls->n_entries + 1));
    ls->pick = malloc(sizeof(double) * (size_t)(ls->n_entries + 1));
    ls->cdf_guide = malloc(sizeof(uint32_t) * (size_t)(ls->n_entries + 1));
    return ls->emitter_tri && ls->emitter_sub && ls->tri_pick && ls->tri_pick_density && ls->part_density &&
           ls->emitter_area && ls->cdf && ls->pick && ls->cdf_guide;
}

/* The emitting triangles and parts (weight tri_w / part_w >= 0) as entries
 * 0.. of the table, in triangle order, their weights into w; returns how
 * many. */
static int64_t list_emitters(struct dr_light_sampler *ls, const struct dr_mesh *m, const double *tri_w,
                             const double *part_w, double *w)
{
    int64_t k = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        const unsigned level = tri_level(ls, t);
        const uint32_t n = 1u << (2 * level);
        const double *tw = level == 0 ? tri_w + t : part_w + ls->tri_part_first[t];
        for (uint32_t j = 0; j < n; j++)
            if (tw[j] >= 0.0) {
                ls->emitter_tri[k] = t;
                ls->emitter_sub[k] = level == 0 ? 0u : j << 3 | level;
                ls->emitter_area[k] = dr_triangle_area(m, t) / (double)n;
                w[k++] = tw[j];
            }
    }
    return k;
}

struct dr_light_sampler *dr_light_sampler_create(const struct dr_scene *s)
{
    struct dr_light_sampler *ls = calloc(1, sizeof *ls);
    if (!ls)
        goto nomem;
    ls->env_entry = -1;
    ls->scene_center = dr_scale(dr_add(s->bbox_min, s->bbox_max), 0.5);
    ls->scene_radius = 0.5 * dr_length(dr_sub(s->bbox_max, s->bbox_min));
    if (!(ls->scene_radius > 0.0))
        ls->scene_radius = 1.0;

    const struct dr_mesh *m = &s->mesh;
    double *tri_w = malloc(sizeof(double) * ((size_t)m->n_triangles + 1)), *part_w = NULL;
    ls->n_materials = s->n_materials;
    if (!tri_w || emitter_weights(s, ls, tri_w, &part_w) != 0) {
        free(tri_w);
        free(part_w);
        goto nomem;
    }
    for (uint32_t t = 0; t < m->n_triangles; t++)
        ls->n_emitters += tri_level(ls, t) == 0 ? tri_w[t] >= 0.0 : 0;
    for (int64_t j = 0; j < ls->n_parts; j++)
        ls->n_emitters += part_w[j] >= 0.0;
    ls->n_punctual = s->n_lights;
    ls->n_entries = ls->n_emitters + ls->n_punctual + (s->env.present ? 1 : 0);
    if (!alloc_tables(ls, m)) {
        free(tri_w);
        free(part_w);
        goto nomem;
    }

    /* Power estimates, comparable across light kinds: flux in watts-ish. */
    double *w = ls->pick;
    int64_t k = list_emitters(ls, m, tri_w, part_w, w);
    free(tri_w);
    free(part_w);
    for (int i = 0; i < s->n_lights; i++)
        w[k++] = punctual_power(&s->lights[i], ls->scene_radius);
    if (s->env.present) {
        if (s->env.map.data && build_env_tables(s, ls) != 0)
            goto nomem;
        double mean = (s->env.color.x + s->env.color.y + s->env.color.z) / 3.0 * s->env.strength;
        if (s->env.map.data)
            mean *= ls->env_integral * 0.5 * M_PI; /* mean radiance over the sphere */
        ls->env_entry = (int)k;
        w[k++] = fmax(M_PI * M_PI * ls->scene_radius * ls->scene_radius * mean, 0.0);
    }
    double total = normalise_picks(ls);
    if (ls->n_entries > 0)
        dr_cdf_guide_build(ls->cdf, ls->n_entries, ls->cdf_guide, ls->n_entries);
    if (total <= 0.0)
        ls->n_entries = 0;   /* nothing emits: NEE is skipped entirely */
    return ls;
nomem:
    dr_set_error("out of memory building the light tables");
    dr_light_sampler_destroy(ls);
    return NULL;
}

void dr_light_sampler_destroy(struct dr_light_sampler *ls)
{
    if (!ls)
        return;
    free(ls->emitter_tri);
    free(ls->emitter_sub);
    free(ls->tri_level);
    free(ls->tri_part_first);
    free(ls->part_density);
    free(ls->tri_pick);
    free(ls->tri_pick_density);
    free(ls->emitter_area);
    free(ls->cdf);
    free(ls->cdf_guide);
    free(ls->pick);
    free(ls->env_marginal);
    free(ls->env_conditional);
    free(ls->env_marginal_guide);
    free(ls->env_row_sin);
    free(ls->env_conditional_guide);
    free(ls->mat_emits);
    free(ls);
}

bool dr_light_sampler_empty(const struct dr_light_sampler *ls) { return ls->n_entries == 0; }

bool dr_light_material_emits(const struct dr_light_sampler *ls, int material)
{
    return material >= 0 && material < ls->n_materials && ls->mat_emits[material];
}

void dr_env_dir_to_uv(dr_vec3 d, double *u, double *v)
{
    /* simd_trig.h's atan2 and acos (within a few ulp of libm's), whose
     * eight-lane twins env8.c's dr_env8_dir_to_uv runs with these
     * operations: the packet renderer's lanes and this agree to the bit */
    *u = 0.5 + dr_atan2(d.x, -d.z) * (0.5 / M_PI);
    *v = dr_acos(dr_clamp(d.y, -1.0, 1.0)) * DR_INV_PI;
}

dr_vec3 dr_env_uv_to_dir(double u, double v)
{
    /* phi = 2 pi (u - 1/2), theta = pi v = 2 pi (v / 2): sines and cosines
     * of turns (dr_sincos_turn, within 2.3e-16; libm took a tenth of a
     * render under a map here) */
    double sin_phi, cos_phi, sin_theta, cos_theta;
    dr_sincos_turn(u - 0.5, &sin_phi, &cos_phi);
    dr_sincos_turn(0.5 * v, &sin_theta, &cos_theta);
    return dr_v3(sin_theta * sin_phi, cos_theta, -sin_theta * cos_phi);
}

/* dr_env_radiance with a map, at the direction's map coordinates (u, v). */
static dr_vec3 env_radiance_uv(const struct dr_scene *s, double u, double v)
{
    double px[4];
    dr_texture_eval(&dr_env_texture, &s->env.map, u, v, true, px);   /* decoded copy if 8-bit sRGB */
    return dr_mul(dr_scale(s->env.color, s->env.strength), dr_v3(px[0], px[1], px[2]));
}

dr_vec3 dr_env_radiance(const struct dr_scene *s, dr_vec3 dir)
{
    if (!s->env.map.data)
        return dr_scale(s->env.color, s->env.strength);
    double u, v;
    dr_env_dir_to_uv(dir, &u, &v);
    return env_radiance_uv(s, u, v);
}

void d_env_radiance(const struct dr_scene *s, const struct dr_param_set *ps, dr_vec3 dir, dr_vec3 d_L,
                    struct dr_grad_sink *k)
{
    if (!ps->env_active)
        return;
    struct dr_env_lookup at = {.valid = false, .map = dr_v3s(1.0)};
    if (s->env.map.data) {
        double px[4];
        dr_env_dir_to_uv(dir, &at.u, &at.v);
        dr_texture_eval(&dr_env_texture, &s->env.map, at.u, at.v, true, px);
        at.map = dr_v3(px[0], px[1], px[2]);
        at.valid = true;
    }
    d_env_radiance_at(s, ps, &at, d_L, k);
}

void d_env_radiance_at(const struct dr_scene *s, const struct dr_param_set *ps, const struct dr_env_lookup *at,
                       dr_vec3 d_L, struct dr_grad_sink *k)
{
    if (!ps->env_active)
        return;
    /* L = color * strength * map(dir) */
    const dr_vec3 map = at->valid ? at->map : dr_v3s(1.0);
    const double u = at->u, v = at->v;
    if (ps->env_color >= 0) {
        dr_vec3 g = dr_scale(dr_mul(d_L, map), s->env.strength);
        dr_sink_add3(k, ps->env_color, g);
    }
    if (ps->env_strength >= 0)
        dr_sink_add(k, ps->env_strength, dr_dot(d_L, dr_mul(s->env.color, map)));
    if (ps->env_map >= 0 && s->env.map.data) {
        dr_vec3 g = dr_scale(dr_mul(d_L, s->env.color), s->env.strength);
        double d_out[4] = {g.x, g.y, g.z, 0.0};
        d_texture_eval(&dr_env_texture, &s->env.map, u, v, d_out, ps->env_map, k);
    }
}

/* env_pdf_dir with a map, at the direction's map coordinates (u, v). */
static double env_pdf_uv(const struct dr_light_sampler *ls, double u, double v)
{
    int x = (int)dr_env_cell(u, ls->env_w), y = (int)dr_env_cell(v, ls->env_h);
    const double *row = ls->env_conditional + (size_t)y * (ls->env_w + 1);
    double p_uv = (ls->env_marginal[y + 1] - ls->env_marginal[y]) * (row[x + 1] - row[x]) * ls->env_w * ls->env_h;
    double st = ls->env_row_sin[y];
    /* Use the row-centre sine, the same factor the weights were built with,
     * so the density stays finite at the poles and matches sampling. */
    return st > 0.0 ? p_uv / (2.0 * M_PI * M_PI * st) : 0.0;
}

static double env_pdf_dir(const struct dr_light_sampler *ls, dr_vec3 dir, double sky_pdf)
{
    if (!ls->env_marginal)
        return sky_pdf;   /* (a constant sky: the point's own density, dr_light_sample) */
    double u, v;
    dr_env_dir_to_uv(dir, &u, &v);
    return env_pdf_uv(ls, u, v);
}

dr_vec3 dr_env_radiance_pdf(const struct dr_scene *s, const struct dr_light_sampler *ls, dr_vec3 dir,
                            double sky_pdf, double *pdf)
{
    if (!s->env.map.data || !ls->env_marginal) {
        if (pdf)
            *pdf = dr_light_pdf_env(s, ls, dir, sky_pdf);
        return dr_env_radiance(s, dir);
    }
    double u, v;
    dr_env_dir_to_uv(dir, &u, &v);
    if (pdf)   /* dr_light_pdf_env's */
        *pdf = ls->env_entry < 0 || ls->n_entries == 0 ? 0.0 : ls->pick[ls->env_entry] * env_pdf_uv(ls, u, v);
    return env_radiance_uv(s, u, v);
}

double dr_light_pdf_env(const struct dr_scene *s, const struct dr_light_sampler *ls, dr_vec3 dir, double sky_pdf)
{
    (void)s;
    if (ls->env_entry < 0 || ls->n_entries == 0)
        return 0.0;
    return ls->pick[ls->env_entry] * env_pdf_dir(ls, dir, sky_pdf);
}

double dr_light_pdf_env_dsky(const struct dr_light_sampler *ls)
{
    if (ls->env_entry < 0 || ls->n_entries == 0 || ls->env_marginal)
        return 0.0;
    return ls->pick[ls->env_entry];
}

double dr_light_pdf_area_pick(const struct dr_light_sampler *ls, int64_t tri) { return ls->tri_pick[tri]; }

double dr_light_area_density(const struct dr_light_sampler *ls, int64_t tri, double b1, double b2)
{
    const double d = ls->tri_pick_density[tri];
    if (d >= 0.0)
        return d;
    return ls->part_density[ls->tri_part_first[tri] + dr_light_part_locate(ls->tri_level[tri], b1, b2)];
}

double dr_light_pdf_area(const struct dr_scene *s, const struct dr_light_sampler *ls, dr_vec3 from,
                         const struct dr_hit *hit)
{
    (void)s;
    double density = dr_light_area_density(ls, hit->tri, hit->b1, hit->b2);
    if (density <= 0.0)
        return 0.0;
    dr_vec3 d = dr_sub(hit->p, from);
    double d2 = dr_dot(d, d);
    double cos_l = fabs(dr_dot(hit->ng, d)) / sqrt(d2);
    return cos_l > 0.0 ? density * d2 / cos_l : 0.0;
}

bool dr_light_tables(const struct dr_light_sampler *ls, struct dr_light_tables *t)
{
    if (ls->n_entries == 0)
        return false;
    *t = (struct dr_light_tables){
        .n_entries = ls->n_entries,
        .n_emitters = ls->n_emitters,
        .cdf = ls->cdf,
        .cdf_guide = ls->cdf_guide,
        .pick = ls->pick,
        .emitter_tri = ls->emitter_tri,
        .emitter_area = ls->emitter_area,
        .emitter_sub = ls->emitter_sub,
        .any_parts = ls->n_parts > 0,
        .tri_pick = ls->tri_pick,
        .tri_pick_density = ls->tri_pick_density,
        .env_uniform_entry = ls->env_entry >= 0 && !ls->env_marginal ? ls->env_entry : -1,
        .env_map_entry = ls->env_entry >= 0 && ls->env_marginal ? ls->env_entry : -1};
    return true;
}

bool dr_light_env_tables(const struct dr_light_sampler *ls, struct dr_env_tables *t)
{
    if (!ls->env_marginal || ls->env_entry < 0 || ls->n_entries == 0)
        return false;
    *t = (struct dr_env_tables){ls->env_w, ls->env_h, ls->env_marginal, ls->env_marginal_guide, ls->env_conditional,
                                ls->env_conditional_guide, ls->env_row_sin, ls->pick[ls->env_entry]};
    return true;
}

dr_vec3 dr_emission(const struct dr_scene *s, const struct dr_hit *hit)
{
    const struct dr_material *m = &s->materials[hit->material];
    if (!hit->front && !m->double_sided)
        return dr_v3s(0.0);
    dr_vec3 e = dr_scale(m->emissive_factor, m->emissive_strength);
    if (m->emissive_tex.texture >= 0 && !dr_is_black(e)) {
        const struct dr_texture *t = &s->textures[m->emissive_tex.texture];
        double px[4], uv[2];
        dr_texref_uv(&s->mesh, &m->emissive_tex, hit, uv);
        dr_texture_eval(t, &s->images[t->image], uv[0], uv[1], true, px);
        e = dr_mul(e, dr_v3(px[0], px[1], px[2]));
    }
    return e;
}

void dr_emission_prefetch(const struct dr_scene *s, const struct dr_hit *hit)
{
    const struct dr_material *m = &s->materials[hit->material];
    if (m->emissive_tex.texture < 0 || dr_is_black(m->emissive_factor) || m->emissive_strength == 0.0)
        return;   /* (dr_emission reads no texel) */
    const struct dr_texture *t = &s->textures[m->emissive_tex.texture];
    double uv[2];
    dr_texref_uv(&s->mesh, &m->emissive_tex, hit, uv);
    dr_texture_prefetch(t, &s->images[t->image], uv[0], uv[1], true);
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
    double uv[2] = {0.0, 0.0};
    if (et) {
        double px[4];
        dr_texref_uv(&s->mesh, &m->emissive_tex, hit, uv);
        dr_texture_eval(et, &s->images[et->image], uv[0], uv[1], true, px);
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
        d_texture_eval(et, &s->images[et->image], uv[0], uv[1], d_out, ps->image[et->image], k);
    }
}

static double spot_falloff(const struct dr_punctual *l, double cos_angle)
{
    /* glTF's recommended smooth cone attenuation */
    double scale = 1.0 / fmax(1e-3, l->cos_inner - l->cos_outer);
    double t = dr_clamp((cos_angle - l->cos_outer) * scale, 0.0, 1.0);
    return t * t;
}

static double range_window(double range, double dist)
{
    if (range <= 0.0)
        return 1.0;
    double r = dist / range;
    double w = dr_clamp(1.0 - r * r * r * r, 0.0, 1.0);
    return w * w;
}

/* A constant sky seen from a surface: dr_sky_pdf's mixture, its half and the
 * BSDF's lobe chosen by u_sel (path_simd.c's env_light_samples: the same
 * operations). False where the BSDF's sample fails. */
static bool sample_sky_from_surface(const struct dr_sky_bsdf *sky, double u_sel, double u1, double u2, dr_vec3 *dir,
                                    double *pdf, struct dr_light_sample *out)
{
    double cos_g, pdf_b;
    if (u_sel >= sky->share) {
        const dr_frame fg = dr_frame_from_normal(sky->ng);
        const dr_vec3 local = dr_bsdf_cosine_dir(u1, u2);
        *dir = dr_frame_to_world(&fg, local);
        cos_g = local.z;
        pdf_b = dr_bsdf_pdf(sky->bsdf, sky->wo, dr_frame_to_local(&sky->frame, *dir));
    } else {
        struct dr_bsdf_sample bs;
        if (!dr_bsdf_sample(sky->bsdf, sky->wo, u_sel / sky->share, u1, u2, &bs))
            return false;
        *dir = dr_frame_to_world(&sky->frame, bs.wi);
        cos_g = dr_dot(*dir, sky->ng);
        pdf_b = bs.pdf;
        out->lobe = bs.lobe;
    }
    *pdf = dr_sky_pdf(sky->share, cos_g, pdf_b);
    return true;
}

/* u_sel: sample_sky_from_surface's, where sky is given. */
static bool sample_env(const struct dr_scene *s, const struct dr_light_sampler *ls, const struct dr_sky_bsdf *sky,
                       double u_sel, double u1, double u2, struct dr_light_sample *out)
{
    dr_vec3 dir;
    double pdf;
    if (!ls->env_marginal && sky) {
        if (!sample_sky_from_surface(sky, u_sel, u1, u2, &dir, &pdf, out))
            return false;
    } else if (!ls->env_marginal) {
        /* constant radiance in a medium: uniform sphere */
        double z = 1.0 - 2.0 * u1, r = sqrt(dr_max(0.0, 1.0 - z * z)), cos_phi, sin_phi;
        dr_sincos_turn(u2, &sin_phi, &cos_phi);   /* phi = 2 pi u2 */
        dir = dr_v3(r * cos_phi, r * sin_phi, z);
        pdf = DR_SKY_SPHERE;
    } else {
        int y = (int)dr_cdf_find_guided(ls->env_marginal, ls->env_h, ls->env_marginal_guide, ls->env_h, u1);
        double py = ls->env_marginal[y + 1] - ls->env_marginal[y];
        if (py <= 0.0)
            return false;
        double dv = (u1 - ls->env_marginal[y]) / py;
        const double *row = ls->env_conditional + (size_t)y * (ls->env_w + 1);
        const uint32_t *row_guide = ls->env_conditional_guide + (size_t)y * (ls->env_w + 1);
        int x = (int)dr_cdf_find_guided(row, ls->env_w, row_guide, ls->env_w, u2);
        double px = row[x + 1] - row[x];
        if (px <= 0.0)
            return false;
        double du = (u2 - row[x]) / px;
        double u = (x + dr_clamp(du, 0.0, 1.0)) / ls->env_w, v = (y + dr_clamp(dv, 0.0, 1.0)) / ls->env_h;
        dir = dr_env_uv_to_dir(u, v);
        double st = ls->env_row_sin[y];
        pdf = st > 0.0 ? py * px * ls->env_w * ls->env_h / (2.0 * M_PI * M_PI * st) : 0.0;
    }
    if (!(pdf > 0.0))
        return false;
    out->wi = dir;
    out->dist = INFINITY;
    out->type = DR_LS_ENV;
    out->radiance = dr_env_radiance(s, dir);
    out->pdf = pdf * ls->pick[ls->env_entry];
    out->delta = false;
    out->valid = true;
    return !dr_is_black(out->radiance);
}

bool dr_light_sample(const struct dr_scene *s, const struct dr_light_sampler *ls, dr_vec3 p,
                     const struct dr_sky_bsdf *sky, double u_pick, double u1, double u2, struct dr_light_sample *out)
{
    out->env_at.valid = false;
    out->valid = false;
    out->lobe = -1;
    if (ls->n_entries == 0)
        return false;
    int64_t i = dr_cdf_find_guided(ls->cdf, ls->n_entries, ls->cdf_guide, ls->n_entries, u_pick);
    if (ls->pick[i] <= 0.0)
        return false;
    if (i < ls->n_emitters) {
        int64_t tri = ls->emitter_tri[i];
        double su = sqrt(u1), b1 = 1.0 - su, b2 = u2 * su;
        if (ls->emitter_sub[i] != 0)   /* uniform over a part: its point in the triangle */
            dr_light_part_point(ls->emitter_sub[i], &b1, &b2);
        struct dr_hit h;
        dr_hit_at(&s->mesh, tri, b1, b2, &h);
        dr_vec3 d = dr_sub(h.p, p);
        double d2 = dr_dot(d, d);
        if (!(d2 > 0.0))
            return false;
        double dist = sqrt(d2);
        out->wi = dr_scale(d, 1.0 / dist);
        double cos_l = dr_dot(h.ng, out->wi);
        h.front = cos_l < 0.0;   /* the shading point sees the front face */
        double area = ls->emitter_area[i];
        if (cos_l == 0.0 || !(area > 0.0))
            return false;
        out->radiance = dr_emission(s, &h);
        out->dist = dist;
        out->type = DR_LS_AREA;
        out->index = tri;
        out->b1 = b1;
        out->b2 = b2;
        out->target = dr_offset_origin(&h, h.ng, dr_neg(out->wi));
        out->pdf = ls->pick[i] * d2 / (fabs(cos_l) * area);
        out->delta = false;
        out->valid = true;
        return !dr_is_black(out->radiance);
    }
    if (i == ls->env_entry)   /* (u_pick within the sky's share, rescaled: the lobe's choice) */
        return sample_env(s, ls, sky, dr_clamp((u_pick - ls->cdf[i]) / ls->pick[i], 0.0, 1.0), u1, u2, out);

    const struct dr_punctual *l = &s->lights[i - ls->n_emitters];
    dr_vec3 I = dr_scale(l->color, dr_punctual_radiant(l));
    out->type = DR_LS_PUNCTUAL;
    out->index = i - ls->n_emitters;
    out->delta = true;
    out->target = l->position;
    out->pdf = ls->pick[i];
    if (l->type == DR_LIGHT_DIRECTIONAL) {
        out->wi = dr_neg(l->direction);
        out->dist = INFINITY;
        out->atten = 1.0;
        out->radiance = I;
        out->valid = true;
        return true;
    }
    dr_vec3 d = dr_sub(l->position, p);
    double d2 = dr_dot(d, d);
    if (!(d2 > 0.0))
        return false;
    double dist = sqrt(d2);
    out->wi = dr_scale(d, 1.0 / dist);
    out->dist = dist;
    double atten = range_window(l->range, dist) / d2;
    if (l->type == DR_LIGHT_SPOT)
        atten *= spot_falloff(l, -dr_dot(out->wi, l->direction));
    out->atten = atten;
    out->radiance = dr_scale(I, atten);
    out->valid = atten > 0.0;   /* (out of range or cone: no light, and none for any parameter) */
    return atten > 0.0;
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
    case DR_LS_ENV:
        if (ls->env_at.valid)   /* (the sampler's own lookup at wi) */
            d_env_radiance_at(s, ps, &ls->env_at, d_L, k);
        else
            d_env_radiance(s, ps, ls->wi, d_L, k);
        return;
    default: {
        /* radiance = color * intensity * watts_per_unit * atten (intensity in the file's units) */
        const struct dr_punctual *l = &s->lights[ls->index];
        int64_t oc = ps->light_color[ls->index], oi = ps->light_intensity[ls->index];
        if (oc >= 0) {
            dr_vec3 g = dr_scale(d_L, dr_punctual_radiant(l) * ls->atten);
            dr_sink_add3(k, oc, g);
        }
        if (oi >= 0)
            dr_sink_add(k, oi, dr_dot(d_L, l->color) * l->watts_per_unit * ls->atten);
        return;
    }
    }
}

/* ---------------------------------------------- adjoints w.r.t. geometry */

/* wi = (y - p) / r, r = |y - p|: reverse mode into d_p given d_wi and d_r. */
static dr_vec3 d_unit_towards(dr_vec3 wi, double r, dr_vec3 d_wi, double d_r)
{
    /* d wi / d y = (I - wi wi^T) / r, d r / d y = wi^T; d/d p = -d/d y */
    dr_vec3 g = dr_scale(dr_sub(d_wi, dr_scale(wi, dr_dot(wi, d_wi))), 1.0 / r);
    return dr_neg(dr_madd(g, wi, d_r));
}

/* d atten / d r and d atten / d (wi) of a point or spot light's attenuation. */
static void d_punctual_atten(const struct dr_punctual *l, const struct dr_light_sample *ls, double d_atten,
                             dr_vec3 *d_wi, double *d_r)
{
    double r = ls->dist, r2 = r * r;
    double win = range_window(l->range, r), fall = l->type == DR_LIGHT_SPOT ? spot_falloff(l, -dr_dot(ls->wi, l->direction)) : 1.0;
    /* atten = win(r) / r^2 * fall(wi) */
    double d_win = 0.0;
    if (l->range > 0.0) {
        double x = r / l->range, w = 1.0 - x * x * x * x;
        if (w > 0.0 && w < 1.0)
            d_win = 2.0 * w * (-4.0 * x * x * x / l->range);
    }
    *d_r += d_atten * fall * (d_win / r2 - 2.0 * win / (r2 * r));
    if (l->type == DR_LIGHT_SPOT) {
        double scale = 1.0 / fmax(1e-3, l->cos_inner - l->cos_outer);
        double t = (-dr_dot(ls->wi, l->direction) - l->cos_outer) * scale;
        if (t > 0.0 && t < 1.0)   /* fall = t^2, t = (cos - cos_outer) scale, cos = -wi . dir */
            *d_wi = dr_madd(*d_wi, l->direction, -d_atten * win / r2 * 2.0 * t * scale);
    }
}

void d_light_sample_point(const struct dr_scene *s, dr_vec3 p, const struct dr_light_sample *ls, dr_vec3 d_wi,
                          double d_pdf, dr_vec3 d_radiance, dr_vec3 *d_p)
{
    (void)p;
    double d_r = 0.0;
    if (ls->type == DR_LS_AREA) {
        /* pdf = pick r^2 / (|ng . wi| area) with pick / area = pdf |cos| / r^2 */
        struct dr_hit h;
        dr_hit_at(&s->mesh, ls->index, ls->b1, ls->b2, &h);
        double c = dr_dot(h.ng, ls->wi);
        d_r += d_pdf * 2.0 * ls->pdf / ls->dist;
        d_wi = dr_madd(d_wi, h.ng, -d_pdf * ls->pdf / c);
        *d_p = dr_add(*d_p, d_unit_towards(ls->wi, ls->dist, d_wi, d_r));
        return;
    }
    if (ls->type != DR_LS_PUNCTUAL || isinf(ls->dist))
        return;
    const struct dr_punctual *l = &s->lights[ls->index];
    /* radiance = I atten */
    double d_atten = dr_dot(d_radiance, dr_scale(l->color, dr_punctual_radiant(l)));
    d_punctual_atten(l, ls, d_atten, &d_wi, &d_r);
    *d_p = dr_add(*d_p, d_unit_towards(ls->wi, ls->dist, d_wi, d_r));
}

void d_light_pdf_area_points(const struct dr_scene *s, const struct dr_light_sampler *ls, dr_vec3 from,
                             const struct dr_hit *hit, double d_pdf, dr_vec3 *d_from, dr_vec3 *d_hit_p)
{
    (void)s;
    double density = dr_light_area_density(ls, hit->tri, hit->b1, hit->b2);   /* (constant within a part) */
    if (density <= 0.0 || d_pdf == 0.0)
        return;
    /* pdf = density |d|^3 / |ng . d|, d = hit.p - from */
    dr_vec3 d = dr_sub(hit->p, from);
    double d2 = dr_dot(d, d), len = sqrt(d2), c = dr_dot(hit->ng, d);
    if (c == 0.0 || !(d2 > 0.0))
        return;
    double pdf = density * d2 * len / fabs(c);
    dr_vec3 g = dr_scale(dr_sub(dr_scale(d, 3.0 / d2), dr_scale(hit->ng, 1.0 / c)), pdf * d_pdf);
    if (d_hit_p)
        *d_hit_p = dr_add(*d_hit_p, g);
    if (d_from)
        *d_from = dr_sub(*d_from, g);
}

void d_emission_uv(const struct dr_scene *s, const struct dr_hit *hit, dr_vec3 d_Le, struct dr_d_hit *d_hit)
{
    const struct dr_material *m = &s->materials[hit->material];
    if (!hit->front && !m->double_sided)
        return;
    dr_vec3 e = dr_scale(m->emissive_factor, m->emissive_strength);
    if (m->emissive_tex.texture < 0 || dr_is_black(e))
        return;
    const struct dr_texture *t = &s->textures[m->emissive_tex.texture];
    dr_vec3 g = dr_mul(d_Le, e);
    double d_out[4] = {g.x, g.y, g.z, 0.0}, uv[2], d_uv[2] = {0.0, 0.0};
    dr_texref_uv(&s->mesh, &m->emissive_tex, hit, uv);
    d_texture_eval_uv(t, &s->images[t->image], uv[0], uv[1], true, d_out, &d_uv[0], &d_uv[1]);
    d_texref_uv(&m->emissive_tex, d_uv, d_hit);
}

void d_env_dir_to_uv(dr_vec3 d, double d_u, double d_v, dr_vec3 *d_dir)
{
    /* u = 1/2 + atan2(x, -z) / (2 pi): du = (-z dx + x dz) / (2 pi (x^2 + z^2));
     * v = acos(y) / pi: dv = -dy / (pi sqrt(1 - y^2)) */
    double r2 = d.x * d.x + d.z * d.z;
    if (!(r2 > 0.0))
        return;
    double k = d_u / (2.0 * M_PI * r2);
    d_dir->x += -d.z * k;
    d_dir->z += d.x * k;
    if (fabs(d.y) < 1.0)
        d_dir->y += -d_v / (M_PI * sqrt(1.0 - d.y * d.y));
}

void d_env_radiance_dir(const struct dr_scene *s, dr_vec3 dir, dr_vec3 d_L, dr_vec3 *d_dir)
{
    if (!s->env.map.data)
        return;
    double u, v, d_u = 0.0, d_v = 0.0;
    dr_env_dir_to_uv(dir, &u, &v);
    dr_vec3 g = dr_scale(dr_mul(d_L, s->env.color), s->env.strength);
    double d_out[4] = {g.x, g.y, g.z, 0.0};
    d_texture_eval_uv(&dr_env_texture, &s->env.map, u, v, true, d_out, &d_u, &d_v);
    d_env_dir_to_uv(dir, d_u, d_v, d_dir);
}
