/* drender fdcheck: a gradient estimator against finite differences, with a
 * statistical verdict (z-scores from independent batches). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "error.h"
#include "fdcheck.h"
#include "grad_common.h"
#include "mem_limits.h"
#include "params.h"
#include "scene.h"

void cmd_fdcheck_usage(FILE *out)
{
    fprintf(out,
            "usage: drender fdcheck [SCENE] --param P [--param P ...] [options]\n"
            "\n"
            "Checks a gradient estimator against finite differences on SCENE (default: the\n"
            "bundled Cornell box). The objective is the mean of the rendered image over\n"
            "pixels and channels. For every component of each --param (for an image: all\n"
            "texels at once, and a fixed random +-1 pattern), K independent batches each\n"
            "give the estimator's derivative in reverse and in forward mode and a central\n"
            "difference with common random numbers (one-sided at the parameter's range\n"
            "ends); z = (gradient - fd) / sqrt(se_gradient^2 + se_fd^2). Exit status 0 when\n"
            "every |z| <= --z-max, 4 when some entry disagrees.\n"
            "\n"
            "options:\n"
            "      --param P       a parameter to check (repeatable, required)\n"
            "      --set P=V[,V...]  use these values for parameter P instead of the file's\n"
            "      --eps E         finite-difference step, absolute (default: 1e-2)\n"
            "      --spp N         samples per pixel of each batch (default: 16)\n"
            "      --batches K     independent batches, at least 2 (default: 8)\n"
            "      --z-max Z       agreement threshold on |z| (default: 4)\n"
            "      --estimator E   gradient estimator: prb (path replay, default) or tape\n"
            GRAD_SAMPLING_HELP
            "      --regularize E  prb, attached: a vertex Jacobian whose smallest/largest\n"
            "                      singular value is below E is not inverted; forward mode\n"
            "                      restarts there instead (default: 1e-3; 0: always invert)\n"
            "      --medium-grad M drt (default) or baseline, for media parameters\n"
            "      --res WxH       image size (default: 32x32)\n"
            "      --max-depth D   path segments (default: 8)\n"
            "      --rr-depth D    Russian roulette from this many segments on (default: 5)\n"
            "      --camera N      which camera of the file (default: 0)\n"
            "      --seed S        random seed (default: 0; batch b uses S + b)\n"
            "      --threads T     worker threads (default: one per CPU)\n"
            "      --sampler S     random numbers: independent (default), stratified\n"
            "                      (jittered strata over the pixel's spp) or sobol\n"
            "                      (Owen-scrambled Sobol); both converge faster\n"
            "      --filter F      pixel filter: box (default), tent or gaussian[:STDDEV]\n"
            "      --crop X,Y,W,H  only this rectangle of the --res frame is rendered (the\n"
            "                      objective is its mean)\n"
            GRAD_IGNORE_UNSUPPORTED_HELP
            "      --json          print the entries as one JSON object on stdout\n"
            "  -h, --help          show this help\n");
    grad_lighting_usage(out);
}

enum { OPT_EPS = GOPT_END, OPT_BATCHES, OPT_ZMAX, OPT_BATCH };

struct fdcheck_args {
    struct grad_common g;
    double eps, z_max;
    int batches;
};

/* The options only `fdcheck` takes (grad_own_option_fn). */
static int own_option(void *ctx, int c, const char *optarg)
{
    struct fdcheck_args *a = ctx;
    long v;
    switch (c) {
    case OPT_EPS:
        if (!cli_parse_double("fdcheck", "--eps", optarg, 0.0, &a->eps)) return DR_EXIT_USAGE;
        return 0;
    case OPT_ZMAX:
        if (!cli_parse_double("fdcheck", "--z-max", optarg, 0.0, &a->z_max)) return DR_EXIT_USAGE;
        return 0;
    case OPT_BATCHES:
        if (!cli_parse_int("fdcheck", "--batches", optarg, 2, 1L << 20, &v)) return DR_EXIT_USAGE;
        a->batches = (int)v;
        return 0;
    case OPT_BATCH:
        cli_error("fdcheck", "--batch (tape paths per sweep) is a 'grad' option; fdcheck's tape sweeps one "
                             "sample of every pixel at a time (did you mean --batches?)");
        return DR_EXIT_USAGE;
    default: return -1;
    }
}

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, struct fdcheck_args *a)
{
    static const struct option opts[] = {
        GRAD_COMMON_LONG_OPTIONS,
        {"eps", required_argument, NULL, OPT_EPS},
        {"batches", required_argument, NULL, OPT_BATCHES},
        {"z-max", required_argument, NULL, OPT_ZMAX},
        /* listed so that getopt does not take it for an abbreviation of --batches */
        {"batch", required_argument, NULL, OPT_BATCH},
        {NULL, 0, NULL, 0},
    };
    return grad_parse_args(&a->g, argc, argv, opts, "", own_option, a, cmd_fdcheck_usage);
}

static void print_json(const struct fdcheck_args *a, const char *scene_path, const struct dr_fd_entry *en, int n,
                       bool all_agree, double t_load, double t_check, double t_total, const struct dr_param_set *ps,
                       const struct dr_grad_stats *st)
{
    FILE *f = stdout;
    fprintf(f, "{");
    grad_json_head(f, &a->g, scene_path);
    cli_json_memory_estimate(f);
    fprintf(f, ", \"batches\": %d, \"eps\": ", a->batches);
    json_number(f, a->eps);
    fprintf(f, ", \"z_max\": ");
    json_number(f, a->z_max);
    fprintf(f, ", \"time\": {\"load\": ");
    json_number(f, t_load);
    fprintf(f, ", \"check\": ");
    json_number(f, t_check);
    fprintf(f, ", \"total\": ");
    json_number(f, t_total);
    fprintf(f, "}, \"peak_memory_bytes\": %llu, \"agree\": %s, \"entries\": [",
            (unsigned long long)cli_peak_rss_bytes(), all_agree ? "true" : "false");
    for (int i = 0; i < n; i++) {
        const struct dr_fd_entry *e = &en[i];
        fprintf(f, "%s{\"label\": ", i ? ", " : "");
        json_string(f, e->label);
        const char *keys[] = {"reverse", "reverse_se", "forward", "forward_se", "fd", "fd_se", "z_reverse",
                              "z_forward"};
        const double vals[] = {e->reverse, e->reverse_se, e->forward, e->forward_se, e->fd, e->fd_se,
                               e->z_reverse, e->z_forward};
        for (int k = 0; k < 8; k++) {
            fprintf(f, ", \"%s\": ", keys[k]);
            json_number(f, vals[k]);
        }
        fprintf(f, ", \"agree\": %s}", e->agree ? "true" : "false");
    }
    fputc(']', f);
    grad_json_media_gain(f, st->media_gain, st->n_media_gain);
    fprintf(f, ", \"effects_differentiated\": ");
    grad_json_effects(f, ps);
    fprintf(f, "}\n");
}

/* The entries as a table on stdout, and the verdict. */
static void print_table(const struct fdcheck_args *a, const char *scene_path, const struct dr_fd_entry *en, int n)
{
    FILE *f = stdout;
    int lw = 5;
    for (int i = 0; i < n; i++)
        if ((int)strlen(en[i].label) > lw)
            lw = (int)strlen(en[i].label);
    fprintf(f, "%s: %s estimator (%s) vs finite differences (eps %g), %d batches of %d spp at %dx%d, |z| <= %g\n",
            scene_path, a->g.estimator->name, dr_sampling_name(a->g.sampling), a->eps, a->batches, a->g.spp,
            a->g.width, a->g.height, a->z_max);
    fprintf(f, "%-*s  %24s  %24s  %24s  %7s  %7s  %s\n", lw, "ENTRY", "REVERSE +- SE", "FORWARD +- SE", "FD +- SE",
            "Z(REV)", "Z(FWD)", "VERDICT");
    int bad = 0;
    for (int i = 0; i < n; i++) {
        const struct dr_fd_entry *e = &en[i];
        char r[64], fw[64], fd[64];
        snprintf(r, sizeof r, "%.5g +- %.2g", e->reverse, e->reverse_se);
        snprintf(fw, sizeof fw, "%.5g +- %.2g", e->forward, e->forward_se);
        snprintf(fd, sizeof fd, "%.5g +- %.2g", e->fd, e->fd_se);
        fprintf(f, "%-*s  %24s  %24s  %24s  %7.2f  %7.2f  %s\n", lw, e->label, r, fw, fd, e->z_reverse, e->z_forward,
                e->agree ? "agree" : "DISAGREE");
        bad += !e->agree;
    }
    if (bad)
        fprintf(f, "%d of %d entries disagree\n", bad, n);
    else
        fprintf(f, "all %d entries agree\n", n);
}

int cmd_fdcheck(int argc, char **argv)
{
    double t_start = dr_clock_seconds();
    struct fdcheck_args a;
    memset(&a, 0, sizeof a);
    grad_common_init(&a.g, "fdcheck", 16);
    a.eps = 1e-2;
    a.z_max = 4.0;
    a.batches = 8;
    char *scene_path = NULL;
    struct dr_scene *scene = NULL;
    struct dr_param_set *ps = NULL;
    struct dr_fd_entry *en = NULL;
    int n = 0;
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0)
        goto out;
    if ((rc = grad_common_check(&a.g)) >= 0)
        goto out;
    struct dr_camera cam;
    if ((rc = grad_load_scene(&a.g, &scene_path, &scene, &cam, 32, 32)) >= 0)
        goto out;
    if ((rc = grad_apply_sets(&a.g, scene)) >= 0 || (rc = grad_param_set(&a.g, scene, &ps)) >= 0)
        goto out;
    grad_resolve_sampling(&a.g, scene, ps);
    if ((rc = cli_limits_fdcheck(&a.g, scene, ps, a.batches)) >= 0)
        goto out;
    if ((rc = grad_check_crop(&a.g, a.g.width, a.g.height)) >= 0)
        goto out;
    double t_loaded = dr_clock_seconds();
    int rw, rh;   /* the rendered rectangle: the frame or --crop's */
    struct dr_film film = grad_film(&a.g, a.g.width, a.g.height, &rw, &rh);
    struct dr_fd_options o = {.estimator = a.g.estimator, .sampling = a.g.sampling, .medium_grad = a.g.medium_grad, .width = rw,
                              .height = rh, .film = film, .spp = a.g.spp, .batches = a.batches,
                              .max_depth = a.g.max_depth, .rr_depth = a.g.rr_depth, .seed = a.g.seed,
                              .regularize = a.g.regularize, .sampler = a.g.sampler,
                              .threads = a.g.threads, .eps = a.eps, .z_max = a.z_max};
    struct dr_grad_stats st = {0};
    o.stats = &st;
    if (dr_fdcheck(scene, &cam, ps, &o, &en, &n) != 0) {
        cli_error("fdcheck", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    double t_end = dr_clock_seconds();
    bool all_agree = true;
    for (int i = 0; i < n; i++)
        all_agree &= en[i].agree;
    if (a.g.json) {
        print_json(&a, scene_path, en, n, all_agree, t_loaded - t_start, t_end - t_loaded, t_end - t_start, ps, &st);
    } else {
        print_table(&a, scene_path, en, n);
    }
    rc = all_agree ? DR_EXIT_OK : DR_EXIT_DISAGREE;
out:
    free(en);
    dr_param_set_destroy(ps);
    dr_scene_destroy(scene);
    free(scene_path);
    grad_common_free(&a.g);
    return rc;
}
