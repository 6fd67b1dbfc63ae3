/* The 4x4 condition measure and solver (core/mat4.h) that prb's attached
 * replay uses to decide between inverting a vertex's Jacobian and forward
 * mode (--regularize). The condition ratio is checked against matrices of
 * known singular values, U diag(s) V^T with random rotations U, V, at
 * ratios either side of the thresholds users pass (1e-2 .. 1e-5) and at
 * overall scales from 1e-6 to 1e6: a Jacobi iteration stopped early (a
 * looser convergence test) misplaces the small eigenvalue and fails here.
 * Rank-deficient, zero and non-finite matrices must come out below any
 * threshold (prb then takes forward mode), and the solver must invert what
 * the measure calls well conditioned. */
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "mat4.h"
#include "test.h"

/* a random rotation: Gram-Schmidt on a random matrix's rows */
static void random_orthogonal(double Q[4][4])
{
    for (int i = 0; i < 4; i++) {
        for (;;) {
            for (int k = 0; k < 4; k++)
                Q[i][k] = 2.0 * drand48() - 1.0;
            for (int j = 0; j < i; j++) {
                double d = 0.0;
                for (int k = 0; k < 4; k++)
                    d += Q[i][k] * Q[j][k];
                for (int k = 0; k < 4; k++)
                    Q[i][k] -= d * Q[j][k];
            }
            double n = 0.0;
            for (int k = 0; k < 4; k++)
                n += Q[i][k] * Q[i][k];
            if (n > 1e-4) {
                for (int k = 0; k < 4; k++)
                    Q[i][k] /= sqrt(n);
                break;
            }
        }
    }
}

/* A = scale * U diag(s) V^T */
static void with_singular_values(const double s[4], double scale, double A[4][4])
{
    double U[4][4], V[4][4];
    random_orthogonal(U);
    random_orthogonal(V);
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) {
            double a = 0.0;
            for (int k = 0; k < 4; k++)
                a += U[r][k] * s[k] * V[c][k];
            A[r][c] = scale * a;
        }
}

static void check_known_ratios(void)
{
    /* singular values in any order (the measure must not assume one) */
    const double sets[][4] = {
        {1.0, 0.5, 0.2, 0.1},  {1.0, 1.0, 1.0, 1.0},    {0.3, 1.0, 2e-2, 0.7},  {1.0, 1e-3, 0.5, 0.9},
        {2e-4, 1.0, 1.0, 0.4}, {1.0, 0.99, 1e-5, 0.98}, {1e-3, 1e-3, 1.0, 1e-3}, {1.0, 3e-5, 3e-5, 0.2},
    };
    const double scales[] = {1.0, 1e-6, 1e6, 3.7e-3};
    double worst = 0.0;
    for (size_t k = 0; k < sizeof sets / sizeof sets[0]; k++)
        for (size_t m = 0; m < sizeof scales / sizeof scales[0]; m++)
            for (int rep = 0; rep < 20; rep++) {
                double A[4][4], lo = INFINITY, hi = 0.0;
                for (int i = 0; i < 4; i++)
                    lo = fmin(lo, sets[k][i]), hi = fmax(hi, sets[k][i]);
                with_singular_values(sets[k], scales[m], A);
                /* rounding in A^T A moves its smallest eigenvalue by about
                 * 1e-16 of its largest: a relative error of about
                 * 0.5e-16 / ratio^2 in the ratio (5e-11 at 1e-3) */
                double want = lo / hi, got = dr_mat4_condition(A), rel = fabs(got - want) / want;
                double tol = 4e-16 / (want * want) + 1e-12;
                worst = fmax(worst, rel / tol);
                CHECK(rel <= tol, "set %zu scale %g: ratio %.17g, want %.17g (relative error %.3g, tolerance %.3g)", k,
                      scales[m], got, want, rel, tol);
            }
    fprintf(stderr, "known ratios 1 .. 1e-5: worst error %.3g of its tolerance\n", worst);
}

static void check_singular(void)
{
    const double rank3[4] = {1.0, 0.6, 0.3, 0.0}, rank1[4] = {0.0, 2.0, 0.0, 0.0};
    for (int rep = 0; rep < 50; rep++) {
        double A[4][4];
        with_singular_values(rep & 1 ? rank3 : rank1, rep < 25 ? 1.0 : 1e4, A);
        double r = dr_mat4_condition(A);
        CHECK(r >= 0.0 && r < 1e-7, "rank-deficient matrix %d: ratio %.3g, want below 1e-7", rep, r);
    }
    double Z[4][4] = {{0}};
    CHECK(dr_mat4_condition(Z) == 0.0, "zero matrix: %g", dr_mat4_condition(Z));
    double N[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
    CHECK(dr_mat4_condition(N) == 1.0, "identity: %.17g", dr_mat4_condition(N));
    N[2][1] = NAN;
    CHECK(dr_mat4_condition(N) == 0.0, "NaN entry: %g", dr_mat4_condition(N));
    N[2][1] = INFINITY;
    CHECK(dr_mat4_condition(N) == 0.0, "Inf entry: %g", dr_mat4_condition(N));
}

/* dr_mat4_condition_at_least gives the answer dr_mat4_condition(A) >= eps
 * gives, for ratios on either side of each threshold and close to it, for
 * matrices with zero rows or columns (a diffuse bounce's Jacobian) and
 * for singular, zero and non-finite ones. */
static void check_decisions(void)
{
    const double eps[] = {1e-2, 1e-3, 1e-4, 1e-5};
    const double near[] = {1e-3, 0.3, 0.9, 0.999, 0.99999, 1.00001, 1.001, 1.1, 3.0, 1e3};
    int differ = 0, checked = 0;
    for (size_t e = 0; e < sizeof eps / sizeof eps[0]; e++)
        for (size_t k = 0; k < sizeof near / sizeof near[0]; k++)
            for (int rep = 0; rep < 40; rep++) {
                double r = fmin(1.0, eps[e] * near[k]), s[4] = {1.0, 0.2 + 0.8 * drand48(), r, 0.0}, A[4][4];
                s[3] = r + (1.0 - r) * drand48() * (rep % 2);   /* (every other: two small ones) */
                with_singular_values(s, rep % 3 == 0 ? 1e-5 : rep % 3 == 1 ? 1e3 : 1.0, A);
                if (rep % 5 == 0)   /* rows of zeros: the map forgets what it came from */
                    for (int c = 0; c < 4; c++)
                        A[2][c] = A[3][c] = 0.0;
                for (size_t f = 0; f < sizeof eps / sizeof eps[0]; f++) {
                    bool want = dr_mat4_condition(A) >= eps[f], got = dr_mat4_condition_at_least(A, eps[f]);
                    differ += want != got;
                    checked++;
                }
            }
    CHECK(differ == 0, "%d of %d threshold decisions differ from the eigenvalues'", differ, checked);
    double Z[4][4] = {{0}}, N[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, NAN, 0}, {0, 0, 0, 1}};
    CHECK(!dr_mat4_condition_at_least(Z, 1e-3) && dr_mat4_condition_at_least(Z, 0.0),
          "zero matrix: below every positive threshold, not below 0");
    CHECK(!dr_mat4_condition_at_least(N, 1e-3), "a NaN entry passes the threshold");
    fprintf(stderr, "threshold decisions: %d checked against the eigenvalues\n", checked);
}

/* A x = y recovered for a known x, where the ratio is at least 1e-4 */
static void check_solve(void)
{
    const double s[4] = {1.0, 0.3, 1e-4, 0.05};
    double worst = 0.0;
    for (int rep = 0; rep < 200; rep++) {
        double A[4][4], x0[4], y[4], x[4];
        with_singular_values(s, rep % 2 ? 1e3 : 1.0, A);
        if (rep % 3 == 0)   /* a zero leading entry: the pivot must come from below */
            for (int c = 0; c < 4; c++) {
                double t = A[0][c];
                A[0][c] = A[3][c], A[3][c] = t;
            }
        for (int i = 0; i < 4; i++)
            x0[i] = 2.0 * drand48() - 1.0;
        for (int r = 0; r < 4; r++) {
            y[r] = 0.0;
            for (int c = 0; c < 4; c++)
                y[r] += A[r][c] * x0[c];
        }
        dr_mat4_solve(A, y, x);
        double err = 0.0;
        for (int i = 0; i < 4; i++)
            err = fmax(err, fabs(x[i] - x0[i]));
        worst = fmax(worst, err);
        CHECK(err <= 1e-10, "solve %d: |x - x0| = %.3g", rep, err);
    }
    double P[4][4] = {{0, 2, 0, 0}, {0, 0, 0, 4}, {1, 0, 0, 0}, {0, 0, 8, 0}}, y[4] = {2, 4, 1, 8}, x[4];
    dr_mat4_solve(P, y, x);
    for (int i = 0; i < 4; i++)
        CHECK(x[i] == 1.0, "permuted diagonal: x[%d] = %.17g", i, x[i]);
    fprintf(stderr, "solve at ratio 1e-4: worst error %.3g\n", worst);
}

int main(void)
{
    srand48(20261206);
    check_known_ratios();
    check_singular();
    check_decisions();
    check_solve();
    return TEST_END();
}
