/* libFuzzer target: the optimize checkpoint reader, dr_checkpoint_read
 * (core/optimizer.c), against a parameter set of tests/data/gltf/basic.gltf
 * with a colour, a scalar, a light intensity and a 2x2 texture (/images/1).
 *
 * With DR_FUZZ_WRITE_SEED=FILE in the environment it instead writes a valid
 * checkpoint of that parameter set to FILE and exits: how the seeds in
 * fuzz/corpus/checkpoint were made. */
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>

#include "fuzz_common.h"
#include "optimizer.h"
#include "params.h"
#include "scene.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static struct dr_scene *scene;
static struct dr_param_set *ps;
static struct dr_adam *adam;
static double *theta;

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_setup();
    scene = dr_scene_load(DR_FUZZ_DATA "/gltf/basic.gltf");
    static const char *const names[] = {
        "/materials/0/pbrMetallicRoughness/baseColorFactor",
        "/materials/0/pbrMetallicRoughness/roughnessFactor",
        "/extensions/KHR_lights_punctual/lights/0/intensity",
        "/images/1",
    };
    ps = scene ? dr_param_set_create(scene, names, 4) : NULL;
    theta = ps ? calloc((size_t)ps->total, sizeof(double)) : NULL;
    if (!theta) {
        fprintf(stderr, "fuzz_checkpoint: cannot set up: %s\n", dr_last_error());
        abort();
    }
    dr_param_set_get(scene, ps, theta);
    adam = dr_adam_create(ps, theta, 0.0);
    if (!adam)
        abort();
    const char *seed = getenv("DR_FUZZ_WRITE_SEED");
    if (seed) {
        for (int64_t i = 0; i < ps->total; i++) {
            adam->m[i] = 0.001 * (double)(i + 1);
            adam->v[i] = 1e-7 * (double)(i + 1);
        }
        adam->t = 7;
        int rc = dr_checkpoint_write(seed, "scene.gltf", ps, theta, adam, 7);
        exit(rc == 0 ? 0 : 1);
    }
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write("checkpoint.txt", data, size);
    int64_t it = -1;
    if (dr_checkpoint_read(path, ps, theta, adam, &it) != 0)
        return 0;
    /* An accepted checkpoint must be a state the optimizer can continue from
     * (optimize indexes its history by iteration and takes sqrt of v). */
    bool ok = it >= 0 && adam->t >= 0 && adam->beta1 >= 0.0 && adam->beta1 < 1.0 && adam->beta2 >= 0.0 &&
              adam->beta2 < 1.0 && adam->eps > 0.0 && isfinite(adam->eps);
    for (int64_t i = 0; ok && i < ps->total; i++) {
        const int k = dr_adam_param_of(adam, i);
        ok = k >= 0 && isfinite(theta[i]) && theta[i] >= adam->lo[k] && theta[i] <= adam->hi[k] &&
             isfinite(adam->m[i]) && isfinite(adam->v[i]) && adam->v[i] >= 0.0;
    }
    if (!ok) {
        fprintf(stderr, "fuzz_checkpoint: accepted an impossible state (iteration %lld)\n", (long long)it);
        abort();
    }
    return 0;
}
