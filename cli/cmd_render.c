/* drender render: forward path tracing of a glTF scene to an image. */
#include <getopt.h>
#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "backface.h"
#include "camera.h"
#include "grad_common.h"
#include "cli.h"
#include "error.h"
#include "image_io.h"
#include "mem_limits.h"
#include "parallel.h"
#include "render.h"
#include "scene.h"

#define DEFAULT_SCENE "cornell-box.gltf"

void cmd_render_usage(FILE *out)
{
    fprintf(out,
            "usage: drender render [SCENE] [options]\n"
            "\n"
            "Renders SCENE (.gltf or .glb; default: the bundled Cornell box) with a\n"
            "unidirectional path tracer and writes the image. The format follows the\n"
            "output's extension: .exr/.hdr/.tif stay linear float, .png/.jpg are\n"
            "sRGB-encoded 8-bit.\n"
            "\n"
            "options:\n"
            "  -o, --output FILE   image to write (default: render.png)\n"
            "      --spp N         samples per pixel (default: 64)\n"
            "      --max-depth D   path segments: 1 = emitters seen directly, 2 = direct\n"
            "                      lighting, 8 = camera ray + 7 bounces (default: 8)\n"
            "      --rr-depth D    Russian roulette from this many segments on (default: 5)\n"
            "      --res WxH       image size (default: 512 high, width from the camera's\n"
            "                      aspect ratio, else 512x512)\n"
            "      --camera N      which camera of the file (default: 0; a file without\n"
            "                      cameras gets one that frames the scene)\n"
            "      --seed S        random seed (default: 0); the same seed gives the same\n"
            "                      image for any --threads\n"
            "      --threads T     worker threads (default: one per CPU)\n"
            "      --sampler S     random numbers: sobol (default: Owen-scrambled Sobol),\n"
            "                      stratified (jittered strata over the pixel's spp) or\n"
            "                      independent (each number hashed on its own: up to 6x\n"
            "                      the variance; the default of render before 2026-12)\n"
            "      --filter F      pixel filter: box (default: the pixel's square), tent\n"
            "                      (radius 1 pixel) or gaussian[:STDDEV] (default 0.5 pixel),\n"
            "                      by filter importance sampling\n"
            "      --crop X,Y,W,H  render only this rectangle of the --res frame (top-left\n"
            "                      pixel X,Y; W x H pixels): the same pixels, bit for bit,\n"
            "                      as the full render's; the image written is W x H\n"
            GRAD_IGNORE_UNSUPPORTED_HELP
            "      --json          print a summary object on stdout (timings, time by\n"
            "                      stage, rays, peak memory, memory estimate, effects\n"
            "                      simulated)\n"
            "  -h, --help          show this help\n");
    grad_lighting_usage(out);
}

struct render_args {
    struct grad_common g;   /* the shared rendering options */
    const char *output;
};

/* The options only `render` takes (grad_own_option_fn). */
static int own_option(void *ctx, int c, const char *arg)
{
    struct render_args *a = ctx;
    if (c != 'o')
        return -1;
    a->output = arg;
    return 0;
}

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, struct render_args *a)
{
    static const struct option opts[] = {
        {"output", required_argument, NULL, 'o'}, RENDER_COMMON_LONG_OPTIONS, {NULL, 0, NULL, 0},
    };
    return grad_parse_args(&a->g, argc, argv, opts, "o", own_option, a, cmd_render_usage);
}

static void print_json(const struct render_args *a, const char *scene_path, const struct dr_scene *scene,
                       const char *camera_name, const struct dr_render_stats *st, double t_startup, double t_load,
                       double t_write, double t_total)
{
    uint64_t total = st->rays.camera + st->rays.extension + st->rays.shadow;
    char fx[256];
    dr_effects_describe(scene->effects, fx, sizeof fx);
    FILE *f = stdout;
    fprintf(f, "{\"command\": \"render\", \"scene\": ");
    json_string(f, scene_path);
    cli_json_memory_estimate(f);
    fprintf(f, ", \"output\": ");
    json_string(f, a->output);
    const struct grad_common *g = &a->g;
    fprintf(f, ", \"width\": %d, \"height\": %d, \"spp\": %d, \"max_depth\": %d, \"rr_depth\": %d, \"seed\": %llu, "
               "\"threads\": %d",
            g->width, g->height, g->spp, g->max_depth, g->rr_depth, (unsigned long long)g->seed, st->threads);
    fputs(", ", f);
    grad_json_film(f, g);
    fprintf(f, ", \"camera\": ");
    json_string(f, camera_name);
    fprintf(f, ", \"triangles\": %u", scene->mesh.n_triangles);
    /* single-sided triangles whose backs no ray can reach: no culling test (backface.h) */
    fprintf(f, ", \"backs_unreachable\": %lld", (long long)dr_backface_count(scene->backface));
    fprintf(f, ", \"time\": {\"startup\": ");
    json_number(f, t_startup);
    fprintf(f, ", \"load\": ");
    json_number(f, t_load);
    fprintf(f, ", \"render\": ");
    json_number(f, st->seconds);
    fprintf(f, ", \"write\": ");
    json_number(f, t_write);
    fprintf(f, ", \"total\": ");
    json_number(f, t_total);
    fprintf(f, "}, \"rays\": {\"camera\": %llu, \"extension\": %llu, \"shadow\": %llu, \"total\": %llu, \"per_second\": ",
            (unsigned long long)st->rays.camera, (unsigned long long)st->rays.extension,
            (unsigned long long)st->rays.shadow, (unsigned long long)total);
    json_number(f, st->seconds > 0 ? total / st->seconds : 0.0);
    /* path vertices shaded eight lanes at a time (path_simd.h), of all hits */
    fprintf(f, "}, \"vertices_shaded_8_wide\": %llu", (unsigned long long)st->rays.simd_vertices);
    json_stage_seconds(f, &st->rays.cpu);
    fprintf(f, ", \"invalid_samples\": %llu, \"peak_memory_bytes\": %llu, \"effects\": ",
            (unsigned long long)st->invalid_samples, (unsigned long long)cli_peak_rss_bytes());
    json_name_list(f, fx);
    char stages[256];
    dr_path_stages_describe(st->stages, stages, sizeof stages);
    fprintf(f, ", \"stages\": ");
    json_name_list(f, stages);
    fprintf(f, "}\n");
}

/* The parallel runs' started hook: the image library's load (0.2 s of one
 * CPU) goes on a thread of its own when the process may use more CPUs than
 * the render's workers, so the write no longer waits for it. With every CPU
 * rendering it would only slow the render by as much (and inflate
 * time.render), so then the write loads it as before. */
static void preload_beside(int workers)
{
    cpu_set_t set;
    int cpus = sched_getaffinity(0, sizeof set, &set) == 0 ? CPU_COUNT(&set) : 1;
    if (workers < cpus)
        dr_image_library_preload();
}

/* Can the image library write -o's format? -1 if so, else the exit code
 * (with the message): no library, or a format it cannot write. */
static int check_output_format(const char *output)
{
    if (dr_image_can_write(output))
        return -1;
    if (!dr_image_library_ok()) {
        cli_error("render", "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    cli_error("render", "-o %s: OpenImageIO cannot write this format (use e.g. .exr, .hdr, .png, .jpg)", output);
    return DR_EXIT_USAGE;
}

int cmd_render(int argc, char **argv)
{
    double t_start = dr_clock_seconds();
    struct render_args a = {.output = "render.png"};
    grad_common_init(&a.g, "render", 64);
    /* An image's default: Owen-scrambled Sobol numbers. On the sample scenes
     * they had 1.5-6 x less variance than independent ones for 0.97-1.09 x
     * the time (media: the same variance). grad and optimize default to them
     * too where their cross primal runs (grad_default_sampler). */
    a.g.sampler = DR_SAMPLER_SOBOL;
    char *scene_path = NULL;
    struct dr_scene *scene = NULL;
    float *rgb = NULL;
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0)
        goto out;
    /* Everything the user can get wrong is checked before rendering. For the
     * common formats the output check needs no image library, so an
     * untextured scene reaches its first ray without loading it
     * (core/image_plugin.h). */
    if (!cli_output_dir_writable("render", a.output)) {
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    struct dr_camera cam;
    if ((rc = grad_load_scene(&a.g, &scene_path, &scene, &cam, 0, 0)) >= 0)
        goto out;
    if ((rc = check_output_format(a.output)) >= 0)
        goto out;
    /* The write needs the image library: have it loaded while the render's
     * workers run, if a CPU is left for it (image_plugin.h) */
    dr_parallel_set_started_hook(preload_beside);
    double t_loaded = dr_clock_seconds();
    if ((rc = grad_check_crop(&a.g, a.g.width, a.g.height)) >= 0)
        goto out;
    /* the rendered rectangle: the frame, or --crop's part of it */
    struct dr_render_opts ro = grad_render_opts(&a.g, a.g.width, a.g.height, a.g.spp, a.g.seed, isatty(2) != 0);
    const int w = ro.width, h = ro.height;
    if ((rc = cli_limits_render(scene, w, h, a.g.spp, a.g.threads)) >= 0)
        goto out;
    rgb = malloc(sizeof(float) * 3 * (size_t)w * (size_t)h);
    if (!rgb) {
        cli_error("render", "out of memory for a %dx%d image", w, h);
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    struct dr_render_stats st;
    const double t_startup = cli_seconds_since_start();   /* to the first ray */
    if (dr_render(scene, &cam, &ro, rgb, &st) != 0) {
        cli_error("render", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    if (st.invalid_samples > 0)
        cli_error("render", "warning: %llu samples were not finite and were dropped",
                  (unsigned long long)st.invalid_samples);
    double t_w0 = dr_clock_seconds();
    if (dr_image_write(a.output, w, h, 3, rgb) != 0) {
        cli_error("render", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    double t_end = dr_clock_seconds();
    if (a.g.json)
        print_json(&a, scene_path, scene, cam.name, &st, t_startup, t_loaded - t_start, t_end - t_w0, t_end - t_start);
    rc = DR_EXIT_OK;
out:
    free(rgb);
    dr_scene_destroy(scene);
    free(scene_path);
    grad_common_free(&a.g);
    return rc;
}
