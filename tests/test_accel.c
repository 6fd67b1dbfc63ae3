/* Ray queries: the unfiltered fast path and the packet queries against the
 * filtered one-ray queries, on a scene of single-sided, double-sided, MASK
 * and BLEND surfaces crossed by random rays from everywhere (so back faces,
 * holes and stochastic layers are hit often). */
#include <string.h>

#include "accel.h"
#include "coverage.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

/* A w x 1 RGBA texture whose alpha alternates 0 and 1 (holes for MASK). */
static int striped_texture(struct sb *b, int w)
{
    float *px = calloc((size_t)4 * (size_t)w, sizeof(float));
    for (int i = 0; i < w; i++) {
        px[4 * i] = px[4 * i + 1] = px[4 * i + 2] = 0.5f;
        px[4 * i + 3] = (float)(i & 1);
    }
    struct dr_image im = sb_image(w, 1, 4, px, 0.0f, false);
    free(px);
    return sb_texture(b, im);
}

/* Boxes and quads of every coverage kind inside [-2, 2]^3. */
static struct dr_scene *mixed_scene(void)
{
    struct sb b;
    sb_init(&b);
    struct dr_material one = sb_diffuse(dr_v3s(0.5)), two = one, mask = one, blend = one;
    two.double_sided = true;
    mask.double_sided = true;
    mask.alpha_mode = DR_ALPHA_MASK;
    mask.base_color_tex.texture = striped_texture(&b, 7);
    blend.alpha_mode = DR_ALPHA_BLEND;
    blend.alpha = 0.4;
    int m1 = sb_material(&b, one), m2 = sb_material(&b, two), mm = sb_material(&b, mask), mb = sb_material(&b, blend);
    sb_box(&b, dr_v3(-1.5, -1.5, -1.5), dr_v3(-0.5, -0.2, -0.4), m1);
    sb_box(&b, dr_v3(0.3, -1.0, 0.2), dr_v3(1.4, 0.1, 1.3), m2);
    sb_open_box(&b, 1.8, m1);   /* fronts inside: seen from outside, back faces */
    sb_quad(&b, dr_v3(-1.8, 0.5, -1.8), dr_v3(3.6, 0, 0), dr_v3(0, 0, 3.6), mm);
    sb_quad(&b, dr_v3(-1.2, 1.2, 1.5), dr_v3(2.4, 0, 0), dr_v3(0, -2.4, 0), mb);
    sb_quad(&b, dr_v3(1.6, -1.6, -1.6), dr_v3(0, 3.2, 0), dr_v3(0, 0, 3.2), m1);
    struct dr_scene *s = sb_finish(&b);
    for (int i = 0; i < s->n_images; i++)
        dr_image_make_linear(&s->images[i]);
    return s;
}

static double u01(uint64_t *k)
{
    *k = dr_hash64(*k);
    return (double)(*k >> 11) * 0x1p-53;
}

static dr_vec3 random_dir(uint64_t *k)
{
    for (;;) {
        double x = 2 * u01(k) - 1, y = 2 * u01(k) - 1, z = 2 * u01(k) - 1;
        dr_vec3 d = dr_v3(x, y, z);
        double l = dr_length(d);
        if (l > 0.1 && l <= 1.0)
            return dr_scale(d, 1.0 / l);
    }
}

#define RAYS 64

/* Fills the stack below the caller with NaN, so a packet lane the queries
 * leave unset is garbage, as in a real renderer (Embree checks every lane of
 * a half-packet it traces on machines without AVX-512). */
static void __attribute__((noinline)) poison_stack(void)
{
    volatile float junk[8192];
    for (int i = 0; i < 8192; i++)
        junk[i] = NAN;
    (void)junk[0];
}

static void test_fast_path_matches_filters(const char *embree_config)
{
    if (embree_config)
        setenv("DRENDER_EMBREE_CONFIG", embree_config, 1);
    else
        unsetenv("DRENDER_EMBREE_CONFIG");
    fprintf(stderr, "Embree configuration: %s\n", embree_config ? embree_config : "(default)");
    struct dr_scene *s = mixed_scene();
    CHECK((s->effects & DR_FX_SINGLE_SIDED) && (s->effects & DR_FX_ALPHA_MASK) && (s->effects & DR_FX_ALPHA_BLEND),
          "the scene has every coverage kind");
    struct dr_accel *ref = dr_accel_create_scene_filtered(s);
    struct dr_accel *bare = dr_accel_create(&s->mesh);   /* no coverage at all: the nearest triangle */
    CHECK(ref != NULL && bare != NULL, "reference accels: %s", dr_last_error());
    if (!ref || !bare)
        return;
    uint64_t k = 12345;
    long hits = 0, passed_over = 0, occl = 0, bad_hit = 0, bad_occl = 0, bad_many = 0, bad_many_occl = 0;
    long bad_coherent = 0, bad_arrays = 0, total = 0;
    for (int round = 0; round < 1500; round++) {
        dr_vec3 o[RAYS], d[RAYS];
        double tmax[RAYS];
        uint64_t key[RAYS];
        int64_t tri_one[RAYS], tri_many[RAYS];
        bool occ_one[RAYS], occ_many[RAYS];
        int n = 1 + (int)(u01(&k) * RAYS);   /* partial packets too */
        for (int i = 0; i < n; i++) {
            o[i] = dr_scale(random_dir(&k), 3.5 * u01(&k));
            d[i] = random_dir(&k);
            tmax[i] = u01(&k) < 0.3 ? INFINITY : 4.0 * u01(&k);
            key[i] = k = dr_hash64(k);
            int64_t want = dr_accel_intersect_key(ref, o[i], d[i], 0.0, tmax[i], key[i]);
            tri_one[i] = dr_accel_intersect_key(s->accel, o[i], d[i], 0.0, tmax[i], key[i]);
            bool want_occ = dr_accel_occluded_key(ref, o[i], d[i], 0.0, tmax[i], key[i]);
            occ_one[i] = dr_accel_occluded_key(s->accel, o[i], d[i], 0.0, tmax[i], key[i]);
            /* how often the nearest triangle is one the filters pass over (the fast path's fallback) */
            passed_over += dr_accel_intersect(bare, o[i], d[i], 0.0, tmax[i]) != want;
            hits += want >= 0;
            occl += want_occ;
            bad_hit += tri_one[i] != want;
            bad_occl += occ_one[i] != want_occ;
            total++;
        }
        struct dr_accel_rays r = {.n = n, .o = o, .d = d, .tmax = tmax, .key = key};
        poison_stack();
        dr_accel_intersect_many(s->accel, &r, tri_many);
        poison_stack();
        dr_accel_occluded_many(s->accel, &r, occ_many);
        for (int i = 0; i < n; i++) {
            bad_many += tri_many[i] != tri_one[i];
            bad_many_occl += occ_many[i] != occ_one[i];
        }
        /* the same packets traced with Embree's coherent flag (the wavefront
         * marks its camera rays so; these rays are not alike, which only
         * makes them slower): the same answers */
        r.coherent = round % 2 ? n : n / 2;
        poison_stack();
        dr_accel_intersect_many(s->accel, &r, tri_many);
        for (int i = 0; i < n; i++)
            bad_coherent += tri_many[i] != tri_one[i];
        /* the same rays given by coordinate (wave_soa.c's layout): the same answers */
        double c[6][RAYS];
        for (int i = 0; i < n; i++) {
            c[0][i] = o[i].x, c[1][i] = o[i].y, c[2][i] = o[i].z;
            c[3][i] = d[i].x, c[4][i] = d[i].y, c[5][i] = d[i].z;
        }
        struct dr_accel_rays a = {.n = n, .ox = c[0], .oy = c[1], .oz = c[2], .dx = c[3], .dy = c[4], .dz = c[5],
                                  .tmax = tmax, .key = key};
        poison_stack();
        dr_accel_intersect_many(s->accel, &a, tri_many);
        poison_stack();
        dr_accel_occluded_many(s->accel, &a, occ_many);
        for (int i = 0; i < n; i++)
            bad_arrays += tri_many[i] != tri_one[i] || occ_many[i] != occ_one[i];
    }
    fprintf(stderr, "%ld rays: %ld hits, %ld occluded, %ld nearest triangles passed over\n", total, hits, occl,
            passed_over);
    CHECK(hits > total / 4 && occl > total / 5 && occl < total - total / 5, "the rays test something (%ld, %ld)",
          hits, occl);
    CHECK(passed_over > total / 10, "the filters' fallback is exercised (%ld of %ld)", passed_over, total);
    CHECK(bad_hit == 0, "closest hit: %ld of %ld differ from the filtered query", bad_hit, total);
    CHECK(bad_occl == 0, "occlusion: %ld of %ld differ from the filtered query", bad_occl, total);
    CHECK(bad_many == 0, "packets: %ld of %ld closest hits differ from one-ray queries", bad_many, total);
    CHECK(bad_many_occl == 0, "packets: %ld of %ld occlusions differ from one-ray queries", bad_many_occl, total);
    CHECK(bad_coherent == 0, "coherent packets: %ld of %ld closest hits differ from one-ray queries", bad_coherent,
          total);
    CHECK(bad_arrays == 0, "rays by coordinate: %ld of %ld answers differ from one-ray queries", bad_arrays, total);
    dr_accel_destroy(ref);
    dr_accel_destroy(bare);
    dr_scene_destroy(s);
}

int main(void)
{
    /* the machine's own kernels (16-wide packets on AVX-512), and the 8- and
     * 4-wide halves other machines trace 16-wide packets with */
    test_fast_path_matches_filters(NULL);
    test_fast_path_matches_filters("isa=avx2");
    test_fast_path_matches_filters("isa=sse4.2");
    return TEST_END();
}
