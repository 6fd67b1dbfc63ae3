/* What an emissive texture holds over one triangle, for the light sampler's
 * pick weights (lights.c).
 *
 * Real assets paint their glowing parts into an emissive texture that is
 * black nearly everywhere (a helmet's visor and lamps, a dashboard's
 * buttons) and apply it to the whole mesh. Weighting every triangle by the
 * whole texture's mean spends most light samples on black texels: they
 * carry no light, and the ones that could are rare. With a triangle's own
 * footprint, the triangles that can only read black texels are left out of
 * the light table, and the others are picked by what they hold.
 *
 * A grid per image keeps, for cells of s x s texels, the sum of the texels'
 * emission (the mean of their colour channels, sRGB-decoded, as dr_emission
 * reads them) and how many of them are not zero, as summed-area tables
 * (cells of up to DR_EMISSION_GRID_CELLS per side: a few MB for any
 * image). A triangle's footprint is a rectangle of texels (or up to four,
 * where REPEAT wraps): every texel a bilinear lookup anywhere on the
 * triangle can read, with a margin of one texel for rounding. It covers the
 * triangle's texture-space bounding box, so it is conservative: a triangle
 * whose footprint holds no texel that is not zero emits exactly nothing at
 * any point (dr_emission multiplies by the lookup, a blend of zeros), and
 * leaving it out of the light table changes no image's expected value. */
#ifndef DR_EMISSION_GRID_H
#define DR_EMISSION_GRID_H

#include <stdbool.h>
#include <stdint.h>

#include "scene.h"

#define DR_EMISSION_GRID_CELLS 512

struct dr_emission_grid;

/* The grid of img (which has pixels). NULL: out of memory. */
struct dr_emission_grid *dr_emission_grid_create(const struct dr_image *img);
void dr_emission_grid_destroy(struct dr_emission_grid *g);

/* The image's mean texel emission. */
double dr_emission_grid_mean(const struct dr_emission_grid *g);

/* What texture reference r (a texture of g's image) can read on triangle
 * tri of mesh m: false where every texel of its footprint is zero (then the
 * triangle emits nothing through r anywhere); else true, with the mean
 * emission of the footprint's cells' texels in *mean. */
bool dr_emission_footprint(const struct dr_emission_grid *g, const struct dr_mesh *m, const struct dr_texref *r,
                           const struct dr_texture *tex, uint32_t tri, double *mean);
/* The same for the part of triangle tri with corners corner[k] = (b1, b2)
 * (a part the light table samples on its own, lights.c): its footprint's
 * mean, how many texels it covers (whole cells, as the mean counts them)
 * and how many of those are not zero. */
struct dr_footprint {
    double mean, texels, lit;
};
bool dr_emission_footprint_part(const struct dr_emission_grid *g, const struct dr_mesh *m, const struct dr_texref *r,
                                const struct dr_texture *tex, uint32_t tri, double corner[3][2],
                                struct dr_footprint *f);

#endif
