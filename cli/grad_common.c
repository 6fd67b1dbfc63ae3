/* Options and set-up shared by drender grad and drender fdcheck. */
#include "grad_common.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "camera.h"
#include "cli.h"
#include "error.h"
#include "image_io.h"
#include "path_deriv.h"
#include "parallel.h"

#define DEFAULT_SCENE "cornell-box.gltf"

void grad_common_init(struct grad_common *g, const char *cmd, int spp)
{
    memset(g, 0, sizeof *g);
    g->cmd = cmd;
    g->estimator = dr_estimator_find("prb");
    g->spp = spp;
    g->max_depth = 8;
    g->rr_depth = DR_RR_DEPTH_DEFAULT;
    g->sampling = DR_SAMPLING_DETACHED;   /* (until grad_resolve_sampling) */
    g->sampling_auto = true;
    g->regularize = DR_PRB_REGULARIZE_DEFAULT;
}

void grad_common_free(struct grad_common *g)
{
    free(g->env_file_buf);
    g->env_file_buf = NULL;
    free(g->params);
    free(g->sets);
    g->params = g->sets = NULL;
    g->n_params = g->n_sets = 0;
}

static void list_estimators(char *buf, size_t size)
{
    buf[0] = '\0';
    for (int i = 0; dr_estimators[i]; i++) {
        size_t len = strlen(buf);
        snprintf(buf + len, size - len, "%s%s", i ? ", " : "", dr_estimators[i]->name);
    }
}

/* --env FILE[,STRENGTH] or --env R,G,B[,STRENGTH] / GREY[,STRENGTH]. Numbers
 * first: "1,1,1" is a colour even if a file of that name existed. */
static int env_option(struct grad_common *g, const char *arg)
{
    double v[5];
    int n = 0;
    const char *p = arg;
    while (*p && n < 5) {
        char *end;
        errno = 0;
        double x = strtod(p, &end);
        if (end == p || errno || (*end && *end != ','))
            break;
        v[n++] = x;
        p = *end ? end + 1 : end;
    }
    g->env_given = true;
    if (!*p && n >= 1 && n <= 4) {
        g->env_file = NULL;
        g->env_color = n >= 3 ? dr_v3(v[0], v[1], v[2]) : dr_v3s(v[0]);
        g->env_strength = n == 2 ? v[1] : n == 4 ? v[3] : 1.0;
        for (int i = 0; i < n; i++)
            if (!isfinite(v[i]) || v[i] < 0.0) {
                cli_error(g->cmd, "--env %s: colour and strength must be finite and >= 0", arg);
                return DR_EXIT_USAGE;
            }
        return 0;
    }
    /* a file, perhaps with ",STRENGTH" */
    g->env_color = dr_v3s(1.0);
    g->env_strength = 1.0;
    g->env_file = arg;
    if (access(arg, R_OK) == 0)
        return 0;
    const char *comma = strrchr(arg, ',');
    if (comma) {
        char *end;
        double st = strtod(comma + 1, &end);
        size_t len = (size_t)(comma - arg);
        char *file = len ? strndup(arg, len) : NULL;
        if (file && !*end && isfinite(st) && st >= 0.0 && access(file, R_OK) == 0) {
            g->env_strength = st;
            free(g->env_file_buf);   /* a repeated --env: the last one wins */
            g->env_file = g->env_file_buf = file;
            return 0;
        }
        free(file);
    }
    cli_error(g->cmd, "--env %s: neither a readable image file nor a colour (R,G,B[,STRENGTH] or GREY[,STRENGTH])",
              arg);
    return DR_EXIT_USAGE;
}

static int film_option(struct grad_common *g, int c, const char *arg);

/* --param and --set: appended to their lists. */
static int list_option(struct grad_common *g, int c, const char *arg)
{
    switch (c) {
    case GOPT_PARAM: {
        const char **p = realloc(g->params, sizeof *p * (size_t)(g->n_params + 1));
        if (!p) {
            cli_error(g->cmd, "out of memory");
            return DR_EXIT_FAILURE;
        }
        g->params = p;
        g->params[g->n_params++] = arg;
        return 0;
    }
    case GOPT_SET: {
        const char **p = realloc(g->sets, sizeof *p * (size_t)(g->n_sets + 1));
        if (!p) {
            cli_error(g->cmd, "out of memory");
            return DR_EXIT_FAILURE;
        }
        g->sets = p;
        g->sets[g->n_sets++] = arg;
        return 0;
    }
    default: return -1;
    }
}

/* How derivatives are estimated: --estimator, --sampling, --regularize, --sampler. */
static int method_option(struct grad_common *g, int c, const char *arg)
{
    switch (c) {
    case GOPT_ESTIMATOR:
        g->estimator = dr_estimator_find(arg);
        if (!g->estimator) {
            char names[256];
            list_estimators(names, sizeof names);
            cli_error(g->cmd, "--estimator: unknown estimator '%s' (available: %s)", arg, names);
            return DR_EXIT_USAGE;
        }
        return 0;
    case GOPT_SAMPLING: {
        if (strcmp(arg, "auto") == 0) {
            g->sampling_auto = true;
            g->sampling = DR_SAMPLING_DETACHED;
            return 0;
        }
        int s = dr_sampling_parse(arg);
        if (s < 0) {
            char known[128] = "auto";   /* from the registry: a new mode is listed as soon as it exists */
            for (int k = 0, len = 4; k < DR_SAMPLING_COUNT; k++)
                len += snprintf(known + len, sizeof known - (size_t)len, ", %s", dr_sampling_name((enum dr_sampling)k));
            cli_error(g->cmd, "--sampling: unknown sampling strategy '%s' (known: %s)", arg, known);
            return DR_EXIT_USAGE;
        }
        g->sampling = (enum dr_sampling)s;
        g->sampling_auto = false;
        return 0;
    }
    case GOPT_REGULARIZE: {
        double e;
        if (!cli_parse_double(g->cmd, "--regularize", arg, -1.0, &e))
            return DR_EXIT_USAGE;
        if (e < 0.0 || e > 1.0) {
            cli_error(g->cmd, "--regularize: %s is outside [0, 1] (0: exact inverse Jacobians)", arg);
            return DR_EXIT_USAGE;
        }
        g->regularize = e;
        return 0;
    }
    case GOPT_SAMPLER: {
        int k = dr_sampler_kind_parse(arg);
        if (k < 0) {
            cli_error(g->cmd, "--sampler: unknown sampler '%s' (known: independent, stratified, sobol)", arg);
            return DR_EXIT_USAGE;
        }
        g->sampler = (enum dr_sampler_kind)k;
        g->sampler_given = true;
        return 0;
    }
    case GOPT_MEDIUM_GRAD: {
        int m = dr_medium_grad_parse(arg);
        if (m < 0) {
            cli_error(g->cmd, "--medium-grad: unknown method '%s' (known: drt, baseline)", arg);
            return DR_EXIT_USAGE;
        }
        g->medium_grad = (enum dr_medium_grad)m;
        return 0;
    }
    default: return -1;
    }
}

int grad_common_option(struct grad_common *g, int c, const char *arg)
{
    long v;
    switch (c) {
    case GOPT_RR_DEPTH:
        if (!cli_parse_int(g->cmd, "--rr-depth", arg, 1, 1L << 30, &v))
            return DR_EXIT_USAGE;
        g->rr_depth = (int)v;
        return 0;
    case GOPT_SPP:
        if (!cli_parse_int(g->cmd, "--spp", arg, 1, 1L << 30, &v))
            return DR_EXIT_USAGE;
        g->spp = (int)v;
        return 0;
    case GOPT_DEPTH:
        if (!cli_parse_int(g->cmd, "--max-depth", arg, 1, 100000, &v))
            return DR_EXIT_USAGE;
        g->max_depth = (int)v;
        return 0;
    case GOPT_RES:
        if (!cli_parse_res(g->cmd, "--res", arg, &g->width, &g->height))
            return DR_EXIT_USAGE;
        g->res_given = true;
        return 0;
    case GOPT_CAMERA:
        if (!cli_parse_int(g->cmd, "--camera", arg, 0, 1L << 30, &v))
            return DR_EXIT_USAGE;
        g->camera = (int)v;
        g->camera_given = true;
        return 0;
    case GOPT_SEED:
        if (!cli_parse_u64(g->cmd, "--seed", arg, &g->seed))
            return DR_EXIT_USAGE;
        return 0;
    case GOPT_THREADS:
        if (!cli_parse_int(g->cmd, "--threads", arg, 0, 256, &v))
            return DR_EXIT_USAGE;
        g->threads = (int)v;
        /* (the loader, the structures' builds and the image library keep to it too) */
        dr_set_default_threads(g->threads);
        dr_image_set_threads(g->threads);
        return 0;
    case GOPT_JSON: g->json = true; return 0;
    case GOPT_PARAM:
    case GOPT_SET: return list_option(g, c, arg);
    case GOPT_ESTIMATOR:
    case GOPT_SAMPLING:
    case GOPT_REGULARIZE:
    case GOPT_SAMPLER:
    case GOPT_MEDIUM_GRAD: return method_option(g, c, arg);
    case GOPT_FILTER:
    case GOPT_CROP: return film_option(g, c, arg);
    case GOPT_ENV: return env_option(g, arg);
    case GOPT_NO_DEFAULT_LIGHT: g->no_default_light = true; return 0;
    case GOPT_LIGHT_UNITS:
        if (strcmp(arg, "photometric") != 0 && strcmp(arg, "radiometric") != 0) {
            cli_error(g->cmd, "--light-units %s: expected photometric (glTF: candela, lux) or radiometric (W/sr, W/m^2)",
                      arg);
            return DR_EXIT_USAGE;
        }
        g->light_units_given = true;
        g->light_units = arg[0] == 'p' ? DR_LIGHT_UNITS_PHOTOMETRIC : DR_LIGHT_UNITS_RADIOMETRIC;
        return 0;
    case GOPT_IGNORE_UNSUPPORTED: g->load.ignore_unsupported = true; return 0;
    default: return -1;
    }
}

int grad_getopt_error(const char *cmd, int c, char **argv, const char *short_with_arg)
{
    if (c == ':') {
        cli_error(cmd, "option '%s' needs a value", argv[optind - 1]);
        return DR_EXIT_USAGE;
    }
    /* optopt: an unknown short option (argv[optind - 1] is not it inside a group
     * like -xy), or the option of '--json=1'; 0 for an unknown long option. */
    if (optopt > 0 && optopt < 256 && optopt != 'h' && !strchr(short_with_arg, optopt))
        cli_error(cmd, "unknown option '-%c' (see 'drender %s --help')", optopt, cmd);
    else if (optopt != 0)
        cli_error(cmd, "option '%s' does not take a value", argv[optind - 1]);
    else
        cli_error(cmd, "unknown option '%s' (see 'drender %s --help')", argv[optind - 1], cmd);
    return DR_EXIT_USAGE;
}

int grad_parse_args(struct grad_common *g, int argc, char **argv, const struct option *opts,
                    const char *short_with_arg, grad_own_option_fn own, void *ctx, void (*usage)(FILE *))
{
    char shortopts[16];
    snprintf(shortopts, sizeof shortopts, ":%sh", short_with_arg[0] ? "o:" : "");
    opterr = 0;
    optind = 0;   /* glibc: re-initialise getopt fully (a batch parses many command lines) */
    int c;
    while ((c = getopt_long(argc, argv, shortopts, opts, NULL)) != -1) {
        if (c == 'h') {
            usage(stdout);
            return DR_EXIT_OK;
        }
        int rc = grad_common_option(g, c, optarg);
        if (rc == -1)
            rc = own(ctx, c, optarg);
        if (rc == -1)
            return grad_getopt_error(g->cmd, c, argv, short_with_arg);
        if (rc != 0)
            return rc;
    }
    if (optind < argc)
        g->scene_arg = argv[optind++];
    if (optind < argc) {
        cli_error(g->cmd, "unexpected argument '%s' (one scene at a time)", argv[optind]);
        return DR_EXIT_USAGE;
    }
    return -1;
}

int grad_common_check(const struct grad_common *g)
{
    if (!dr_estimator_supports(g->estimator, g->sampling)) {
        char have[64] = "", others[128] = "";
        for (int k = 0; k < DR_SAMPLING_COUNT; k++)
            if (dr_estimator_supports(g->estimator, (enum dr_sampling)k))
                snprintf(have + strlen(have), sizeof have - strlen(have), "%s%s", have[0] ? ", " : "",
                         dr_sampling_name((enum dr_sampling)k));
        for (int e = 0; dr_estimators[e]; e++)
            if (dr_estimator_supports(dr_estimators[e], g->sampling))
                snprintf(others + strlen(others), sizeof others - strlen(others), "%s%s", others[0] ? ", " : "",
                         dr_estimators[e]->name);
        cli_error(g->cmd, "--sampling %s: not available for estimator '%s' (it implements: %s; %s sampling: --estimator %s)",
                  dr_sampling_name(g->sampling), g->estimator->name, have, dr_sampling_name(g->sampling),
                  others[0] ? others : "none yet");
        return DR_EXIT_USAGE;
    }
    if (g->n_params == 0) {
        cli_error(g->cmd, "--param is required (at least one; 'drender params SCENE' lists them)");
        return DR_EXIT_USAGE;
    }
    return -1;
}

void grad_lighting_usage(FILE *out)
{
    fprintf(out,
            "\nlighting:\n"
            "      --env FILE|COLOR[,STRENGTH]\n"
            "                      set the environment: an equirectangular image (.exr,\n"
            "                      .hdr, ...) or a colour R,G,B or GREY, times STRENGTH\n"
            "                      (default 1); replaces the file's DR_environment\n"
            "      --no-default-light\n"
            "                      render a scene without any light black (by default it gets\n"
            "                      a white environment of radiance 1, with a note on stderr)\n"
            "      --light-units U photometric (glTF's definition: candela, lux; divided by\n"
            "                      683 lm/W) or radiometric (W/sr, W/m^2) punctual light\n"
            "                      intensities (default: the file's DR_units, else\n"
            "                      photometric)\n");
}

int grad_apply_lighting(const struct grad_common *g, const char *scene_path, struct dr_scene *scene)
{
    if (g->light_units_given && dr_scene_set_light_units(scene, g->light_units) != 0) {
        cli_error(g->cmd, "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    if (g->env_given) {
        if (dr_scene_set_environment(scene, g->env_color, g->env_strength, g->env_file, false) != 0) {
            cli_error(g->cmd, "--env %s", dr_last_error());
            return g->env_file ? cli_error_exit(DR_EXIT_INPUT) : DR_EXIT_FAILURE;
        }
        return -1;
    }
    if (dr_scene_has_light(scene) || g->no_default_light)
        return -1;
    if (dr_scene_set_environment(scene, dr_v3s(1.0), 1.0, NULL, true) != 0) {
        cli_error(g->cmd, "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    cli_error(g->cmd, "note: %s has no light (no emissive surface, punctual light or environment): lit by a "
                      "default white environment of radiance 1 (--env to choose one, --no-default-light for none)",
              scene_path);
    return -1;
}

void grad_camera_error(const char *cmd, const char *what, int index, const char *scene_path,
                       const struct dr_scene *s)
{
    char unplaced[160] = "";
    if (s->n_unplaced_cameras > 0)
        snprintf(unplaced, sizeof unplaced, "; %d more in its \"cameras\" %s placed by no node, so not renderable",
                 s->n_unplaced_cameras, s->n_unplaced_cameras == 1 ? "is" : "are");
    cli_error(cmd, "%s %d: %s has %d camera%s%s%s", what, index, scene_path, s->n_cameras,
              s->n_cameras == 1 ? "" : "s",
              s->n_cameras > 0 ? " (numbered from 0 in node order, orthographic ones included)"
                               : "; without --camera a default view is used",
              unplaced);
}

int grad_load_scene(struct grad_common *g, char **scene_path, struct dr_scene **scene, struct dr_camera *cam,
                    int default_w, int default_h)
{
    *scene = NULL;
    *scene_path = g->scene_arg ? strdup(g->scene_arg) : cli_find_bundled_scene(DEFAULT_SCENE);
    if (!*scene_path) {
        cli_error(g->cmd, "no SCENE given and the bundled %s was not found (set DRENDER_DATA)", DEFAULT_SCENE);
        return DR_EXIT_INPUT;
    }
    *scene = dr_scene_load_opts(*scene_path, &g->load);
    if (!*scene) {
        cli_error(g->cmd, "%s", dr_last_error());
        return cli_error_exit(DR_EXIT_INPUT);
    }
    int lrc = grad_apply_lighting(g, *scene_path, *scene);
    if (lrc >= 0)
        return lrc;
    const struct dr_scene *s = *scene;
    if (g->camera_given && g->camera >= s->n_cameras) {
        grad_camera_error(g->cmd, "--camera", g->camera, *scene_path, s);
        return DR_EXIT_USAGE;
    }
    *cam = s->n_cameras > 0 ? s->cameras[g->camera] : dr_camera_default(s);
    if (!g->res_given) {
        if (default_w > 0 && default_h > 0) {
            g->width = default_w;
            g->height = default_h;
        } else {
            g->height = 512;
            g->width = cam->aspect > 0.0 ? (int)(512.0 * cam->aspect + 0.5) : 512;
            if (g->width < 1)
                g->width = 1;
        }
    }
    return -1;
}

int grad_param_set(const struct grad_common *g, const struct dr_scene *scene, struct dr_param_set **set)
{
    *set = dr_param_set_create(scene, g->params, g->n_params);
    if (!*set) {
        if (dr_last_error_is_nomem()) {
            cli_error(g->cmd, "%s", dr_last_error());
            return DR_EXIT_FAILURE;
        }
        cli_error(g->cmd, "--param %s", dr_last_error());
        return DR_EXIT_USAGE;
    }
    /* a sampling mode this scene cannot take is bad usage: refused before any work */
    struct dr_grad_problem p = {.scene = scene, .params = *set, .sampling = g->sampling};
    if (g->estimator && dr_estimator_check(g->estimator, &p) != 0) {
        cli_error(g->cmd, "%s", dr_last_error());
        dr_param_set_destroy(*set);
        *set = NULL;
        return DR_EXIT_USAGE;
    }
    return -1;
}

static int cmp_float(const void *a, const void *b)
{
    const float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The median roughness of material m's metallic-roughness texture (its G
 * channel, stored linear, times the factor) over at most 65536 texels taken
 * at an even stride; -1 without texels. */
static double texture_median_roughness(const struct dr_scene *scene, int m)
{
    const struct dr_material *mat = &scene->materials[m];
    const struct dr_image *img = &scene->images[scene->textures[mat->metallic_roughness_tex.texture].image];
    const size_t n = (size_t)img->width * (size_t)img->height;
    if (n == 0 || img->channels < 2)
        return -1.0;
    const size_t stride = n > 65536 ? n / 65536 : 1, k = (n + stride - 1) / stride;
    float *g = malloc(k * sizeof *g);
    if (!g)
        return -1.0;   /* (no choice made on it: detached, as before auto) */
    for (size_t i = 0; i < k; i++)
        g[i] = dr_image_value(img, i * stride * (size_t)img->channels + 1, false);
    qsort(g, k, sizeof *g, cmp_float);
    const double med = g[k / 2] * mat->roughness;
    free(g);
    return med;
}

/* A differentiated roughness below threshold: the factor's value (times
 * its material's metallic-roughness texture's median, material_roughness),
 * or a differentiated metallic-roughness texture's median. */
static void auto_candidate(struct grad_auto_choice *c, const struct dr_param *q, double r, bool texture,
                           double threshold)
{
    if (!(r >= 0.0 && r < threshold))
        return;
    if (!c->lowest || r < c->roughness)
        c->lowest = q, c->roughness = r, c->texture = texture, c->lowest_threshold = threshold;
    c->narrow++;
}

/* The roughness of material m as auto weighs a differentiated factor: the
 * factor, times the median of the material's metallic-roughness texture's G
 * where it has one (the roughness the surface has is their product). */
static double material_roughness(const struct dr_scene *scene, int m)
{
    const struct dr_material *mat = &scene->materials[m];
    return mat->metallic_roughness_tex.texture >= 0 ? texture_median_roughness(scene, m) : mat->roughness;
}

struct grad_auto_choice grad_auto_sampling(const struct dr_estimator_ops *e, const struct dr_scene *scene,
                                           const struct dr_param_set *set)
{
    struct grad_auto_choice c = {.sampling = DR_SAMPLING_DETACHED, .threshold = GRAD_AUTO_ROUGHNESS};
    for (int m = 0; m < scene->n_materials; m++)   /* (derivative sampling then samples for them too) */
        if (dr_path_material_dparams(scene, set, m) & (DR_BSDF_D_BASE | DR_BSDF_D_METALLIC))
            c.threshold = GRAD_AUTO_ROUGHNESS_WITH_COLOUR;
    bool any = false;
    for (int i = 0; i < set->n; i++) {
        const struct dr_param *q = &set->params[i];
        if (q->kind == DR_PARAM_CLEARCOAT_ROUGHNESS && q->target >= 0 && q->target < scene->n_materials) {
            any = true;   /* (its factor: a clearcoatRoughnessTexture's texels are weighed by no median) */
            auto_candidate(&c, q, scene->materials[q->target].coat_roughness, false,
                           c.threshold == GRAD_AUTO_ROUGHNESS ? GRAD_AUTO_COAT_ROUGHNESS : c.threshold);
        } else if (q->kind == DR_PARAM_ROUGHNESS && q->target >= 0 && q->target < scene->n_materials &&
                   dr_path_deriv_aniso_pair_ok(&scene->materials[q->target])) {   /* (path_deriv.h) */
            any = true;
            auto_candidate(&c, q, material_roughness(scene, q->target), false, c.threshold);
        } else if (q->kind == DR_PARAM_IMAGE) {   /* the metallic-roughness textures it is */
            for (int m = 0; m < scene->n_materials; m++) {
                const int t = scene->materials[m].metallic_roughness_tex.texture;
                if (t < 0 || scene->textures[t].image != q->target || !dr_path_deriv_aniso_pair_ok(&scene->materials[m]))
                    continue;
                any = true;
                auto_candidate(&c, q, texture_median_roughness(scene, m), true, c.threshold);
            }
        }
    }
    if (any && e) {
        struct dr_grad_problem p = {.scene = scene, .params = set, .sampling = DR_SAMPLING_DERIVATIVE_ROUGHNESS};
        c.derivative_possible = dr_estimator_check(e, &p) == 0;   /* (an estimator without it) */
        if (!c.derivative_possible)
            snprintf(c.why, sizeof c.why, "%s", dr_last_error());
    }
    if (c.lowest && c.derivative_possible)
        c.sampling = DR_SAMPLING_DERIVATIVE_ROUGHNESS;
    return c;
}

void grad_auto_describe(const struct dr_scene *scene, const struct grad_auto_choice *c, char *buf, size_t size)
{
    buf[0] = '\0';
    if (!c->lowest)
        return;
    char name[DR_PARAM_NAME_MAX + 64], more[48] = "";
    dr_param_display_name(scene, c->lowest, name, sizeof name);
    if (c->narrow > 1)
        snprintf(more, sizeof more, " (and %d more)", c->narrow - 1);
    /* a factor on a textured material: its value, then the product auto weighed */
    char is[96];
    const int m = c->lowest->target;
    if (!c->texture && c->lowest->kind == DR_PARAM_ROUGHNESS && scene->materials[m].metallic_roughness_tex.texture >= 0)
        snprintf(is, sizeof is, "is %g (%g with its metallic-roughness texture: the texels' median G times it)",
                 scene->materials[m].roughness, c->roughness);
    else
        snprintf(is, sizeof is, "%s %g", c->texture ? "has median" : "is", c->roughness);
    snprintf(buf, size, "%s%s %s%s, below %g%s", c->texture ? "the roughness in " : "", name, is, more,
             c->lowest_threshold,
             c->lowest_threshold == GRAD_AUTO_ROUGHNESS_WITH_COLOUR ? " (with a base colour or metallic differentiated)"
                                                                    : "");
}

void grad_auto_note(const struct grad_common *g, const struct dr_scene *scene, const struct grad_auto_choice *c,
                    int iteration)
{
    char when[48] = "", what[DR_PARAM_NAME_MAX + 256];
    if (iteration > 0)
        snprintf(when, sizeof when, "iteration %d: ", iteration);
    if (!c->lowest) {
        if (iteration > 0)
            cli_error(g->cmd, "note: %s--sampling auto goes back to detached sampling (no differentiated roughness "
                              "below %g)", when, c->threshold);
        return;
    }
    grad_auto_describe(scene, c, what, sizeof what);
    if (c->sampling == DR_SAMPLING_DERIVATIVE_ROUGHNESS)
        cli_error(g->cmd,
                  "note: %s--sampling auto chose derivative-roughness sampling (directions sampled for the roughness "
                  "derivative; base colours and metallic as detached): %s, where detached sampling's roughness "
                  "derivative is noisy (on the bundled box derivative sampling was 4.6x as efficient at roughness "
                  "0.1, ~1e7x at 0.001; attached or mis can do better on near-specular lobes but are biased where "
                  "moving samples cross an edge). Manual: SAMPLING",
                  when, what);
    else   /* a small roughness left to detached sampling: say why (the estimator's check's message) */
        cli_error(g->cmd,
                  "note: %s%s, where detached sampling's roughness derivative is noisy, but --sampling auto cannot "
                  "use derivative sampling here (%s). Manual: SAMPLING",
                  when, what, c->why);
}

void grad_resolve_sampling(struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *set)
{
    if (!g->sampling_auto)
        return;
    const struct grad_auto_choice c = grad_auto_sampling(g->estimator, scene, set);
    g->sampling = c.sampling;
    grad_auto_note(g, scene, &c, 0);
}

static void effect_names(const struct dr_param_set *set, const char *names[8], int *n)
{
    bool bsdf = false, emission = false, textures = false, envmap = false;
    for (int m = 0; m < set->n_materials; m++) {
        bsdf |= set->mat_bsdf_active[m];
        emission |= set->mat_emission_active[m];
    }
    for (int i = 0; i < set->n; i++) {
        textures |= set->params[i].kind == DR_PARAM_IMAGE;
        envmap |= set->params[i].kind == DR_PARAM_ENV_MAP;
    }
    *n = 0;
    if (bsdf) names[(*n)++] = "bsdf";
    if (emission) names[(*n)++] = "emission";
    if (set->lights_active) names[(*n)++] = "punctual_lights";
    if (set->env_active) names[(*n)++] = "environment";
    if (envmap) names[(*n)++] = "environment_map";
    if (textures) names[(*n)++] = "textures";
}

void grad_effects_differentiated(const struct dr_param_set *set, char *buf, size_t size)
{
    const char *names[8];
    int n;
    effect_names(set, names, &n);
    buf[0] = '\0';
    for (int i = 0; i < n; i++) {
        size_t len = strlen(buf);
        snprintf(buf + len, size - len, "%s%s", i ? ", " : "", names[i]);
    }
}

void grad_json_effects(FILE *f, const struct dr_param_set *set)
{
    const char *names[8];
    int n;
    effect_names(set, names, &n);
    fputc('[', f);
    for (int i = 0; i < n; i++) {
        if (i)
            fputs(", ", f);
        json_string(f, names[i]);
    }
    fputc(']', f);
}

int grad_load_target(const char *cmd, const char *path, struct dr_image *img, float **rgb)
{
    if (dr_image_read(path, img) != 0) {
        cli_error(cmd, "--target %s", dr_last_error());
        return cli_error_exit(DR_EXIT_INPUT);
    }
    size_t n = (size_t)img->width * img->height;
    *rgb = malloc(sizeof(float) * n * 3);
    if (!*rgb) {
        cli_error(cmd, "--target %s: out of memory", path);
        return DR_EXIT_FAILURE;
    }
    const int ch = img->channels;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            float v = img->data[i * ch + (ch >= 3 ? c : 0)];
            if (!isfinite(v)) {
                cli_error(cmd, "--target %s: pixel (%zu, %zu) channel %d is not a finite number", path,
                          i % (size_t)img->width, i / (size_t)img->width, ch >= 3 ? c : 0);
                return DR_EXIT_INPUT;
            }
            (*rgb)[i * 3 + c] = img->file_is_srgb ? (float)dr_srgb_to_linear(v) : v;
        }
    return -1;
}

/* --set P=v1,v2,... */
static int apply_set(const char *cmd, struct dr_scene *scene, const char *spec)
{
    const char *eq = strrchr(spec, '=');
    if (!eq) {
        cli_error(cmd, "--set %s: expected POINTER=VALUE[,VALUE...]", spec);
        return DR_EXIT_USAGE;
    }
    char ptr[DR_PARAM_NAME_MAX * 2];
    snprintf(ptr, sizeof ptr, "%.*s", (int)(eq - spec), spec);
    struct dr_param p;
    if (dr_param_resolve(scene, ptr, &p) != 0) {
        cli_error(cmd, "--set %s", dr_last_error());
        return cli_error_exit(DR_EXIT_USAGE);
    }
    if (dr_param_is_array(&p)) {
        cli_error(cmd, "--set %s: images cannot be set from the command line (nor density grids)", ptr);
        return DR_EXIT_USAGE;
    }
    double v[4];
    int n = 0;   /* counts every value given, so the message says how many */
    const char *s = eq + 1;
    while (*s) {
        char *end;
        errno = 0;
        double x = strtod(s, &end);
        if (end == s || errno || !isfinite(x) || (*end && *end != ',')) {
            cli_error(cmd, "--set %s: '%s' is not a list of numbers", ptr, eq + 1);
            return DR_EXIT_USAGE;
        }
        if (n < 4)
            v[n] = x;
        n++;
        s = *end ? end + 1 : end;
    }
    if (n != p.size) {
        cli_error(cmd, "--set %s: %d value%s given, the parameter has %lld", ptr, n, n == 1 ? "" : "s",
                  (long long)p.size);
        return DR_EXIT_USAGE;
    }
    double lo, hi;
    dr_param_range(&p, &lo, &hi);
    for (int i = 0; i < n; i++)
        if (v[i] < lo || v[i] > hi) {
            cli_error(cmd, "--set %s: %g is outside the parameter's range [%g, %g]", ptr, v[i], lo, hi);
            return DR_EXIT_USAGE;
        }
    dr_param_put(scene, &p, v);
    return -1;
}

int grad_apply_sets(const struct grad_common *g, struct dr_scene *scene)
{
    for (int i = 0; i < g->n_sets; i++) {
        int rc = apply_set(g->cmd, scene, g->sets[i]);
        if (rc >= 0)
            return rc;
    }
    if (g->n_sets > 0 && dr_scene_refresh(scene) != 0) {
        cli_error(g->cmd, "%s", dr_last_error());
        return DR_EXIT_FAILURE;
    }
    return -1;
}

struct dr_grad_problem grad_problem(const struct grad_common *g, const struct dr_scene *scene,
                                    const struct dr_camera *cam, const struct dr_param_set *ps, int w, int h, int spp,
                                    uint64_t seed)
{
    int rw, rh;
    struct dr_film film = grad_film(g, w, h, &rw, &rh);
    return (struct dr_grad_problem){.scene = scene, .camera = cam, .params = ps, .width = rw, .height = rh,
                                    .spp = spp, .max_depth = g->max_depth, .rr_depth = g->rr_depth, .seed = seed,
                                    .threads = g->threads, .sampling = g->sampling, .film = film,
                                    .regularize = g->regularize, .sampler = g->sampler,
                                    .medium_grad = g->medium_grad};
}

struct dr_render_opts grad_render_opts(const struct grad_common *g, int w, int h, int spp, uint64_t seed,
                                       bool progress)
{
    int rw, rh;
    struct dr_film film = grad_film(g, w, h, &rw, &rh);
    return (struct dr_render_opts){.width = rw, .height = rh, .spp = spp, .max_depth = g->max_depth,
                                   .rr_depth = g->rr_depth, .seed = seed, .threads = g->threads,
                                   .progress = progress, .film = film, .sampler = g->sampler};
}

void grad_totals_add(struct grad_totals *t, const struct dr_grad_stats *st)
{
    t->seconds += st->seconds;
    dr_ray_counts_add(&t->rays, &st->rays);
    t->invalid += st->invalid_samples;
    if (st->memory_bytes > t->memory_bytes)
        t->memory_bytes = st->memory_bytes;
    if (st->record_bytes > t->record_bytes)
        t->record_bytes = st->record_bytes;
    t->stages |= st->stages;
    if (st->threads > 0)
        t->threads = st->threads;
    t->sampling_runs |= 1u << st->sampling_run;
    if (st->n_media_gain > 0) {
        t->n_media_gain = st->n_media_gain;
        memcpy(t->media_gain, st->media_gain, sizeof t->media_gain);
    }
}

void grad_totals_add_render(struct grad_totals *t, const struct dr_render_stats *rs)
{
    dr_ray_counts_add(&t->rays, &rs->rays);
    t->invalid += rs->invalid_samples;
    t->stages |= rs->stages;
    if (rs->threads > 0)
        t->threads = rs->threads;
}

void grad_totals_warn(const char *cmd, const struct grad_totals *t)
{
    if (t->invalid > 0)
        cli_error(cmd, "warning: %llu samples were not finite and were dropped", (unsigned long long)t->invalid);
}

void grad_json_head(FILE *f, const struct grad_common *g, const char *scene_path)
{
    fprintf(f, "\"command\": ");
    json_string(f, g->cmd);
    fprintf(f, ", \"scene\": ");
    json_string(f, scene_path);
    fprintf(f, ", \"estimator\": ");
    json_string(f, g->estimator->name);
    fprintf(f, ", \"sampling\": ");
    json_string(f, dr_sampling_name(g->sampling));
    fprintf(f, ", \"sampling_requested\": ");   /* (auto: "sampling" is its choice) */
    json_string(f, g->sampling_auto ? "auto" : dr_sampling_name(g->sampling));
    fprintf(f, ", \"regularize\": %.17g", g->regularize);
    fprintf(f, ", \"medium_grad\": \"%s\"", dr_medium_grad_name(g->medium_grad));
    fprintf(f, ", \"width\": %d, \"height\": %d, \"spp\": %d, \"max_depth\": %d, \"rr_depth\": %d, \"seed\": %llu",
            g->width, g->height, g->spp, g->max_depth, g->rr_depth, (unsigned long long)g->seed);
    fputs(", ", f);
    grad_json_film(f, g);
}

void grad_json_media_gain(FILE *f, const struct dr_medium_gain_choice *c, int n)
{
    if (n == 0)
        return;
    fputs(", \"medium_gain\": [", f);
    for (int i = 0; i < n; i++) {
        char medium[64];
        dr_medium_param_prefix(c[i].material, medium, sizeof medium);
        fprintf(f, "%s{\"medium\": \"%s\", \"source\": \"%s\", \"reason\": \"%s\"", i ? ", " : "", medium,
                c[i].collisions ? "collisions" : "gain_paths", dr_gain_reason_name(c[i].why));
        if (c[i].grid && c[i].collisions)
            fputs(", \"voxels_source\": \"gain_paths\"", f);
        if (c[i].why == DR_GAIN_PILOT)
            fprintf(f, ", \"pilot_stretches\": %llu, \"pilot_collided\": %llu", (unsigned long long)c[i].stretches,
                    (unsigned long long)c[i].collided);
        fputc('}', f);
    }
    fputc(']', f);
}

void grad_json_run(FILE *f, const struct grad_totals *t)
{
    const struct dr_ray_counts *r = &t->rays;
    fprintf(f, "\"threads\": %d, \"estimator_memory_bytes\": %llu, \"record_bytes\": %llu, "
               "\"peak_memory_bytes\": %llu",
            t->threads, (unsigned long long)t->memory_bytes, (unsigned long long)t->record_bytes,
            (unsigned long long)cli_peak_rss_bytes());
    fprintf(f, ", \"rays\": {\"camera\": %llu, \"extension\": %llu, \"shadow\": %llu, \"total\": %llu}",
            (unsigned long long)r->camera, (unsigned long long)r->extension, (unsigned long long)r->shadow,
            (unsigned long long)(r->camera + r->extension + r->shadow));
    fprintf(f, ", \"vertices_shaded_8_wide\": %llu, \"replayed_vertices_shaded_8_wide\": %llu",
            (unsigned long long)r->simd_vertices, (unsigned long long)r->simd_replayed);
    json_stage_seconds(f, &r->cpu);
    char stages[256];
    dr_path_stages_describe(t->stages, stages, sizeof stages);
    fprintf(f, ", \"invalid_samples\": %llu, \"stages\": ", (unsigned long long)t->invalid);
    json_name_list(f, stages);
    /* attached or mis sampling with no parameter in a sampling map runs detached; so
     * does derivative sampling with no BSDF parameter (derivative-roughness:
     * no roughness). Runs that differ (optimize under auto) name the first
     * of these that ran. */
    static const enum dr_sampling order[] = {DR_SAMPLING_MIS, DR_SAMPLING_ATTACHED, DR_SAMPLING_DERIVATIVE,
                                             DR_SAMPLING_DERIVATIVE_ROUGHNESS};
    enum dr_sampling eff = DR_SAMPLING_DETACHED;
    for (int k = (int)(sizeof order / sizeof order[0]) - 1; k >= 0; k--)
        if (t->sampling_runs & (1u << order[k]))
            eff = order[k];
    fprintf(f, ", \"sampling_effective\": ");
    json_string(f, dr_sampling_name(eff));
    grad_json_media_gain(f, t->media_gain, t->n_media_gain);
}

void grad_json_mis_weight(FILE *f, const struct grad_common *g, double w_detached)
{
    if (g->sampling != DR_SAMPLING_MIS)
        return;
    fprintf(f, ", \"mis_weight\": {\"detached\": ");
    json_number(f, w_detached);
    fprintf(f, ", \"attached\": ");
    json_number(f, 1.0 - w_detached);
    fputc('}', f);
}

/* ---- the film: --filter and --crop (issue 14) ---- */

/* "X,Y,W,H": four integers, X, Y >= 0, W, H >= 1. */
static bool parse_crop(const char *arg, int v[4])
{
    const char *s = arg;
    for (int i = 0; i < 4; i++) {
        char *end;
        errno = 0;
        long x = strtol(s, &end, 10);
        if (end == s || errno || x < (i < 2 ? 0 : 1) || x > (1L << 24) || *end != (i < 3 ? ',' : '\0'))
            return false;
        v[i] = (int)x;
        s = end + 1;
    }
    return true;
}

static int film_option(struct grad_common *g, int c, const char *arg)
{
    if (c == GOPT_FILTER) {
        if (dr_filter_parse(arg, &g->filter) != 0) {
            cli_error(g->cmd, "--filter: %s", dr_last_error());
            return cli_error_exit(DR_EXIT_USAGE);
        }
        return 0;
    }
    int v[4];
    if (!parse_crop(arg, v)) {
        cli_error(g->cmd, "--crop %s: expected X,Y,W,H (the rectangle's top-left pixel, X, Y >= 0, and its size, "
                          "W, H >= 1)", arg);
        return DR_EXIT_USAGE;
    }
    g->crop_given = true;
    g->crop_x = v[0];
    g->crop_y = v[1];
    g->crop_w = v[2];
    g->crop_h = v[3];
    return 0;
}

struct dr_film grad_film(const struct grad_common *g, int w, int h, int *rw, int *rh)
{
    struct dr_film film = {.filter = g->filter};
    *rw = w;
    *rh = h;
    if (g->crop_given) {
        film.frame_w = w;
        film.frame_h = h;
        film.x0 = g->crop_x;
        film.y0 = g->crop_y;
        *rw = g->crop_w;
        *rh = g->crop_h;
    }
    return film;
}

int grad_check_crop(const struct grad_common *g, int frame_w, int frame_h)
{
    if (!g->crop_given || ((int64_t)g->crop_x + g->crop_w <= frame_w && (int64_t)g->crop_y + g->crop_h <= frame_h))
        return -1;
    cli_error(g->cmd, "--crop %d,%d,%d,%d: the rectangle does not lie inside the %dx%d frame (pixels %d..%d x "
                      "%d..%d)", g->crop_x, g->crop_y, g->crop_w, g->crop_h, frame_w, frame_h, g->crop_x,
              g->crop_x + g->crop_w - 1, g->crop_y, g->crop_y + g->crop_h - 1);
    return DR_EXIT_USAGE;
}

int grad_crop_image(const struct grad_common *g, const char *what, float **rgb, int tw, int th, int frame_w,
                    int frame_h)
{
    if (g->crop_given && tw == g->crop_w && th == g->crop_h)
        return -1;   /* already the crop's rectangle */
    if (tw != frame_w || th != frame_h) {
        if (g->crop_given)
            cli_error(g->cmd, "%s is %dx%d: with --crop it must be the crop's size (%dx%d) or the frame's (%dx%d)",
                      what, tw, th, g->crop_w, g->crop_h, frame_w, frame_h);
        else
            cli_error(g->cmd, "%s is %dx%d but the render is %dx%d", what, tw, th, frame_w, frame_h);
        return DR_EXIT_USAGE;
    }
    if (!g->crop_given)
        return -1;
    float *out = malloc(sizeof(float) * 3 * (size_t)g->crop_w * (size_t)g->crop_h);
    if (!out) {
        cli_error(g->cmd, "%s: out of memory", what);
        return DR_EXIT_FAILURE;
    }
    for (int y = 0; y < g->crop_h; y++)
        memcpy(out + 3 * (size_t)y * g->crop_w, *rgb + 3 * ((size_t)(g->crop_y + y) * frame_w + g->crop_x),
               sizeof(float) * 3 * (size_t)g->crop_w);
    free(*rgb);
    *rgb = out;
    return -1;
}

void grad_json_film(FILE *f, const struct grad_common *g)
{
    char name[64];
    dr_filter_format(&g->filter, name, sizeof name);
    fprintf(f, "\"filter\": ");
    json_string(f, name);
    if (g->crop_given)
        fprintf(f, ", \"crop\": [%d, %d, %d, %d]", g->crop_x, g->crop_y, g->crop_w, g->crop_h);
    else
        fprintf(f, ", \"crop\": null");
    fprintf(f, ", \"sampler\": ");
    json_string(f, dr_sampler_kind_name(g->sampler));
}

int grad_parse_primal(const char *cmd, const char *arg, enum dr_primal_mode *mode)
{
    if (strcmp(arg, "cross") == 0)
        *mode = DR_PRIMAL_CROSS;
    else if (strcmp(arg, "separate") == 0)
        *mode = DR_PRIMAL_PER_BATCH;
    else {
        cli_error(cmd, "--primal: unknown mode '%s' (available: cross, separate)", arg);
        return DR_EXIT_USAGE;
    }
    return 0;
}

const char *grad_primal_name(enum dr_primal_mode mode)
{
    return mode == DR_PRIMAL_CROSS ? "cross" : mode == DR_PRIMAL_PER_BATCH ? "separate" : "shared";
}

/* Why (scripts/sampler-table.sh; the man page, "Reverse mode and
 * independent random numbers"): under the cross primal, which weighs each
 * Sobol sample at the other half of its pixel's samples, sobol had 0.9-2.8 x
 * less variance than independent numbers at 4 samples a batch (the
 * default's; median 1.5, glossy roughness the lowest) and 1.1-4.2 x from 8
 * (one case 0.97), for 1.07-1.14 x the time; forward mode 1.2-1.75 x. A
 * batch's separate primal render under sobol was 1.2-1.3 x worse in
 * variance x time: there the independent numbers stay. */
void grad_default_sampler(struct grad_common *g, bool reverse, enum dr_primal_mode primal, int batches)
{
    if (g->sampler_given)
        return;
    const bool cross = dr_reverse_primal_run(primal, g->spp, batches, DR_SAMPLER_SOBOL) == DR_PRIMAL_CROSS;
    g->sampler = !reverse || cross ? DR_SAMPLER_SOBOL : DR_SAMPLER_INDEPENDENT;
}
