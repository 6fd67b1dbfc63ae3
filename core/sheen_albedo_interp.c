/* Interpolation of the sheen albedo table (sheen_albedo.h; the table itself
 * is generated into sheen_albedo.c by scripts/sheen_albedo_gen.c).
 *
 * Bicubic Hermite patches: each node carries its value, its slopes along mu
 * and r and the cross slope, all taken from the parabola through the node
 * and its neighbours (one-sided at the grid's ends). The slopes are linear
 * in the table, so they are made once (node_slopes, on first use) and each
 * lookup combines the four corners of its cell: the same interpolant as a
 * tensor product of the two one-dimensional Hermite rules with those
 * slopes, at a fraction of the work (the BSDF asks for E twice per
 * evaluation). */
#include "sheen_albedo.h"

#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stddef.h>

typedef double (*grid_fn)(int);

/* The slope at node k of the parabola through its neighbours, as weights
 * w[0..2] of the nodes first, first+1, first+2. */
static int parabola_slope(grid_fn g, int n, int k, double w[3])
{
    const int first = k == 0 ? 0 : k == n - 1 ? n - 3 : k - 1;
    const double x = g(k), x0 = g(first), x1 = g(first + 1), x2 = g(first + 2);
    w[0] = (2.0 * x - x1 - x2) / ((x0 - x1) * (x0 - x2));
    w[1] = (2.0 * x - x0 - x2) / ((x1 - x0) * (x1 - x2));
    w[2] = (2.0 * x - x0 - x1) / ((x2 - x0) * (x2 - x1));
    return first;
}

/* Per node: dE/dmu, dE/dr and d2E/dmu dr. */
static double slope_mu[DR_SHEEN_NR][DR_SHEEN_NMU], slope_r[DR_SHEEN_NR][DR_SHEEN_NMU],
    slope_mr[DR_SHEEN_NR][DR_SHEEN_NMU];
static pthread_once_t slopes_once = PTHREAD_ONCE_INIT;

static void node_slopes(void)
{
    double w[3];
    for (int j = 0; j < DR_SHEEN_NR; j++)
        for (int i = 0; i < DR_SHEEN_NMU; i++) {
            const int f = parabola_slope(dr_sheen_grid_mu, DR_SHEEN_NMU, i, w);
            slope_mu[j][i] = w[0] * DR_SHEEN_ALBEDO[j][f] + w[1] * DR_SHEEN_ALBEDO[j][f + 1] +
                             w[2] * DR_SHEEN_ALBEDO[j][f + 2];
        }
    for (int j = 0; j < DR_SHEEN_NR; j++) {
        const int f = parabola_slope(dr_sheen_grid_r, DR_SHEEN_NR, j, w);
        for (int i = 0; i < DR_SHEEN_NMU; i++) {
            slope_r[j][i] = w[0] * DR_SHEEN_ALBEDO[f][i] + w[1] * DR_SHEEN_ALBEDO[f + 1][i] +
                            w[2] * DR_SHEEN_ALBEDO[f + 2][i];
            slope_mr[j][i] = w[0] * slope_mu[f][i] + w[1] * slope_mu[f + 1][i] + w[2] * slope_mu[f + 2][i];
        }
    }
}

/* The cubic Hermite basis at t in [0, 1] on an interval of length h: the
 * weights of the two values and the two slopes (b), and of their d/dx (db). */
struct hermite { double b[4], db[4]; };

static struct hermite hermite(double t, double h)
{
    const double t2 = t * t, t3 = t2 * t;
    return (struct hermite){{2 * t3 - 3 * t2 + 1, -2 * t3 + 3 * t2, h * (t3 - 2 * t2 + t), h * (t3 - t2)},
                            {(6 * t2 - 6 * t) / h, (-6 * t2 + 6 * t) / h, 3 * t2 - 4 * t + 1, 3 * t2 - 2 * t}};
}

/* The interval [x_k, x_{k+1}] of a grid x_i = lo + span (i / (n-1))^2 holding x. */
static int interval(double x, double lo, double span, int n)
{
    const int k = (int)floor(sqrt((x - lo) / span) * (n - 1));
    return k < 0 ? 0 : k > n - 2 ? n - 2 : k;
}

/* Row jj's values and mu-slopes combined along mu by basis weights w: the
 * function along mu (a = the values) and its r-slope (s = the r-slopes).
 * Inlined: called out of line, GCC 12 built the weights in a ymm register
 * and called it without the vzeroupper the ABI expects, and the lookup
 * returned with the upper halves dirty; the next libm call (whose wrapper
 * is SSE code) then paid the AVX-SSE transition, measured at 15 % of a
 * sheened render. */
static inline __attribute__((always_inline)) void along_mu(const double w[4], int jj, int i, double *a, double *s)
{
    *a = w[0] * DR_SHEEN_ALBEDO[jj][i] + w[1] * DR_SHEEN_ALBEDO[jj][i + 1] + w[2] * slope_mu[jj][i] +
         w[3] * slope_mu[jj][i + 1];
    *s = w[0] * slope_r[jj][i] + w[1] * slope_r[jj][i + 1] + w[2] * slope_mr[jj][i] + w[3] * slope_mr[jj][i + 1];
}

double dr_sheen_albedo(double mu, double r, double *d_mu, double *d_r)
{
    pthread_once(&slopes_once, node_slopes);
    const double rmin = DR_SHEEN_MIN_ROUGHNESS;
    /* (r = 1, a common value, has the slope from inside; mu = 1 is flat like
     * mu > 1, as the lobe's Lambda is there: bsdf_sheen.c) */
    const bool mu_in = mu >= 0.0 && mu < 1.0, r_in = r >= rmin && r <= 1.0;
    mu = mu_in ? mu : mu > 0.0 ? 1.0 : 0.0;   /* (NaN: 0) */
    r = r_in ? r : r > rmin ? 1.0 : rmin;
    const int i = interval(mu, 0.0, 1.0, DR_SHEEN_NMU), j = interval(r, rmin, 1.0 - rmin, DR_SHEEN_NR);
    const double x0 = dr_sheen_grid_mu(i), hx = dr_sheen_grid_mu(i + 1) - x0;
    const double y0 = dr_sheen_grid_r(j), hy = dr_sheen_grid_r(j + 1) - y0;
    const struct hermite hm = hermite((mu - x0) / hx, hx), hr = hermite((r - y0) / hy, hy);
    double v0, s0, v1, s1;   /* rows j, j+1: values and r-slopes */
    along_mu(hm.b, j, i, &v0, &s0);
    along_mu(hm.b, j + 1, i, &v1, &s1);
    const double e = hr.b[0] * v0 + hr.b[1] * v1 + hr.b[2] * s0 + hr.b[3] * s1;
    /* Where E ~ 0 (small r, mu near 1: E < 1e-8) the cubic can undershoot
     * below 0 by ~1e-9: held at 0 there (flat), so that m E stays >= 0. */
    const bool pos = e > 0.0;
    if (d_mu) {   /* (the rows' mu-slopes: only here, half the lookup's work) */
        double m0, ms0, m1, ms1;
        along_mu(hm.db, j, i, &m0, &ms0);
        along_mu(hm.db, j + 1, i, &m1, &ms1);
        *d_mu = mu_in && pos ? hr.b[0] * m0 + hr.b[1] * m1 + hr.b[2] * ms0 + hr.b[3] * ms1 : 0.0;
    }
    if (d_r)
        *d_r = r_in && pos ? hr.db[0] * v0 + hr.db[1] * v1 + hr.db[2] * s0 + hr.db[3] * s1 : 0.0;
    return pos ? e : 0.0;
}
