/* Options and set-up shared by the gradient commands (grad, fdcheck):
 * --param, --estimator, --sampling, --spp, --max-depth, --res, --camera,
 * --seed, --threads, --json; loading the scene, choosing the camera and the
 * image size, resolving the parameters. */
#ifndef DR_GRAD_COMMON_H
#define DR_GRAD_COMMON_H

#include <getopt.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "estimator.h"
#include "params.h"
#include "scene.h"

/* getopt_long codes of the shared options; each command numbers its own
 * options from GOPT_END on. */
enum {
    GOPT_PARAM = 256,
    GOPT_ESTIMATOR,
    GOPT_SAMPLING,
    GOPT_SPP,
    GOPT_DEPTH,
    GOPT_RES,
    GOPT_CAMERA,
    GOPT_SEED,
    GOPT_THREADS,
    GOPT_JSON,
    GOPT_SET,
    GOPT_END
};

/* The shared entries of a getopt_long table (copied into each command's table). */
#define GRAD_COMMON_LONG_OPTIONS                                                                       \
    {"param", required_argument, NULL, GOPT_PARAM}, {"estimator", required_argument, NULL, GOPT_ESTIMATOR}, \
        {"sampling", required_argument, NULL, GOPT_SAMPLING}, {"spp", required_argument, NULL, GOPT_SPP},   \
        {"max-depth", required_argument, NULL, GOPT_DEPTH}, {"res", required_argument, NULL, GOPT_RES},     \
        {"camera", required_argument, NULL, GOPT_CAMERA}, {"seed", required_argument, NULL, GOPT_SEED},     \
        {"threads", required_argument, NULL, GOPT_THREADS}, {"json", no_argument, NULL, GOPT_JSON},         \
        {"set", required_argument, NULL, GOPT_SET},                                                    \
        {"help", no_argument, NULL, 'h'}

struct grad_common {
    const char *cmd;                 /* "grad", "fdcheck": prefixes messages */
    const char *scene_arg;
    const char **params;             /* the --param values, in order (argv strings) */
    int n_params;
    const char **sets;               /* the --set P=V,... values, in order */
    int n_sets;
    const struct dr_estimator_ops *estimator;
    int spp, max_depth, width, height, camera, threads;
    bool res_given, camera_given, json;
    uint64_t seed;
};

/* Defaults: prb, detached, the given spp, depth 8, no --res. */
void grad_common_init(struct grad_common *g, const char *cmd, int spp);
void grad_common_free(struct grad_common *g);

/* Handles one shared option. Returns 0 when handled, DR_EXIT_USAGE after
 * printing a message, or -1 when `c` is not a shared option. */
int grad_common_option(struct grad_common *g, int c, const char *arg);

/* Reports a getopt_long failure ('?' or ':') the way every command does. */
int grad_getopt_error(const char *cmd, int c, char **argv, const char *short_with_arg);

/* Checks the options that need no scene (at least one --param). */
int grad_common_check(const struct grad_common *g);

/* Loads the scene (exit 3 on failure), checks --camera (exit 2) and picks the
 * camera. When !g->res_given, the size is taken from default_w/default_h if
 * positive, else as `render` does (512 high, width from the aspect ratio).
 * Returns -1 to go on, or an exit code; *scene must be destroyed by the caller. */
int grad_load_scene(struct grad_common *g, char **scene_path, struct dr_scene **scene, struct dr_camera *cam,
                    int default_w, int default_h);

/* Applies every --set POINTER=V[,V...] to the scene (before parameters are
 * read), refreshing it. Returns -1 to go on or DR_EXIT_USAGE after a message
 * (unknown pointer with nearest names, wrong count, value out of range). */
int grad_apply_sets(const struct grad_common *g, struct dr_scene *scene);

/* Resolves the --param list (exit 2 with dr_last_error's nearest names). */
int grad_param_set(const struct grad_common *g, const struct dr_scene *scene, struct dr_param_set **set);

/* Reads a target image (--target): the first 3 channels (grey replicated) as
 * linear float rgb (8-bit sRGB files decoded); NaN/Inf pixels refused.
 * img keeps the file's size (release it). Returns -1 to go on or an exit code. */
int grad_load_target(const char *cmd, const char *path, struct dr_image *img, float **rgb);

/* Names of the effects a parameter set differentiates, comma separated. */
void grad_effects_differentiated(const struct dr_param_set *set, char *buf, size_t size);
/* The same as a JSON array. */
void grad_json_effects(FILE *f, const struct dr_param_set *set);

#endif
