/* Small dense linear algebra on 4x4 matrices: what prb's attached replay
 * (estimators/prb_attached.c) does with a vertex's sampling Jacobian (the
 * map from the arriving state's tangents to the next state's, ND = 4). It
 * inverts that Jacobian where it is well conditioned, and falls back to
 * forward mode where it is not (--regularize), so it needs both a
 * condition measure and a solver. */
#ifndef DR_MAT4_H
#define DR_MAT4_H

#include <stdbool.h>

/* sigma_min / sigma_max of A, in [0, 1] (0 for a zero or non-finite A).
 * Computed from the eigenvalues of A^T A, whose rounding moves the smallest
 * by about 1e-16 of the largest: a relative error of about 0.5e-16 /
 * ratio^2 (5e-11 at a ratio of 1e-3, 5e-7 at 1e-5), and below about 1e-8
 * a number below 1e-7 that is not the ratio. Enough to place a
 * --regularize threshold (1e-2 .. 1e-5). */
double dr_mat4_condition(double A[4][4]);

/* dr_mat4_condition(A) >= eps, the same answer for every A, but mostly
 * without the eigenvalues: bounds from the diagonal, the trace and the
 * determinant of A^T A decide most matrices (mat4.c). */
bool dr_mat4_condition_at_least(double A[4][4], double eps);

/* x with A x = y (Gaussian elimination with partial pivoting). For a
 * well-conditioned A (dr_mat4_condition well above rounding); a zero pivot
 * gives that component 0 rather than Inf. */
void dr_mat4_solve(double A[4][4], const double y[4], double x[4]);

#endif
