/* Inverting a discrete distribution's CDF: the index a uniform number picks.
 *
 * cdf[0..n] is non-decreasing with cdf[0] = 0; entry i owns [cdf[i],
 * cdf[i+1]). dr_cdf_find is the plain binary search. A guide table (Chen and
 * Asau's "index table") makes the same inversion O(1) on average: bucket j
 * of k equal buckets of [0, 1) stores the entry the bucket's left end picks,
 * so a lookup only searches between two neighbouring buckets' entries. The
 * guided lookup returns exactly what dr_cdf_find returns for every u (the
 * light sampler's decisions, and with them every image, do not change); it
 * only stops being a log2(n)-deep chain of dependent loads, which on a scene
 * with 16k emissive triangles was three quarters of the light sample. */
#ifndef DR_CDF_H
#define DR_CDF_H

#include <stdint.h>

/* The largest i in [0, n) with cdf[i] <= u (0 if there is none). */
int64_t dr_cdf_find(const double *cdf, int64_t n, double u);

/* Fills at[0..k] (k >= 1 buckets): at[j] = dr_cdf_find(cdf, n, j / k).
 * n must be below 2^32. */
void dr_cdf_guide_build(const double *cdf, int64_t n, uint32_t *at, int64_t k);

/* dr_cdf_find(cdf, n, u) through the guide at[0..k] of the same cdf. */
int64_t dr_cdf_find_guided(const double *cdf, int64_t n, const uint32_t *at, int64_t k, double u);

/* The guide's bucket j of u: dr_cdf_find_guided reads at[j], at[j + 1],
 * then cdf[at[j]]; -1 where it searches without the guide. A caller with
 * several u can ask the cache for all their at[j], then all their
 * cdf[at[j]], before looking any up, so that a big table's misses overlap. */
static inline int64_t dr_cdf_guide_bucket(int64_t k, double u)
{
    double x = u * (double)k;
    return x >= 0.0 && x < (double)k ? (int64_t)x : -1;
}

#endif
