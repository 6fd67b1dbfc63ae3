/* Where parameter adjoints land. Every d_ function that reaches a scene
 * parameter writes through a sink instead of knowing the estimator's mode:
 *  - reverse mode: a gradient vector, grad[slot] += v  (d loss / d theta),
 *    the thread's own, or one all threads share, added to exactly
 *    (exact_sum.h: a texture parameter on many threads);
 *  - forward mode: a running dot product with a direction per image channel,
 *    forward[channel] += dir[slot] * v  (d I_channel / d theta . dir);
 *    with groups, one per group of slots (a parameter each: `grad -o` with
 *    several parameters differentiates them all in one pass over the
 *    paths, an image each, instead of a pass each in which every
 *    parameter's adjoints were computed and all but one multiplied by 0),
 *    forward[3 * group + channel] += dir[slot] * v.
 * Forward mode keeps the three image channels apart in one pass over a path:
 * the caller splits a channel-diagonal adjoint into its channels and sets
 * `channel` before each part (dr_sink_for_channels). Slots are offsets into
 * the parameter set's gradient vector (params.h). */
#ifndef DR_GRAD_SINK_H
#define DR_GRAD_SINK_H

#include <stdint.h>

#include "exact_sum.h"
#include "zero_blocks.h"
#include "vec.h"

/* The most groups one forward pass keeps apart (estimator.h's
 * dr_estimator_forward_groups). */
#define DR_FORWARD_MAX 4

struct dr_grad_sink {
    double *grad;        /* reverse mode: gradient vector (+=) */
    uint64_t *touched;   /* reverse mode, when not NULL: the blocks of grad (or exact) it adds to are
                            marked here (zero_blocks.h's masks: whoever sums them then reads only
                            those; the thread's own, also with the shared exact sums) */
    struct dr_exact_sum *exact;   /* reverse mode, when not NULL: the shared exact sums instead */
    const double *dir;   /* forward mode (when not NULL): direction */
    /* forward mode, with n_groups > 1: slot s is group g's where
     * group_end[g - 1] <= s < group_end[g] (group_end[-1] = 0); slots past
     * the last end are the last group's */
    const int64_t *group_end;
    int n_groups;
    int channel;         /* forward mode: the channel the current adjoint belongs to */
    double forward[3 * DR_FORWARD_MAX];   /* forward mode: accumulated dot product per group and image channel */
};

static inline struct dr_grad_sink dr_sink_reverse(double *grad)
{
    return (struct dr_grad_sink){.grad = grad};
}

static inline struct dr_grad_sink dr_sink_reverse_marked(double *grad, uint64_t *touched)
{
    return (struct dr_grad_sink){.grad = grad, .touched = touched};
}

static inline struct dr_grad_sink dr_sink_exact(struct dr_exact_sum *e, uint64_t *touched)
{
    return (struct dr_grad_sink){.exact = e, .touched = touched};
}

static inline struct dr_grad_sink dr_sink_forward(const double *dir)
{
    return (struct dr_grad_sink){.dir = dir, .n_groups = 1};
}

/* n_groups (1 .. DR_FORWARD_MAX) groups of slots, ending at group_end[g] */
static inline struct dr_grad_sink dr_sink_forward_groups(const double *dir, int n_groups, const int64_t *group_end)
{
    return (struct dr_grad_sink){.dir = dir, .n_groups = n_groups, .group_end = group_end};
}

/* Slot's forward group (0 without groups). */
static inline int dr_sink_group(const struct dr_grad_sink *k, int64_t slot)
{
    int g = 0;
    while (g + 1 < k->n_groups && slot >= k->group_end[g])
        g++;
    return g;
}

static inline void dr_sink_add(struct dr_grad_sink *k, int64_t slot, double v)
{
    if (k->dir)
        k->forward[3 * dr_sink_group(k, slot) + k->channel] += k->dir[slot] * v;
    else {
        if (k->exact)
            dr_exact_add(k->exact, slot, v);
        else if (k->touched && !k->touched[slot / DR_MASK_SPAN])
            /* The first entry written in its mask word's span (4 KiB), all
             * +0 until now (the mask's contract): set without being read.
             * A sparse vector's pages are mapped only when first touched,
             * and += touched them by reading: the kernel mapped its shared
             * zero page, and the write that followed copied it and shot
             * the old mapping down on every other CPU (an interrupt each),
             * a fifth of a 2k texture's gradient time on two threads.
             * (0.0 + v: the bits += gave, -0 included.) */
            k->grad[slot] = 0.0 + v;
        else
            k->grad[slot] += v;
        if (k->touched)
            dr_mask_mark(k->touched, slot);
    }
}

/* Adds v = (v0, v1, v2) to three consecutive slots (a colour parameter). */
static inline void dr_sink_add3(struct dr_grad_sink *k, int64_t slot, dr_vec3 v)
{
    dr_sink_add(k, slot + 0, v.x);
    dr_sink_add(k, slot + 1, v.y);
    dr_sink_add(k, slot + 2, v.z);
}

#endif
