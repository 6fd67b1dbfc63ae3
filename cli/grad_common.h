/* Options and set-up shared by the commands that render (render, grad,
 * fdcheck, optimize): --spp, --max-depth, --rr-depth, --res, --camera,
 * --seed, --threads, --json, and for gradients --param, --set, --estimator,
 * --sampling; loading the scene, choosing the camera and the image size,
 * resolving the parameters, and the JSON pieces every summary shares. */
#ifndef DR_GRAD_COMMON_H
#define DR_GRAD_COMMON_H

#include <getopt.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "estimator.h"
#include "params.h"
#include "render.h"
#include "reverse.h"
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
    GOPT_RR_DEPTH,
    GOPT_FILTER,   /* film (issue 14) */
    GOPT_CROP,
    GOPT_REGULARIZE,
    GOPT_SAMPLER,   /* random numbers: independent | sobol */
    GOPT_ENV,       /* lighting: --env FILE|COLOR[,STRENGTH] */
    GOPT_NO_DEFAULT_LIGHT,
    GOPT_LIGHT_UNITS,   /* --light-units photometric|radiometric */
    GOPT_MEDIUM_GRAD,
    GOPT_IGNORE_UNSUPPORTED,   /* loading: dr_load_opts.ignore_unsupported */
    GOPT_END
};

/* The shared entries of a getopt_long table (copied into each command's
 * table): what every rendering command takes, and what gradient commands add. */
#define RENDER_COMMON_LONG_OPTIONS                                                                     \
    {"spp", required_argument, NULL, GOPT_SPP}, {"max-depth", required_argument, NULL, GOPT_DEPTH},        \
        {"rr-depth", required_argument, NULL, GOPT_RR_DEPTH}, {"res", required_argument, NULL, GOPT_RES},  \
        {"camera", required_argument, NULL, GOPT_CAMERA}, {"seed", required_argument, NULL, GOPT_SEED},     \
        {"threads", required_argument, NULL, GOPT_THREADS}, {"json", no_argument, NULL, GOPT_JSON},         \
        {"filter", required_argument, NULL, GOPT_FILTER}, {"crop", required_argument, NULL, GOPT_CROP},     \
        {"sampler", required_argument, NULL, GOPT_SAMPLER}, {"env", required_argument, NULL, GOPT_ENV},      \
        {"no-default-light", no_argument, NULL, GOPT_NO_DEFAULT_LIGHT},                                   \
        {"light-units", required_argument, NULL, GOPT_LIGHT_UNITS},                                       \
        {"ignore-unsupported", no_argument, NULL, GOPT_IGNORE_UNSUPPORTED}, {"help", no_argument, NULL, 'h'}
#define GRAD_COMMON_LONG_OPTIONS                                                                       \
    {"param", required_argument, NULL, GOPT_PARAM}, {"estimator", required_argument, NULL, GOPT_ESTIMATOR}, \
        {"sampling", required_argument, NULL, GOPT_SAMPLING}, {"set", required_argument, NULL, GOPT_SET},   \
        {"regularize", required_argument, NULL, GOPT_REGULARIZE},                           \
        {"medium-grad", required_argument, NULL, GOPT_MEDIUM_GRAD}, RENDER_COMMON_LONG_OPTIONS

struct grad_common {
    const char *cmd;                 /* "grad", "fdcheck": prefixes messages */
    const char *scene_arg;
    const char **params;             /* the --param values, in order (argv strings) */
    int n_params;
    const char **sets;               /* the --set P=V,... values, in order */
    int n_sets;
    const struct dr_estimator_ops *estimator;
    enum dr_sampling sampling;       /* what runs (auto: resolved by grad_resolve_sampling) */
    bool sampling_auto;              /* --sampling auto, the default of grad, fdcheck and optimize */
    bool sampling_may_switch;        /* optimize: auto may pick derivative sampling at a later iteration */
    enum dr_medium_grad medium_grad;   /* --medium-grad: drt (default) or baseline */
    int spp, max_depth, rr_depth, width, height, camera, threads;
    bool res_given, camera_given, json;
    uint64_t seed;
    /* the film (core/film.h): --filter, and --crop X,Y,W,H of the frame
     * (width x height above stay the frame's size) */
    struct dr_filter filter;
    enum dr_sampler_kind sampler;    /* --sampler */
    bool sampler_given;
    bool crop_given;
    int crop_x, crop_y, crop_w, crop_h;
    double regularize;               /* prb attached: conditioning threshold (estimator.h) */
    /* lighting: --env (a file, or a colour) and --no-default-light */
    const char *env_file;            /* NULL: env_color * env_strength, if env_given */
    char *env_file_buf;              /* owned copy when --env FILE,STRENGTH was split */
    bool env_given, no_default_light;
    bool light_units_given;          /* --light-units: overrides the file's DR_units */
    enum dr_light_units light_units;
    struct dr_load_opts load;        /* --ignore-unsupported */
    dr_vec3 env_color;
    double env_strength;
};

/* The help line of --ignore-unsupported, shared by every command that loads a scene. */
#define GRAD_IGNORE_UNSUPPORTED_HELP                                                   \
    "      --ignore-unsupported  skip, with one warning, what drender cannot read but\n" \
    "                      would not change its image (KTX2 normal/occlusion maps)\n" \
    "                      instead of failing\n"

/* Defaults: prb, --sampling auto, the given spp, depth 8, Russian roulette from
 * DR_RR_DEPTH_DEFAULT, no --res. */
void grad_common_init(struct grad_common *g, const char *cmd, int spp);
void grad_common_free(struct grad_common *g);

/* Handles one shared option. Returns 0 when handled, DR_EXIT_USAGE after
 * printing a message, or -1 when `c` is not a shared option. */
int grad_common_option(struct grad_common *g, int c, const char *arg);

/* A command's own options: 0 when handled, an exit code after a message, or
 * -1 when `c` is not one of them. */
typedef int (*grad_own_option_fn)(void *ctx, int c, const char *arg);

/* The option loop every rendering command runs: getopt_long over argv with
 * the command's table; shared options go to g, the rest to `own`; -h prints
 * `usage`; the single positional argument is the scene. short_with_arg names
 * the short options that take a value ("o" or ""). Returns -1 to go on, or an
 * exit code. */
int grad_parse_args(struct grad_common *g, int argc, char **argv, const struct option *opts,
                    const char *short_with_arg, grad_own_option_fn own, void *ctx, void (*usage)(FILE *));

/* Reports a getopt_long failure ('?' or ':') the way every command does. */
int grad_getopt_error(const char *cmd, int c, char **argv, const char *short_with_arg);

/* Checks the options that need no scene (at least one --param). */
int grad_common_check(const struct grad_common *g);

/* Loads the scene (exit 3 on failure), checks --camera (exit 2) and picks the
 * camera. When !g->res_given, the size is taken from default_w/default_h if
 * positive, else as `render` does (512 high, width from the aspect ratio).
 * Returns -1 to go on, or an exit code; *scene must be destroyed by the caller. */
/* The lighting after loading: --env replaces the environment; a scene with
 * no light at all gets the default white environment (one note on stderr)
 * unless --no-default-light. -1 to go on, or an exit code. Called by
 * grad_load_scene; params calls it with a grad_common of its own. */
int grad_apply_lighting(const struct grad_common *g, const char *scene_path, struct dr_scene *scene);

/* The lighting options' help lines (--env, --no-default-light, --light-units),
 * printed by every command that renders, after its own options. */
void grad_lighting_usage(FILE *out);
/* "--camera N: SCENE has K cameras (...)": the cameras counted as --camera
 * counts them (node order), plus the file's cameras no node places. */
void grad_camera_error(const char *cmd, const char *what, int index, const char *scene_path,
                       const struct dr_scene *s);

int grad_load_scene(struct grad_common *g, char **scene_path, struct dr_scene **scene, struct dr_camera *cam,
                    int default_w, int default_h);

/* Applies every --set POINTER=V[,V...] to the scene (before parameters are
 * read), refreshing it. Returns -1 to go on or DR_EXIT_USAGE after a message
 * (unknown pointer with nearest names, wrong count, value out of range). */
int grad_apply_sets(const struct grad_common *g, struct dr_scene *scene);

/* Resolves the --param list (exit 2 with dr_last_error's nearest names). */
int grad_param_set(const struct grad_common *g, const struct dr_scene *scene, struct dr_param_set **set);

/* --sampling auto (the default of grad, fdcheck and optimize): derivative
 * sampling where a differentiated roughnessFactor is below the threshold
 * and the estimator and scene can take it, detached sampling elsewhere.
 * Derivative sampling because it stays unbiased at visibility edges, as
 * detached does (attached and mis do not), and below the thresholds it is
 * the better of the two. The thresholds are where it stops paying,
 * measured with `compare` (prb, reverse mode, 32x32, 16 spp x 64 batches,
 * depth 6, finite-difference reference; README: Which sampling mode), the
 * roughness derivative's efficiency against detached at roughness
 * 0.1 / 0.15 / 0.2 / 0.25 / 0.3:
 *  - a roughness alone (no base colour or metallic differentiated): the
 *    bundled box's gold sphere 4.6 / 2.8 / 1.65 / 1.2 / 0.9, the peer's box
 *    with its red wall a metal 3.4 / 1.7 / 0.7 / 0.9 / 0.8: below 0.2;
 *  - with a base colour or metallic factor (or base-colour texture)
 *    differentiated, derivative sampling draws directions for those too,
 *    which halves their efficiency (0.4-0.55 x at every roughness); the
 *    roughness gains 3.4 / 2.0 / 1.2 (box) and 2.5 / 1.2 / 0.5 (peer): below
 *    0.12, where the roughness, whose relative variance is hundreds of
 *    times the colour's, gains about twice what the colour loses.
 * A differentiated metallic-roughness texture counts with its texels' median
 * roughness (G x the factor; it moves metallic too, so the second
 * threshold), and so does a factor whose material has such a texture (the
 * factor times that median: the roughness the surface has). Every run
 * without a small roughness is what it was. */
#define GRAD_AUTO_ROUGHNESS 0.2
#define GRAD_AUTO_ROUGHNESS_WITH_COLOUR 0.12
/* A clear coat's roughness (its own antithetic pair, path_deriv.h), where no
 * base colour or metallic is differentiated (else the threshold above):
 * forward sampling gives the coat's lobe only c Fc(wo.z) of the samples, so
 * its derivative gains more. drender compare (prb, 64x64, 16 spp), derivative
 * over detached efficiency at coat roughness 0.1 / 0.2 / 0.3 / 0.4: 26.5 /
 * 8.35 / 3.15 / 2.88 on the peer box's red wall coated (Lambertian base),
 * 216 (at 0.05) / 4.8 / 2.3 / 0.91 on the bundled box's gold sphere (a
 * metal of roughness 0.5) under a coat of 0.8 (2026-12-07). */
#define GRAD_AUTO_COAT_ROUGHNESS 0.3
#define GRAD_STR_(x) #x
#define GRAD_STR(x) GRAD_STR_(x)

/* --sampling in grad's and fdcheck's --help, with the thresholds above. */
#define GRAD_SAMPLING_HELP                                                                           \
    "      --sampling S    auto (default), detached, attached, mis, derivative or\n"                \
    "                      derivative-roughness: attached differentiates through the\n"            \
    "                      sampling (for roughness), mis takes both from the same\n"               \
    "                      paths, weighted per parameter, derivative adds directions\n"            \
    "                      sampled for the BSDF derivative, combined by MIS, and\n"                \
    "                      derivative-roughness only those for the roughness; auto is\n"           \
    "                      derivative-roughness where a differentiated\n"                          \
    "                      roughnessFactor is below " GRAD_STR(GRAD_AUTO_ROUGHNESS) " ("             \
    GRAD_STR(GRAD_AUTO_ROUGHNESS_WITH_COLOUR) " beside a base colour or\n"                           \
    "                      metallic) or a clearcoatRoughnessFactor below "                           \
    GRAD_STR(GRAD_AUTO_COAT_ROUGHNESS) ",\n"                                                          \
    "                      else detached. See SAMPLING in the manual\n"

struct grad_auto_choice {
    enum dr_sampling sampling;      /* what auto runs */
    const struct dr_param *lowest;  /* the differentiated roughness (factor, metallic-roughness texture,
                                       or a clear coat's roughness factor) below the threshold with the
                                       lowest value (NULL: none) */
    double roughness;               /* ... its value (a texture: its median) */
    double lowest_threshold;        /* ... the threshold it is below (a coat's may differ) */
    bool texture;                   /* ... it is a metallic-roughness texture (an image parameter) */
    double threshold;               /* GRAD_AUTO_ROUGHNESS, or ..._WITH_COLOUR when a base colour or
                                       metallic is differentiated */
    int narrow;                     /* how many are below the threshold */
    bool derivative_possible;       /* a roughness is differentiated and derivative sampling can run */
    char why[512];                  /* a roughness is differentiated but derivative sampling cannot run:
                                       the reason */
};
/* Auto's choice for estimator e on the scene's current values. */
struct grad_auto_choice grad_auto_sampling(const struct dr_estimator_ops *e, const struct dr_scene *scene,
                                           const struct dr_param_set *set);
/* "/materials/gold/.../roughnessFactor is 0.05 (and 1 more), below 0.2" (a
 * texture: "the roughness in /images/1 has median 0.06, below 0.12 (with a
 * base colour or metallic differentiated)"); "" without a small roughness.
 * The notes' and compare's report's words. */
void grad_auto_describe(const struct dr_scene *scene, const struct grad_auto_choice *c, char *buf, size_t size);

/* Under --sampling auto, sets g->sampling to auto's choice for the scene's
 * current values and says on stderr when that is not detached sampling, or
 * when a small roughness is left to detached sampling because derivative
 * sampling cannot run there (the reason). Given modes are left alone. */
void grad_resolve_sampling(struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *set);
/* The note for a choice (also optimize's, when auto changes its mind between
 * iterations: iteration > 0 names it). */
void grad_auto_note(const struct grad_common *g, const struct dr_scene *scene, const struct grad_auto_choice *c,
                    int iteration);

/* Reads a target image (--target): the first 3 channels (grey replicated) as
 * linear float rgb (8-bit sRGB files decoded); NaN/Inf pixels refused.
 * img keeps the file's size (release it). Returns -1 to go on or an exit code. */
int grad_load_target(const char *cmd, const char *path, struct dr_image *img, float **rgb);

/* --primal cross|separate (reverse.h's DR_PRIMAL_CROSS / DR_PRIMAL_PER_BATCH):
 * 0, or DR_EXIT_USAGE with the message printed. */
int grad_parse_primal(const char *cmd, const char *arg, enum dr_primal_mode *mode);
/* Its name, for --json and messages. */
const char *grad_primal_name(enum dr_primal_mode mode);
/* grad's and optimize's sampler where --sampler is not given: sobol, but
 * independent numbers where a reverse-mode batch renders a primal of its own
 * (--primal separate, or batches of one sample: spp over `batches`). */
void grad_default_sampler(struct grad_common *g, bool reverse, enum dr_primal_mode primal, int batches);

/* ---- the film: --filter and --crop ----
 * The film of a w x h frame under the options: the filter, and with --crop
 * the rectangle; *rw x *rh is the size of what is rendered (the crop's, else
 * the frame's). */
struct dr_film grad_film(const struct grad_common *g, int w, int h, int *rw, int *rh);
/* Checks that --crop lies inside a frame_w x frame_h frame (the message names
 * --crop and the frame). Returns -1 to go on or DR_EXIT_USAGE. */
int grad_check_crop(const struct grad_common *g, int frame_w, int frame_h);
/* An image to compare with the rendered rectangle (a --target; `compare`
 * can use it for its images too): tw x th rgb that is either the crop's size
 * (kept) or the frame's (the crop's rectangle cut out into a new buffer,
 * *rgb replaced and the old one freed). Without --crop it must be the
 * frame's size. Returns -1 to go on or DR_EXIT_USAGE after a message naming
 * `what` (e.g. "--target t.exr"). */
int grad_crop_image(const struct grad_common *g, const char *what, float **rgb, int tw, int th, int frame_w,
                    int frame_h);
/* JSON: `"filter": "box", "crop": [x, y, w, h] or null` (no braces). */
void grad_json_film(FILE *f, const struct grad_common *g);

/* The estimator problem / render options the shared options describe, for a
 * frame of w x h (the rendered rectangle follows --crop, the filter
 * --filter) at spp samples per pixel with this seed. */
struct dr_grad_problem grad_problem(const struct grad_common *g, const struct dr_scene *scene,
                                    const struct dr_camera *cam, const struct dr_param_set *ps, int w, int h, int spp,
                                    uint64_t seed);
struct dr_render_opts grad_render_opts(const struct grad_common *g, int w, int h, int spp, uint64_t seed,
                                       bool progress);

/* What several estimator runs did, summed (time, rays, dropped samples) or
 * maximised (memory), for the summaries. */
struct grad_totals {
    double seconds;
    struct dr_ray_counts rays;
    uint64_t invalid, memory_bytes, record_bytes;
    unsigned stages;
    int threads;
    unsigned sampling_runs; /* 1 << the sampling mode each run ran (dr_est_sampling_run: attached,
                               mis and derivative sampling without a parameter they act on run
                               detached) */
    struct dr_medium_gain_choice media_gain[DR_STATS_MEDIA_GAIN];   /* (every run's: the same) */
    int n_media_gain;
};
void grad_totals_add(struct grad_totals *t, const struct dr_grad_stats *st);
void grad_totals_add_render(struct grad_totals *t, const struct dr_render_stats *rs);
/* Prints the dropped-samples warning when some were dropped. */
void grad_totals_warn(const char *cmd, const struct grad_totals *t);

/* JSON: `"command": ..., "scene": ..., "estimator": ..., "sampling": ...,
 * "width": ..., "height": ..., "spp": ..., "max_depth": ..., "rr_depth": ...,
 * "seed": ...` (no braces), the start of every gradient command's summary. */
void grad_json_head(FILE *f, const struct grad_common *g, const char *scene_path);
/* JSON: `"threads", "estimator_memory_bytes", "record_bytes", "peak_memory_bytes",
 * "rays", "invalid_samples", "stages", "sampling_effective"`, and
 * "medium_gain" where DRT differentiated a medium's sigma_t (no braces). */
void grad_json_run(FILE *f, const struct grad_totals *t);
/* JSON: `, "medium_gain": [{"medium", "source", "reason"[, "voxels_source"]
 * [, "pilot_stretches", "pilot_collided"]}, ...]`, the n choices c (medium_grad.h); nothing if n is 0. */
void grad_json_media_gain(FILE *f, const struct dr_medium_gain_choice *c, int n);

/* JSON, with --sampling mis only: `, "mis_weight": {"detached": w, "attached": 1 - w}`
 * (w: the weight of the detached estimate, estimators/mis.h). */
void grad_json_mis_weight(FILE *f, const struct grad_common *g, double w_detached);

/* Names of the effects a parameter set differentiates, comma separated. */
void grad_effects_differentiated(const struct dr_param_set *set, char *buf, size_t size);
/* The same as a JSON array. */
void grad_json_effects(FILE *f, const struct dr_param_set *set);

#endif
