/* Work distribution: the image is cut into square tiles handed out to a
 * fixed number of threads through an atomic counter. Each pixel is computed by
 * exactly one thread from its own random numbers, so results do not depend on
 * the thread count. */
#ifndef DR_PARALLEL_H
#define DR_PARALLEL_H

#define DR_TILE_SIZE 16

/* Called once per tile, from worker `thread` (0..threads-1); [x0,x1) x [y0,y1). */
typedef void (*dr_tile_fn)(void *ctx, int thread, int x0, int y0, int x1, int y1);
/* Called after each finished tile with the count of finished tiles, from the
 * finishing worker, serialised by a mutex. May be NULL. */
typedef void (*dr_progress_fn)(void *ctx, int done, int total);

/* Runs fn over all tiles of a width x height image on `threads` threads
 * (<= 0: one per online CPU). Returns 0 or DR_ERR_INTERNAL (thread creation). */
int dr_parallel_tiles(int width, int height, int threads, dr_tile_fn fn, dr_progress_fn progress, void *ctx);

/* Number of online CPUs (>= 1). */
int dr_cpu_count(void);

#endif
