/* Gradients against finite differences (statistical: both sides carry a
 * standard error from independent batches, the verdict is a z-score), on the
 * cases a user relies on and on the hard ones. Each case builds a small scene
 * in code, runs dr_fdcheck with both estimators and requires agreement and
 * finite values. */
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "estimator.h"
#include "fdcheck.h"
#include "scene_builder.h"
#include "test.h"

struct fd_case {
    const char *name;
    int spp, batches, max_depth, res;
    double eps;
};

static void run_case(const struct fd_case *c, struct dr_scene *s, struct dr_camera cam, const char *const *ptrs,
                     int n)
{
    s->n_file_materials = s->n_materials;
    struct dr_param_set *ps = dr_param_set_create(s, ptrs, n);
    CHECK(ps != NULL, "%s: %s", c->name, dr_last_error());
    if (!ps)
        return;
    for (int e = 0; dr_estimators[e]; e++) {
        struct dr_fd_options o = {dr_estimators[e], c->res, c->res, c->spp, c->batches, c->max_depth, 5,
                                  1234, 2, c->eps, 4.0};
        struct dr_fd_entry *en = NULL;
        int count = 0;
        int rc = dr_fdcheck(s, &cam, ps, &o, &en, &count);
        CHECK(rc == 0, "%s: fdcheck failed: %s", c->name, dr_last_error());
        for (int i = 0; i < count; i++) {
            printf("%-12s %-5s %-70s rev %.5g +- %.2g  fwd %.5g +- %.2g  fd %.5g +- %.2g  z %.2f %.2f\n", c->name,
                   dr_estimators[e]->name, en[i].label, en[i].reverse, en[i].reverse_se, en[i].forward,
                   en[i].forward_se, en[i].fd, en[i].fd_se, en[i].z_reverse, en[i].z_forward);
            CHECK(isfinite(en[i].reverse) && isfinite(en[i].forward) && isfinite(en[i].fd), "%s: %s not finite",
                  c->name, en[i].label);
            CHECK(en[i].agree, "%s (%s): %s: gradient %.6g/%.6g vs finite differences %.6g (z %.2f, %.2f)", c->name,
                  dr_estimators[e]->name, en[i].label, en[i].reverse, en[i].forward, en[i].fd, en[i].z_reverse,
                  en[i].z_forward);
            /* a check that cannot fail is no check: the derivative must be resolved */
            CHECK(fabs(en[i].fd) > 3.0 * en[i].fd_se || fabs(en[i].reverse) < 1e-12,
                  "%s: %s: finite differences too noisy to judge (%.3g +- %.3g)", c->name, en[i].label, en[i].fd,
                  en[i].fd_se);
        }
        free(en);
    }
    dr_param_set_destroy(ps);
}

static void diffuse_plane_env(void)
{
    struct sb b;
    sb_init(&b);
    sb_quad(&b, dr_v3(-100, 0, 100), dr_v3(200, 0, 0), dr_v3(0, 0, -200), sb_material(&b, sb_diffuse(dr_v3(0.6, 0.5, 0.4))));
    sb_environment(&b, dr_v3(0.8, 1.0, 1.2));
    struct dr_scene *s = sb_finish(&b);
    const char *p[] = {"/materials/0/pbrMetallicRoughness/baseColorFactor", "/extensions/DR_environment/color",
                       "/extensions/DR_environment/strength"};
    struct fd_case c = {"plane-env", 4, 8, 4, 16, 1e-2};
    run_case(&c, s, sb_camera(dr_v3(0, 1, 0.5), dr_v3(0, 0, 0), 40), p, 3);
    dr_scene_destroy(s);
}

int main(void)
{
    diffuse_plane_env();
    return TEST_END();
}
