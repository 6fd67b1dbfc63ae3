/* libFuzzer target: the option-value parsers of the command line.
 *
 * Input: one selector byte, then the text (cut at the first NUL; '\n'
 * separates several values where a parser takes a list). Selector % 9:
 *   0 cli_parse_int (--spp's range)   1 cli_parse_u64 (--seed)
 *   2 cli_parse_double (--lr, --eps)  3 cli_parse_res (--res)
 *   4 grad_common_option: the next byte picks the option (--spp, --max-depth,
 *     --res, --camera, --seed, --threads, --estimator, --sampling, ...)
 *   5 --param P...: dr_param_set_create on tests/data/gltf/basic.gltf
 *   6 --set P=V,...: grad_apply_sets on the same scene
 *   7 dr_loss_parse and dr_param_resolve of one pointer
 *   8 cli_parse_bytes (DRENDER_MEM_LIMIT)
 * The messages go to stderr (run with -close_fd_mask=2 to hide them). */
#include <math.h>
#include <stdlib.h>

#include "../cli/cli.h"
#include "fuzz_common.h"
#include "../cli/grad_common.h"
#include "../cli/mem_limits.h"
#include "loss.h"
#include "params.h"
#include "scene.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static struct dr_scene *scene;

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_setup();
    scene = dr_scene_load(DR_FUZZ_DATA "/gltf/basic.gltf");
    if (!scene) {
        fprintf(stderr, "fuzz_cli: %s\n", dr_last_error());
        abort();
    }
    return 0;
}

/* Splits text at '\n' into at most max pieces (in place). */
static int split_lines(char *text, const char **out, int max)
{
    int n = 0;
    char *save = NULL;
    for (char *tok = strtok_r(text, "\n", &save); tok && n < max; tok = strtok_r(NULL, "\n", &save))
        out[n++] = tok;
    return n;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1 || size > 4096)
        return 0;
    const int sel = data[0] % 9;
    char *text = malloc(size);
    if (!text)
        return 0;
    memcpy(text, data + 1, size - 1);
    text[size - 1] = '\0';
    long l;
    uint64_t u;
    double d;
    int w, h;
    switch (sel) {
    case 0:
        if (cli_parse_int("fuzz", "--spp", text, 1, 1L << 30, &l) && (l < 1 || l > (1L << 30)))
            abort();
        break;
    case 1: cli_parse_u64("fuzz", "--seed", text, &u); break;
    case 2:
        if (cli_parse_double("fuzz", "--lr", text, 0.0, &d) && !(d > 0.0 && isfinite(d)))
            abort();
        break;
    case 3:
        if (cli_parse_res("fuzz", "--res", text, &w, &h) && (w < 1 || h < 1 || w > 32768 || h > 32768))
            abort();
        break;
    case 4: {
        struct grad_common g;
        grad_common_init(&g, "fuzz", 8);
        int opt = text[0] ? GOPT_PARAM + (unsigned char)text[0] % (GOPT_END - GOPT_PARAM) : GOPT_SPP;
        const char *arg = text[0] ? text + 1 : text;
        /* after a refused value the command exits: only accepted values must leave a sane state */
        if (grad_common_option(&g, opt, arg) == 0 &&
            (g.spp < 1 || g.max_depth < 1 || g.width < 0 || g.height < 0 || g.camera < 0 || g.threads < 0 ||
             !g.estimator))
            abort();
        grad_common_free(&g);
        break;
    }
    case 5: {
        const char *ptrs[8];
        int n = split_lines(text, ptrs, 8);
        struct dr_param_set *ps = dr_param_set_create(scene, ptrs, n);
        if (ps) {
            double *v = malloc(sizeof(double) * (size_t)(ps->total + 1));
            if (v) {
                dr_param_set_get(scene, ps, v);
                dr_param_set_put(scene, ps, v);
            }
            free(v);
        }
        dr_param_set_destroy(ps);
        break;
    }
    case 6: {
        const char *sets[8];
        struct grad_common g;
        grad_common_init(&g, "fuzz", 8);
        g.n_sets = split_lines(text, sets, 8);
        g.sets = sets;
        grad_apply_sets(&g, scene);
        break;
    }
    case 7: {
        struct dr_param p;
        dr_loss_parse(text);
        if (dr_param_resolve(scene, text, &p) == 0 && (p.size < 1 || p.name[0] != '/'))
            abort();
        break;
    }
    case 8:
        if (cli_parse_bytes(text, &u) && u == 0)
            abort();
        break;
    }
    free(text);
    return 0;
}
