/* The samplers: independent numbers unchanged, Sobol numbers stratified as a
 * (0,2) sequence, pure functions of (seed, pixel, sample, dimension), and a
 * faster-converging estimate of a smooth integral. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sampler.h"
#include "sampler8.h"
#include "test.h"

/* The independent sampler's numbers are what they were before samplers had
 * kinds (the formula, restated): old images and gradients stay bit-identical. */
static void test_independent_unchanged(void)
{
    struct dr_sampler a, b;
    dr_sampler_init(&a, 7, 1234, 5);
    dr_sampler_init_kind(&b, DR_SAMPLER_INDEPENDENT, 7, 1234, 5, 8);
    uint64_t key = dr_hash64(dr_hash64(dr_hash64(7 + 0x9e3779b97f4a7c15ULL) ^ 1234) ^ (5 * 0x9e3779b97f4a7c15ULL));
    for (uint32_t d = 1; d <= 40; d++) {
        double want = (double)(dr_hash64(key + (uint64_t)d * 0xd1b54a32d192ed03ULL) >> 11) * (1.0 / 9007199254740992.0);
        double x = dr_sampler_next(&a), y;
        if (d % 2) {
            double y2;
            dr_sampler_next2(&b, &y, &y2);
            double want2 = (double)(dr_hash64(key + (uint64_t)(d + 1) * 0xd1b54a32d192ed03ULL) >> 11) *
                           (1.0 / 9007199254740992.0);
            CHECK(y2 == want2, "next2's second number, dimension %u", d + 1);
        } else {
            y = want;   /* consumed by next2 above */
        }
        CHECK(x == want, "independent dimension %u changed", d);
        CHECK(y == want, "next2's first number, dimension %u", d);
    }
}

/* dr_sobol_dim1's table against the generator matrix's columns
 * (v_0 = 2^31, v_(b+1) = v_b ^ (v_b >> 1)), on every one-bit index and on
 * hashed ones. */
static uint32_t sobol_dim1_columns(uint32_t i)
{
    uint32_t x = 0, v = 0x80000000u;
    for (int b = 0; b < 32; b++, v ^= v >> 1)
        if (i >> b & 1u)
            x ^= v;
    return x;
}

static void test_sobol_dim1(void)
{
    int bad = 0;
    for (int b = 0; b < 32; b++)
        bad += dr_sobol_dim1(1u << b) != sobol_dim1_columns(1u << b);
    for (uint64_t k = 0; k < 100000; k++) {
        uint32_t i = (uint32_t)dr_hash64(k);
        bad += dr_sobol_dim1(i) != sobol_dim1_columns(i);
    }
    CHECK(bad == 0, "dr_sobol_dim1 differs from its columns on %d indices", bad);
    CHECK(dr_sobol_dim1(0) == 0 && dr_sobol_dim1(1) == 0x80000000u && dr_sobol_dim1(3) == 0x40000000u,
          "dr_sobol_dim1 of 0, 1, 3: %#x %#x %#x", dr_sobol_dim1(0), dr_sobol_dim1(1), dr_sobol_dim1(3));
}

/* The Sobol pair restated from its definition, bit by bit: the index
 * Owen-scrambled (reversed, Laine-Karras, reversed), dimension 0 its bits
 * reversed and dimension 1 dr_sobol_dim1's columns, each Owen-scrambled by
 * its own seed. dr_sampler_sobol2 cancels reversals that meet and reverses
 * with GFNI where it can; its numbers must be these. */
static uint32_t reverse_by_bits(uint32_t x)
{
    uint32_t r = 0;
    for (int b = 0; b < 32; b++)
        r |= (x >> b & 1u) << (31 - b);
    return r;
}

static uint32_t owen_by_definition(uint32_t x, uint32_t seed)
{
    x = reverse_by_bits(x) + seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_by_bits(x);
}

static void test_sobol_definition(void)
{
    int bad_rev = 0, bad = 0;
    for (uint64_t k = 0; k < 20000; k++) {
        uint32_t x = (uint32_t)dr_hash64(k ^ 0xabcdefULL);
        bad_rev += dr_reverse_bits32(x) != reverse_by_bits(x) || dr_reverse_bits32(1u << (k % 32)) != 1u << (31 - k % 32);
        struct dr_sampler s;
        dr_sampler_init_kind(&s, DR_SAMPLER_SOBOL, k % 7, k / 7, k % 300, 300);
        uint32_t dim = 1 + (uint32_t)(k % 37);
        uint64_t h = dr_hash64(s.pkey + (uint64_t)dim * 0xd1b54a32d192ed03ULL);
        uint64_t h1 = dr_hash64(h ^ 0x1111111111111111ULL), h2 = dr_hash64(h ^ 0x2222222222222222ULL);
        uint32_t i = owen_by_definition(s.index, (uint32_t)h);
        double want1 = dr_sobol_to_double(owen_by_definition(reverse_by_bits(i), (uint32_t)(h1 >> 32)), h1);
        double want2 = dr_sobol_to_double(owen_by_definition(sobol_dim1_columns(i), (uint32_t)(h2 >> 32)), h2);
        double u1, u2, v1;
        dr_sampler_sobol2(&s, dim, &u1, &u2);
        dr_sampler_sobol2(&s, dim, &v1, NULL);
        bad += u1 != want1 || u2 != want2 || v1 != want1;
    }
    CHECK(bad_rev == 0, "dr_reverse_bits32 wrong on %d numbers", bad_rev);
    CHECK(bad == 0, "dr_sampler_sobol2 differs from the definition on %d of 20000 draws", bad);
}

/* A pixel's samples made once per pixel (dr_sampler_pixel_sample and
 * dr_sampler_pixel_first2, as render does) draw what dr_sampler_init_kind's
 * and dr_sampler_next2 draw, first draw and later ones, every kind. */
static void test_pixel_sampler(void)
{
    const enum dr_sampler_kind kinds[] = {DR_SAMPLER_INDEPENDENT, DR_SAMPLER_SOBOL, DR_SAMPLER_STRATIFIED};
    int bad = 0, n = 0;
    for (int k = 0; k < 3; k++)
        for (uint64_t pixel = 0; pixel < 40; pixel++) {
            const int spp = 1 + (int)(pixel % 13);
            struct dr_sampler_pixel p;
            dr_sampler_pixel_init(&p, kinds[k], 99, pixel * 7919, spp);
            for (int smp = 0; smp < spp; smp++, n++) {
                struct dr_sampler a, b;
                dr_sampler_pixel_sample(&p, (uint64_t)smp, &a);
                dr_sampler_init_kind(&b, kinds[k], 99, pixel * 7919, (uint64_t)smp, spp);
                double a1, a2, b1, b2;
                dr_sampler_pixel_first2(&p, &a, &a1, &a2);
                dr_sampler_next2(&b, &b1, &b2);
                bad += a1 != b1 || a2 != b2 || a.dim != b.dim || dr_sampler_next(&a) != dr_sampler_next(&b);
            }
        }
    CHECK(bad == 0, "a pixel's samplers differ from dr_sampler_init_kind's on %d of %d samples", bad, n);
}

/* The eight-lane start (dr_sampler_pixel_first2_8, render's) against the
 * scalar one lane by lane: the same samplers, field by field, and the same
 * first draws, for every kind, with lanes from different pixels. */
static void test_pixel_sampler_eight(void)
{
    const enum dr_sampler_kind kinds[] = {DR_SAMPLER_INDEPENDENT, DR_SAMPLER_SOBOL, DR_SAMPLER_STRATIFIED};
    int bad = 0;
    for (int k = 0; k < 3; k++)
        for (uint64_t first = 0; first < 64; first += 3) {
            struct dr_sampler_pixel px[8];
            const struct dr_sampler_pixel *p[8];
            uint64_t sample[8];
            for (int l = 0; l < 8; l++) {   /* 6 samples per pixel: the lanes straddle pixels */
                dr_sampler_pixel_init(&px[l], kinds[k], 5, (first + l) / 6 * 31, 6);
                p[l] = &px[l], sample[l] = (first + l) % 6;
            }
            struct dr_sampler s8[8];
            dr_f8 u8, v8;
            dr_sampler_pixel_first2_8(p, sample, s8, &u8, &v8);
            for (int l = 0; l < 8; l++) {
                struct dr_sampler s1;
                double u, v;
                dr_sampler_pixel_sample(p[l], sample[l], &s1);
                dr_sampler_pixel_first2(p[l], &s1, &u, &v);
                bad += memcmp(&s1, &s8[l], sizeof s1) != 0 || u != u8[l] || v != v8[l];
            }
        }
    CHECK(bad == 0, "the eight-lane start differs from the scalar one in %d lanes", bad);
}

/* A path vertex's seven numbers from the eight-lane Sobol draws
 * (dr_sobol_vertex8, the packet tracer's) against dr_sampler_next and
 * next2 lane by lane: every lane its own pixel, sample and dimension. */
static void test_sobol_vertex_eight(void)
{
    int bad = 0;
    for (uint64_t k = 0; k < 400; k++) {
        struct dr_sampler s[8];
        dr_u8 pkey, d;
        dr_u32x8 index;
        for (int l = 0; l < 8; l++) {
            const uint64_t n = 8 * k + (uint64_t)l;
            dr_sampler_init_kind(&s[l], DR_SAMPLER_SOBOL, n % 5, n / 5 * 17, dr_hash64(n) % 1000, 1000);
            s[l].dim = 2 + 7 * (uint32_t)(dr_hash64(n ^ 77) % 40);
            pkey[l] = s[l].pkey, index[l] = s[l].index, d[l] = s[l].dim;
        }
        dr_f8 u[7];
        dr_sobol_vertex8(pkey, dr_reverse_bits8(index), d, u);
        for (int l = 0; l < 8; l++) {
            double r[7];
            r[0] = dr_sampler_next(&s[l]);
            dr_sampler_next2(&s[l], &r[1], &r[2]);
            r[3] = dr_sampler_next(&s[l]);
            dr_sampler_next2(&s[l], &r[4], &r[5]);
            r[6] = dr_sampler_next(&s[l]);
            for (int j = 0; j < 7; j++) {
                const double v = u[j][l];
                bad += memcmp(&r[j], &v, sizeof v) != 0;
            }
        }
    }
    CHECK(bad == 0, "dr_sobol_vertex8 differs from the scalar draws in %d of %d numbers", bad, 400 * 8 * 7);
}

/* Over N = 2^k samples of a pixel, every 1D Sobol draw puts one sample in
 * each interval [i/N, (i+1)/N), and every 2D draw one in each elementary box
 * of area 1/N (2^a x 2^b cells, a + b = k). */
static void test_sobol_stratified(void)
{
    enum { K = 6, N = 1 << K };
    for (uint64_t pixel = 0; pixel < 20; pixel++) {
        double u1[N][8];
        for (int i = 0; i < N; i++) {
            struct dr_sampler s;
            dr_sampler_init_kind(&s, DR_SAMPLER_SOBOL, 3, pixel, (uint64_t)i, N);
            u1[i][0] = dr_sampler_next(&s);
            dr_sampler_next2(&s, &u1[i][1], &u1[i][2]);
            u1[i][3] = dr_sampler_next(&s);
            dr_sampler_next2(&s, &u1[i][4], &u1[i][5]);
            u1[i][6] = dr_sampler_next(&s);
            u1[i][7] = dr_sampler_next(&s);
            for (int d = 0; d < 8; d++)
                CHECK(u1[i][d] >= 0.0 && u1[i][d] < 1.0, "pixel %llu sample %d dim %d: %g out of [0,1)",
                      (unsigned long long)pixel, i, d, u1[i][d]);
        }
        for (int d = 0; d < 8; d++) {
            int count[N] = {0}, bad = 0;
            for (int i = 0; i < N; i++)
                count[(int)(u1[i][d] * N)]++;
            for (int c = 0; c < N; c++)
                bad += count[c] != 1;
            CHECK(bad == 0, "pixel %llu dimension %d: 1D strata not one sample each (%d off)",
                  (unsigned long long)pixel, d, bad);
        }
        const int pairs[2][2] = {{1, 2}, {4, 5}};
        for (int p = 0; p < 2; p++)
            for (int a = 0; a <= K; a++) {
                int count[N] = {0}, bad = 0;
                for (int i = 0; i < N; i++) {
                    int cx = (int)(u1[i][pairs[p][0]] * (1 << a)), cy = (int)(u1[i][pairs[p][1]] * (1 << (K - a)));
                    count[cy * (1 << a) + cx]++;
                }
                for (int c = 0; c < N; c++)
                    bad += count[c] != 1;
                CHECK(bad == 0, "pixel %llu pair %d: %dx%d elementary boxes not one sample each (%d off)",
                      (unsigned long long)pixel, p, 1 << a, 1 << (K - a), bad);
            }
    }
}

/* Pure function: the same (seed, pixel, sample, dimension) gives the same
 * number in any order; other seeds and pixels give other numbers. */
static void test_sobol_pure(void)
{
    struct dr_sampler a, b, c;
    dr_sampler_init_kind(&a, DR_SAMPLER_SOBOL, 11, 99, 13, 16);
    double first[10];
    for (int d = 0; d < 10; d++)
        first[d] = dr_sampler_next(&a);
    dr_sampler_init_kind(&b, DR_SAMPLER_SOBOL, 11, 99, 13, 16);
    b.dim = 6;   /* jump ahead, as the path walker does per vertex */
    CHECK(dr_sampler_next(&b) == first[6], "jumping to dimension 7 gives the same number");
    dr_sampler_init_kind(&c, DR_SAMPLER_SOBOL, 12, 99, 13, 16);
    int same = 0;
    for (int d = 0; d < 10; d++)
        same += dr_sampler_next(&c) == first[d];
    CHECK(same == 0, "another seed gives other numbers (%d equal)", same);
}

/* RMSE over independent randomisations (pixels) of the N-sample estimate of
 * the integral of a smooth 2D function over the unit square. */
static double rmse(enum dr_sampler_kind kind, int n)
{
    const double exact = (1.0 - cos(3.0)) / 3.0 * (exp(1.0) - 1.0);   /* of sin(3x) e^y */
    double sq = 0.0;
    const int reps = 400;
    for (int r = 0; r < reps; r++) {
        double sum = 0.0;
        for (int i = 0; i < n; i++) {
            struct dr_sampler s;
            dr_sampler_init_kind(&s, kind, 5, (uint64_t)r, (uint64_t)i, n);
            double x, y;
            dr_sampler_next2(&s, &x, &y);
            sum += sin(3.0 * x) * exp(y);
        }
        double e = sum / n - exact;
        sq += e * e;
    }
    return sqrt(sq / reps);
}

/* Slope of log RMSE against log N: about -0.5 for independent numbers, about
 * -1.5 for scrambled Sobol on a smooth integrand (Owen 1997). */
static void test_convergence(void)
{
    const int ns[] = {16, 64, 256};
    double li[3], ls[3];
    for (int k = 0; k < 3; k++) {
        li[k] = log(rmse(DR_SAMPLER_INDEPENDENT, ns[k]));
        ls[k] = log(rmse(DR_SAMPLER_SOBOL, ns[k]));
    }
    double slope_i = (li[2] - li[0]) / log(16.0), slope_s = (ls[2] - ls[0]) / log(16.0);
    fprintf(stderr, "error-vs-N slope: independent %.2f, sobol %.2f; RMSE at 256: %.3g vs %.3g\n", slope_i, slope_s,
            exp(li[2]), exp(ls[2]));
    CHECK(slope_i > -0.65 && slope_i < -0.35, "independent slope %.2f is not about -0.5", slope_i);
    CHECK(slope_s < -1.1, "sobol slope %.2f is not much steeper than -0.5", slope_s);
    CHECK(exp(ls[2]) < 0.1 * exp(li[2]), "sobol RMSE at 256 samples not 10x below independent");
}

int main(void)
{
    test_independent_unchanged();
    test_sobol_dim1();
    test_sobol_definition();
    test_pixel_sampler();
    test_pixel_sampler_eight();
    test_sobol_vertex_eight();
    test_sobol_stratified();
    test_sobol_pure();
    test_convergence();
    CHECK(dr_sampler_kind_parse("sobol") == DR_SAMPLER_SOBOL && dr_sampler_kind_parse("independent") == 0 &&
              dr_sampler_kind_parse("halton") == -1,
          "sampler names");
    return TEST_END();
}
