/* The coated BSDF (KHR_materials_clearcoat, struct dr_bsdf's coated):
 * bsdf.c's public functions hand a coated BSDF to these, which compose the
 * base BSDF and the coat's lobe out of those same public functions called on
 * uncoated copies. Private to bsdf.c and bsdf_coat.c: callers use bsdf.h. */
#ifndef DR_BSDF_COAT_H
#define DR_BSDF_COAT_H

#include "bsdf.h"

/* f (and, if pdf is not NULL, the density; wo.z, wi.z > DR_BSDF_COS_EPS). */
dr_vec3 dr_coat_eval_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double *pdf);
bool dr_coat_sample(const struct dr_bsdf *b, dr_vec3 wo, double u_lobe, double u1, double u2,
                    struct dr_bsdf_sample *out);
dr_vec3 dr_coat_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2);
double dr_coat_sky_share(const struct dr_bsdf *b, dr_vec3 wo);
double dr_coat_specular_prob(const struct dr_bsdf *b, dr_vec3 wo);

void d_coat_eval(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, struct dr_d_bsdf *d,
                 dr_vec3 *d_wo, dr_vec3 *d_wi);
void d_coat_pdf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, double d_pdf, bool prob_moves, struct dr_d_bsdf *d,
                dr_vec3 *d_wo, dr_vec3 *d_wi);
void d_coat_specular_prob(const struct dr_bsdf *b, dr_vec3 wo, double d_p, struct dr_d_bsdf *d, dr_vec3 *d_wo);
void d_coat_sample_dir(const struct dr_bsdf *b, dr_vec3 wo, enum dr_bsdf_lobe lobe, double u1, double u2,
                       dr_vec3 d_wi, struct dr_d_bsdf *d, dr_vec3 *d_wo);

/* Derivative sampling (bsdf.h): the coat's lobe as an uncoated BSDF (its
 * roughness lobes are the coat's), and the NDF parts of a coated BSDF. */
struct dr_bsdf dr_coat_lobe(const struct dr_bsdf *b);
void d_coat_eval_rough_ndf(const struct dr_bsdf *b, dr_vec3 wo, dr_vec3 wi, dr_vec3 d_out, unsigned parts,
                           struct dr_d_bsdf *d);

#endif
