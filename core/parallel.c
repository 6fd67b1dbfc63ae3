#include "parallel.h"

#include <pthread.h>
#include <stdbool.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"

struct job {
    int width, height, tiles_x, total;
    atomic_int next;
    int done;
    pthread_mutex_t lock;
    dr_tile_fn fn;
    dr_progress_fn progress;
    void *ctx;
};

struct worker {
    struct job *job;
    int index;
};

static void *worker_main(void *arg)
{
    struct worker *w = arg;
    struct job *j = w->job;
    for (;;) {
        int t = atomic_fetch_add(&j->next, 1);
        if (t >= j->total)
            break;
        int x0 = (t % j->tiles_x) * DR_TILE_SIZE, y0 = (t / j->tiles_x) * DR_TILE_SIZE;
        int x1 = x0 + DR_TILE_SIZE < j->width ? x0 + DR_TILE_SIZE : j->width;
        int y1 = y0 + DR_TILE_SIZE < j->height ? y0 + DR_TILE_SIZE : j->height;
        j->fn(j->ctx, w->index, x0, y0, x1, y1);
        if (j->progress) {
            pthread_mutex_lock(&j->lock);
            j->done++;
            j->progress(j->ctx, j->done, j->total);
            pthread_mutex_unlock(&j->lock);
        }
    }
    return NULL;
}

int dr_cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n >= 1 ? (int)n : 1;
}

static _Atomic int default_threads;   /* 0: one per CPU */

void dr_set_default_threads(int n)
{
    atomic_store(&default_threads, n > 0 ? n : 0);
}

int dr_default_threads(void)
{
    const int n = atomic_load(&default_threads);
    return n > 0 ? n : dr_cpu_count();
}

static void (*_Atomic started_hook)(int workers);

void dr_parallel_set_started_hook(void (*hook)(int workers))
{
    atomic_store(&started_hook, hook);
}

static void workers_started(int workers)
{
    void (*hook)(int) = atomic_load(&started_hook);
    if (hook)
        hook(workers);
}

int dr_parallel_tiles(int width, int height, int threads, dr_tile_fn fn, dr_progress_fn progress, void *ctx)
{
    struct job j;
    j.width = width;
    j.height = height;
    j.tiles_x = (width + DR_TILE_SIZE - 1) / DR_TILE_SIZE;
    j.total = j.tiles_x * ((height + DR_TILE_SIZE - 1) / DR_TILE_SIZE);
    atomic_init(&j.next, 0);
    j.done = 0;
    j.fn = fn;
    j.progress = progress;
    j.ctx = ctx;
    pthread_mutex_init(&j.lock, NULL);
    if (threads <= 0)
        threads = dr_default_threads();
    if (threads > j.total)
        threads = j.total > 0 ? j.total : 1;

    struct worker *ws = calloc((size_t)threads, sizeof *ws);
    pthread_t *ids = calloc((size_t)threads, sizeof *ids);
    int started = 0, rc = 0;
    if (!ws || !ids) {
        dr_set_error("out of memory");
        rc = DR_ERR_NOMEM;
        goto out;
    }
    for (int i = 0; i < threads; i++) {
        ws[i].job = &j;
        ws[i].index = i;
    }
    /* The calling thread is worker 0; the others are spawned. */
    for (int i = 1; i < threads; i++) {
        if (pthread_create(&ids[i], NULL, worker_main, &ws[i]) != 0)
            break;
        started++;
    }
    workers_started(1 + started);
    worker_main(&ws[0]);
    for (int i = 1; i <= started; i++)
        pthread_join(ids[i], NULL);
out:
    free(ws);
    free(ids);
    pthread_mutex_destroy(&j.lock);
    return rc;
}

struct range_job {
    int64_t n, chunk;
    int threads;
    bool fixed;            /* static assignment: chunk c -> worker c mod threads */
    _Atomic int64_t next;
    dr_range_fn fn;
    void *ctx;
};

struct range_worker {
    struct range_job *job;
    int index;
};

static void *range_main(void *arg)
{
    struct range_worker *w = arg;
    struct range_job *j = w->job;
    if (j->fixed) {
        for (int64_t b = (int64_t)w->index * j->chunk; b < j->n; b += (int64_t)j->threads * j->chunk)
            j->fn(j->ctx, w->index, b, b + j->chunk < j->n ? b + j->chunk : j->n);
        return NULL;
    }
    for (;;) {
        int64_t b = atomic_fetch_add(&j->next, j->chunk);
        if (b >= j->n)
            break;
        int64_t e = b + j->chunk < j->n ? b + j->chunk : j->n;
        j->fn(j->ctx, w->index, b, e);
    }
    return NULL;
}

static int range_run(int64_t n, int64_t chunk, int threads, bool fixed, dr_range_fn fn, void *ctx)
{
    struct range_job j;
    j.n = n;
    j.chunk = chunk > 0 ? chunk : 1;
    j.fixed = fixed;
    atomic_init(&j.next, 0);
    j.fn = fn;
    j.ctx = ctx;
    if (threads <= 0)
        threads = dr_default_threads();
    const int64_t chunks = (n + j.chunk - 1) / j.chunk;   /* (no more workers than chunks) */
    if (threads > chunks)
        threads = chunks > 0 ? (int)chunks : 1;
    j.threads = threads;
    struct range_worker *ws = calloc((size_t)threads, sizeof *ws);
    pthread_t *ids = calloc((size_t)threads, sizeof *ids);
    if (!ws || !ids) {
        free(ws);
        free(ids);
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    int started = 0;
    for (int i = 0; i < threads; i++) {
        ws[i].job = &j;
        ws[i].index = i;
    }
    for (int i = 1; i < threads; i++) {
        if (pthread_create(&ids[i], NULL, range_main, &ws[i]) != 0)
            break;
        started++;
    }
    workers_started(1 + started);
    range_main(&ws[0]);
    for (int i = 1; i <= started; i++)
        pthread_join(ids[i], NULL);
    free(ws);
    free(ids);
    return 0;
}

int dr_parallel_for(int64_t n, int64_t chunk, int threads, dr_range_fn fn, void *ctx)
{
    return range_run(n, chunk, threads, false, fn, ctx);
}

int dr_parallel_for_static(int64_t n, int64_t chunk, int threads, dr_range_fn fn, void *ctx)
{
    return range_run(n, chunk, threads, true, fn, ctx);
}

void dr_parallel_elements(int64_t n, int threads, dr_range_fn fn, void *ctx)
{
    threads = dr_thread_count(threads);
    if (threads > 1 && n >= DR_PARALLEL_ELEMENTS_MIN) {
        /* at least four chunks a worker, of whole DR_PARALLEL_ALIGN elements */
        int64_t chunk = n / (4 * threads) / DR_PARALLEL_ALIGN * DR_PARALLEL_ALIGN;
        chunk = chunk > DR_PARALLEL_ALIGN ? chunk : DR_PARALLEL_ALIGN;
        if (dr_parallel_for(n, chunk, threads, fn, ctx) == 0)
            return;
    }
    fn(ctx, 0, 0, n);
}

static void zero_range(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    memset((double *)ctx + begin, 0, sizeof(double) * (size_t)(end - begin));
}

void dr_parallel_zero(double *x, int64_t n, int threads)
{
    if (n > 0)
        dr_parallel_elements(n, threads, zero_range, x);
}

int dr_thread_count(int requested)
{
    int t = requested > 0 ? requested : dr_default_threads();
    return t > DR_MAX_THREADS ? DR_MAX_THREADS : t;
}
