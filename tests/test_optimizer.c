/* Adam and checkpoints: Adam finds the minimum of a separable quadratic and
 * keeps every scalar inside its range; a checkpoint restores parameters and
 * optimizer state bit for bit, so a resumed run continues exactly (also for
 * zeros of either sign, subnormals and the extremes of the double range,
 * and from a checkpoint written in decimal, as drender did before); a
 * checkpoint for other parameters or a truncated one is refused. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "error.h"
#include "optimizer.h"
#include "scene_builder.h"
#include "test.h"

static struct dr_scene *scene(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.5, 0.5, 0.5));
    m.emissive_factor = dr_v3(1, 1, 1);
    m.emissive_strength = 4.0;
    sb_quad(&b, dr_v3(0, 0, 0), dr_v3(1, 0, 0), dr_v3(0, 1, 0), sb_material(&b, m));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    return s;
}

/* A checkpoint as drender wrote it before version 3, of theta, m and v at
 * iteration `it`: version 1 all text, every number printed with fmt
 * (" %.17g": decimal, as before 2026-11-27; " %a": hexadecimal); version 2
 * (from 2026-12-03) the same but for parameters of more than 64 values: a
 * line "binary le64" and the raw doubles (values, m, v). */
static void write_old(const char *path, int version, const struct dr_param_set *ps, const struct dr_adam *a, int it,
                      const double *theta, const double *m, const double *v, const char *fmt)
{
    FILE *f = fopen(path, "wb");
    if (!f)
        return;
    fprintf(f, "drender-checkpoint %d\nscene scene.gltf\niteration %d\nadam %d %.17g %.17g %.17g\n", version, it, it,
            a->beta1, a->beta2, a->eps);
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        fprintf(f, "param %s %lld\n", p->name, (long long)p->size);
        const double *vec[3] = {theta + p->offset, m + p->offset, v + p->offset};
        const char *key[3] = {"value", "m", "v"};
        const bool raw = version >= 2 && p->size > 64;
        if (raw)
            fputs("binary le64\n", f);
        for (int j = 0; j < 3; j++) {
            if (raw) {
                fwrite(vec[j], sizeof(double), (size_t)p->size, f);
                continue;
            }
            fputs(key[j], f);
            for (int64_t i = 0; i < p->size; i++)
                fprintf(f, fmt, vec[j][i]);
            fputc('\n', f);
        }
        if (raw)
            fputc('\n', f);
    }
    fputs("end\n", f);
    fclose(f);
}

/* n bytes at offset `at` of the file at path replaced by bytes. */
static void patch_file(const char *path, long at, const void *bytes, size_t n)
{
    FILE *f = fopen(path, "r+b");
    if (!f)
        return;
    fseek(f, at, SEEK_SET);
    fwrite(bytes, 1, n, f);
    fclose(f);
}

/* The checkpoint's numbers (hexadecimal, optimizer.c's put_double) read back
 * bit for bit at the edges of the double range; a decimal checkpoint (the
 * format before) reads as it did. */
static void edge_values(const struct dr_param_set *ps, const double *theta0, const char *path)
{
    struct dr_adam *a = dr_adam_create(ps, theta0, 0.0), *b = dr_adam_create(ps, theta0, 0.0);
    double theta[5] = {0.0, 4.9406564584124654e-324, 1.0 / 3.0, 0.5, fmin(1e300, a->hi[dr_adam_param_of(a, 4)])};
    const double m[5] = {-0.0, -4.9406564584124654e-324, DBL_MAX, -DBL_MIN / 3.0, -1.0 / 3.0};
    const double v[5] = {0.0, DBL_MIN, DBL_MAX, 0.1, 2.2250738585072009e-308 /* largest subnormal */};
    memcpy(a->m, m, sizeof m);
    memcpy(a->v, v, sizeof v);
    a->t = 7;
    double back[5];
    int64_t it = 0;
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 7) == 0, "edge write: %s", dr_last_error());
    CHECK(dr_checkpoint_read(path, ps, back, b, &it) == 0, "edge read: %s", dr_last_error());
    CHECK(memcmp(back, theta, sizeof back) == 0 && memcmp(b->m, m, sizeof m) == 0 && memcmp(b->v, v, sizeof v) == 0,
          "edge values not restored bit for bit");
    for (int i = 0; i < 5; i++)   /* say which, if any */
        CHECK(memcmp(&b->m[i], &m[i], sizeof(double)) == 0, "m[%d]: %a read back as %a", i, m[i], b->m[i]);
    /* the same state in decimal, as written before */
    write_old(path, 1, ps, a, 7, theta, m, v, " %.17g");
    memset(back, 0, sizeof back);
    CHECK(dr_checkpoint_read(path, ps, back, b, &it) == 0, "decimal read: %s", dr_last_error());
    CHECK(memcmp(back, theta, sizeof back) == 0 && memcmp(b->m, m, sizeof m) == 0 && memcmp(b->v, v, sizeof v) == 0,
          "a decimal checkpoint not read bit for bit");
    dr_adam_destroy(a);
    dr_adam_destroy(b);
}

/* A texture parameter (more values than the text limit): version 3 stores
 * it packed after "binary packed", beside a colour in text; with values no
 * float holds it is the raw doubles and little else; it reads back bit for
 * bit, the same state written all in text (version 1) or raw (version 2)
 * reads the same, and a file cut inside the binary values, or with the
 * binary block's end changed, is refused. */
/* A quad with a w x h colour texture; *ps: its base colour factor and its
 * texels (3 + w * h * 3 values), NULL if that cannot be had. */
static struct dr_scene *texture_scene(struct dr_param_set **ps, int w, int h)
{
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3(0.5, 0.5, 0.5));
    m.base_color_tex.texture = sb_texture(&b, sb_varied_image(w, h, 3, 2));
    sb_quad(&b, dr_v3(0, 0, 0), dr_v3(1, 0, 0), dr_v3(0, 1, 0), sb_material(&b, m));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    const char *ptrs[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor", "/images/0"};
    *ps = dr_param_set_create(s, ptrs, 2);
    return s;
}

static void texture_checkpoint(const char *path)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 32, 24);
    CHECK(ps && ps->total == 3 + 32 * 24 * 3, "texture param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const int64_t n = ps->total;
    double *theta = malloc(sizeof(double) * (size_t)n), *back = malloc(sizeof(double) * (size_t)n);
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0), *r = dr_adam_create(ps, theta, 0.0);
    for (int64_t i = 0; i < n; i++) {
        theta[i] = (double)(i % 97) / 97.0 + 1.0 / 3.0 * 1e-3;
        a->m[i] = i % 5 == 0 ? -0.0 : -1.0 / (double)(i + 3);
        a->v[i] = i % 7 == 0 ? 4.9406564584124654e-324 : 1.0 / (double)(i + 1);
    }
    a->moved_known = a->ranged = false;   /* (m and v set outside a step: their owner says so, optimizer.h) */
    a->t = 12;
    int64_t it = 0;
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 12) == 0, "texture write: %s", dr_last_error());
    FILE *f = fopen(path, "rb");
    char head[64] = {0};
    size_t got = f ? fread(head, 1, sizeof head - 1, f) : 0;
    long size2 = -1;
    if (f) {
        fseek(f, 0, SEEK_END);
        size2 = ftell(f);
        fclose(f);
    }
    CHECK(got > 0 && strncmp(head, "drender-checkpoint 3\n", 21) == 0, "version 3 header: %.21s", head);
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == 0, "texture read: %s", dr_last_error());
    CHECK(it == 12 && r->t == 12 && memcmp(back, theta, sizeof(double) * (size_t)n) == 0 &&
              memcmp(r->m, a->m, sizeof(double) * (size_t)n) == 0 && memcmp(r->v, a->v, sizeof(double) * (size_t)n) == 0,
          "texture checkpoint not restored bit for bit");
    /* doubles no float holds: 3 x 8 bytes a value and little else */
    CHECK(size2 > 24 * (n - 3) && size2 < 24 * (n - 3) + 1024, "texture checkpoint of %ld bytes for %lld values",
          size2, (long long)n);

    /* the same state all in text, as version 1 wrote it */
    write_old(path, 1, ps, a, 12, theta, a->m, a->v, " %a");
    memset(back, 0, sizeof(double) * (size_t)n);
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == 0 && memcmp(back, theta, sizeof(double) * (size_t)n) == 0 &&
              memcmp(r->v, a->v, sizeof(double) * (size_t)n) == 0,
          "a version 1 texture checkpoint: %s", dr_last_error());

    /* the same state raw, as version 2 wrote it */
    write_old(path, 2, ps, a, 12, theta, a->m, a->v, " %a");
    memset(back, 0, sizeof(double) * (size_t)n);
    memset(r->m, 0, sizeof(double) * (size_t)n);
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == 0 && memcmp(back, theta, sizeof(double) * (size_t)n) == 0 &&
              memcmp(r->m, a->m, sizeof(double) * (size_t)n) == 0 &&
              memcmp(r->v, a->v, sizeof(double) * (size_t)n) == 0,
          "a version 2 texture checkpoint: %s", dr_last_error());

    /* cut inside the binary values; the newline after them changed */
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 12) == 0, "rewrite: %s", dr_last_error());
    CHECK(truncate(path, size2 - 4000) == 0, "truncate");
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == DR_ERR_FORMAT, "a cut raw block was accepted");
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 12) == 0, "rewrite: %s", dr_last_error());
    patch_file(path, size2 - 5, "x", 1);   /* "\nend\n" ends the file: the binary block's newline */
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == DR_ERR_FORMAT, "a raw block without its newline was accepted");
    free(theta);
    free(back);
    dr_adam_destroy(a);
    dr_adam_destroy(r);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* A preview's state, packed (version 3): values that are floats, moments
 * +0 but for a few blocks. It reads back bit for bit, -0 and subnormals
 * included (a -0 is not a zero run's +0; a double subnormal is no float),
 * takes about a float a value, and a run that overruns the array or has no
 * kind is refused. The texture's 7 x 5 x 3 = 105 values end in a short
 * block. */
static void packed_checkpoint(const char *path)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 7, 5);
    CHECK(ps && ps->total == 3 + 105, "small texture param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const int64_t n = ps->total, n_tex = 105;
    double *theta = malloc(sizeof(double) * (size_t)n), *back = malloc(sizeof(double) * (size_t)n);
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0), *r = dr_adam_create(ps, theta, 0.0);
    for (int64_t i = 3; i < n; i++) {
        theta[i] = (double)((float)(i % 97) / 97.0f);
        a->m[i] = a->v[i] = 0.0;
    }
    theta[3 + 17] = 1.0 / 3.0;      /* no float: its block is doubles */
    theta[3 + 18] = -0.0;
    theta[3 + 104] = (double)1e-40f;   /* a float subnormal, in the short last block */
    for (int64_t i = 3 + 40; i < 3 + 48; i++)   /* a block of -0 moments */
        a->m[i] = -0.0;
    a->m[3 + 60] = -1.0 / 7.0;
    a->v[3 + 60] = 1.0 / 49.0;
    a->m[3 + 100] = 4.9406564584124654e-324;   /* in the short last block */
    a->v[3 + 100] = 4.9406564584124654e-324;
    a->moved_known = a->ranged = false;   /* (as above) */
    a->t = 3;
    int64_t it = 0;
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 3) == 0, "packed write: %s", dr_last_error());
    CHECK(dr_checkpoint_read(path, ps, back, r, &it) == 0, "packed read: %s", dr_last_error());
    CHECK(it == 3 && memcmp(back, theta, sizeof(double) * (size_t)n) == 0 &&
              memcmp(r->m, a->m, sizeof(double) * (size_t)n) == 0 && memcmp(r->v, a->v, sizeof(double) * (size_t)n) == 0,
          "packed checkpoint not restored bit for bit");
    for (int64_t i = 3; i < n; i++)   /* say which, if any */
        CHECK(memcmp(&back[i], &theta[i], 8) == 0 && memcmp(&r->m[i], &a->m[i], 8) == 0 &&
                  memcmp(&r->v[i], &a->v[i], 8) == 0,
              "entry %lld: value %a m %a v %a read back as %a %a %a", (long long)(i - 3), theta[i], a->m[i], a->v[i],
              back[i], r->m[i], r->v[i]);

    /* its size: the header, the colour's text, and the binary part: values
     * as floats but one block of doubles, moments as runs */
    FILE *f = fopen(path, "rb");
    char buf[8192];
    const size_t size = f ? fread(buf, 1, sizeof buf, f) : 0;
    if (f)
        fclose(f);
    const char *bin = memmem(buf, size, "binary packed\n", 14);
    CHECK(bin != NULL, "no packed section");
    if (bin) {
        const size_t body = size - (size_t)(bin + 14 - buf) - 5;   /* less "\nend\n" */
        /* values: runs of 2 float blocks, the double block, 11 float blocks
         * (81 entries); m: +0 x 40, the -0 block as floats, +0 x 8, a double
         * block, +0 x 32, a double block, +0 x 1; v: the same without the -0
         * block. 8 bytes a run's header. */
        const size_t values = 3 * 8 + 4 * 16 + 8 * 8 + 4 * 81, m = 7 * 8 + 4 * 8 + 2 * 8 * 8, v = 5 * 8 + 2 * 8 * 8;
        CHECK(body == values + m + v, "packed body of %zu bytes, expected %zu", body, values + m + v);

        /* a run longer than what is left of its array; a run of kind 3 */
        uint64_t head;
        const long at = (long)(bin + 14 - buf);
        memcpy(&head, bin + 14, 8);
        const uint64_t longer = (head >> 62) << 62 | (uint64_t)(n_tex + 1), bad_kind = (UINT64_C(3) << 62) | (head & 0xff);
        patch_file(path, at, &longer, 8);
        CHECK(dr_checkpoint_read(path, ps, back, r, &it) == DR_ERR_FORMAT, "a run past its array was accepted");
        patch_file(path, at, &bad_kind, 8);
        CHECK(dr_checkpoint_read(path, ps, back, r, &it) == DR_ERR_FORMAT, "a run of kind 3 was accepted");
    }
    free(theta);
    free(back);
    dr_adam_destroy(a);
    dr_adam_destroy(r);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Adam's formula, entry by entry, with nothing skipped: what dr_adam_step
 * must give to the bit (its blocks of untouched entries left alone:
 * zero_blocks.h). */
static int64_t adam_reference(const struct dr_adam *a, int64_t t, double *theta, double *m, double *v,
                              const double *grad)
{
    const double c1 = 1.0 - pow(a->beta1, (double)t), c2 = 1.0 - pow(a->beta2, (double)t);
    int64_t bad = 0;
    for (int k = 0; k < a->n_params; k++)
        for (int64_t i = a->offset[k]; i < a->offset[k] + a->size[k]; i++) {
            double g = grad[i];
            bad += !isfinite(g);
            g = isfinite(g) ? g : 0.0;
            m[i] = a->beta1 * m[i] + (1.0 - a->beta1) * g;
            v[i] = a->beta2 * v[i] + (1.0 - a->beta2) * g * g;
            double x = theta[i] - a->lr[k] * (m[i] / c1) / (sqrt(v[i] / c2) + a->eps);
            theta[i] = x < a->lo[k] ? a->lo[k] : (x > a->hi[k] ? a->hi[k] : x);
        }
    return bad;
}

/* A texture's step where most of the gradient is +0 (a preview's): the
 * same bits as the formula, with blocks of +0 entries, -0 gradients, a
 * NaN, entries whose moments are not yet zero, and untouched entries
 * outside their range (which the step clamps: they must not be skipped). */
static void sparse_adam_step(void)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 32, 24);
    CHECK(ps != NULL, "sparse adam: param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const size_t n = (size_t)ps->total;
    double *theta = malloc(sizeof(double) * n), *ref = malloc(sizeof(double) * n), *grad = calloc(n, sizeof(double));
    double *m = calloc(n, sizeof(double)), *v = calloc(n, sizeof(double));
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0);
    a->threads = 2;
    const int tex = dr_adam_param_of(a, 3);
    for (size_t i = 0; i < n; i++)
        theta[i] = (double)(i % 89) / 89.0;
    for (size_t i = 200; i < 216; i++)   /* untouched, out of range: clamped by the step */
        theta[i] = i % 2 ? a->hi[tex] + 0.25 : a->lo[tex] - 0.5;
    a->m[400] = m[400] = -0.0;   /* not +0 as bits: its block is stepped */
    memcpy(ref, theta, sizeof(double) * n);
    int64_t moved = 0;
    for (int64_t t = 1; t <= 3; t++) {
        memset(grad, 0, sizeof(double) * n);
        for (size_t i = 0; i < n; i += 37 + (size_t)t)   /* a sparse gradient */
            grad[i] = (double)(i % 11) * 1e-3 - 4e-3;
        grad[500] = -0.0, grad[900] = NAN;
        const int64_t want_bad = adam_reference(a, t, ref, m, v, grad);
        const int64_t bad = dr_adam_step(a, theta, grad);
        CHECK(bad == want_bad, "sparse adam step %lld: %lld non-finite, the formula %lld", (long long)t,
              (long long)bad, (long long)want_bad);
        CHECK(memcmp(theta, ref, sizeof(double) * n) == 0 && memcmp(a->m, m, sizeof(double) * n) == 0 &&
                  memcmp(a->v, v, sizeof(double) * n) == 0,
              "sparse adam step %lld differs from the formula", (long long)t);
    }
    for (size_t i = 0; i < n; i++)
        moved += theta[i] != (double)(i % 89) / 89.0;
    CHECK(moved > 0 && moved < (int64_t)n / 2, "sparse adam: %lld of %zu entries moved", (long long)moved, n);
    /* the step written back as optimize writes it (only the texels that
     * changed, on workers): every texel the float of its value, -0 over a
     * +0 included; dr_param_set_put gives the same */
    dr_param_set_put(s, ps, ref);
    theta[10] = -0.0;
    ref[10] = 0.0;
    dr_param_set_put(s, ps, ref);
    dr_param_set_put_threads(s, ps, theta, 2, NULL);
    dr_param_set_get(s, ps, ref);
    int64_t wrong = 0;
    for (size_t i = 0; i < n; i++) {   /* (the colour factor is kept in doubles, the texels in floats) */
        const double want = (int64_t)i >= ps->params[1].offset ? (double)(float)theta[i] : theta[i];
        wrong += memcmp(&want, &ref[i], sizeof want) != 0;
    }
    CHECK(wrong == 0, "dr_param_set_put_threads: %lld values not the floats of the step", (long long)wrong);
    dr_adam_destroy(a);
    free(theta);
    free(ref);
    free(grad);
    free(m);
    free(v);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* dr_adam_step_masked against dr_adam_step, step by step to the bit: a
 * sparse gradient with its block mask (its blocks move from step to step,
 * so the moments' mask grows; one marked block is all +0), a NaN,
 * untouched values out of range (the first step finds them by their values
 * alone and clamps them),
 * with or without a -0 moment set before (its owner then says the
 * moments' mask is not known); dr_adam_changed is NULL after the steps
 * that clamp (the first, the first after a checkpoint) and after the
 * others marks every value they moved; the write-back through
 * it leaves every texel the float of its value; after a checkpoint is read
 * (moments the masks do not know: a block of them set here), a masked step
 * still gives the bits of the formula. */
static void masked_adam_steps(const char *path, bool minus_zero)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 32, 24);
    CHECK(ps != NULL, "masked adam: param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const size_t n = (size_t)ps->total, words = (n + 511) / 512;
    double *theta = malloc(sizeof(double) * n), *ref = malloc(sizeof(double) * n), *grad = calloc(n, sizeof(double));
    double *before = malloc(sizeof(double) * n), *back = malloc(sizeof(double) * n);
    uint64_t *mask = calloc(words, sizeof(uint64_t));
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0), *b = dr_adam_create(ps, theta, 0.0);
    a->threads = b->threads = 2;
    const int tex = dr_adam_param_of(a, 3);
    for (size_t i = 0; i < n; i++)
        theta[i] = (double)(i % 89) / 89.0;
    for (size_t i = 200; i < 216; i++)
        theta[i] = i % 2 ? a->hi[tex] + 0.25 : a->lo[tex] - 0.5;
    if (minus_zero) {   /* (m set outside a step: its owner says so, optimizer.h) */
        a->m[400] = b->m[400] = -0.0;
        a->moved_known = false;
    }
    memcpy(ref, theta, sizeof(double) * n);
    dr_param_set_put(s, ps, theta);
    for (int t = 1; t <= 7; t++) {
        if (t == 6) {   /* through a checkpoint, with a block of moments no mask knows */
            for (size_t i = 8 * 52; i < 8 * 53; i++)   /* (a block no gradient here reaches) */
                a->m[i] = b->m[i] = 1e-3, a->v[i] = b->v[i] = 1e-6;
            a->moved_known = a->ranged = false;   /* (set outside a step: optimizer.h) */
            int64_t it = 0;
            CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 5) == 0 &&
                      dr_checkpoint_read(path, ps, theta, a, &it) == 0,
                  "masked adam: checkpoint: %s", dr_last_error());
        }
        memset(grad, 0, sizeof(double) * n);
        memset(mask, 0, sizeof(uint64_t) * words);
        for (size_t i = (size_t)t * 13; i < n; i += 97 + 11 * (size_t)t) {   /* a sparse gradient, moving */
            grad[i] = (double)(i % 11) * 1e-3 - 4e-3;
            mask[i / 512] |= UINT64_C(1) << (i / 8 % 64);
        }
        grad[900] = NAN;
        mask[900 / 512] |= UINT64_C(1) << (900 / 8 % 64);
        mask[1200 / 512] |= UINT64_C(1) << (1200 / 8 % 64);   /* marked, all +0 */
        for (size_t i = 1200; i < 1208; i++)
            grad[i] = 0.0;
        memcpy(before, theta, sizeof(double) * n);
        const int64_t bad_a = dr_adam_step_masked(a, theta, grad, mask), bad_b = dr_adam_step(b, ref, grad);
        CHECK(bad_a == bad_b && memcmp(theta, ref, sizeof(double) * n) == 0 &&
                  memcmp(a->m, b->m, sizeof(double) * n) == 0 && memcmp(a->v, b->v, sizeof(double) * n) == 0,
              "masked adam step %d (-0 moment %d) differs from the step over every entry", t, minus_zero);
        const uint64_t *changed = dr_adam_changed(a);
        CHECK((t == 1 || t == 6) == (changed == NULL), "masked adam step %d: changed is %s", t,
              changed ? "a mask" : "NULL");
        int64_t outside = 0, moved = 0;
        for (size_t i = 0; i < n; i++) {
            const bool differs = memcmp(&before[i], &theta[i], sizeof(double)) != 0;
            moved += differs;
            outside += differs && changed && !(changed[i / 512] >> (i / 8 % 64) & 1);
        }
        CHECK(outside == 0 && moved > 0, "masked adam step %d: %lld of %lld moved values outside the changed mask", t,
              (long long)outside, (long long)moved);
        dr_param_set_put_threads(s, ps, theta, 2, changed);
        dr_param_set_get(s, ps, back);
        int64_t wrong = 0;
        for (size_t i = 0; i < n; i++) {
            const double want = (int64_t)i >= ps->params[1].offset ? (double)(float)theta[i] : theta[i];
            wrong += memcmp(&want, &back[i], sizeof want) != 0;
        }
        CHECK(wrong == 0, "masked adam step %d: %lld values written back wrong", t, (long long)wrong);
    }
    dr_adam_destroy(a);
    dr_adam_destroy(b);
    free(theta);
    free(ref);
    free(grad);
    free(before);
    free(back);
    free(mask);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* Where Adam's moments' mask says a block's m and v are +0, neither a
 * masked step nor a checkpoint reads them (a read of a page nothing wrote
 * maps the zero page, and the next write costs a copy-on-write fault with
 * a TLB shootdown: optimizer.c's adam_entry). Seen by breaking the
 * invariant on purpose: values planted there are not what the step
 * starts from, nor what the checkpoint holds. */
static void unmarked_moments_unread(const char *path)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 32, 24);
    CHECK(ps != NULL, "unread moments: param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const size_t n = (size_t)ps->total, words = (n + 511) / 512;
    double *theta = malloc(sizeof(double) * n), *ref = malloc(sizeof(double) * n), *grad = calloc(n, sizeof(double));
    uint64_t *mask = calloc(words, sizeof(uint64_t));
    dr_param_set_get(s, ps, theta);
    for (size_t i = 3; i < n; i++)
        theta[i] = 0.25 + (double)(i % 13) / 52.0;   /* (inside the range) */
    memcpy(ref, theta, sizeof(double) * n);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0), *b = dr_adam_create(ps, theta, 0.0);
    const size_t stepped = 8 * 30, planted = 8 * 70;   /* two blocks: one the gradient reaches, one not */
    for (size_t i = stepped; i < stepped + 8; i++) {
        grad[i] = 1e-3 * (double)(i - stepped + 1);
        a->m[i] = a->v[i] = 7.0;   /* (the mask says +0) */
    }
    mask[stepped / 512] |= UINT64_C(1) << (stepped / 8 % 64);
    CHECK(dr_adam_step_masked(a, theta, grad, mask) == 0 && dr_adam_step(b, ref, grad) == 0,
          "unread moments: a step failed");
    CHECK(memcmp(theta, ref, sizeof(double) * n) == 0 && memcmp(a->m, b->m, sizeof(double) * n) == 0 &&
              memcmp(a->v, b->v, sizeof(double) * n) == 0,
          "a masked step read m and v of a block the moments' mask leaves clear");
    /* a second step whose gradient's mask leaves that block clear: its
     * moments decay, and the gradient there (planted: the mask says +0) is
     * not read either */
    memset(mask, 0, sizeof(uint64_t) * words);
    for (size_t i = stepped; i < stepped + 8; i++)
        grad[i] = 5.0;
    double *zeros = calloc(n, sizeof(double));
    CHECK(dr_adam_step_masked(a, theta, grad, mask) == 0 && dr_adam_step(b, ref, zeros) == 0,
          "unread moments: a second step failed");
    CHECK(memcmp(theta, ref, sizeof(double) * n) == 0 && memcmp(a->m, b->m, sizeof(double) * n) == 0 &&
              memcmp(a->v, b->v, sizeof(double) * n) == 0,
          "a masked step read the gradient of a block its mask leaves clear");
    free(zeros);
    for (size_t i = planted; i < planted + 8; i++)
        a->m[i] = a->v[i] = 7.0;
    struct dr_adam *r = dr_adam_create(ps, theta, 0.0);
    int64_t it = 0;
    CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, 1) == 0 && dr_checkpoint_read(path, ps, ref, r, &it) == 0,
          "unread moments: checkpoint: %s", dr_last_error());
    int64_t planted_read = 0, stepped_lost = 0;
    for (size_t i = 0; i < 8; i++) {
        planted_read += r->m[planted + i] != 0.0 || r->v[planted + i] != 0.0;
        stepped_lost += r->m[stepped + i] != b->m[stepped + i] || r->v[stepped + i] != b->v[stepped + i];
    }
    CHECK(planted_read == 0 && stepped_lost == 0,
          "the checkpoint read %lld moments of an unmarked block, lost %lld of a marked one", (long long)planted_read,
          (long long)stepped_lost);
    dr_adam_destroy(a);
    dr_adam_destroy(b);
    dr_adam_destroy(r);
    free(theta);
    free(ref);
    free(grad);
    free(mask);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

/* dr_checkpoint_write_async: the same file as dr_checkpoint_write once
 * waited for; the previous checkpoint in place until then; a second write
 * waits for the first; a rename that fails (a directory where the file
 * goes) is reported by the wait, the temporary removed. */
static void async_checkpoint(const char *path)
{
    struct dr_param_set *ps;
    struct dr_scene *s = texture_scene(&ps, 32, 24);
    CHECK(ps != NULL, "async: param set: %s", dr_last_error());
    if (!ps) {
        dr_scene_destroy(s);
        return;
    }
    const size_t n = (size_t)ps->total;
    double *theta = malloc(sizeof(double) * n);
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0);
    char sync_path[4200], async_path[4200], dir[4200];
    snprintf(sync_path, sizeof sync_path, "%s.sync", path);
    snprintf(async_path, sizeof async_path, "%s.async", path);
    snprintf(dir, sizeof dir, "%s.dir", path);
    struct dr_checkpoint_pending pending = {0};
    CHECK(dr_checkpoint_write(sync_path, "scene.gltf", ps, theta, a, 4) == 0 &&
              dr_checkpoint_write_async(&pending, async_path, "scene.gltf", ps, theta, a, 2) == 0 &&
              dr_checkpoint_write_async(&pending, async_path, "scene.gltf", ps, theta, a, 4) == 0,
          "async: writes: %s", dr_last_error());
    CHECK(dr_checkpoint_wait(&pending) == 0 && !pending.running, "async: wait: %s", dr_last_error());
    FILE *fa = fopen(async_path, "rb"), *fs = fopen(sync_path, "rb");
    bool same = fa && fs;
    for (int ca = 0, cs = 0; same && (ca != EOF || cs != EOF);) {
        ca = getc(fa), cs = getc(fs);
        same = ca == cs;
    }
    if (fa)
        fclose(fa);
    if (fs)
        fclose(fs);
    CHECK(same, "async: the file differs from the one written at once");
    CHECK(mkdir(dir, 0755) == 0, "async: mkdir %s", dir);
    CHECK(dr_checkpoint_write_async(&pending, dir, "scene.gltf", ps, theta, a, 5) == 0, "async: write: %s",
          dr_last_error());
    CHECK(dr_checkpoint_wait(&pending) == DR_ERR_IO && strstr(dr_last_error(), "cannot write checkpoint"),
          "async: a failed rename not reported: %s", dr_last_error());
    char tmp[4300];
    snprintf(tmp, sizeof tmp, "%s.tmp%ld", dir, (long)getpid());
    CHECK(access(tmp, F_OK) != 0, "async: the temporary %s was left", tmp);
    CHECK(dr_checkpoint_wait(&pending) == 0, "async: a second wait reports again");
    rmdir(dir);
    unlink(sync_path);
    unlink(async_path);
    dr_adam_destroy(a);
    free(theta);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
}

int main(void)
{
    sparse_adam_step();
    struct dr_scene *s = scene();
    const char *ptrs[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor",
                          "/materials/0/pbrMetallicRoughness/roughnessFactor",
                          "/materials/0/extensions/KHR_materials_emissive_strength/emissiveStrength"};
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, 3);
    CHECK(ps && ps->total == 5, "param set: %s", dr_last_error());
    double theta[5], target[5] = {0.2, 0.9, 1.5 /* outside [0,1]: must stop at 1 */, 0.0005 /* below floor */, 9.0};
    dr_param_set_get(s, ps, theta);
    struct dr_adam *a = dr_adam_create(ps, theta, 0.0);
    CHECK(a != NULL, "adam");
    CHECK(dr_adam_param_of(a, 0) == 0 && dr_adam_param_of(a, 2) == 0 && dr_adam_param_of(a, 3) == 1 &&
              dr_adam_param_of(a, 4) == 2 && dr_adam_param_of(a, 5) == -1,
          "scalars' parameters");
    CHECK_NEAR(a->lr[dr_adam_param_of(a, 0)], 0.02, 0, "colour learning rate");
    CHECK_NEAR(a->lr[dr_adam_param_of(a, 4)], 0.05 * 4.0, 1e-12, "strength learning rate is 5% of its value");
    double grad[5], saved_theta[5];
    struct dr_adam *b = dr_adam_create(ps, theta, 0.0);
    char path[] = "/tmp/drender-ckpt-XXXXXX";
    int fd = mkstemp(path);
    close(fd);
    for (int it = 0; it < 600; it++) {
        for (int i = 0; i < 5; i++)
            grad[i] = 2.0 * (theta[i] - target[i]);   /* d/dtheta (theta - target)^2 */
        dr_adam_step(a, theta, grad);
        if (it == 299) {
            CHECK(dr_checkpoint_write(path, "scene.gltf", ps, theta, a, it + 1) == 0, "write: %s", dr_last_error());
            memcpy(saved_theta, theta, sizeof theta);
        }
    }
    CHECK_NEAR(theta[0], 0.2, 2e-3, "base colour r");
    CHECK_NEAR(theta[1], 0.9, 2e-3, "base colour g");
    CHECK(theta[2] == 1.0, "base colour b clamped to 1: %.17g", theta[2]);
    CHECK(theta[3] == 0.001, "roughness clamped to its floor 0.001: %.17g", theta[3]);
    CHECK_NEAR(theta[4], 9.0, 0.05, "emission strength");

    /* resume from iteration 300: exactly the same end point */
    double resumed[5];
    int64_t it0 = 0;
    CHECK(dr_checkpoint_read(path, ps, resumed, b, &it0) == 0, "read: %s", dr_last_error());
    CHECK(it0 == 300 && b->t == 300, "iteration %lld, adam t %lld", (long long)it0, (long long)b->t);
    CHECK(memcmp(resumed, saved_theta, sizeof resumed) == 0, "parameters not restored bit for bit");
    for (int64_t it = it0; it < 600; it++) {
        for (int i = 0; i < 5; i++)
            grad[i] = 2.0 * (resumed[i] - target[i]);
        dr_adam_step(b, resumed, grad);
    }
    CHECK(memcmp(resumed, theta, sizeof resumed) == 0, "resumed run differs from the uninterrupted one");
    edge_values(ps, saved_theta, path);

    /* a different parameter list is refused */
    struct dr_param_set *other = dr_param_set_create(s, ptrs, 2);
    double tmp[5];
    CHECK(dr_checkpoint_read(path, other, tmp, b, &it0) == DR_ERR_ARG, "mismatched parameters accepted");
    CHECK(strstr(dr_last_error(), "--param") != NULL, "message: %s", dr_last_error());
    /* a truncated file is refused */
    FILE *f = fopen(path, "r+");
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fclose(f);
    CHECK(truncate(path, len / 2) == 0, "truncate");
    CHECK(dr_checkpoint_read(path, ps, tmp, b, &it0) == DR_ERR_FORMAT, "truncated checkpoint accepted");
    texture_checkpoint(path);
    masked_adam_steps(path, false);
    masked_adam_steps(path, true);
    packed_checkpoint(path);
    unmarked_moments_unread(path);
    async_checkpoint(path);
    unlink(path);
    dr_param_set_destroy(other);
    dr_adam_destroy(a);
    dr_adam_destroy(b);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
    return TEST_END();
}
