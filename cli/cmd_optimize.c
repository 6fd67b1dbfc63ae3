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

#include "camera.h"
#include "cli.h"
#include "error.h"
#include "gltf_write.h"
#include "grad_common.h"
#include "image_io.h"
#include "loss.h"
#include "mem_limits.h"
#include "optimizer.h"
#include "render.h"
#include "sampler.h"
#include "stale_temps.h"

#define MAX_TARGETS 64

void cmd_optimize_usage(FILE *out)
{
    fprintf(out,
            "usage: drender optimize [SCENE] --target [CAMERA=]IMG [--target ...] --param P [--param P ...]\n"
            "                        [options]\n"
            "\n"
            "Fits the parameters P of SCENE (default: the bundled Cornell box) so that its\n"
            "renders match the target images, with Adam on gradients from an estimator.\n"
            "Each --target is seen through camera CAMERA of the file (default 0) and is\n"
            "rendered at the target's own size.\n"
            "\n"
            "options:\n"
            "      --target [N=]IMG   target image, optionally tied to camera N (repeatable)\n"
            "      --param P          parameter to optimise (JSON pointer, see 'drender params')\n"
            "      --set P=V[,V...]   start parameter P from these values instead of the file's\n"
            "      --iters N          iterations (default 100)\n"
            "      --lr X             learning rate for every parameter (default: per kind:\n"
            "                         0.02 for base colours, metallic, roughness and texels;\n"
            "                         5%% of the value for emission, lights and environment)\n"
            "      --loss l1|l2       image loss (default l2)\n"
            "      --estimator E      gradient estimator: prb (default) or tape\n"
            "      --sampling S       detached (the only one implemented)\n"
            "      --spp N            samples per pixel for the loss image and for the gradient\n"
            "                         (default 8)\n"
            "      --max-depth D      path segments (default 6)\n"
            "      --res WxH          render size; every target must have it (default: each\n"
            "                         target's own size)\n"
            "      --seed S           random seed (default 0)\n"
            "      --threads T        worker threads (default: one per CPU)\n"
            "  -o, --output FILE      write the optimised scene (.gltf or .glb)\n"
            "      --out-dir DIR      progress files (default optimize-out): loss.csv, loss.png,\n"
            "                         render-NNNN.png, before.png, after.png, target.png,\n"
            "                         checkpoint.txt\n"
            "      --render-every K   save the current render every K iterations (default 10)\n"
            "      --checkpoint-every K  checkpoint every K iterations (default 10)\n"
            "      --resume           continue from DIR/checkpoint.txt\n"
            "      --reference SCENE  a scene holding the true values (synthetic tests): report\n"
            "                         the parameter error each iteration and at the end\n"
            "      --json             one JSON object per iteration on stdout, then a summary\n"
            "  -h, --help             show this help\n");
}

enum { OOPT_TARGET = GOPT_END, OOPT_ITERS, OOPT_LR, OOPT_LOSS, OOPT_OUTDIR, OOPT_RESUME, OOPT_RENDER_EVERY,
       OOPT_CKPT_EVERY, OOPT_REFERENCE };

struct target {
    const char *arg, *path;
    int camera;
    struct dr_image img;
    float *rgb;          /* linear target */
    int w, h;
    float *render, *adjoint;
};

struct opt_args {
    struct grad_common g;
    struct target targets[MAX_TARGETS];
    int n_targets;
    int iters, render_every, ckpt_every;
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
        {NULL, 0, NULL, 0},
    };
    long v;
    opterr = 0;
    optind = 1;
    int c;
    while ((c = getopt_long(argc, argv, ":o:h", opts, NULL)) != -1) {
        int rc = grad_common_option(&a->g, c, optarg);
        if (rc >= 0) {
            if (rc != 0)
                return rc;
            continue;
        }
        switch (c) {
        case 'h': cmd_optimize_usage(stdout); return DR_EXIT_OK;
        case 'o': a->output = optarg; break;
        case OOPT_TARGET:
            if (a->n_targets == MAX_TARGETS) {
                cli_error("optimize", "--target: at most %d targets", MAX_TARGETS);
                return DR_EXIT_USAGE;
            }
            a->targets[a->n_targets++].arg = optarg;
            break;
        case OOPT_ITERS:
            if (!cli_parse_int("optimize", "--iters", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
            a->iters = (int)v;
            break;
        case OOPT_LR:
            if (!cli_parse_double("optimize", "--lr", optarg, 0.0, &a->lr)) return DR_EXIT_USAGE;
            break;
        case OOPT_LOSS:
            a->loss = dr_loss_parse(optarg);
            if (a->loss < 0) {
                cli_error("optimize", "--loss: '%s' is not a loss (use l1 or l2)", optarg);
                return DR_EXIT_USAGE;
            }
            break;
        case OOPT_OUTDIR: a->out_dir = optarg; break;
        case OOPT_RESUME: a->resume = true; break;
        case OOPT_RENDER_EVERY:
            if (!cli_parse_int("optimize", "--render-every", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
            a->render_every = (int)v;
            break;
        case OOPT_CKPT_EVERY:
            if (!cli_parse_int("optimize", "--checkpoint-every", optarg, 1, 100000000, &v)) return DR_EXIT_USAGE;
            a->ckpt_every = (int)v;
            break;
        case OOPT_REFERENCE: a->reference = optarg; break;
        default: return grad_getopt_error("optimize", c, argv, "o");
        }
    }
    if (optind < argc)
        a->g.scene_arg = argv[optind++];
    if (optind < argc) {
        cli_error("optimize", "unexpected argument '%s' (one scene at a time)", argv[optind]);
        return DR_EXIT_USAGE;
    }
    return -1;
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

static void history_add(struct history *h, int it, double loss, double sec, double err)
{
    if (it >= h->cap) {
        int cap = h->cap ? h->cap * 2 : 256;
        while (cap <= it)
            cap *= 2;
        h->loss = realloc(h->loss, sizeof(double) * (size_t)cap);
        h->seconds = realloc(h->seconds, sizeof(double) * (size_t)cap);
        h->error = realloc(h->error, sizeof(double) * (size_t)cap);
        h->cap = cap;
    }
    h->loss[it] = loss;
    h->seconds[it] = sec;
    h->error[it] = err;
    if (it + 1 > h->n)
        h->n = it + 1;
}

static void path_in(char *buf, size_t size, const char *dir, const char *name)
{
    snprintf(buf, size, "%s/%s", dir, name);
}

/* Rewrites DIR/loss.csv atomically. */
static void write_loss_csv(const char *dir, const struct history *h)
{
    char path[4096], tmp[4200];
    path_in(path, sizeof path, dir, "loss.csv");
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return;
    fprintf(f, "iteration,loss,seconds,parameter_error\n");
    for (int i = 0; i < h->n; i++) {
        fprintf(f, "%d,%.10g,%.4f,", i, h->loss[i], h->seconds[i]);
        if (isfinite(h->error[i]))
            fprintf(f, "%.6g", h->error[i]);
        fputc('\n', f);
    }
    if (fclose(f) == 0)
        rename(tmp, path);
    else
        unlink(tmp);
}

/* Reads back DIR/loss.csv (on --resume) up to `upto` iterations. */
static void read_loss_csv(const char *dir, struct history *h, int upto)
{
    char path[4096], line[256];
    path_in(path, sizeof path, dir, "loss.csv");
    FILE *f = fopen(path, "r");
    if (!f)
        return;
    while (fgets(line, sizeof line, f)) {
        int it;
        double l, s, e = NAN;
        int n = sscanf(line, "%d,%lf,%lf,%lf", &it, &l, &s, &e);
        if (n >= 3 && it >= 0 && it < upto)
            history_add(h, it, l, s, n == 4 ? e : NAN);
    }
    fclose(f);
}

/* DIR/loss.png with gnuplot (a warning if gnuplot is missing). */
static void plot_loss(const char *dir, bool with_error)
{
    char csv[4096], png[4096], tmp[4200], cmd[9000];
    path_in(csv, sizeof csv, dir, "loss.csv");
    path_in(png, sizeof png, dir, "loss.png");
    snprintf(tmp, sizeof tmp, "%s/.loss.tmp.png", dir);
    snprintf(cmd, sizeof cmd, "gnuplot 2>/dev/null");
    FILE *g = popen(cmd, "w");
    if (!g) {
        cli_error("optimize", "warning: cannot run gnuplot: %s not drawn", png);
        return;
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
    if (rc == 0 && access(tmp, R_OK) == 0)
        rename(tmp, png);
    else {
        unlink(tmp);
        cli_error("optimize", "warning: gnuplot failed: %s not drawn (install gnuplot-nox)", png);
    }
}

static void eta_text(double secs, char *buf, size_t size)
{
    long s = (long)(secs + 0.5);
    if (s >= 3600)
        snprintf(buf, size, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
    else
        snprintf(buf, size, "%ld:%02ld", s / 60, s % 60);
}

/* Renders target 0's view at higher quality into DIR/NAME. */
static int save_view(const struct opt_args *a, const struct dr_scene *scene, const char *name)
{
    const struct target *t = &a->targets[0];
    char path[4096];
    path_in(path, sizeof path, a->out_dir, name);
    float *rgb = malloc(sizeof(float) * 3 * (size_t)t->w * t->h);
    if (!rgb)
        return DR_EXIT_FAILURE;
    struct dr_render_opts ro = {t->w, t->h, 4 * a->g.spp, a->g.max_depth, 5, a->g.seed ^ 0xbefa, a->g.threads, false};
    int rc = dr_render(scene, &scene->cameras[t->camera], &ro, rgb, NULL);
    if (rc == 0)
        rc = dr_image_write(path, t->w, t->h, 3, rgb);
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
        if (p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP)
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

static int load_targets(struct opt_args *a)
{
    for (int i = 0; i < a->n_targets; i++) {
        struct target *t = &a->targets[i];
        int rc = grad_load_target("optimize", t->path, &t->img, &t->rgb);
        if (rc >= 0)
            return rc;
        t->w = t->img.width;
        t->h = t->img.height;
        if (a->g.res_given && (t->w != a->g.width || t->h != a->g.height)) {
            cli_error("optimize", "--target %s is %dx%d but --res asks for %dx%d", t->path, t->w, t->h, a->g.width,
                      a->g.height);
            return DR_EXIT_USAGE;
        }
        t->render = malloc(sizeof(float) * 3 * (size_t)t->w * t->h);
        t->adjoint = malloc(sizeof(float) * 3 * (size_t)t->w * t->h);
        if (!t->render || !t->adjoint) {
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

int cmd_optimize(int argc, char **argv)
{
    double t_start = cli_now();
    struct opt_args a;
    memset(&a, 0, sizeof a);
    grad_common_init(&a.g, "optimize", 8);
    a.g.max_depth = 6;
    a.iters = 100;
    a.render_every = 10;
    a.ckpt_every = 10;
    a.loss = DR_LOSS_L2;
    a.out_dir = "optimize-out";
    char *scene_path = NULL;
    struct dr_scene *scene = NULL, *ref_scene = NULL;
    struct dr_param_set *ps = NULL;
    struct dr_adam *adam = NULL;
    double *theta = NULL, *grad = NULL, *gt = NULL, *ref = NULL;
    struct history hist = {0, 0, NULL, NULL, NULL};
    struct dr_camera cam0;
    double loss = 0.0;
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0)
        goto out;
    if ((rc = check_args(&a)) >= 0)
        goto out;
    /* Every input is checked before any work starts. */
    if ((rc = load_targets(&a)) >= 0)
        goto out;
    if ((rc = grad_load_scene(&a.g, &scene_path, &scene, &cam0, a.targets[0].w, a.targets[0].h)) >= 0)
        goto out;
    for (int i = 0; i < a.n_targets; i++)
        if (a.targets[i].camera >= scene->n_cameras) {
            cli_error("optimize", "--target %s: camera %d: %s has %d camera%s", a.targets[i].arg,
                      a.targets[i].camera, scene_path, scene->n_cameras, scene->n_cameras == 1 ? "" : "s");
            rc = DR_EXIT_USAGE;
            goto out;
        }
    if ((rc = grad_param_set(&a.g, scene, &ps)) >= 0)
        goto out;
    if ((rc = cli_limits_optimize(&a.g, scene, ps, target_pixels(&a, false), target_pixels(&a, true))) >= 0)
        goto out;
    if (a.reference) {
        ref_scene = dr_scene_load(a.reference);
        if (!ref_scene) {
            cli_error("optimize", "--reference %s", dr_last_error());
            rc = DR_EXIT_INPUT;
            goto out;
        }
        struct dr_param_set *rps = dr_param_set_create(ref_scene, a.g.params, a.g.n_params);
        if (!rps || rps->total != ps->total) {
            cli_error("optimize", "--reference %s: does not have the same parameters (%s)", a.reference,
                      rps ? "different sizes" : dr_last_error());
            dr_param_set_destroy(rps);
            rc = DR_EXIT_USAGE;
            goto out;
        }
        ref = malloc(sizeof(double) * (size_t)ps->total);
        dr_param_set_get(ref_scene, rps, ref);
        dr_param_set_destroy(rps);
    }
    if ((rc = grad_apply_sets(&a.g, scene)) >= 0)
        goto out;
    theta = malloc(sizeof(double) * (size_t)ps->total);
    grad = malloc(sizeof(double) * (size_t)ps->total);
    gt = malloc(sizeof(double) * (size_t)ps->total);
    if (!theta || !grad || !gt) {
        cli_error("optimize", "out of memory");
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    dr_param_set_get(scene, ps, theta);
    adam = dr_adam_create(ps, theta, a.lr);
    if (!adam) {
        cli_error("optimize", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    char ckpt[4096];
    path_in(ckpt, sizeof ckpt, a.out_dir, "checkpoint.txt");
    int it0 = 0;
    if (a.resume) {   /* read before --out-dir is created: a missing checkpoint leaves nothing behind */
        int64_t it;
        int crc = dr_checkpoint_read(ckpt, ps, theta, adam, &it);
        if (crc != 0) {
            cli_error("optimize", "--resume: %s", dr_last_error());
            rc = crc == DR_ERR_ARG ? DR_EXIT_USAGE : DR_EXIT_INPUT;
            goto out;
        }
        if (it > a.iters) {
            cli_error("optimize", "--resume: %s is at iteration %lld, beyond --iters %d", ckpt, (long long)it,
                      a.iters);
            rc = DR_EXIT_USAGE;
            goto out;
        }
        it0 = (int)it;
    }
    size_t made_from = first_missing_prefix(a.out_dir);
    if (make_dirs(a.out_dir) != 0) {
        cli_error("optimize", "--out-dir %s: cannot create: %s", a.out_dir, strerror(errno));
        unmake_dirs(a.out_dir, made_from);
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    cli_remove_stale_temps(a.out_dir, a.output);   /* left by a killed run */
    /* -o may point into the progress directory just created */
    if (a.output && !cli_output_dir_writable("optimize", a.output)) {
        unmake_dirs(a.out_dir, made_from);
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    if (a.resume) {
        read_loss_csv(a.out_dir, &hist, it0);
        /* a run resumed at its last iteration reports the loss it ended with */
        loss = it0 > 0 && hist.n >= it0 ? hist.loss[it0 - 1] : NAN;
        dr_param_set_put(scene, ps, theta);
        if (dr_scene_refresh(scene) != 0) {
            cli_error("optimize", "%s", dr_last_error());
            rc = DR_EXIT_FAILURE;
            goto out;
        }
        fprintf(stderr, "drender optimize: resuming at iteration %d from %s\n", it0, ckpt);
    } else {
        int vrc = save_view(&a, scene, "before.png");
        if (vrc != DR_EXIT_OK) {
            rc = vrc;
            goto out;
        }
        char tp[4096];
        path_in(tp, sizeof tp, a.out_dir, "target.png");
        dr_image_write(tp, a.targets[0].w, a.targets[0].h, 3, a.targets[0].rgb);
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    const bool tty = isatty(2);
    double t_loop = cli_now();
    struct dr_grad_stats gs;
    memset(&gs, 0, sizeof gs);
    int it = it0;
    for (; it < a.iters; it++) {
        double t_it = cli_now();
        memset(grad, 0, sizeof(double) * (size_t)ps->total);
        loss = 0.0;
        for (int ti = 0; ti < a.n_targets && rc < 0; ti++) {
            struct target *t = &a.targets[ti];
            const struct dr_camera *cam = &scene->cameras[t->camera];
            size_t n = (size_t)t->w * t->h * 3;
            /* loss image and gradient from independent random numbers */
            struct dr_render_opts ro = {t->w, t->h, a.g.spp, a.g.max_depth, 5,
                                        iteration_seed(a.g.seed, it, ti, 0x5052494d), a.g.threads, false};
            if (dr_render(scene, cam, &ro, t->render, NULL) != 0) {
                cli_error("optimize", "%s", dr_last_error());
                rc = DR_EXIT_FAILURE;
                break;
            }
            loss += dr_loss_eval(a.loss, t->render, t->rgb, n) / a.n_targets;
            d_loss_eval(a.loss, t->render, t->rgb, n, 1.0 / a.n_targets, t->adjoint);
            struct dr_grad_problem p = {scene, cam, ps, t->w, t->h, a.g.spp, a.g.max_depth, 5,
                                        iteration_seed(a.g.seed, it, ti, 0x47524144), a.g.threads, 0};
            if (a.g.estimator->backward(&p, t->adjoint, gt, &gs) != 0) {
                cli_error("optimize", "%s", dr_last_error());
                rc = DR_EXIT_FAILURE;
                break;
            }
            for (int64_t i = 0; i < ps->total; i++)
                grad[i] += gt[i];
            if (ti == 0 && (it % a.render_every == 0)) {
                char name[64], path[4096];
                snprintf(name, sizeof name, "render-%04d.png", it);
                path_in(path, sizeof path, a.out_dir, name);
                dr_image_write(path, t->w, t->h, 3, t->render);
            }
        }
        if (rc >= 0)
            break;
        dr_adam_step(adam, theta, grad);
        dr_param_set_put(scene, ps, theta);
        if (dr_scene_refresh(scene) != 0) {
            cli_error("optimize", "%s", dr_last_error());
            rc = DR_EXIT_FAILURE;
            break;
        }
        double now = cli_now(), sec = now - t_it, err = NAN;
        if (ref) {
            err = 0.0;
            for (int k = 0; k < ps->n; k++)
                err = fmax(err, reference_error(ps, theta, ref, k));
        }
        history_add(&hist, it, loss, sec, err);
        write_loss_csv(a.out_dir, &hist);
        double per = (now - t_loop) / (it - it0 + 1);
        char eta[32];
        eta_text(per * (a.iters - it - 1), eta, sizeof eta);
        char refmsg[128] = "";
        if (ref)
            snprintf(refmsg, sizeof refmsg, "  max |error| %.4f", err);
        char bar[32] = "";
        if (tty) {   /* a live bar on a terminal, plain lines otherwise */
            int fill = (int)(20.0 * (it + 1) / a.iters);
            bar[0] = '[';
            for (int b = 0; b < 20; b++)
                bar[b + 1] = b < fill ? '=' : ' ';
            strcpy(bar + 21, "] ");
        }
        fprintf(stderr, "%s%siter %*d/%d  loss %.6e  %.2f s/iter  eta %s%s%s", tty ? "\r" : "", bar,
                (int)snprintf(NULL, 0, "%d", a.iters), it + 1, a.iters, loss, sec, eta, refmsg, tty ? "  " : "\n");
        if (a.g.json) {
            printf("{\"iteration\": %d, \"loss\": ", it + 1);
            json_number(stdout, loss);
            printf(", \"seconds\": ");
            json_number(stdout, sec);
            printf(", \"eta_seconds\": ");
            json_number(stdout, per * (a.iters - it - 1));
            printf(", \"parameters\": {");
            print_values(stdout, ps, theta, true);
            printf("}}\n");
            fflush(stdout);
        }
        bool last = it + 1 == a.iters;
        if ((it + 1) % a.ckpt_every == 0 || last || stop_signal) {
            if (dr_checkpoint_write(ckpt, scene_path, ps, theta, adam, it + 1) != 0) {
                cli_error("optimize", "%s", dr_last_error());
                rc = DR_EXIT_FAILURE;
                break;
            }
        }
        if (stop_signal) {
            if (tty)
                fputc('\n', stderr);
            cli_error("optimize", "interrupted after iteration %d: checkpoint written to %s; continue with --resume",
                      it + 1, ckpt);
            rc = 128 + stop_signal;
            break;
        }
    }
    if (tty && rc < 0)
        fputc('\n', stderr);
    if (rc >= 0)
        goto out;
    plot_loss(a.out_dir, ref != NULL);
    int vrc = save_view(&a, scene, "after.png");
    if (vrc != DR_EXIT_OK) {
        rc = vrc;
        goto out;
    }
    if (a.output && dr_gltf_write(scene, ps, a.output) != 0) {
        cli_error("optimize", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    /* human summary on stderr (stdout is for --json) */
    FILE *so = a.g.json ? stderr : stdout;
    fprintf(so, "final loss %.6e after %d iterations (%.1f s)\n", loss, a.iters, cli_now() - t_start);
    if (ref) {
        fprintf(so, "%-68s %-26s %-26s %s\n", "parameter", "recovered", "true", "max |error|");
        for (int k = 0; k < ps->n; k++) {
            const struct dr_param *p = &ps->params[k];
            if (p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP) {
                fprintf(so, "%-68s relative error %.4f\n", p->name, reference_rel_error(ps, theta, ref, k));
                continue;
            }
            char got[128] = "", want[128] = "";
            for (int64_t i = 0; i < p->size; i++) {
                size_t gl = strlen(got), wl = strlen(want);
                snprintf(got + gl, sizeof got - gl, "%s%.4f", i ? " " : "", theta[p->offset + i]);
                snprintf(want + wl, sizeof want - wl, "%s%.4f", i ? " " : "", ref[p->offset + i]);
            }
            char shown[DR_PARAM_NAME_MAX * 2];
            dr_param_display_name(scene, p, shown, sizeof shown);
            fprintf(so, "%-68s %-26s %-26s %.4f\n", shown, got, want, reference_error(ps, theta, ref, k));
        }
    } else {
        fprintf(so, "optimised parameters:\n");
        print_values(so, ps, theta, false);
    }
    if (a.output)
        fprintf(so, "wrote %s\n", a.output);
    fprintf(so, "progress files in %s/ (loss.csv, loss.png, before.png, after.png, target.png, render-*.png)\n",
            a.out_dir);
    if (a.g.json) {
        printf("{\"done\": true, \"iterations\": %d, \"final_loss\": ", a.iters);
        json_number(stdout, loss);
        printf(", \"seconds\": ");
        json_number(stdout, cli_now() - t_start);
        printf(", \"estimator\": ");
        json_string(stdout, a.g.estimator->name);
        printf(", \"peak_memory_bytes\": %llu", (unsigned long long)cli_peak_rss_bytes());
        cli_json_memory_estimate(stdout);
        printf(", \"output\": ");
        if (a.output)
            json_string(stdout, a.output);
        else
            fputs("null", stdout);
        if (ref) {
            printf(", \"reference_error\": {");
            for (int k = 0; k < ps->n; k++) {
                printf("%s", k ? ", " : "");
                json_string(stdout, ps->params[k].name);
                printf(": ");
                const struct dr_param *p = &ps->params[k];
                json_number(stdout, p->kind == DR_PARAM_IMAGE || p->kind == DR_PARAM_ENV_MAP
                                        ? reference_rel_error(ps, theta, ref, k)
                                        : reference_error(ps, theta, ref, k));
            }
            printf("}");
        }
        printf(", \"parameters\": {");
        print_values(stdout, ps, theta, true);
        printf("}}\n");
    }
    rc = DR_EXIT_OK;
out:
    for (int i = 0; i < a.n_targets; i++) {
        dr_image_release(&a.targets[i].img);
        free(a.targets[i].rgb);
        free(a.targets[i].render);
        free(a.targets[i].adjoint);
    }
    free(hist.loss);
    free(hist.seconds);
    free(hist.error);
    free(theta);
    free(grad);
    free(gt);
    free(ref);
    dr_adam_destroy(adam);
    dr_param_set_destroy(ps);
    dr_scene_destroy(scene);
    dr_scene_destroy(ref_scene);
    free(scene_path);
    grad_common_free(&a.g);
    return rc;
}
