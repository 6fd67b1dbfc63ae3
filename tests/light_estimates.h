/* Irradiance estimates the light-table tests share (test_emission_grid,
 * test_light_parts). */
#ifndef DR_TEST_LIGHT_ESTIMATES_H
#define DR_TEST_LIGHT_ESTIMATES_H

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>

#include "cdf.h"
#include "geometry.h"
#include "lights.h"
#include "sampler.h"
#include "test.h"

/* Does material m emit (factor x strength not black)? */
static inline bool material_emits(const struct dr_material *m)
{
    return !dr_is_black(dr_scale(m->emissive_factor, m->emissive_strength));
}

/* Irradiance at p (normal +y) from the emitters, with its standard error:
 * by next-event estimation (nee: dr_light_sample) or by uniform points on
 * all emitting area, numbers from seed. *lit: the fraction of samples that
 * carry light. */
static inline void irradiance_at(const struct dr_scene *s, dr_vec3 p, uint64_t seed, bool nee, int n, double *mean,
                                 double *se, double *lit)
{
    const struct dr_mesh *m = &s->mesh;
    double total = 0.0, *cdf = malloc(sizeof(double) * (m->n_triangles + 1));
    cdf[0] = 0.0;
    for (uint32_t t = 0; t < m->n_triangles; t++)
        cdf[t + 1] = total += material_emits(&s->materials[m->material[t]]) ? dr_triangle_area(m, t) : 0.0;
    struct dr_sampler smp;
    dr_sampler_init(&smp, seed, nee, 0);
    double sum = 0.0, sum2 = 0.0;
    int carrying = 0;
    for (int i = 0; i < n; i++) {
        double f = 0.0;
        if (nee) {
            struct dr_light_sample ls;
            double u0 = dr_sampler_next(&smp), u1 = dr_sampler_next(&smp), u2 = dr_sampler_next(&smp);
            if (dr_light_sample(s, s->light_sampler, p, NULL, u0, u1, u2, &ls) && ls.wi.y > 0.0)
                f = (ls.radiance.x + ls.radiance.y + ls.radiance.z) * ls.wi.y / ls.pdf;
        } else {
            const int64_t t = dr_cdf_find(cdf, m->n_triangles, dr_sampler_next(&smp) * total);
            double su = sqrt(dr_sampler_next(&smp)), b2 = dr_sampler_next(&smp) * su;
            struct dr_hit h;
            dr_hit_at(m, t, 1.0 - su, b2, &h);
            dr_vec3 d = dr_sub(h.p, p);
            double d2 = dr_dot(d, d), cos_l = -dr_dot(h.ng, d) / sqrt(d2);
            h.front = cos_l > 0.0;
            dr_vec3 e = dr_emission(s, &h);
            if (cos_l > 0.0 && d.y > 0.0)
                f = (e.x + e.y + e.z) * (d.y / sqrt(d2)) * cos_l / d2 * total;
        }
        carrying += f > 0.0;
        sum += f;
        sum2 += f * f;
    }
    free(cdf);
    *mean = sum / n;
    *se = sqrt(fmax(sum2 / n - *mean * *mean, 0.0) / n);
    *lit = (double)carrying / n;
}

/* Both estimates at p with n samples each, printed and checked: the
 * emitters light p, and next-event estimation agrees with uniform points
 * within 4 standard errors (it is unbiased). */
struct irradiance_pair {
    double nee, se_nee, lit_nee, area, se_area, lit_area;
};
static inline struct irradiance_pair irradiance_agrees(const struct dr_scene *s, dr_vec3 p, uint64_t seed, int n)
{
    struct irradiance_pair r;
    irradiance_at(s, p, seed, true, n, &r.nee, &r.se_nee, &r.lit_nee);
    irradiance_at(s, p, seed, false, n, &r.area, &r.se_area, &r.lit_area);
    printf("irradiance: next-event %.5f +- %.5f (%.1f %% of samples carry light), uniform area %.5f +- %.5f "
           "(%.1f %%)\n", r.nee, r.se_nee, 100 * r.lit_nee, r.area, r.se_area, 100 * r.lit_area);
    CHECK(r.area > 0.0, "the emitters light the point");
    CHECK(fabs(r.nee - r.area) < 4.0 * sqrt(r.se_nee * r.se_nee + r.se_area * r.se_area),
          "next-event estimate %.5f vs uniform points %.5f (se %.5f, %.5f): more than 4 standard errors apart", r.nee,
          r.area, r.se_nee, r.se_area);
    return r;
}

#endif
