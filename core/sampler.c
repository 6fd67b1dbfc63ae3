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
