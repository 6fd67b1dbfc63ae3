/* drender compare: what a comparison writes. results.csv (one row per run,
 * stable columns), results.json (the same plus per-parameter detail and one
 * summary per combination), report.md (the table a person reads first) and
 * the gnuplot plots (plots.gp keeps the data inline, so it can be edited and
 * re-run by hand). */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cli.h"
#include "compare.h"
#include "cut_short.h"

bool cmp_same_pair(const struct cmp_combo *a, const struct cmp_combo *b)
{
    return a->est == b->est && a->sampling == b->sampling && a->sampler == b->sampler &&
           a->medium_grad == b->medium_grad;
}

void cmp_pair_label(const struct cmp_run *r, const struct cmp_combo *c, char *buf, size_t size)
{
    /* a single sampler (media method) is the run's setting, not a dimension */
    char media[32] = "";
    if (r->a->n_medium_grads > 1)
        snprintf(media, sizeof media, " (media %s)", dr_medium_grad_name(c->medium_grad));
    if (r->a->n_samplers > 1)
        snprintf(buf, size, "%s %s %s%s", c->est->name, dr_sampling_name(c->sampling), dr_sampler_kind_name(c->sampler),
                 media);
    else
        snprintf(buf, size, "%s %s%s", c->est->name, dr_sampling_name(c->sampling), media);
}

void cmp_combo_label(const struct cmp_run *r, const struct cmp_combo *c, char *buf, size_t size)
{
    char pair[96];
    cmp_pair_label(r, c, pair, sizeof pair);
    snprintf(buf, size, "%s d%d", pair, c->max_depth);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

void cmp_seconds_spread(const struct cmp_run *r, int c, double *median, double *lo, double *hi)
{
    const int n = r->a->repeat;
    double s[1000];
    memcpy(s, r->results[c].seconds, sizeof(double) * (size_t)n);
    qsort(s, (size_t)n, sizeof(double), cmp_double);
    *lo = s[0];
    *hi = s[n - 1];
    *median = n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

static double efficiency_at(const struct cmp_result *res, double seconds)
{
    double d = res->rel_variance * seconds;
    return d > 0.0 && isfinite(d) ? 1.0 / d : NAN;
}

double cmp_efficiency(const struct cmp_run *r, int c)
{
    double med, lo, hi;
    cmp_seconds_spread(r, c, &med, &lo, &hi);
    return efficiency_at(&r->results[c], med);
}

double cmp_param_efficiency(const struct cmp_run *r, int c, int k)
{
    double med, lo, hi;
    cmp_seconds_spread(r, c, &med, &lo, &hi);
    double d = r->results[c].params[k].rel_variance * med;
    return d > 0.0 && isfinite(d) ? 1.0 / d : NAN;
}

/* ---- results.csv ---- */

static void csv_string(FILE *f, const char *s)
{
    if (!strpbrk(s, ",\"\n")) {
        fputs(s, f);
        return;
    }
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '"')
            fputc('"', f);
        fputc(*s, f);
    }
    fputc('"', f);
}

static void csv_number(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, ",%.6g", v);
    else
        fputc(',', f);   /* undefined (a zero reference): empty */
}

#define CSV_COLUMNS                                                                                           \
    "scene,mode,estimator,sampling,max_depth,spp,repeat,batches,seconds,rays,memory_bytes,record_bytes,"       \
    "invalid_samples,rel_error,rel_variance,efficiency,reference,reference_rel_se,sampler,medium_grad"

int cmp_write_csv(const struct cmp_run *r, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return -1;
    fprintf(f, CSV_COLUMNS "\n");
    for (int rep = 0; rep < r->a->repeat; rep++)
        for (int c = 0; c < r->n_combos; c++) {
            const struct cmp_combo *cb = &r->combos[c];
            const struct cmp_result *res = &r->results[c];
            csv_string(f, r->scene_path);
            fprintf(f, ",%s,%s,%s,%d,%d,%d,%d", r->reverse ? "reverse" : "forward", cb->est->name,
                    dr_sampling_name(cb->sampling), cb->max_depth, cb->spp, rep, r->a->batches);
            csv_number(f, res->seconds[rep]);
            fprintf(f, ",%.0f,%llu,%llu,%llu", res->rays, (unsigned long long)res->memory_bytes,
                    (unsigned long long)res->record_bytes, (unsigned long long)res->invalid);
            csv_number(f, res->rel_error);
            csv_number(f, res->rel_variance);
            csv_number(f, efficiency_at(res, res->seconds[rep]));
            fprintf(f, ",%s", r->ref.kind);
            csv_number(f, r->ref.rel_se);
            /* last: older columns keep their place */
            fprintf(f, ",%s,%s\n", dr_sampler_kind_name(cb->sampler), dr_medium_grad_name(cb->medium_grad));
        }
    return cli_fclose_checked(f);
}

/* ---- results.json ---- */

static void json_key_number(FILE *f, const char *key, double v)
{
    fprintf(f, ", \"%s\": ", key);
    json_number(f, v);
}

static void json_array(FILE *f, const double *v, int n)
{
    fputc('[', f);
    for (int i = 0; i < n; i++) {
        if (i)
            fputs(", ", f);
        json_number(f, v[i]);
    }
    fputc(']', f);
}

static const char *summary_kind(const struct cmp_run *r, int k)
{
    const struct dr_param *p = &r->ps->params[k];
    if (!r->reverse)
        return "pixel_mean";
    return p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP ? "norm" : "components";
}

static void json_params(FILE *f, const struct cmp_run *r, int c)
{
    const struct cmp_result *res = &r->results[c];
    fputs(", \"parameters\": [", f);
    for (int k = 0; k < r->ps->n; k++) {
        const struct cmp_param_result *pr = &res->params[k];
        fprintf(f, "%s{\"name\": ", k ? ", " : "");
        json_string(f, r->ps->params[k].name);
        fprintf(f, ", \"summary\": \"%s\", \"value\": ", summary_kind(r, k));
        json_array(f, pr->value, pr->n);
        fputs(", \"stderr\": ", f);
        json_array(f, pr->se, pr->n);
        fputs(", \"reference\": ", f);
        json_array(f, pr->ref, pr->n);
        fputs(", \"reference_stderr\": ", f);
        json_array(f, pr->ref_se, pr->n);
        json_key_number(f, "rel_error", pr->rel_error);
        json_key_number(f, "rel_variance", pr->rel_variance);
        json_key_number(f, "efficiency", cmp_param_efficiency(r, c, k));
        fputc('}', f);
    }
    fputc(']', f);
}

static void json_combination(FILE *f, const struct cmp_run *r, int c)
{
    const struct cmp_combo *cb = &r->combos[c];
    const struct cmp_result *res = &r->results[c];
    double med, lo, hi;
    cmp_seconds_spread(r, c, &med, &lo, &hi);
    fprintf(f, "{\"estimator\": \"%s\", \"sampling\": \"%s\", \"sampler\": \"%s\", \"medium_grad\": \"%s\", "
               "\"max_depth\": %d, \"spp\": %d", cb->est->name, dr_sampling_name(cb->sampling),
            dr_sampler_kind_name(cb->sampler), dr_medium_grad_name(cb->medium_grad), cb->max_depth, cb->spp);
    json_key_number(f, "seconds_median", med);
    json_key_number(f, "seconds_min", lo);
    json_key_number(f, "seconds_max", hi);
    json_key_number(f, "rays", res->rays);
    fprintf(f, ", \"memory_bytes\": %llu, \"record_bytes\": %llu, \"invalid_samples\": %llu",
            (unsigned long long)res->memory_bytes, (unsigned long long)res->record_bytes,
            (unsigned long long)res->invalid);
    json_key_number(f, "rel_error", res->rel_error);
    json_key_number(f, "rel_variance", res->rel_variance);
    json_key_number(f, "efficiency", efficiency_at(res, med));
    grad_json_media_gain(f, res->media_gain, res->n_media_gain);
    json_params(f, r, c);
    fputc('}', f);
}

static void json_reference(FILE *f, const struct cmp_run *r)
{
    const struct cmp_reference *ref = &r->ref;
    fputs(", \"reference\": {\"kind\": ", f);
    json_string(f, ref->kind);
    fputs(", \"file\": ", f);
    if (ref->file[0])
        json_string(f, ref->file);
    else
        fputs("null", f);
    fputs(", \"estimator\": ", f);
    json_string(f, ref->estimator);
    fputs(", \"sampling\": ", f);
    json_string(f, ref->sampling);
    fprintf(f, ", \"spp\": %d, \"batches\": %d, \"max_depth\": %d", ref->spp, ref->batches, r->fp.max_depth);
    json_key_number(f, "eps", ref->eps);
    json_key_number(f, "seconds", ref->seconds);
    json_key_number(f, "rel_se", ref->rel_se);
    fputc('}', f);
}

static int best_combo(const struct cmp_run *r)
{
    int best = 0;
    for (int c = 1; c < r->n_combos; c++)
        if (cmp_efficiency(r, c) > cmp_efficiency(r, best) || !isfinite(cmp_efficiency(r, best)))
            best = c;
    return best;
}

static void json_rows(FILE *f, const struct cmp_run *r)
{
    fputs(", \"rows\": [", f);
    for (int rep = 0, i = 0; rep < r->a->repeat; rep++)
        for (int c = 0; c < r->n_combos; c++, i++) {
            const struct cmp_combo *cb = &r->combos[c];
            fprintf(f, "%s{\"estimator\": \"%s\", \"sampling\": \"%s\", \"sampler\": \"%s\", \"medium_grad\": \"%s\", "
                       "\"max_depth\": %d, \"spp\": %d, \"repeat\": %d", i ? ", " : "", cb->est->name,
                    dr_sampling_name(cb->sampling), dr_sampler_kind_name(cb->sampler),
                    dr_medium_grad_name(cb->medium_grad), cb->max_depth, cb->spp, rep);
            json_key_number(f, "seconds", r->results[c].seconds[rep]);
            json_key_number(f, "rel_error", r->results[c].rel_error);
            json_key_number(f, "efficiency", efficiency_at(&r->results[c], r->results[c].seconds[rep]));
            fputc('}', f);
        }
    fputc(']', f);
}

void cmp_write_json(const struct cmp_run *r, FILE *f)
{
    const struct cmp_args *a = r->a;
    fputs("{\"command\": \"compare\", \"scene\": ", f);
    json_string(f, r->scene_path);
    fprintf(f, ", \"mode\": \"%s\", \"loss\": \"%s\", \"primal\": %s, \"target\": ", r->fp.mode, r->fp.loss,
            !r->reverse ? "null" : a->cross ? "\"cross\"" : "\"shared\"");
    if (a->target)
        json_string(f, a->target);
    else
        fputs("null", f);
    fprintf(f, ", \"width\": %d, \"height\": %d, \"rr_depth\": %d, \"seed\": %llu, \"batches\": %d, \"repeat\": %d",
            a->g.width, a->g.height, a->g.rr_depth, (unsigned long long)a->g.seed, a->batches, a->repeat);
    fputs(", ", f);
    grad_json_film(f, &a->g);
    fputs(", \"samplers\": [", f);   /* "sampler" (the film's) is the first: the reference's */
    for (int q = 0; q < a->n_samplers; q++)
        fprintf(f, "%s\"%s\"", q ? ", " : "", dr_sampler_kind_name(a->samplers[q]));
    fputs("], \"medium_grads\": [", f);
    for (int q = 0; q < a->n_medium_grads; q++)
        fprintf(f, "%s\"%s\"", q ? ", " : "", dr_medium_grad_name(a->medium_grads[q]));
    fputs("], \"output_dir\": ", f);
    json_string(f, a->out_dir);
    fputs(", \"parameters\": [", f);
    for (int k = 0; k < r->ps->n; k++) {
        fprintf(f, "%s{\"name\": ", k ? ", " : "");
        json_string(f, r->ps->params[k].name);
        fprintf(f, ", \"size\": %lld, \"summary\": \"%s\"}", (long long)r->ps->params[k].size, summary_kind(r, k));
    }
    fputs("], \"skipped\": ", f);
    json_name_list(f, r->skipped);
    fputs(", \"as_detached\": ", f);   /* (default modes left out: they would run detached) */
    json_name_list(f, r->as_detached);
    fputs(", \"auto_sampling\": ", f);   /* (what grad's default would run) */
    json_string(f, r->auto_sampling);
    json_reference(f, r);
    fputs(", \"combinations\": [", f);
    for (int c = 0; c < r->n_combos; c++) {
        if (c)
            fputs(", ", f);
        json_combination(f, r, c);
    }
    fputc(']', f);
    json_rows(f, r);
    int b = best_combo(r);
    fprintf(f, ", \"best\": {\"estimator\": \"%s\", \"sampling\": \"%s\", \"sampler\": \"%s\", \"medium_grad\": \"%s\", "
               "\"max_depth\": %d, \"spp\": %d", r->combos[b].est->name, dr_sampling_name(r->combos[b].sampling),
            dr_sampler_kind_name(r->combos[b].sampler), dr_medium_grad_name(r->combos[b].medium_grad),
            r->combos[b].max_depth, r->combos[b].spp);
    json_key_number(f, "efficiency", cmp_efficiency(r, b));
    fputc('}', f);
    json_key_number(f, "seconds_total", r->t_total);
    fputs("}\n", f);
}

/* A paragraph: lead, the comma-separated list csv with ", " between its
 * items, then tail. */
static void report_list(FILE *f, const char *lead, const char *csv, const char *tail)
{
    fputs(lead, f);
    for (const char *c = csv; *c; c++)
        if (*c == ',')
            fputs(", ", f);
        else
            fputc(*c, f);
    fprintf(f, "%s\n\n", tail);
}

/* ---- report.md ---- */

static bool series_start(const struct cmp_run *r, int c);
static bool same_series(const struct cmp_combo *a, const struct cmp_combo *b);

static void bytes_text(uint64_t b, char *buf, size_t size)
{
    if (b >= (1ull << 30))
        snprintf(buf, size, "%.2f GiB", b / 1073741824.0);
    else if (b >= (1ull << 20))
        snprintf(buf, size, "%.1f MiB", b / 1048576.0);
    else if (b >= 1024)
        snprintf(buf, size, "%.1f KiB", b / 1024.0);
    else
        snprintf(buf, size, "%llu B", (unsigned long long)b);
}

static void report_head(FILE *f, const struct cmp_run *r)
{
    const struct cmp_args *a = r->a;
    const struct cmp_reference *ref = &r->ref;
    fprintf(f, "# drender compare: %s\n\n", r->scene_path);
    if (r->reverse && a->cross)
        fprintf(f, "Reverse mode: d loss / d parameters, loss %s against %s, every run its own primal (--primal "
                   "cross, as grad: each sample weighted at the loss's adjoint at the mean of its pixel's other "
                   "samples, under sobol of the other half), so the errors include the primal's noise. ",
                r->fp.loss, a->target);
    else if (r->reverse)
        fprintf(f, "Reverse mode: d loss / d parameters, loss %s against %s (adjoint from one %d spp primal "
                   "image shared by every run). ", r->fp.loss, a->target, r->fp.primal_spp);
    else
        fprintf(f, "Forward mode: d image / d parameter (all of a parameter's components at once); errors are "
                   "over image pixels. ");
    fprintf(f, "Image %dx%d, Russian roulette from depth %d, seed %llu. Each run is %d independent estimates of "
               "SPP samples per pixel; its time, rays and error are those of one estimate.",
            a->g.width, a->g.height, a->g.rr_depth, (unsigned long long)a->g.seed, a->batches);
    fprintf(f, " Film: %s.", r->fp.film);
    fprintf(f, "\n\nParameters:");
    for (int k = 0; k < r->ps->n; k++)
        fprintf(f, "%s `%s` (%lld)", k ? "," : "", r->ps->params[k].name, (long long)r->ps->params[k].size);
    fprintf(f, ".\n\n**Reference:** %s", ref->kind);
    if (ref->estimator[0])
        fprintf(f, " (%s %s", ref->estimator, ref->sampling);
    else
        fprintf(f, " (finite differences, common random numbers, step %g", ref->eps);
    fprintf(f, ", %d batches of %d spp at max depth %d, %.3g s)%s%s. Its own relative standard error is "
               "**%.3g**: errors near it are not resolved.\n\n",
            ref->batches, ref->spp, r->fp.max_depth, ref->seconds, ref->file[0] ? ", read from " : "", ref->file,
            ref->rel_se);
    if (r->skipped[0])   /* "prb attached,tape attached" */
        report_list(f, "Left out (the estimator does not support the sampling mode): ", r->skipped, ".");
    if (r->as_detached[0])   /* "attached,mis" */
        report_list(f,
                    "Left out of the default modes, as they would run as detached sampling on these parameters (no "
                    "parameter enters a sampling map, or none is one derivative sampling samples for): ",
                    r->as_detached, ". `--sampling` runs them anyway.");
}

/* Where DRT took each differentiated medium's scattering gain (the first
 * DRT combination's choices: every run of one depth chooses alike), if any. */
static void report_media_gain(FILE *f, const struct cmp_run *r)
{
    for (int c = 0; c < r->n_combos; c++) {
        const struct cmp_result *res = &r->results[c];
        if (res->n_media_gain == 0)
            continue;
        fprintf(f, "**Media (drt, max depth %d):** the scattering a change of extinction adds is taken",
                r->combos[c].max_depth);
        for (int i = 0; i < res->n_media_gain; i++) {
            const struct dr_medium_gain_choice *g = &res->media_gain[i];
            char medium[64];
            dr_medium_param_prefix(g->material, medium, sizeof medium);
            fprintf(f, "%s in `%s` from %s (%s", i ? ";" : "", medium,
                    g->collisions ? "the path's collisions" : "gain paths", dr_gain_reason_name(g->why));
            if (g->why == DR_GAIN_PILOT)
                fprintf(f, ": %llu of %llu stretches collided", (unsigned long long)g->collided,
                        (unsigned long long)g->stretches);
            fprintf(f, ")%s", g->grid && g->collisions ? ", its voxels' from gain paths" : "");
        }
        fprintf(f, " (see --medium-grad in drender(1)).\n\n");
        return;
    }
}

/* The tables' sampling cell: the mode, and the media method when the
 * comparison lists both. */
static const char *sampling_cell(const struct cmp_run *r, const struct cmp_combo *cb, char *buf, size_t size)
{
    if (r->a->n_medium_grads < 2)
        return dr_sampling_name(cb->sampling);
    snprintf(buf, size, "%s (media %s)", dr_sampling_name(cb->sampling), dr_medium_grad_name(cb->medium_grad));
    return buf;
}

static void report_table(FILE *f, const struct cmp_run *r)
{
    fprintf(f, "| estimator | sampling | sampler | max depth | spp | time / estimate (s)%s | rays | memory | tape "
               "records | rel. error | rel. variance | efficiency |\n"
               "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
            r->a->repeat > 1 ? ", median (min–max)" : "");
    for (int c = 0; c < r->n_combos; c++) {
        const struct cmp_combo *cb = &r->combos[c];
        const struct cmp_result *res = &r->results[c];
        double med, lo, hi;
        cmp_seconds_spread(r, c, &med, &lo, &hi);
        char mem[32], rec[32], t[64], smp[64];
        bytes_text(res->memory_bytes, mem, sizeof mem);
        bytes_text(res->record_bytes, rec, sizeof rec);
        if (r->a->repeat > 1)
            snprintf(t, sizeof t, "%.4g (%.4g–%.4g)", med, lo, hi);
        else
            snprintf(t, sizeof t, "%.4g", med);
        fprintf(f, "| %s | %s | %s | %d | %d | %s | %.3g | %s | %s | %.3g | %.3g | %.4g |\n", cb->est->name,
                sampling_cell(r, cb, smp, sizeof smp), dr_sampler_kind_name(cb->sampler), cb->max_depth, cb->spp, t,
                res->rays, mem, rec, res->rel_error, res->rel_variance, efficiency_at(res, med));
    }
    fputc('\n', f);
}

static void report_params(FILE *f, const struct cmp_run *r)
{
    fprintf(f, "## Per parameter (largest spp and max depth)\n\n%s\n\n"
               "| estimator | sampling | sampler | parameter | estimate ± standard error | reference ± standard "
               "error | rel. error | rel. variance | efficiency |\n|---|---|---|---|---|---|---:|---:|---:|\n",
            r->reverse ? "Colours and scalars component by component; textures by the norm of their gradient. The "
                         "table above mixes all components, so its error follows the largest gradients."
                       : "The derivative image's mean over pixels; the error is over every pixel.");
    for (int c = 0; c < r->n_combos; c++) {
        const struct cmp_combo *cb = &r->combos[c];
        if (cb->spp != r->a->spps[r->a->n_spps - 1] || cb->max_depth != r->a->depths[r->a->n_depths - 1])
            continue;
        char smp[64];
        for (int k = 0; k < r->ps->n; k++) {
            const struct cmp_param_result *pr = &r->results[c].params[k];
            fprintf(f, "| %s | %s | %s | `%s`%s | ", cb->est->name, sampling_cell(r, cb, smp, sizeof smp),
                    dr_sampler_kind_name(cb->sampler), r->ps->params[k].name,
                    strcmp(summary_kind(r, k), "norm") == 0 ? " (norm)" : "");
            for (int i = 0; i < pr->n; i++)
                fprintf(f, "%s%.4g ± %.2g", i ? ", " : "", pr->value[i], pr->se[i]);
            fputs(" | ", f);
            for (int i = 0; i < pr->n; i++)
                fprintf(f, "%s%.4g ± %.2g", i ? ", " : "", pr->ref[i], pr->ref_se[i]);
            fprintf(f, " | %.3g | %.3g | %.4g |\n", pr->rel_error, pr->rel_variance, cmp_param_efficiency(r, c, k));
        }
    }
    fputc('\n', f);
}

/* Least-squares slope of log(error) against log(spp) of the combinations
 * sharing c's estimator, sampling, sampler and depth (-0.5: Monte Carlo as
 * usual; steeper for stratified and Sobol numbers on smooth integrands). */
static double error_slope(const struct cmp_run *r, int c)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int n = 0;
    for (int i = 0; i < r->n_combos; i++) {
        const struct cmp_combo *a = &r->combos[i], *b = &r->combos[c];
        double e = r->results[i].rel_error;
        if (!same_series(a, b) || !(e > 0.0))
            continue;
        double x = log((double)a->spp), y = log(e);
        sx += x, sy += y, sxx += x * x, sxy += x * y, n++;
    }
    double d = n * sxx - sx * sx;
    return n >= 2 && d > 0.0 ? (n * sxy - sx * sy) / d : NAN;
}

/* Median over spp of the efficiency of the series starting at c (one
 * estimate of it per spp: steadier than any single cell). */
static double median_efficiency(const struct cmp_run *r, int c)
{
    double e[CMP_MAX_LIST];
    int n = 0;
    for (int i = c; i < r->n_combos && same_series(&r->combos[i], &r->combos[c]); i++)
        if (isfinite(cmp_efficiency(r, i)))
            e[n++] = cmp_efficiency(r, i);
    if (n == 0)
        return NAN;
    qsort(e, (size_t)n, sizeof(double), cmp_double);
    return n % 2 ? e[n / 2] : 0.5 * (e[n / 2 - 1] + e[n / 2]);
}

/* "At max depth D, median efficiency over spp: prb detached X, tape detached
 * Y (Y/X)": the ranking of estimators, once per depth. */
static void report_median_efficiency(FILE *f, const struct cmp_run *r)
{
    for (int d = 0; d < r->a->n_depths; d++) {
        double first = NAN;
        fprintf(f, "- Max depth %d, median efficiency over spp:", r->a->depths[d]);
        for (int c = 0, k = 0; c < r->n_combos; c++) {
            if (!series_start(r, c) || r->combos[c].max_depth != r->a->depths[d])
                continue;
            double e = median_efficiency(r, c);
            if (k == 0)
                first = e;
            char pair[96];
            cmp_pair_label(r, &r->combos[c], pair, sizeof pair);
            fprintf(f, "%s %s %.4g", k++ ? "," : "", pair, e);
            if (k > 1)
                fprintf(f, " (%.2fx the first)", e / first);
        }
        fprintf(f, ".\n");
    }
}

/* Sentences the table supports: most efficient, least memory, convergence. */
static void report_reading(FILE *f, const struct cmp_run *r)
{
    fprintf(f, "## Reading it\n\n");
    int best = best_combo(r);
    char label[128];
    cmp_combo_label(r, &r->combos[best], label, sizeof label);
    /* (the cross primal's variance has a part in 1 / spp^2, the product of
     * the adjoint's noise and the derivative's: its efficiency grows with
     * spp until the 1 / spp part dominates) */
    fprintf(f, "- Most accuracy per second: **%s at %d spp** (efficiency %.4g = 1 / (relative variance x "
               "seconds)); %s\n",
            label, r->combos[best].spp, cmp_efficiency(r, best),
            r->a->cross ? "with the cross primal efficiency grows with spp (the adjoint's noise shrinks with the "
                          "samples it averages), so compare estimators at the spp per batch you will run."
                        : "efficiency hardly depends on spp, so compare estimators by it and pick spp for the "
                          "error you need.");
    report_median_efficiency(f, r);
    fprintf(f, "- `grad` and `optimize` without `--sampling` (auto, prb) would run **%s** sampling here%s%s%s.\n",
            r->auto_sampling, r->auto_why[0] ? " (" : "", r->auto_why, r->auto_why[0] ? ")" : "");
    for (int d = 0; d < r->a->n_depths; d++) {
        int lo = -1, hi = -1;
        for (int c = 0; c < r->n_combos; c++) {
            if (r->combos[c].max_depth != r->a->depths[d])
                continue;
            if (lo < 0 || r->results[c].memory_bytes < r->results[lo].memory_bytes)
                lo = c;
            if (hi < 0 || r->results[c].memory_bytes > r->results[hi].memory_bytes)
                hi = c;
        }
        char m1[32], m2[32], p1[96], p2[96];
        bytes_text(r->results[lo].memory_bytes, m1, sizeof m1);
        bytes_text(r->results[hi].memory_bytes, m2, sizeof m2);
        cmp_pair_label(r, &r->combos[lo], p1, sizeof p1);
        cmp_pair_label(r, &r->combos[hi], p2, sizeof p2);
        fprintf(f, "- Max depth %d: least memory %s (%s), most %s (%s).\n", r->a->depths[d], p1, m1, p2, m2);
    }
    for (int c = 0; c < r->n_combos; c++) {
        if (r->combos[c].spp != r->a->spps[0])
            continue;
        cmp_combo_label(r, &r->combos[c], label, sizeof label);
        fprintf(f, "- %s: error ~ spp^%.2f (Monte Carlo: -0.5; flatter once the error meets the reference's or "
                   "a depth bias).\n", label, error_slope(r, c));
    }
    fprintf(f, "\n![error vs time](error_vs_time.png)\n\n![memory vs max depth](memory_vs_depth.png)\n\n"
               "![efficiency](efficiency.png)\n");
}

int cmp_write_report(const struct cmp_run *r, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return -1;
    report_head(f, r);
    report_media_gain(f, r);
    report_table(f, r);
    report_params(f, r);
    report_reading(f, r);
    return cli_fclose_checked(f);
}

/* ---- plots ---- */

/* Combinations c of one estimator x sampling x sampler x depth "series" (the
 * first of each series is where combos[c].spp is the smallest). */
static bool series_start(const struct cmp_run *r, int c)
{
    return r->combos[c].spp == r->a->spps[0];
}

static bool same_series(const struct cmp_combo *a, const struct cmp_combo *b)
{
    return cmp_same_pair(a, b) && a->max_depth == b->max_depth;
}

/* Which estimator x sampling (x sampler) pair combination c belongs to,
 * counted in the order the pairs first appear. */
static int pair_index(const struct cmp_run *r, int c)
{
    int n = 0;
    for (int i = 0; i < c; i++)
        if (series_start(r, i) && r->combos[i].max_depth == r->a->depths[0] &&
            !cmp_same_pair(&r->combos[i], &r->combos[c]))
            n++;
    return n;
}

static void plot_error_vs_time(FILE *g, const struct cmp_run *r)
{
    int s = 0;
    for (int c = 0; c < r->n_combos; c++) {
        if (!series_start(r, c))
            continue;
        fprintf(g, "$err%d << EOD\n", s++);
        for (int i = c; i < r->n_combos && same_series(&r->combos[i], &r->combos[c]); i++) {
            double med, lo, hi;
            cmp_seconds_spread(r, i, &med, &lo, &hi);
            if (med > 0.0 && r->results[i].rel_error > 0.0)
                fprintf(g, "%.6g %.6g %d\n", med, r->results[i].rel_error, r->combos[i].spp);
        }
        fprintf(g, "EOD\n");
    }
    fprintf(g, "set output out.'error_vs_time.png'\nset title 'Error vs time (reference %s, its own relative error "
               "%.2g)'\nset xlabel 'seconds per estimate'\nset ylabel 'relative RMS error'\nset logscale xy\n"
               "set key outside right top\nset grid\nplot ", r->ref.kind, r->ref.rel_se);
    /* colour = estimator x sampling, point and dash = depth, each keyed once
     * (one key entry per series made the legend as large as the plot); spp
     * labels on the deepest series only, so the plot stays readable */
    static const int pts[] = {7, 5, 9, 11, 13, 15};
    s = 0;
    int pairs = 0;
    for (int c = 0; c < r->n_combos; c++) {
        if (!series_start(r, c))
            continue;
        int depth_i = 0;
        while (r->a->depths[depth_i] != r->combos[c].max_depth)
            depth_i++;
        int pair = pair_index(r, c);
        if (pair == pairs) {   /* the first series of a new pair: its colour's key entry */
            char label[128];
            cmp_pair_label(r, &r->combos[c], label, sizeof label);
            fprintf(g, "NaN with lines lw 2 lc %d title '%s', ", pair + 1, label);
            pairs++;
        }
        fprintf(g, "$err%d using 1:2 with linespoints lw 2 lc %d pt %d dt %d notitle, ", s, pair + 1,
                pts[depth_i % 6], depth_i % 5 + 1);
        if (depth_i == r->a->n_depths - 1)
            fprintf(g, "$err%d using 1:2:(sprintf('%%d spp', $3)) with labels offset 0,0.9 font ',8' tc lt %d "
                       "notitle, ", s, pair + 1);
        s++;
    }
    for (int d = 0; d < r->a->n_depths; d++)   /* the depths' key entries */
        fprintf(g, "NaN with linespoints lw 2 lc 'gray40' pt %d dt %d title 'max depth %d', ", pts[d % 6], d % 5 + 1,
                r->a->depths[d]);
    if (isfinite(r->ref.rel_se) && r->ref.rel_se > 0.0)
        fprintf(g, "%.6g with lines dt 2 lc 'black' title \"reference's own error\"\n", r->ref.rel_se);
    else
        fprintf(g, "NaN notitle\n");
    fprintf(g, "unset logscale\nunset title\n");
}

/* Memory against max depth, one line per estimator x sampling (x sampler;
 * the largest over spp: the tape's records do not grow with spp). */
static void plot_memory(FILE *g, const struct cmp_run *r)
{
    int s = 0;
    fprintf(g, "set output out.'memory_vs_depth.png'\nset title 'Estimator memory vs max depth'\n"
               "set xlabel 'max depth (path segments)'\nset ylabel 'memory (MiB)'\nset logscale y\n"
               "set key outside right top\nset grid\nset xtics (");
    for (int d = 0; d < r->a->n_depths; d++)
        fprintf(g, "%s%d", d ? ", " : "", r->a->depths[d]);
    fprintf(g, ")\nplot ");
    for (int c = 0; c < r->n_combos; c++) {
        if (!series_start(r, c) || r->combos[c].max_depth != r->a->depths[0])
            continue;
        char pair[96];
        cmp_pair_label(r, &r->combos[c], pair, sizeof pair);
        fprintf(g, "%s'-' using 1:2 with linespoints lw 2 pt 7 title '%s'", s++ ? ", " : "", pair);
    }
    fputc('\n', g);
    for (int c = 0; c < r->n_combos; c++) {
        if (!series_start(r, c) || r->combos[c].max_depth != r->a->depths[0])
            continue;
        for (int i = 0; i < r->n_combos; i++) {
            const struct cmp_combo *x = &r->combos[i];
            if (!cmp_same_pair(x, &r->combos[c]) || !series_start(r, i))
                continue;
            uint64_t m = 0;
            for (int j = i; j < r->n_combos && same_series(&r->combos[j], x); j++)
                m = r->results[j].memory_bytes > m ? r->results[j].memory_bytes : m;
            fprintf(g, "%d %.6g\n", x->max_depth, m / 1048576.0);
        }
        fprintf(g, "e\n");
    }
    fprintf(g, "unset logscale\nset xtics autofreq\n");
}

/* Efficiency bars at the largest depth: a cluster per spp, a bar per
 * estimator x sampling. */
static void plot_efficiency(FILE *g, const struct cmp_run *r)
{
    const int dmax = r->a->depths[r->a->n_depths - 1];
    int cols = 0;
    fprintf(g, "$eff << EOD\nspp");
    for (int c = 0; c < r->n_combos; c++)
        if (series_start(r, c) && r->combos[c].max_depth == dmax) {
            char pair[96];
            cmp_pair_label(r, &r->combos[c], pair, sizeof pair);
            fprintf(g, " \"%s\"", pair);
            cols++;
        }
    fputc('\n', g);
    for (int k = 0; k < r->a->n_spps; k++) {
        fprintf(g, "%d", r->a->spps[k]);
        for (int c = 0; c < r->n_combos; c++)
            if (r->combos[c].spp == r->a->spps[k] && r->combos[c].max_depth == dmax) {
                double e = cmp_efficiency(r, c);
                fprintf(g, isfinite(e) && e > 0.0 ? " %.6g" : " NaN", e);
            }
        fputc('\n', g);
    }
    fprintf(g, "EOD\nset output out.'efficiency.png'\nset title \"Efficiency = 1 / (relative variance x seconds), "
               "higher is better\\nmax depth %d, reference %s\"\nset xlabel 'samples per pixel'\nset ylabel 'efficiency (1/s)'\n"
               "set style data histograms\nset style histogram cluster gap 1\nset style fill solid 0.8 border -1\n"
               "set boxwidth 0.9\nset key outside right top\nset grid ytics\nset logscale y\n"
               "plot for [i=2:%d] $eff using i:xtic(1) title columnheader(i)\n",
            dmax, r->ref.kind, cols + 1);
}

/* plots.gp: the three plots, data inline. */
static int write_plot_script(const struct cmp_run *r, const char *path)
{
    FILE *g = fopen(path, "w");
    if (!g) {
        cli_error("compare", "%s: cannot write: %s", path, strerror(errno));
        return DR_EXIT_FAILURE;
    }
    /* out: a prefix of the plots' file names; compare draws them under
     * temporary names (out = '.tmp.') and renames the whole ones */
    fprintf(g, "# drender compare: gnuplot script with its data inline (run: gnuplot plots.gp)\n"
               "if (!exists('out')) out = ''\n"
               "set terminal pngcairo size 900,560 noenhanced\n");
    /* a zero reference leaves errors and efficiencies undefined: those plots are left out */
    bool defined = r->ref.norm2 > 0.0;
    if (defined)
        plot_error_vs_time(g, r);
    plot_memory(g, r);
    if (defined)
        plot_efficiency(g, r);
    if (cli_fclose_checked(g) == 0)
        return 0;
    cli_error("compare", "%s: cannot write: %s", path, strerror(errno));
    return DR_EXIT_FAILURE;
}

/* Runs gnuplot on DIR/plots.gp with the plots' names prefixed by tmp_prefix:
 * false (a warning given) if gnuplot is missing or failed. */
static bool run_gnuplot(const char *dir, const char *tmp_prefix)
{
    char quoted[8800];
    size_t k = 0;
    for (const char *s = dir; *s && k + 2 < sizeof quoted; s++) {
        if (*s == '\'')
            quoted[k++] = '\'';
        quoted[k++] = *s;
    }
    quoted[k] = '\0';
    FILE *g = popen("gnuplot 2>/dev/null", "w");
    if (!g) {
        cli_error("compare", "warning: cannot run gnuplot: plots not drawn (install gnuplot-nox)");
        return false;
    }
    /* gnuplot runs in DIR, so the script's file names are relative to it */
    fprintf(g, "cd '%s'\nout = '%s'\nload 'plots.gp'\n", quoted, tmp_prefix);
    if (pclose(g) != 0) {
        cli_error("compare", "warning: gnuplot failed on %s/plots.gp: plots not drawn (install gnuplot-nox)", dir);
        return false;
    }
    return true;
}

int cmp_write_plots(const struct cmp_run *r, const char *dir)
{
    char path[4400], tmp[4400], why[256];
    static const char *const pngs[] = {"error_vs_time.png", "memory_vs_depth.png", "efficiency.png"};
    for (int i = 0; i < 3; i++) {   /* no stale plot of an earlier run survives a plot left out */
        snprintf(path, sizeof path, "%s/%s", dir, pngs[i]);
        unlink(path);
    }
    snprintf(path, sizeof path, "%s/plots.gp", dir);
    snprintf(tmp, sizeof tmp, "%s/.tmp.plots.gp", dir);
    int rc = write_plot_script(r, tmp);
    if (rc == 0 && rename(tmp, path) != 0) {
        cli_error("compare", "%s: cannot write: %s", path, strerror(errno));
        rc = DR_EXIT_FAILURE;
    }
    if (rc != 0) {
        unlink(tmp);
        return rc;
    }
    const bool drawn = run_gnuplot(dir, ".tmp.");
    /* gnuplot does not tell when a plot could not be written whole (a full
     * disk): a plot that does not end as a PNG ends fails the run */
    for (int i = 0; i < 3; i++) {
        snprintf(tmp, sizeof tmp, "%s/.tmp.%s", dir, pngs[i]);
        snprintf(path, sizeof path, "%s/%s", dir, pngs[i]);
        if (access(tmp, F_OK) != 0)
            continue;   /* (left out: a zero reference) */
        if (drawn && !dr_png_complete(tmp)) {
            cli_error("compare", "%s: cannot write the plot: %s", path, dr_why_cut_short(tmp, why, sizeof why));
            rc = DR_EXIT_FAILURE;
        }
        if (!drawn || rc != 0 || rename(tmp, path) != 0)
            unlink(tmp);
    }
    return rc;
}
