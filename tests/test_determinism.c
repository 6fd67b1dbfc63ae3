/* The same seed gives a bit-identical image whatever the thread count (every
 * random number is a function of seed, pixel, sample and dimension), and a
 * different seed gives a different one. Uses the bundled Cornell box, which
 * exercises every code path (area light, textures, metal, shading normals). */
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "error.h"
#include "render.h"
#include "scene.h"
#include "test.h"

static float *render(const struct dr_scene *s, int threads, uint64_t seed)
{
    const int w = 48, h = 40;
    float *rgb = malloc(sizeof(float) * 3 * w * h);
    struct dr_render_opts o = {.width = w, .height = h, .spp = 4, .max_depth = 12, .rr_depth = DR_RR_DEPTH_DEFAULT,
                              .seed = seed, .threads = threads};
    struct dr_render_stats st;
    CHECK(dr_render(s, &s->cameras[0], &o, rgb, &st) == 0, "render: %s", dr_last_error());
    CHECK(st.threads == threads, "ran on %d threads, asked %d", st.threads, threads);
    return rgb;
}

int main(void)
{
    const char *path = scene_path("cornell-box.gltf");
    struct dr_scene *s = dr_scene_load(path);
    CHECK(s != NULL, "load %s: %s", path, dr_last_error());
    if (!s)
        return TEST_END();
    size_t bytes = sizeof(float) * 3 * 48 * 40;
    float *a = render(s, 1, 42), *b = render(s, 2, 42), *c = render(s, 3, 42), *d = render(s, 2, 43);
    CHECK(memcmp(a, b, bytes) == 0, "1 and 2 threads differ");
    CHECK(memcmp(a, c, bytes) == 0, "1 and 3 threads differ");
    CHECK(memcmp(a, d, bytes) != 0, "seeds 42 and 43 give the same image");
    double sum = 0;
    for (size_t i = 0; i < 3 * 48 * 40; i++)
        sum += a[i];
    CHECK(sum > 0.0 && isfinite(sum), "image is black or not finite (sum %g)", sum);
    free(a);
    free(b);
    free(c);
    free(d);
    dr_scene_destroy(s);
    return TEST_END();
}
