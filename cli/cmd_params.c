/* drender params: the differentiable parameters a scene offers, with their
 * current values. */
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "grad_common.h"
#include "error.h"
#include "params.h"
#include "scene.h"

#define DEFAULT_SCENE "cornell-box.gltf"

void cmd_params_usage(FILE *out)
{
    fprintf(out,
            "usage: drender params [SCENE] [--json] [--env FILE|COLOR[,STRENGTH]]\n"
            "                      [--no-default-light] [--light-units U]\n"
            "                      [--ignore-unsupported]\n"
            "\n"
            "Lists every differentiable parameter of SCENE (.gltf or .glb; default: the\n"
            "bundled Cornell box): its name (a JSON pointer into the glTF document, as\n"
            "--param takes it), type (color, scalar, image), number of scalars, current\n"
            "value (images: size and mean texel) and, for material parameters, the\n"
            "material's name (which may stand in for its index in --param).\n"
            "\n"
            "options:\n"
            "      --json          print one JSON object on stdout instead of the table\n"
            GRAD_IGNORE_UNSUPPORTED_HELP
            "  -h, --help          show this help\n");
    /* the lighting options change what is listed, as they change what the
     * rendering commands differentiate: --env's parameters replace the
     * file's environment, the default light's appear or not, --light-units
     * sets the punctual intensities shown */
    grad_lighting_usage(out);
}


static bool is_material(const struct dr_param *p)
{
    return p->kind <= DR_PARAM_LAST_MATERIAL;
}

static bool is_image(const struct dr_param *p)
{
    return dr_param_is_array(p);
}

/* Mean of each channel of an image parameter (values: size scalars). */
static void channel_means(const struct dr_param *p, const double *values, double mean[4])
{
    int ch = p->channels > 0 ? p->channels : 1;
    int64_t texels = p->size / ch;
    for (int c = 0; c < 4; c++)
        mean[c] = 0.0;
    for (int64_t i = 0; i < texels; i++)
        for (int c = 0; c < ch && c < 4; c++)
            mean[c] += values[i * ch + c];
    for (int c = 0; c < ch && c < 4; c++)
        mean[c] = texels > 0 ? mean[c] / (double)texels : 0.0;
}

static void print_value(FILE *f, const struct dr_param *p, const double *values)
{
    if (is_image(p)) {
        double mean[4];
        channel_means(p, values, mean);
        if (p->kind == DR_PARAM_MEDIUM_DENSITY)
            fprintf(f, "grid of %lld voxels, mean (", (long long)p->size);
        else
            fprintf(f, "%dx%dx%d image, mean (", p->width, p->height, p->channels);
        for (int c = 0; c < p->channels && c < 4; c++)
            fprintf(f, "%s%.6g", c ? ", " : "", mean[c]);
        fputc(')', f);
        return;
    }
    if (p->size == 1) {
        fprintf(f, "%.6g", values[0]);
        return;
    }
    fputc('(', f);
    for (int64_t i = 0; i < p->size; i++)
        fprintf(f, "%s%.6g", i ? ", " : "", values[i]);
    fputc(')', f);
}

static void print_json_param(FILE *f, const struct dr_scene *s, const struct dr_param *p, const double *values)
{
    fprintf(f, "{\"name\": ");
    json_string(f, p->name);
    fprintf(f, ", \"type\": ");
    json_string(f, dr_param_type_name(p));
    fprintf(f, ", \"size\": %lld", (long long)p->size);
    if (is_image(p)) {
        double mean[4];
        channel_means(p, values, mean);
        fprintf(f, ", \"width\": %d, \"height\": %d, \"channels\": %d, \"mean\": [", p->width, p->height,
                p->channels);
        for (int c = 0; c < p->channels && c < 4; c++) {
            if (c)
                fputs(", ", f);
            json_number(f, mean[c]);
        }
        fputc(']', f);
    } else {
        fprintf(f, ", \"value\": [");
        for (int64_t i = 0; i < p->size; i++) {
            if (i)
                fputs(", ", f);
            json_number(f, values[i]);
        }
        fputc(']', f);
    }
    if (is_material(p) && s->materials[p->target].name[0]) {
        fprintf(f, ", \"material\": ");
        json_string(f, s->materials[p->target].name);
    }
    fputc('}', f);
}

/* The list, as the table or (json) one JSON object, on f. -1 when done, or
 * an exit code. */
static int print_params(FILE *f, bool json, const char *scene_path, const struct dr_scene *scene,
                        const struct dr_param *list, int n)
{
    int64_t biggest = 1;
    size_t name_w = 4;
    for (int i = 0; i < n; i++) {
        if (list[i].size > biggest)
            biggest = list[i].size;
        if (strlen(list[i].name) > name_w)
            name_w = strlen(list[i].name);
    }
    double *values = malloc(sizeof(double) * (size_t)biggest);
    if (!values) {
        cli_error("params", "out of memory");
        return DR_EXIT_FAILURE;
    }
    if (json) {
        fprintf(f, "{\"command\": \"params\", \"scene\": ");
        json_string(f, scene_path);
        fprintf(f, ", \"parameters\": [");
        for (int i = 0; i < n; i++) {
            dr_param_get(scene, &list[i], values);
            if (i)
                fputs(", ", f);
            print_json_param(f, scene, &list[i], values);
        }
        fprintf(f, "]}\n");
    } else {
        fprintf(f, "%s: %d differentiable parameter%s\n", scene_path, n, n == 1 ? "" : "s");
        if (n > 0)
            fprintf(f, "%-*s  %-6s  %7s  %s\n", (int)name_w, "NAME", "TYPE", "SIZE", "VALUE");
        for (int i = 0; i < n; i++) {
            const struct dr_param *p = &list[i];
            dr_param_get(scene, p, values);
            fprintf(f, "%-*s  %-6s  %7lld  ", (int)name_w, p->name, dr_param_type_name(p), (long long)p->size);
            print_value(f, p, values);
            if (is_material(p) && scene->materials[p->target].name[0])
                fprintf(f, "  [material '%s']", scene->materials[p->target].name);
            fputc('\n', f);
        }
    }
    free(values);
    return -1;
}

static int no_own_option(void *ctx, int c, const char *arg)
{
    (void)ctx, (void)c, (void)arg;
    return -1;
}

int cmd_params(int argc, char **argv)
{
    static const struct option opts[] = {
        {"json", no_argument, NULL, GOPT_JSON},
        {"ignore-unsupported", no_argument, NULL, GOPT_IGNORE_UNSUPPORTED},
        {"env", required_argument, NULL, GOPT_ENV},
        {"no-default-light", no_argument, NULL, GOPT_NO_DEFAULT_LIGHT},
        {"light-units", required_argument, NULL, GOPT_LIGHT_UNITS},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    struct grad_common g;
    grad_common_init(&g, "params", 1);
    int prc = grad_parse_args(&g, argc, argv, opts, "", no_own_option, NULL, cmd_params_usage);
    const bool json = g.json;
    const char *scene_arg = g.scene_arg;
    const struct dr_load_opts load = g.load;
    if (prc >= 0) {
        grad_common_free(&g);
        return prc;
    }
    char *scene_path = scene_arg ? strdup(scene_arg) : cli_find_bundled_scene(DEFAULT_SCENE);
    if (!scene_path) {
        cli_error("params", "no SCENE given and the bundled %s was not found (set DRENDER_DATA)", DEFAULT_SCENE);
        grad_common_free(&g);
        return DR_EXIT_INPUT;
    }
    int rc;
    struct dr_param *list = NULL;
    int n = 0;
    struct dr_scene *scene = dr_scene_load_opts(scene_path, &load);
    if (!scene) {
        cli_error("params", "%s", dr_last_error());
        rc = cli_error_exit(DR_EXIT_INPUT);
        goto out;
    }
    /* the lighting a rendering command would use with the same options
     * (--env, or the default environment) has parameters too */
    if ((rc = grad_apply_lighting(&g, scene_path, scene)) >= 0)
        goto out;
    if (dr_params_list(scene, &list, &n) != 0) {
        cli_error("params", "%s", dr_last_error());
        rc = DR_EXIT_FAILURE;
        goto out;
    }
    if ((rc = print_params(stdout, json, scene_path, scene, list, n)) >= 0)
        goto out;
    rc = DR_EXIT_OK;
out:
    free(list);
    dr_scene_destroy(scene);
    free(scene_path);
    grad_common_free(&g);
    return rc;
}
