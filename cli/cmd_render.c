/* drender render: forward path tracing of a glTF scene to an image. */
#include <getopt.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "camera.h"
#include "cli.h"
#include "error.h"
#include "image_io.h"
#include "mem_limits.h"
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
            "      --res WxH       image size (default: 512 high, width from the camera's\n"
            "                      aspect ratio, else 512x512)\n"
            "      --camera N      which camera of the file (default: 0; a file without\n"
            "                      cameras gets one that frames the scene)\n"
            "      --seed S        random seed (default: 0); the same seed gives the same\n"
            "                      image for any --threads\n"
            "      --threads T     worker threads (default: one per CPU)\n"
            "      --json          print a summary object on stdout (timings, rays,\n"
            "                      peak memory, memory estimate, effects simulated)\n"
            "  -h, --help          show this help\n");
}

enum { OPT_SPP = 256, OPT_DEPTH, OPT_RES, OPT_CAMERA, OPT_SEED, OPT_THREADS, OPT_JSON };

struct render_args {
    const char *scene_arg;
    const char *output;
    int spp, max_depth, width, height, camera, threads;
    bool res_given, camera_given, json;
    uint64_t seed;
};

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, struct render_args *a)
{
    static const struct option opts[] = {
        {"output", required_argument, NULL, 'o'},   {"spp", required_argument, NULL, OPT_SPP},
        {"max-depth", required_argument, NULL, OPT_DEPTH}, {"res", required_argument, NULL, OPT_RES},
        {"camera", required_argument, NULL, OPT_CAMERA}, {"seed", required_argument, NULL, OPT_SEED},
        {"threads", required_argument, NULL, OPT_THREADS}, {"json", no_argument, NULL, OPT_JSON},
        {"help", no_argument, NULL, 'h'},           {NULL, 0, NULL, 0},
    };
    long v;
    opterr = 0;
    optind = 1;
    int c;
    while ((c = getopt_long(argc, argv, ":o:h", opts, NULL)) != -1) {
        switch (c) {
        case 'o': a->output = optarg; break;
        case 'h': cmd_render_usage(stdout); return DR_EXIT_OK;
        case OPT_SPP:
            if (!cli_parse_int("render", "--spp", optarg, 1, 1L << 30, &v)) return DR_EXIT_USAGE;
            a->spp = (int)v;
            break;
        case OPT_DEPTH:
            if (!cli_parse_int("render", "--max-depth", optarg, 1, 100000, &v)) return DR_EXIT_USAGE;
            a->max_depth = (int)v;
            break;
        case OPT_RES:
            if (!cli_parse_res("render", "--res", optarg, &a->width, &a->height)) return DR_EXIT_USAGE;
            a->res_given = true;
            break;
        case OPT_CAMERA:
            if (!cli_parse_int("render", "--camera", optarg, 0, 1L << 30, &v)) return DR_EXIT_USAGE;
            a->camera = (int)v;
            a->camera_given = true;
            break;
        case OPT_SEED:
            if (!cli_parse_u64("render", "--seed", optarg, &a->seed)) return DR_EXIT_USAGE;
            break;
        case OPT_THREADS:
            if (!cli_parse_int("render", "--threads", optarg, 0, 256, &v)) return DR_EXIT_USAGE;
            a->threads = (int)v;
            break;
        case OPT_JSON: a->json = true; break;
        case ':':
            cli_error("render", "option '%s' needs a value", argv[optind - 1]);
            return DR_EXIT_USAGE;
        default:
            /* optopt: an unknown short option (argv[optind - 1] is not it inside a group
             * like -xy), or the option of '--json=1'; 0 for an unknown long option. */
            if (optopt > 0 && optopt < 256 && optopt != 'h' && optopt != 'o')
                cli_error("render", "unknown option '-%c' (see 'drender render --help')", optopt);
            else if (optopt != 0)
                cli_error("render", "option '%s' does not take a value", argv[optind - 1]);
            else
                cli_error("render", "unknown option '%s' (see 'drender render --help')", argv[optind - 1]);
            return DR_EXIT_USAGE;
        }
    }
    if (optind < argc)
        a->scene_arg = argv[optind++];
    if (optind < argc) {
        cli_error("render", "unexpected argument '%s' (one scene at a time)", argv[optind]);
        return DR_EXIT_USAGE;
    }
    return -1;
}

static void print_json(const struct render_args *a, const char *scene_path, const struct dr_scene *scene,
                       const char *camera_name, const struct dr_render_stats *st, double t_load, double t_write,
                       double t_total)
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
    fprintf(f, ", \"width\": %d, \"height\": %d, \"spp\": %d, \"max_depth\": %d, \"seed\": %llu, \"threads\": %d",
            a->width, a->height, a->spp, a->max_depth, (unsigned long long)a->seed, st->threads);
    fprintf(f, ", \"camera\": ");
    json_string(f, camera_name);
    fprintf(f, ", \"triangles\": %u", scene->mesh.n_triangles);
    fprintf(f, ", \"time\": {\"load\": ");
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
    fprintf(f, "}, \"invalid_samples\": %llu, \"peak_memory_bytes\": %llu, \"effects\": [",
            (unsigned long long)st->invalid_samples, (unsigned long long)cli_peak_rss_bytes());
    /* effects as a JSON array of names */
    char *save = NULL;
    int first = 1;
    for (char *tok = strtok_r(fx, ",", &save); tok; tok = strtok_r(NULL, ",", &save), first = 0) {
        if (!first)
            fputs(", ", f);
        json_string(f, tok);
    }
    fprintf(f, "]}\n");
}

int cmd_render(int argc, char **argv)
{
    double t_start = cli_now();
    struct render_args a = {NULL, "render.png", 64, 8, 512, 512, 0, 0, false, false, false, 0};
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0)
        return rc;
    /* Everything the user can get wrong in the options is checked before any work. */
    if (!dr_image_can_write(a.output)) {
        cli_error("render", "-o %s: OpenImageIO cannot write this format (use e.g. .exr, .hdr, .png, .jpg)",
                  a.output);
        return DR_EXIT_USAGE;
    }
    if (!cli_output_dir_writable("render", a.output))
        return DR_EXIT_FAILURE;
    char *scene_path = a.scene_arg ? strdup(a.scene_arg) : cli_find_bundled_scene(DEFAULT_SCENE);
    if (!scene_path) {
        cli_error("render", "no SCENE given and the bundled %s was not found (set DRENDER_DATA)", DEFAULT_SCENE);
        return DR_EXIT_INPUT;
    }

    float *rgb = NULL;
    struct dr_scene *scene = dr_scene_load(scene_path);
    if (!scene) {
        cli_error("render", "%s", dr_last_error());
        rc = DR_EXIT_INPUT;
        goto out;
    }
    double t_loaded = cli_now();

    struct dr_camera cam;
    if (a.camera_given && a.camera >= scene->n_cameras) {
        cli_error("render", "--camera %d: %s has %d camera%s%s", a.camera, scene_path, scene->n_cameras,
                  scene->n_cameras == 1 ? "" : "s",
                  scene->n_cameras > 0 ? " (numbered from 0)" : "; without --camera a default view is used");
        rc = DR_EXIT_USAGE;
        goto out;
    }
    cam = scene->n_cameras > 0 ? scene->cameras[a.camera] : dr_camera_default(scene);
    if (!a.res_given) {
        a.height = 512;
        a.width = cam.aspect > 0.0 ? (int)(512.0 * cam.aspect + 0.5) : 512;
        if (a.width < 1)
            a.width = 1;
    }

    if ((rc = cli_limits_render(scene, a.width, a.height, a.threads)) >= 0)
        goto out;
    rgb = malloc(sizeof(float) * 3 * (size_t)a.width * (size_t)a.height);
    if (!rgb) {
        cli_error("render", "out of memory for a %dx%d image", a.width, a.height);
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    struct dr_render_opts ro = {a.width, a.height, a.spp, a.max_depth, 5, a.seed, a.threads, isatty(2) != 0};
    struct dr_render_stats st;
    if (dr_render(scene, &cam, &ro, rgb, &st) != 0) {
        cli_error("render", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    if (st.invalid_samples > 0)
        cli_error("render", "warning: %llu samples were not finite and were dropped",
                  (unsigned long long)st.invalid_samples);
    double t_w0 = cli_now();
    if (dr_image_write(a.output, a.width, a.height, 3, rgb) != 0) {
        cli_error("render", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    double t_end = cli_now();
    if (a.json)
        print_json(&a, scene_path, scene, cam.name, &st, t_loaded - t_start, t_end - t_w0, t_end - t_start);
    rc = DR_EXIT_OK;
out:
    free(rgb);
    dr_scene_destroy(scene);
    free(scene_path);
    return rc;
}
