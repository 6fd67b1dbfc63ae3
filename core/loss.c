#include "loss.h"

#include <math.h>
#include <string.h>

int dr_loss_parse(const char *name)
{
    if (strcmp(name, "l1") == 0)
        return DR_LOSS_L1;
    if (strcmp(name, "l2") == 0)
        return DR_LOSS_L2;
    return -1;
}

const char *dr_loss_name(enum dr_loss_kind k) { return k == DR_LOSS_L1 ? "l1" : "l2"; }

double dr_loss_eval(enum dr_loss_kind k, const float *image, const float *target, size_t n)
{
    double sum = 0.0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)image[i] - (double)target[i];
        sum += k == DR_LOSS_L1 ? fabs(d) : d * d;
    }
    return n > 0 ? sum / (double)n : 0.0;
}

double d_loss_value(enum dr_loss_kind k, double image, double target, size_t n, double d_out)
{
    double scale = n > 0 ? d_out / (double)n : 0.0;
    double d = image - target;
    double g = k == DR_LOSS_L1 ? (d > 0.0 ? 1.0 : (d < 0.0 ? -1.0 : 0.0)) : 2.0 * d;
    return g * scale;
}

void d_loss_eval(enum dr_loss_kind k, const float *image, const float *target, size_t n, double d_out,
                 float *d_image)
{
    for (size_t i = 0; i < n; i++)
        d_image[i] = (float)d_loss_value(k, image[i], target[i], n, d_out);
}
