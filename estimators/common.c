#include "common.h"

#include <stdlib.h>
#include <string.h>

#include "bigalloc.h"
#include "camera8.h"
#include "clock.h"
#include "error.h"
#include "medium_grad.h"
#include "path_deriv.h"   /* dr_path_material_dparams */
#include "parallel.h"
#include "sampler8.h"
#include "zero_blocks.h"

/* Scalar problems up to this size sum each chunk locally first. */
#define CHUNK_LOCAL_MAX 4096

/* Cross mode under the sobol sampler (dr_est_cross_adjoint): a pixel's
 * samples of even and of odd index are two Sobol sequences, each scrambled
 * on its own (this salt gives the odd half's seed), so that each half is
 * independent of the other. */
#define CROSS_HALF_SALT 0x8f1bbcdc5a827999ULL

static bool sobol_halves(const struct dr_grad_problem *p)
{
    return p->cross && p->sampler == DR_SAMPLER_SOBOL;
}

/* How many of spp samples are in half g (g = index mod 2). */
static int half_count(int spp, int g)
{
    return (spp + 1 - g) / 2;
}

/* Thread's pixel start for `pixel`, made anew when it holds another. Under
 * the sobol cross primal a pixel's samples of even and of odd index are two
 * sequences (dr_est_cross_adjoint), the odd one with a seed of its own. */
static const struct dr_est_pixel_start *pixel_start(struct dr_est_base *b, int thread, int64_t pixel)
{
    struct dr_est_pixel_start *ps = &b->thr[thread].start;
    if (ps->valid && ps->pixel == pixel)
        return ps;
    const struct dr_grad_problem *p = b->p;
    /* film.h: the frame pixel keys the random numbers, the filter draws the offset */
    const uint64_t frame_pixel = dr_film_pixel(&p->film, p->width, pixel, &ps->x, &ps->y);
    if (sobol_halves(p)) {
        dr_sampler_pixel_init(&ps->half[0], DR_SAMPLER_SOBOL, p->seed, frame_pixel, half_count(p->spp, 0));
        dr_sampler_pixel_init(&ps->half[1], DR_SAMPLER_SOBOL, dr_hash64(p->seed ^ CROSS_HALF_SALT), frame_pixel,
                              half_count(p->spp, 1));
    } else {
        dr_sampler_pixel_init(&ps->half[0], p->sampler, p->seed, frame_pixel, p->spp);
    }
    ps->valid = true, ps->pixel = pixel;
    return ps;
}

void dr_est_camera_ray(struct dr_est_base *b, int thread, int64_t pixel, int sample, struct dr_sampler *smp,
                       dr_vec3 *o, dr_vec3 *d)
{
    const struct dr_est_pixel_start *ps = pixel_start(b, thread, pixel);
    /* sobol cross primal: the sample's half, index sample / 2 in it */
    const bool halves = sobol_halves(b->p);
    const struct dr_sampler_pixel *sp = &ps->half[halves ? sample & 1 : 0];
    dr_sampler_pixel_sample(sp, (uint64_t)(halves ? sample >> 1 : sample), smp);
    double u, v, fx, fy;
    dr_sampler_pixel_first2(sp, smp, &u, &v);
    dr_film_sample(&b->p->film.filter, ps->x, ps->y, u, v, &fx, &fy);
    dr_camera_ray(&b->view, fx, fy, o, d);
}

void dr_est_camera_rays8(struct dr_est_base *b, int thread, const int64_t pixel[8], const int sample[8],
                         struct dr_sampler smp[8], dr_vec3 o[8], dr_vec3 d[8])
{
    /* each lane's pixel start: the thread's own where all eight share a
     * pixel (the walks' usual case), else copies, as pixel_start keeps one */
    struct dr_est_pixel_start own[8];
    const struct dr_est_pixel_start *ps[8];
    bool one_pixel = true;
    for (int l = 1; l < 8; l++)
        one_pixel &= pixel[l] == pixel[0];
    const struct dr_est_pixel_start *shared = one_pixel ? pixel_start(b, thread, pixel[0]) : NULL;
    for (int l = 0, n_own = 0; l < 8; l++) {
        if (shared)
            ps[l] = shared;
        else if (l > 0 && pixel[l] == pixel[l - 1])
            ps[l] = ps[l - 1];
        else
            own[n_own] = *pixel_start(b, thread, pixel[l]), ps[l] = &own[n_own++];
    }
    const bool halves = sobol_halves(b->p);
    const struct dr_sampler_pixel *sp[8];
    uint64_t index[8];
    for (int l = 0; l < 8; l++) {
        sp[l] = &ps[l]->half[halves ? sample[l] & 1 : 0];
        index[l] = (uint64_t)(halves ? sample[l] >> 1 : sample[l]);
    }
    dr_f8 u, v, x, y;
    dr_sampler_pixel_first2_8(sp, index, smp, &u, &v);
    for (int l = 0; l < 8; l++)
        x[l] = ps[l]->x, y[l] = ps[l]->y;
    dr_f8 fx = x + u, fy = y + v;   /* dr_film_sample's box */
    const struct dr_filter *f = &b->p->film.filter;
    if (f->kind != DR_FILTER_BOX)
        for (int l = 0; l < 8; l++) {   /* (clang takes no address of a vector's element) */
            double sx, sy;
            dr_film_sample(f, ps[l]->x, ps[l]->y, u[l], v[l], &sx, &sy);
            fx[l] = sx;
            fy[l] = sy;
        }
    dr_v3x8 o8, d8;
    dr_camera_ray8(&b->view, fx, fy, &o8, &d8);
    for (int l = 0; l < 8; l++)
        o[l] = dr_v3x8_get(&o8, l), d[l] = dr_v3x8_get(&d8, l);
}

/* ------------------------------------------------------------ accumulators */

/* What accum_init allocated (never the caller's vectors: grad[0], image,
 * nor the scratch's). */
static void accum_free(struct dr_est_accum *a)
{
    if (!a->scratch)
        dr_exact_sum_destroy(a->exact);
    a->exact = NULL;
    for (int t = 0; t < DR_MAX_THREADS; t++) {
        if (t > 0 && !a->scratch)
            free(a->grad[t]);
        free(a->chunk[t]);
        a->grad[t] = a->chunk[t] = NULL;
    }
    memset(a->image, 0, sizeof a->image);
}

static double *accum_alloc(struct dr_est_accum *a, size_t n)
{
    a->bytes += n * sizeof(double);
    return dr_calloc_big(n, sizeof(double));   /* texture gradients: 100 MB a 2k texture */
}

/* Thread t's gradient vector of n entries, zeroed: the scratch's, cleared,
 * where it holds one of that size (estimator.h: no fresh pages), else a
 * new one, kept there when there is a scratch; sparse: one whose untouched
 * pages stay out of memory (bigalloc.h), for a vector with a block mask
 * (every pass then touches only the blocks the sinks wrote). */
static double *accum_thread_vector(struct dr_est_accum *a, int t, size_t n, bool sparse)
{
    struct dr_est_scratch *s = a->scratch;
    if (!s)
        return accum_alloc(a, n);
    a->bytes += n * sizeof(double);
    bool kept;
    double *v = dr_big_vector_keep(&s->grad[t], &s->len[t], (int64_t)n, sparse, &kept);
    if (kept && s->dirty[t]) {   /* (not dirty: the last run's sum cleared it, and its mask) */
        dr_parallel_zero(v, (int64_t)n, a->threads);
        if (s->touched[t])
            memset(s->touched[t], 0, sizeof(uint64_t) * (size_t)dr_mask_words((int64_t)n));
    }
    if (!kept) {   /* (a new vector: a new mask, made when asked for) */
        free(s->touched[t]);
        s->touched[t] = NULL;
    }
    s->dirty[t] = v != NULL;   /* (this run writes it) */
    return v;
}

/* Thread t's block mask over its vector of n entries (the scratch's, all
 * clear: accum_thread_vector). */
static uint64_t *accum_thread_mask(struct dr_est_accum *a, int t, int64_t n)
{
    struct dr_est_scratch *s = a->scratch;
    if (!s->touched[t])
        s->touched[t] = calloc((size_t)dr_mask_words(n), sizeof(uint64_t));
    a->bytes += sizeof(uint64_t) * (size_t)dr_mask_words(n);
    return s->touched[t];
}

/* The shared exact sum of n entries, zeroed: the scratch's if it has one of
 * that size, as accum_thread_vector (sparse: one whose untouched pages
 * stay out of memory, for a sum read through block masks, which clear it
 * as they read it). */
static struct dr_exact_sum *accum_exact(struct dr_est_accum *a, int64_t n, bool sparse)
{
    struct dr_est_scratch *s = a->scratch;
    a->bytes += dr_exact_sum_bytes(n);
    if (!s)
        return dr_exact_sum_create(n);
    if (s->exact && s->exact_len == n) {
        if (s->exact_dirty) {
            dr_exact_sum_clear(s->exact);
            for (int t = 0; t < DR_MAX_THREADS; t++)   /* (a failed run's marks with it) */
                if (s->touched[t])
                    memset(s->touched[t], 0, sizeof(uint64_t) * (size_t)dr_mask_words(n + 1));
        }
        s->exact_dirty = true;   /* (this run writes it) */
        return s->exact;
    }
    dr_exact_sum_destroy(s->exact);
    for (int t = 0; t < DR_MAX_THREADS; t++) {   /* (masks of another size: made anew) */
        free(s->touched[t]);
        s->touched[t] = NULL;
    }
    s->exact = sparse ? dr_exact_sum_create_sparse(n) : dr_exact_sum_create(n);
    s->exact_len = s->exact ? n : 0;
    s->exact_dirty = s->exact != NULL;
    return s->exact;
}

void dr_est_scratch_free(struct dr_est_scratch *s)
{
    if (!s)
        return;
    for (int t = 0; t < DR_MAX_THREADS; t++) {
        free(s->grad[t]);
        free(s->touched[t]);
    }
    dr_exact_sum_destroy(s->exact);
    memset(s, 0, sizeof *s);
}

bool dr_estimator_shared_sums(int threads, int64_t total)
{
    return threads >= 4 && total >= DR_SHARED_SUMS_MIN;
}

bool dr_estimator_consumes(const struct dr_grad_problem *p)
{
    return p->consumer && p->scratch && dr_est_sampling_run(p) != DR_SAMPLING_MIS;
}

/* Where the threads' sums go; out and d_image are the caller's outputs
 * (zeroed here).
 *  - Reverse mode: thread 0 sums straight into `out`, the others into
 *    their own vectors, added to it in thread order by accum_sum: a texture
 *    parameter costs (threads - 1) vectors of its size here, not threads.
 *    With a consumer (estimator.h) thread 0 has its own too, and the sums
 *    go to the consumer instead of `out`.
 *    From four threads on a large vector is one shared exact sum instead
 *    (exact_sum.h: 17 bytes an entry, not 8 a thread).
 *  - Forward mode: every thread writes d_image itself. A pixel's samples are
 *    all taken by one thread (prb hands out pixel ranges, the tape whole
 *    pixels per worker), so no two threads add to the same value, and each
 *    value is its pixel's samples summed in order: the bits per-thread
 *    images summed gave, for any thread count, in one image.
 *  - mis: nothing (its samples go to the mis accumulator). */
static int accum_init(struct dr_est_accum *a, const struct dr_grad_problem *p, int forward, bool mis, double *out,
                      double *const *d_image)
{
    memset(a, 0, sizeof *a);
    a->scratch = forward || mis ? NULL : p->scratch;
    a->threads = dr_thread_count(p->threads);
    a->total = p->params->total;
    if (mis)
        return 0;
    for (int g = 0; g < forward; g++) {   /* (forward: the number of images) */
        memset(d_image[g], 0, sizeof(double) * (size_t)p->width * (size_t)p->height * 3);
        a->image[g] = d_image[g];
    }
    if (forward)
        return 0;
    /* thread 0 sums into the caller's vector, or with a consumer into the
     * scratch's first, as the others into theirs; a consumer's run too big
     * for chunks marks what each thread adds to (accum_thread_mask) */
    a->consumer = p->consumer && a->scratch ? p->consumer : NULL;
    const bool masked = a->consumer && a->total > CHUNK_LOCAL_MAX;   /* (below: chunks, no masks) */
    const bool sparse = masked && !a->scratch->many_runs;   /* (masked: a scratch's) */
    if (dr_estimator_shared_sums(a->threads, a->total)) {
        if (!(a->exact = accum_exact(a, a->total, sparse)))
            return DR_ERR_NOMEM;
        for (int t = 0; masked && t < a->threads; t++)
            if (!(a->touched[t] = accum_thread_mask(a, t, a->total + 1)))
                goto nomem;
        return 0;
    }
    if (!a->consumer) {
        dr_parallel_zero(out, a->total, a->threads);
        a->grad[0] = out;
    }
    for (int t = 0; t < a->threads; t++) {
        if ((t > 0 || a->consumer) && !(a->grad[t] = accum_thread_vector(a, t, (size_t)a->total + 1, sparse)))
            goto nomem;
        if (a->total <= CHUNK_LOCAL_MAX && !(a->chunk[t] = accum_alloc(a, (size_t)a->total + 1)))
            goto nomem;
        /* a consumer's vectors too big for chunks: each with the mask of
         * the blocks its paths reached, so that the sums read only those */
        if (masked && !(a->touched[t] = accum_thread_mask(a, t, a->total + 1)))
            goto nomem;
    }
    return 0;
nomem:
    accum_free(a);
    dr_set_error("out of memory for the gradient buffers");
    return DR_ERR_NOMEM;
}

#define SUM_PIECE 1024
/* out[k] = grad[0][i0 + k] + grad[1][i0 + k] + ... + 0.0 for k < n, in that
 * order entry by entry, thread by thread over the piece so that each loop
 * is one vector add (entry by entry over the threads, with the vectors'
 * pointers reloaded each time, it ran one add at a time). out may be
 * grad[0] + i0 itself. */
static void sum_piece(const struct dr_est_accum *a, int64_t i0, int64_t n, double *out)
{
    if (out != a->grad[0] + i0)
        memcpy(out, a->grad[0] + i0, sizeof(double) * (size_t)n);
    for (int t = 1; t < a->threads; t++) {
        const double *restrict g = a->grad[t] + i0;
        double *restrict o = out;
        for (int64_t k = 0; k < n; k++)
            o[k] += g[k];
    }
    for (int64_t k = 0; k < n; k++)
        out[k] += 0.0;
}

/* accum_sum's entries [begin, end): each entry's threads added in thread
 * order, then +0.0 (the same operations, and bits, as one pass per
 * thread), a piece at a time. */
static void sum_threads(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct dr_est_accum *a = ctx;
    for (int64_t i0 = begin; i0 < end; i0 += SUM_PIECE) {   /* (pieces: cleared while in the cache) */
        const int64_t n = end - i0 < SUM_PIECE ? end - i0 : SUM_PIECE;
        sum_piece(a, i0, n, a->grad[0] + i0);
        for (int t = 1; a->scratch && t < a->threads; t++)   /* (the scratch's vectors: for the next run) */
            dr_clear_touched(a->grad[t] + i0, n);
    }
}

/* The same sums for a consumer (accum_init: every thread's vector the
 * scratch's), a piece at a time through a buffer in the cache, each
 * vector cleared once read (its lines that held only zeros left clean:
 * zero_blocks.h). */
static void consume_threads(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct dr_est_accum *a = ctx;
    double piece[SUM_PIECE];
    for (int64_t i0 = begin; i0 < end; i0 += SUM_PIECE) {
        const int64_t n = end - i0 < SUM_PIECE ? end - i0 : SUM_PIECE;
        sum_piece(a, i0, n, piece);
        for (int t = 0; t < a->threads; t++)
            dr_clear_touched(a->grad[t] + i0, n);
        a->consumer->take(a->consumer->ctx, i0, i0 + n, piece, NULL);
    }
}

#define PIECE_WORDS (SUM_PIECE / DR_MASK_SPAN)
/* The piece of [i0, end) a masked sum takes next: its length in *n, and in
 * all[w] the threads' marks of its mask words (the blocks of the piece any
 * thread added to; the piece's first word is i0 / DR_MASK_SPAN). Returns
 * how many words it has. */
static int piece_marks(const struct dr_est_accum *a, int64_t i0, int64_t end, int64_t *n,
                       uint64_t all[PIECE_WORDS])
{
    *n = end - i0 < SUM_PIECE ? end - i0 : SUM_PIECE;
    const int64_t w0 = i0 / DR_MASK_SPAN;
    const int words = (int)dr_mask_words(*n);
    for (int w = 0; w < words; w++) {
        all[w] = 0;
        for (int t = 0; t < a->threads; t++)
            all[w] |= a->touched[t][w0 + w];
    }
    return words;
}

/* The threads' marks of those words cleared (their blocks were read). */
static void clear_piece_marks(const struct dr_est_accum *a, int64_t i0, int words)
{
    for (int t = 0; t < a->threads; t++)
        memset(&a->touched[t][i0 / DR_MASK_SPAN], 0, sizeof(uint64_t) * (size_t)words);
}

/* consume_threads where the threads' vectors have block masks (accum_init):
 * a piece's marked blocks only (the union of the threads' masks), each
 * summed as sum_piece sums it; each thread's marked blocks cleared and its
 * mask words with them; the consumer gets the union. Pieces begin at
 * multiples of SUM_PIECE (dr_parallel_elements' ranges do), so a mask word
 * is this piece's alone. */
static void consume_marked(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct dr_est_accum *a = ctx;
    double piece[SUM_PIECE];
    for (int64_t i0 = begin; i0 < end; i0 += SUM_PIECE) {
        int64_t n;
        uint64_t all[PIECE_WORDS];
        const int words = piece_marks(a, i0, end, &n, all);
        const int64_t w0 = i0 / DR_MASK_SPAN;
        for (int w = 0; w < words; w++)
            for (uint64_t bits = all[w]; bits; bits &= bits - 1) {
                const int64_t k = (int64_t)w * DR_MASK_SPAN + __builtin_ctzll(bits) * DR_ZERO_BLOCK;
                const int64_t m = n - k < DR_ZERO_BLOCK ? n - k : DR_ZERO_BLOCK;
                sum_piece(a, i0 + k, m, piece + k);
                for (int t = 0; t < a->threads; t++)
                    if (a->touched[t][w0 + w] >> (k / DR_ZERO_BLOCK % 64) & 1)
                        memset(a->grad[t] + i0 + k, 0, sizeof(double) * (size_t)m);
            }
        clear_piece_marks(a, i0, words);
        a->consumer->take(a->consumer->ctx, i0, i0 + n, piece, all);
    }
}

/* consume_marked for the shared exact sum: a piece's blocks marked by any
 * thread read and cleared (dr_exact_sum_take: the bits dr_exact_sum_read
 * gives; the unmarked blocks are zero, +0 read), the marks cleared. */
static void consume_exact_marked(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct dr_est_accum *a = ctx;
    double piece[SUM_PIECE];
    for (int64_t i0 = begin; i0 < end; i0 += SUM_PIECE) {
        int64_t n;
        uint64_t all[PIECE_WORDS];
        const int words = piece_marks(a, i0, end, &n, all);
        clear_piece_marks(a, i0, words);
        for (int64_t k = dr_mask_next(all, NULL, 0, n); k < n;) {
            const int64_t j = dr_mask_run_end(all, NULL, k, n);
            dr_exact_sum_take(a->exact, i0 + k, i0 + j, piece + k);
            k = dr_mask_next(all, NULL, j, n);
        }
        a->consumer->take(a->consumer->ctx, i0, i0 + n, piece, all);
    }
}

/* The threads' sums into grad (thread 0 summed there already: the others
 * added in thread order), to the consumer, or into d_image (written in
 * place). Adding +0.0 at the end gives every entry the bits the former
 * 0 + g0 + g1 + ... gave (a -0 sum became +0). */
static void accum_sum(const struct dr_est_accum *a, const struct dr_grad_problem *p, double *grad)
{
    if (a->consumer && a->exact) {
        dr_parallel_elements(a->total, a->threads, consume_exact_marked, (void *)a);
        a->scratch->exact_dirty = false;   /* (cleared as read) */
    } else if (a->consumer || (grad && !a->exact)) {
        dr_parallel_elements(a->total, a->threads,
                             a->touched[0] ? consume_marked : a->consumer ? consume_threads : sum_threads, (void *)a);
        for (int t = a->consumer ? 0 : 1; a->scratch && t < a->threads; t++)
            a->scratch->dirty[t] = false;   /* (cleared as read) */
    } else if (grad && a->exact) {
        dr_exact_sum_read(a->exact, grad);   /* NaN where a contribution was out of its range (exact_sum.h) */
    }
    for (int g = 0; g < DR_FORWARD_MAX && a->image[g]; g++)
        for (size_t i = 0, n = (size_t)p->width * (size_t)p->height * 3; i < n; i++)
            a->image[g][i] += 0.0;
}

/* ------------------------------------------------------------ per sample */

struct dr_grad_sink dr_est_sink_begin(struct dr_est_base *b, int thread)
{
    if (b->dir)
        return dr_sink_forward_groups(b->dir, b->n_groups, b->group_end);
    struct dr_est_accum *a = &b->acc;
    if (a->exact)
        return dr_sink_exact(a->exact, a->touched[thread]);
    if (!a->chunk[thread])
        return dr_sink_reverse_marked(a->grad[thread], a->touched[thread]);
    memset(a->chunk[thread], 0, sizeof(double) * (size_t)a->total);
    return dr_sink_reverse(a->chunk[thread]);
}

void dr_est_sink_end(struct dr_est_base *b, int thread)
{
    struct dr_est_accum *a = &b->acc;
    if (b->dir || !a->chunk[thread])
        return;
    double *g = a->grad[thread], *c = a->chunk[thread];
    for (int64_t i = 0; i < a->total; i++)
        g[i] += c[i];
}

bool dr_est_sample_adjoint(const struct dr_est_base *b, int64_t pixel, dr_vec3 *adj)
{
    if (b->dir) {
        *adj = dr_v3s(1.0);
        return true;
    }
    const float *a = b->adjoint + 3 * pixel;
    *adj = dr_scale(dr_v3(a[0], a[1], a[2]), 1.0 / b->p->spp);
    return !dr_is_black(*adj);
}

void dr_est_cross_pixel(const struct dr_est_base *b, int64_t pixel, const struct dr_cross_sum *sum)
{
    double *img = b->p->cross->image + 3 * pixel;
    for (int c = 0; c < 3; c++)
        img[c] = dr_v3_get(sum->all, c) / b->p->spp;
}

dr_vec3 dr_est_cross_adjoint(const struct dr_est_base *b, int64_t pixel, const struct dr_cross_sum *sum, int sample,
                             dr_vec3 L)
{
    const struct dr_cross_loss *x = b->p->cross;
    const int spp = b->p->spp;
    const size_t values = (size_t)b->p->width * (size_t)b->p->height * 3;
    const float *target = x->target + 3 * pixel;
    /* the mean of the samples independent of this one: the other half's
     * (sobol: dr_est_camera_ray), or all the others (independent numbers:
     * leave one out) */
    const int h = sample & 1;
    const bool halves = sobol_halves(b->p);
    const dr_vec3 others_sum = halves ? sum->half[1 - h] : dr_sub(sum->all, L);
    const int n_others = halves ? half_count(spp, 1 - h) : spp - 1;
    dr_vec3 adj;
    for (int c = 0; c < 3; c++) {
        double others = dr_v3_get(others_sum, c) / n_others;
        dr_v3_set(&adj, c, d_loss_value(x->loss, others, target[c], values, x->scale) / spp);
    }
    return adj;
}

void dr_est_sample_done(struct dr_est_base *b, int64_t pixel, struct dr_grad_sink *sink)
{
    if (!b->dir)
        return;
    const double inv_spp = 1.0 / b->p->spp;
    for (int g = 0; g < b->n_groups; g++) {
        double *out = b->acc.image[g] + 3 * pixel;   /* this thread's pixel (accum_init) */
        for (int c = 0; c < 3; c++) {
            out[c] += sink->forward[3 * g + c] * inv_spp;
            sink->forward[3 * g + c] = 0.0;
        }
    }
}

/* ------------------------------------------------------------------- run */

enum dr_sampling dr_est_sampling_run(const struct dr_grad_problem *p)
{
    /* attached and mis differ from detached only through a moving sampling map */
    if ((p->sampling == DR_SAMPLING_ATTACHED || p->sampling == DR_SAMPLING_MIS) &&
        !dr_path_params_enter_sampling(p->scene, p->params))
        return DR_SAMPLING_DETACHED;
    /* derivative sampling adds work only at vertices with a BSDF parameter
     * it samples for (derivative-roughness: a roughness) */
    if (dr_sampling_is_derivative(p->sampling)) {
        const unsigned want = dr_sampling_deriv_params(p->sampling);
        bool any = false;
        for (int m = 0; p->params && m < p->params->n_materials; m++)
            any |= (dr_path_material_dparams(p->scene, p->params, m) & want) != 0;
        if (!any)
            return DR_SAMPLING_DETACHED;
    }
    return p->sampling;
}

int dr_estimator_check(const struct dr_estimator_ops *e, const struct dr_grad_problem *p)
{
    if (!dr_estimator_supports(e, p->sampling)) {
        dr_set_error("estimator '%s' does not implement %s sampling", e->name, dr_sampling_name(p->sampling));
        return DR_ERR_ARG;
    }
    const enum dr_sampling run = dr_est_sampling_run(p);
    if (run == DR_SAMPLING_DETACHED)
        return 0;
    /* The attached adjoints (path_attached.c; mis uses them too) know
     * surfaces only: a path through a medium would silently lose its moving
     * terms. (Derivative sampling's radiance walks are the medium walker's
     * there, path_deriv.h.) */
    if ((run == DR_SAMPLING_ATTACHED || run == DR_SAMPLING_MIS) && (p->scene->effects & DR_FX_MEDIA)) {
        dr_set_error("%s sampling does not handle participating media yet (the scene has %d medi%s); use "
                     "--sampling detached",
                     dr_sampling_name(p->sampling), p->scene->n_media, p->scene->n_media == 1 ? "um" : "a");
        return DR_ERR_ARG;
    }
    /* Nor thin glass, whose stop probability depends on the ray's direction
     * (coverage.h): a moving direction moves it, and a stochastic decision
     * has no derivative for the walker to follow. */
    if (!dr_sampling_is_derivative(run) && (p->scene->effects & DR_FX_THIN_TRANSMISSION)) {
        const char *name = "";
        for (int m = 0; m < p->scene->n_materials && !name[0]; m++)
            if (p->scene->materials[m].thin_ior > 0.0)
                name = p->scene->materials[m].name;
        dr_set_error("%s sampling does not differentiate through thin-walled glass (material '%s'); use --sampling "
                     "detached", dr_sampling_name(p->sampling), name);
        return DR_ERR_ARG;
    }
    /* Nor the normal map's dependence on the moving hit point (normal_map.h);
     * derivative sampling keeps the hit points fixed, like detached. */
    if (!dr_sampling_is_derivative(run) && (p->scene->effects & DR_FX_NORMAL_MAPS)) {
        const char *name = "";
        for (int m = 0; m < p->scene->n_materials && !name[0]; m++)
            if (p->scene->materials[m].normal_tex.texture >= 0)
                name = p->scene->materials[m].name;
        dr_set_error("%s sampling does not differentiate normal maps (material '%s' has a normalTexture); "
                     "use --sampling detached",
                     dr_sampling_name(p->sampling), name);
        return DR_ERR_ARG;
    }
    /* Nor KHR_materials_specular's textures, whose texels change the BSDF
     * as the hit point moves (the specular inputs have no adjoint:
     * d_material_eval_uv would drop that term, silently) */
    if (!dr_sampling_is_derivative(run)) {
        for (int m = 0; m < p->scene->n_materials; m++) {
            const struct dr_material *mat = &p->scene->materials[m];
            if (mat->specular_tex.texture < 0 && mat->specular_color_tex.texture < 0)
                continue;
            dr_set_error("%s sampling does not differentiate specular textures (material '%s' has "
                         "KHR_materials_specular textures); use --sampling detached",
                         dr_sampling_name(p->sampling), mat->name);
            return DR_ERR_ARG;
        }
    }
    /* (an anisotropic frame turns with the moving hit point:
     * d_anisotropy_frame differentiates it, anisotropy.h) */
    return 0;
}

/* mis: one weight per parameter in reverse mode, one for the direction in
 * forward mode (mis.h). */
static int mis_init(struct dr_est_base *b)
{
    const struct dr_grad_problem *p = b->p;
    const struct dr_param_set *ps = p->params;
    const int64_t pixels = (int64_t)p->width * p->height;
    if (b->dir) {
        int64_t off = 0, n = pixels * 3;
        return dr_mis_init(&b->mis_acc, b->acc.threads, n, 1, &off, &n, pixels, true);
    }
    int64_t *seg = malloc(sizeof(int64_t) * 2 * (size_t)(ps->n > 0 ? ps->n : 1));
    if (!seg) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    for (int k = 0; k < ps->n; k++) {
        seg[k] = ps->params[k].offset;
        seg[ps->n + k] = ps->params[k].size;
    }
    int rc = dr_mis_init(&b->mis_acc, b->acc.threads, ps->total, ps->n, seg, seg + ps->n, pixels, false);
    free(seg);
    return rc;
}

/* mis: the groups' estimates combined into grad or d_image, the weights to
 * p->mis_weights (forward mode: the direction's weight for every parameter). */
static void mis_finish(struct dr_est_base *b, double *grad, double *d_image)
{
    const struct dr_grad_problem *p = b->p;
    double wd = 1.0;
    dr_mis_combine(&b->mis_acc, d_image ? d_image : grad, d_image ? &wd : p->mis_weights, p->mis_history);
    for (int k = 0; d_image && p->mis_weights && k < p->params->n; k++)
        p->mis_weights[k] = wd;
}

void dr_est_mis_sinks(struct dr_est_base *b, int thread, int64_t pixel, struct dr_grad_sink *det,
                      struct dr_grad_sink *att)
{
    struct dr_mis_accum *m = &b->mis_acc;
    if (b->dir) {
        *det = dr_sink_forward(b->dir);
        *att = dr_sink_forward(b->dir);
    } else if (m->scratch[thread]) {   /* per-sample statistics: the sample apart first */
        *det = dr_sink_reverse(m->scratch[thread]);
        *att = dr_sink_reverse(m->scratch[thread] + m->stride);
    } else {
        int g = dr_mis_group(pixel);
        *det = dr_sink_reverse(dr_mis_slot(m, thread, g, DR_MIS_DETACHED));
        *att = dr_sink_reverse(dr_mis_slot(m, thread, g, DR_MIS_ATTACHED));
    }
}

void dr_est_mis_sample_done(struct dr_est_base *b, int thread, int64_t pixel, struct dr_grad_sink *det,
                            struct dr_grad_sink *att)
{
    struct dr_mis_accum *m = &b->mis_acc;
    if (!b->dir) {
        if (m->scratch[thread])
            dr_mis_add_scratch(m, thread, pixel);
        return;
    }
    const double inv_spp = 1.0 / b->p->spp;
    double d[3], a[3];
    for (int c = 0; c < 3; c++) {
        d[c] = det->forward[c] * inv_spp;
        a[c] = att->forward[c] * inv_spp;
        det->forward[c] = att->forward[c] = 0.0;
    }
    dr_mis_add(m, thread, pixel, 3 * pixel, 3, d, a);
}

/* What a run asks before any work: the cross primal's conditions, the
 * film, the viewpoint. 0 or an error code (after dr_set_error). */
static int check_problem(const struct dr_grad_problem *p, const double *dir)
{
    if (p->cross && (dir || p->spp < 2 || p->sampler == DR_SAMPLER_STRATIFIED || !p->cross->target ||
                     !p->cross->image)) {
        dr_set_error("the cross primal is for reverse mode with at least 2 independent or sobol samples per "
                     "pixel (spp %d, sampler %d)", p->spp, (int)p->sampler);
        return DR_ERR_ARG;
    }
    if (dr_film_check(&p->film, p->width, p->height) != 0)
        return DR_ERR_ARG;
    return dr_scene_check_viewpoint(p->scene, p->camera);   /* (backface.h) */
}

/* The run's statistics, summed over the worker threads. */
static void run_stats(const struct dr_est_base *b, struct dr_grad_stats *st)
{
    *st = (struct dr_grad_stats){.seconds = dr_clock_seconds() - b->t0, .threads = b->acc.threads,
                                 .memory_bytes = b->acc.bytes + b->mis_acc.bytes + b->record_bytes + b->scratch_bytes,
                                 .record_bytes = b->record_bytes, .stages = b->popts.stages,
                                 .sampling_run = dr_est_sampling_run(b->p), .n_media_gain = b->n_media_gain};
    memcpy(st->media_gain, b->media_gain, sizeof st->media_gain);
    for (int t = 0; t < b->acc.threads; t++) {
        dr_ray_counts_add(&st->rays, &b->thr[t].rays);
        st->invalid_samples += b->thr[t].invalid;
    }
}

/* Random numbers of the media pilot (a seed of its own, whatever the run's). */
#define MEDIA_PILOT_SEED 0x6d656469615f706cULL

/* DRT's pilot (medium_grad.h): primal paths spread evenly over the rendered
 * pixels, each walked for at most DR_MEDIUM_PILOT_VERTICES vertices, their
 * stretches through media tallied into t (one per medium). Its rays count
 * as the run's. */
static void media_pilot(struct dr_est_base *b, struct dr_medium_tally *t)
{
    const struct dr_grad_problem *p = b->p;
    struct dr_medium_record rec;   /* (the walker records the media a flight crosses) */
    const int64_t pixels = (int64_t)p->width * p->height;
    for (int k = 0; k < DR_MEDIUM_PILOT_PATHS; k++) {
        int x, y;
        const uint64_t frame_pixel = dr_film_pixel(&p->film, p->width, k * pixels / DR_MEDIUM_PILOT_PATHS, &x, &y);
        struct dr_sampler smp;
        dr_sampler_init(&smp, MEDIA_PILOT_SEED, frame_pixel, (uint64_t)k);
        double u = dr_sampler_next(&smp), v = dr_sampler_next(&smp), fx, fy;
        dr_film_sample(&p->film.filter, x, y, u, v, &fx, &fy);
        dr_vec3 o, d;
        dr_camera_ray(&b->view, fx, fy, &o, &d);
        struct dr_path_state st;
        struct dr_path_vertex vx = {.mrec = &rec};
        dr_path_start(&st, o, d);
        bool more = true;
        for (int n = 0; more && n < DR_MEDIUM_PILOT_VERTICES; n++) {
            more = dr_path_step(p->scene, &b->popts, &st, &smp, &vx, &b->thr[0].rays);
            dr_medium_tally_vertex(&vx, t);
        }
    }
}

/* What the pilot's choice depends on (dr_media_plan): a hash. */
static uint64_t media_plan_key(const struct dr_est_base *b)
{
    const struct dr_grad_problem *p = b->p;
    const struct dr_scene *s = p->scene;
    uint64_t h = dr_hash64((uint64_t)(uintptr_t)s ^ dr_hash64((uint64_t)(uintptr_t)p->camera));
    const int64_t ints[] = {p->width, p->height, p->max_depth, p->rr_depth, b->popts.stages, b->popts.sky_uniform,
                            p->film.frame_w, p->film.frame_h, p->film.x0, p->film.y0, p->film.filter.kind,
                            s->n_media};
    for (size_t i = 0; i < sizeof ints / sizeof ints[0]; i++)
        h = dr_hash64(h ^ (uint64_t)ints[i]);
    uint64_t bits;
    memcpy(&bits, &p->film.filter.stddev, sizeof bits);
    return dr_media_values_hash(s, dr_hash64(h ^ bits));
}

/* The pilot into plan (its arrays made for the scene's media). */
static int media_plan_fill(struct dr_est_base *b, struct dr_media_plan *plan, uint64_t key)
{
    const struct dr_scene *s = b->p->scene;
    dr_media_plan_free(plan);
    plan->tally = calloc((size_t)s->n_media, sizeof *plan->tally);
    plan->collision_gain = calloc((size_t)s->n_media, 1);
    if (!plan->tally || !plan->collision_gain) {
        dr_media_plan_free(plan);
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    media_pilot(b, plan->tally);
    dr_medium_gain_decide(s, plan->tally, plan->collision_gain);
    plan->n_media = s->n_media;
    plan->key = key;
    plan->valid = true;
    return 0;
}

/* Where DRT takes each medium's sigma_t gain: the pilot where a thin medium
 * asks for it (or the caller's plan from an earlier run, where it still
 * applies; else *own, which the caller frees), its choice pointed to by
 * b->popts; and every differentiated medium's choice into b->media_gain for
 * the statistics. */
static int plan_media_gain(struct dr_est_base *b, struct dr_media_plan *own)
{
    const struct dr_scene *s = b->p->scene;
    const struct dr_media_plan *use = NULL;
    if (dr_medium_gain_pilot_wanted(s, &b->popts)) {
        struct dr_media_plan *plan = b->p->media_plan ? b->p->media_plan : own;
        const uint64_t key = media_plan_key(b);
        if (!(plan->valid && plan->key == key && plan->n_media == s->n_media)) {
            int rc = media_plan_fill(b, plan, key);
            if (rc != 0)
                return rc;
        }
        use = plan;
        b->popts.collision_gain = plan->collision_gain;
    }
    b->n_media_gain = dr_medium_gain_choices(s, &b->popts, use ? use->tally : NULL, b->media_gain,
                                             DR_STATS_MEDIA_GAIN);
    return 0;
}

/* A run: reverse mode (adjoint, grad) or forward (dir, n_groups images
 * d_image[g], slot groups ending at group_end: grad_sink.h). */
static int run(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const float *adjoint,
               const double *dir, int n_groups, const int64_t *group_end, double *grad, double *const *d_image,
               struct dr_grad_stats *st)
{
    int rc = dr_estimator_check(e, p);
    if (rc == 0)
        rc = check_problem(p, dir);
    if (rc == 0 && dir && (n_groups < 1 || n_groups > DR_FORWARD_MAX ||
                           (n_groups > 1 && (!group_end || dr_est_sampling_run(p) == DR_SAMPLING_MIS)))) {
        dr_set_error("forward mode: %d images in one pass (1 to %d; mis sampling: 1)", n_groups, DR_FORWARD_MAX);
        rc = DR_ERR_ARG;
    }
    if (rc != 0)
        return rc;
    struct dr_est_base *b = calloc(1, e->job_size);
    if (!b) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    }
    b->t0 = dr_clock_seconds();
    b->p = p;
    b->view = dr_camera_view(p->camera, dr_film_frame_w(&p->film, p->width), dr_film_frame_h(&p->film, p->height));
    /* mis samples a constant sky over the sphere: its roughness gradients on
     * a sky-lit metal had 2.6-3.4 x less variance so than with the mixture
     * the other runs use (lights.h's dr_sky_pdf), and no more elsewhere
     * (issue 11's note of 2026-12-02: less light-sampling density leaves
     * more weight to the BSDF's samples, whose attached derivative is the
     * quiet one) */
    const enum dr_sampling run = dr_est_sampling_run(p);
    b->popts = (struct dr_path_opts){.max_depth = p->max_depth, .rr_depth = p->rr_depth,
                                     .stages = dr_path_plan(p->scene, p->params), .params = p->params,
                                     .deriv_params = dr_sampling_deriv_params(run),
                                     .medium_grad = p->medium_grad, .sky_uniform = run == DR_SAMPLING_MIS};
    b->adjoint = adjoint;
    b->dir = dir;
    b->n_groups = dir ? n_groups : 0;
    b->group_end = group_end;
    b->mis = run == DR_SAMPLING_MIS;
    struct dr_media_plan own_plan = {0};
    rc = plan_media_gain(b, &own_plan);
    if (rc == 0)
        rc = accum_init(&b->acc, p, b->n_groups, b->mis, grad, d_image);
    if (rc == 0 && b->mis)
        rc = mis_init(b);
    if (rc == 0) {
        rc = e->run(b);
        if (b->mis)
            mis_finish(b, grad, d_image ? d_image[0] : NULL);
        else
            accum_sum(&b->acc, p, grad);
    }
    if (p->mis_weights && p->sampling == DR_SAMPLING_MIS && !b->mis)   /* ran detached */
        for (int k = 0; k < p->params->n; k++)
            p->mis_weights[k] = 1.0;
    if (st)
        run_stats(b, st);
    if (e->release)
        e->release(b);
    accum_free(&b->acc);
    dr_mis_free(&b->mis_acc);
    dr_media_plan_free(&own_plan);
    free(b);
    return rc;
}

int dr_estimator_forward(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const double *dir,
                         double *d_image, struct dr_grad_stats *st)
{
    return run(e, p, NULL, dir, 1, NULL, NULL, &d_image, st);
}

int dr_forward_per_pass(enum dr_sampling sampling)
{
    return sampling == DR_SAMPLING_MIS ? 1 : DR_FORWARD_MAX;
}

void dr_forward_param_groups(const struct dr_param_set *ps, int first, int count, double *dir, int64_t *group_end)
{
    memset(dir, 0, sizeof(double) * (size_t)ps->total);
    for (int k = 0; k < count; k++) {
        const struct dr_param *p = &ps->params[first + k];
        for (int64_t i = 0; i < p->size; i++)
            dir[p->offset + i] = 1.0;
        group_end[k] = p->offset + p->size;
    }
}

int dr_estimator_forward_groups(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const double *dir,
                                int n_groups, const int64_t *group_end, double *const *d_images,
                                struct dr_grad_stats *st)
{
    return run(e, p, NULL, dir, n_groups, group_end, NULL, d_images, st);
}

int dr_estimator_backward(const struct dr_estimator_ops *e, const struct dr_grad_problem *p, const float *adjoint,
                          double *grad, struct dr_grad_stats *st)
{
    return run(e, p, adjoint, NULL, 0, NULL, grad, NULL, st);
}
