/* Image losses: the mean over pixels and channels of |I - T| (l1) or
 * (I - T)^2 (l2), and their derivative with respect to I. */
#ifndef DR_LOSS_H
#define DR_LOSS_H

#include <stddef.h>

enum dr_loss_kind { DR_LOSS_L1, DR_LOSS_L2 };

/* "l1"/"l2" -> kind; -1 when unknown. */
int dr_loss_parse(const char *name);
const char *dr_loss_name(enum dr_loss_kind k);

/* n = pixels * channels values each. */
double dr_loss_eval(enum dr_loss_kind k, const float *image, const float *target, size_t n);
/* d_image[i] = d_out * d loss / d image[i] (l1 at I == T: 0). */
void d_loss_eval(enum dr_loss_kind k, const float *image, const float *target, size_t n, double d_out,
                 float *d_image);
/* One value's part of d_loss_eval: d_out * d loss / d image[i] at image[i] =
 * image, target[i] = target, for a loss over n values. Both losses are means
 * of per-value terms, so a pixel's adjoint needs only that pixel. */
double d_loss_value(enum dr_loss_kind k, double image, double target, size_t n, double d_out);

#endif
