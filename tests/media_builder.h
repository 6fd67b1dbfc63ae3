/* Media for scenes built in code (scene_builder.h). */
#ifndef DR_TEST_MEDIA_BUILDER_H
#define DR_TEST_MEDIA_BUILDER_H

#include "medium_scene.h"
#include "scene_builder.h"

/* Gives material `mat` (a closed box) the medium m; returns its index. */
static inline int sb_medium(struct sb *b, int mat, struct dr_medium m)
{
    struct dr_scene *s = b->s;
    if (!s->material_medium) {
        s->material_medium = malloc(sizeof(int) * 16);
        for (int i = 0; i < 16; i++)
            s->material_medium[i] = -1;
        s->global_medium = -1;
    }
    s->media = realloc(s->media, sizeof m * (size_t)(s->n_media + 1));
    m.material = mat;
    s->media[s->n_media] = m;
    if (mat >= 0)
        s->material_medium[mat] = s->n_media;
    else
        s->global_medium = s->n_media;
    return s->n_media++;
}

static inline struct dr_medium medium(dr_vec3 extinction, dr_vec3 albedo, double g)
{
    struct dr_medium m;
    memset(&m, 0, sizeof m);
    strcpy(m.name, "test");
    m.extinction = extinction;
    m.albedo = albedo;
    m.g = g;
    m.density_scale = 1.0;
    return m;
}

/* A grid over [lo, hi] with density f(x, y, z) (voxel indices). */
static inline void set_grid(struct dr_medium *m, int nx, int ny, int nz, dr_vec3 lo, dr_vec3 hi,
                     double (*f)(int, int, int))
{
    m->has_grid = true;
    m->grid = (struct dr_grid){.nx = nx, .ny = ny, .nz = nz, .bmin = lo, .bmax = hi};
    m->grid.density = malloc(sizeof(float) * (size_t)nx * ny * nz);
    for (int z = 0; z < nz; z++)
        for (int y = 0; y < ny; y++)
            for (int x = 0; x < nx; x++)
                m->grid.density[((size_t)z * ny + y) * nx + x] = (float)f(x, y, z);
}

#endif
