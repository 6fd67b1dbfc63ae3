/* Memory for big arrays: textures, texture gradients, tapes' neighbours.
 *
 * A page fault costs about 10 microseconds on the virtual machines drender
 * runs on, and a fresh 100 MB array (one 2k texture's gradient vector) takes
 * 25 thousand of them in 4 KiB pages, again in every estimator run. Arrays
 * of 2 MiB or more therefore start on a 2 MiB boundary and ask for
 * transparent huge pages: a few dozen faults instead. Release with free(). */
#ifndef DR_BIGALLOC_H
#define DR_BIGALLOC_H

#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#define DR_BIG_PAGE ((size_t)2 << 20)

static inline void *dr_alloc_big(size_t bytes)
{
    if (bytes < DR_BIG_PAGE)
        return malloc(bytes);
    size_t rounded = (bytes + DR_BIG_PAGE - 1) / DR_BIG_PAGE * DR_BIG_PAGE;
    void *p = aligned_alloc(DR_BIG_PAGE, rounded);
    if (p)
        madvise(p, rounded, MADV_HUGEPAGE);   /* advice only: failure changes nothing */
    return p;
}

/* From this size on glibc's calloc always maps fresh pages (its mmap
 * threshold, which grows as mapped blocks are freed, stops at 32 MiB on
 * 64-bit machines) and knows they are zero: it writes nothing. */
#define DR_LAZY_ZERO_BYTES ((size_t)32 << 20)

/* calloc's contract (n elements of size bytes, zeroed; NULL on overflow).
 * Arrays of DR_LAZY_ZERO_BYTES or more are calloc's fresh pages, with huge
 * pages asked for on the 2 MiB-aligned part: the kernel zeroes a page where
 * it is first written, so the pages a sparse vector never touches (a
 * texture gradient's, at a preview size) are never zeroed nor resident.
 * Smaller ones are dr_alloc_big's, zeroed now. */
static inline void *dr_calloc_big(size_t n, size_t size)
{
    if (size != 0 && n > SIZE_MAX / size)
        return NULL;
    const size_t bytes = n * size;
    if (bytes < DR_BIG_PAGE)
        return calloc(n, size);
    if (bytes >= DR_LAZY_ZERO_BYTES) {
        void *p = calloc(n, size);
        uintptr_t b = ((uintptr_t)p + DR_BIG_PAGE - 1) / DR_BIG_PAGE * DR_BIG_PAGE;
        uintptr_t e = ((uintptr_t)p + bytes) / DR_BIG_PAGE * DR_BIG_PAGE;
        if (p && e > b)
            madvise((void *)b, e - b, MADV_HUGEPAGE);   /* advice only */
        return p;
    }
    void *p = dr_alloc_big(bytes);
    if (p)
        memset(p, 0, bytes);
    return p;
}

/* A vector of n doubles kept in *buf from call to call (caller-owned
 * scratch, estimator.h's dr_est_scratch): *buf itself where it holds n
 * already (*kept true: its old values are still there), else a new zeroed
 * one (*kept false) in place of the old, *len n (0 and NULL when out of
 * memory). sparse: the new one is for a vector written in few places (a
 * preview's texture gradient): plain calloc, whose fresh pages the kernel
 * maps as they are first written, 4 KiB at a time, so that only those
 * become resident (a 2k texture's gradient at 64 x 64 on two threads:
 * `grad`'s peak 596 -> 496 MiB); else huge pages (dr_calloc_big: zeroed
 * now, or from 32 MiB on by the kernel where first written, 2 MiB at a
 * time), cheaper for a vector written whole, and for one passed over
 * sparsely many times (4 KiB pages: a TLB miss a block). */
static inline double *dr_big_vector_keep(double **buf, int64_t *len, int64_t n, bool sparse, bool *kept)
{
    *kept = *buf && *len == n;
    if (*kept)
        return *buf;
    free(*buf);
    *buf = (double *)(sparse ? calloc((size_t)n, sizeof(double)) : dr_calloc_big((size_t)n, sizeof(double)));
    *len = *buf ? n : 0;
    return *buf;
}

#endif
