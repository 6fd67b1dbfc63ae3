/* Gradients accumulated over 10^8 samples keep their precision. The camera
 * sees only an emitter (max depth 1), so every sample's derivative of the
 * image mean with respect to the emissive factor's red channel is exactly
 * 1 / (3 N spp): the reverse-mode result must be 1/3 to ~1e-12 relative
 * (naive float accumulation would be off by percent; a single double running
 * sum by ~1e-9). */
#include <stdlib.h>

#include "error.h"
#include "estimator.h"
#include "scene_builder.h"
#include "test.h"

int main(int argc, char **argv)
{
    /* 100 x 100 pixels x 10^4 samples = 10^8 (argv[1] scales spp down for quick runs) */
    int spp = argc > 1 ? atoi(argv[1]) : 10000;
    struct sb b;
    sb_init(&b);
    struct dr_material m = sb_diffuse(dr_v3s(0.0));
    m.emissive_factor = dr_v3(0.3, 0.2, 0.1);
    sb_quad(&b, dr_v3(-50, -50, -1), dr_v3(100, 0, 0), dr_v3(0, 100, 0), sb_material(&b, m));
    struct dr_scene *s = sb_finish(&b);
    s->n_file_materials = s->n_materials;
    struct dr_camera cam = sb_camera(dr_v3(0, 0, 0), dr_v3(0, 0, -1), 30);
    const char *ptr = "/materials/0/emissiveFactor";
    struct dr_param_set *ps = dr_param_set_create(s, &ptr, 1);
    CHECK(ps != NULL, "%s", dr_last_error());
    const int W = 100, H = 100;
    float *adj = malloc(sizeof(float) * 3 * W * H);
    for (int i = 0; i < 3 * W * H; i++)
        adj[i] = (float)(1.0 / (3.0 * W * H));
    double exact = (double)adj[0] * W * H;   /* the float adjoint's own value, summed */
    struct dr_grad_problem p = {.scene = s, .camera = &cam, .params = ps, .width = W, .height = H, .spp = spp,
                                .max_depth = 1, .rr_depth = DR_RR_DEPTH_DEFAULT, .seed = 3, .threads = 2};
    double g[3];
    struct dr_grad_stats st;
    CHECK(dr_estimator_backward(dr_estimator_find("prb"), &p, adj, g, &st) == 0, "%s", dr_last_error());
    printf("%lld samples: gradient %.17g, exact %.17g, relative error %.3g (%.1f s)\n", (long long)W * H * spp, g[0],
           exact, fabs(g[0] - exact) / exact, st.seconds);
    CHECK(fabs(g[0] - exact) <= 1e-12 * exact, "gradient %.17g vs %.17g", g[0], exact);
    CHECK(fabs(g[1] - exact) <= 1e-12 * exact && fabs(g[2] - exact) <= 1e-12 * exact, "green/blue %.17g %.17g", g[1],
          g[2]);
    free(adj);
    dr_param_set_destroy(ps);
    dr_scene_destroy(s);
    return TEST_END();
}
