/* Vertices welded by position (weld.h). */
#include "weld.h"

#include <stdlib.h>
#include <string.h>

#include "sampler.h"

/* A coordinate's bits, -0 read as +0, so that equal coordinates weld. */
static uint32_t coord_bits(float f)
{
    uint32_t u;
    f = f == 0.0f ? 0.0f : f;
    memcpy(&u, &f, sizeof u);
    return u;
}

uint32_t *dr_mesh_weld(const struct dr_mesh *m)
{
    size_t cap = 16;
    while (cap < 2 * (size_t)m->n_vertices)
        cap *= 2;
    uint32_t *slot = malloc(sizeof(uint32_t) * cap), *id = malloc(sizeof(uint32_t) * ((size_t)m->n_vertices + 1));
    if (!slot || !id) {
        free(slot);
        free(id);
        return NULL;
    }
    memset(slot, 0xff, sizeof(uint32_t) * cap);   /* UINT32_MAX: empty */
    for (uint32_t v = 0; v < m->n_vertices; v++) {
        const float *p = m->positions + 3 * (size_t)v;
        uint32_t b[3] = {coord_bits(p[0]), coord_bits(p[1]), coord_bits(p[2])};
        size_t h = dr_hash64(((uint64_t)b[0] << 32 | b[1]) ^ dr_hash64(b[2])) & (cap - 1);
        for (;; h = (h + 1) & (cap - 1)) {   /* linear probing */
            if (slot[h] == UINT32_MAX) {
                slot[h] = id[v] = v;
                break;
            }
            const float *q = m->positions + 3 * (size_t)slot[h];
            if (coord_bits(q[0]) == b[0] && coord_bits(q[1]) == b[1] && coord_bits(q[2]) == b[2]) {
                id[v] = slot[h];
                break;
            }
        }
    }
    free(slot);
    return id;
}
