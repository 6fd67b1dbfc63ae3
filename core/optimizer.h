/* Adam over a parameter vector, with a learning rate per scalar and each
 * scalar kept inside its physical range (projected after every step). */
#ifndef DR_OPTIMIZER_H
#define DR_OPTIMIZER_H

#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "params.h"

struct dr_adam {
    int64_t n;
    int64_t t;                 /* steps taken */
    double beta1, beta2, eps;
    double *m, *v;             /* moment estimates, per scalar */
    /* per parameter (scalars [offset[k], offset[k] + size[k])): a texture's
     * texels share one learning rate and range, so three vectors of its size
     * would hold one number each */
    int n_params;
    int64_t *offset, *size;
    double *lr, *lo, *hi;
    int threads;               /* workers for a big parameter's step (dr_parallel_elements;
                                  dr_adam_create: 1; the same bits for any number) */
    /* dr_adam_step_masked's bookkeeping: `moved`, the blocks of m and v
     * that may not be +0 (zero_blocks.h), is true while moved_known (from
     * dr_adam_create: m and v start at +0); `ranged`: every value is inside
     * its range (after a masked step). Whoever changes theta, m or v
     * otherwise clears both (dr_adam_step and dr_checkpoint_read do).
     * changed: NULL or the blocks the last step may have moved
     * (dr_adam_changed). */
    uint64_t *moved;
    bool moved_known, ranged;
    const uint64_t *changed;
};

/* The parameter scalar i belongs to (-1: none). */
int dr_adam_param_of(const struct dr_adam *a, int64_t i);

/* Learning rates: lr_override > 0 applies to every parameter; otherwise a
 * default per kind (see dr_param_default_lr). NULL + dr_last_error. */
struct dr_adam *dr_adam_create(const struct dr_param_set *ps, const double *theta, double lr_override);
void dr_adam_destroy(struct dr_adam *a);
/* theta -= lr * mhat / (sqrt(vhat) + eps), then clamped into [lo, hi].
 * Non-finite gradient entries are treated as 0 (and counted in the return). */
int64_t dr_adam_step(struct dr_adam *a, double *theta, const double *grad);
/* The same step given grad's block mask (zero_blocks.h; grad is +0 in
 * every block it leaves clear; NULL: none known), to the bit: where a
 * value's gradient and moments are +0 and it is inside its range, the step
 * leaves it, its m and v as they are, so only the blocks grad_mask or the
 * moments' mask (a->moved) mark are stepped, and, while the values' ranges
 * are not known (the first step, or after a checkpoint is read), the
 * others whose values are outside their range (which the step clamps),
 * found without reading m and v (a read maps the zero page, and the
 * write after it costs a copy-on-write fault with a TLB shootdown). A
 * preview's texture: the blocks its gradients have reached so far. */
int64_t dr_adam_step_masked(struct dr_adam *a, double *theta, const double *grad, const uint64_t *grad_mask);
/* The blocks of theta the last step may have changed (NULL: any). */
const uint64_t *dr_adam_changed(const struct dr_adam *a);
/* The blocks of m and v that may not be +0 (a->moved where it is known;
 * NULL: any). */
const uint64_t *dr_adam_moments(const struct dr_adam *a);

/* Default learning rate of a parameter given its current values:
 * 0.02 for colours, metallic, roughness and texels (they live in [0,1]);
 * 5% of the current magnitude (at least 0.01) for intensities, emission
 * strengths and environment radiance, which have no natural scale. */
double dr_param_default_lr(const struct dr_param *p, const double *values);

/* Checkpoint (checkpoint.c): parameters and optimizer state, as text with
 * every double as a C99 hexadecimal constant (exact round trip; decimal is
 * read too), textures as packed binary runs, written to PATH.tmp and
 * renamed (atomic).
 * Reading checks that the names and sizes match the parameter set. */
int dr_checkpoint_write(const char *path, const char *scene_path, const struct dr_param_set *ps,
                        const double *theta, const struct dr_adam *adam, int64_t iteration);
int dr_checkpoint_read(const char *path, const struct dr_param_set *ps, double *theta, struct dr_adam *adam,
                       int64_t *iteration);

/* The same write with its end on a thread of its own: the contents are
 * written and flushed now (theta and adam may change once it returns; a
 * full disk fails here), the fsync and the rename over PATH run beside the
 * caller's next iterations (a 2k texture's checkpoint of 150 MB: about
 * 0.1 s of fsync and 0.04 s of rename, where the old file's blocks are
 * freed). A write waits for the one before it, so checkpoints replace each
 * other in order; dr_checkpoint_wait says how the last one ended (0, or
 * DR_ERR_IO with dr_last_error set). Until it returns, PATH holds the
 * previous checkpoint. Zero-initialise the struct; wait before exiting. */
struct dr_checkpoint_pending {
    pthread_t thread;
    bool running;
    FILE *f;
    int rc;
    char path[4096], tmp[4096], error[4300];
};
int dr_checkpoint_write_async(struct dr_checkpoint_pending *p, const char *path, const char *scene_path,
                              const struct dr_param_set *ps, const double *theta, const struct dr_adam *adam,
                              int64_t iteration);
int dr_checkpoint_wait(struct dr_checkpoint_pending *p);

#endif
