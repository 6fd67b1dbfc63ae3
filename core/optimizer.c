#include "optimizer.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"

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
    a->beta1 = 0.9;
    a->beta2 = 0.999;
    a->eps = 1e-8;
    size_t n = (size_t)(a->n > 0 ? a->n : 1);
    a->m = calloc(n, sizeof(double));
    a->v = calloc(n, sizeof(double));
    a->lr = malloc(n * sizeof(double));
    a->lo = malloc(n * sizeof(double));
    a->hi = malloc(n * sizeof(double));
    if (!a->m || !a->v || !a->lr || !a->lo || !a->hi)
        goto nomem;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        double lo, hi;
        dr_param_range(p, &lo, &hi);
        double lr = lr_override > 0.0 ? lr_override : dr_param_default_lr(p, theta + p->offset);
        for (int64_t i = p->offset; i < p->offset + p->size; i++) {
            a->lr[i] = lr;
            a->lo[i] = lo;
            a->hi[i] = hi;
        }
    }
    return a;
nomem:
    dr_set_error("out of memory");
    dr_adam_destroy(a);
    return NULL;
}

int64_t dr_adam_step(struct dr_adam *a, double *theta, const double *grad)
{
    int64_t bad = 0;
    a->t++;
    double c1 = 1.0 - pow(a->beta1, (double)a->t), c2 = 1.0 - pow(a->beta2, (double)a->t);
    for (int64_t i = 0; i < a->n; i++) {
        double g = grad[i];
        if (!isfinite(g)) {
            g = 0.0;
            bad++;
        }
        a->m[i] = a->beta1 * a->m[i] + (1.0 - a->beta1) * g;
        a->v[i] = a->beta2 * a->v[i] + (1.0 - a->beta2) * g * g;
        double step = a->lr[i] * (a->m[i] / c1) / (sqrt(a->v[i] / c2) + a->eps);
        double x = theta[i] - step;
        theta[i] = x < a->lo[i] ? a->lo[i] : (x > a->hi[i] ? a->hi[i] : x);
    }
    return bad;
}

/* ---- checkpoints ---- */

static void write_doubles(FILE *f, const char *key, const double *v, int64_t n)
{
    fputs(key, f);
    for (int64_t i = 0; i < n; i++)
        fprintf(f, " %.17g", v[i]);
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
    fprintf(f, "drender-checkpoint 1\nscene %s\niteration %lld\nadam %lld %.17g %.17g %.17g\n", scene_path,
            (long long)iteration, (long long)a->t, a->beta1, a->beta2, a->eps);
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        fprintf(f, "param %s %lld\n", p->name, (long long)p->size);
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

static bool read_doubles(FILE *f, const char *key, double *v, int64_t n)
{
    char word[64];
    if (fscanf(f, "%63s", word) != 1 || strcmp(word, key) != 0)
        return false;
    for (int64_t i = 0; i < n; i++)
        if (fscanf(f, "%lf", &v[i]) != 1)
            return false;
    return true;
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
    bool ok = fscanf(f, "drender-checkpoint %d\n", &version) == 1 && version == 1 && fgets(line, sizeof line, f) &&
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
        ok = read_doubles(f, "value", theta + p->offset, p->size) && read_doubles(f, "m", a->m + p->offset, p->size) &&
             read_doubles(f, "v", a->v + p->offset, p->size);
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
    /* A well-formed file can still hold a state no run reaches: a negative
     * iteration (optimize indexes its history with it), Adam constants out of
     * range, non-finite or out-of-range values, a negative second moment. */
    if (it < 0 || t < 0 || !(a->beta1 >= 0.0 && a->beta1 < 1.0) || !(a->beta2 >= 0.0 && a->beta2 < 1.0) ||
        !(a->eps > 0.0 && isfinite(a->eps))) {
        dr_set_error("%s: not a valid drender checkpoint: iteration %lld, adam %lld %g %g %g out of range", path, it,
                     t, a->beta1, a->beta2, a->eps);
        return DR_ERR_FORMAT;
    }
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        for (int64_t i = p->offset; i < p->offset + p->size; i++)
            if (!(theta[i] >= a->lo[i] && theta[i] <= a->hi[i]) || !isfinite(a->m[i]) || !isfinite(a->v[i]) ||
                a->v[i] < 0.0) {
                dr_set_error("%s: not a valid drender checkpoint: %s value %lld is %g (range [%g, %g]), m %g, v %g",
                             path, p->name, (long long)(i - p->offset), theta[i], a->lo[i], a->hi[i], a->m[i],
                             a->v[i]);
                return DR_ERR_FORMAT;
            }
    }
    a->t = t;
    *iteration = it;
    return 0;
}
