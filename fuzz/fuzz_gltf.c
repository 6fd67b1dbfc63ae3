/* libFuzzer target: the glTF/GLB loader (core/gltf_load.cpp through
 * dr_gltf_load), then what dr_scene_prepare does with its result except the
 * Embree build (mesh derivation, effect flags, light sampling tables) and
 * the parameter listing of `drender params`.
 *
 * The input is written to a scratch file (the loader reads by path; a GLB is
 * recognised by its magic). The scratch directory also holds the external
 * files the seeds of fuzz/corpus/gltf reference: basic.bin, checker.png,
 * mr.png, sky.hdr. */
#include <stdlib.h>

#include "fuzz_common.h"
#include "geometry.h"
#include "params.h"
#include "scene.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_setup();
    fuzz_copy_aux("gltf/basic.bin", "basic.bin");
    fuzz_copy_aux("gltf/checker.png", "checker.png");
    fuzz_copy_aux("gltf/mr.png", "mr.png");
    fuzz_copy_aux("gltf/sky.hdr", "sky.hdr");
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write("scene.gltf", data, size);
    struct dr_scene *s = calloc(1, sizeof *s);
    if (!s)
        return 0;
    s->path = strdup(path);
    if (s->path && dr_gltf_load(path, s) == 0 && dr_mesh_derive(&s->mesh) == 0 && dr_scene_refresh(s) == 0) {
        struct dr_param *params = NULL;
        int n = 0;
        if (dr_params_list(s, &params, &n) == 0) {
            double v[4];
            for (int i = 0; i < n; i++)
                if (params[i].size <= 4)
                    dr_param_get(s, &params[i], v);
        }
        free(params);
    }
    dr_scene_destroy(s);
    return 0;
}
