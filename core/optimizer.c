#include "optimizer.h"

#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"
#include "parallel.h"
#include "zero_blocks.h"

double dr_param_default_lr(const struct dr_param *p, const double *values)
{
    switch (p->kind) {
    case DR_PARAM_BASE_COLOR:
    case DR_PARAM_METALLIC:
    case DR_PARAM_ROUGHNESS:
    case DR_PARAM_IMAGE:
    case DR_PARAM_MEDIUM_ALBEDO:
    case DR_PARAM_MEDIUM_G: return 0.02;
    case DR_PARAM_MEDIUM_DENSITY: return 0.05;   /* voxels: densities of order 1, often starting at 0 */
    default: {
        double mean = 0.0;
        for (int64_t i = 0; i < p->size; i++)
            mean += fabs(values[i]);
        mean /= (double)(p->size > 0 ? p->size : 1);
        return 0.05 * (mean > 0.2 ? mean : 0.2);
    }
    }
}

void dr_adam_destroy(struct dr_adam *a)
{
    if (!a)
        return;
    free(a->m);
    free(a->v);
    free(a->offset);
    free(a->size);
    free(a->lr);
    free(a->lo);
    free(a->hi);
    free(a);
}

struct dr_adam *dr_adam_create(const struct dr_param_set *ps, const double *theta, double lr_override)
{
    struct dr_adam *a = calloc(1, sizeof *a);
    if (!a)
        goto nomem;
    a->n = ps->total;
    a->threads = 1;
    a->beta1 = 0.9;
    a->beta2 = 0.999;
    a->eps = 1e-8;
    size_t n = (size_t)(a->n > 0 ? a->n : 1), np = (size_t)(ps->n > 0 ? ps->n : 1);
    a->n_params = ps->n;
    a->m = calloc(n, sizeof(double));
    a->v = calloc(n, sizeof(double));
    a->offset = malloc(np * sizeof(int64_t));
    a->size = malloc(np * sizeof(int64_t));
    a->lr = malloc(np * sizeof(double));
    a->lo = malloc(np * sizeof(double));
    a->hi = malloc(np * sizeof(double));
    if (!a->m || !a->v || !a->offset || !a->size || !a->lr || !a->lo || !a->hi)
        goto nomem;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        a->offset[k] = p->offset;
        a->size[k] = p->size;
        dr_param_range(p, &a->lo[k], &a->hi[k]);
        a->lr[k] = lr_override > 0.0 ? lr_override : dr_param_default_lr(p, theta + p->offset);
    }
    return a;
nomem:
    dr_set_error("out of memory");
    dr_adam_destroy(a);
    return NULL;
}

int dr_adam_param_of(const struct dr_adam *a, int64_t i)
{
    for (int k = 0; k < a->n_params; k++)
        if (i >= a->offset[k] && i < a->offset[k] + a->size[k])
            return k;
    return -1;
}

/* One parameter's scalars. restrict: m, v, theta and grad never overlap, so
 * GCC may vectorise (the same operations in the same order: the same bits). */
static int64_t adam_span(const struct dr_adam *a, int64_t n, double *restrict m, double *restrict v,
                         double *restrict theta, const double *restrict grad, double lr, double lo, double hi,
                         double c1, double c2)
{
    int64_t bad = 0;
    const double b1 = a->beta1, b2 = a->beta2, eps = a->eps;
#define ADAM_ENTRY(i)                                                   \
    do {                                                                \
        double g = grad[i];                                             \
        bool finite = isfinite(g);                                      \
        bad += !finite;                                                 \
        g = finite ? g : 0.0;                                           \
        m[i] = b1 * m[i] + (1.0 - b1) * g;                              \
        v[i] = b2 * v[i] + (1.0 - b2) * g * g;                          \
        double step = lr * (m[i] / c1) / (sqrt(v[i] / c2) + eps);       \
        double x = theta[i] - step;                                     \
        theta[i] = x < lo ? lo : (x > hi ? hi : x);                     \
    } while (0)
    int64_t i0 = 0;
    for (; i0 + DR_ZERO_BLOCK <= n; i0 += DR_ZERO_BLOCK) {
        /* an entry no gradient has reached yet (m, v and its gradient +0)
         * inside its bounds does not move: m and v stay +0, the step is
         * lr * +0 / (+0 + eps) = +0 (lr, eps > 0), theta - +0 = theta; most
         * of a texture's, in the first iterations at a preview size
         * (zero_blocks.h) */
        if (dr_block_zero(grad + i0) && dr_block_zero(m + i0) && dr_block_zero(v + i0) && lr > 0.0 && eps > 0.0) {
            bool inside = true;
            for (int64_t i = i0; i < i0 + DR_ZERO_BLOCK; i++)
                inside &= theta[i] >= lo && theta[i] <= hi;
            if (inside)
                continue;
        }
        for (int64_t i = i0; i < i0 + DR_ZERO_BLOCK; i++)
            ADAM_ENTRY(i);
    }
    for (int64_t i = i0; i < n; i++)
        ADAM_ENTRY(i);
#undef ADAM_ENTRY
    return bad;
}

/* One parameter's step on scalars [begin, end) of it (dr_parallel_elements). */
struct adam_step {
    const struct dr_adam *a;
    int k;
    double *theta, c1, c2;
    const double *grad;
    _Atomic int64_t bad;
};

static void adam_range(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    struct adam_step *x = ctx;
    const struct dr_adam *a = x->a;
    const int64_t o = a->offset[x->k] + begin;
    x->bad += adam_span(a, end - begin, a->m + o, a->v + o, x->theta + o, x->grad + o, a->lr[x->k], a->lo[x->k],
                        a->hi[x->k], x->c1, x->c2);
}

int64_t dr_adam_step(struct dr_adam *a, double *theta, const double *grad)
{
    a->t++;
    struct adam_step x = {.a = a, .theta = theta, .grad = grad, .c1 = 1.0 - pow(a->beta1, (double)a->t),
                          .c2 = 1.0 - pow(a->beta2, (double)a->t)};
    atomic_init(&x.bad, 0);
    for (x.k = 0; x.k < a->n_params; x.k++)
        dr_parallel_elements(a->size[x.k], a->threads, adam_range, &x);
    return atomic_load(&x.bad);
}

/* ---- checkpoints ---- */

/* x exactly, as a C99 hexadecimal floating constant (what "%a" prints;
 * strtod and scanf's %lf read it back bit for bit): [-]0x1.<hex>p<exp>, or
 * 0x0.<hex>p-1022 below the normal range. Written by hand because printf's
 * %.17g took 0.3 us a value (a 2048x2048x3 texture parameter's checkpoint,
 * value, m and v: 38 M doubles, took 11 s) and its %a 0.14 us (5.5 s); this
 * takes a few ns. Non-finite values
 * (which a checkpoint never holds: the reader refuses them) go through
 * printf. Returns the end of the text (at most 24 characters). */
static char *put_double(char *s, double x)
{
    if (!isfinite(x))
        return s + sprintf(s, "%.17g", x);
    uint64_t b;
    memcpy(&b, &x, sizeof b);
    if (b >> 63)
        *s++ = '-';
    const int biased = (int)((b >> 52) & 0x7ff);
    uint64_t man = b & ((UINT64_C(1) << 52) - 1);
    if (biased == 0 && man == 0) {
        memcpy(s, "0x0p+0", 6);
        return s + 6;
    }
    memcpy(s, biased ? "0x1" : "0x0", 3);
    s += 3;
    if (man) {
        *s++ = '.';
        for (int k = 48; k >= 0 && man; k -= 4) {   /* 13 hex digits, trailing zeros left out */
            *s++ = "0123456789abcdef"[(man >> k) & 0xf];
            man &= (UINT64_C(1) << k) - 1;
        }
    }
    int e = biased ? biased - 1023 : -1022;
    *s++ = 'p';
    *s++ = e < 0 ? '-' : '+';
    e = abs(e);
    char digits[4];
    int n = 0;
    do {
        digits[n++] = (char)('0' + e % 10);
        e /= 10;
    } while (e);
    while (n)
        *s++ = digits[--n];
    return s;
}

static void write_doubles(FILE *f, const char *key, const double *v, int64_t n)
{
    char buf[1 << 16];
    size_t len = (size_t)snprintf(buf, sizeof buf, "%s", key);
    for (int64_t i = 0; i < n; i++) {
        if (len > sizeof buf - 32) {
            fwrite(buf, 1, len, f);
            len = 0;
        }
        buf[len++] = ' ';
        len = (size_t)(put_double(buf + len, v[i]) - buf);
    }
    buf[len++] = '\n';
    fwrite(buf, 1, len, f);
}

/* Version 2 stores a parameter of more than CHECKPOINT_TEXT_MAX values (a
 * texture) as raw little-endian doubles after a line "binary le64": its
 * values, then m, then v. In text (hexadecimal, about 20 characters a
 * value) a 2k texture's checkpoint was 769 MB and took 2.7-5 s to write
 * and flush every --checkpoint-every iterations; raw it is 302 MB, 0.3-1.1
 * s. Scalars and colours stay text, readable. Version 1 files (all text)
 * still read. */
#define CHECKPOINT_TEXT_MAX 64
#define CHECKPOINT_LITTLE_ENDIAN (__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__)

static bool binary_section(const struct dr_param *p)
{
    return CHECKPOINT_LITTLE_ENDIAN && p->size > CHECKPOINT_TEXT_MAX;
}

static void write_binary(FILE *f, const double *value, const double *m, const double *v, int64_t n)
{
    fputs("binary le64\n", f);
    fwrite(value, sizeof(double), (size_t)n, f);
    fwrite(m, sizeof(double), (size_t)n, f);
    fwrite(v, sizeof(double), (size_t)n, f);
    fputc('\n', f);
}

int dr_checkpoint_write(const char *path, const char *scene_path, const struct dr_param_set *ps,
                        const double *theta, const struct dr_adam *a, int64_t iteration)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "w");
    if (!f) {
        dr_set_error("%s: cannot write checkpoint: %s", path, strerror(errno));
        return DR_ERR_IO;
    }
    fprintf(f, "drender-checkpoint 2\nscene %s\niteration %lld\nadam %lld %.17g %.17g %.17g\n", scene_path,
            (long long)iteration, (long long)a->t, a->beta1, a->beta2, a->eps);
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        fprintf(f, "param %s %lld\n", p->name, (long long)p->size);
        if (binary_section(p)) {
            write_binary(f, theta + p->offset, a->m + p->offset, a->v + p->offset, p->size);
            continue;
        }
        write_doubles(f, "value", theta + p->offset, p->size);
        write_doubles(f, "m", a->m + p->offset, p->size);
        write_doubles(f, "v", a->v + p->offset, p->size);
    }
    fputs("end\n", f);
    bool ok = fflush(f) == 0 && fsync(fileno(f)) == 0;
    ok = (fclose(f) == 0) && ok;
    if (!ok || rename(tmp, path) != 0) {
        dr_set_error("%s: cannot write checkpoint: %s", path, strerror(errno));
        unlink(tmp);
        return DR_ERR_IO;
    }
    return 0;
}

/* The next whitespace-separated word of f into w (at most size - 1
 * characters; false at the end or for a longer word). */
static bool read_word(FILE *f, char *w, size_t size)
{
    int c;
    while ((c = getc_unlocked(f)) != EOF && (c == ' ' || c == '\n' || c == '\t' || c == '\r'))
        ;
    size_t n = 0;
    for (; c != EOF && c != ' ' && c != '\n' && c != '\t' && c != '\r'; c = getc_unlocked(f)) {
        if (n + 1 >= size)
            return false;
        w[n++] = (char)c;
    }
    w[n] = '\0';
    return n > 0;
}

/* n numbers: hexadecimal (put_double) or decimal (checkpoints written
 * before it), each read whole by strtod. */
static bool read_numbers(FILE *f, double *v, int64_t n)
{
    char word[64];
    for (int64_t i = 0; i < n; i++) {
        char *end;
        if (!read_word(f, word, sizeof word))
            return false;
        v[i] = strtod(word, &end);
        if (*end != '\0')
            return false;
    }
    return true;
}

/* key, then n numbers. */
static bool read_doubles(FILE *f, const char *key, double *v, int64_t n)
{
    char word[16];
    return read_word(f, word, sizeof word) && strcmp(word, key) == 0 && read_numbers(f, v, n);
}

/* One parameter's values, m and v: text ("value" and n numbers, then m and
 * v), or in version 2 a "binary le64" line and the raw doubles
 * (write_binary). */
static bool read_section(FILE *f, int version, double *value, double *m, double *v, int64_t n)
{
    char word[16];
    if (!read_word(f, word, sizeof word))
        return false;
    if (version >= 2 && strcmp(word, "binary") == 0) {
        if (!CHECKPOINT_LITTLE_ENDIAN || !read_word(f, word, sizeof word) || strcmp(word, "le64") != 0)
            return false;   /* (read_word took the newline after it) */
        return fread(value, sizeof(double), (size_t)n, f) == (size_t)n &&
               fread(m, sizeof(double), (size_t)n, f) == (size_t)n &&
               fread(v, sizeof(double), (size_t)n, f) == (size_t)n && getc_unlocked(f) == '\n';
    }
    return strcmp(word, "value") == 0 && read_numbers(f, value, n) && read_doubles(f, "m", m, n) &&
           read_doubles(f, "v", v, n);
}

/* A well-formed file can still hold a state no run reaches: a negative
 * iteration (optimize indexes its history with it), Adam constants out of
 * range, non-finite or out-of-range values, a negative second moment.
 * 0, or DR_ERR_FORMAT after a message naming the file and the value. */
static int check_state(const char *path, const struct dr_param_set *ps, const double *theta, const struct dr_adam *a,
                       long long it, long long t)
{
    if (it < 0 || t < 0 || !(a->beta1 >= 0.0 && a->beta1 < 1.0) || !(a->beta2 >= 0.0 && a->beta2 < 1.0) ||
        !(a->eps > 0.0 && isfinite(a->eps))) {
        dr_set_error("%s: not a valid drender checkpoint: iteration %lld, adam %lld %g %g %g out of range", path, it,
                     t, a->beta1, a->beta2, a->eps);
        return DR_ERR_FORMAT;
    }
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        for (int64_t i = p->offset; i < p->offset + p->size; i++)
            if (!(theta[i] >= a->lo[k] && theta[i] <= a->hi[k]) || !isfinite(a->m[i]) || !isfinite(a->v[i]) ||
                a->v[i] < 0.0) {
                dr_set_error("%s: not a valid drender checkpoint: %s value %lld is %g (range [%g, %g]), m %g, v %g",
                             path, p->name, (long long)(i - p->offset), theta[i], a->lo[k], a->hi[k], a->m[i],
                             a->v[i]);
                return DR_ERR_FORMAT;
            }
    }
    return 0;
}

int dr_checkpoint_read(const char *path, const struct dr_param_set *ps, double *theta, struct dr_adam *a,
                       int64_t *iteration)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        dr_set_error("%s: cannot read checkpoint: %s", path, strerror(errno));
        return DR_ERR_IO;
    }
    char line[8192], name[DR_PARAM_NAME_MAX + 1];
    long long it = 0, t = 0, size = 0;
    int version = 0;
    bool ok = fscanf(f, "drender-checkpoint %d\n", &version) == 1 && (version == 1 || version == 2) &&
              fgets(line, sizeof line, f) &&
              strncmp(line, "scene ", 6) == 0 && fscanf(f, "iteration %lld\n", &it) == 1 &&
              fscanf(f, "adam %lld %lf %lf %lf\n", &t, &a->beta1, &a->beta2, &a->eps) == 4;
    for (int k = 0; ok && k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        char word[16];
        if (fscanf(f, " %15s", word) == 1 && strcmp(word, "end") == 0) {
            dr_set_error("%s: checkpoint holds fewer parameters than the run asks for: resume with the same --param "
                         "list",
                         path);
            fclose(f);
            return DR_ERR_ARG;
        }
        if (strcmp(word, "param") != 0 || fscanf(f, " %160s %lld", name, &size) != 2) {
            ok = false;
            break;
        }
        if (strcmp(name, p->name) != 0 || size != p->size) {
            dr_set_error("%s: checkpoint holds %s (%lld values) where the run asks for %s (%lld): resume with the "
                         "same --param list",
                         path, name, size, p->name, (long long)p->size);
            fclose(f);
            return DR_ERR_ARG;
        }
        ok = read_section(f, version, theta + p->offset, a->m + p->offset, a->v + p->offset, p->size);
    }
    char end[16];
    ok = ok && fscanf(f, "%15s", end) == 1;
    if (ok && strcmp(end, "param") == 0) {
        dr_set_error("%s: checkpoint holds more parameters than the run asks for: resume with the same --param list",
                     path);
        fclose(f);
        return DR_ERR_ARG;
    }
    ok = ok && strcmp(end, "end") == 0;
    fclose(f);
    if (!ok) {
        dr_set_error("%s: not a valid drender checkpoint (or truncated)", path);
        return DR_ERR_FORMAT;
    }
    int rc = check_state(path, ps, theta, a, it, t);
    if (rc != 0)
        return rc;
    a->t = t;
    *iteration = it;
    return 0;
}
