/* The guided inverse-CDF lookup (core/cdf.h) picks exactly the entry the
 * plain binary search picks, for every u: at the cdf's own values, at the
 * guide's bucket edges and one ulp either side, and for random u; on
 * distributions with zero-probability runs, one dominant entry, a single
 * entry, and with a guide of fewer or more buckets than entries. Through a
 * scrambled guide too: the lookup checks the guide's bounds against the cdf
 * itself, so a wrong guide costs time, never a different entry (a lookup that
 * trusted its guide fails that case). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "cdf.h"
#include "sampler.h"
#include "test.h"

/* the cdf of weights w[0..n) (cdf[0] = 0, cdf[n] = 1), as the light sampler builds it */
static void make_cdf(const double *w, int64_t n, double *cdf)
{
    double total = 0.0;
    cdf[0] = 0.0;
    for (int64_t i = 0; i < n; i++)
        cdf[i + 1] = (total += w[i]);
    for (int64_t i = 1; i <= n; i++)
        cdf[i] /= total;
}

static int mismatches;

static void check_u(const double *cdf, int64_t n, const uint32_t *at, int64_t k, double u)
{
    int64_t want = dr_cdf_find(cdf, n, u), got = dr_cdf_find_guided(cdf, n, at, k, u);
    if (want != got && mismatches++ < 5)
        fprintf(stderr, "n %lld k %lld u %.17g: guided %lld, plain %lld\n", (long long)n, (long long)k, u,
                (long long)got, (long long)want);
}

/* every interesting u of one distribution under a guide of k buckets */
static void check_all(const double *cdf, int64_t n, int64_t k, struct dr_sampler *smp)
{
    uint32_t *at = malloc(sizeof *at * (size_t)(k + 1));
    dr_cdf_guide_build(cdf, n, at, k);
    for (int64_t i = 0; i <= n; i++) {
        check_u(cdf, n, at, k, cdf[i]);
        check_u(cdf, n, at, k, nextafter(cdf[i], -1.0));
        check_u(cdf, n, at, k, nextafter(cdf[i], 2.0));
    }
    for (int64_t j = 0; j <= k; j++) {
        double e = (double)j / (double)k;
        check_u(cdf, n, at, k, e);
        check_u(cdf, n, at, k, nextafter(e, -1.0));
        check_u(cdf, n, at, k, nextafter(e, 2.0));
    }
    for (int r = 0; r < 20000; r++)
        check_u(cdf, n, at, k, dr_sampler_next(smp));
    check_u(cdf, n, at, k, nextafter(1.0, 0.0));
    check_u(cdf, n, at, k, -0.0);
    check_u(cdf, n, at, k, 1.0);    /* outside [0, 1): the plain search's answer */
    check_u(cdf, n, at, k, NAN);
    free(at);
}

int main(void)
{
    struct dr_sampler smp;
    dr_sampler_init(&smp, 12345, 0, 0);
    const int64_t sizes[] = {1, 2, 3, 7, 64, 1000, 16384};
    for (size_t si = 0; si < sizeof sizes / sizeof *sizes; si++) {
        int64_t n = sizes[si];
        double *w = malloc(sizeof *w * (size_t)n), *cdf = malloc(sizeof *cdf * (size_t)(n + 1));
        for (int shape = 0; shape < 4; shape++) {
            for (int64_t i = 0; i < n; i++) {
                double x = dr_sampler_next(&smp);
                switch (shape) {
                case 0: w[i] = 0.5 + x; break;                      /* even-ish */
                case 1: w[i] = x < 0.5 ? 0.0 : x; break;            /* zero-probability runs */
                case 2: w[i] = i == n / 2 ? 1e9 : x * 1e-6; break;  /* one dominant entry */
                default: w[i] = pow(x, 8.0); break;                 /* heavy skew */
                }
            }
            if (shape == 1)
                w[n - 1] = 1.0;   /* something is drawable */
            make_cdf(w, n, cdf);
            check_all(cdf, n, n, &smp);
            check_all(cdf, n, n / 3 + 1, &smp);   /* fewer buckets than entries */
            check_all(cdf, n, 4 * n + 1, &smp);   /* more */
        }
        free(w);
        free(cdf);
    }
    CHECK(mismatches == 0, "%d guided lookups differ from the plain search", mismatches);

    /* a wrong guide costs time, not a different answer */
    double w[5] = {1, 2, 3, 4, 5}, cdf[6];
    make_cdf(w, 5, cdf);
    uint32_t bad[6] = {4, 0, 4, 0, 4, 0};
    int bad_diff = 0;
    for (int r = 0; r < 1000; r++) {
        double u = dr_sampler_next(&smp);
        bad_diff += dr_cdf_find_guided(cdf, 5, bad, 5, u) != dr_cdf_find(cdf, 5, u);
    }
    CHECK(bad_diff == 0, "%d lookups through a scrambled guide differ", bad_diff);
    /* and the plain search itself: entry i owns [cdf[i], cdf[i+1]) */
    CHECK(dr_cdf_find(cdf, 5, 0.0) == 0 && dr_cdf_find(cdf, 5, cdf[1]) == 1 &&
              dr_cdf_find(cdf, 5, nextafter(cdf[1], 0.0)) == 0 && dr_cdf_find(cdf, 5, nextafter(1.0, 0.0)) == 4,
          "plain search: entry i owns [cdf[i], cdf[i+1])");
    return TEST_END();
}
