/* 4x4 condition measure and solver (mat4.h). */
#include "mat4.h"

#include <math.h>
#include <stdbool.h>
#include <stddef.h>

/* Cyclic Jacobi rotations on S = A^T A until the off-diagonal part is below
 * 1e-16 of the diagonal's norm: converged to rounding, the eigenvalues then
 * move by at most about 1e-16 of the largest. (An absolute test, off <=
 * 1e-300, as before 2026-12-06, is never met once the rotations only stir
 * rounding noise, so nearly every call ran all 30 sweeps: 13 % of a prb
 * attached run.) test_mat4 checks the ratio against matrices of known
 * singular values, near the --regularize thresholds. */
double dr_mat4_condition(double A[4][4])
{
    double S[4][4];
    for (int i = 0; i < 4; i++)
        for (int k = 0; k < 4; k++) {
            double s = 0.0;
            for (int r = 0; r < 4; r++)
                s += A[r][i] * A[r][k];
            S[i][k] = s;
        }
    for (int sweep = 0; sweep < 30; sweep++) {
        double off = 0.0, diag = 0.0;
        for (int p = 0; p < 4; p++) {
            diag += S[p][p] * S[p][p];
            for (int q = p + 1; q < 4; q++)
                off += S[p][q] * S[p][q];
        }
        if (!isfinite(off + diag))
            return 0.0;
        if (off <= 1e-32 * diag || off <= 1e-300)
            break;
        for (int p = 0; p < 4; p++)
            for (int q = p + 1; q < 4; q++) {
                if (S[p][q] == 0.0)
                    continue;
                double th = 0.5 * (S[q][q] - S[p][p]) / S[p][q];
                double t = (th >= 0.0 ? 1.0 : -1.0) / (fabs(th) + sqrt(th * th + 1.0));
                double cs = 1.0 / sqrt(t * t + 1.0), sn = t * cs;
                for (int k = 0; k < 4; k++) {   /* S <- S J */
                    double a = S[k][p], b = S[k][q];
                    S[k][p] = cs * a - sn * b;
                    S[k][q] = sn * a + cs * b;
                }
                for (int k = 0; k < 4; k++) {   /* S <- J^T S */
                    double a = S[p][k], b = S[q][k];
                    S[p][k] = cs * a - sn * b;
                    S[q][k] = sn * a + cs * b;
                }
            }
    }
    double lo = INFINITY, hi = 0.0;
    for (int i = 0; i < 4; i++) {
        lo = fmin(lo, fabs(S[i][i]));
        hi = fmax(hi, fabs(S[i][i]));
    }
    return hi > 0.0 ? sqrt(lo / hi) : 0.0;
}

/* Forward elimination with partial pivoting on [A | y] (M), in place: M's
 * left 4x4 becomes upper triangular. A zero pivot leaves its column as it
 * is. Returns the sign of the row permutation. One elimination for both
 * the determinant and the solver. */
static double eliminate(double M[4][5])
{
    double sign = 1.0;
    for (int col = 0; col < 4; col++) {
        int piv = col;
        for (int r = col + 1; r < 4; r++)
            if (fabs(M[r][col]) > fabs(M[piv][col]))
                piv = r;
        if (piv != col)
            sign = -sign;
        for (int k = 0; k <= 4; k++) {
            double t = M[col][k];
            M[col][k] = M[piv][k];
            M[piv][k] = t;
        }
        for (int r = col + 1; r < 4; r++) {
            double f = M[col][col] != 0.0 ? M[r][col] / M[col][col] : 0.0;
            for (int k = col; k <= 4; k++)
                M[r][k] -= f * M[col][k];
        }
    }
    return sign;
}

/* [A | y] as eliminate takes it */
static void augmented(double A[4][4], const double y[4], double M[4][5])
{
    for (int i = 0; i < 4; i++) {
        for (int k = 0; k < 4; k++)
            M[i][k] = A[i][k];
        M[i][4] = y ? y[i] : 0.0;
    }
}

static double det4(double A[4][4])
{
    double M[4][5];
    augmented(A, NULL, M);
    double det = eliminate(M);
    for (int i = 0; i < 4; i++)
        det *= M[i][i];
    return det;
}

/* With S = A^T A, eigenvalues l_1 >= .. >= l_4 >= 0 and trace T:
 *  - l_4 <= min_i S_ii and l_1 >= max_i S_ii, so the ratio is at most
 *    sqrt(min S_ii / max S_ii): a vertex whose direction forgets where it
 *    came from has (near-)zero rows, and is decided here;
 *  - l_1 <= T and l_4 = det S / (l_1 l_2 l_3) >= det S / T^3, so the ratio
 *    is at least sqrt(det S) / T^2 = |det A| / T^2: a well-conditioned
 *    vertex is decided here.
 * Only what falls between takes the rotations. The margins (1e-6 of eps)
 * are far above the rotations' rounding (about 5e-11 of the ratio at 1e-3,
 * mat4.h) and the bounds', so every decision is the one
 * dr_mat4_condition(A) >= eps makes (test_mat4 checks that). */
bool dr_mat4_condition_at_least(double A[4][4], double eps)
{
    if (!(eps > 0.0))
        return true;   /* (the ratio is never below 0) */
    double lo = INFINITY, hi = 0.0, T = 0.0;
    for (int i = 0; i < 4; i++) {
        double d = A[0][i] * A[0][i] + A[1][i] * A[1][i] + A[2][i] * A[2][i] + A[3][i] * A[3][i];
        lo = fmin(lo, d);
        hi = fmax(hi, d);
        T += d;
    }
    if (isfinite(T) && T > 0.0) {
        if (lo < eps * eps * (1.0 - 1e-6) * hi)
            return false;
        if (fabs(det4(A)) >= eps * (1.0 + 1e-6) * T * T)
            return true;
    }
    return dr_mat4_condition(A) >= eps;
}

void dr_mat4_solve(double A[4][4], const double y[4], double x[4])
{
    double M[4][5];
    augmented(A, y, M);
    eliminate(M);
    for (int i = 3; i >= 0; i--) {
        double s = M[i][4];
        for (int k = i + 1; k < 4; k++)
            s -= M[i][k] * x[k];
        x[i] = M[i][i] != 0.0 ? s / M[i][i] : 0.0;
    }
}
