/* The environment map for eight lanes at once (simd.h): the equirectangular
 * mapping, the radiance, the density of next-event estimation and its
 * samples, for the packet renderer (path_simd.c, wave_soa.c). Lane by lane
 * these had been scalar calls (two libm arc functions, a scalar bilinear
 * lookup and two table searches each), and a scene under a map took three
 * times as long per ray as under a constant sky.
 *
 * Each function names the scalar one in lights.c it mirrors and runs its
 * operations, so a lane gets the scalar function's bits (test_render
 * compares the packet renderer with the one-path walker under a map). */
#ifndef DR_ENV8_H
#define DR_ENV8_H

#include <math.h>
#include <stdbool.h>

#include "lights.h"
#include "scene.h"
#include "simd.h"

/* The map's lookup: repeat across the seam, clamp at the poles. */
extern const struct dr_texture dr_env_texture;

/* The cell of a map n cells wide at coordinate t: floor(t n) clamped to
 * [0, n - 1]; 0 for a NaN (no table is read out of bounds). */
static inline double dr_env_cell(double t, int n)
{
    double f = floor(t * n);
    return f == f ? (f < 0.0 ? 0.0 : (f > n - 1.0 ? n - 1.0 : f)) : 0.0;
}

/* dr_env_dir_to_uv: u = 1/2 + atan2(x, -z) / 2 pi, v = acos(y) / pi, with
 * simd_trig.h's atan2 and acos. */
void dr_env8_dir_to_uv(dr_v3x8 dir, dr_f8 *u, dr_f8 *v);

/* The lookup a radiance makes (lights.h's dr_env_lookup, eight lanes): the
 * map coordinates and the texel blend there. */
struct dr_env8_lookup {
    dr_f8 u, v;
    dr_v3x8 map;
};

/* dr_env_radiance_pdf for the lanes of on, in a scene whose environment
 * has a map and its tables t: the radiance seen along dir, and (pdf not
 * NULL) dr_light_pdf_env's density of that direction; its lookup into *at
 * unless at is NULL. Other lanes: 0. */
dr_v3x8 dr_env8_radiance_pdf(const struct dr_scene *s, const struct dr_env_tables *t, dr_m8 on, dr_v3x8 dir,
                             dr_f8 *pdf, struct dr_env8_lookup *at);

/* dr_light_sample's environment-map sample (lights.c's sample_env) from the
 * numbers (u1, u2) for the lanes of on: the direction, its radiance and its
 * density times the environment's pick (and the radiance's lookup into *at
 * unless NULL). Returns the lanes whose sample carries light
 * (dr_light_sample's answer), and those of keep_black whose sample carries
 * none but is one (dr_path_light_kept); the others' outputs are not to be
 * read. */
dr_m8 dr_env8_sample(const struct dr_scene *s, const struct dr_env_tables *t, dr_m8 on, dr_f8 u1, dr_f8 u2,
                     dr_m8 keep_black, dr_v3x8 *wi, dr_v3x8 *radiance, dr_f8 *pdf, struct dr_env8_lookup *at);

#endif
