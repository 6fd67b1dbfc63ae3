/* drender optimize: fit scene parameters to target images with Adam.
 *
 * Never loses work: parameters and optimizer state are checkpointed
 * atomically every K iterations and on SIGINT/SIGTERM; --resume continues
 * from the checkpoint and, because every iteration's random numbers depend
 * only on (seed, iteration, target), gives the same result as a run that was
 * never interrupted. */
#include <errno.h>
#include <getopt.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bigalloc.h"
#include "camera.h"
#include "cli.h"
#include "cut_short.h"
#include "error.h"
#include "gltf_write.h"
#include "grad_common.h"
#include "image_io.h"
#include "loss.h"
#include "mem_limits.h"
#include "optimizer.h"
#include "parallel.h"
#include "render.h"
#include "reverse.h"
#include "sampler.h"
#include "stale_temps.h"
#include "zero_blocks.h"

#define MAX_TARGETS 64

void cmd_optimize_usage(FILE *out)
{
    fprintf(out,
            "usage: drender optimize [SCENE] --target [CAMERA=]IMG [--target ...]\n"
            "                        --param P [--param P ...] [options]\n"
            "\n"
            "Fits the parameters P of SCENE (default: the bundled Cornell box) so that its\n"
            "renders match the target images, with Adam on gradients from an estimator.\n"
            "Each --target is seen through camera CAMERA of the file (default 0) and is\n"
            "rendered at the target's own size.\n"
            "\n"
            "options:\n"
            "      --target [N=]IMG   target image, optionally tied to camera N (repeatable)\n"
            "      --param P          parameter to optimise (a JSON pointer: see\n"
            "                         'drender params')\n"
            "      --set P=V[,V...]   start parameter P from these values instead of the\n"
            "                         file's\n"
            "      --iters N          iterations (default 100)\n"
            "      --lr X             learning rate for every parameter (default: per kind:\n"
            "                         0.02 for base colours, metallic, roughness and texels;\n"
            "                         5%% of the value for emission, lights and environment)\n"
            "      --loss l1|l2       image loss (default l2)\n"
            "      --estimator E      gradient estimator: prb (default) or tape\n"
            "      --sampling S       auto (default), detached, attached, mis, derivative or\n"
            "                         derivative-roughness (see SAMPLING in the manual);\n"
            "                         auto is derivative-roughness while a differentiated\n"
            "                         roughnessFactor is below " GRAD_STR(GRAD_AUTO_ROUGHNESS) " ("
            GRAD_STR(GRAD_AUTO_ROUGHNESS_WITH_COLOUR) " beside a base\n"
            "                         colour or metallic), decided at every iteration,\n"
            "                         else detached\n"
            "      --regularize E     prb, attached: a vertex Jacobian whose smallest/largest\n"
            "                         singular value is below E is not inverted; forward mode\n"
            "                         restarts there instead (default 1e-3; 0: always invert)\n"
            "      --medium-grad M    drt (default) or baseline, for media parameters\n"
            "      --spp N            samples per pixel for the loss image and for the\n"
            "                         gradient (default 8)\n"
            "      --batches K        split each iteration's samples into K independent\n"
            "                         batches (own primal each) for the gradient's standard\n"
            "                         error (--json: gradient_stderr; default 2, at least 2)\n"
            "      --primal M         where a batch's primal (the image the loss is taken at)\n"
            "                         comes from: cross (default: the gradient's own samples,\n"
            "                         each weighted at the mean of its pixel's others, sobol:\n"
            "                         the other half's; unbiased, no extra render) or\n"
            "                         separate (a render of its own)\n"
            "      --max-depth D      path segments (default 6)\n");
    fprintf(out,   /* (two strings: each within what C99 compilers must accept) */
            "      --rr-depth D       Russian roulette from this many segments on (default 5)\n"
            "      --res WxH          render size; every target must have it (default: each\n"
            "                         target's own size)\n"
            "      --seed S           random seed (default 0)\n"
            "      --threads T        worker threads (default: one per CPU)\n"
            "      --sampler S        random numbers: sobol (Owen-scrambled Sobol; the\n"
            "                         default, but independent where a batch renders its own\n"
            "                         primal: --primal separate or 1 sample a batch),\n"
            "                         independent (each number hashed on its own; the default\n"
            "                         before 2026-12) or stratified (jittered strata)\n"
            "      --filter F         pixel filter: box (default), tent or gaussian[:STDDEV]\n"
            "      --crop X,Y,W,H     fit only this rectangle of every target's frame; a\n"
            "                         target may be W x H (then --res gives the frame) or the\n"
            "                         full frame\n"
            "  -o, --output FILE      write the optimised scene (.gltf or .glb)\n"
            "      --out-dir DIR      progress files (default optimize-out): loss.csv,\n"
            "                         loss.png, render-NNNN.png, before.png, after.png,\n"
            "                         target.png, checkpoint.txt\n"
            "      --render-every K   save the current render every K iterations (default 10)\n"
            "      --checkpoint-every K  checkpoint every K iterations (default 10)\n"
            "      --resume           continue from DIR/checkpoint.txt\n"
            "      --reference SCENE  a scene holding the true values (synthetic tests):\n"
            "                         report the parameter error each iteration and at the\n"
            "                         end\n"
            GRAD_IGNORE_UNSUPPORTED_HELP
            "      --json             one JSON object per iteration on stdout, then a summary\n"
            "  -h, --help             show this help\n");
    grad_lighting_usage(out);
}

enum { OOPT_TARGET = GOPT_END, OOPT_ITERS, OOPT_LR, OOPT_LOSS, OOPT_OUTDIR, OOPT_RESUME, OOPT_RENDER_EVERY,
       OOPT_CKPT_EVERY, OOPT_REFERENCE, OOPT_BATCHES, OOPT_PRIMAL };

struct target {
    const char *arg, *path;
    int camera;
    struct dr_image img;
    float *rgb;          /* linear target (the rendered rectangle: --crop's or the frame) */
    int w, h;            /* the frame */
    int rw, rh;          /* the rendered rectangle: --crop's size, else the frame's */
    float *render;
};

struct opt_args {
    struct grad_common g;
    struct target targets[MAX_TARGETS];
    int n_targets;
    int iters, render_every, ckpt_every, batches;
    enum dr_primal_mode primal;
    double lr;
    int loss;
    const char *output, *out_dir, *reference;
    bool resume;
};

static volatile sig_atomic_t stop_signal = 0;

static void on_signal(int sig)
{
    if (stop_signal)
        _exit(128 + sig);   /* a second signal: stop at once */
    stop_signal = sig;
}

/* The options only `optimize` takes (grad_own_option_fn). */
static int own_option(void *ctx, int c, const char *optarg)
{
    struct opt_args *a = ctx;
    long v;
    switch (c) {
    case 'o': a->output = optarg; return 0;
    case OOPT_TARGET:
        if (a->n_targets == MAX_TARGETS) {
            cli_error("optimize", "--target: at most %d targets", MAX_TARGETS);
            return DR_EXIT_USAGE;
        }
        a->targets[a->n_targets++].arg = optarg;
        return 0;
    case OOPT_ITERS:
        if (!cli_parse_int("optimize", "--iters", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
        a->iters = (int)v;
        return 0;
    case OOPT_LR:
        if (!cli_parse_double("optimize", "--lr", optarg, 0.0, &a->lr)) return DR_EXIT_USAGE;
        return 0;
    case OOPT_LOSS:
        a->loss = dr_loss_parse(optarg);
        if (a->loss < 0) {
            cli_error("optimize", "--loss: '%s' is not a loss (use l1 or l2)", optarg);
            return DR_EXIT_USAGE;
        }
        return 0;
    case OOPT_OUTDIR: a->out_dir = optarg; return 0;
    case OOPT_RESUME: a->resume = true; return 0;
    case OOPT_RENDER_EVERY:
        if (!cli_parse_int("optimize", "--render-every", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
        a->render_every = (int)v;
        return 0;
    case OOPT_CKPT_EVERY:
        if (!cli_parse_int("optimize", "--checkpoint-every", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
        a->ckpt_every = (int)v;
        return 0;
    case OOPT_REFERENCE: a->reference = optarg; return 0;
    case OOPT_BATCHES:
        if (!cli_parse_int("optimize", "--batches", optarg, 2, 1L << 20, &v)) return DR_EXIT_USAGE;
        a->batches = (int)v;
        return 0;
    case OOPT_PRIMAL: return grad_parse_primal("optimize", optarg, &a->primal);
    default: return -1;
    }
}

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, struct opt_args *a)
{
    static const struct option opts[] = {
        GRAD_COMMON_LONG_OPTIONS,
        {"target", required_argument, NULL, OOPT_TARGET},
        {"iters", required_argument, NULL, OOPT_ITERS},
        {"lr", required_argument, NULL, OOPT_LR},
        {"loss", required_argument, NULL, OOPT_LOSS},
        {"output", required_argument, NULL, 'o'},
        {"out-dir", required_argument, NULL, OOPT_OUTDIR},
        {"resume", no_argument, NULL, OOPT_RESUME},
        {"render-every", required_argument, NULL, OOPT_RENDER_EVERY},
        {"checkpoint-every", required_argument, NULL, OOPT_CKPT_EVERY},
        {"reference", required_argument, NULL, OOPT_REFERENCE},
        {"batches", required_argument, NULL, OOPT_BATCHES},
        {"primal", required_argument, NULL, OOPT_PRIMAL},
        {NULL, 0, NULL, 0},
    };
    return grad_parse_args(&a->g, argc, argv, opts, "o", own_option, a, cmd_optimize_usage);
}

/* "N=path" -> camera N; "path" -> camera 0. */
static bool split_target(struct target *t)
{
    const char *eq = strchr(t->arg, '=');
    t->camera = 0;
    t->path = t->arg;
    if (!eq)
        return true;
    char *end;
    long cam = strtol(t->arg, &end, 10);
    if (end != eq || end == t->arg || cam < 0 || cam > 100000)
        return true;   /* an '=' that is part of the file name */
    t->camera = (int)cam;
    t->path = eq + 1;
    return true;
}

static int check_args(struct opt_args *a)
{
    int rc = grad_common_check(&a->g);
    if (rc >= 0)
        return rc;
    if (a->n_targets == 0) {
        cli_error("optimize", "at least one --target is needed");
        return DR_EXIT_USAGE;
    }
    if (a->output) {
        const char *dot = strrchr(a->output, '.');
        if (!dot || (strcasecmp(dot, ".gltf") != 0 && strcasecmp(dot, ".glb") != 0)) {
            cli_error("optimize", "-o %s: the optimised scene is written as glTF: use .gltf or .glb", a->output);
            return DR_EXIT_USAGE;
        }
    }
    for (int i = 0; i < a->n_targets; i++)
        split_target(&a->targets[i]);
    return -1;
}

/* Length of the shortest prefix of PATH (at a '/' or its end) that does not
 * exist yet: what make_dirs will create from; 0 when PATH exists. */
static size_t first_missing_prefix(const char *path)
{
    char buf[4096];
    struct stat st;
    snprintf(buf, sizeof buf, "%s", path);
    size_t n = strlen(buf);
    for (size_t i = 1; i <= n; i++)
        if (buf[i] == '/' || buf[i] == '\0') {
            char c = buf[i];
            buf[i] = '\0';
            bool exists = stat(buf, &st) == 0;
            buf[i] = c;
            if (!exists)
                return i;
        }
    return 0;
}

/* Removes what make_dirs created (directories at least `from` long), so a run
 * rejected after creating --out-dir leaves nothing behind. */
static void unmake_dirs(const char *path, size_t from)
{
    char buf[4096];
    snprintf(buf, sizeof buf, "%s", path);
    size_t n = strlen(buf);
    while (n > 1 && buf[n - 1] == '/')
        buf[--n] = '\0';
    while (from > 0 && n >= from) {
        if (rmdir(buf) != 0)
            return;
        char *slash = strrchr(buf, '/');
        if (!slash)
            return;
        *slash = '\0';
        n = strlen(buf);
    }
}

/* mkdir -p */
static int make_dirs(const char *path)
{
    char buf[4096];
    snprintf(buf, sizeof buf, "%s", path);
    for (char *p = buf + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            if (mkdir(buf, 0777) != 0 && errno != EEXIST)
                return -1;
            *p = '/';
        }
    return mkdir(buf, 0777) != 0 && errno != EEXIST ? -1 : 0;
}

/* ---- progress files ---- */

struct history {
    int n, cap;
    double *loss, *seconds, *error;   /* error: max |parameter - reference|, NaN without --reference */
};

/* Iteration it's loss, time and error into h; false when out of memory
 * (h is then as it was). */
static bool history_add(struct history *h, int it, double loss, double sec, double err)
{
    if (it >= h->cap) {
        int cap = h->cap ? h->cap * 2 : 256;
        while (cap <= it)
            cap *= 2;
        /* (an array that grew before another failed is only larger: cap,
         * which says what all three hold, grows once all have) */
        double **arrays[3] = {&h->loss, &h->seconds, &h->error};
        for (int k = 0; k < 3; k++) {
            double *grown = realloc(*arrays[k], sizeof(double) * (size_t)cap);
            if (!grown)
                return false;
            *arrays[k] = grown;
        }
        h->cap = cap;
    }
    h->loss[it] = loss;
    h->seconds[it] = sec;
    h->error[it] = err;
    if (it + 1 > h->n)
        h->n = it + 1;
    return true;
}

static void path_in(char *buf, size_t size, const char *dir, const char *name)
{
    snprintf(buf, size, "%s/%s", dir, name);
}

/* Rewrites DIR/loss.csv atomically: false, said, when it cannot be written
 * (--resume reads it back: a run must not go on without it). */
static bool write_loss_csv(const char *dir, const struct history *h)
{
    char path[4096], tmp[4200];
    path_in(path, sizeof path, dir, "loss.csv");
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        cli_error("optimize", "%s: cannot write: %s", path, strerror(errno));
        return false;
    }
    fprintf(f, "iteration,loss,seconds,parameter_error\n");
    for (int i = 0; i < h->n; i++) {
        fprintf(f, "%d,%.10g,%.4f,", i, h->loss[i], h->seconds[i]);
        if (isfinite(h->error[i]))
            fprintf(f, "%.6g", h->error[i]);
        fputc('\n', f);
    }
    int e = cli_fclose_checked(f) != 0 ? errno : 0;
    if (!e && rename(tmp, path) != 0)
        e = errno;
    if (e) {
        unlink(tmp);
        cli_error("optimize", "%s: cannot write: %s", path, strerror(e));
    }
    return !e;
}

/* Reads back DIR/loss.csv (on --resume) up to `upto` iterations; false
 * when out of memory. */
static bool read_loss_csv(const char *dir, struct history *h, int upto)
{
    char path[4096], line[256];
    path_in(path, sizeof path, dir, "loss.csv");
    FILE *f = fopen(path, "r");
    if (!f)
        return true;
    bool ok = true;
    while (ok && fgets(line, sizeof line, f)) {
        int it;
        double l, s, e = NAN;
        int n = sscanf(line, "%d,%lf,%lf,%lf", &it, &l, &s, &e);
        if (n >= 3 && it >= 0 && it < upto)
            ok = history_add(h, it, l, s, n == 4 ? e : NAN);
    }
    fclose(f);
    return ok;
}

/* DIR/loss.png with gnuplot (a warning if gnuplot is missing): false, said,
 * when the plot could not be written whole. */
static bool plot_loss(const char *dir, bool with_error)
{
    char csv[4096], png[4096], tmp[4200], cmd[9000];
    path_in(csv, sizeof csv, dir, "loss.csv");
    path_in(png, sizeof png, dir, "loss.png");
    snprintf(tmp, sizeof tmp, "%s/.loss.tmp.png", dir);
    snprintf(cmd, sizeof cmd, "gnuplot 2>/dev/null");
    FILE *g = popen(cmd, "w");
    if (!g) {
        cli_error("optimize", "warning: cannot run gnuplot: %s not drawn", png);
        return true;
    }
    fprintf(g,
            "set terminal png size 800,500\n"
            "set output '%s'\n"
            "set datafile separator ','\n"
            "set title 'drender optimize'\n"
            "set xlabel 'iteration'\nset ylabel 'loss'\nset logscale y\nset grid\nset key top right\n",
            tmp);
    if (with_error)
        fprintf(g, "set y2tics\nset y2label 'max |parameter - reference|'\nset logscale y2\nset ytics nomirror\n"
                   "plot '%s' using 1:2 skip 1 with lines lw 2 title 'loss (includes Monte Carlo noise)', "
                   "'%s' using 1:4 skip 1 axes x1y2 with lines lw 2 title 'max |parameter - reference|'\n",
                csv, csv);
    else
        fprintf(g, "plot '%s' using 1:2 skip 1 with lines lw 2 title 'loss'\n", csv);
    int rc = pclose(g);
    if (rc != 0 || access(tmp, R_OK) != 0) {
        unlink(tmp);
        cli_error("optimize", "warning: gnuplot failed: %s not drawn (install gnuplot-nox)", png);
        return true;
    }
    /* gnuplot does not tell when it could not write the plot whole (a full disk) */
    char why[256];
    bool whole = dr_png_complete(tmp);
    if (!whole)
        cli_error("optimize", "%s: cannot write the plot: %s", png, dr_why_cut_short(tmp, why, sizeof why));
    if (!whole || rename(tmp, png) != 0)
        unlink(tmp);
    return whole;
}

static void eta_text(double secs, char *buf, size_t size)
{
    long s = (long)(secs + 0.5);
    if (s >= 3600)
        snprintf(buf, size, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
    else
        snprintf(buf, size, "%ld:%02ld", s / 60, s % 60);
}

/* Camera `index` of the file, or, for a file without cameras, the default
 * view render uses (index 0 only: opt_load checks). */
static struct dr_camera view_camera(const struct dr_scene *scene, int index)
{
    return scene->n_cameras > 0 ? scene->cameras[index] : dr_camera_default(scene);
}

/* Renders target 0's view at higher quality into DIR/NAME. */
static int save_view(const struct opt_args *a, const struct dr_scene *scene, const char *name)
{
    const struct target *t = &a->targets[0];
    char path[4096];
    path_in(path, sizeof path, a->out_dir, name);
    float *rgb = malloc(sizeof(float) * 3 * (size_t)t->rw * t->rh);
    if (!rgb) {
        cli_error("optimize", "%s: out of memory for a %dx%d image", path, t->rw, t->rh);
        return DR_EXIT_FAILURE;
    }
    struct dr_render_opts ro = grad_render_opts(&a->g, t->w, t->h, 4 * a->g.spp, a->g.seed ^ 0xbefa, false);
    struct dr_camera cam = view_camera(scene, t->camera);
    int rc = dr_render(scene, &cam, &ro, rgb, NULL);
    if (rc == 0)
        rc = dr_image_write(path, t->rw, t->rh, 3, rgb);
    if (rc != 0)
        cli_error("optimize", "%s", dr_last_error());
    free(rgb);
    return rc == 0 ? DR_EXIT_OK : DR_EXIT_FAILURE;
}

/* Values of the non-image parameters, for messages and JSON. */
static void print_values(FILE *f, const struct dr_param_set *ps, const double *theta, bool json)
{
    bool first = true;
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        if (dr_param_is_array(p))
            continue;
        if (json) {
            fprintf(f, "%s", first ? "" : ", ");
            json_string(f, p->name);
            fputs(": [", f);
        } else {
            fprintf(f, "  %-66s", p->name);
        }
        for (int64_t i = 0; i < p->size; i++) {
            if (json) {
                if (i)
                    fputs(", ", f);
                json_number(f, theta[p->offset + i]);
            } else {
                fprintf(f, " %.4f", theta[p->offset + i]);
            }
        }
        fputs(json ? "]" : "\n", f);
        first = false;
    }
}

/* Largest absolute difference to the reference scene, per parameter. */
static double reference_error(const struct dr_param_set *ps, const double *theta, const double *ref, int k)
{
    const struct dr_param *p = &ps->params[k];
    double e = 0.0;
    for (int64_t i = p->offset; i < p->offset + p->size; i++)
        e = fmax(e, fabs(theta[i] - ref[i]));
    return e;
}

/* Relative texture error: |theta - ref| / |ref| over the parameter. */
static double reference_rel_error(const struct dr_param_set *ps, const double *theta, const double *ref, int k)
{
    const struct dr_param *p = &ps->params[k];
    double num = 0.0, den = 0.0;
    for (int64_t i = p->offset; i < p->offset + p->size; i++) {
        num += (theta[i] - ref[i]) * (theta[i] - ref[i]);
        den += ref[i] * ref[i];
    }
    return den > 0.0 ? sqrt(num / den) : sqrt(num);
}

/* --crop: the target's frame (--res, else the target's own size: a
 * crop-sized target needs --res) and the target cut to the crop. */
static int target_frame(struct opt_args *a, struct target *t)
{
    char what[4200];
    snprintf(what, sizeof what, "--target %s", t->path);
    if (!a->g.res_given && t->w == a->g.crop_w && t->h == a->g.crop_h) {
        cli_error("optimize", "%s is the crop's size (%dx%d): give the full frame's size with --res WxH", what, t->w,
                  t->h);
        return DR_EXIT_USAGE;
    }
    int fw = a->g.res_given ? a->g.width : t->w, fh = a->g.res_given ? a->g.height : t->h;
    int rc = grad_check_crop(&a->g, fw, fh);
    if (rc < 0)
        rc = grad_crop_image(&a->g, what, &t->rgb, t->w, t->h, fw, fh);
    t->w = fw;
    t->h = fh;
    return rc;
}

static int load_targets(struct opt_args *a)
{
    for (int i = 0; i < a->n_targets; i++) {
        struct target *t = &a->targets[i];
        int rc = grad_load_target("optimize", t->path, &t->img, &t->rgb);
        if (rc >= 0)
            return rc;
        t->w = t->img.width;
        t->h = t->img.height;
        if (a->g.crop_given && (rc = target_frame(a, t)) >= 0)
            return rc;
        if (a->g.res_given && (t->w != a->g.width || t->h != a->g.height)) {
            cli_error("optimize", "--target %s is %dx%d but --res asks for %dx%d", t->path, t->w, t->h, a->g.width,
                      a->g.height);
            return DR_EXIT_USAGE;
        }
        grad_film(&a->g, t->w, t->h, &t->rw, &t->rh);
        t->render = malloc(sizeof(float) * 3 * (size_t)t->rw * t->rh);
        if (!t->render) {
            cli_error("optimize", "out of memory");
            return DR_EXIT_FAILURE;
        }
    }
    return -1;
}

/* Pixels of all targets, or of the largest (memory estimate). */
static uint64_t target_pixels(const struct opt_args *a, bool largest)
{
    uint64_t sum = 0, max = 0;
    for (int i = 0; i < a->n_targets; i++) {
        uint64_t n = (uint64_t)a->targets[i].w * (uint64_t)a->targets[i].h;
        sum += n;
        max = n > max ? n : max;
    }
    return largest ? max : sum;
}

static uint64_t iteration_seed(uint64_t seed, int it, int target, uint64_t what)
{
    return dr_hash64(dr_hash64(dr_hash64(seed ^ what) + (uint64_t)it) + (uint64_t)target);
}

/* What one optimisation run holds, from loading to the summary. */
struct opt_run {
    double t_start;
    char *scene_path;
    struct dr_scene *scene, *ref_scene;
    struct dr_param_set *ps;
    struct dr_adam *adam;
    double *theta, *grad, *ref;        /* values, gradient, reference values */
    double *se;                        /* the gradient's standard error */
    double *gt, *se_t;                 /* several targets: one target's gradient and standard error */
    uint64_t *nonzero;                 /* the blocks of grad and se that may not be +0 (reverse.h), kept
                                          true from iteration to iteration */
    uint64_t *nonzero_t;               /* several targets: the same of gt and se_t */
    uint64_t *se_blocks;               /* the blocks of the parameters whose standard errors are
                                          shown (not images': reverse.h) */
    struct dr_reverse_scratch scratch; /* the gradient runs' vectors, kept from iteration to iteration */
    struct history hist;
    double loss;
    char ckpt[4096];
    struct dr_checkpoint_pending pending;   /* the last checkpoint's fsync and rename, in the background */
    int it0;                           /* first iteration to run (resumed runs: > 0) */
    int sampling;                      /* what the last gradient ran (--sampling auto decides at every
                                          iteration from the values then: opt_sampling); -1 before */
    int auto_changes;                  /* changes of auto's mind so far (the first 4 are said) */
};

/* --reference: the true values of the same parameters, for error reports. */
static int load_reference(const struct opt_args *a, struct opt_run *r)
{
    r->ref_scene = dr_scene_load_opts(a->reference, &a->g.load);
    if (!r->ref_scene) {
        cli_error("optimize", "--reference %s", dr_last_error());
        return cli_error_exit(DR_EXIT_INPUT);
    }
    struct dr_param_set *rps = dr_param_set_create(r->ref_scene, a->g.params, a->g.n_params);
    if (!rps || rps->total != r->ps->total) {
        cli_error("optimize", "--reference %s: does not have the same parameters (%s)", a->reference,
                  rps ? "different sizes" : dr_last_error());
        const int code = rps ? DR_EXIT_USAGE : cli_error_exit(DR_EXIT_USAGE);
        dr_param_set_destroy(rps);
        return code;
    }
    r->ref = malloc(sizeof(double) * (size_t)r->ps->total);
    if (r->ref)
        dr_param_set_get(r->ref_scene, rps, r->ref);
    dr_param_set_destroy(rps);
    if (!r->ref) {
        cli_error("optimize", "out of memory");
        return DR_EXIT_FAILURE;
    }
    return -1;
}

/* Targets, scene, cameras, parameters, reference, starting values, Adam:
 * every input is checked before any work starts. */
static int opt_load(struct opt_args *a, struct opt_run *r)
{
    int rc;
    struct dr_camera cam0;
    if ((rc = load_targets(a)) >= 0 ||
        (rc = grad_load_scene(&a->g, &r->scene_path, &r->scene, &cam0, a->targets[0].w, a->targets[0].h)) >= 0)
        return rc;
    /* a file without cameras has one view: the default framing render uses */
    const int n_views = r->scene->n_cameras > 0 ? r->scene->n_cameras : 1;
    for (int i = 0; i < a->n_targets; i++)
        if (a->targets[i].camera >= n_views) {
            char what[4200];
            snprintf(what, sizeof what, "--target %s: camera", a->targets[i].arg);
            if (r->scene->n_cameras > 0)
                grad_camera_error("optimize", what, a->targets[i].camera, r->scene_path, r->scene);
            else
                cli_error("optimize", "%s %d: %s has 0 cameras; its one view is the default framing, target 0", what,
                          a->targets[i].camera, r->scene_path);
            return DR_EXIT_USAGE;
        }
    if ((rc = grad_param_set(&a->g, r->scene, &r->ps)) >= 0)
        return rc;
    /* (auto may move to derivative sampling as the fit lowers a roughness:
     * the memory check counts that mode's tape) */
    a->g.sampling_may_switch =
        a->g.sampling_auto && grad_auto_sampling(a->g.estimator, r->scene, r->ps).derivative_possible;
    if ((rc = cli_limits_optimize(&a->g, r->scene, r->ps, target_pixels(a, false), target_pixels(a, true),
                                   a->n_targets)) >= 0)
        return rc;
    if (a->reference && (rc = load_reference(a, r)) >= 0)
        return rc;
    if ((rc = grad_apply_sets(&a->g, r->scene)) >= 0)
        return rc;
    r->sampling = -1;   /* (decided at each iteration: opt_sampling) */
    if (dr_param_set_writable(r->scene, r->ps) != 0) {   /* (every step puts its values) */
        cli_error("optimize", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    const size_t T = (size_t)r->ps->total;
    r->theta = dr_alloc_big(sizeof(double) * T);
    r->grad = dr_alloc_big(sizeof(double) * T);
    r->se = dr_alloc_big(sizeof(double) * T);
    /* one target's result goes straight into grad and se (no parts: optimize
     * does not report them); several add up through gt and se_t */
    const bool several = a->n_targets > 1;
    r->gt = several ? dr_alloc_big(sizeof(double) * T) : NULL;
    r->se_t = several ? dr_alloc_big(sizeof(double) * T) : NULL;
    /* all marked: the first run writes grad and se whole (several: gt and
     * se_t, and grad and se are cleared whole), and the masks are true
     * from then on */
    const size_t words = (size_t)dr_mask_words((int64_t)T);
    r->nonzero = malloc(sizeof(uint64_t) * words);
    r->nonzero_t = several ? malloc(sizeof(uint64_t) * words) : NULL;
    if (r->nonzero)
        memset(r->nonzero, 0xff, sizeof(uint64_t) * words);
    if (r->nonzero_t)
        memset(r->nonzero_t, 0xff, sizeof(uint64_t) * words);
    r->se_blocks = calloc(words, sizeof(uint64_t));
    for (int k = 0; r->se_blocks && k < r->ps->n; k++)
        for (int64_t i = 0; !dr_param_is_array(&r->ps->params[k]) && i < r->ps->params[k].size; i++)
            dr_mask_mark(r->se_blocks, r->ps->params[k].offset + i);
    if (!r->theta || !r->grad || !r->se || !r->nonzero || !r->se_blocks ||
        (several && (!r->gt || !r->se_t || !r->nonzero_t))) {
        cli_error("optimize", "out of memory");
        return DR_EXIT_FAILURE;
    }
    dr_param_set_get(r->scene, r->ps, r->theta);
    r->adam = dr_adam_create(r->ps, r->theta, a->lr);
    if (!r->adam) {
        cli_error("optimize", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    r->adam->threads = a->g.threads;   /* (a texture's step on the workers the run asked for) */
    r->scratch.est.many_runs = true;   /* (its gradient runs: one an iteration, estimator.h) */
    return -1;
}

/* --resume: the checkpoint, read before --out-dir is created, so a missing
 * one leaves nothing behind. */
static int read_checkpoint(const struct opt_args *a, struct opt_run *r)
{
    int64_t it;
    int crc = dr_checkpoint_read(r->ckpt, r->ps, r->theta, r->adam, &it);
    if (crc != 0) {
        cli_error("optimize", "--resume: %s", dr_last_error());
        return crc == DR_ERR_ARG ? DR_EXIT_USAGE : cli_error_exit(DR_EXIT_INPUT);
    }
    if (it > a->iters) {
        cli_error("optimize", "--resume: %s is at iteration %lld, beyond --iters %d", r->ckpt, (long long)it,
                  a->iters);
        return DR_EXIT_USAGE;
    }
    r->it0 = (int)it;
    return -1;
}

/* The output directory (created, or the resumed run's history read back)
 * and, for a new run, the before and target pictures. */
static int opt_open_outputs(const struct opt_args *a, struct opt_run *r)
{
    int rc;
    path_in(r->ckpt, sizeof r->ckpt, a->out_dir, "checkpoint.txt");
    if (a->resume && (rc = read_checkpoint(a, r)) >= 0)
        return rc;
    size_t made_from = first_missing_prefix(a->out_dir);
    if (make_dirs(a->out_dir) != 0) {
        cli_error("optimize", "--out-dir %s: cannot create: %s", a->out_dir, strerror(errno));
        unmake_dirs(a->out_dir, made_from);
        return DR_EXIT_FAILURE;
    }
    cli_remove_stale_temps(a->out_dir, a->output);   /* left by a killed run */
    /* -o may point into the progress directory just created */
    if (a->output && !cli_output_dir_writable("optimize", a->output)) {
        unmake_dirs(a->out_dir, made_from);
        return DR_EXIT_FAILURE;
    }
    if (!a->resume) {
        if ((rc = save_view(a, r->scene, "before.png")) != DR_EXIT_OK) {
            unmake_dirs(a->out_dir, made_from);
            return rc;
        }
        char tp[4096];
        path_in(tp, sizeof tp, a->out_dir, "target.png");
        if (dr_image_write(tp, a->targets[0].rw, a->targets[0].rh, 3, a->targets[0].rgb) != 0) {
            cli_error("optimize", "%s", dr_last_error());
            unmake_dirs(a->out_dir, made_from);
            return cli_error_exit(DR_EXIT_FAILURE);
        }
        return -1;
    }
    if (!read_loss_csv(a->out_dir, &r->hist, r->it0)) {
        cli_error("optimize", "out of memory for the loss history");
        return DR_EXIT_FAILURE;
    }
    /* a run resumed at its last iteration reports the loss it ended with */
    r->loss = r->it0 > 0 && r->hist.n >= r->it0 ? r->hist.loss[r->it0 - 1] : NAN;
    dr_param_set_put(r->scene, r->ps, r->theta);
    if (dr_scene_refresh(r->scene) != 0) {
        cli_error("optimize", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    fprintf(stderr, "drender optimize: resuming at iteration %d from %s\n", r->it0, r->ckpt);
    return -1;
}

/* Several targets: grad and se are sums over the targets' runs, of gt and
 * of se_t squared, each +0 outside its mask (reverse.h). A sum that starts
 * at +0 never becomes -0, so adding +0 changes none of them: only the
 * marked blocks of grad are visited, and grad's mask is the union of the
 * targets'. The standard errors are those of the parameters shown (not
 * images': r->se_blocks), a few numbers, summed entry by entry.
 * clear_sums: +0 where the last iteration's sums were (its mask); add_target
 * adds a target's run; root_sums takes the standard errors' roots. */
static void clear_sums(struct opt_run *r, int64_t T)
{
    for (int64_t i = dr_mask_next(r->nonzero, NULL, 0, T); i < T;) {
        const int64_t j = dr_mask_run_end(r->nonzero, NULL, i, T);
        memset(r->grad + i, 0, sizeof(double) * (size_t)(j - i));
        i = dr_mask_next(r->nonzero, NULL, j, T);
    }
    memset(r->nonzero, 0, sizeof(uint64_t) * (size_t)dr_mask_words(T));
    for (int k = 0; k < r->ps->n; k++)
        if (!dr_param_is_array(&r->ps->params[k]))
            memset(r->se + r->ps->params[k].offset, 0, sizeof(double) * (size_t)r->ps->params[k].size);
}

static void add_target(struct opt_run *r, int64_t T)
{
    for (int64_t i = dr_mask_next(r->nonzero_t, NULL, 0, T); i < T;) {
        const int64_t j = dr_mask_run_end(r->nonzero_t, NULL, i, T);
        for (; i < j; i++)
            r->grad[i] += r->gt[i];
        i = dr_mask_next(r->nonzero_t, NULL, j, T);
    }
    for (int64_t w = 0; w < dr_mask_words(T); w++)
        r->nonzero[w] |= r->nonzero_t[w];
    for (int k = 0; k < r->ps->n; k++)
        for (int64_t i = 0; !dr_param_is_array(&r->ps->params[k]) && i < r->ps->params[k].size; i++) {
            const int64_t e = r->ps->params[k].offset + i;
            r->se[e] += r->se_t[e] * r->se_t[e];
        }
}

static void root_sums(struct opt_run *r)
{
    for (int k = 0; k < r->ps->n; k++)
        for (int64_t i = 0; !dr_param_is_array(&r->ps->params[k]) && i < r->ps->params[k].size; i++)
            r->se[r->ps->params[k].offset + i] = sqrt(r->se[r->ps->params[k].offset + i]);
}

/* The sampling mode of iteration it: --sampling's, or auto's choice from the
 * values the fit has reached (a pure function of them, so a resumed run
 * decides as the uninterrupted one did). A change is said on stderr, the
 * first few times (a roughness that hovers at the threshold would say it at
 * every step). */
static enum dr_sampling opt_sampling(const struct opt_args *a, struct opt_run *r, int it)
{
    if (!a->g.sampling_auto)
        return a->g.sampling;
    const struct grad_auto_choice c = grad_auto_sampling(a->g.estimator, r->scene, r->ps);
    if (r->sampling < 0) {   /* the first iteration this run: the note grad would print */
        grad_auto_note(&a->g, r->scene, &c, 0);
    } else if ((int)c.sampling != r->sampling) {
        if (r->auto_changes < 4) {
            if (isatty(2))
                fputc('\n', stderr);   /* (after the progress line) */
            grad_auto_note(&a->g, r->scene, &c, it + 1);
        } else if (r->auto_changes == 4)
            cli_error("optimize", "note: --sampling auto: further changes of sampling mode are not reported "
                                  "(--json gives every iteration's)");
        r->auto_changes++;
    }
    return c.sampling;
}

/* Loss and gradient of iteration `it` over every target, from
 * drivers/reverse.h (batches with primals of their own, independent of
 * their gradient samples); the targets' standard errors add in quadrature. */
static int opt_gradient(const struct opt_args *a, struct opt_run *r, int it)
{
    r->sampling = (int)opt_sampling(a, r, it);
    const int64_t T = r->ps->total;
    const bool several = a->n_targets > 1;
    if (several)   /* (one target's run overwrites both) */
        clear_sums(r, T);
    r->loss = 0.0;
    for (int ti = 0; ti < a->n_targets; ti++) {
        const struct target *t = &a->targets[ti];
        const struct dr_camera view = view_camera(r->scene, t->camera), *cam = &view;
        struct dr_reverse_options o = {
            .estimator = a->g.estimator, .loss = (enum dr_loss_kind)a->loss, .loss_scale = 1.0 / a->n_targets,
            .batches = a->batches, .primal = a->primal,
            .problem = grad_problem(&a->g, r->scene, cam, r->ps, t->w, t->h, a->g.spp,
                                    iteration_seed(a->g.seed, it, ti, 0x47524144))};
        o.problem.sampling = (enum dr_sampling)r->sampling;
        o.scratch = &r->scratch;
        struct dr_reverse_result res = {.grad = several ? r->gt : r->grad, .se = several ? r->se_t : r->se,
                                        .image = t->render, .nonzero = several ? r->nonzero_t : r->nonzero,
                                        .se_blocks = r->se_blocks};
        if (dr_reverse_gradient(&o, t->rgb, &res) != 0) {
            cli_error("optimize", "%s", dr_last_error());
            return DR_EXIT_FAILURE;
        }
        r->loss += res.loss;
        if (several)
            add_target(r, T);
        if (ti == 0 && (it % a->render_every == 0)) {
            char name[64], path[4096];
            snprintf(name, sizeof name, "render-%04d.png", it);
            path_in(path, sizeof path, a->out_dir, name);
            if (dr_image_write(path, t->rw, t->rh, 3, t->render) != 0) {
                cli_error("optimize", "%s", dr_last_error());
                return cli_error_exit(DR_EXIT_FAILURE);
            }
        }
    }
    if (several)
        root_sums(r);
    return -1;
}

/* The largest error against --reference over the parameters (NaN without). */
static double reference_max_error(const struct opt_run *r)
{
    if (!r->ref)
        return NAN;
    double err = 0.0;
    for (int k = 0; k < r->ps->n; k++)
        err = fmax(err, reference_error(r->ps, r->theta, r->ref, k));
    return err;
}

/* One progress line per iteration (a live bar on a terminal), and one JSON
 * object on stdout with --json: 0, or the errno of its failed write. */
static int opt_report(const struct opt_args *a, const struct opt_run *r, int it, double sec, double per, double err)
{
    const bool tty = isatty(2);
    char eta[32];
    eta_text(per * (a->iters - it - 1), eta, sizeof eta);
    char refmsg[128] = "";
    if (r->ref)
        snprintf(refmsg, sizeof refmsg, "  max |error| %.4f", err);
    char bar[32] = "";
    if (tty) {
        int fill = (int)(20.0 * (it + 1) / a->iters);
        bar[0] = '[';
        for (int b = 0; b < 20; b++)
            bar[b + 1] = b < fill ? '=' : ' ';
        strcpy(bar + 21, "] ");
    }
    fprintf(stderr, "%s%siter %*d/%d  loss %.6e  %.2f s/iter  eta %s%s%s", tty ? "\r" : "", bar,
            (int)snprintf(NULL, 0, "%d", a->iters), it + 1, a->iters, r->loss, sec, eta, refmsg, tty ? "  " : "\n");
    if (!a->g.json)
        return 0;
    printf("{\"iteration\": %d, \"loss\": ", it + 1);
    json_number(stdout, r->loss);
    printf(", \"sampling\": ");
    json_string(stdout, dr_sampling_name((enum dr_sampling)r->sampling));
    printf(", \"seconds\": ");
    json_number(stdout, sec);
    printf(", \"eta_seconds\": ");
    json_number(stdout, per * (a->iters - it - 1));
    printf(", \"parameters\": {");
    print_values(stdout, r->ps, r->theta, true);
    /* this iteration's gradient and its total standard error (primal noise included) */
    printf("}, \"gradient\": {");
    print_values(stdout, r->ps, r->grad, true);
    printf("}, \"gradient_stderr\": {");
    print_values(stdout, r->ps, r->se, true);
    printf("}}\n");
    errno = 0;
    if (fflush(stdout) == 0 && !ferror(stdout))
        return 0;
    return errno ? errno : EIO;
}

/* The iterations: gradient, Adam step, history, report, checkpoint every K
 * and on SIGINT/SIGTERM (then exit 128 + signal). */
static int opt_iterations(const struct opt_args *a, struct opt_run *r)
{
    double t_loop = dr_clock_seconds();
    for (int it = r->it0; it < a->iters; it++) {
        double t_it = dr_clock_seconds();
        int rc = opt_gradient(a, r, it);
        if (rc >= 0)
            return rc;
        /* (a texture's step and write-back visit the blocks its gradients have reached) */
        dr_adam_step_masked(r->adam, r->theta, r->grad, r->nonzero);
        dr_param_set_put_threads(r->scene, r->ps, r->theta, a->g.threads, dr_adam_changed(r->adam));
        if (dr_param_set_refresh(r->scene, r->ps) != 0) {
            cli_error("optimize", "%s", dr_last_error());
            return DR_EXIT_FAILURE;
        }
        double now = dr_clock_seconds(), sec = now - t_it, err = reference_max_error(r);
        if (!history_add(&r->hist, it, r->loss, sec, err)) {
            cli_error("optimize", "out of memory for the loss history");
            return DR_EXIT_FAILURE;
        }
        if (!write_loss_csv(a->out_dir, &r->hist))
            return DR_EXIT_FAILURE;
        /* (--json progress nobody receives, a full disk say: the run stops
         * here as when interrupted, its checkpoint written) */
        const int lost = opt_report(a, r, it, sec, (now - t_loop) / (it - r->it0 + 1), err);
        /* (an interrupted run's is on disk before it stops; the others
         * finish beside the next iterations, the last beside the final
         * pictures, opt_finish) */
        const bool last = it + 1 == a->iters, stop = stop_signal || lost != 0;
        if ((it + 1) % a->ckpt_every == 0 || last || stop) {
            int crc = dr_checkpoint_write_async(&r->pending, r->ckpt, r->scene_path, r->ps, r->theta, r->adam, it + 1);
            if (crc == 0 && stop)
                crc = dr_checkpoint_wait(&r->pending);
            if (crc != 0) {
                cli_error("optimize", "%s", dr_last_error());
                return DR_EXIT_FAILURE;
            }
        }
        if (lost && !last) {
            if (isatty(2))
                fputc('\n', stderr);
            cli_error("optimize", "cannot write standard output: %s; stopped after iteration %d, checkpoint written to %s; continue with --resume",
                      strerror(lost), it + 1, r->ckpt);
            clearerr(stdout);   /* (reported: main's close need not say it again) */
            return DR_EXIT_FAILURE;
        }
        if (stop_signal) {
            if (isatty(2))
                fputc('\n', stderr);
            cli_error("optimize", "interrupted after iteration %d: checkpoint written to %s; continue with --resume",
                      it + 1, r->ckpt);
            return 128 + stop_signal;
        }
    }
    if (isatty(2))
        fputc('\n', stderr);
    return -1;
}

/* opt_iterations with SIGINT/SIGTERM caught, and the previous handlers put
 * back afterwards: in a batch (cmd_batch.c) the jobs after this one must be
 * stoppable as usual. */
static int opt_loop(const struct opt_args *a, struct opt_run *r)
{
    struct sigaction sa, old_int, old_term;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    stop_signal = 0;
    sigaction(SIGINT, &sa, &old_int);
    sigaction(SIGTERM, &sa, &old_term);
    int rc = opt_iterations(a, r);
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    return rc;
}

/* Human summary (stdout, or stderr when stdout carries --json). */
static void opt_summary_text(FILE *so, const struct opt_args *a, const struct opt_run *r)
{
    const struct dr_param_set *ps = r->ps;
    fprintf(so, "final loss %.6e after %d iterations (%.1f s)\n", r->loss, a->iters, dr_clock_seconds() - r->t_start);
    if (r->ref) {
        fprintf(so, "%-68s %-26s %-26s %s\n", "parameter", "recovered", "true", "max |error|");
        for (int k = 0; k < ps->n; k++) {
            const struct dr_param *p = &ps->params[k];
            if (dr_param_is_array(p)) {
                fprintf(so, "%-68s relative error %.4f\n", p->name, reference_rel_error(ps, r->theta, r->ref, k));
                continue;
            }
            char got[128] = "", want[128] = "";
            for (int64_t i = 0; i < p->size; i++) {
                size_t gl = strlen(got), wl = strlen(want);
                snprintf(got + gl, sizeof got - gl, "%s%.4f", i ? " " : "", r->theta[p->offset + i]);
                snprintf(want + wl, sizeof want - wl, "%s%.4f", i ? " " : "", r->ref[p->offset + i]);
            }
            char shown[DR_PARAM_NAME_MAX * 2];
            dr_param_display_name(r->scene, p, shown, sizeof shown);
            fprintf(so, "%-68s %-26s %-26s %.4f\n", shown, got, want, reference_error(ps, r->theta, r->ref, k));
        }
    } else {
        fprintf(so, "optimised parameters:\n");
        print_values(so, ps, r->theta, false);
    }
    if (a->output)
        fprintf(so, "wrote %s\n", a->output);
    fprintf(so, "progress files in %s/ (loss.csv, loss.png, before.png, after.png, target.png, render-*.png)\n",
            a->out_dir);
}

static void opt_summary_json(const struct opt_args *a, const struct opt_run *r)
{
    const struct dr_param_set *ps = r->ps;
    printf("{\"done\": true, \"iterations\": %d, \"final_loss\": ", a->iters);
    json_number(stdout, r->loss);
    printf(", \"seconds\": ");
    json_number(stdout, dr_clock_seconds() - r->t_start);
    printf(", \"estimator\": ");
    json_string(stdout, a->g.estimator->name);
    printf(", \"sampling\": ");   /* (the last iteration's; auto decides at every one) */
    json_string(stdout, dr_sampling_name(r->sampling >= 0 ? (enum dr_sampling)r->sampling : a->g.sampling));
    printf(", \"sampling_requested\": ");
    json_string(stdout, a->g.sampling_auto ? "auto" : dr_sampling_name(a->g.sampling));
    printf(", \"sampler\": ");   /* (the default depends on --primal and --batches: grad_default_sampler) */
    json_string(stdout, dr_sampler_kind_name(a->g.sampler));
    printf(", \"peak_memory_bytes\": %llu", (unsigned long long)cli_peak_rss_bytes());
    cli_json_memory_estimate(stdout);
    printf(", \"output\": ");
    if (a->output)
        json_string(stdout, a->output);
    else
        fputs("null", stdout);
    if (r->ref) {
        printf(", \"reference_error\": {");
        for (int k = 0; k < ps->n; k++) {
            const struct dr_param *p = &ps->params[k];
            printf("%s", k ? ", " : "");
            json_string(stdout, p->name);
            printf(": ");
            json_number(stdout, dr_param_is_array(p)
                                    ? reference_rel_error(ps, r->theta, r->ref, k)
                                    : reference_error(ps, r->theta, r->ref, k));
        }
        printf("}");
    }
    printf(", \"parameters\": {");
    print_values(stdout, ps, r->theta, true);
    printf("}}\n");
}

/* After the last iteration: the loss plot, the after picture, the glTF, the summary. */
static int opt_finish(const struct opt_args *a, struct opt_run *r)
{
    if (!plot_loss(a->out_dir, r->ref != NULL))
        return DR_EXIT_FAILURE;
    int rc = save_view(a, r->scene, "after.png");
    if (rc != DR_EXIT_OK)
        return rc;
    if (a->output && dr_gltf_write(r->scene, r->ps, a->output) != 0) {
        cli_error("optimize", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    if (dr_checkpoint_wait(&r->pending) != 0) {   /* (the last checkpoint, on disk before the summary) */
        cli_error("optimize", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    opt_summary_text(a->g.json ? stderr : stdout, a, r);
    if (a->g.json)
        opt_summary_json(a, r);
    return DR_EXIT_OK;
}

static void opt_free(struct opt_args *a, struct opt_run *r)
{
    if (dr_checkpoint_wait(&r->pending) != 0)   /* (a run that failed otherwise: its last checkpoint's end) */
        cli_error("optimize", "%s", dr_last_error());
    for (int i = 0; i < a->n_targets; i++) {
        dr_image_release(&a->targets[i].img);
        free(a->targets[i].rgb);
        free(a->targets[i].render);
    }
    free(r->hist.loss);
    free(r->hist.seconds);
    free(r->hist.error);
    free(r->theta);
    dr_reverse_scratch_free(&r->scratch);
    free(r->grad);
    free(r->gt);
    free(r->se);
    free(r->nonzero);
    free(r->nonzero_t);
    free(r->se_t);
    free(r->se_blocks);
    free(r->ref);
    dr_adam_destroy(r->adam);
    dr_param_set_destroy(r->ps);
    dr_scene_destroy(r->scene);
    dr_scene_destroy(r->ref_scene);
    free(r->scene_path);
    grad_common_free(&a->g);
}

int cmd_optimize(int argc, char **argv)
{
    struct opt_run r = {.t_start = dr_clock_seconds()};
    struct opt_args a;
    memset(&a, 0, sizeof a);
    grad_common_init(&a.g, "optimize", 8);
    a.g.max_depth = 6;
    a.iters = 100;
    a.render_every = 10;
    a.ckpt_every = 10;
    a.batches = 2;
    a.primal = DR_PRIMAL_CROSS;
    a.loss = DR_LOSS_L2;
    a.out_dir = "optimize-out";
    int rc = parse_args(argc, argv, &a);
    if (rc < 0 && (rc = check_args(&a)) < 0) {
        grad_default_sampler(&a.g, true, a.primal, a.batches);
        if ((rc = opt_load(&a, &r)) < 0 && (rc = opt_open_outputs(&a, &r)) < 0 && (rc = opt_loop(&a, &r)) < 0)
            rc = opt_finish(&a, &r);
    }
    opt_free(&a, &r);
    return rc;
}
