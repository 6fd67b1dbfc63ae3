/* Single-sided backs no ray can reach (core/backface.c): which triangles the
 * room and closed-surface tests mark, which they must not (a viewpoint
 * behind, holes, an open or inconsistently wound surface, an orthographic
 * camera), cameras admitted or refused, and that dropping the culling test
 * where it is proved unnecessary changes no answer: the same image as with
 * every test kept, and the same hits as the fully filtered structure for
 * rays from the camera and from surface points. */
#include <math.h>
#include <string.h>

#include "accel.h"
#include "backface.h"
#include "geometry.h"
#include "render.h"
#include "sampler.h"
#include "scene_builder.h"
#include "test.h"

/* The scene's own camera, as a file's would be (the analysis is made for
 * it, not for drender's default view). */
static void scene_camera(struct dr_scene *s, struct dr_camera c)
{
    s->cameras = malloc(sizeof c);
    s->cameras[0] = c;
    s->n_cameras = 1;
}

static int count_marked(const struct dr_scene *s, uint32_t first, uint32_t n)
{
    const uint8_t *m = dr_backface_marks(s->backface);
    int c = 0;
    for (uint32_t t = first; t < first + n; t++)
        c += m && m[t];
    return c;
}

/* A Cornell-like room: floor, ceiling, back and side walls facing in (10
 * triangles, 0..9), a closed box on the floor (12, 10..21), a light quad
 * just under the ceiling facing down (2, 22..23); the camera outside the
 * open front. */
static struct dr_scene *room_scene(struct dr_camera *cam, int box_material_alpha)
{
    struct sb b;
    sb_init(&b);
    int white = sb_material(&b, sb_diffuse(dr_v3s(0.7)));
    struct dr_material bm = sb_diffuse(dr_v3s(0.6));
    if (box_material_alpha) {
        bm.alpha_mode = DR_ALPHA_MASK;
        bm.alpha = 1.0;
    }
    int boxm = sb_material(&b, bm);
    struct dr_material lm = sb_diffuse(dr_v3s(0.0));
    lm.emissive_factor = dr_v3s(10.0);
    int light = sb_material(&b, lm);
    sb_quad(&b, dr_v3(-1, -1, -1), dr_v3(0, 0, 2), dr_v3(2, 0, 0), white);   /* floor, +y */
    sb_quad(&b, dr_v3(-1, 1, -1), dr_v3(2, 0, 0), dr_v3(0, 0, 2), white);    /* ceiling, -y */
    sb_quad(&b, dr_v3(-1, -1, -1), dr_v3(2, 0, 0), dr_v3(0, 2, 0), white);   /* back, +z */
    sb_quad(&b, dr_v3(-1, -1, -1), dr_v3(0, 2, 0), dr_v3(0, 0, 2), white);   /* left, +x */
    sb_quad(&b, dr_v3(1, -1, -1), dr_v3(0, 0, 2), dr_v3(0, 2, 0), white);    /* right, -x */
    sb_box(&b, dr_v3(-0.5, -1, -0.5), dr_v3(0.1, 0.2, 0.1), boxm);
    sb_quad(&b, dr_v3(-0.25, 0.99, -0.25), dr_v3(0.5, 0, 0), dr_v3(0, 0, 0.5), light);   /* -y */
    *cam = sb_camera(dr_v3(0, 0, 3.9), dr_v3(0, 0, 0), 40);
    scene_camera(b.s, *cam);
    return sb_finish(&b);
}

static void test_room(void)
{
    struct dr_camera cam;
    struct dr_scene *s = room_scene(&cam, 0);
    CHECK(count_marked(s, 0, 10) == 10, "the room's walls: %d of 10 marked", count_marked(s, 0, 10));
    CHECK(count_marked(s, 10, 12) == 12, "the closed box: %d of 12 marked", count_marked(s, 10, 12));
    CHECK(count_marked(s, 22, 2) == 0, "the light (the ceiling is behind it) is not marked");
    CHECK(dr_backface_count(s->backface) == 22, "22 marked (%lld)", (long long)dr_backface_count(s->backface));
    dr_scene_destroy(s);

    /* holes let rays into the box: only the walls */
    s = room_scene(&cam, 1);
    CHECK(count_marked(s, 10, 12) == 0, "a MASK box is not sealed (%d marked)", count_marked(s, 10, 12));
    CHECK(count_marked(s, 0, 10) == 10, "... the walls still are");
    dr_scene_destroy(s);
}

/* Far from the origin (coordinates of 1e5, a georeferenced scene): a box
 * that pokes 0.05 below the floor keeps the floor unproved (its back can
 * be met from the box's part below); the room test allows no slack beyond
 * rounding. */
static void test_far_from_origin(void)
{
    struct sb b;
    sb_init(&b);
    int white = sb_material(&b, sb_diffuse(dr_v3s(0.7)));
    dr_vec3 o = dr_v3(1e5, 0, 1e5);
    sb_quad(&b, dr_add(o, dr_v3(-2, 0, -2)), dr_v3(0, 0, 4), dr_v3(4, 0, 0), white);   /* floor, +y */
    sb_box(&b, dr_add(o, dr_v3(-0.5, -0.05, -0.5)), dr_add(o, dr_v3(0.5, 1, 0.5)), white);
    scene_camera(b.s, sb_camera(dr_add(o, dr_v3(0, 3, 6)), o, 40));
    struct dr_scene *s = sb_finish(&b);
    CHECK(count_marked(s, 0, 2) == 0, "far from the origin, a floor with a box poking below it: %d marked",
          count_marked(s, 0, 2));
    CHECK(count_marked(s, 2, 12) == 12, "... the closed box is sealed (%d of 12)", count_marked(s, 2, 12));
    dr_scene_destroy(s);
}

/* The closed-mesh scenes' start: a single-sided grey material (*m) and a
 * double-sided one for the plate (*plate). */
static void closed_scene_start(struct sb *b, int *m, int *plate)
{
    sb_init(b);
    *m = sb_material(b, sb_diffuse(dr_v3s(0.5)));
    struct dr_material ds = sb_diffuse(dr_v3s(0.5));
    ds.double_sided = true;
    *plate = sb_material(b, ds);
}

/* ... and their end: the double-sided plate far off (it keeps the room
 * test from proving anything), a white sky, the camera. */
static struct dr_scene *closed_scene_finish(struct sb *b, int plate, struct dr_camera cam)
{
    sb_quad(b, dr_v3(-20, 5, -20), dr_v3(40, 0, 0), dr_v3(0, 0, 40), plate);
    sb_environment(b, dr_v3s(1.0));
    b->s->n_file_materials = b->s->n_materials;
    scene_camera(b->s, cam);
    return sb_finish(b);
}

/* A closed box seen from outside and from inside; a scene of one
 * double-sided plate far off keeps the room test from proving anything. */
enum variant { CLOSED, OPEN, FLIPPED, INWARD };
static struct dr_scene *box_scene(enum variant v, dr_vec3 view)
{
    struct sb b;
    int m, plate;
    closed_scene_start(&b, &m, &plate);
    dr_vec3 lo = dr_v3(-1, -1, -1), hi = dr_v3(1, 1, 1);
    if (v == INWARD) {   /* the box's faces wound the other way: a closed room */
        dr_vec3 dx = dr_v3(2, 0, 0), dy = dr_v3(0, 2, 0), dz = dr_v3(0, 0, 2);
        sb_quad(&b, lo, dx, dy, m);
        sb_quad(&b, dr_add(lo, dz), dy, dx, m);
        sb_quad(&b, lo, dy, dz, m);
        sb_quad(&b, dr_add(lo, dx), dz, dy, m);
        sb_quad(&b, lo, dz, dx, m);
        sb_quad(&b, dr_add(lo, dy), dx, dz, m);
    } else {
        sb_box(&b, lo, hi, m);
    }
    struct dr_mesh *mesh = &b.s->mesh;
    if (v == OPEN)
        mesh->n_triangles -= 2;   /* no top */
    if (v == FLIPPED) {           /* one triangle wound against its neighbours */
        uint32_t tmp = mesh->indices[1];
        mesh->indices[1] = mesh->indices[2];
        mesh->indices[2] = tmp;
    }
    CHECK(mesh->n_triangles == (v == OPEN ? 10u : 12u), "the box's triangles come first (%u)", mesh->n_triangles);
    return closed_scene_finish(&b, plate, sb_camera(view, dr_v3(0, 0, 0.5), 40));
}

static void test_closed(void)
{
    dr_vec3 outside = dr_v3(0.3, 0.2, 6), inside = dr_v3(0.1, 0.2, 0.3);
    struct dr_scene *s = box_scene(CLOSED, outside);
    CHECK(count_marked(s, 0, 12) == 12, "closed box seen from outside: %d of 12 marked", count_marked(s, 0, 12));
    CHECK(count_marked(s, 12, 2) == 0, "the double-sided plate needs no mark");
    /* a camera inside is refused, then added: the box is no longer sealed */
    struct dr_camera in = sb_camera(inside, dr_v3(0, 0, -1), 40);
    CHECK(!dr_backface_admits(s->backface, s, &in), "a camera inside the sealed box is refused");
    CHECK(dr_scene_check_viewpoint(s, &in) == DR_ERR_ARG, "dr_scene_check_viewpoint refuses it");
    float rgb[3 * 4 * 4];
    struct dr_render_opts o = {.width = 4, .height = 4, .spp = 1, .max_depth = 3, .rr_depth = 5, .threads = 1};
    CHECK(dr_render(s, &in, &o, rgb, NULL) == DR_ERR_ARG, "dr_render refuses a camera not analysed");
    CHECK(strstr(dr_last_error(), "dr_scene_add_viewpoint") != NULL, "the message says what to do: %s",
          dr_last_error());
    CHECK(dr_scene_add_viewpoint(s, &in) == 0 && count_marked(s, 0, 12) == 0,
          "after adding the inside camera nothing of the box is marked (%d)", count_marked(s, 0, 12));
    CHECK(dr_render(s, &in, &o, rgb, NULL) == 0, "render from inside: %s", dr_last_error());
    struct dr_camera out = sb_camera(outside, dr_v3(0, 0, 0), 40);
    CHECK(dr_backface_admits(s->backface, s, &out), "the outside camera is still admitted");
    dr_scene_destroy(s);

    s = box_scene(CLOSED, inside);
    CHECK(count_marked(s, 0, 12) == 0, "closed box, camera inside: %d marked", count_marked(s, 0, 12));
    dr_scene_destroy(s);
    s = box_scene(OPEN, outside);
    CHECK(count_marked(s, 0, 10) == 0, "open box: %d marked", count_marked(s, 0, 10));
    dr_scene_destroy(s);
    s = box_scene(FLIPPED, outside);
    CHECK(count_marked(s, 0, 12) == 0, "inconsistently wound box: %d marked", count_marked(s, 0, 12));
    dr_scene_destroy(s);
    /* a closed room (inward normals) seen from inside: sealed; from outside: not */
    s = box_scene(INWARD, inside);
    CHECK(count_marked(s, 0, 12) == 12, "closed inward room, camera inside: %d of 12 marked",
          count_marked(s, 0, 12));
    dr_scene_destroy(s);
    /* from outside only its floor (8, 9: nothing lies below it) is proved, by the room test */
    s = box_scene(INWARD, outside);
    CHECK(count_marked(s, 0, 12) == 2 && count_marked(s, 8, 2) == 2,
          "closed inward room, camera outside: %d marked, the floor's %d", count_marked(s, 0, 12),
          count_marked(s, 8, 2));
    dr_scene_destroy(s);

    /* an orthographic camera's rays start across a plane: nothing marked */
    s = box_scene(CLOSED, outside);
    struct dr_camera ortho = sb_camera(outside, dr_v3(0, 0, 0), 40);
    ortho.orthographic = true;
    ortho.ymag = 2.0;
    CHECK(!dr_backface_admits(s->backface, s, &ortho), "an orthographic camera is refused while marks stand");
    CHECK(dr_scene_add_viewpoint(s, &ortho) == 0 && dr_backface_count(s->backface) == 0,
          "after adding it nothing is marked (%lld)", (long long)dr_backface_count(s->backface));
    dr_scene_destroy(s);
}

/* A closed bipyramid of 2 x FAN triangles around a ring, its apexes first,
 * so the edges to the top apex are all filed under that vertex (a bucket
 * of 2 x FAN uses, sorted by qsort rather than by insertion), each ring
 * vertex written once per triangle (the weld joins them). FIN adds a
 * triangle on the edge apex - ring 0 (used three times: not closed);
 * TWISTED winds one fan triangle against its neighbours. */
enum { FAN = 40 };
enum fan_variant { FAN_CLOSED, FAN_FIN, FAN_TWISTED };
static struct dr_scene *bipyramid_scene(enum fan_variant v)
{
    struct sb b;
    int m, plate;
    closed_scene_start(&b, &m, &plate);
    uint32_t top = sb_vertex(&b, dr_v3(0, 1, 0), 0, 0), bottom = sb_vertex(&b, dr_v3(0, -1, 0), 0, 0);
    for (int i = 0; i < FAN; i++) {
        double a0 = 2 * M_PI * i / FAN, a1 = 2 * M_PI * ((i + 1) % FAN) / FAN;   /* the ring closes exactly */
        dr_vec3 p0 = dr_v3(cos(a0), 0, -sin(a0)), p1 = dr_v3(cos(a1), 0, -sin(a1));
        uint32_t r0 = sb_vertex(&b, p0, 0, 0), r1 = sb_vertex(&b, p1, 0, 0);
        if (v == FAN_TWISTED && i == 7)
            sb_triangle(&b, top, r1, r0, m);
        else
            sb_triangle(&b, top, r0, r1, m);   /* counter-clockwise seen from outside */
        uint32_t s0 = sb_vertex(&b, p0, 0, 0), s1 = sb_vertex(&b, p1, 0, 0);
        sb_triangle(&b, bottom, s1, s0, m);
    }
    if (v == FAN_FIN)
        sb_triangle(&b, top, sb_vertex(&b, dr_v3(1, 0, 0), 0, 0), sb_vertex(&b, dr_v3(2, 0.5, 0), 0, 0), m);
    return closed_scene_finish(&b, plate, sb_camera(dr_v3(0.3, 0.4, 6), dr_v3(0, 0, 0), 40));
}

static void test_closed_fan(void)
{
    struct dr_scene *s = bipyramid_scene(FAN_CLOSED);
    CHECK(count_marked(s, 0, 2 * FAN) == 2 * FAN, "closed bipyramid: %d of %d marked", count_marked(s, 0, 2 * FAN),
          2 * FAN);
    dr_scene_destroy(s);
    s = bipyramid_scene(FAN_FIN);
    CHECK(count_marked(s, 0, 2 * FAN + 1) == 0, "an edge used three times: %d marked",
          count_marked(s, 0, 2 * FAN + 1));
    dr_scene_destroy(s);
    s = bipyramid_scene(FAN_TWISTED);
    CHECK(count_marked(s, 0, 2 * FAN) == 0, "one fan triangle wound the other way: %d marked",
          count_marked(s, 0, 2 * FAN));
    dr_scene_destroy(s);
}

/* The same answers with the proofs as without: the image of the room scene
 * (every marked triangle's test dropped) against the same scene analysed
 * with an orthographic viewpoint added (nothing marked, every test kept);
 * and closest hits and shadow rays from surface points against the fully
 * filtered structure. */
static void test_same_answers(void)
{
    struct dr_camera cam;
    struct dr_scene *s = room_scene(&cam, 0);
    enum { W = 32, H = 32 };
    static float a[3 * W * H], b[3 * W * H];
    struct dr_render_opts o = {.width = W, .height = H, .spp = 16, .max_depth = 6, .rr_depth = 5, .threads = 2};
    CHECK(dr_backface_count(s->backface) == 22, "marks before");
    CHECK(dr_render(s, &cam, &o, a, NULL) == 0, "render: %s", dr_last_error());

    /* rays from the camera and from lifted surface points, as paths make them */
    struct dr_accel *ref = dr_accel_create_scene_filtered(s);
    struct dr_sampler smp;
    dr_sampler_init(&smp, 7, 0, 0);
    int n_same = 0, n = 0, n_occ_same = 0;
    for (int i = 0; i < 20000; i++) {
        dr_vec3 d = dr_normalize(dr_v3(dr_sampler_next(&smp) - 0.5, dr_sampler_next(&smp) - 0.5, -1.0));
        int64_t t0 = dr_accel_intersect(s->accel, cam.origin, d, 0, INFINITY);
        n_same += t0 == dr_accel_intersect(ref, cam.origin, d, 0, INFINITY);
        n++;
        if (t0 < 0)
            continue;
        struct dr_hit h;
        dr_hit_compute(&s->mesh, t0, cam.origin, d, &h);
        dr_vec3 ng = h.front ? h.ng : dr_neg(h.ng);
        double z = 2.0 * dr_sampler_next(&smp) - 1.0, phi = 2.0 * M_PI * dr_sampler_next(&smp);
        dr_vec3 w = dr_v3(sqrt(1 - z * z) * cos(phi), sqrt(1 - z * z) * sin(phi), z);
        if (dr_dot(w, ng) < 0.0)
            w = dr_neg(w);
        dr_vec3 org = dr_offset_origin(&h, ng, w);
        n_same += dr_accel_intersect(s->accel, org, w, 0, INFINITY) == dr_accel_intersect(ref, org, w, 0, INFINITY);
        n++;
        n_occ_same += dr_accel_occluded(s->accel, org, w, 0, 3.0) == dr_accel_occluded(ref, org, w, 0, 3.0);
    }
    dr_accel_destroy(ref);
    printf("same closest hit %d of %d, same shadow answer %d of %d\n", n_same, n, n_occ_same, n - 20000);
    CHECK(n_same == n, "closest hits: %d of %d the same as the filtered structure's", n_same, n);
    CHECK(n_occ_same == n - 20000, "shadow rays: %d of %d the same", n_occ_same, n - 20000);

    struct dr_camera ortho = cam;
    ortho.orthographic = true;
    ortho.ymag = 1.5;
    CHECK(dr_scene_add_viewpoint(s, &ortho) == 0 && dr_backface_count(s->backface) == 0, "marks dropped");
    CHECK(dr_render(s, &cam, &o, b, NULL) == 0, "render without marks: %s", dr_last_error());
    int differ = 0;
    double sum = 0.0;
    for (int i = 0; i < 3 * W * H; i++) {
        differ += a[i] != b[i];
        sum += a[i];
    }
    printf("room image with and without the marks: %d of %d values differ (mean %.4f)\n", differ, 3 * W * H,
           sum / (3 * W * H));
    CHECK(differ == 0, "the same image with and without the marks (%d values differ)", differ);
    CHECK(sum > 0.01 * 3 * W * H, "the image is lit (mean %g)", sum / (3 * W * H));
    dr_scene_destroy(s);
}

int main(void)
{
    test_room();
    test_far_from_origin();
    test_closed();
    test_closed_fan();
    test_same_answers();
    return TEST_END();
}
