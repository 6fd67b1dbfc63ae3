/* Inverse CDF lookups (cdf.h). */
#include "cdf.h"

/* The largest i in [lo, hi) with cdf[i] <= u, given that it lies there. */
static int64_t search(const double *cdf, int64_t lo, int64_t hi, double u)
{
    while (hi - lo > 1) {
        int64_t mid = lo + (hi - lo) / 2;
        if (cdf[mid] <= u)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

int64_t dr_cdf_find(const double *cdf, int64_t n, double u)
{
    return search(cdf, 0, n, u);
}

void dr_cdf_guide_build(const double *cdf, int64_t n, uint32_t *at, int64_t k)
{
    /* one sweep, O(n + k): the bucket edges rise, and so do their entries */
    int64_t i = 0;
    for (int64_t j = 0; j <= k; j++) {
        double t = (double)j / (double)k;
        while (i + 1 < n && cdf[i + 1] <= t)
            i++;
        at[j] = (uint32_t)i;
    }
}

int64_t dr_cdf_find_guided(const double *cdf, int64_t n, const uint32_t *at, int64_t k, double u)
{
    /* u outside [0, 1) or NaN: the plain search answers as it always did */
    int64_t j = dr_cdf_guide_bucket(k, u);
    if (j < 0)
        return dr_cdf_find(cdf, n, u);
    /* The answer lies in [at[j], at[j+1]] when j / k <= u < (j+1) / k. The
     * product u * k may round across a bucket edge, so both ends are checked
     * against the search's own condition; when a check fails the search
     * widens to everything on that side, and the answer is still the one the
     * plain search gives (it is unique: cdf is non-decreasing). The checks
     * also make a wrong guide cost time, never a different answer. */
    int64_t lo = at[j], hi = (int64_t)at[j + 1] + 1;
    if (lo > 0 && !(cdf[lo] <= u))
        lo = 0;
    if (hi >= n || !(cdf[hi] > u))
        hi = n;
    return search(cdf, lo, hi, u);
}
