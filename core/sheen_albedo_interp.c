/* Interpolation of the sheen albedo table (sheen_albedo.h; the table itself
 * is generated into sheen_albedo.c by scripts/sheen_albedo_gen.c). */
#include "sheen_albedo.h"

#include <math.h>
#include <stdbool.h>
#include <stddef.h>

/* The grid's nodes as a function of the index (one of the two axes). */
typedef double (*grid_fn)(int);

/* d/dx at x of the Lagrange parabola through nodes j0 < j0+1 < j0+2, as
 * weights of their values, added (times s) to w[j - base]. */
static void add_parabola_slope(grid_fn g, int j0, double x, double s, int base, double w[4])
{
    const double x0 = g(j0), x1 = g(j0 + 1), x2 = g(j0 + 2);
    w[j0 - base] += s * (2.0 * x - x1 - x2) / ((x0 - x1) * (x0 - x2));
    w[j0 + 1 - base] += s * (2.0 * x - x0 - x2) / ((x1 - x0) * (x1 - x2));
    w[j0 + 2 - base] += s * (2.0 * x - x0 - x1) / ((x2 - x0) * (x2 - x1));
}

/* Cubic Hermite on [x_k, x_{k+1}] with the node slopes of the parabola
 * through each node and its neighbours (second-order accurate on a
 * non-uniform grid; one-sided parabolas at the grid's ends): the weights of
 * the nodes base .. base+3 (base = k - 1; nodes off the grid get 0) in the
 * value (w) and in d/dx (dw). */
static void hermite_weights(grid_fn g, int n, int k, double x, double w[4], double dw[4])
{
    const int base = k - 1;
    const double xk = g(k), h = g(k + 1) - xk, t = (x - xk) / h;
    const double t2 = t * t, t3 = t2 * t;
    const double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = -2 * t3 + 3 * t2, h11 = t3 - t2;
    const double d00 = (6 * t2 - 6 * t) / h, d10 = 3 * t2 - 4 * t + 1, d01 = (-6 * t2 + 6 * t) / h,
                 d11 = 3 * t2 - 2 * t;
    double mk[4] = {0}, mk1[4] = {0};
    add_parabola_slope(g, k == 0 ? 0 : k - 1, xk, 1.0, base, mk);
    add_parabola_slope(g, k + 1 == n - 1 ? n - 3 : k, g(k + 1), 1.0, base, mk1);
    for (int i = 0; i < 4; i++) {
        w[i] = h * (h10 * mk[i] + h11 * mk1[i]);
        dw[i] = d10 * mk[i] + d11 * mk1[i];
    }
    w[1] += h00, w[2] += h01;
    dw[1] += d00, dw[2] += d01;
}

/* The interval [x_k, x_{k+1}] of a grid x_i = lo + span (i / (n-1))^2 holding x. */
static int interval(double x, double lo, double span, int n)
{
    const int k = (int)floor(sqrt((x - lo) / span) * (n - 1));
    return k < 0 ? 0 : k > n - 2 ? n - 2 : k;
}

double dr_sheen_albedo(double mu, double r, double *d_mu, double *d_r)
{
    const double rmin = DR_SHEEN_MIN_ROUGHNESS;
    /* (r = 1, a common value, has the slope from inside; mu = 1 is flat like
     * mu > 1, as the lobe's Lambda is there: bsdf_sheen.c) */
    const bool mu_in = mu >= 0.0 && mu < 1.0, r_in = r >= rmin && r <= 1.0;
    mu = mu_in ? mu : mu > 0.0 ? 1.0 : 0.0;   /* (NaN: 0) */
    r = r_in ? r : r > rmin ? 1.0 : rmin;
    const int i = interval(mu, 0.0, 1.0, DR_SHEEN_NMU), j = interval(r, rmin, 1.0 - rmin, DR_SHEEN_NR);
    double wm[4], dwm[4], wr[4], dwr[4];
    hermite_weights(dr_sheen_grid_mu, DR_SHEEN_NMU, i, mu, wm, dwm);
    hermite_weights(dr_sheen_grid_r, DR_SHEEN_NR, j, r, wr, dwr);
    double e = 0.0, em = 0.0, er = 0.0;
    for (int b = 0; b < 4; b++) {
        const int jj = j - 1 + b;
        if (jj < 0 || jj >= DR_SHEEN_NR || (wr[b] == 0.0 && dwr[b] == 0.0))
            continue;
        double row = 0.0, row_m = 0.0;   /* the row's interpolant in mu and its slope */
        for (int a = 0; a < 4; a++) {
            const int ii = i - 1 + a;
            if (ii < 0 || ii >= DR_SHEEN_NMU)
                continue;
            row += wm[a] * DR_SHEEN_ALBEDO[jj][ii];
            row_m += dwm[a] * DR_SHEEN_ALBEDO[jj][ii];
        }
        e += wr[b] * row;
        em += wr[b] * row_m;
        er += dwr[b] * row;
    }
    /* Where E ~ 0 (small r, mu near 1: E < 1e-8) the cubic can undershoot
     * below 0 by ~1e-9: held at 0 there (flat), so that m E stays >= 0. */
    const bool pos = e > 0.0;
    if (d_mu)
        *d_mu = mu_in && pos ? em : 0.0;
    if (d_r)
        *d_r = r_in && pos ? er : 0.0;
    return pos ? e : 0.0;
}
