/* drender grad: derivatives of the rendered image with respect to scene
 * parameters. Forward mode (no --target) writes d image / d parameter as a
 * float image per parameter; reverse mode (--target) prints d loss / d
 * parameter with standard errors from independent batches. */
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"
#include "error.h"
#include "estimator.h"
#include "bigalloc.h"
#include "grad_common.h"
#include "image.h"
#include "image_io.h"
#include "mem_limits.h"
#include "loss.h"
#include "params.h"
#include "render.h"
#include "reverse.h"
#include "sampler.h"
#include "scene.h"
#include "vis.h"
#include "zero_blocks.h"

/* DR_TAPE_PATHS_PER_WORKER as text, for the help */
#define TEXT_(x) #x
#define TEXT(x) TEXT_(x)
#define TAPE_PER_THREAD TEXT(DR_TAPE_PATHS_PER_WORKER)

/* The help text: one string, long by nature (no logic). */
void cmd_grad_usage(FILE *out)
{
    fprintf(out,
            "usage: drender grad [SCENE] --param P [--param P ...] -o DIMG [options]\n"
            "       drender grad [SCENE] --param P [--param P ...] --target IMG [options]\n"
            "\n"
            "Differentiates the image rendered from SCENE (default: the bundled Cornell box)\n"
            "with respect to parameters named by JSON pointers ('drender params SCENE' lists\n"
            "them; material names may stand in for indices).\n"
            "\n"
            "Forward mode (-o) writes, for each --param, d image / d parameter along all\n"
            "of the parameter's components at once (the image's change when every\n"
            "component grows by the same amount) as a linear float RGB image. With several\n"
            "--param, the parameter's index is inserted before the extension: dimg.0.exr,\n"
            "dimg.1.exr.\n"
            "\n"
            "Reverse mode (--target) renders the image, compares it with the target\n"
            "(--loss) and prints d loss / d parameter for every component, with a standard\n"
            "error from --batches independent batches. Texture gradients are written as\n"
            "float images to --grad-dir (/images/3 -> DIR/grad-images-3.exr).\n"
            "\n"
            "options:\n"
            "      --param P       a parameter to differentiate (repeatable, required)\n"
            "      --set P=V[,V...]  use these values for parameter P instead of the file's\n"
            "  -o, --output FILE   forward mode: derivative image, a float format\n"
            "                      (.exr, .tif, .pfm; not .png/.jpg, not .hdr: no negatives)\n"
            "      --vis FILE      forward mode: also a picture of the derivative (.png),\n"
            "                      blue < 0 < red, white = 0, scaled to the 99th percentile\n"
            "                      of |per-pixel mean over r, g, b|\n"
            "      --target IMG    reverse mode: the image to match (same size as the render;\n"
            "                      8-bit sRGB files are decoded to linear)\n"
            "      --loss L        reverse mode: l1 or l2 (mean over pixels and channels;\n"
            "                      default: l2)\n"
            "      --batches K     reverse mode: independent batches of ceil(spp / K) samples\n"
            "                      per pixel, each with its own primal (default: 4, at least\n"
            "                      2); the standard error is their spread, primal noise\n"
            "                      included\n"
            "      --primal M      reverse mode: where a batch's primal (the image the loss\n"
            "                      is taken at) comes from: cross (default: from the\n"
            "                      gradient's own samples, each weighted at the mean of its\n"
            "                      pixel's other samples: unbiased, no extra render) or\n"
            "                      separate\n"
            "                      (a render of its own; --json then also splits the standard\n"
            "                      error into gradient-sample and primal parts). Cross needs\n"
            "                      2+ samples per batch and the independent or sobol sampler\n"
            "                      (sobol: weighted at the other half's mean); else separate\n"
            "                      runs (--json: primal)\n"
            "      --grad-dir DIR  reverse mode: where texture gradients go (default: .)\n"
            "      --estimator E   gradient estimator: prb (path replay, default) or tape\n"
            GRAD_SAMPLING_HELP
            "      --regularize E  prb, attached: a vertex Jacobian whose smallest/largest\n"
            "                      singular value is below E is not inverted; forward mode\n"
            "                      restarts there instead (default: 1e-3; 0: always invert)\n"
            "      --medium-grad M drt (default: differential ratio tracking, unbiased) or\n"
            "                      baseline (differentiates the sampled collisions; biased\n"
            "                      where the density is 0), for media parameters\n"
            );
    /* split again: together these would pass the 4095 characters ISO C guarantees */
    fprintf(out,
            "      --spp N         samples per pixel (default: 16)\n"
            "      --max-depth D   path segments (default: 8)\n"
            "      --rr-depth D    Russian roulette from this many segments on (default: 5)\n"
            "      --res WxH       image size (default: the target's size, else as render)\n"
            "      --camera N      which camera of the file (default: 0)\n"
            "      --seed S        random seed (default: 0)\n"
            "      --threads T     worker threads (default: one per CPU)\n"
            "      --sampler S     random numbers: sobol (Owen-scrambled Sobol; the default,\n"
            "                      but independent where a batch renders its own primal:\n"
            "                      --primal separate or 1 sample a batch), independent\n"
            "                      (each number hashed on its own; the default before\n"
            "                      2026-12) or stratified (jittered strata over the spp)\n"
            "      --filter F      pixel filter: box (default), tent or gaussian[:STDDEV]\n"
            "                      (as render)\n"
            "      --crop X,Y,W,H  only this rectangle of the --res frame is rendered and\n"
            "                      compared: -o images are W x H; a --target may be W x H\n"
            "                      (then --res gives the frame) or the full frame\n"
            "      --batch N       tape: paths recorded per backward sweep, over all threads,\n"
            "                      in whole pixels (default 0: " TAPE_PER_THREAD " per thread, a tape the\n"
            "                      sweep reads back from the cache); bounds the tape's memory\n");
    /* a second literal: one would pass the 4095 characters ISO C guarantees */
    fprintf(out, GRAD_IGNORE_UNSUPPORTED_HELP
            "      --json          print a summary object on stdout (memory estimate and\n"
            "                      time by stage included)\n"
            "  -h, --help          show this help\n");
    grad_lighting_usage(out);
}

enum { OPT_VIS = GOPT_END, OPT_TARGET, OPT_LOSS, OPT_BATCHES, OPT_BATCH, OPT_GRAD_DIR, OPT_PRIMAL };

struct grad_args {
    struct grad_common g;
    const char *output, *vis, *target, *grad_dir;
    enum dr_loss_kind loss;
    bool loss_given, batches_given, grad_dir_given, primal_given;
    enum dr_primal_mode primal;
    int batches;
    int64_t batch;
    struct dr_media_plan media_plan;   /* forward mode: the parameters' runs share the media pilot */
};

/* The options only `grad` takes (grad_own_option_fn). */
static int own_option(void *ctx, int c, const char *optarg)
{
    struct grad_args *a = ctx;
    long v;
    switch (c) {
    case 'o': a->output = optarg; return 0;
    case OPT_VIS: a->vis = optarg; return 0;
    case OPT_TARGET: a->target = optarg; return 0;
    case OPT_LOSS: {
        int k = dr_loss_parse(optarg);
        if (k < 0) {
            cli_error("grad", "--loss: unknown loss '%s' (available: l1, l2)", optarg);
            return DR_EXIT_USAGE;
        }
        a->loss = (enum dr_loss_kind)k;
        a->loss_given = true;
        return 0;
    }
    case OPT_BATCHES:
        if (!cli_parse_int("grad", "--batches", optarg, 2, 1L << 20, &v)) return DR_EXIT_USAGE;
        a->batches = (int)v;
        a->batches_given = true;
        return 0;
    case OPT_BATCH:
        if (!cli_parse_int("grad", "--batch", optarg, 0, LONG_MAX, &v)) return DR_EXIT_USAGE;
        a->batch = v;
        return 0;
    case OPT_GRAD_DIR:
        a->grad_dir = optarg;
        a->grad_dir_given = true;
        return 0;
    case OPT_PRIMAL:
        a->primal_given = true;
        return grad_parse_primal("grad", optarg, &a->primal);
    default: return -1;
    }
}

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, struct grad_args *a)
{
    static const struct option opts[] = {
        GRAD_COMMON_LONG_OPTIONS,
        {"output", required_argument, NULL, 'o'},
        {"vis", required_argument, NULL, OPT_VIS},
        {"target", required_argument, NULL, OPT_TARGET},
        {"loss", required_argument, NULL, OPT_LOSS},
        {"batches", required_argument, NULL, OPT_BATCHES},
        {"batch", required_argument, NULL, OPT_BATCH},
        {"grad-dir", required_argument, NULL, OPT_GRAD_DIR},
        {"primal", required_argument, NULL, OPT_PRIMAL},
        {NULL, 0, NULL, 0},
    };
    return grad_parse_args(&a->g, argc, argv, opts, "o", own_option, a, cmd_grad_usage);
}

/* ---- file names ---- */

static const char *extension(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    return dot && (!slash || dot > slash) && dot != (slash ? slash + 1 : path) ? dot : NULL;
}

static bool ext_is(const char *ext, const char *want)
{
    return ext && strcasecmp(ext, want) == 0;
}

/* "dimg.exr" -> "dimg.3.exr" (no extension: "dimg.3"). */
static char *indexed_name(const char *path, int index)
{
    const char *ext = extension(path);
    size_t stem = ext ? (size_t)(ext - path) : strlen(path);
    size_t len = strlen(path) + 24;
    char *s = malloc(len);
    if (s)
        snprintf(s, len, "%.*s.%d%s", (int)stem, path, index, ext ? ext : "");
    return s;
}

/* Gradient image of an image parameter: DIR/grad-<pointer without the leading
 * '/', '/' -> '-'>.exr, e.g. /images/3 -> DIR/grad-images-3.exr and the
 * environment map -> DIR/grad-environment.exr. */
static char *grad_image_name(const char *dir, const struct dr_param *p)
{
    char base[DR_PARAM_NAME_MAX + 16];
    if (p->kind == DR_PARAM_ENV_MAP) {
        snprintf(base, sizeof base, "grad-environment.exr");
    } else {
        size_t k = 0;
        k += (size_t)snprintf(base, sizeof base, "grad-");
        for (const char *c = p->name + (p->name[0] == '/'); *c && k + 5 < sizeof base; c++)
            base[k++] = (*c == '/' || *c == '~' || isspace((unsigned char)*c)) ? '-' : *c;
        snprintf(base + k, sizeof base - k, ".exr");
    }
    size_t len = strlen(dir) + strlen(base) + 2;
    char *s = malloc(len);
    if (s)
        snprintf(s, len, "%s%s%s", dir, dir[strlen(dir) - 1] == '/' ? "" : "/", base);
    return s;
}

/* --crop with a crop-sized target and no --res: the frame's size is unknown
 * (without --res a target is the full frame). Returns -1 to go on or an exit code. */
static int crop_target_size(const struct grad_args *a, const struct dr_image *timg)
{
    const struct grad_common *g = &a->g;
    if (!g->crop_given || g->res_given || timg->width != g->crop_w || timg->height != g->crop_h)
        return -1;
    cli_error("grad", "--target %s is the crop's size (%dx%d): give the full frame's size with --res WxH",
              a->target, timg->width, timg->height);
    return DR_EXIT_USAGE;
}

/* ---- option checks that need no scene ---- */

static int check_args(struct grad_args *a)
{
    int rc = grad_common_check(&a->g);
    if (rc >= 0)
        return rc;
    if (!a->target) {
        if (a->loss_given || a->batches_given || a->grad_dir_given || a->primal_given) {
            cli_error("grad", "%s is for reverse mode: give --target IMG (forward mode writes -o)",
                      a->loss_given      ? "--loss"
                      : a->batches_given ? "--batches"
                      : a->primal_given  ? "--primal"
                                         : "--grad-dir");
            return DR_EXIT_USAGE;
        }
        if (!a->output) {
            cli_error("grad", "forward mode needs -o DIMG.exr (or give --target IMG for reverse mode)");
            return DR_EXIT_USAGE;
        }
        const char *ext = extension(a->output);
        if (ext_is(ext, ".hdr")) {
            cli_error("grad", "-o %s: Radiance HDR cannot store negative values; derivatives are signed: "
                              "use .exr, .tif or .pfm", a->output);
            return DR_EXIT_USAGE;
        }
        if (!(ext_is(ext, ".exr") || ext_is(ext, ".tif") || ext_is(ext, ".tiff") || ext_is(ext, ".pfm"))) {
            cli_error("grad", "-o %s: derivative images need a float format: use .exr, .tif or .pfm "
                              "(--vis FILE.png draws a picture of it)", a->output);
            return DR_EXIT_USAGE;
        }
        if (!dr_image_library_ok()) {
            cli_error("grad", "%s", dr_last_error());
            return DR_EXIT_FAILURE;
        }
        if (!dr_image_can_write(a->output)) {
            cli_error("grad", "-o %s: OpenImageIO cannot write this format", a->output);
            return DR_EXIT_USAGE;
        }
        if (a->vis && !dr_image_can_write(a->vis)) {
            cli_error("grad", "--vis %s: OpenImageIO cannot write this format (use e.g. .png)", a->vis);
            return DR_EXIT_USAGE;
        }
        if (a->vis && strcmp(a->vis, a->output) == 0) {
            cli_error("grad", "--vis %s: the same file as -o", a->vis);
            return DR_EXIT_USAGE;
        }
        if (!cli_output_dir_writable("grad", a->output) || (a->vis && !cli_output_dir_writable("grad", a->vis)))
            return DR_EXIT_FAILURE;
    } else {
        if (a->output || a->vis) {
            cli_error("grad", "%s is for forward mode; with --target, texture gradients go to --grad-dir",
                      a->output ? "-o" : "--vis");
            return DR_EXIT_USAGE;
        }
        struct stat sb;
        if (stat(a->grad_dir, &sb) != 0 || !S_ISDIR(sb.st_mode)) {
            cli_error("grad", "--grad-dir %s: not a directory", a->grad_dir);
            return DR_EXIT_USAGE;
        }
        if (access(a->grad_dir, W_OK) != 0) {
            cli_error("grad", "--grad-dir %s: cannot write into it: %s", a->grad_dir, strerror(errno));
            return DR_EXIT_FAILURE;
        }
    }
    return -1;
}

/* ---- summaries ---- */

static void json_open(FILE *f, const struct grad_args *a, const char *scene_path, const char *mode,
                      const struct grad_totals *t)
{
    fprintf(f, "{");
    grad_json_head(f, &a->g, scene_path);
    cli_json_memory_estimate(f);
    fprintf(f, ", \"mode\": \"%s\", ", mode);
    grad_json_run(f, t);
}

static bool is_image_param(const struct dr_param *p)
{
    return dr_param_is_array(p);
}

/* ---- forward mode ---- */

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* 99th percentile of |v| (n values); scratch: n floats. */
static double percentile99(const float *v, size_t n, float *scratch)
{
    for (size_t i = 0; i < n; i++)
        scratch[i] = isfinite(v[i]) ? fabsf(v[i]) : 0.0f;
    qsort(scratch, n, sizeof(float), cmp_float);
    return scratch[(size_t)floor(0.99 * (double)(n - 1))];
}

/* The --vis picture: t = 0.5 + 0.5 * clamp(mean_rgb / m, -1, 1). */
static int write_vis(const char *path, const float *dimg, int w, int h, double *scale)
{
    size_t n = (size_t)w * h;
    float *mean = malloc(sizeof(float) * n), *t = malloc(sizeof(float) * n);
    float *rgb = malloc(sizeof(float) * n * 3);
    int rc = DR_ERR_NOMEM;
    if (!mean || !t || !rgb) {
        dr_set_error("out of memory");
        goto out;
    }
    for (size_t i = 0; i < n; i++)
        mean[i] = (dimg[3 * i] + dimg[3 * i + 1] + dimg[3 * i + 2]) / 3.0f;
    double m = percentile99(mean, n, t);
    *scale = m;
    for (size_t i = 0; i < n; i++) {
        double x = m > 0.0 ? mean[i] / m : 0.0;
        x = x < -1.0 ? -1.0 : x > 1.0 ? 1.0 : x;
        t[i] = (float)(0.5 + 0.5 * x);
    }
    if ((rc = dr_colormap_diverging(t, w, h, rgb)) != 0)
        goto out;
    rc = dr_image_write(path, w, h, 3, rgb);
out:
    free(mean);
    free(t);
    free(rgb);
    return rc;
}

/* The forward-mode summary: JSON or one line per written image. */
struct forward_outputs {
    char **outs, **viss;             /* derivative image and --vis picture per parameter */
    double *vis_scale, *lo, *hi;     /* the picture's scale; the image's range */
    double *mis_w;                   /* --sampling mis: each parameter's weight of the detached estimate */
};

static void forward_print(FILE *f, const struct grad_args *a, const char *scene_path, const struct dr_param_set *ps,
                          const struct forward_outputs *fo, const struct grad_totals *tot, double t_load,
                          double t_write, double t_total)
{
    const int n = ps->n;
    char **outs = fo->outs, **viss = fo->viss;
    const double *vis_scale = fo->vis_scale, *lo = fo->lo, *hi = fo->hi;
    if (a->g.json) {
        json_open(f, a, scene_path, "forward", tot);
        fprintf(f, ", \"time\": {\"load\": ");
        json_number(f, t_load);
        fprintf(f, ", \"gradient\": ");
        json_number(f, tot->seconds);
        fprintf(f, ", \"write\": ");
        json_number(f, t_write);
        fprintf(f, ", \"total\": ");
        json_number(f, t_total);
        fprintf(f, "}, \"parameters\": [");
        for (int i = 0; i < n; i++) {
            fprintf(f, "%s{\"name\": ", i ? ", " : "");
            json_string(f, ps->params[i].name);
            fprintf(f, ", \"size\": %lld, \"file\": ", (long long)ps->params[i].size);
            json_string(f, outs[i]);
            if (viss[i]) {
                fprintf(f, ", \"vis\": ");
                json_string(f, viss[i]);
                fprintf(f, ", \"vis_scale\": ");
                json_number(f, vis_scale[i]);
            }
            fprintf(f, ", \"min\": ");
            json_number(f, lo[i]);
            fprintf(f, ", \"max\": ");
            json_number(f, hi[i]);
            grad_json_mis_weight(f, &a->g, fo->mis_w[i]);
            fputc('}', f);
        }
        fprintf(f, "], \"effects_differentiated\": ");
        grad_json_effects(f, ps);
        fprintf(f, "}\n");
    } else {
        for (int i = 0; i < n; i++) {
            fprintf(f, "%s: d image / d %s (sum over its %lld component%s), range [%.6g, %.6g]\n", outs[i],
                    ps->params[i].name, (long long)ps->params[i].size, ps->params[i].size == 1 ? "" : "s", lo[i],
                    hi[i]);
            if (viss[i])
                fprintf(f, "%s: picture, blue -%.3g .. white 0 .. red +%.3g\n", viss[i], vis_scale[i],
                        vis_scale[i]);
            if (a->g.sampling == DR_SAMPLING_MIS)
                fprintf(f, "%s: mis weight %.3f detached, %.3f attached\n", outs[i], fo->mis_w[i],
                        1.0 - fo->mis_w[i]);
        }
    }
}

/* The buffers of the forward passes, reused from pass to pass. */
struct forward_images {
    int w, h;                      /* the rendered rectangle */
    double *dir;                   /* the tangent direction (params->total entries) */
    double *dimg[DR_FORWARD_MAX];  /* d image / d parameter, one a parameter of the pass */
    float *fimg;                   /* ... as written */
    double *mis_one;               /* mis: the direction's weight */
};

/* Parameter i's derivative image (img->dimg[k]): its range and its files.
 * 0, or non-zero with dr_last_error set. */
static int forward_write(const struct forward_images *img, const struct forward_outputs *fo, int i, int k,
                         double *t_write)
{
    const size_t npix = (size_t)img->w * img->h;
    fo->lo[i] = INFINITY;
    fo->hi[i] = -INFINITY;
    for (size_t q = 0; q < npix * 3; q++) {
        img->fimg[q] = (float)img->dimg[k][q];
        fo->lo[i] = fmin(fo->lo[i], img->dimg[k][q]);
        fo->hi[i] = fmax(fo->hi[i], img->dimg[k][q]);
    }
    double t_w0 = dr_clock_seconds();
    if (dr_image_write(fo->outs[i], img->w, img->h, 3, img->fimg) != 0 ||
        (fo->viss[i] && write_vis(fo->viss[i], img->fimg, img->w, img->h, &fo->vis_scale[i]) != 0))
        return -1;
    *t_write += dr_clock_seconds() - t_w0;
    return 0;
}

/* Parameters first .. first + count - 1 in one pass over the paths
 * (estimator.h's dr_estimator_forward_groups): each one's derivative image
 * along all its components, written. Per parameter, a pass differentiated
 * every parameter of the set and kept one: three colours of the peer's box
 * took 2.5 s, their passes alone 1.7. 0, or non-zero with dr_last_error set. */
static int forward_pass(struct grad_args *a, const struct dr_scene *scene, const struct dr_camera *cam,
                        const struct dr_param_set *ps, int first, int count, const struct forward_images *img,
                        const struct forward_outputs *fo, struct grad_totals *tot, double *t_write)
{
    int64_t group_end[DR_FORWARD_MAX];
    dr_forward_param_groups(ps, first, count, img->dir, group_end);
    struct dr_grad_problem prob = grad_problem(&a->g, scene, cam, ps, a->g.width, a->g.height, a->g.spp, a->g.seed);
    prob.batch = a->batch;
    prob.mis_weights = img->mis_one;   /* mis: the direction's weight (every entry the same) */
    prob.media_plan = &a->media_plan;
    struct dr_grad_stats st = {0};
    if (dr_estimator_forward_groups(a->g.estimator, &prob, img->dir, count, group_end, img->dimg, &st) != 0)
        return -1;
    grad_totals_add(tot, &st);
    for (int k = 0; k < count; k++) {
        fo->mis_w[first + k] = img->mis_one[first + k];
        if (forward_write(img, fo, first + k, k, t_write) != 0)
            return -1;
    }
    return 0;
}

static int run_forward(struct grad_args *a, const char *scene_path, const struct dr_scene *scene,
                       const struct dr_camera *cam, const struct dr_param_set *ps, double t_start, double t_loaded)
{
    const int n = ps->n;
    int w, h;   /* the rendered rectangle: the frame or --crop's */
    grad_film(&a->g, a->g.width, a->g.height, &w, &h);
    const size_t npix = (size_t)w * h;
    /* parameters a pass (dr_forward_per_pass), at most n */
    const int max_pass = dr_forward_per_pass(a->g.sampling), per_pass = n < max_pass ? n : max_pass;
    double *dir = calloc((size_t)(ps->total > 0 ? ps->total : 1), sizeof(double));
    struct forward_images img = {.w = w, .h = h, .dir = dir};
    bool images_ok = true;
    for (int k = 0; k < per_pass; k++)
        images_ok &= (img.dimg[k] = malloc(sizeof(double) * npix * 3)) != NULL;
    float *fimg = malloc(sizeof(float) * npix * 3);
    char **outs = calloc((size_t)n, sizeof(char *)), **viss = calloc((size_t)n, sizeof(char *));
    double *vis_scale = calloc((size_t)n, sizeof(double)), *lo = calloc((size_t)n, sizeof(double)),
           *hi = calloc((size_t)n, sizeof(double));
    double *mis_w = calloc((size_t)n, sizeof(double)), *mis_one = calloc((size_t)n, sizeof(double));
    img.fimg = fimg;
    img.mis_one = mis_one;
    int rc = DR_EXIT_FAILURE;
    if (!dir || !images_ok || !fimg || !outs || !viss || !vis_scale || !lo || !hi || !mis_w || !mis_one) {
        cli_error("grad", "out of memory for a %dx%d derivative image", w, h);
        goto out;
    }
    for (int i = 0; i < n; i++) {
        outs[i] = n > 1 ? indexed_name(a->output, i) : strdup(a->output);
        viss[i] = a->vis ? (n > 1 ? indexed_name(a->vis, i) : strdup(a->vis)) : NULL;
        if (!outs[i] || (a->vis && !viss[i])) {
            cli_error("grad", "out of memory");
            goto out;
        }
    }
    bool progress = isatty(2) != 0;
    struct grad_totals tot = {0};
    double t_write = 0.0;
    struct forward_outputs fo = {outs, viss, vis_scale, lo, hi, mis_w};
    for (int i = 0; i < n; i += per_pass) {
        if (progress)
            dr_progress_bar("grad", i, n);
        const int count = n - i < per_pass ? n - i : per_pass;
        if (forward_pass(a, scene, cam, ps, i, count, &img, &fo, &tot, &t_write) != 0) {
            if (progress)
                fputc('\n', stderr);
            cli_error("grad", "%s", dr_last_error());
            goto out;
        }
    }
    if (progress)
        dr_progress_bar("grad", n, n);
    grad_totals_warn("grad", &tot);
    double t_end = dr_clock_seconds();
    forward_print(stdout, a, scene_path, ps, &fo, &tot, t_loaded - t_start, t_write, t_end - t_start);
    rc = DR_EXIT_OK;
out:
    for (int i = 0; outs && viss && i < n; i++) {
        free(outs[i]);
        free(viss[i]);
    }
    free(outs);
    free(viss);
    free(vis_scale);
    free(lo);
    free(hi);
    free(mis_w);
    free(mis_one);
    free(dir);
    for (int k = 0; k < DR_FORWARD_MAX; k++)
        free(img.dimg[k]);
    free(fimg);
    dr_media_plan_free(&a->media_plan);
    return rc;
}

/* ---- reverse mode ---- */

/* One reverse-mode run (drivers/reverse.h): K batches, each with its own
 * primal image and gradient samples, reduced to a mean and standard errors. */
struct reverse_run {
    int64_t T;
    int n_params;
    double *mean, *se, *se_grad, *se_primal;
    uint64_t *nonzero;   /* the blocks of mean and se that may not be +0 (reverse.h) */
    char **files;                  /* gradient images of image parameters */
    double t_write;
    struct dr_reverse_result res;
    struct grad_totals tot;
    /* --sampling mis: every estimator run's weights (mis_last, per parameter)
     * summed into mis_sum; reported as their mean */
    double *mis_last, *mis_sum;
    int mis_runs;
};

static void reverse_free(struct reverse_run *r, int n_params)
{
    for (int k = 0; r->files && k < n_params; k++)
        free(r->files[k]);
    free(r->files);
    free(r->mean);
    free(r->se);
    free(r->nonzero);
    free(r->se_grad);
    free(r->se_primal);
    free(r->mis_last);
    free(r->mis_sum);
}

static void reverse_progress(void *ctx, int done, int total)
{
    (void)ctx;
    dr_progress_bar("grad", done, total);
}

static void reverse_on_render(void *ctx, const struct dr_render_stats *rs)
{
    grad_totals_add_render(&((struct reverse_run *)ctx)->tot, rs);
}

static void reverse_on_gradient(void *ctx, const struct dr_grad_stats *st)
{
    struct reverse_run *r = ctx;
    grad_totals_add(&r->tot, st);
    if (!r->mis_last)
        return;
    for (int64_t k = 0; k < r->n_params; k++)
        r->mis_sum[k] += r->mis_last[k];
    r->mis_runs++;
}

/* The mean weight of the detached estimate for parameter k (mis). */
static double reverse_mis_weight(const struct reverse_run *r, int k)
{
    return r->mis_runs > 0 ? r->mis_sum[k] / r->mis_runs : NAN;
}

/* The reverse run's options, without its callbacks. */
static struct dr_reverse_options reverse_options(const struct grad_args *a, const struct dr_scene *scene,
                                                 const struct dr_camera *cam, const struct dr_param_set *ps)
{
    struct dr_reverse_options o = {
        .estimator = a->g.estimator,
        .problem = grad_problem(&a->g, scene, cam, ps, a->g.width, a->g.height, a->g.spp, a->g.seed),
        .loss = a->loss, .loss_scale = 1.0, .batches = a->batches, .primal = a->primal};
    o.problem.batch = a->batch;
    return o;
}

/* The batches: gradient, total standard error and its parts. */
static int reverse_batches(const struct grad_args *a, const struct dr_scene *scene, const struct dr_camera *cam,
                           const struct dr_param_set *ps, const float *target, bool progress, struct reverse_run *r)
{
    struct dr_reverse_options o = reverse_options(a, scene, cam, ps);
    o.progress = progress ? reverse_progress : NULL;
    o.on_render = reverse_on_render;
    o.on_gradient = reverse_on_gradient;
    o.ctx = r;
    o.problem.mis_weights = r->mis_last;
    /* the parts' vectors only when the run estimates them (null in the output otherwise) */
    if (dr_reverse_parts(&o)) {
        const size_t T1 = (size_t)(r->T > 0 ? r->T : 1);
        r->se_grad = dr_alloc_big(T1 * sizeof(double));   /* (written whole by the run: run_reverse) */
        r->se_primal = dr_alloc_big(T1 * sizeof(double));
        if (!r->se_grad || !r->se_primal) {
            cli_error("grad", "out of memory (%lld gradient entries)", (long long)r->T);
            return DR_EXIT_FAILURE;
        }
    }
    r->res = (struct dr_reverse_result){.grad = r->mean, .se = r->se, .se_gradient = r->se_grad,
                                        .se_primal = r->se_primal, .nonzero = r->nonzero};
    if (dr_reverse_gradient(&o, target, &r->res) != 0) {
        if (progress)
            fputc('\n', stderr);
        cli_error("grad", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    return -1;
}

/* Texture and environment-map gradients as float images in --grad-dir. */
static int reverse_write_images(const struct grad_args *a, const struct dr_param_set *ps, struct reverse_run *r)
{
    double t0 = dr_clock_seconds();
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        if (!is_image_param(p))
            continue;
        r->files[k] = grad_image_name(a->grad_dir, p);
        /* (+0 where the mask says: not written. The writer reads it whole:
         * huge pages, dr_calloc_big, fault in a 2k texture's 50 MB a few
         * dozen times instead of 12 thousand) */
        float *gimg = dr_calloc_big((size_t)p->size, sizeof(float));
        if (!r->files[k] || !gimg) {
            free(gimg);
            cli_error("grad", "out of memory");
            return DR_EXIT_FAILURE;
        }
        const int64_t o = p->offset, e = o + p->size;
        for (int64_t i = dr_mask_next(r->nonzero, NULL, o, e); i < e;) {
            const int64_t j = dr_mask_run_end(r->nonzero, NULL, i, e);
            for (; i < j; i++)
                gimg[i - o] = (float)r->mean[i];
            i = dr_mask_next(r->nonzero, NULL, j, e);
        }
        int rc = dr_image_write(r->files[k], p->width, p->height, p->channels, gimg);
        free(gimg);
        if (rc != 0) {
            cli_error("grad", "%s", dr_last_error());
            return DR_EXIT_FAILURE;
        }
    }
    r->t_write = dr_clock_seconds() - t0;
    return -1;
}

/* Root of the sum of squares of v over an image parameter's entries, in
 * the blocks the result's mask marks (reverse.h: v is +0 elsewhere, and
 * adding +0 to a sum of squares changes nothing). A pass over all of a
 * texture's entries read the result vectors' pages nothing had written:
 * a page fault each, a tenth of `grad` on a 2k texture. */
static double image_norm(const struct dr_param *p, const double *v, const uint64_t *nonzero)
{
    double a = 0.0;
    const int64_t o = p->offset, e = o + p->size;
    for (int64_t i = dr_mask_next(nonzero, NULL, o, e); i < e;) {
        const int64_t j = dr_mask_run_end(nonzero, NULL, i, e);
        for (; i < j; i++)
            a += v[i] * v[i];
        i = dr_mask_next(nonzero, NULL, j, e);
    }
    return sqrt(a);
}

/* v NULL: n nulls (standard-error parts the run did not estimate) */
static void json_array(FILE *f, const double *v, int64_t n)
{
    fputc('[', f);
    for (int64_t i = 0; i < n; i++) {
        if (i)
            fputs(", ", f);
        json_number(f, v ? v[i] : NAN);
    }
    fputc(']', f);
}

/* One parameter's gradient and standard errors (total, gradient-sample and
 * primal-image parts; null parts when a batch has a single sample). */
static void reverse_json_param(FILE *f, const struct grad_args *a, const struct dr_param_set *ps, int k,
                               const struct reverse_run *r)
{
    const struct dr_param *p = &ps->params[k];
    const char *file = r->files[k];
    fprintf(f, "{\"name\": ");
    json_string(f, p->name);
    fprintf(f, ", \"size\": %lld", (long long)p->size);
    const char *keys[] = {"stderr", "stderr_gradient", "stderr_primal"};
    const double *vals[] = {r->se, r->se_grad, r->se_primal};
    if (is_image_param(p)) {
        fprintf(f, ", \"width\": %d, \"height\": %d, \"channels\": %d, \"norm\": ", p->width, p->height,
                p->channels);
        json_number(f, image_norm(p, r->mean, r->nonzero));
        for (int k = 0; k < 3; k++) {
            fprintf(f, ", \"%s_norm\": ", keys[k]);
            json_number(f, vals[k] ? image_norm(p, vals[k], r->nonzero) : NAN);
        }
        fprintf(f, ", \"file\": ");
        json_string(f, file);
    } else {
        fprintf(f, ", \"gradient\": ");
        json_array(f, r->mean + p->offset, p->size);
        for (int k = 0; k < 3; k++) {
            fprintf(f, ", \"%s\": ", keys[k]);
            json_array(f, vals[k] ? vals[k] + p->offset : NULL, p->size);
        }
    }
    grad_json_mis_weight(f, &a->g, reverse_mis_weight(r, k));
    fputc('}', f);
}

static void reverse_print_json(FILE *f, const struct grad_args *a, const char *scene_path,
                               const struct dr_param_set *ps, const struct reverse_run *r, double t_load, double t_end)
{
    json_open(f, a, scene_path, "reverse", &r->tot);
    fprintf(f, ", \"target\": ");
    json_string(f, a->target);
    fprintf(f, ", \"loss\": ");
    json_number(f, r->res.loss);
    fprintf(f, ", \"loss_kind\": ");
    json_string(f, dr_loss_name(a->loss));
    fprintf(f, ", \"batches\": %d, \"spp_per_batch\": %d, \"primal\": \"%s\", \"primal_seed\": %llu", a->batches,
            r->res.spp_batch, grad_primal_name(r->res.primal_run), (unsigned long long)r->res.primal_seed);
    fprintf(f, ", \"time\": {\"load\": ");
    json_number(f, t_load);
    fprintf(f, ", \"primal\": ");
    json_number(f, r->res.t_primal);
    fprintf(f, ", \"gradient\": ");
    json_number(f, r->res.t_gradient);
    fprintf(f, ", \"write\": ");
    json_number(f, r->t_write);
    fprintf(f, ", \"total\": ");
    json_number(f, t_end);
    fprintf(f, "}, \"parameters\": [");
    for (int k = 0; k < ps->n; k++) {
        fputs(k ? ", " : "", f);
        reverse_json_param(f, a, ps, k, r);
    }
    fprintf(f, "], \"effects_differentiated\": ");
    grad_json_effects(f, ps);
    fprintf(f, "}\n");
}

static void reverse_print_text(FILE *f, const struct grad_args *a, const struct dr_param_set *ps,
                               const struct reverse_run *r)
{
    fprintf(f, "loss (%s): %.9g\n", dr_loss_name(a->loss), r->res.loss);
    fprintf(f, "d loss / d parameter (mean of %d batches of %d spp, +- standard error incl. primal noise; %s, %s, "
               "%s numbers, %s primal):\n",
            a->batches, r->res.spp_batch, a->g.estimator->name, dr_sampling_name(a->g.sampling),
            dr_sampler_kind_name(a->g.sampler), grad_primal_name(r->res.primal_run));
    for (int k = 0; k < ps->n; k++) {
        const struct dr_param *p = &ps->params[k];
        if (is_image_param(p)) {
            fprintf(f, "%s (%dx%dx%d image): gradient norm %.6g (standard errors' norm %.3g) -> %s\n", p->name,
                    p->width, p->height, p->channels, image_norm(p, r->mean, r->nonzero), image_norm(p, r->se, r->nonzero),
                    r->files[k]);
        } else if (p->size == 1) {
            fprintf(f, "%s: %.6g +- %.2g\n", p->name, r->mean[p->offset], r->se[p->offset]);
        } else {
            fprintf(f, "%s:", p->name);
            for (int64_t i = 0; i < p->size; i++)
                fprintf(f, "%s%.6g +- %.2g", i ? ", " : " ", r->mean[p->offset + i], r->se[p->offset + i]);
            fputc('\n', f);
        }
    }
    for (int k = 0; a->g.sampling == DR_SAMPLING_MIS && k < ps->n; k++)
        fprintf(f, "%s: mis weight %.3f detached, %.3f attached (mean over runs)\n", ps->params[k].name,
                reverse_mis_weight(r, k), 1.0 - reverse_mis_weight(r, k));
}

static int run_reverse(struct grad_args *a, const char *scene_path, const struct dr_scene *scene,
                       const struct dr_camera *cam, const struct dr_param_set *ps, const float *target,
                       double t_start, double t_loaded)
{
    struct reverse_run r = {.T = ps->total, .n_params = ps->n};
    const size_t T1 = (size_t)(r.T > 0 ? r.T : 1);
    /* (zeros by calloc: fresh pages, resident only where written; the
     * mask clear says so, and the run writes the blocks its gradient
     * reaches, reverse.h: a preview's texture gradient is a few per cent
     * of the texture. A zeroing pass here had faulted a texture's pages in
     * on one thread; writing them whole, on the workers, still all of them) */
    r.mean = calloc(T1, sizeof(double));
    r.se = calloc(T1, sizeof(double));
    r.nonzero = calloc((size_t)dr_mask_words((int64_t)T1), sizeof(uint64_t));
    r.files = calloc((size_t)ps->n, sizeof(char *));
    bool mis_ok = true;
    if (a->g.sampling == DR_SAMPLING_MIS) {
        r.mis_last = calloc((size_t)ps->n, sizeof(double));
        r.mis_sum = calloc((size_t)ps->n, sizeof(double));
        mis_ok = r.mis_last && r.mis_sum;
    }
    int rc = DR_EXIT_FAILURE;
    bool progress = isatty(2) != 0;
    if (!r.mean || !r.se || !r.nonzero || !r.files || !mis_ok)
        cli_error("grad", "out of memory (%lld gradient entries)", (long long)r.T);
    else if ((rc = reverse_batches(a, scene, cam, ps, target, progress, &r)) < 0 &&
             (rc = reverse_write_images(a, ps, &r)) < 0) {
        grad_totals_warn("grad", &r.tot);
        if (a->g.json)
            reverse_print_json(stdout, a, scene_path, ps, &r, t_loaded - t_start, dr_clock_seconds() - t_start);
        else
            reverse_print_text(stdout, a, ps, &r);
        rc = DR_EXIT_OK;
    }
    reverse_free(&r, ps->n);
    return rc;
}

int cmd_grad(int argc, char **argv)
{
    double t_start = dr_clock_seconds();
    struct grad_args a;
    memset(&a, 0, sizeof a);
    grad_common_init(&a.g, "grad", 16);
    a.loss = DR_LOSS_L2;
    a.batches = 4;
    a.primal = DR_PRIMAL_CROSS;
    a.grad_dir = ".";
    char *scene_path = NULL;
    struct dr_scene *scene = NULL;
    struct dr_param_set *ps = NULL;
    struct dr_image timg;
    memset(&timg, 0, sizeof timg);
    float *target = NULL;
    char target_what[4200];
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0)
        goto out;
    /* Everything the user can get wrong in the options is checked before any work. */
    if ((rc = check_args(&a)) >= 0)
        goto out;
    grad_default_sampler(&a.g, a.target != NULL, a.primal, a.batches);
    if (a.target) {
        if ((rc = grad_load_target("grad", a.target, &timg, &target)) >= 0)
            goto out;
        if ((rc = crop_target_size(&a, &timg)) >= 0)
            goto out;
        if (a.g.res_given && (a.g.width != timg.width || a.g.height != timg.height) && !a.g.crop_given) {
            cli_error("grad", "--target %s is %dx%d but --res asks for %dx%d (the render and the target must be "
                              "the same size)", a.target, timg.width, timg.height, a.g.width, a.g.height);
            rc = DR_EXIT_USAGE;
            goto out;
        }
    }
    snprintf(target_what, sizeof target_what, "--target %s", a.target ? a.target : "");
    struct dr_camera cam;
    if ((rc = grad_load_scene(&a.g, &scene_path, &scene, &cam, a.target ? timg.width : 0,
                              a.target ? timg.height : 0)) >= 0)
        goto out;
    if ((rc = grad_check_crop(&a.g, a.g.width, a.g.height)) >= 0)
        goto out;
    if (a.target && (rc = grad_crop_image(&a.g, target_what, &target, timg.width, timg.height, a.g.width,
                                          a.g.height)) >= 0)
        goto out;
    if ((rc = grad_apply_sets(&a.g, scene)) >= 0 || (rc = grad_param_set(&a.g, scene, &ps)) >= 0)
        goto out;
    grad_resolve_sampling(&a.g, scene, ps);
    const struct dr_reverse_options planned = reverse_options(&a, scene, &cam, ps);
    if ((rc = cli_limits_grad(&a.g, scene, ps, a.target != NULL, a.batches, a.batches_given, a.batch,
                              a.target && dr_reverse_parts(&planned))) >= 0)
        goto out;
    double t_loaded = dr_clock_seconds();
    if (a.target)
        rc = run_reverse(&a, scene_path, scene, &cam, ps, target, t_start, t_loaded);
    else
        rc = run_forward(&a, scene_path, scene, &cam, ps, t_start, t_loaded);
out:
    free(target);
    dr_image_release(&timg);
    dr_param_set_destroy(ps);
    dr_scene_destroy(scene);
    free(scene_path);
    grad_common_free(&a.g);
    return rc;
}
