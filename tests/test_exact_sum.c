/* core/exact_sum.h, the shared gradient sums of runs on many threads: the
 * same contributions added in any order, or from several threads at once,
 * give the same bits; the result is the correctly rounded fixed-point sum
 * (checked against an exact integer reference, and against a long double
 * sum within the rounding of the contributions to 2^-88); carries through
 * the low word in both directions; an out-of-range or non-finite
 * contribution, or a sum near the range's end, gives NaN for that entry
 * only. */
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <string.h>

#include "exact_sum.h"
#include "test.h"

__extension__ typedef __int128 i128;

#define N 64          /* entries */
#define ADDS 20000    /* contributions per entry */

static uint64_t rng = 0x9e3779b97f4a7c15ULL;
static double uniform(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) * 0x1p-53;
}

/* a contribution: either sign, magnitudes 1e-20 .. 1e6 */
static double contribution(void)
{
    double v = pow(10.0, -20.0 + 26.0 * uniform()) * (uniform() < 0.5 ? -1.0 : 1.0);
    return v;
}

static double vals[N][ADDS];

struct job {
    struct dr_exact_sum *e;
    int first, step;   /* this thread adds contributions first, first + step, ... of every entry */
};

static void *add_some(void *arg)
{
    const struct job *j = arg;
    for (int k = j->first; k < ADDS; k += j->step)
        for (int i = 0; i < N; i++)
            dr_exact_add(j->e, i, vals[i][k]);
    return NULL;
}

/* The contribution as the accumulator rounds it: nearest multiple of 2^-88. */
static i128 units(double v)
{
    double x = fabs(v) * DR_EXACT_SCALE;
    i128 u = (i128)floor(x);
    if (x - floor(x) >= 0.5)
        u++;
    return v < 0 ? -u : u;
}

int main(void)
{
    for (int i = 0; i < N; i++)
        for (int k = 0; k < ADDS; k++)
            vals[i][k] = contribution();

    /* in order, backwards, and from four threads at once */
    struct dr_exact_sum *fwd = dr_exact_sum_create(N), *bwd = dr_exact_sum_create(N), *par = dr_exact_sum_create(N);
    CHECK(fwd && bwd && par, "create");
    for (int i = 0; i < N; i++)
        for (int k = 0; k < ADDS; k++) {
            dr_exact_add(fwd, i, vals[i][k]);
            dr_exact_add(bwd, i, vals[i][ADDS - 1 - k]);
        }
    pthread_t th[4];
    struct job jobs[4];
    for (int t = 0; t < 4; t++) {
        jobs[t] = (struct job){par, t, 4};
        pthread_create(&th[t], NULL, add_some, &jobs[t]);
    }
    for (int t = 0; t < 4; t++)
        pthread_join(th[t], NULL);
    double a[N], b[N], c[N];
    CHECK(dr_exact_sum_read(fwd, a) == 0 && dr_exact_sum_read(bwd, b) == 0 && dr_exact_sum_read(par, c) == 0,
          "no entry out of range");
    CHECK(memcmp(a, b, sizeof a) == 0, "forwards and backwards differ");
    CHECK(memcmp(a, c, sizeof a) == 0, "one thread and four threads differ");

    /* against the exact integer sum of the rounded contributions, and a long
     * double sum: the difference is the contributions' rounding, at most half
     * a unit each */
    int off_exact = 0, off_ld = 0;
    for (int i = 0; i < N; i++) {
        i128 s = 0;
        long double ld = 0.0L, abs_sum = 0.0L;
        for (int k = 0; k < ADDS; k++) {
            s += units(vals[i][k]);
            ld += vals[i][k];
            abs_sum += fabs(vals[i][k]);
        }
        off_exact += a[i] != (double)s / DR_EXACT_SCALE;
        /* the contributions' rounding, the double result's, and the long
         * double sum's own error bound (n u sum |v|) */
        long double tol = ADDS * 0.5L / DR_EXACT_SCALE + 0x1p-53L * fabsl(ld) + ADDS * 0x1p-64L * abs_sum;
        off_ld += fabsl((long double)a[i] - ld) > tol;
    }
    CHECK(off_exact == 0, "%d of %d sums differ from the integer reference", off_exact, N);
    CHECK(off_ld == 0, "%d of %d sums off the long double sum by more than their rounding", off_ld, N);

    /* contributions of a few hundred to a few thousand units: the rounding
     * of each to the nearest unit shows in the sum */
    struct dr_exact_sum *t = dr_exact_sum_create(1);
    i128 tu = 0;
    for (int k = 0; k < ADDS; k++) {
        double v = 1e-24 * (1.0 + 9.0 * uniform());
        dr_exact_add(t, 0, v);
        tu += units(v);
    }
    double tv;
    dr_exact_sum_read(t, &tv);
    CHECK(tv == (double)tu / DR_EXACT_SCALE, "tiny contributions: %a, not %a", tv, (double)tu / DR_EXACT_SCALE);
    dr_exact_sum_destroy(t);

    /* carries: crossing zero many times (the low word wraps up and down) */
    struct dr_exact_sum *z = dr_exact_sum_create(2);
    double small = 0x1p-70, big = 3.0 + 0x1p-60;
    for (int k = 0; k < 1000; k++) {
        dr_exact_add(z, 0, small);
        dr_exact_add(z, 0, -2 * small);
        dr_exact_add(z, 1, big);
        dr_exact_add(z, 1, -big);
    }
    dr_exact_add(z, 0, -0.0);
    double zz[2];
    dr_exact_sum_read(z, zz);
    CHECK(zz[0] == -1000 * small, "carries below zero: %a, not %a", zz[0], -1000 * small);
    CHECK(zz[1] == 0.0, "big values in and out: %a, not 0", zz[1]);
    dr_exact_sum_destroy(z);

    /* out of range, non-finite, and a sum near the range's end: NaN for
     * that entry, the others untouched */
    struct dr_exact_sum *r = dr_exact_sum_create(4);
    dr_exact_add(r, 0, DR_EXACT_MAX_ADD);
    dr_exact_add(r, 1, NAN);
    dr_exact_add(r, 2, 1.5);
    for (int k = 0; k < 20000; k++)   /* 20000 x 1.6e7 = 3.2e11 > 2^38 */
        dr_exact_add(r, 3, 1.6e7);
    double rr[4];
    CHECK(dr_exact_sum_read(r, rr) == 3, "three entries out of range");
    CHECK(isnan(rr[0]) && isnan(rr[1]) && rr[2] == 1.5 && isnan(rr[3]), "range: %g %g %g %g", rr[0], rr[1], rr[2],
          rr[3]);
    dr_exact_sum_destroy(r);
    dr_exact_sum_destroy(fwd);
    dr_exact_sum_destroy(bwd);
    dr_exact_sum_destroy(par);
    return TEST_END();
}
