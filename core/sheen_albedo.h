/* The sheen lobe's directional albedo E(mu, r) (bsdf_sheen.c): the integral
 * over the hemisphere of D G / (4 mu wi.z) wi.z of the Estevez-Kulla lobe
 * with a white colour, for mu = wo.z and sheen roughness r, tabulated by
 * scripts/sheen_albedo_gen.c (`make sheen-table` writes sheen_albedo.c) and
 * interpolated here.
 *
 * Grid: mu_i = (i / (NMU-1))^2, r_j = floor + (1 - floor) (j / (NR-1))^2
 * (denser near grazing and near the roughness floor, where E varies fast).
 * Node mu_0 = 0 holds E(DR_SHEEN_MU_LO): the fit's Lambda(mu) grows slower
 * than 1/mu, so E diverges as mu -> 0 (E(1e-7, 0.07) ~ 7); every E the BSDF
 * uses below mu_1 is the interpolant's.
 * Interpolation: tensor-product cubic Hermite on the non-uniform grid, the
 * node slopes those of the parabola through each node and its neighbours
 * (one-sided parabolas at the ends): C1 in both variables; the derivatives
 * returned are the interpolant's own. */
#ifndef DR_SHEEN_ALBEDO_H
#define DR_SHEEN_ALBEDO_H

#include "bsdf.h"   /* DR_SHEEN_MIN_ROUGHNESS */

#define DR_SHEEN_NMU 64
#define DR_SHEEN_NR 32
#define DR_SHEEN_MU_LO 1e-4

extern const double DR_SHEEN_ALBEDO[DR_SHEEN_NR][DR_SHEEN_NMU];

static inline double dr_sheen_grid_mu(int i)
{
    double s = (double)i / (DR_SHEEN_NMU - 1);
    return s * s;
}

static inline double dr_sheen_grid_r(int j)
{
    double s = (double)j / (DR_SHEEN_NR - 1);
    return DR_SHEEN_MIN_ROUGHNESS + (1.0 - DR_SHEEN_MIN_ROUGHNESS) * (s * s);
}

/* E(mu, r) with mu clamped to [0, 1] and r to [floor, 1]; *d_mu, *d_r (if not
 * NULL) receive the interpolant's partial derivatives (0 outside the ranges,
 * where the clamps hold it, and at mu = 1; at r = 1 the slope from inside).
 * Never below 0 (the cubic's undershoot where E < 1e-8 is held at 0). */
double dr_sheen_albedo(double mu, double r, double *d_mu, double *d_r);

#endif
