#include "sampler.h"

#include <string.h>

const char *dr_sampler_kind_name(enum dr_sampler_kind k)
{
    return k == DR_SAMPLER_SOBOL ? "sobol" : "independent";
}

int dr_sampler_kind_parse(const char *name)
{
    if (strcmp(name, "independent") == 0)
        return DR_SAMPLER_INDEPENDENT;
    if (strcmp(name, "sobol") == 0)
        return DR_SAMPLER_SOBOL;
    return -1;
}
