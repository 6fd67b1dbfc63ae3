/* Work distribution: the image is cut into square tiles handed out to a
 * fixed number of threads through an atomic counter. Each pixel is computed by
 * exactly one thread from its own random numbers, so results do not depend on
 * the thread count. */
#ifndef DR_PARALLEL_H
#define DR_PARALLEL_H

#include <stdint.h>

#define DR_TILE_SIZE 16
/* The most worker threads any run uses (per-thread buffers are sized by it). */
#define DR_MAX_THREADS 256

/* Called once per tile, from worker `thread` (0..threads-1); [x0,x1) x [y0,y1). */
typedef void (*dr_tile_fn)(void *ctx, int thread, int x0, int y0, int x1, int y1);
/* Called after each finished tile with the count of finished tiles, from the
 * finishing worker, serialised by a mutex. May be NULL. */
typedef void (*dr_progress_fn)(void *ctx, int done, int total);

/* Runs fn over all tiles of a width x height image on `threads` threads
 * (<= 0: one per online CPU). Returns 0 or DR_ERR_INTERNAL (thread creation). */
int dr_parallel_tiles(int width, int height, int threads, dr_tile_fn fn, dr_progress_fn progress, void *ctx);

/* Runs fn over [0, n) in chunks of `chunk` items handed out dynamically to
 * `threads` workers (<= 0: dr_default_threads; no more than there are
 * chunks); fn gets [begin, end). */
typedef void (*dr_range_fn)(void *ctx, int thread, int64_t begin, int64_t end);
int dr_parallel_for(int64_t n, int64_t chunk, int threads, dr_range_fn fn, void *ctx);
/* The same with a fixed assignment: chunk c goes to worker c mod threads, each
 * worker taking its chunks in increasing order. Per-thread sums then do not
 * depend on timing, so results are bit-identical run to run for a given
 * thread count (what gradient estimators and resumable optimisation need). */
int dr_parallel_for_static(int64_t n, int64_t chunk, int threads, dr_range_fn fn, void *ctx);

/* Element-wise work on a big vector (a texture parameter's 12.6 M entries:
 * clearing, summing, Adam's step), whose every element's result does not
 * depend on how [0, n) is split: fn over [0, n) on up to `threads` workers
 * (<= 0: dr_default_threads), the same bits for any thread count. Below
 * DR_PARALLEL_ELEMENTS_MIN elements, with one thread, or if no worker can be
 * had, fn runs on the calling thread alone. Every range but the last is a
 * multiple of DR_PARALLEL_ALIGN elements long, so ranges begin at its
 * multiples: a bit mask word over 512 elements (zero_blocks.h) belongs to
 * one range, which may write it. */
#define DR_PARALLEL_ELEMENTS_MIN 65536
#define DR_PARALLEL_ALIGN 1024
void dr_parallel_elements(int64_t n, int threads, dr_range_fn fn, void *ctx);
/* dr_parallel_elements clearing n doubles at x. */
void dr_parallel_zero(double *x, int64_t n, int threads);

/* Sets a function every later run (dr_parallel_tiles, _for, _for_static)
 * calls on its calling thread, with the run's number of workers, once all
 * of them have been created (NULL: none). For work to start in the
 * background while the workers run without holding up their creation: the
 * CLI's preload of the image library, whose dlopen holds a lock
 * pthread_create also takes (image_plugin.h). */
void dr_parallel_set_started_hook(void (*hook)(int workers));
/* Number of online CPUs (>= 1). */
int dr_cpu_count(void);
/* The workers of work that names no number (threads <= 0 above, the scene
 * loader's decodes, the light tables' builds): one per CPU, or the number
 * set here (the command line's --threads; n <= 0: one per CPU again), so
 * that a run asked to keep to n threads does so from its start. */
void dr_set_default_threads(int n);
int dr_default_threads(void);
/* The workers a run uses for a request (<= 0: dr_default_threads), at most DR_MAX_THREADS. */
int dr_thread_count(int requested);

#endif
