/* The table of gradient estimators. */
#include <string.h>

#include "estimator.h"

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
