#include "sampler.h"

#include <string.h>

const char *dr_sampler_kind_name(enum dr_sampler_kind k)
{
    return k == DR_SAMPLER_SOBOL ? "sobol" : k == DR_SAMPLER_STRATIFIED ? "stratified" : "independent";
}

int dr_sampler_kind_parse(const char *name)
{
    if (strcmp(name, "independent") == 0)
        return DR_SAMPLER_INDEPENDENT;
    if (strcmp(name, "sobol") == 0)
        return DR_SAMPLER_SOBOL;
    if (strcmp(name, "stratified") == 0)
        return DR_SAMPLER_STRATIFIED;
    return -1;
}

double dr_sampler_next_structured(struct dr_sampler *s)
{
    if (s->kind == DR_SAMPLER_SOBOL) {
        double u;
        dr_sampler_sobol2(s, ++s->dim, &u, NULL);
        return u;
    }
    ++s->dim;   /* DR_SAMPLER_STRATIFIED */
    return dr_strat_1d(s->index, s->count, (uint32_t)dr_sampler_strat_seed(s, s->dim),
                       dr_sampler_strat_jitter(s, s->dim, 0x3c6ef372fe94f82bULL));
}

void dr_sampler_next2_structured(struct dr_sampler *s, double *u1, double *u2)
{
    if (s->kind == DR_SAMPLER_SOBOL) {
        dr_sampler_sobol2(s, ++s->dim, u1, u2);
        ++s->dim;
        return;
    }
    uint32_t d = ++s->dim;   /* DR_SAMPLER_STRATIFIED */
    ++s->dim;
    dr_strat_2d(s->index, s->grid_m, s->grid_n, dr_sampler_strat_seed(s, d), dr_sampler_strat_jitter(s, d, 0x1ULL),
                dr_sampler_strat_jitter(s, d, 0x2ULL), u1, u2);
}
