/* An allocation-failure injector for the command-line tests
 * (tests/cli_alloc_failures.sh), loaded with LD_PRELOAD.
 *
 * It counts the allocations (malloc, calloc, realloc, aligned_alloc,
 * posix_memalign, and C++'s operator new, failalloc_new.cpp, which throws
 * std::bad_alloc when it fails) that drender's own code makes: those whose caller lies in
 * the main program's executable segments. Allocations of the libraries
 * (OpenImageIO, Embree, tinygltf, the C++ runtime) are not counted and never
 * fail: the test is about drender's fallbacks and error paths, not theirs.
 *
 *   FAILALLOC_NTH=k      the k-th counted allocation (from 1) returns NULL;
 *                        0 or unset: none fails, they are only counted
 *   FAILALLOC_REPORT=F   at exit, "COUNT INJECTED" is written to F: how many
 *                        were counted, and 1 if the k-th was among them;
 *                        then, one line each, the counted allocations' call
 *                        sites (offsets in the program, so the same from run
 *                        to run), for the test to pick one allocation per site
 *
 * The real allocator is the next one in the search order (dlsym RTLD_NEXT):
 * glibc's, or AddressSanitizer's where drender is built with it (then this
 * library is preloaded before libasan, with verify_asan_link_order=0). */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif
#include <dlfcn.h>
#include <errno.h>
#include <link.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *(*malloc_fn)(size_t);
typedef void *(*calloc_fn)(size_t, size_t);
typedef void *(*realloc_fn)(void *, size_t);
typedef void *(*aligned_alloc_fn)(size_t, size_t);
typedef int (*posix_memalign_fn)(void **, size_t, size_t);

static malloc_fn real_malloc;
static calloc_fn real_calloc;
static realloc_fn real_realloc;
static aligned_alloc_fn real_aligned_alloc;
static posix_memalign_fn real_posix_memalign;
static void (*real_free)(void *);

/* dlsym may allocate (calloc) while the real functions are looked up: that
 * comes from this static arena, which free must then leave alone. */
static _Alignas(64) char bootstrap[8192];
static size_t bootstrap_used;
static int resolving;

/* the main program's executable segments: [lo, hi) pairs */
#define MAX_SEGMENTS 8
static uintptr_t seg_lo[MAX_SEGMENTS], seg_hi[MAX_SEGMENTS];
static int n_segments;
static uintptr_t program_base;

/* the call sites of the first MAX_SITES counted allocations */
#define MAX_SITES 65536
static uintptr_t sites[MAX_SITES];

static atomic_long counted;
static atomic_int injected;
static long nth;
static const char *report;

static int find_main_program(struct dl_phdr_info *info, size_t size, void *data)
{
    (void)size, (void)data;
    program_base = info->dlpi_addr;
    for (int i = 0; i < info->dlpi_phnum && n_segments < MAX_SEGMENTS; i++) {
        const ElfW(Phdr) *ph = &info->dlpi_phdr[i];
        if (ph->p_type == PT_LOAD && (ph->p_flags & PF_X)) {
            seg_lo[n_segments] = info->dlpi_addr + ph->p_vaddr;
            seg_hi[n_segments] = seg_lo[n_segments] + ph->p_memsz;
            n_segments++;
        }
    }
    return 1;   /* the first object is the main program */
}

/* the next definition of `name` in the search order, into the function
 * pointer *fn (through memcpy: ISO C has no cast from dlsym's void *) */
static void next_definition(const char *name, void *fn, size_t size)
{
    void *p = dlsym(RTLD_NEXT, name);
    memcpy(fn, &p, size);
}

static void resolve(void)
{
    if (real_malloc || resolving)
        return;
    resolving = 1;
    next_definition("malloc", &real_malloc, sizeof real_malloc);
    next_definition("calloc", &real_calloc, sizeof real_calloc);
    next_definition("realloc", &real_realloc, sizeof real_realloc);
    next_definition("aligned_alloc", &real_aligned_alloc, sizeof real_aligned_alloc);
    next_definition("posix_memalign", &real_posix_memalign, sizeof real_posix_memalign);
    next_definition("free", &real_free, sizeof real_free);
    resolving = 0;
}

static void *bootstrap_alloc(size_t n)
{
    n = (n + 63) & ~(size_t)63;
    if (n > sizeof bootstrap - bootstrap_used)
        return NULL;
    void *p = bootstrap + bootstrap_used;
    bootstrap_used += n;
    return p;
}

__attribute__((constructor)) static void failalloc_init(void)
{
    resolve();
    dl_iterate_phdr(find_main_program, NULL);
    const char *k = getenv("FAILALLOC_NTH");
    nth = k ? strtol(k, NULL, 10) : 0;
    static char report_path[4096];
    const char *r = getenv("FAILALLOC_REPORT");
    if (r && strlen(r) < sizeof report_path)
        report = strcpy(report_path, r);
    /* (the programs drender starts, gnuplot for one, inherit the preload
     * but not the settings: their allocations never fail, and their exit
     * does not overwrite the report) */
    unsetenv("FAILALLOC_NTH");
    unsetenv("FAILALLOC_REPORT");
}

__attribute__((destructor)) static void failalloc_report(void)
{
    if (!report)
        return;
    FILE *f = fopen(report, "w");
    if (f) {
        const long n = atomic_load(&counted);
        fprintf(f, "%ld %d\n", n, atomic_load(&injected));
        for (long i = 0; i < n && i < MAX_SITES; i++)
            fprintf(f, "%lx\n", (unsigned long)sites[i]);
        fclose(f);
    }
}

/* True if this allocation, called from `caller`, is to fail. */
static int should_fail(const void *caller)
{
    const uintptr_t a = (uintptr_t)caller;
    int ours = 0;
    for (int i = 0; i < n_segments; i++)
        ours |= a >= seg_lo[i] && a < seg_hi[i];
    if (!ours)
        return 0;
    const long k = atomic_fetch_add(&counted, 1) + 1;
    if (k <= MAX_SITES)
        sites[k - 1] = a - program_base;
    if (nth > 0 && k == nth) {
        atomic_store(&injected, 1);
        return 1;
    }
    return 0;
}

/* for the C++ allocation functions (tests/failalloc_new.cpp): the same
 * count, and the real allocator */
int failalloc_should_fail(const void *caller) { return should_fail(caller); }

void *failalloc_real_malloc(size_t n)
{
    if (!real_malloc)
        resolve();
    return real_malloc ? real_malloc(n) : bootstrap_alloc(n);
}

void *malloc(size_t n)
{
    if (!real_malloc) {
        resolve();
        if (!real_malloc)
            return bootstrap_alloc(n);
    }
    if (should_fail(__builtin_return_address(0))) {
        errno = ENOMEM;
        return NULL;
    }
    return real_malloc(n);
}

void *calloc(size_t n, size_t size)
{
    if (!real_calloc) {
        resolve();
        if (!real_calloc) {   /* (dlsym's own, zeroed already: static) */
            if (size && n > SIZE_MAX / size)
                return NULL;
            return bootstrap_alloc(n * size);
        }
    }
    if (should_fail(__builtin_return_address(0))) {
        errno = ENOMEM;
        return NULL;
    }
    return real_calloc(n, size);
}

void free(void *p)
{
    if ((char *)p >= bootstrap && (char *)p < bootstrap + sizeof bootstrap)
        return;
    if (!real_free) {
        /* (dlsym frees its error strings: while it runs for resolve, what it
         * frees is left, rather than asking dlsym again from inside it) */
        resolve();
        if (!real_free)
            return;
    }
    real_free(p);
}

void *realloc(void *p, size_t n)
{
    if (!real_realloc)
        resolve();
    if ((char *)p >= bootstrap && (char *)p < bootstrap + sizeof bootstrap) {
        /* (a bootstrap block: its size is not kept, so as much as the
         * arena holds after it is copied, at most n) */
        const size_t left = (size_t)(bootstrap + sizeof bootstrap - (char *)p);
        void *q = real_malloc(n);
        if (q)
            memcpy(q, p, n < left ? n : left);
        return q;
    }
    if (should_fail(__builtin_return_address(0))) {
        errno = ENOMEM;
        return NULL;
    }
    return real_realloc(p, n);
}

void *aligned_alloc(size_t align, size_t n)
{
    if (!real_aligned_alloc)
        resolve();
    if (should_fail(__builtin_return_address(0))) {
        errno = ENOMEM;
        return NULL;
    }
    return real_aligned_alloc(align, n);
}

int posix_memalign(void **out, size_t align, size_t n)
{
    if (!real_posix_memalign)
        resolve();
    if (should_fail(__builtin_return_address(0)))
        return ENOMEM;
    return real_posix_memalign(out, align, n);
}
