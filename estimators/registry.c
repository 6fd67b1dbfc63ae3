/* The table of gradient estimators and the names of the sampling modes. */
#include <string.h>

#include "estimator.h"

#include "bsdf.h"   /* enum dr_bsdf_dparam */

extern const struct dr_estimator_ops dr_estimator_prb;
extern const struct dr_estimator_ops dr_estimator_tape;

const struct dr_estimator_ops *const dr_estimators[] = {
    &dr_estimator_prb,
    &dr_estimator_tape,
    NULL,
};

const struct dr_estimator_ops *dr_estimator_find(const char *name)
{
    for (int i = 0; dr_estimators[i]; i++)
        if (strcmp(dr_estimators[i]->name, name) == 0)
            return dr_estimators[i];
    return NULL;
}

static const char *const sampling_names[DR_SAMPLING_COUNT] = {"detached", "attached", "mis", "derivative",
                                                              "derivative-roughness"};

const char *dr_sampling_name(enum dr_sampling s)
{
    return (unsigned)s < DR_SAMPLING_COUNT ? sampling_names[s] : "?";
}

int dr_sampling_parse(const char *name)
{
    for (int i = 0; i < DR_SAMPLING_COUNT; i++)
        if (strcmp(sampling_names[i], name) == 0)
            return i;
    return -1;
}

unsigned dr_sampling_deriv_params(enum dr_sampling s)
{
    if (s == DR_SAMPLING_DERIVATIVE)
        return DR_BSDF_D_BASE | DR_BSDF_D_METALLIC | DR_BSDF_D_ROUGHNESS | DR_BSDF_D_COAT_ROUGHNESS;
    return s == DR_SAMPLING_DERIVATIVE_ROUGHNESS ? DR_BSDF_D_ROUGHNESS | DR_BSDF_D_COAT_ROUGHNESS : 0u;
}

bool dr_estimator_supports(const struct dr_estimator_ops *e, enum dr_sampling s)
{
    return (unsigned)s < DR_SAMPLING_COUNT && (e->sampling & (1u << s)) != 0;
}
