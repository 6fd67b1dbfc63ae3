/* Tests of core/parallel.c's started hook (the render's background load of
 * the image library hangs on it): called once per run, on the calling
 * thread, by every kind of run, and not once it is unset; of the preload
 * it carries in the CLI; and of the default number of workers (--threads),
 * which the scene loader and Embree's builds keep to as well. */
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "error.h"
#include "image_io.h"
#include "parallel.h"
#include "scene.h"
#include "test.h"

static _Atomic int hook_calls, hook_off_caller, hook_workers, work_items;
static pthread_t caller;

static void hook(int workers)
{
    atomic_fetch_add(&hook_calls, 1);
    atomic_fetch_add(&hook_workers, workers);
    if (!pthread_equal(pthread_self(), caller))
        atomic_fetch_add(&hook_off_caller, 1);
}

static void tile(void *ctx, int thread, int x0, int y0, int x1, int y1)
{
    (void)ctx, (void)thread;
    atomic_fetch_add(&work_items, (x1 - x0) * (y1 - y0));
}

static void range(void *ctx, int thread, int64_t b, int64_t e)
{
    (void)ctx, (void)thread;
    atomic_fetch_add(&work_items, (int)(e - b));
}

static void test_started_hook(void)
{
    caller = pthread_self();
    dr_parallel_set_started_hook(hook);
    for (int threads = 1; threads <= 3; threads++) {
        atomic_store(&hook_calls, 0);
        atomic_store(&hook_workers, 0);
        atomic_store(&work_items, 0);
        CHECK(dr_parallel_tiles(40, 30, threads, tile, NULL, NULL) == 0, "tiles on %d threads", threads);
        CHECK(dr_parallel_for(1000, 7, threads, range, NULL) == 0, "for on %d threads", threads);
        CHECK(dr_parallel_for_static(1000, 7, threads, range, NULL) == 0, "for_static on %d threads", threads);
        CHECK(atomic_load(&hook_calls) == 3, "%d threads: the hook ran %d times for 3 runs", threads,
              atomic_load(&hook_calls));
        CHECK(atomic_load(&hook_workers) == 3 * threads, "%d threads: the hook was told %d workers in 3 runs", threads,
              atomic_load(&hook_workers));
        CHECK(atomic_load(&work_items) == 40 * 30 + 2000, "%d threads: %d items done", threads,
              atomic_load(&work_items));
    }
    CHECK(atomic_load(&hook_off_caller) == 0, "the hook ran off the calling thread %d times",
          atomic_load(&hook_off_caller));
    dr_parallel_set_started_hook(NULL);
    atomic_store(&hook_calls, 0);
    CHECK(dr_parallel_tiles(40, 30, 2, tile, NULL, NULL) == 0 && atomic_load(&hook_calls) == 0,
          "unset, the hook does not run (%d)", atomic_load(&hook_calls));
}

/* The preload as the CLI's render sets it up: its runs go on, and the
 * library is there for the write afterwards (a second preload is a no-op). */
static void preload(int workers)
{
    (void)workers;
    dr_image_library_preload();
}

static void test_preload(void)
{
    dr_parallel_set_started_hook(preload);
    atomic_store(&work_items, 0);
    CHECK(dr_parallel_tiles(64, 64, 2, tile, NULL, NULL) == 0 && atomic_load(&work_items) == 64 * 64,
          "a run with the preload as its hook");
    dr_image_library_preload();
    CHECK(dr_image_library_ok(), "the image library is loaded after the preload");
    CHECK(dr_image_can_write("out.exr"), "and writes EXR");
    dr_parallel_set_started_hook(NULL);
}

/* dr_parallel_elements: every element exactly once; a big vector handed
 * out in chunks to the workers (which worker takes which depends on
 * timing), each beginning at a multiple of DR_PARALLEL_ALIGN, a small one,
 * or any with one thread, in one call on the calling
 * thread; dr_parallel_zero clears all of it and nothing else. */
struct marks {
    unsigned char *seen;
    _Atomic int calls, unaligned;
    pthread_t caller;
    _Atomic int off_caller;
};

static void mark(void *ctx, int thread, int64_t b, int64_t e)
{
    struct marks *m = ctx;
    for (int64_t i = b; i < e; i++)
        m->seen[i]++;
    (void)thread;
    atomic_fetch_add(&m->calls, 1);
    if (b % DR_PARALLEL_ALIGN != 0)
        atomic_fetch_add(&m->unaligned, 1);
    if (!pthread_equal(pthread_self(), m->caller))
        atomic_store(&m->off_caller, 1);
}

static void test_elements(void)
{
    const int64_t sizes[] = {0, 1, DR_PARALLEL_ELEMENTS_MIN - 1, DR_PARALLEL_ELEMENTS_MIN, 1000003};
    for (int k = 0; k < 5; k++)
        for (int threads = 1; threads <= 3; threads += 2) {
            const int64_t n = sizes[k];
            struct marks m = {.seen = calloc((size_t)n + 1, 1), .caller = pthread_self()};
            atomic_init(&m.calls, 0);
            atomic_init(&m.unaligned, 0);
            atomic_init(&m.off_caller, 0);
            dr_parallel_elements(n, threads, mark, &m);
            int64_t wrong = 0;
            for (int64_t i = 0; i < n; i++)
                wrong += m.seen[i] != 1;
            CHECK(wrong == 0 && m.seen[n] == 0, "n %lld, %d threads: %lld elements not seen exactly once",
                  (long long)n, threads, (long long)wrong);
            const bool big = threads > 1 && n >= DR_PARALLEL_ELEMENTS_MIN;
            CHECK(big ? atomic_load(&m.calls) >= 4 * threads : atomic_load(&m.calls) == 1 && !atomic_load(&m.off_caller),
                  "n %lld, %d threads: %d calls, off the caller %d", (long long)n, threads, atomic_load(&m.calls),
                  atomic_load(&m.off_caller));
            CHECK(atomic_load(&m.unaligned) == 0, "n %lld, %d threads: %d ranges not at a multiple of %d",
                  (long long)n, threads, atomic_load(&m.unaligned), DR_PARALLEL_ALIGN);
            free(m.seen);
        }
    enum { N = 200003 };
    double *x = malloc(sizeof(double) * (N + 2));
    for (int i = 0; i < N + 2; i++)
        x[i] = 1.5;
    dr_parallel_zero(x + 1, N, 2);
    int64_t nonzero = 0;
    for (int i = 1; i <= N; i++)
        nonzero += x[i] != 0.0;
    CHECK(nonzero == 0 && x[0] == 1.5 && x[N + 1] == 1.5, "dr_parallel_zero: %lld left, edges %g %g",
          (long long)nonzero, x[0], x[N + 1]);
    free(x);
}

/* The process's threads now (/proc/self/status), 0 if unknown. */
static int process_threads(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    int n = 0;
    while (f && fgets(line, sizeof line, f))
        if (strncmp(line, "Threads:", 8) == 0)
            n = atoi(line + 8);
    if (f)
        fclose(f);
    return n;
}

static _Atomic int most_workers;

static void note_workers(int workers)
{
    int m = atomic_load(&most_workers);
    while (workers > m && !atomic_compare_exchange_weak(&most_workers, &m, workers)) {
    }
}

/* A flat grid of 2 * n * n triangles, big enough for Embree to build it
 * on several threads where it may. */
static void grid_mesh(struct dr_mesh *m, uint32_t n)
{
    memset(m, 0, sizeof *m);
    m->n_vertices = (n + 1) * (n + 1);
    m->n_triangles = 2 * n * n;
    m->positions = calloc((size_t)m->n_vertices * 3 + 1, sizeof(float));
    m->indices = calloc((size_t)m->n_triangles * 3, sizeof(uint32_t));
    for (uint32_t y = 0; y <= n; y++)
        for (uint32_t x = 0; x <= n; x++) {
            float *p = m->positions + 3 * (y * (n + 1) + x);
            p[0] = (float)x, p[1] = (float)y, p[2] = (float)((x * 7 + y * 3) % 5) * 0.1f;
        }
    for (uint32_t y = 0, t = 0; y < n; y++)
        for (uint32_t x = 0; x < n; x++, t += 2) {
            const uint32_t a = y * (n + 1) + x, b = a + 1, c = a + n + 1, d = c + 1;
            const uint32_t tri[6] = {a, b, d, a, d, c};
            memcpy(m->indices + 3 * t, tri, sizeof tri);
        }
}

/* dr_set_default_threads (the CLI's --threads): runs that name no number
 * take it, Embree builds on no more threads, and the scene loader decodes
 * its images on no more workers. Runs first: the threads Embree's task
 * scheduler starts stay for the process's life. */
static void test_default_threads(void)
{
    dr_set_default_threads(1);
    CHECK(dr_default_threads() == 1 && dr_thread_count(0) == 1 && dr_thread_count(3) == 3,
          "default 1: %d, a run of 0 gets %d, of 3 gets %d", dr_default_threads(), dr_thread_count(0),
          dr_thread_count(3));
    /* Embree's build: no new thread (it had started one per CPU, less its caller) */
    struct dr_mesh m;
    grid_mesh(&m, 400);
    const int before = process_threads();
    struct dr_accel *a = dr_accel_create(&m);
    const int during = process_threads();
    CHECK(a != NULL, "a 320k-triangle structure: %s", dr_last_error());
    CHECK(before > 0 && during == before, "default 1: Embree's build left %d threads (%d before)", during, before);
    if (a)
        CHECK(dr_accel_intersect(a, dr_v3(10.5, 10.25, 5.0), dr_v3(0.0, 0.0, -1.0), 0.0, 100.0) >= 0,
              "the structure built on one thread answers");
    dr_accel_destroy(a);
    free(m.positions);
    free(m.indices);
    /* the loader's image decodes (three 2048 x 2048 PNGs) */
    const char *sample = shared_sample("NormalTangentTest/glTF/NormalTangentTest.gltf");
    CHECK(sample != NULL, "the shared sample NormalTangentTest was not found beside the checkout");
    dr_parallel_set_started_hook(note_workers);
    for (int limit = 1; sample && limit <= 3; limit += 2) {
        dr_set_default_threads(limit);
        atomic_store(&most_workers, 0);
        CHECK(dr_parallel_for(1000, 7, 0, range, NULL) == 0 && atomic_load(&most_workers) == limit,
              "default %d: a run of 0 threads took %d workers", limit, atomic_load(&most_workers));
        atomic_store(&most_workers, 0);
        struct dr_scene *s = dr_scene_load(sample);
        CHECK(s != NULL && s->n_images == 3, "%s: %s", sample, s ? "not three images" : dr_last_error());
        CHECK(atomic_load(&most_workers) == limit, "default %d: the loader's runs took up to %d workers", limit,
              atomic_load(&most_workers));
        dr_scene_destroy(s);
    }
    /* no more workers than chunks: three items of one, eight workers asked */
    atomic_store(&most_workers, 0);
    atomic_store(&work_items, 0);
    CHECK(dr_parallel_for(3, 1, 8, range, NULL) == 0 && atomic_load(&most_workers) == 3 &&
              atomic_load(&work_items) == 3,
          "3 chunks on 8 threads: %d workers, %d items", atomic_load(&most_workers), atomic_load(&work_items));
    dr_parallel_set_started_hook(NULL);
    /* back to one per CPU */
    dr_set_default_threads(0);
    CHECK(dr_default_threads() == dr_cpu_count() && dr_thread_count(0) == dr_cpu_count(),
          "default reset: %d (%d CPUs)", dr_default_threads(), dr_cpu_count());
}

int main(void)
{
    test_default_threads();
    test_started_hook();
    test_preload();
    test_elements();
    return TEST_END();
}
