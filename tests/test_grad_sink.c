/* Tests of core/grad_sink.h's reverse-mode sink with a block mask (the
 * per-thread vectors of texture and grid gradients): the same bits as a
 * plain +=, -0 included, the mask marking every block written; and the
 * first write into a fresh part of the vector faulting its page in once,
 * for writing (a read first had the kernel map its zero page and then copy
 * it, with a TLB shoot-down on every other CPU). */
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include "grad_sink.h"
#include "test.h"

static uint64_t rng(uint64_t *s)
{
    *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
    return *s >> 11;
}

/* Random adds into a marked and a plain sink: identical vectors, bit for
 * bit, and a mask whose set blocks are exactly those written. */
static void same_bits(void)
{
    enum { N = 20000, ADDS = 60000 };
    double *a = calloc(N, sizeof(double)), *b = calloc(N, sizeof(double));
    uint64_t *mask = calloc((size_t)dr_mask_words(N), sizeof(uint64_t));
    bool *written = calloc(N / DR_ZERO_BLOCK + 1, sizeof(bool));
    const double values[] = {-0.0, 0.0, 1.5, -2.25, 1e-310, -1e-310, 3e300, 0.1, -0.0};
    struct dr_grad_sink marked = dr_sink_reverse_marked(a, mask), plain = dr_sink_reverse(b);
    uint64_t s = 7;
    for (int k = 0; k < ADDS; k++) {
        /* clustered slots, so that spans get both first and later writes */
        const int64_t slot = (int64_t)(rng(&s) % 40) * 500 + (int64_t)(rng(&s) % 7);
        const double v = values[rng(&s) % (sizeof values / sizeof *values)] * (k % 3 ? 1.0 : -1.0);
        dr_sink_add(&marked, slot, v);
        dr_sink_add(&plain, slot, v);
        written[slot / DR_ZERO_BLOCK] = true;
    }
    CHECK(memcmp(a, b, N * sizeof(double)) == 0, "a marked sink's vector differs from +='s");
    int wrong = 0, set = 0;
    for (int64_t i = 0; i < N; i += DR_ZERO_BLOCK) {
        set += dr_mask_test(mask, i);
        wrong += dr_mask_test(mask, i) != written[i / DR_ZERO_BLOCK];
    }
    CHECK(set > 0 && wrong == 0, "mask: %d blocks set, %d wrong", set, wrong);
    /* a first write of -0 gives +0, as += on +0 does (storing v itself would keep -0) */
    double c[DR_MASK_SPAN] = {0};
    uint64_t m[1] = {0};
    struct dr_grad_sink z = dr_sink_reverse_marked(c, m);
    dr_sink_add(&z, 3, -0.0);
    CHECK(!signbit(c[3]), "a first write of -0 made %g with its sign", c[3]);
    free(a);
    free(b);
    free(mask);
    free(written);
}

static long minor_faults(void)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
}

/* One add into each 4 KiB page of a fresh vector (4 KiB pages: no huge
 * pages there): about one fault per page. Read first, each page took two. */
static void one_fault_per_page(void)
{
    enum { PAGES = 4096, PER = 4096 / sizeof(double) };
    const size_t bytes = (size_t)PAGES * 4096;
    double *v = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    CHECK(v != MAP_FAILED, "mmap");
    if (v == MAP_FAILED)
        return;
    madvise(v, bytes, MADV_NOHUGEPAGE);
    uint64_t *mask = calloc((size_t)dr_mask_words((int64_t)PAGES * PER), sizeof(uint64_t));
    struct dr_grad_sink k = dr_sink_reverse_marked(v, mask);
    const long before = minor_faults();
    for (int p = 0; p < PAGES; p++)   /* (an entry inside each span, as a texel's channels land) */
        dr_sink_add(&k, (int64_t)p * PER + 37, 1.0 + p);
    const long faults = minor_faults() - before;
    /* (at least half a fault a page: the count is measured, the pages were fresh) */
    CHECK(faults >= PAGES / 2 && faults < PAGES * 3 / 2, "%ld page faults for the first writes into %d fresh pages",
          faults, PAGES);
    CHECK(v[37] == 1.0 && v[(int64_t)(PAGES - 1) * PER + 37] == PAGES, "the values written");
    printf("first writes into %d fresh pages: %ld faults\n", PAGES, faults);
    munmap(v, bytes);
    free(mask);
}

int main(void)
{
    same_bits();
    one_fault_per_page();
    return TEST_END();
}
