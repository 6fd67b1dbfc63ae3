/* Tests of core/parallel.c's started hook (the render's background load of
 * the image library hangs on it): called once per run, on the calling
 * thread, by every kind of run, and not once it is unset; and of the
 * preload it carries in the CLI. */
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "image_io.h"
#include "parallel.h"
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

int main(void)
{
    test_started_hook();
    test_preload();
    return TEST_END();
}
