/* Memory estimates and limits of the commands (see mem_limits.h). */
#include "mem_limits.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cli.h"
#include "exact_sum.h"
#include "grad_common.h"
#include "render.h"
#include "mis.h"
#include "image_io.h"
#include "medium.h"
#include "parallel.h"
#include "params.h"
#include "scene.h"

bool cli_parse_bytes(const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    if (!text || !isdigit((unsigned char)text[0]))
        return false;
    double v = strtod(text, &end);
    if (errno || end == text || !isfinite(v))
        return false;
    double unit = 1.0;
    switch (toupper((unsigned char)*end)) {
    case '\0': break;
    case 'K': unit = 1024.0; break;
    case 'M': unit = 1024.0 * 1024.0; break;
    case 'G': unit = 1024.0 * 1024.0 * 1024.0; break;
    case 'T': unit = 1024.0 * 1024.0 * 1024.0 * 1024.0; break;
    default: return false;
    }
    if (*end && end[1] && !((end[1] == 'B' || end[1] == 'b') && end[2] == '\0'))
        return false;
    v *= unit;
    if (!(v >= 1.0) || v >= 18446744073709551615.0)
        return false;
    *out = (uint64_t)v;
    return true;
}

/* A "key: N kB" line of /proc/meminfo, in bytes; 0 when absent. */
static uint64_t meminfo(const char *key)
{
    FILE *f = fopen("/proc/meminfo", "r");
    if (!f)
        return 0;
    char line[256];
    uint64_t v = 0;
    size_t n = strlen(key);
    while (fgets(line, sizeof line, f))
        if (strncmp(line, key, n) == 0 && line[n] == ':') {
            unsigned long long kb;
            if (sscanf(line + n + 1, "%llu", &kb) == 1)
                v = (uint64_t)kb * 1024u;
            break;
        }
    fclose(f);
    return v;
}

/* memory.max of this process's cgroup (v2), 0 when unlimited or unknown. */
static uint64_t cgroup_limit(void)
{
    FILE *f = fopen("/proc/self/cgroup", "r");
    if (!f)
        return 0;
    char line[4096], path[4200];
    uint64_t v = 0;
    while (fgets(line, sizeof line, f))
        if (strncmp(line, "0::", 3) == 0) {
            line[strcspn(line, "\n")] = '\0';
            snprintf(path, sizeof path, "/sys/fs/cgroup%s/memory.max", line + 3);
            FILE *m = fopen(path, "r");
            if (m) {
                unsigned long long b;
                if (fscanf(m, "%llu", &b) == 1)
                    v = b;
                fclose(m);
            }
            break;
        }
    fclose(f);
    return v;
}

uint64_t cli_mem_limit(void)
{
    uint64_t v;
    const char *env = getenv("DRENDER_MEM_LIMIT");
    if (env && *env && cli_parse_bytes(env, &v))
        return v;
    uint64_t total = meminfo("MemTotal");
    if (total == 0) {
        long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
        total = pages > 0 && page > 0 ? (uint64_t)pages * (uint64_t)page : UINT64_MAX;
    }
    uint64_t cg = cgroup_limit();
    return cg > 0 && cg < total ? cg : total;
}

void cli_limits_init(void)
{
    const char *env = getenv("DRENDER_MEM_LIMIT");
    uint64_t v;
    if (env && *env && !cli_parse_bytes(env, &v))
        cli_error(NULL, "warning: DRENDER_MEM_LIMIT='%s' is not a size (e.g. 512M, 8G); ignored", env);
    dr_image_set_max_bytes(cli_mem_limit());
}

/* ---- estimates, in double: absurd requests overflow 64 bits ---- */

static double image_bytes(const struct dr_image *im)
{
    return (double)dr_image_pixel_bytes(im);
}

uint64_t cli_mem_scene(const struct dr_scene *s)
{
    if (!s)
        return 0;
    double b = 0.0;
    b += (double)s->mesh.n_vertices * (4 + 3 + 2) * sizeof(float);
    /* indices, material, flags, normal + offset, and about 64 bytes of BVH per triangle */
    b += (double)s->mesh.n_triangles * (3 * sizeof(uint32_t) + sizeof(int32_t) + 1 + 4 * sizeof(double) + 64);
    for (int i = 0; i < s->n_images; i++)
        b += image_bytes(&s->images[i]);
    b += image_bytes(&s->env.map);
    b += (double)s->n_materials * sizeof(struct dr_material) + (double)s->n_textures * sizeof(struct dr_texture);
    for (int i = 0; i < s->n_media; i++)   /* density voxels (and their majorants, at most as many) */
        b += 2.0 * (double)s->media[i].grid.nx * s->media[i].grid.ny * s->media[i].grid.nz * sizeof(float);
    return b >= 1.8e19 ? UINT64_MAX : (uint64_t)b;
}

static int thread_count(int threads)
{
    int t = threads > 0 ? threads : dr_default_threads();
    return t < 1 ? 1 : (t > 64 ? 64 : t);
}

/* What a request needs, by cause: the largest names the option to blame. */
struct need {
    double images;     /* image buffers: --res (or the targets' size) */
    double grads;      /* gradient vectors and per-thread copies: --param (textures), --threads */
    double tape;       /* tape estimator: --max-depth x paths per batch */
    double batches;    /* per-batch gradient storage: --batches x --param */
    double mis;        /* --sampling mis: its group copies of the estimate, per thread */
    double work;       /* the estimator's workers' own storage (paths in flight): --threads */
    double scene;      /* already loaded */
};

static void fmt_bytes(double b, char *buf, size_t size)
{
    static const char *const units[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    int u = 0;
    while (b >= 1024.0 && u < 6) {
        b /= 1024.0;
        u++;
    }
    if (u == 0)
        snprintf(buf, size, "%.0f bytes", b);
    else
        snprintf(buf, size, "%.1f %s", b, units[u]);
}

static uint64_t last_estimate;

uint64_t cli_mem_estimate(void) { return last_estimate; }

void cli_json_memory_estimate(FILE *f)
{
    fprintf(f, ", \"memory_estimate_bytes\": %llu", (unsigned long long)last_estimate);
}

static int check(const char *cmd, const struct need *n, const char *images_opt, const char *tape_opt)
{
    double total = n->images + n->grads + n->tape + n->batches + n->mis + n->work + n->scene;
    last_estimate = total >= 1.8e19 ? UINT64_MAX : (uint64_t)total;
    uint64_t limit = cli_mem_limit();
    if (total <= (double)limit)
        return -1;
    /* the biggest part is what to change */
    const char *what = images_opt;
    double part = n->images;
    if (n->grads > part) {
        part = n->grads;
        what = "--param (texture gradients need one vector per thread; fewer --threads or smaller textures)";
    }
    if (n->tape > part) {
        part = n->tape;
        what = tape_opt;
    }
    if (n->batches > part) {
        part = n->batches;
        what = "--batches (every batch keeps its gradient of every --param scalar)";
    }
    if (n->mis > part) {
        part = n->mis;
        what = "--sampling mis (16 copies of the estimate per thread: fewer --threads, a smaller --res, or "
               "--sampling detached)";
    }
    if (n->work > part) {
        part = n->work;
        what = "--threads (every worker holds its own paths in flight)";
    }
    if (n->scene > part) {
        part = n->scene;
        what = "the scene itself (its textures and mesh)";
    }
    char need_s[32], limit_s[32], part_s[32];
    fmt_bytes(total, need_s, sizeof need_s);
    fmt_bytes((double)limit, limit_s, sizeof limit_s);
    fmt_bytes(part, part_s, sizeof part_s);
    cli_error(cmd, "this request needs about %s of memory (%s for %s), more than the %s drender may use (%s)",
              need_s, part_s, what, limit_s, getenv("DRENDER_MEM_LIMIT") ? "DRENDER_MEM_LIMIT" : "the machine's memory");
    return DR_EXIT_USAGE;
}

int cli_limits_render(const struct dr_scene *scene, int width, int height, int spp, int threads)
{
    const double npix = (double)width * height;
    struct need n = {0};
    n.images = 2.0 * npix * 3 * sizeof(float);   /* the image, and its encoded copy while writing */
    /* per thread: the wavefront's lanes and a run of pixels' path values (render.h) */
    n.images += (double)dr_thread_count(threads) * (double)dr_render_thread_bytes(spp);
    n.scene = (double)cli_mem_scene(scene);
    return check("render", &n, "--res", "--max-depth");
}

/* The workers' own storage: threads x the estimator's bound (prb by default). */
static double work_bytes(const struct dr_estimator_ops *e, int spp, int threads)
{
    if (!e)
        e = dr_estimator_find("prb");
    return e && e->thread_bytes ? (double)e->thread_bytes(spp > 1 ? spp : 1) * threads : 0.0;
}

/* Tape: every vertex of every path of a batch, at most max_depth per path. */
static double tape_bytes(const struct grad_common *g, double paths_per_batch)
{
    if (!g->estimator || strcmp(g->estimator->name, "tape") != 0)
        return 0.0;
    const bool derivative = dr_sampling_is_derivative(g->sampling) || g->sampling_may_switch;
    return paths_per_batch * ((double)g->max_depth * (double)dr_tape_vertex_bytes(derivative) + 64.0);
}

/* --sampling mis (estimators/mis.h): per thread, 2 x DR_MIS_GROUPS copies of
 * the estimate (T gradient entries, or the 3 npix derivative image in
 * forward mode), plus per-pixel sums where per-sample statistics are kept. */
static double mis_bytes(const struct grad_common *g, double T, double npix, int threads, bool forward)
{
    if (g->sampling != DR_SAMPLING_MIS)
        return 0.0;
    double n = forward ? 3.0 * npix : T, per_thread = n * 2 * DR_MIS_GROUPS + npix;
    if (!forward && T <= DR_MIS_SAMPLE_STATS_MAX && npix * 2 * T <= (double)DR_MIS_PIXEL_SUMS_MAX)
        per_thread += npix * 2 * T + 2 * T;
    return per_thread * sizeof(double) * threads;
}

/* A reverse-mode estimator run's own gradient sums beside the caller's
 * vector: one per thread but the first, or the shared exact sums
 * (estimator.h). */
static double est_sums_bytes(double T, int threads)
{
    if (dr_estimator_shared_sums(threads, (int64_t)T))
        return (double)dr_exact_sum_bytes((int64_t)T);
    return T * sizeof(double) * (threads - 1);
}

int cli_limits_grad(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                    bool reverse, int batches, bool batches_given, int64_t batch, bool parts)
{
    if (reverse && batches_given && batches > g->spp) {
        cli_error("grad", "--batches %d exceeds --spp %d: every batch needs at least one sample per pixel", batches,
                  g->spp);
        return DR_EXIT_USAGE;
    }
    const double npix = (double)g->width * g->height, T = ps ? (double)ps->total : 0.0;
    const int threads = thread_count(g->threads);
    struct need n = {0};
    n.scene = (double)cli_mem_scene(scene);
    if (reverse) {
        /* primal image, adjoint, target (read + rgb), texture gradient images */
        n.images = npix * 3 * (3 * sizeof(float)) + npix * 4 * sizeof(float);
        /* mean, standard error, a batch's gradient (the estimator's thread 0
         * sums into it, the others into their own: drivers/reverse.c,
         * estimators/common.c), a float copy for gradient images; with the
         * standard error's parts a batch's second half and the two parts */
        n.grads = T * (3 * sizeof(double) + sizeof(float)) + est_sums_bytes(T, threads) +
                  (parts ? T * 3 * sizeof(double) : 0.0);
        n.mis = mis_bytes(g, T, npix, threads, false);
        double spp_b = ceil((double)g->spp / (batches > 0 ? batches : 1));
        double paths = npix * spp_b;
        n.tape = tape_bytes(g, fmin(dr_tape_batch_paths(batch, threads, (int)spp_b), paths));
        n.work = work_bytes(g->estimator, (int)spp_b, threads);
    } else {
        /* d image in double (every thread writes it: estimators/common.c), plus its float copy */
        n.images = npix * 3 * (sizeof(double) + sizeof(float));
        n.mis = mis_bytes(g, T, npix, threads, true);
        n.grads = T * sizeof(double);
        double paths = npix * g->spp;
        n.tape = tape_bytes(g, fmin(dr_tape_batch_paths(batch, threads, g->spp), paths));
        n.work = work_bytes(g->estimator, g->spp, threads);
    }
    return check("grad", &n, "--res", "--max-depth x --batch (tape records every vertex of a batch: lower them, or --estimator prb)");
}

int cli_limits_fdcheck(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                       int batches)
{
    const double npix = (double)g->width * g->height, T = ps ? (double)ps->total : 0.0;
    const int threads = thread_count(g->threads);
    struct need n = {0};
    n.scene = (double)cli_mem_scene(scene);
    /* d image (double; the forward runs' threads all write it), adjoint and renders (float) */
    n.images = npix * 3 * (sizeof(double) + 3 * sizeof(float));
    /* direction, theta, its copy and range; one estimator run at a time:
     * forward mode writes the d image alone, reverse mode's thread 0 sums
     * into the batch's gradient (n.batches) and the others beside it */
    n.grads = T * 5 * sizeof(double) + est_sums_bytes(T, threads);
    n.mis = fmax(mis_bytes(g, T, npix, threads, true), mis_bytes(g, T, npix, threads, false));
    n.batches = (double)batches * T * sizeof(double);
    n.tape = tape_bytes(g, fmin(dr_tape_batch_paths(0, threads, g->spp), npix * g->spp));
    n.work = work_bytes(g->estimator, g->spp, threads);
    return check("fdcheck", &n, "--res", "--max-depth (tape records every vertex of a batch; or --estimator prb)");
}

int cli_limits_optimize(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                        uint64_t target_pixels, uint64_t max_pixels, int n_targets)
{
    const double T = ps ? (double)ps->total : 0.0;
    const int threads = thread_count(g->threads);
    struct need n = {0};
    n.scene = 2.0 * (double)cli_mem_scene(scene);   /* with --reference, a second scene */
    /* per target: the file (up to 4 channels), rgb, render, adjoint; one view render */
    n.images = (double)target_pixels * (4 + 9) * sizeof(float) + (double)max_pixels * 3 * sizeof(float);
    /* theta, grad, its standard error, reference, Adam's m and v (its
     * learning rates and ranges are per parameter); with several targets one
     * target's gradient and error; a batch's gradient or two halves
     * (drivers/reverse.c); the estimator's threads but the first */
    n.grads = T * (6 + (n_targets > 1 ? 2 : 0) + 2) * sizeof(double) + est_sums_bytes(T, threads);
    n.mis = mis_bytes(g, T, (double)max_pixels, threads, false);
    n.tape = tape_bytes(g, fmin(dr_tape_batch_paths(0, threads, g->spp), (double)max_pixels * g->spp));
    n.work = work_bytes(g->estimator, g->spp, threads);
    return check("optimize", &n, "--target (the images' size)",
                 "--max-depth (tape records every vertex of a batch; or --estimator prb)");
}

/* ---- compare (cmd_compare.c) ---- */

int cli_limits_compare(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                       bool reverse, bool tape, bool mis)
{
    const double npix = (double)g->width * g->height, T = ps ? (double)ps->total : 0.0;
    const double P = ps ? (double)ps->n : 0.0;
    const int threads = thread_count(g->threads);
    struct grad_common gt = *g;
    gt.estimator = tape ? dr_estimator_find("tape") : NULL;
    struct need n = {0};
    n.scene = (double)cli_mem_scene(scene);
    /* the estimated vector: d loss / d theta (T) or one d image per --param;
     * the reference's mean and error, one estimate, running mean and m2 */
    const double V = reverse ? T : P * npix * 3;
    n.batches = V * 5 * sizeof(double);
    /* target, primal and adjoint; the d image in double (forward mode's
     * threads all write the one image: estimators/common.c) and a second
     * double image of margin */
    n.images = npix * 3 * (3 * sizeof(float) + sizeof(double) * 2);
    /* the direction and two vectors of margin; a reverse run's sums beside
     * the estimate's vector (thread 0 sums into it) */
    n.grads = T * 3 * sizeof(double) + est_sums_bytes(T, threads);
    if (mis) {   /* one estimator run at a time: a mis one holds its group copies */
        gt.sampling = DR_SAMPLING_MIS;
        n.mis = mis_bytes(&gt, T, npix, threads, !reverse);
    }
    n.tape = tape_bytes(&gt, npix);
    for (int e = 0; dr_estimators[e]; e++)   /* one estimator run at a time */
        n.work = fmax(n.work, work_bytes(dr_estimators[e], g->spp, threads));
    return check("compare", &n, "--res", "--max-depth (tape records every vertex of a batch: lower it, or "
                                         "--estimators prb)");
}
