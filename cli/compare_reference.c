/* drender compare: the reference file (DIR/reference.txt), so an expensive
 * reference is computed once and reused. A line-oriented text file: a
 * header naming what the reference answers (scene, parameters, mode and
 * the settings that change the quantity), then one "mean se" line per entry
 * of v (compare.h). Read back only for the same question. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "compare.h"
#include "error.h"

#define REF_MAGIC "drender-reference 1"

uint64_t cmp_hash_bytes(uint64_t h, const void *data, size_t n)
{
    const unsigned char *p = data;
    if (h == 0)
        h = 0xcbf29ce484222325ULL;   /* FNV-1a 64 */
    for (size_t i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ULL;
    }
    return h;
}

uint64_t cmp_hash_file(const char *path, bool *ok)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        dr_set_error("%s: %s", path, strerror(errno));
        *ok = false;
        return 0;
    }
    unsigned char buf[65536];
    uint64_t h = 0;
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0)
        h = cmp_hash_bytes(h, buf, n);
    fclose(f);
    return h;
}

static void write_header(FILE *f, const struct cmp_run *r)
{
    const struct cmp_fingerprint *fp = &r->fp;
    fprintf(f, REF_MAGIC "\nmode %s\nloss %s\nscene_file %s\n", fp->mode, fp->loss, r->scene_path);
    fprintf(f, "scene_hash %016" PRIx64 "\nparams %d\n", fp->scene_hash, r->ps->n);
    for (int k = 0; k < r->ps->n; k++)
        fprintf(f, "%lld %s\n", (long long)r->ps->params[k].size, r->ps->params[k].name);
    fprintf(f, "target_hash %016" PRIx64 "\nvalues_hash %016" PRIx64 "\n", fp->target_hash, fp->values_hash);
    fprintf(f, "size %d %d\ncamera %d\nmax_depth %d\nrr_depth %d\nprimal_spp %d\n", fp->width, fp->height,
            fp->camera, fp->max_depth, fp->rr_depth, fp->primal_spp);
    fprintf(f, "film %s\n", fp->film);
}

int cmp_reference_write(const struct cmp_run *r, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return -1;
    const struct cmp_reference *ref = &r->ref;
    write_header(f, r);
    fprintf(f, "kind %s\nestimator %s %s\nspp %d\nbatches %d\neps %.17g\nseconds %.6g\nvalues %lld\n", ref->kind,
            ref->estimator[0] ? ref->estimator : "-", ref->sampling[0] ? ref->sampling : "-", ref->spp,
            ref->batches, ref->eps, ref->seconds, (long long)r->V);
    for (int64_t i = 0; i < r->V; i++)
        fprintf(f, "%.17g %.17g\n", ref->mean[i], ref->se[i]);
    return cli_fclose_checked(f);
}

/* ---- reading ---- */

struct ref_reader {
    FILE *f;
    const char *file;
    int line;
    char buf[1024];
};

/* The next line, which must start with "key ": its value, or NULL after a message. */
static const char *field(struct ref_reader *rd, const char *key)
{
    rd->line++;
    if (!fgets(rd->buf, sizeof rd->buf, rd->f)) {
        cli_error("compare", "--reference %s: ends before '%s' (line %d): not a complete reference file", rd->file,
                  key, rd->line);
        return NULL;
    }
    rd->buf[strcspn(rd->buf, "\n")] = '\0';
    size_t n = strlen(key);
    if (strncmp(rd->buf, key, n) != 0 || rd->buf[n] != ' ') {
        cli_error("compare", "--reference %s: line %d: expected '%s ...'", rd->file, rd->line, key);
        return NULL;
    }
    return rd->buf + n + 1;
}

/* "mismatch" messages name the file, what differs, both values. */
static int differs(const struct ref_reader *rd, const char *what, const char *theirs, const char *ours)
{
    cli_error("compare", "--reference %s was made for %s %s; this run has %s (compute a new reference: "
                         "--reference spp:N or fd)", rd->file, what, theirs, ours);
    return DR_EXIT_USAGE;
}

static int read_u64_field(struct ref_reader *rd, const char *key, uint64_t *v)
{
    const char *s = field(rd, key);
    if (!s)
        return DR_EXIT_INPUT;
    if (sscanf(s, "%" SCNx64, v) != 1) {
        cli_error("compare", "--reference %s: line %d: '%s' is not a hash", rd->file, rd->line, s);
        return DR_EXIT_INPUT;
    }
    return -1;
}

static int read_int_field(struct ref_reader *rd, const char *key, int n, int *v)
{
    const char *s = field(rd, key);
    if (!s)
        return DR_EXIT_INPUT;
    int got = n == 1 ? sscanf(s, "%d", &v[0]) : sscanf(s, "%d %d", &v[0], &v[1]);
    if (got != n) {
        cli_error("compare", "--reference %s: line %d: '%s' is not %s", rd->file, rd->line, s,
                  n == 1 ? "a number" : "two numbers");
        return DR_EXIT_INPUT;
    }
    return -1;
}

/* mode, loss, scene: the question in words. */
static int check_identity(struct ref_reader *rd, const struct cmp_run *r)
{
    const struct cmp_fingerprint *fp = &r->fp;
    const char *s;
    rd->line++;
    if (!fgets(rd->buf, sizeof rd->buf, rd->f) || strncmp(rd->buf, REF_MAGIC, strlen(REF_MAGIC)) != 0) {
        cli_error("compare", "--reference %s: not a drender reference file (expected '%s' on line 1)", rd->file,
                  REF_MAGIC);
        return DR_EXIT_INPUT;
    }
    if (!(s = field(rd, "mode")))
        return DR_EXIT_INPUT;
    if (strcmp(s, fp->mode) != 0)
        return differs(rd, "mode", s, fp->mode);
    if (!(s = field(rd, "loss")))
        return DR_EXIT_INPUT;
    if (strcmp(s, fp->loss) != 0)
        return differs(rd, "loss", s, fp->loss);
    if (!(s = field(rd, "scene_file")))
        return DR_EXIT_INPUT;
    char scene_file[1024];
    snprintf(scene_file, sizeof scene_file, "%s", s);
    uint64_t h;
    int rc = read_u64_field(rd, "scene_hash", &h);
    if (rc >= 0)
        return rc;
    if (h != fp->scene_hash) {
        char theirs[1100];
        snprintf(theirs, sizeof theirs, "%s (other contents)", scene_file);
        return differs(rd, "scene", theirs, r->scene_path);
    }
    return -1;
}

/* target and parameter values: what else the quantity depends on. */
static int check_inputs(struct ref_reader *rd, const struct cmp_run *r)
{
    const struct cmp_fingerprint *fp = &r->fp;
    uint64_t h;
    int rc;
    if ((rc = read_u64_field(rd, "target_hash", &h)) >= 0)
        return rc;
    if (h != fp->target_hash)
        return differs(rd, "another", "--target image", r->a->target ? r->a->target : "none");
    if ((rc = read_u64_field(rd, "values_hash", &h)) >= 0)
        return rc;
    if (h != fp->values_hash) {
        cli_error("compare", "--reference %s was made with other values of the parameters (a different --set, or "
                             "an edited scene file); compute a new reference: --reference spp:N or fd", rd->file);
        return DR_EXIT_USAGE;
    }
    return -1;
}

/* size, camera, depths, primal spp: the settings that change the quantity. */
static int check_settings(struct ref_reader *rd, const struct cmp_run *r)
{
    const struct cmp_fingerprint *fp = &r->fp;
    static const char *const keys[] = {"camera", "max_depth", "rr_depth", "primal_spp"};
    const int ours[] = {fp->camera, fp->max_depth, fp->rr_depth, fp->primal_spp};
    static const char *const what[] = {"--camera", "--max-depth (the largest)", "--rr-depth", "a primal of spp"};
    int wh[2], rc;
    char t[64], o[64];
    if ((rc = read_int_field(rd, "size", 2, wh)) >= 0)
        return rc;
    if (wh[0] != fp->width || wh[1] != fp->height) {
        snprintf(t, sizeof t, "%dx%d", wh[0], wh[1]);
        snprintf(o, sizeof o, "%dx%d", fp->width, fp->height);
        return differs(rd, "image size", t, o);
    }
    for (int i = 0; i < 4; i++) {
        int v;
        if ((rc = read_int_field(rd, keys[i], 1, &v)) >= 0)
            return rc;
        if (v != ours[i]) {
            snprintf(t, sizeof t, "%d", v);
            snprintf(o, sizeof o, "%d", ours[i]);
            return differs(rd, what[i], t, o);
        }
    }
    /* the filter, crop and sampler change the estimated quantity's pixels */
    const char *film = field(rd, "film");
    if (!film)
        return DR_EXIT_INPUT;
    if (strcmp(film, fp->film) != 0)
        return differs(rd, "the film", film, fp->film);
    return -1;
}

/* The parameter list, in order, with sizes. */
static int check_params(struct ref_reader *rd, const struct cmp_run *r)
{
    int n, rc;
    if ((rc = read_int_field(rd, "params", 1, &n)) >= 0)
        return rc;
    char ours[2048] = "", theirs[2048] = "";
    for (int k = 0; k < r->ps->n; k++) {
        size_t len = strlen(ours);
        snprintf(ours + len, sizeof ours - len, "%s%s", k ? ", " : "", r->ps->params[k].name);
    }
    if (n < 0 || n > 4096) {
        cli_error("compare", "--reference %s: line %d: %d parameters", rd->file, rd->line, n);
        return DR_EXIT_INPUT;
    }
    bool same = n == r->ps->n;
    for (int k = 0; k < n; k++) {
        rd->line++;
        long long size;
        char name[DR_PARAM_NAME_MAX + 8];
        if (!fgets(rd->buf, sizeof rd->buf, rd->f) || sscanf(rd->buf, "%lld %167[^\n]", &size, name) != 2) {
            cli_error("compare", "--reference %s: line %d: expected 'SIZE NAME' of parameter %d", rd->file, rd->line,
                      k);
            return DR_EXIT_INPUT;
        }
        size_t len = strlen(theirs);
        snprintf(theirs + len, sizeof theirs - len, "%s%s", k ? ", " : "", name);
        same = same && strcmp(name, r->ps->params[k].name) == 0 && size == r->ps->params[k].size;
    }
    return same ? -1 : differs(rd, "parameters", theirs, ours);
}

/* kind, estimator, counts, then the values. */
static int read_values(struct ref_reader *rd, struct cmp_run *r)
{
    struct cmp_reference *ref = &r->ref;
    const char *s;
    int rc;
    if (!(s = field(rd, "kind")))
        return DR_EXIT_INPUT;
    snprintf(ref->kind, sizeof ref->kind, "%s", s);
    if (!(s = field(rd, "estimator")))
        return DR_EXIT_INPUT;
    if (sscanf(s, "%31s %31s", ref->estimator, ref->sampling) != 2) {
        cli_error("compare", "--reference %s: line %d: expected 'estimator NAME SAMPLING'", rd->file, rd->line);
        return DR_EXIT_INPUT;
    }
    if (strcmp(ref->estimator, "-") == 0)
        ref->estimator[0] = ref->sampling[0] = '\0';
    if ((rc = read_int_field(rd, "spp", 1, &ref->spp)) >= 0 || (rc = read_int_field(rd, "batches", 1, &ref->batches)) >= 0)
        return rc;
    if (!(s = field(rd, "eps")) || sscanf(s, "%lf", &ref->eps) != 1 || !(s = field(rd, "seconds")) ||
        sscanf(s, "%lf", &ref->seconds) != 1 || !(s = field(rd, "values")))
        return DR_EXIT_INPUT;
    long long V;
    if (sscanf(s, "%lld", &V) != 1 || V != r->V) {
        cli_error("compare", "--reference %s: line %d: %s values, this run has %lld", rd->file, rd->line, s,
                  (long long)r->V);
        return DR_EXIT_INPUT;
    }
    for (int64_t i = 0; i < r->V; i++) {
        rd->line++;
        if (!fgets(rd->buf, sizeof rd->buf, rd->f) ||
            sscanf(rd->buf, "%lf %lf", &ref->mean[i], &ref->se[i]) != 2 || !isfinite(ref->mean[i]) ||
            !isfinite(ref->se[i]) || ref->se[i] < 0.0) {
            cli_error("compare", "--reference %s: line %d: expected 'MEAN SE' (finite numbers, SE >= 0)", rd->file,
                      rd->line);
            return DR_EXIT_INPUT;
        }
    }
    return -1;
}

int cmp_reference_read(struct cmp_run *r, const char *file)
{
    struct ref_reader rd = {.file = file};
    rd.f = fopen(file, "r");
    if (!rd.f) {
        cli_error("compare", "--reference %s: %s", file, strerror(errno));
        return DR_EXIT_INPUT;
    }
    int rc;
    if ((rc = check_identity(&rd, r)) < 0 && (rc = check_params(&rd, r)) < 0 && (rc = check_inputs(&rd, r)) < 0 &&
        (rc = check_settings(&rd, r)) < 0)
        rc = read_values(&rd, r);
    fclose(rd.f);
    if (rc < 0)
        snprintf(r->ref.file, sizeof r->ref.file, "%s", file);
    return rc;
}
