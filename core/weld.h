/* Vertices welded by position: glTF primitives split a vertex wherever its
 * normal or texture coordinates differ, but a surface is closed, and its
 * triangles neighbours, in positions. */
#ifndef DR_WELD_H
#define DR_WELD_H

#include <stdint.h>

#include "scene.h"

/* id[v] for every vertex of m: the first vertex at v's position (bitwise
 * equal coordinates, -0 equal to +0). NULL when out of memory (and m has
 * vertices). Linear time: a hash table of the positions. */
uint32_t *dr_mesh_weld(const struct dr_mesh *m);

#endif
