/* The stratified sampler (core/stratified.h through sampler.h): every draw
 * stratified over the pixel's samples for any spp, each sample uniform over
 * the random seeds (an unbiased estimate), a pure function of
 * (seed, pixel, sample, dimension, spp), dimensions decorrelated, and a
 * faster-converging estimate of smooth integrals than independent numbers. */
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "sampler.h"
#include "test.h"

enum { DIMS = 8 };   /* 1D, 2D (x, y), 1D, 2D (x, y), 1D, 1D: a path vertex's layout */

/* The DIMS numbers of sample i of n of a pixel, drawn as the path walker does. */
static void draw(uint64_t seed, uint64_t pixel, int i, int n, double u[DIMS])
{
    struct dr_sampler s;
    dr_sampler_init_kind(&s, DR_SAMPLER_STRATIFIED, seed, pixel, (uint64_t)i, n);
    u[0] = dr_sampler_next(&s);
    dr_sampler_next2(&s, &u[1], &u[2]);
    u[3] = dr_sampler_next(&s);
    dr_sampler_next2(&s, &u[4], &u[5]);
    u[6] = dr_sampler_next(&s);
    u[7] = dr_sampler_next(&s);
}

static bool is_1d(int d) { return d == 0 || d == 3 || d == 6 || d == 7; }

/* Over n samples: every 1D draw has one sample per stratum [k/n, (k+1)/n);
 * every 2D draw has at most one sample per cell of its m x n' grid (exactly
 * one when n = m n'), and its x and y are one per 1/(m n') strip when the
 * grid is full (the Latin hypercube of multi-jittering). */
static void check_strata(int n)
{
    uint32_t gm, gn;
    dr_strat_grid((uint32_t)n, &gm, &gn);
    CHECK(gm * gn >= (uint32_t)n && (gm - 1) * gn < (uint32_t)n, "grid %ux%u for %d samples", gm, gn, n);
    const bool full = gm * gn == (uint32_t)n;
    double (*u)[DIMS] = malloc(sizeof(double[DIMS]) * (size_t)n);
    int *count = malloc(sizeof(int) * (size_t)n * 2 + sizeof(int) * gm * gn);
    for (uint64_t pixel = 0; pixel < 12; pixel++) {
        for (int i = 0; i < n; i++) {
            draw(5, pixel, i, n, u[i]);
            for (int d = 0; d < DIMS; d++)
                CHECK(u[i][d] >= 0.0 && u[i][d] < 1.0, "n %d sample %d dim %d: %g outside [0,1)", n, i, d, u[i][d]);
        }
        for (int d = 0; d < DIMS; d++) {
            int bad = 0;
            if (is_1d(d)) {
                memset(count, 0, sizeof(int) * (size_t)n);
                for (int i = 0; i < n; i++)
                    count[(int)(u[i][d] * n)]++;
                for (int k = 0; k < n; k++)
                    bad += count[k] != 1;
                CHECK(bad == 0, "n %d dim %d: 1D strata not one sample each (%d off)", n, d, bad);
                continue;
            }
            if (d != 1 && d != 4)
                continue;
            memset(count, 0, sizeof(int) * gm * gn);
            for (int i = 0; i < n; i++)
                count[(int)(u[i][d + 1] * gn) * (int)gm + (int)(u[i][d] * gm)]++;
            for (uint32_t k = 0; k < gm * gn; k++)
                bad += count[k] > 1 || (full && count[k] != 1);
            CHECK(bad == 0, "n %d dims %d,%d: %ux%u cells not one sample each (%d off)", n, d, d + 1, gm, gn, bad);
            if (!full)
                continue;
            for (int axis = 0; axis < 2; axis++) {
                memset(count, 0, sizeof(int) * (size_t)n);
                for (int i = 0; i < n; i++)
                    count[(int)(u[i][d + axis] * n)]++;
                bad = 0;
                for (int k = 0; k < n; k++)
                    bad += count[k] != 1;
                CHECK(bad == 0, "n %d dim %d: not a Latin hypercube (%d strips off)", n, d + axis, bad);
            }
        }
    }
    free(count);
    free(u);
}

/* dr_strat_permute is a bijection of [0, l) for any l, and its final
 * rotation (i + p) mod l is exact also where the 32-bit sum wraps. */
static void test_permute(void)
{
    const uint32_t ls[] = {1, 2, 3, 7, 16, 100, 1000};
    static unsigned char seen[1000];
    for (int k = 0; k < 7; k++)
        for (uint32_t p = 0; p < 40; p++) {
            uint32_t l = ls[k], seed = (uint32_t)dr_hash64(p), bad = 0;
            memset(seen, 0, l);
            for (uint32_t i = 0; i < l; i++) {
                uint32_t j = dr_strat_permute(i, l, seed);
                bad += j >= l || seen[j]++;
            }
            CHECK(bad == 0, "permute over %u (seed %u): not a bijection (%u off)", l, p, bad);
        }
    /* the final rotation against 64-bit arithmetic, l up to 2^32 - 1 (sums that wrap) */
    int wrong = 0;
    for (uint64_t k = 0; k < 20000; k++) {
        uint64_t h = dr_hash64(k);
        uint32_t l = (uint32_t)(h >> 32) | (k % 2 ? 0x80000000u : 0u), p = (uint32_t)h;
        if (l == 0)
            continue;
        uint32_t i = (uint32_t)(dr_hash64(h) % l);
        wrong += dr_strat_rotate(i, p, l) != (uint32_t)(((uint64_t)i + p) % l);
    }
    CHECK(wrong == 0, "(i + p) mod l wrong in %d of 20000 cases", wrong);
}

/* The 2D grid is exact (m x n = spp, m <= 2n) for squares, powers of two
 * and other near-square products, and padded only where none exists. */
static void test_grid(void)
{
    const uint32_t c[] = {1, 2, 8, 12, 32, 48, 128, 200, 7, 14, 1021};
    const uint32_t want_m[] = {1, 2, 4, 4, 8, 8, 16, 20, 3, 4, 32}, want_n[] = {1, 1, 2, 3, 4, 6, 8, 10, 3, 4, 32};
    for (int k = 0; k < 11; k++) {
        uint32_t m, n;
        dr_strat_grid(c[k], &m, &n);
        CHECK(m == want_m[k] && n == want_n[k], "grid for %u: %ux%u, want %ux%u", c[k], m, n, want_m[k], want_n[k]);
    }
}

/* Unbiased: one fixed sample index, over many seeds (pixels), is uniform in
 * every dimension (chi-square over 16 bins, 4x4 cells for the 2D draws), for
 * a square, a padded and a prime sample count. */
static void test_uniform(void)
{
    const int ns[] = {16, 12, 7};
    const int P = 16000;
    for (int t = 0; t < 3; t++) {
        int n = ns[t], idx = n / 2 + 1;
        int h1[DIMS][16] = {{0}}, h2[2][16] = {{0}};
        for (int p = 0; p < P; p++) {
            double u[DIMS];
            draw(9, (uint64_t)p, idx, n, u);
            for (int d = 0; d < DIMS; d++)
                h1[d][(int)(u[d] * 16)]++;
            h2[0][(int)(u[1] * 4) * 4 + (int)(u[2] * 4)]++;
            h2[1][(int)(u[4] * 4) * 4 + (int)(u[5] * 4)]++;
        }
        /* chi-square with 15 degrees of freedom: P(> 37.7) = 0.001 */
        const double e = P / 16.0;
        for (int d = 0; d < DIMS + 2; d++) {
            const int *h = d < DIMS ? h1[d] : h2[d - DIMS];
            double chi = 0.0;
            for (int k = 0; k < 16; k++)
                chi += (h[k] - e) * (h[k] - e) / e;
            CHECK(chi < 37.7, "n %d sample %d %s %d: chi-square %.1f (not uniform over seeds)", n, idx,
                  d < DIMS ? "dim" : "2D draw", d < DIMS ? d : d - DIMS, chi);
        }
    }
}

/* Pure function: the same inputs give the same numbers in any order and after
 * jumping to a dimension; another seed, pixel or spp gives other numbers. */
static void test_pure(void)
{
    double a[DIMS], b[DIMS], c[DIMS], d[DIMS], e[DIMS];
    draw(11, 99, 13, 48, a);
    draw(11, 98, 13, 48, c);   /* another pixel drawn in between */
    draw(11, 99, 13, 48, b);
    CHECK(memcmp(a, b, sizeof a) == 0, "the same (seed, pixel, sample, spp) gives the same numbers");
    struct dr_sampler s;
    dr_sampler_init_kind(&s, DR_SAMPLER_STRATIFIED, 11, 99, 13, 48);
    s.dim = 4;   /* jump ahead to the second 2D draw (dimensions 5, 6), as the path walker does */
    double x, y;
    dr_sampler_next2(&s, &x, &y);
    CHECK(x == a[4] && y == a[5], "jumping to dimension 4 gives the same pair");
    draw(12, 99, 13, 48, d);
    draw(11, 99, 13, 50, e);
    int same_c = 0, same_d = 0, same_e = 0;
    for (int k = 0; k < DIMS; k++) {
        same_c += a[k] == c[k];
        same_d += a[k] == d[k];
        same_e += a[k] == e[k];
    }
    CHECK(same_c == 0 && same_d == 0 && same_e == 0, "another pixel/seed/spp gives other numbers (%d, %d, %d equal)",
          same_c, same_d, same_e);
    CHECK(dr_sampler_kind_parse("stratified") == DR_SAMPLER_STRATIFIED &&
              strcmp(dr_sampler_kind_name(DR_SAMPLER_STRATIFIED), "stratified") == 0,
          "the name 'stratified'");
}

/* Decorrelated dimensions: within a pixel, the correlation over its samples
 * between two dimensions averages to 0 over pixels, and its spread is that of
 * independent permutations (1/sqrt(n-1)), far from 1 (the same permutation). */
static void test_decorrelated(void)
{
    enum { N = 64, PIX = 400 };
    const int pairs[][2] = {{0, 3}, {0, 6}, {6, 7}, {1, 4}, {2, 5}, {1, 2}, {0, 1}};
    const int np = (int)(sizeof pairs / sizeof pairs[0]);
    for (int q = 0; q < np; q++) {
        double sum = 0.0, sq = 0.0;
        for (int p = 0; p < PIX; p++) {
            double u[N][DIMS], ma = 0, mb = 0, cab = 0, va = 0, vb = 0;
            for (int i = 0; i < N; i++) {
                draw(21, (uint64_t)p, i, N, u[i]);
                ma += u[i][pairs[q][0]] / N;
                mb += u[i][pairs[q][1]] / N;
            }
            for (int i = 0; i < N; i++) {
                double da = u[i][pairs[q][0]] - ma, db = u[i][pairs[q][1]] - mb;
                cab += da * db;
                va += da * da;
                vb += db * db;
            }
            double r = cab / sqrt(va * vb);
            sum += r;
            sq += r * r;
        }
        double mean = sum / PIX, rms = sqrt(sq / PIX), expect = 1.0 / sqrt(N - 1.0);
        /* mean's standard error: expect / sqrt(PIX) = 0.0063 */
        CHECK(fabs(mean) < 0.03, "dims %d,%d: mean correlation %.3f", pairs[q][0], pairs[q][1], mean);
        CHECK(rms < 1.5 * expect, "dims %d,%d: correlation spread %.3f (independent permutations: %.3f)",
              pairs[q][0], pairs[q][1], rms, expect);
    }
}

/* RMSE over independent randomisations (pixels) of the n-sample estimate of
 * a smooth 2D integral (one 2D draw) and of a smooth 1D integral. */
static double rmse(enum dr_sampler_kind kind, int n, bool two_d, double *bias)
{
    const double exact2 = (1.0 - cos(3.0)) / 3.0 * (exp(1.0) - 1.0);   /* of sin(3x) e^y */
    const double exact1 = 1.0 - cos(1.0);                              /* of sin(x) */
    double sq = 0.0, sum_e = 0.0;
    const int reps = 400;
    for (int r = 0; r < reps; r++) {
        double sum = 0.0;
        for (int i = 0; i < n; i++) {
            struct dr_sampler s;
            dr_sampler_init_kind(&s, kind, 5, (uint64_t)r, (uint64_t)i, n);
            double x, y;
            if (two_d) {
                dr_sampler_next2(&s, &x, &y);
                sum += sin(3.0 * x) * exp(y);
            } else {
                s.dim = 3;   /* a later dimension, as at a path vertex */
                sum += sin(dr_sampler_next(&s));
            }
        }
        double e = sum / n - (two_d ? exact2 : exact1);
        sq += e * e;
        sum_e += e;
    }
    if (bias)
        *bias = sum_e / reps / (sqrt(sq / reps) / sqrt((double)reps));   /* in standard errors */
    return sqrt(sq / reps);
}

/* Jittered sampling of a smooth integrand converges as N^-1 in 2D and
 * N^-1.5 in 1D, against independent numbers' N^-0.5; the estimate has no
 * bias beyond noise, also for sample counts that are not squares. */
static void test_convergence(void)
{
    const int ns[] = {16, 64, 256};
    double li[3], l2[3], l1[3];
    for (int k = 0; k < 3; k++) {
        li[k] = log(rmse(DR_SAMPLER_INDEPENDENT, ns[k], true, NULL));
        l2[k] = log(rmse(DR_SAMPLER_STRATIFIED, ns[k], true, NULL));
        l1[k] = log(rmse(DR_SAMPLER_STRATIFIED, ns[k], false, NULL));
    }
    double si = (li[2] - li[0]) / log(16.0), s2 = (l2[2] - l2[0]) / log(16.0), s1 = (l1[2] - l1[0]) / log(16.0);
    fprintf(stderr, "error-vs-N slope: independent %.2f, stratified 2D %.2f, stratified 1D %.2f\n", si, s2, s1);
    CHECK(s2 < -0.75, "stratified 2D slope %.2f is not about -1", s2);
    CHECK(s1 < -1.3, "stratified 1D slope %.2f is not about -1.5", s1);
    CHECK(exp(l2[1]) < 0.3 * exp(li[1]), "stratified RMSE at 64 samples not well below independent");
    /* more samples, less error, also between the squares (a padded grid
     * with empty cells once made 32 samples worse than 16) */
    const int steps[] = {16, 24, 32, 48, 64};
    double prev = INFINITY;
    for (int k = 0; k < 5; k++) {
        double e = rmse(DR_SAMPLER_STRATIFIED, steps[k], true, NULL);
        CHECK(e < 0.9 * prev, "stratified RMSE at %d samples %.3g is not below %.3g at fewer", steps[k], e, prev);
        prev = e;
    }
    const int odd[] = {7, 12, 48, 200};
    for (int k = 0; k < 4; k++) {
        double b2, b1;
        double e2 = rmse(DR_SAMPLER_STRATIFIED, odd[k], true, &b2), ei = rmse(DR_SAMPLER_INDEPENDENT, odd[k], true, NULL);
        rmse(DR_SAMPLER_STRATIFIED, odd[k], false, &b1);
        CHECK(e2 < 0.6 * ei, "%d samples: stratified RMSE %.3g not below independent %.3g", odd[k], e2, ei);
        CHECK(fabs(b2) < 4.0 && fabs(b1) < 4.0, "%d samples: mean error %.1f / %.1f standard errors (biased)",
              odd[k], b2, b1);
    }
}

int main(void)
{
    const int ns[] = {1, 2, 7, 8, 12, 14, 16, 32, 48, 64, 100};
    for (int k = 0; k < 11; k++)
        check_strata(ns[k]);
    test_grid();
    test_permute();
    test_uniform();
    test_pure();
    test_decorrelated();
    test_convergence();
    return TEST_END();
}
