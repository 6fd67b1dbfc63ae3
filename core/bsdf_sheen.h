/* The sheened BSDF (KHR_materials_sheen, struct dr_bsdf's sheened): bsdf.c's
 * public functions hand a sheened BSDF (not coated, or the base a coat
 * hands down) to these, which compose the base BSDF out of those same
 * public functions called on a copy without the sheen. Private to bsdf.c,
 * bsdf_coat.c and bsdf_sheen.c: callers use bsdf.h. */
#ifndef DR_BSDF_SHEEN_H
#define DR_BSDF_SHEEN_H

#include "bsdf.h"

/* f (and, if pdf is not NULL, the density; wo.z, wi.z > DR_BSDF_COS_EPS). */
dr_vec3 dr_sheen_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf);
bool dr_sheen_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                     struct dr_bsdf_sample *out);
/* The lobe dr_sheen_sample chooses with u_lobe (wo.z > DR_BSDF_COS_EPS);
 * a coat over the sheen chooses the base's lobe with it. */
enum dr_bsdf_lobe dr_sheen_pick_lobe(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe);
dr_vec3 dr_sheen_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2);
double dr_sheen_sky_share(const struct dr_bsdf *b, dr_vec3 wo);
double dr_sheen_specular_prob(const struct dr_bsdf *b, dr_vec3 wo);

void d_sheen_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                  dr_vec3 *d_wo, dr_vec3 *d_wi);
void d_sheen_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, bool prob_moves, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi);
void d_sheen_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo);
void d_sheen_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                        dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo);
/* Derivative sampling (bsdf.h): the base's NDF part times T(wo) T(wi). */
void d_sheen_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                            struct dr_d_bsdf *d);

#endif
