/* drender compare: what accuracy costs in time. Runs every estimator x
 * sampling x sampler x max depth x spp combination on one scene and parameter set,
 * measures time, rays and memory, and the error of each against a reference
 * (a high-sample estimate, finite differences, or a file of an earlier run);
 * writes a table, a report and plots (compare_output.c). */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"
#include "compare.h"
#include "error.h"
#include "fdcheck.h"
#include "image.h"
#include "mem_limits.h"
#include "render.h"
#include "sampler.h"

/* Random-number streams independent of every run's (seed + 1 + batch). */
#define REF_SEED_SALT 0x5245464552454eULL   /* "REFEREN" */
#define PRIMAL_SEED 0x5052494d414cULL        /* "PRIMAL": fixed, so a reference file fits any --seed */
#define PRIMAL_SPP 256
#define DEFAULT_RES 64

static void sampling_list(const struct dr_estimator_ops *e, char *buf, size_t size)
{
    buf[0] = '\0';
    for (int s = 0; s < DR_SAMPLING_COUNT; s++)
        if (dr_estimator_supports(e, (enum dr_sampling)s)) {
            size_t len = strlen(buf);
            snprintf(buf + len, size - len, "%s%s", len ? ", " : "", dr_sampling_name((enum dr_sampling)s));
        }
    if (!buf[0])
        snprintf(buf, size, "none");
}

/* "prb (detached), tape (detached)": what the registry offers right now. */
static void available_pairs(char *buf, size_t size, const char *sep)
{
    buf[0] = '\0';
    for (int i = 0; dr_estimators[i]; i++) {
        char modes[128];
        sampling_list(dr_estimators[i], modes, sizeof modes);
        size_t len = strlen(buf);
        snprintf(buf + len, size - len, "%s%s (%s)", i ? sep : "", dr_estimators[i]->name, modes);
    }
}

/* Appends to buf (size bytes, *len used) what fmt says, cut at the end of buf. */
static void append(char *buf, size_t size, size_t *len, const char *fmt, ...)
{
    if (*len + 1 >= size)
        return;
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf + *len, size - *len, fmt, ap);
    va_end(ap);
    if (n > 0)
        *len = *len + (size_t)n < size ? *len + (size_t)n : size - 1;
}

/* The same for the help text: "available now: prb (detached, ...)," one
 * estimator a line, wrapped at 80 columns under the modes. */
static void available_pairs_help(char *buf, size_t size)
{
    enum { INDENT = 22, WIDTH = 80 };
    static const char lead[] = "available now: ";
    size_t len = 0;
    buf[0] = '\0';
    for (int i = 0; dr_estimators[i]; i++) {
        const struct dr_estimator_ops *e = dr_estimators[i];
        const int hang = INDENT + (i == 0 ? (int)strlen(lead) : 0) + (int)strlen(e->name) + 2;   /* under the modes */
        append(buf, size, &len, "%*s%s%s (", INDENT, "", i == 0 ? lead : "", e->name);
        int col = hang, last = -1;
        for (int s = 0; s < DR_SAMPLING_COUNT; s++)
            if (dr_estimator_supports(e, (enum dr_sampling)s))
                last = s;
        for (int s = 0; s <= last; s++) {
            if (!dr_estimator_supports(e, (enum dr_sampling)s))
                continue;
            const char *mode = dr_sampling_name((enum dr_sampling)s);
            /* "mode," or, last, "mode)" and the comma before the next estimator */
            const int w = (int)strlen(mode) + 1 + (s == last && dr_estimators[i + 1]);
            if (col > hang && col + 1 + w > WIDTH) {
                append(buf, size, &len, "\n%*s", hang, "");
                col = hang;
            } else if (col > hang) {
                append(buf, size, &len, " ");
                col++;
            }
            append(buf, size, &len, "%s%s", mode, s == last ? "" : ",");
            col += w;
        }
        append(buf, size, &len, ")%s\n", dr_estimators[i + 1] ? "," : "");
    }
}

/* The help text: one string, long by nature (no logic). */
void cmd_compare_usage(FILE *out)
{
    char pairs[1024];
    available_pairs_help(pairs, sizeof pairs);
    fprintf(out,
            "usage: drender compare [SCENE] --param P [--param P ...] -o DIR [options]\n"
            "\n"
            "What accuracy costs in time: runs every estimator x sampling x sampler x max\n"
            "depth x spp combination on SCENE (default: the bundled Cornell box) and\n"
            "measures, per run, wall time, rays, memory, the gradient +- standard error per\n"
            "parameter, its error against a reference and the efficiency 1 / (relative\n"
            "variance x seconds), in all and per parameter.\n"
            "With --target, runs differentiate the loss (reverse mode; one primal image of\n"
            "%d spp gives every run the same adjoint, or with --primal cross each run is\n"
            "its own primal, as in grad); without, they compute d image / d parameter\n"
            "(forward mode) and errors are over image pixels. Each run is --batches\n"
            "independent estimates with N spp each (seeds S+1 .. S+K).\n"
            "\n"
            "Writes DIR/results.csv, results.json, report.md, reference.txt, plots.gp and\n"
            "the gnuplot plots error_vs_time.png, memory_vs_depth.png, efficiency.png.\n"
            "\n"
            "options:\n"
            "  -o, --output-dir DIR  where the results go (created if missing)\n"
            "      --param P       a parameter (repeatable, required)\n"
            "      --set P=V[,V...]  use these values for parameter P instead of the file's\n"
            "      --estimators L  comma-separated estimators (default: every one)\n"
            "      --sampling L    comma-separated sampling modes (default: every one an\n"
            "                      estimator supports, but those that would run as detached\n"
            "                      on these parameters; naming both lists asks for every\n"
            "                      pair)\n"
            "%s"
            "      --spp L         samples per pixel of one estimate (default: 1,4,16,64)\n"
            "      --max-depth L   path segments (default: 8); errors are against a\n"
            "                      reference at the largest, so shorter paths show their bias\n"
            "      --reference R   spp:N  N spp per batch from the first estimator and\n"
            "                             sampling listed (default: 16 x the largest --spp)\n"
            "                      fd[:N] finite differences, N spp per batch, common random\n"
            "                             numbers, step --eps (not for texture gradients)\n"
            "                      FILE   reference.txt of an earlier run (same scene,\n"
            "                             parameters, mode and settings, else refused)\n"
            "      --target IMG    reverse mode: the image to match (sets the default size)\n"
            "      --loss L        reverse mode: l1 or l2 (default: l2)\n",
            PRIMAL_SPP, pairs);
    fprintf(out,   /* (two strings: each within what C99 compilers must accept) */
            "      --primal M      reverse mode: where the loss's adjoint comes from: shared\n"
            "                      (default: the one primal image above; runs then differ in\n"
            "                      their derivative noise alone) or cross (each sample\n"
            "                      weighted at the mean of its pixel's other samples, sobol:\n"
            "                      of the other half, as grad and optimize run by default:\n"
            "                      primal noise included, so the samplers compare as grad\n"
            "                      would gain; needs every --spp >= 2, the independent or\n"
            "                      sobol sampler and a reference of spp:N or a file)\n"
            "      --batches K     independent estimates per run and for the reference\n"
            "                      (default: 4, at least 2)\n"
            "      --repeat K      run each combination K times (same random numbers) and\n"
            "                      report the spread of the timings (default: 1)\n"
            "      --eps E         finite-difference step of --reference fd (default: 1e-2)\n"
            "      --res WxH       image size (default: the target's, else %dx%d)\n"
            "      --rr-depth D    Russian roulette from this many segments on (default: 5)\n"
            "      --camera N      which camera of the file (default: 0)\n"
            "      --seed S        random seed (default: 0); the same seed gives the same\n"
            "                      table\n"
            "      --threads T     worker threads (default: one per CPU)\n"
            "      --filter F      pixel filter: box (default), tent or gaussian[:STDDEV]\n"
            "      --crop X,Y,W,H  only this rectangle of the --res frame is rendered and\n"
            "                      compared (a full-frame target is cut to it; a crop-sized\n"
            "                      one needs --res)\n"
            "      --sampler L     comma-separated random numbers: independent (default),\n"
            "                      stratified, sobol (as render); every combination runs\n"
            "                      with each, the reference with the first\n"
            "      --medium-grad L comma-separated media derivative methods: drt (default),\n"
            "                      baseline (as grad); with both, every combination runs\n"
            "                      with each (the reference: drt, unbiased in every medium)\n"
            GRAD_IGNORE_UNSUPPORTED_HELP
            "      --json          print results.json on stdout too\n"
            "  -h, --help          show this help\n",
            DEFAULT_RES, DEFAULT_RES);
    grad_lighting_usage(out);
}

enum {
    OPT_ESTS = GOPT_END,
    OPT_SAMPLINGS,
    OPT_SPPS,
    OPT_DEPTHS,
    OPT_REFERENCE,
    OPT_TARGET,
    OPT_LOSS,
    OPT_BATCHES,
    OPT_REPEAT,
    OPT_EPS,
    OPT_SAMPLERS,
    OPT_PRIMAL,
    OPT_MEDIUM_GRADS,
};

/* ---- options ---- */

/* Splits "a,b,c" into at most `max` items (each handed to `one`). */
static int split_list(const char *opt, const char *text, int max, int (*one)(struct cmp_args *, const char *),
                      struct cmp_args *a)
{
    char buf[512];
    if (snprintf(buf, sizeof buf, "%s", text) >= (int)sizeof buf || !text[0]) {
        cli_error("compare", "%s '%s': expected a comma-separated list", opt, text);
        return DR_EXIT_USAGE;
    }
    int n = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (++n > max) {
            cli_error("compare", "%s: at most %d values", opt, max);
            return DR_EXIT_USAGE;
        }
        int rc = one(a, tok);
        if (rc >= 0)
            return rc;
    }
    return -1;
}

static int one_estimator(struct cmp_args *a, const char *name)
{
    const struct dr_estimator_ops *e = dr_estimator_find(name);
    if (!e) {
        char pairs[512];
        available_pairs(pairs, sizeof pairs, ", ");
        cli_error("compare", "--estimators: unknown estimator '%s' (available: %s)", name, pairs);
        return DR_EXIT_USAGE;
    }
    for (int i = 0; i < a->n_ests; i++)
        if (a->ests[i] == e) {
            cli_error("compare", "--estimators: '%s' is listed twice", name);
            return DR_EXIT_USAGE;
        }
    a->ests[a->n_ests++] = e;
    return -1;
}

static int one_sampling(struct cmp_args *a, const char *name)
{
    int s = dr_sampling_parse(name);
    if (s < 0) {
        char known[128] = "";
        for (int i = 0; i < DR_SAMPLING_COUNT; i++) {
            size_t len = strlen(known);
            snprintf(known + len, sizeof known - len, "%s%s", i ? ", " : "", dr_sampling_name((enum dr_sampling)i));
        }
        cli_error("compare", "--sampling: unknown sampling mode '%s' (known: %s)", name, known);
        return DR_EXIT_USAGE;
    }
    for (int i = 0; i < a->n_samplings; i++)
        if ((int)a->samplings[i] == s) {
            cli_error("compare", "--sampling: '%s' is listed twice", name);
            return DR_EXIT_USAGE;
        }
    a->samplings[a->n_samplings++] = (enum dr_sampling)s;
    return -1;
}

static int one_sampler(struct cmp_args *a, const char *name)
{
    int k = dr_sampler_kind_parse(name);
    if (k < 0) {
        cli_error("compare", "--sampler: unknown sampler '%s' (known: independent, stratified, sobol)", name);
        return DR_EXIT_USAGE;
    }
    for (int i = 0; i < a->n_samplers; i++)
        if ((int)a->samplers[i] == k) {
            cli_error("compare", "--sampler: '%s' is listed twice", name);
            return DR_EXIT_USAGE;
        }
    a->samplers[a->n_samplers++] = (enum dr_sampler_kind)k;
    a->g.sampler = a->samplers[0];   /* the reference's, and the one --json's "sampler" names */
    return -1;
}

static int one_medium_grad(struct cmp_args *a, const char *name)
{
    int m = dr_medium_grad_parse(name);
    if (m < 0) {
        cli_error("compare", "--medium-grad: unknown method '%s' (known: drt, baseline)", name);
        return DR_EXIT_USAGE;
    }
    for (int i = 0; i < a->n_medium_grads; i++)
        if ((int)a->medium_grads[i] == m) {
            cli_error("compare", "--medium-grad: '%s' is listed twice", name);
            return DR_EXIT_USAGE;
        }
    a->medium_grads[a->n_medium_grads++] = (enum dr_medium_grad)m;
    return -1;
}

/* An ascending list of distinct integers in [lo, hi]. */
static int int_list(const char *opt, const char *text, long lo, long hi, int *vals, int *n)
{
    char buf[512];
    if (snprintf(buf, sizeof buf, "%s", text) >= (int)sizeof buf || !text[0]) {
        cli_error("compare", "%s '%s': expected a comma-separated list of numbers", opt, text);
        return DR_EXIT_USAGE;
    }
    *n = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        long v;
        if (*n >= CMP_MAX_LIST) {
            cli_error("compare", "%s: at most %d values", opt, CMP_MAX_LIST);
            return DR_EXIT_USAGE;
        }
        if (!cli_parse_int("compare", opt, tok, lo, hi, &v))
            return DR_EXIT_USAGE;
        int k = *n;
        for (int i = 0; i < *n; i++)
            if (vals[i] == (int)v) {
                cli_error("compare", "%s: %ld is listed twice", opt, v);
                return DR_EXIT_USAGE;
            }
        while (k > 0 && vals[k - 1] > v) {   /* insertion keeps the list ascending */
            vals[k] = vals[k - 1];
            k--;
        }
        vals[k] = (int)v;
        (*n)++;
    }
    return -1;
}

/* --reference spp:N | fd[:N] | FILE */
static int parse_reference(struct cmp_args *a, const char *text)
{
    long v;
    a->reference = text;
    a->ref_spp = 0;
    if (strncmp(text, "spp:", 4) == 0) {
        a->ref_kind = CMP_REF_SPP;
        if (!cli_parse_int("compare", "--reference spp:N", text + 4, 1, 1L << 24, &v))
            return DR_EXIT_USAGE;
        a->ref_spp = (int)v;
    } else if (strcmp(text, "fd") == 0 || strncmp(text, "fd:", 3) == 0) {
        a->ref_kind = CMP_REF_FD;
        if (text[2] == ':') {
            if (!cli_parse_int("compare", "--reference fd:N", text + 3, 1, 1L << 24, &v))
                return DR_EXIT_USAGE;
            a->ref_spp = (int)v;
        }
    } else {
        a->ref_kind = CMP_REF_FILE;
        if (access(text, R_OK) != 0) {
            cli_error("compare", "--reference %s: %s (expected spp:N, fd[:N] or a reference.txt of an earlier run)",
                      text, strerror(errno));
            return DR_EXIT_INPUT;
        }
    }
    return 0;
}

static int own_option(void *ctx, int c, const char *arg)
{
    struct cmp_args *a = ctx;
    long v;
    switch (c) {
    case 'o': a->out_dir = arg; return 0;
    case OPT_ESTS:
        a->n_ests = 0;
        a->est_given = true;
        return split_list("--estimators", arg, CMP_MAX_LIST, one_estimator, a) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_SAMPLINGS:
        a->n_samplings = 0;
        a->sampling_given = true;
        return split_list("--sampling", arg, DR_SAMPLING_COUNT, one_sampling, a) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_SAMPLERS:
        a->n_samplers = 0;
        return split_list("--sampler", arg, CMP_MAX_SAMPLERS, one_sampler, a) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_MEDIUM_GRADS:
        a->n_medium_grads = 0;
        return split_list("--medium-grad", arg, 2, one_medium_grad, a) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_SPPS:
        a->spp_given = true;
        return int_list("--spp", arg, 1, 1L << 24, a->spps, &a->n_spps) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_DEPTHS: return int_list("--max-depth", arg, 1, 100000, a->depths, &a->n_depths) >= 0 ? DR_EXIT_USAGE : 0;
    case OPT_REFERENCE: return parse_reference(a, arg);
    case OPT_TARGET: a->target = arg; return 0;
    case OPT_LOSS: {
        int k = dr_loss_parse(arg);
        if (k < 0) {
            cli_error("compare", "--loss: unknown loss '%s' (available: l1, l2)", arg);
            return DR_EXIT_USAGE;
        }
        a->loss = (enum dr_loss_kind)k;
        a->loss_given = true;
        return 0;
    }
    case OPT_PRIMAL:
        if (strcmp(arg, "shared") != 0 && strcmp(arg, "cross") != 0) {
            cli_error("compare", "--primal: unknown mode '%s' (known: shared, cross)", arg);
            return DR_EXIT_USAGE;
        }
        a->cross = strcmp(arg, "cross") == 0;
        return 0;
    case OPT_BATCHES:
        if (!cli_parse_int("compare", "--batches", arg, 2, 1 << 16, &v)) return DR_EXIT_USAGE;
        a->batches = (int)v;
        return 0;
    case OPT_REPEAT:
        if (!cli_parse_int("compare", "--repeat", arg, 1, 1000, &v)) return DR_EXIT_USAGE;
        a->repeat = (int)v;
        return 0;
    case OPT_EPS:
        if (!cli_parse_double("compare", "--eps", arg, 0.0, &a->eps)) return DR_EXIT_USAGE;
        return 0;
    default: return -1;
    }
}

static int parse_args(int argc, char **argv, struct cmp_args *a)
{
    static const struct option opts[] = {
        {"param", required_argument, NULL, GOPT_PARAM},
        {"set", required_argument, NULL, GOPT_SET},
        {"rr-depth", required_argument, NULL, GOPT_RR_DEPTH},
        {"res", required_argument, NULL, GOPT_RES},
        {"camera", required_argument, NULL, GOPT_CAMERA},
        {"seed", required_argument, NULL, GOPT_SEED},
        {"threads", required_argument, NULL, GOPT_THREADS},
        {"filter", required_argument, NULL, GOPT_FILTER},
        {"crop", required_argument, NULL, GOPT_CROP},
        {"sampler", required_argument, NULL, OPT_SAMPLERS},   /* a list here: compare's own */
        {"medium-grad", required_argument, NULL, OPT_MEDIUM_GRADS},   /* (a list too) */
        {"env", required_argument, NULL, GOPT_ENV},
        {"no-default-light", no_argument, NULL, GOPT_NO_DEFAULT_LIGHT},
        {"light-units", required_argument, NULL, GOPT_LIGHT_UNITS},
        {"ignore-unsupported", no_argument, NULL, GOPT_IGNORE_UNSUPPORTED},
        {"json", no_argument, NULL, GOPT_JSON},
        {"help", no_argument, NULL, 'h'},
        {"output-dir", required_argument, NULL, 'o'},
        {"estimators", required_argument, NULL, OPT_ESTS},
        {"estimator", required_argument, NULL, OPT_ESTS},
        {"sampling", required_argument, NULL, OPT_SAMPLINGS},
        {"spp", required_argument, NULL, OPT_SPPS},
        {"max-depth", required_argument, NULL, OPT_DEPTHS},
        {"reference", required_argument, NULL, OPT_REFERENCE},
        {"target", required_argument, NULL, OPT_TARGET},
        {"loss", required_argument, NULL, OPT_LOSS},
        {"batches", required_argument, NULL, OPT_BATCHES},
        {"primal", required_argument, NULL, OPT_PRIMAL},
        {"repeat", required_argument, NULL, OPT_REPEAT},
        {"eps", required_argument, NULL, OPT_EPS},
        {NULL, 0, NULL, 0},
    };
    return grad_parse_args(&a->g, argc, argv, opts, "o", own_option, a, cmd_compare_usage);
}

static void args_defaults(struct cmp_args *a)
{
    memset(a, 0, sizeof *a);
    grad_common_init(&a->g, "compare", 0);
    a->g.sampling_auto = false;   /* (compare names its modes: --sampling L) */
    a->loss = DR_LOSS_L2;
    a->batches = 4;
    a->repeat = 1;
    a->eps = 1e-2;
    for (int i = 0; dr_estimators[i] && i < CMP_MAX_LIST; i++)
        a->ests[a->n_ests++] = dr_estimators[i];
    for (int s = 0; s < DR_SAMPLING_COUNT; s++)
        a->samplings[a->n_samplings++] = (enum dr_sampling)s;
    const int spps[] = {1, 4, 16, 64};
    for (int i = 0; i < 4; i++)
        a->spps[a->n_spps++] = spps[i];
    a->depths[a->n_depths++] = 8;
    a->samplers[a->n_samplers++] = DR_SAMPLER_INDEPENDENT;
    a->medium_grads[a->n_medium_grads++] = DR_MEDIUM_GRAD_DRT;
    a->ref_kind = CMP_REF_SPP;
}

/* ---- checks before any work ---- */

/* DIR exists as a writable directory, or can be created (its parent is). */
static int check_out_dir(const char *dir)
{
    struct stat sb;
    if (stat(dir, &sb) == 0) {
        if (!S_ISDIR(sb.st_mode)) {
            cli_error("compare", "-o %s: exists and is not a directory", dir);
            return DR_EXIT_USAGE;
        }
        if (access(dir, W_OK) != 0) {
            cli_error("compare", "-o %s: cannot write into it: %s", dir, strerror(errno));
            return DR_EXIT_FAILURE;
        }
        return -1;
    }
    char trimmed[4096];
    snprintf(trimmed, sizeof trimmed, "%s", dir);
    for (size_t n = strlen(trimmed); n > 1 && trimmed[n - 1] == '/'; n--)
        trimmed[n - 1] = '\0';
    /* created at the end, by mkdir: its parent must exist and take it */
    return cli_output_dir_writable("compare", trimmed) ? -1 : DR_EXIT_FAILURE;
}

/* Every estimator x sampling pair: refused when both were named and the pair
 * does not apply; left out (and listed in the report) otherwise. */
static int build_combos(const struct cmp_args *a, struct cmp_run *r)
{
    r->combos = calloc((size_t)(a->n_ests * a->n_samplings * a->n_medium_grads * a->n_samplers * a->n_depths *
                                a->n_spps),
                       sizeof *r->combos);
    if (!r->combos) {
        cli_error("compare", "out of memory");
        return DR_EXIT_FAILURE;
    }
    for (int e = 0; e < a->n_ests; e++)
        for (int s = 0; s < a->n_samplings; s++) {
            const struct dr_estimator_ops *est = a->ests[e];
            if (!dr_estimator_supports(est, a->samplings[s])) {
                if (a->est_given && a->sampling_given) {
                    char modes[128];
                    sampling_list(est, modes, sizeof modes);
                    cli_error("compare", "--estimators %s --sampling %s: estimator '%s' does not support %s "
                                         "sampling (it supports: %s)", est->name, dr_sampling_name(a->samplings[s]),
                              est->name, dr_sampling_name(a->samplings[s]), modes);
                    return DR_EXIT_USAGE;
                }
                size_t len = strlen(r->skipped);
                snprintf(r->skipped + len, sizeof r->skipped - len, "%s%s %s", len ? "," : "", est->name,
                         dr_sampling_name(a->samplings[s]));
                continue;
            }
            for (int m = 0; m < a->n_medium_grads; m++)
                for (int q = 0; q < a->n_samplers; q++)
                    for (int d = 0; d < a->n_depths; d++)
                        for (int k = 0; k < a->n_spps; k++)
                            r->combos[r->n_combos++] = (struct cmp_combo){
                                est, a->samplings[s], a->depths[d], a->spps[k], a->samplers[q], a->medium_grads[m]};
        }
    if (r->n_combos == 0) {
        char pairs[512];
        available_pairs(pairs, sizeof pairs, ", ");
        cli_error("compare", "no estimator listed supports a sampling mode listed (available: %s)", pairs);
        return DR_EXIT_USAGE;
    }
    return -1;
}

/* Without --sampling, the modes that would run as detached sampling on this
 * problem (attached or mis with no parameter in a sampling map, derivative
 * sampling with none it samples for: dr_est_sampling_run) are left out:
 * they would give detached's numbers for their time. The report lists
 * them; --sampling runs them anyway. */
static void drop_detached_twins(const struct cmp_args *a, struct cmp_run *r, const struct dr_scene *scene)
{
    if (a->sampling_given)
        return;
    bool left_out[DR_SAMPLING_COUNT] = {false};
    int n = 0;
    for (int c = 0; c < r->n_combos; c++) {
        const struct dr_grad_problem p = {.scene = scene, .params = r->ps, .sampling = r->combos[c].sampling};
        if (p.sampling != DR_SAMPLING_DETACHED && dr_est_sampling_run(&p) == DR_SAMPLING_DETACHED)
            left_out[p.sampling] = true;
        else
            r->combos[n++] = r->combos[c];
    }
    r->n_combos = n;
    for (int s = 0; s < DR_SAMPLING_COUNT; s++)
        if (left_out[s]) {
            size_t len = strlen(r->as_detached);
            snprintf(r->as_detached + len, sizeof r->as_detached - len, "%s%s", len ? "," : "",
                     dr_sampling_name((enum dr_sampling)s));
        }
}

/* --primal cross runs what grad's cross primal runs (estimator.h, struct
 * dr_cross_loss): reverse mode, at least 2 samples a pixel, samples of a
 * pixel independent of each other (not the stratified sampler's shared
 * strata). Finite differences take the adjoint at one primal image, a
 * different quantity (the loss's gradient at that image, not at the
 * noise-free one), so their reference does not apply. */
static int check_cross_args(struct cmp_args *a)
{
    if (!a->cross)
        return -1;
    if (!a->target) {
        cli_error("compare", "--primal is for reverse mode: give --target IMG");
        return DR_EXIT_USAGE;
    }
    if (!a->spp_given && a->spps[0] < 2) {   /* the default list without its 1 */
        memmove(a->spps, a->spps + 1, sizeof(int) * (size_t)(a->n_spps - 1));
        a->n_spps--;
    }
    if (a->spps[0] < 2) {
        cli_error("compare", "--primal cross: --spp %d: the cross primal needs at least 2 samples per pixel "
                             "(a sample is weighted at the mean of its pixel's others)", a->spps[0]);
        return DR_EXIT_USAGE;
    }
    for (int q = 0; q < a->n_samplers; q++)
        if (a->samplers[q] == DR_SAMPLER_STRATIFIED) {
            cli_error("compare", "--primal cross: --sampler stratified: a pixel's samples share its strata, so "
                                 "the mean of the others is not independent of a sample (use independent or "
                                 "sobol)");
            return DR_EXIT_USAGE;
        }
    if (a->ref_kind == CMP_REF_SPP && a->ref_spp == 1) {
        cli_error("compare", "--primal cross: --reference spp:1: the cross primal needs at least 2 samples per "
                             "pixel");
        return DR_EXIT_USAGE;
    }
    if (a->ref_kind == CMP_REF_FD) {
        cli_error("compare", "--primal cross: --reference fd differentiates the loss at one primal image, not at "
                             "the noise-free image the cross primal's runs estimate (use --reference spp:N)");
        return DR_EXIT_USAGE;
    }
    return -1;
}

static int check_args(struct cmp_args *a)
{
    if (a->g.n_params == 0) {
        cli_error("compare", "--param is required (at least one; 'drender params SCENE' lists them)");
        return DR_EXIT_USAGE;
    }
    if (!a->out_dir) {
        cli_error("compare", "-o DIR is required (results.csv, results.json, report.md and plots go there)");
        return DR_EXIT_USAGE;
    }
    if (a->loss_given && !a->target) {
        cli_error("compare", "--loss is for reverse mode: give --target IMG");
        return DR_EXIT_USAGE;
    }
    int rc = check_cross_args(a);
    if (rc >= 0)
        return rc;
    if (a->ref_kind == CMP_REF_SPP && a->ref_spp == 0)
        a->ref_spp = 16 * a->spps[a->n_spps - 1];
    if (a->ref_kind == CMP_REF_FD && a->ref_spp == 0)
        a->ref_spp = 4 * a->spps[a->n_spps - 1];
    return check_out_dir(a->out_dir);
}

/* ---- the runs ---- */

/* What the runs share: the scene, the adjoint (reverse mode), scratch. */
struct cmp_ctx {
    struct cmp_run *r;
    struct dr_scene *scene;
    const struct dr_camera *cam;
    float *adj;               /* reverse mode: d loss / d image of the shared primal */
    const float *target;      /* --primal cross: the target (the runs take their adjoints from it) */
    double *cross_img;        /* --primal cross: a run's primal image (w*h*3, unused but required) */
    double *dir, *v, *dimg;   /* direction (T), one estimate (V), an fd image (w*h*3) */
    double *mean, *m2;        /* V: Welford over batches */
    double *seg_mean, *seg_m2, *seg_err2;   /* per parameter */
    bool progress;
    int done, total;
    struct dr_media_plan media_plan;   /* DRT's media pilot, shared by the runs it applies to */
};

static bool is_image_param(const struct dr_param *p)
{
    return p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP;
}

static void tick(struct cmp_ctx *x)
{
    x->done++;
    if (x->progress)
        dr_progress_bar("compare", x->done, x->total);
}

static void stats_add(struct dr_grad_stats *sum, const struct dr_grad_stats *st)
{
    sum->seconds += st->seconds;
    sum->rays.camera += st->rays.camera;
    sum->rays.extension += st->rays.extension;
    sum->rays.shadow += st->rays.shadow;
    sum->invalid_samples += st->invalid_samples;
    if (st->memory_bytes > sum->memory_bytes)
        sum->memory_bytes = st->memory_bytes;
    if (st->record_bytes > sum->record_bytes)
        sum->record_bytes = st->record_bytes;
    if (st->n_media_gain > 0) {   /* (every run of a combination chooses alike) */
        sum->n_media_gain = st->n_media_gain;
        memcpy(sum->media_gain, st->media_gain, sizeof sum->media_gain);
    }
}

/* One estimate of v as combination `how` runs it (stats summed into *sum). */
static int estimate(struct cmp_ctx *x, const struct cmp_combo *how, uint64_t seed, double *v, struct dr_grad_stats *sum)
{
    const struct cmp_run *r = x->r;
    const struct dr_estimator_ops *e = how->est;
    struct grad_common g = r->a->g;
    g.max_depth = how->max_depth;
    g.sampling = how->sampling;
    g.sampler = how->sampler;
    g.medium_grad = how->medium_grad;
    struct dr_grad_problem p = grad_problem(&g, x->scene, x->cam, r->ps, g.width, g.height, how->spp, seed);
    p.media_plan = &x->media_plan;
    struct dr_grad_stats st = {0};
    const struct dr_cross_loss cross = {.loss = r->a->loss, .target = x->target, .scale = 1.0, .image = x->cross_img};
    if (r->reverse) {
        p.cross = r->a->cross ? &cross : NULL;
        if (dr_estimator_backward(e, &p, p.cross ? NULL : x->adj, v, &st) != 0)
            return -1;
        stats_add(sum, &st);
        return 0;
    }
    /* forward mode: each parameter's image along all its components, as
     * many a pass as one keeps apart (dr_forward_per_pass) */
    const int per_pass = dr_forward_per_pass(how->sampling);
    for (int k0 = 0; k0 < r->ps->n; k0 += per_pass) {
        const int count = r->ps->n - k0 < per_pass ? r->ps->n - k0 : per_pass;
        int64_t group_end[DR_FORWARD_MAX];
        double *images[DR_FORWARD_MAX];
        dr_forward_param_groups(r->ps, k0, count, x->dir, group_end);
        for (int k = 0; k < count; k++)
            images[k] = v + r->seg_off[k0 + k];
        memset(&st, 0, sizeof st);
        if (dr_estimator_forward_groups(e, &p, x->dir, count, group_end, images, &st) != 0)
            return -1;
        stats_add(sum, &st);
    }
    return 0;
}

static void welford_reset(struct cmp_ctx *x)
{
    const struct cmp_run *r = x->r;
    memset(x->mean, 0, sizeof(double) * (size_t)r->V);
    memset(x->m2, 0, sizeof(double) * (size_t)r->V);
    memset(x->seg_mean, 0, sizeof(double) * (size_t)r->ps->n);
    memset(x->seg_m2, 0, sizeof(double) * (size_t)r->ps->n);
    memset(x->seg_err2, 0, sizeof(double) * (size_t)r->ps->n);
}

/* Batch b's estimate x->v into the running means, and its squared error
 * per parameter against the reference (when there is one). */
static void welford_add(struct cmp_ctx *x, int b, const double *ref)
{
    const struct cmp_run *r = x->r;
    for (int64_t i = 0; i < r->V; i++) {
        double d = x->v[i] - x->mean[i];
        x->mean[i] += d / (b + 1);
        x->m2[i] += d * (x->v[i] - x->mean[i]);
    }
    for (int k = 0; k < r->ps->n; k++) {
        double s = 0.0, e2 = 0.0;
        for (int64_t i = r->seg_off[k]; i < r->seg_off[k] + r->seg_len[k]; i++) {
            s += x->v[i];
            if (ref)
                e2 += (x->v[i] - ref[i]) * (x->v[i] - ref[i]);
        }
        s /= (double)r->seg_len[k];
        double d = s - x->seg_mean[k];
        x->seg_mean[k] += d / (b + 1);
        x->seg_m2[k] += d * (s - x->seg_mean[k]);
        x->seg_err2[k] += e2;
    }
}

static double seg_norm2(const struct cmp_run *r, int k, const double *v)
{
    double s = 0.0;
    for (int64_t i = r->seg_off[k]; i < r->seg_off[k] + r->seg_len[k]; i++)
        s += v[i] * v[i];
    return s;
}

/* A parameter's estimate and reference, summarised (see compare.h). */
static void summarise_param(const struct cmp_ctx *x, int k, int B, struct cmp_param_result *pr)
{
    const struct cmp_run *r = x->r;
    const struct dr_param *pp = &r->ps->params[k];
    const struct cmp_reference *ref = &r->ref;
    const int64_t off = r->seg_off[k], len = r->seg_len[k];
    double rn2 = seg_norm2(r, k, ref->mean);
    pr->rel_error = rn2 > 0.0 ? sqrt(x->seg_err2[k] / B / rn2) : NAN;
    double var = 0.0;   /* as cmp_result's rel_variance, over this parameter's entries */
    for (int64_t i = off; i < off + len; i++)
        var += x->m2[i] / (B - 1);
    pr->rel_variance = rn2 > 0.0 ? var / rn2 : NAN;
    if (!r->reverse) {   /* the derivative image's mean over pixels */
        pr->n = 1;
        pr->value[0] = x->seg_mean[k];
        pr->se[0] = sqrt(x->seg_m2[k] / (B - 1) / B);
        double m = 0.0, q = 0.0;
        for (int64_t i = off; i < off + len; i++) {
            m += ref->mean[i];
            q += ref->se[i] * ref->se[i];
        }
        pr->ref[0] = m / (double)len;
        pr->ref_se[0] = sqrt(q) / (double)len;
    } else if (is_image_param(pp)) {   /* norms of the gradient and of its standard errors */
        double q = 0.0, rq = 0.0;
        for (int64_t i = off; i < off + len; i++) {
            q += x->m2[i] / (B - 1) / B;
            rq += ref->se[i] * ref->se[i];
        }
        pr->n = 1;
        pr->value[0] = sqrt(seg_norm2(r, k, x->mean));
        pr->se[0] = sqrt(q);
        pr->ref[0] = sqrt(rn2);
        pr->ref_se[0] = sqrt(rq);
    } else {
        pr->n = (int)(len < 3 ? len : 3);
        for (int i = 0; i < pr->n; i++) {
            pr->value[i] = x->mean[off + i];
            pr->se[i] = sqrt(x->m2[off + i] / (B - 1) / B);
            pr->ref[i] = ref->mean[off + i];
            pr->ref_se[i] = ref->se[off + i];
        }
    }
}

/* The errors of combination c from the batches just accumulated. */
static void finish_combo(struct cmp_ctx *x, int c, const struct dr_grad_stats *sum, int B)
{
    struct cmp_run *r = x->r;
    struct cmp_result *res = &r->results[c];
    double err2 = 0.0, var = 0.0;
    for (int k = 0; k < r->ps->n; k++)
        err2 += x->seg_err2[k];
    for (int64_t i = 0; i < r->V; i++)
        var += x->m2[i] / (B - 1);
    const double n2 = r->ref.norm2;
    res->rel_error = n2 > 0.0 ? sqrt(err2 / B / n2) : NAN;
    res->rel_variance = n2 > 0.0 ? var / n2 : NAN;
    res->rays = (double)(sum->rays.camera + sum->rays.extension + sum->rays.shadow) / B;
    res->memory_bytes = sum->memory_bytes;
    res->record_bytes = sum->record_bytes;
    res->invalid = sum->invalid_samples;
    res->n_media_gain = sum->n_media_gain;
    memcpy(res->media_gain, sum->media_gain, sizeof res->media_gain);
    for (int k = 0; k < r->ps->n; k++)
        summarise_param(x, k, B, &res->params[k]);
}

/* Combination c, repeat `rep`: --batches estimates with seeds S+1 ... */
static int run_combo(struct cmp_ctx *x, int c, int rep)
{
    struct cmp_run *r = x->r;
    const struct cmp_combo *cb = &r->combos[c];
    const int B = r->a->batches;
    struct dr_grad_stats sum = {0};
    welford_reset(x);
    for (int b = 0; b < B; b++) {
        if (estimate(x, cb, r->a->g.seed + 1 + (uint64_t)b, x->v, &sum))
            return -1;
        welford_add(x, b, r->ref.mean);
        tick(x);
    }
    r->results[c].seconds[rep] = sum.seconds / B;
    if (rep == 0)
        finish_combo(x, c, &sum, B);
    return 0;
}

/* ---- the reference ---- */

/* One finite-difference estimate of v (common random numbers, seed). */
static int fd_estimate(struct cmp_ctx *x, const struct dr_fd_options *o, uint64_t seed)
{
    const struct cmp_run *r = x->r;
    const size_t n = (size_t)o->width * o->height * 3;
    for (int k = 0; k < r->ps->n; k++) {
        const struct dr_param *pp = &r->ps->params[k];
        /* reverse: one direction per component, contracted with the adjoint;
         * forward: all components at once, the derivative image itself */
        int ndir = r->reverse ? (int)pp->size : 1;
        for (int c = 0; c < ndir; c++) {
            memset(x->dir, 0, sizeof(double) * (size_t)r->ps->total);
            for (int64_t i = 0; i < pp->size; i++)
                x->dir[pp->offset + i] = (!r->reverse || i == c) ? 1.0 : 0.0;
            double *dst = r->reverse ? x->dimg : x->v + r->seg_off[k];
            if (dr_fd_image(x->scene, x->cam, r->ps, o, x->dir, seed, dst) != 0)
                return -1;
            if (r->reverse) {
                double s = 0.0;
                for (size_t i = 0; i < n; i++)
                    s += (double)x->adj[i] * x->dimg[i];
                x->v[pp->offset + c] = s;
            }
        }
    }
    return 0;
}

/* --reference spp:N or fd:N: --batches estimates with their own seeds. */
static int compute_reference(struct cmp_ctx *x)
{
    struct cmp_run *r = x->r;
    const struct cmp_args *a = r->a;
    struct cmp_reference *ref = &r->ref;
    const int B = a->batches;
    const struct cmp_combo *first = &r->combos[0];
    ref->spp = a->ref_spp;
    ref->batches = B;
    ref->max_depth = a->depths[a->n_depths - 1];
    /* the first estimator and sampling listed; media derivatives by DRT,
     * unbiased in every medium (the baseline is not in a density grid's
     * empty or constant regions: its error there must show) */
    const struct cmp_combo ref_run = {first->est, first->sampling, ref->max_depth, ref->spp, a->g.sampler,
                                      DR_MEDIUM_GRAD_DRT};
    int rw, rh;   /* the rendered rectangle: the frame or --crop's */
    struct dr_film film = grad_film(&a->g, a->g.width, a->g.height, &rw, &rh);
    struct dr_fd_options o = {.width = rw, .height = rh, .film = film, .sampler = a->g.sampler, .spp = ref->spp,
                              .batches = B, .max_depth = ref->max_depth, .rr_depth = a->g.rr_depth,
                              .threads = a->g.threads, .eps = a->eps};
    if (a->ref_kind == CMP_REF_FD) {
        snprintf(ref->kind, sizeof ref->kind, "fd:%d", ref->spp);
        ref->eps = a->eps;
    } else {
        snprintf(ref->kind, sizeof ref->kind, "spp:%d", ref->spp);
        snprintf(ref->estimator, sizeof ref->estimator, "%s", first->est->name);
        snprintf(ref->sampling, sizeof ref->sampling, "%s", dr_sampling_name(first->sampling));
    }
    double t0 = dr_clock_seconds();
    struct dr_grad_stats sum = {0};
    welford_reset(x);
    for (int b = 0; b < B; b++) {
        uint64_t seed = dr_hash64(a->g.seed ^ REF_SEED_SALT) + (uint64_t)b;
        int rc = a->ref_kind == CMP_REF_FD
                     ? fd_estimate(x, &o, seed)
                     : estimate(x, &ref_run, seed, x->v, &sum);
        if (rc != 0)
            return -1;
        welford_add(x, b, NULL);
        tick(x);
    }
    ref->seconds = dr_clock_seconds() - t0;
    for (int64_t i = 0; i < r->V; i++) {
        ref->mean[i] = x->mean[i];
        ref->se[i] = sqrt(x->m2[i] / (B - 1) / B);
    }
    return 0;
}

/* |mean|^2 and the relative standard error of a reference however obtained. */
static void reference_norms(struct cmp_run *r)
{
    double n2 = 0.0, s2 = 0.0;
    for (int64_t i = 0; i < r->V; i++) {
        n2 += r->ref.mean[i] * r->ref.mean[i];
        s2 += r->ref.se[i] * r->ref.se[i];
    }
    r->ref.norm2 = n2;
    r->ref.rel_se = n2 > 0.0 ? sqrt(s2 / n2) : NAN;
}

/* ---- set-up ---- */

static void run_free(struct cmp_run *r)
{
    for (int c = 0; r->results && c < r->n_combos; c++) {
        free(r->results[c].seconds);
        free(r->results[c].params);
    }
    free(r->results);
    free(r->combos);
    free(r->seg_off);
    free(r->seg_len);
    free(r->ref.mean);
    free(r->ref.se);
}

static void ctx_free(struct cmp_ctx *x)
{
    dr_media_plan_free(&x->media_plan);
    free(x->adj);
    free(x->cross_img);
    free(x->dir);
    free(x->v);
    free(x->dimg);
    free(x->mean);
    free(x->m2);
    free(x->seg_mean);
    free(x->seg_m2);
    free(x->seg_err2);
}

/* Values of one rendered image: the frame, or --crop's rectangle of it. */
static int64_t rendered_values(const struct cmp_args *a)
{
    int rw, rh;
    grad_film(&a->g, a->g.width, a->g.height, &rw, &rh);
    return (int64_t)rw * rh * 3;
}

/* Segments of v, result slots, the reference's arrays and the scratch. */
static int run_alloc(struct cmp_run *r, struct cmp_ctx *x)
{
    const struct dr_param_set *ps = r->ps;
    const int64_t npix3 = rendered_values(r->a);
    r->seg_off = calloc((size_t)ps->n, sizeof(int64_t));
    r->seg_len = calloc((size_t)ps->n, sizeof(int64_t));
    if (!r->seg_off || !r->seg_len)
        return -1;
    for (int k = 0; k < ps->n; k++) {
        r->seg_off[k] = r->reverse ? ps->params[k].offset : k * npix3;
        r->seg_len[k] = r->reverse ? ps->params[k].size : npix3;
    }
    r->V = r->reverse ? ps->total : ps->n * npix3;
    const size_t V = (size_t)r->V, P = (size_t)ps->n;
    r->results = calloc((size_t)r->n_combos, sizeof *r->results);
    if (!r->results)
        return -1;
    for (int c = 0; c < r->n_combos; c++) {
        r->results[c].seconds = calloc((size_t)r->a->repeat, sizeof(double));
        r->results[c].params = calloc(P, sizeof(struct cmp_param_result));
        if (!r->results[c].seconds || !r->results[c].params)
            return -1;
    }
    r->ref.mean = calloc(V, sizeof(double));
    r->ref.se = calloc(V, sizeof(double));
    x->dir = calloc((size_t)(ps->total > 0 ? ps->total : 1), sizeof(double));
    x->v = calloc(V, sizeof(double));
    x->dimg = calloc((size_t)npix3, sizeof(double));
    if (r->a->cross && !(x->cross_img = calloc((size_t)npix3, sizeof(double))))
        return -1;
    x->mean = calloc(V, sizeof(double));
    x->m2 = calloc(V, sizeof(double));
    x->seg_mean = calloc(P, sizeof(double));
    x->seg_m2 = calloc(P, sizeof(double));
    x->seg_err2 = calloc(P, sizeof(double));
    return r->ref.mean && r->ref.se && x->dir && x->v && x->dimg && x->mean && x->m2 && x->seg_mean && x->seg_m2 &&
                   x->seg_err2 ? 0 : -1;
}

static void fingerprint(struct cmp_run *r, const struct dr_scene *scene, bool *ok)
{
    const struct cmp_args *a = r->a;
    struct cmp_fingerprint *fp = &r->fp;
    *ok = true;
    fp->scene_hash = cmp_hash_file(r->scene_path, ok);
    bool tok = true;
    fp->target_hash = a->target ? cmp_hash_file(a->target, &tok) : 0;
    *ok = *ok && tok;
    double *vals = malloc(sizeof(double) * (size_t)(r->ps->total > 0 ? r->ps->total : 1));
    fp->values_hash = 0;
    if (vals) {
        dr_param_set_get(scene, r->ps, vals);
        fp->values_hash = cmp_hash_bytes(0, vals, sizeof(double) * (size_t)r->ps->total);
        free(vals);
    } else {   /* (a fingerprint without the values could match another scene's reference) */
        dr_set_error("out of memory");
        *ok = false;
    }
    fp->width = a->g.width;
    fp->height = a->g.height;
    char filter[64], crop[64] = "none";
    dr_filter_format(&a->g.filter, filter, sizeof filter);
    if (a->g.crop_given)
        snprintf(crop, sizeof crop, "%d,%d,%d,%d", a->g.crop_x, a->g.crop_y, a->g.crop_w, a->g.crop_h);
    char samplers[64] = "";   /* the list as given: one name for a single sampler, as before lists */
    for (int q = 0; q < a->n_samplers; q++) {
        size_t len = strlen(samplers);
        snprintf(samplers + len, sizeof samplers - len, "%s%s", q ? "," : "", dr_sampler_kind_name(a->samplers[q]));
    }
    snprintf(fp->film, sizeof fp->film, "filter=%s crop=%s sampler=%s", filter, crop, samplers);
    fp->camera = a->g.camera;
    fp->max_depth = a->depths[a->n_depths - 1];
    fp->rr_depth = a->g.rr_depth;
    fp->primal_spp = r->reverse && !a->cross ? PRIMAL_SPP : 0;
    snprintf(fp->mode, sizeof fp->mode, "%s", r->reverse ? "reverse" : "forward");
    snprintf(fp->loss, sizeof fp->loss, "%s", r->reverse ? dr_loss_name(a->loss) : "none");
}

/* Reverse mode: one primal image with its own fixed random numbers and the
 * loss's adjoint, shared by every run and by the reference. */
static int shared_adjoint(struct cmp_ctx *x, const float *target)
{
    const struct cmp_args *a = x->r->a;
    const size_t n = (size_t)rendered_values(a);   /* target: cut to the crop by load_target */
    float *img = malloc(sizeof(float) * n);
    x->adj = malloc(sizeof(float) * n);
    if (!img || !x->adj) {
        free(img);
        cli_error("compare", "out of memory");
        return DR_EXIT_FAILURE;
    }
    struct grad_common g = a->g;
    g.max_depth = a->depths[a->n_depths - 1];
    struct dr_render_opts ro = grad_render_opts(&g, g.width, g.height, PRIMAL_SPP, PRIMAL_SEED, false);
    if (dr_render(x->scene, x->cam, &ro, img, NULL) != 0) {
        free(img);
        cli_error("compare", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    d_loss_eval(a->loss, img, target, n, 1.0, x->adj);
    free(img);
    return -1;
}

/* Checks that need the scene but no work: fd cannot give texel gradients,
 * two media methods need a medium's parameter, memory, a reference file. */
static int check_scene_args(struct cmp_run *r, const struct dr_scene *scene)
{
    const struct cmp_args *a = r->a;
    if (a->n_medium_grads > 1 && !r->ps->media_active) {
        cli_error("compare", "--medium-grad %s,%s: no --param is a participating medium's (DR_medium, "
                             "KHR_materials_volume), so both methods would run the same paths",
                  dr_medium_grad_name(a->medium_grads[0]), dr_medium_grad_name(a->medium_grads[1]));
        return DR_EXIT_USAGE;
    }
    if (a->ref_kind == CMP_REF_FD && r->reverse)
        for (int k = 0; k < r->ps->n; k++)
            if (is_image_param(&r->ps->params[k])) {
                cli_error("compare", "--reference fd: %s is an image of %lld values; finite differences would need "
                                     "two renders per texel (use --reference spp:N)",
                          r->ps->params[k].name, (long long)r->ps->params[k].size);
                return DR_EXIT_USAGE;
            }
    struct grad_common g = a->g;
    g.max_depth = a->depths[a->n_depths - 1];
    g.spp = a->ref_spp;   /* the most samples per pixel a run takes (the workers' storage follows it) */
    for (int k = 0; k < a->n_spps; k++)
        g.spp = a->spps[k] > g.spp ? a->spps[k] : g.spp;
    bool tape = false, mis = false;
    for (int c = 0; c < r->n_combos; c++) {
        tape |= strcmp(r->combos[c].est->name, "tape") == 0;
        mis |= r->combos[c].sampling == DR_SAMPLING_MIS;
    }
    int rc = cli_limits_compare(&g, scene, r->ps, r->reverse, tape, mis);
    if (rc >= 0)
        return rc;
    bool ok;
    fingerprint(r, scene, &ok);
    if (!ok) {
        cli_error("compare", "%s", dr_last_error());
        return cli_error_exit(DR_EXIT_INPUT);
    }
    if (a->ref_kind == CMP_REF_FILE)
        return cmp_reference_read(r, a->reference);
    return -1;
}

/* ---- outputs ---- */

static int write_json_file(const struct cmp_run *r, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return -1;
    cmp_write_json(r, f);
    return cli_fclose_checked(f);
}

/* Each writer returns 0, or -1 with errno set (the message is write_outputs'). */
static const struct {
    const char *name;
    int (*write)(const struct cmp_run *r, const char *path);
} out_files[] = {
    {"results.csv", cmp_write_csv},
    {"results.json", write_json_file},
    {"report.md", cmp_write_report},
    {"reference.txt", cmp_reference_write},
};
#define N_OUT_FILES (int)(sizeof out_files / sizeof out_files[0])

static void out_path(char *buf, size_t size, const char *dir, const char *prefix, const char *name)
{
    snprintf(buf, size, "%s%s%s%s", dir, dir[strlen(dir) - 1] == '/' ? "" : "/", prefix, name);
}

/* Every file goes to a temporary name first and is renamed once all are
 * written, so a failure leaves nothing half-written. */
static int write_outputs(const struct cmp_run *r, const char *dir)
{
    struct stat sb;
    bool created = false;
    if (stat(dir, &sb) != 0) {
        if (mkdir(dir, 0777) != 0) {
            cli_error("compare", "-o %s: cannot create the directory: %s", dir, strerror(errno));
            return DR_EXIT_FAILURE;
        }
        created = true;
    }
    char tmp[N_OUT_FILES][4400], dst[4400];
    int written = 0;
    for (; written < N_OUT_FILES; written++) {
        out_path(tmp[written], sizeof tmp[written], dir, ".tmp.", out_files[written].name);
        if (out_files[written].write(r, tmp[written]) != 0) {
            out_path(dst, sizeof dst, dir, "", out_files[written].name);
            cli_error("compare", "%s: cannot write: %s", dst, strerror(errno));
            break;
        }
    }
    if (written < N_OUT_FILES) {
        for (int i = 0; i <= written && i < N_OUT_FILES; i++)
            unlink(tmp[i]);
        if (created)
            rmdir(dir);
        return DR_EXIT_FAILURE;
    }
    for (int i = 0; i < N_OUT_FILES; i++) {
        out_path(dst, sizeof dst, dir, "", out_files[i].name);
        rename(tmp[i], dst);
    }
    return cmp_write_plots(r, dir) != 0 ? DR_EXIT_FAILURE : -1;
}

static void print_summary(const struct cmp_run *r)
{
    if (r->a->g.json) {
        cmp_write_json(r, stdout);
        return;
    }
    const char *dir = r->a->out_dir;
    printf("%d runs of %d combinations; reference %s (relative standard error %.3g)\n",
           r->n_combos * r->a->repeat, r->n_combos, r->ref.kind, r->ref.rel_se);
    if (r->as_detached[0])
        printf("left out: %s (they would run as detached sampling on these parameters)\n", r->as_detached);
    int best = 0;
    for (int c = 1; c < r->n_combos; c++)
        if (cmp_efficiency(r, c) > cmp_efficiency(r, best))
            best = c;
    char label[128];
    cmp_combo_label(r, &r->combos[best], label, sizeof label);
    printf("most efficient: %s at %d spp (efficiency %.4g, relative error %.3g)\n", label, r->combos[best].spp,
           cmp_efficiency(r, best), r->results[best].rel_error);
    printf("written to %s: report.md, results.csv, results.json, reference.txt, plots.gp and the plots\n", dir);
}

/* ---- the command ---- */

/* The target image (reverse mode) and the image size; -1 to go on. */
static int load_target(struct cmp_args *a, struct dr_image *timg, float **target)
{
    if (!a->target)
        return -1;
    int rc = grad_load_target("compare", a->target, timg, target);
    if (rc >= 0)
        return rc;
    const struct grad_common *g = &a->g;
    if (g->crop_given && !g->res_given && timg->width == g->crop_w && timg->height == g->crop_h) {
        cli_error("compare", "--target %s is the crop's size (%dx%d): give the full frame's size with --res WxH",
                  a->target, timg->width, timg->height);
        return DR_EXIT_USAGE;
    }
    if (a->g.res_given && !g->crop_given && (a->g.width != timg->width || a->g.height != timg->height)) {
        cli_error("compare", "--target %s is %dx%d but --res asks for %dx%d (the render and the target must be "
                             "the same size)", a->target, timg->width, timg->height, a->g.width, a->g.height);
        return DR_EXIT_USAGE;
    }
    return -1;
}

/* The reference, then every combination --repeat times. */
static int run_all(struct cmp_ctx *x)
{
    struct cmp_run *r = x->r;
    const int B = r->a->batches;
    x->progress = isatty(2) != 0;
    x->total = (r->a->ref_kind == CMP_REF_FILE ? 0 : B) + r->n_combos * r->a->repeat * B;
    if (r->a->ref_kind != CMP_REF_FILE && compute_reference(x) != 0)
        goto fail;
    reference_norms(r);
    if (!(r->ref.norm2 > 0.0) && !r->a->g.json)
        cli_error("compare", "warning: the reference is zero: relative errors are undefined (the parameters "
                             "do not change the %s)", r->reverse ? "loss" : "image");
    for (int rep = 0; rep < r->a->repeat; rep++)
        for (int c = 0; c < r->n_combos; c++)
            if (run_combo(x, c, rep) != 0)
                goto fail;
    return -1;
fail:
    if (x->progress)
        fputc('\n', stderr);
    cli_error("compare", "%s", dr_last_error());
    return DR_EXIT_FAILURE;
}

/* What --sampling auto (grad's and optimize's default, with its default
 * estimator) would run on this problem, for the report: compare measures
 * the modes, auto is the choice a user gets without naming one. */
static void auto_choice(struct cmp_run *r, const struct dr_scene *scene)
{
    const struct grad_auto_choice c = grad_auto_sampling(dr_estimator_find("prb"), scene, r->ps);
    snprintf(r->auto_sampling, sizeof r->auto_sampling, "%s", dr_sampling_name(c.sampling));
    grad_auto_describe(scene, &c, r->auto_why, sizeof r->auto_why);
}

int cmd_compare(int argc, char **argv)
{
    double t_start = dr_clock_seconds();
    struct cmp_args a;
    args_defaults(&a);
    struct cmp_run r;
    memset(&r, 0, sizeof r);
    r.a = &a;
    struct cmp_ctx x;
    memset(&x, 0, sizeof x);
    x.r = &r;
    char *scene_path = NULL;
    struct dr_scene *scene = NULL;
    struct dr_param_set *ps = NULL;
    struct dr_image timg;
    memset(&timg, 0, sizeof timg);
    float *target = NULL;
    struct dr_camera cam;
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0 || (rc = check_args(&a)) >= 0 || (rc = build_combos(&a, &r)) >= 0 ||
        (rc = load_target(&a, &timg, &target)) >= 0)
        goto out;
    int dw = a.target ? timg.width : DEFAULT_RES, dh = a.target ? timg.height : DEFAULT_RES;
    if ((rc = grad_load_scene(&a.g, &scene_path, &scene, &cam, dw, dh)) >= 0 ||
        (rc = grad_check_crop(&a.g, a.g.width, a.g.height)) >= 0 ||
        (target && (rc = grad_crop_image(&a.g, "--target", &target, timg.width, timg.height, a.g.width,
                                         a.g.height)) >= 0) ||
        (rc = grad_apply_sets(&a.g, scene)) >= 0 || (rc = grad_param_set(&a.g, scene, &ps)) >= 0)
        goto out;
    r.scene_path = scene_path;
    r.ps = ps;
    drop_detached_twins(&a, &r, scene);
    auto_choice(&r, scene);
    r.reverse = a.target != NULL;
    x.scene = scene;
    x.cam = &cam;
    if (run_alloc(&r, &x) != 0) {
        cli_error("compare", "out of memory");
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    if ((rc = check_scene_args(&r, scene)) >= 0)
        goto out;
    /* everything the user can get wrong has been checked: the work starts */
    x.target = target;
    if ((r.reverse && !a.cross && (rc = shared_adjoint(&x, target)) >= 0) || (rc = run_all(&x)) >= 0)
        goto out;
    r.t_total = dr_clock_seconds() - t_start;
    if ((rc = write_outputs(&r, a.out_dir)) >= 0)
        goto out;
    print_summary(&r);
    rc = DR_EXIT_OK;
out:
    ctx_free(&x);
    run_free(&r);
    free(target);
    dr_image_release(&timg);
    dr_param_set_destroy(ps);
    dr_scene_destroy(scene);
    free(scene_path);
    grad_common_free(&a.g);
    return rc;
}
