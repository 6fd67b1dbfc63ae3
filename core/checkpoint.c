/* Optimize's checkpoints: parameters and Adam's state, restored bit for
 * bit (optimizer.h documents the calls). */
#include "optimizer.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"
#include "zero_blocks.h"

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

/* A parameter of more than CHECKPOINT_TEXT_MAX values (a texture) is
 * stored in binary after a line naming the encoding; scalars and colours
 * stay text, readable.
 *
 * Version 2 wrote "binary le64" and the raw little-endian doubles: its
 * values, then m, then v (in hexadecimal text, about 20 characters a value,
 * a 2k texture's checkpoint had been 769 MB and 2.7-5 s to write; raw it is
 * 302 MB). Version 3 writes "binary packed": the same three arrays as runs
 * (pack_array). An optimisation at a preview resolution touches a few per
 * cent of a texture's entries an iteration, so m and v are mostly +0 and
 * the values no step moved are still the texture's floats: a 2k texture's
 * checkpoint after 20 iterations at 64 x 64, 16 spp is 139 MB (a third of
 * its entries moved), written and flushed in about half the time
 * (optimize's 20 iterations with two checkpoints 4.8 -> 3.0 s in all).
 * Versions 1 and 2 still read. */
#define CHECKPOINT_VERSION 3
#define CHECKPOINT_TEXT_MAX 64
#define CHECKPOINT_LITTLE_ENDIAN (__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__)

static bool binary_section(const struct dr_param *p)
{
    return CHECKPOINT_LITTLE_ENDIAN && p->size > CHECKPOINT_TEXT_MAX;
}

/* A packed array is a sequence of runs, each a little-endian 64-bit header
 * (kind << 62 | count, count >= 1) and count words: PACK_ZERO, count +0
 * doubles and no words; PACK_F32, count doubles each exactly a float, as
 * the floats; PACK_F64, count raw doubles. The runs' counts add up to the
 * array's length. Runs are made of blocks of PACK_BLOCK entries (the last
 * may be shorter) so that a header costs at most an eighth of its run. */
enum { PACK_ZERO = 0, PACK_F32 = 1, PACK_F64 = 2 };
#define PACK_BLOCK 8
#define PACK_COUNT_MASK ((UINT64_C(1) << 62) - 1)

/* The kind of v[0..n): PACK_ZERO if every word is +0 (as bits: -0 is a
 * float, not a zero), else PACK_F32 if every double survives a round trip
 * through float to the bit, else PACK_F64. (Whole blocks: pack_kind_block.) */
static int pack_kind(const double *v, int64_t n)
{
    uint64_t any = 0;
    bool f32 = true;
    for (int64_t i = 0; i < n; i++) {
        const double back = (double)(float)v[i];
        uint64_t w, b;
        memcpy(&w, &v[i], sizeof w);
        memcpy(&b, &back, sizeof b);
        any |= w;
        f32 &= w == b;
    }
    return any == 0 ? PACK_ZERO : (f32 ? PACK_F32 : PACK_F64);
}

/* pack_kind of a whole block, as vectors: one conversion each way for
 * eight doubles (the scalar loop converted them one at a time, a fifth of
 * a 2k texture's checkpoint). The same rounding as (double)(float). */
typedef float pack_f8 __attribute__((vector_size(8 * sizeof(float))));
typedef double pack_d8 __attribute__((vector_size(8 * sizeof(double))));
typedef uint64_t pack_u8 __attribute__((vector_size(8 * sizeof(uint64_t))));
static inline int pack_kind_block(const double *v)
{
    pack_d8 x;
    memcpy(&x, v, sizeof x);
    const pack_d8 back = __builtin_convertvector(__builtin_convertvector(x, pack_f8), pack_d8);
    pack_u8 w, b;
    memcpy(&w, &x, sizeof w);
    memcpy(&b, &back, sizeof b);
    const pack_u8 differ = w ^ b;
    uint64_t any = 0, moved = 0;
    for (int i = 0; i < PACK_BLOCK; i++)
        any |= w[i], moved |= differ[i];
    return any == 0 ? PACK_ZERO : (moved == 0 ? PACK_F32 : PACK_F64);
}

/* The runs' bytes, gathered into big writes: a texture's moved entries
 * make runs of a block or two, and a write call each cost a quarter of a
 * checkpoint (in _IO_fwrite). */
struct packer {
    FILE *f;
    size_t n;
    unsigned char buf[1 << 16];
};

static void pack_flush(struct packer *p)
{
    if (p->n)
        fwrite(p->buf, 1, p->n, p->f);
    p->n = 0;
}

/* Room for bytes (at most sizeof buf) at the end of the buffer. */
static unsigned char *pack_room(struct packer *p, size_t bytes)
{
    if (p->n + bytes > sizeof p->buf)
        pack_flush(p);
    unsigned char *at = p->buf + p->n;
    p->n += bytes;
    return at;
}

static void write_run(struct packer *p, int kind, const double *v, int64_t n)
{
    const uint64_t head = (uint64_t)kind << 62 | (uint64_t)n;
    memcpy(pack_room(p, sizeof head), &head, sizeof head);
    const size_t size = kind == PACK_F64 ? sizeof(double) : kind == PACK_F32 ? sizeof(float) : 0;
    const int64_t piece = (int64_t)(sizeof p->buf / sizeof(double));
    for (int64_t i = 0; size && i < n; i += piece) {
        const int64_t m = n - i < piece ? n - i : piece;
        unsigned char *at = pack_room(p, size * (size_t)m);
        if (kind == PACK_F64) {
            memcpy(at, v + i, sizeof(double) * (size_t)m);
        } else {
            float x[1024];   /* (converted as vectors, then copied) */
            for (int64_t j0 = 0; j0 < m; j0 += 1024) {
                const int64_t mj = m - j0 < 1024 ? m - j0 : 1024;
                for (int64_t j = 0; j < mj; j++)
                    x[j] = (float)v[i + j0 + j];
                memcpy(at + sizeof(float) * (size_t)j0, x, sizeof(float) * (size_t)mj);
            }
        }
    }
}

/* Is every entry of global entries [i, i + n) in a block zeros leaves
 * clear (zero_blocks.h; n <= 8, so two blocks at most)? */
static bool unmarked(const uint64_t *zeros, int64_t i, int64_t n)
{
    return !dr_mask_test(zeros, i) && !dr_mask_test(zeros, i + n - 1);
}

/* v[0..n) as runs of whole blocks of one kind. zeros (NULL: none): a block
 * mask over the global entries (v[0] is entry `first`) whose clear blocks
 * are +0: not read, a run of PACK_ZERO as reading them would give. (Adam's
 * moments, mostly zeros: a read of a page nothing wrote maps the shared
 * zero page, and Adam's next write there would cost a copy-on-write fault
 * and a TLB shootdown, optimizer.c's adam_entry.) */
static void pack_array(struct packer *p, const double *v, int64_t n, const uint64_t *zeros, int64_t first)
{
    int64_t start = 0;
    int kind = -1;
    for (int64_t k = 0; k < n; k += PACK_BLOCK) {
        const int64_t len = n - k < PACK_BLOCK ? n - k : PACK_BLOCK;
        const int b = zeros && unmarked(zeros, first + k, len) ? PACK_ZERO
                      : len == PACK_BLOCK                      ? pack_kind_block(v + k)
                                                               : pack_kind(v + k, len);
        if (b != kind && kind >= 0) {
            write_run(p, kind, v + start, k - start);
            start = k;
        }
        kind = b;
    }
    if (kind >= 0)
        write_run(p, kind, v + start, n - start);
}

/* Parameter p's section; moments: Adam's mask of the blocks whose m and v
 * may not be +0, NULL where it is not known (optimizer.h). */
static void write_binary(FILE *f, const struct dr_param *p, const double *theta, const struct dr_adam *a,
                         const uint64_t *moments)
{
    fputs("binary packed\n", f);
    struct packer pk;   /* (64 KiB: on the stack of the thread that writes) */
    pk.f = f, pk.n = 0;
    pack_array(&pk, theta + p->offset, p->size, NULL, 0);
    pack_array(&pk, a->m + p->offset, p->size, moments, p->offset);
    pack_array(&pk, a->v + p->offset, p->size, moments, p->offset);
    pack_flush(&pk);
    fputc('\n', f);
}

/* The file's contents, written to f (not flushed). */
static void write_body(FILE *f, const char *scene_path, const struct dr_param_set *ps, const double *theta,
                       const struct dr_adam *a, int64_t iteration)
{
    fprintf(f, "drender-checkpoint %d\nscene %s\niteration %lld\nadam %lld %.17g %.17g %.17g\n", CHECKPOINT_VERSION,
            scene_path, (long long)iteration, (long long)a->t, a->beta1, a->beta2, a->eps);
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        fprintf(f, "param %s %lld\n", p->name, (long long)p->size);
        if (binary_section(p)) {
            write_binary(f, p, theta, a, dr_adam_moments(a));
            continue;
        }
        write_doubles(f, "value", theta + p->offset, p->size);
        write_doubles(f, "m", a->m + p->offset, p->size);
        write_doubles(f, "v", a->v + p->offset, p->size);
    }
    fputs("end\n", f);
}

/* The end of a write whose data f has flushed: on disk (fsync), closed,
 * renamed over the checkpoint. 0, or DR_ERR_IO with the message in why
 * (the temporary removed). */
static int finish_file(FILE *f, const char *tmp, const char *path, char *why, size_t size)
{
    bool ok = fsync(fileno(f)) == 0;
    int e = errno;
    if (fclose(f) != 0 && ok)
        ok = false, e = errno;
    if (ok && rename(tmp, path) != 0)
        ok = false, e = errno;
    if (ok)
        return 0;
    snprintf(why, size, "%s: cannot write checkpoint: %s", path, strerror(e));
    unlink(tmp);
    return DR_ERR_IO;
}

/* The contents written and flushed to tmp (opened here); NULL with the
 * error set, the temporary removed, if that fails (a full disk shows here,
 * not in the finisher). */
static FILE *write_flushed(const char *path, const char *tmp, const char *scene_path, const struct dr_param_set *ps,
                           const double *theta, const struct dr_adam *a, int64_t iteration)
{
    FILE *f = fopen(tmp, "w");
    if (!f) {
        dr_set_error("%s: cannot write checkpoint: %s", path, strerror(errno));
        return NULL;
    }
    write_body(f, scene_path, ps, theta, a, iteration);
    if (fflush(f) != 0 || ferror(f)) {
        dr_set_error("%s: cannot write checkpoint: %s", path, strerror(errno ? errno : EIO));
        fclose(f);
        unlink(tmp);
        return NULL;
    }
    return f;
}

int dr_checkpoint_write(const char *path, const char *scene_path, const struct dr_param_set *ps,
                        const double *theta, const struct dr_adam *a, int64_t iteration)
{
    char tmp[4096], why[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp%ld", path, (long)getpid());
    FILE *f = write_flushed(path, tmp, scene_path, ps, theta, a, iteration);
    if (!f)
        return DR_ERR_IO;
    int rc = finish_file(f, tmp, path, why, sizeof why);
    if (rc != 0)
        dr_set_error("%s", why);
    return rc;
}

static void *finisher_main(void *arg)
{
    struct dr_checkpoint_pending *p = arg;
    p->rc = finish_file(p->f, p->tmp, p->path, p->error, sizeof p->error);
    return NULL;
}

int dr_checkpoint_write_async(struct dr_checkpoint_pending *p, const char *path, const char *scene_path,
                              const struct dr_param_set *ps, const double *theta, const struct dr_adam *a,
                              int64_t iteration)
{
    int rc = dr_checkpoint_wait(p);   /* (the last one renamed first: checkpoints replace in order) */
    if (rc != 0)
        return rc;
    if (strlen(path) >= sizeof p->path - 32) {
        dr_set_error("%s: cannot write checkpoint: path too long", path);
        return DR_ERR_IO;
    }
    snprintf(p->path, sizeof p->path, "%s", path);
    snprintf(p->tmp, sizeof p->tmp, "%s.tmp%ld", path, (long)getpid());
    p->f = write_flushed(p->path, p->tmp, scene_path, ps, theta, a, iteration);
    if (!p->f)
        return DR_ERR_IO;
    p->rc = 0;
    /* the finisher blocks every signal (it inherits the mask it is created
     * with): SIGINT and SIGTERM go to the threads that stop the run, and
     * its fsync and close are never interrupted */
    sigset_t all, old;
    sigfillset(&all);
    pthread_sigmask(SIG_BLOCK, &all, &old);
    const bool started = pthread_create(&p->thread, NULL, finisher_main, p) == 0;
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    if (started) {
        p->running = true;
        return 0;
    }
    finisher_main(p);   /* (no thread: finished here) */
    if (p->rc != 0)
        dr_set_error("%s", p->error);
    return p->rc;
}

int dr_checkpoint_wait(struct dr_checkpoint_pending *p)
{
    if (!p->running)
        return 0;
    pthread_join(p->thread, NULL);
    p->running = false;
    if (p->rc != 0)
        dr_set_error("%s", p->error);
    return p->rc;
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

/* A packed array of n doubles (pack_array); false if it is cut short or
 * its runs do not add up to n exactly. */
static bool unpack_array(FILE *f, double *v, int64_t n)
{
    for (int64_t got = 0; got < n;) {
        uint64_t head;
        if (fread(&head, sizeof head, 1, f) != 1)
            return false;
        const int kind = (int)(head >> 62);
        const uint64_t count = head & PACK_COUNT_MASK;
        if (count == 0 || count > (uint64_t)(n - got))
            return false;
        double *out = v + got;
        got += (int64_t)count;
        if (kind == PACK_ZERO) {
            memset(out, 0, sizeof(double) * count);
        } else if (kind == PACK_F64) {
            if (fread(out, sizeof(double), count, f) != count)
                return false;
        } else if (kind == PACK_F32) {
            float buf[1024];
            for (uint64_t i = 0; i < count; i += 1024) {
                const size_t m = count - i < 1024 ? (size_t)(count - i) : 1024;
                if (fread(buf, sizeof(float), m, f) != m)
                    return false;
                for (size_t j = 0; j < m; j++)
                    out[i + j] = (double)buf[j];
            }
        } else {
            return false;
        }
    }
    return true;
}

/* One parameter's values, m and v: text ("value" and n numbers, then m and
 * v), or a line "binary le64" (version 2 on) or "binary packed" (version 3
 * on) and the three arrays (write_binary). */
static bool read_section(FILE *f, int version, double *value, double *m, double *v, int64_t n)
{
    char word[16];
    if (!read_word(f, word, sizeof word))
        return false;
    if (version >= 2 && strcmp(word, "binary") == 0) {
        if (!CHECKPOINT_LITTLE_ENDIAN || !read_word(f, word, sizeof word))
            return false;   /* (read_word took the newline after it) */
        if (strcmp(word, "le64") == 0)
            return fread(value, sizeof(double), (size_t)n, f) == (size_t)n &&
                   fread(m, sizeof(double), (size_t)n, f) == (size_t)n &&
                   fread(v, sizeof(double), (size_t)n, f) == (size_t)n && getc_unlocked(f) == '\n';
        return version >= 3 && strcmp(word, "packed") == 0 && unpack_array(f, value, n) && unpack_array(f, m, n) &&
               unpack_array(f, v, n) && getc_unlocked(f) == '\n';
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
    bool ok = fscanf(f, "drender-checkpoint %d\n", &version) == 1 && version >= 1 && version <= CHECKPOINT_VERSION &&
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
    a->moved_known = a->ranged = false, a->changed = NULL;   /* (new theta, m and v: optimizer.h) */
    *iteration = it;
    return 0;
}
