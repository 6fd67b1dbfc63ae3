/* make_big_scene: writes the benchmark's "big" scene, a Cornell box with
 * ~120k triangles of finely tessellated spheres and tori, as glTF 2.0
 * (OUT.gltf + OUT.bin, the .bin next to it and named after it).
 *
 *   usage: make_big_scene OUT.gltf
 *
 * Conventions follow /work/shared/bench/peer-cornell-box.gltf (the Mitsuba 3
 * Cornell box replica): the box spans [-1,1]^3, each wall is the unit quad
 * [-1,1]^2 in the z = 0 plane (normal +z) placed by a node matrix, Lambertian
 * materials are metallic 0 / roughness 1 with KHR_materials_specular
 * specularFactor 0, the ceiling light is a small quad just below the ceiling
 * facing down with radiometric emission emissiveFactor * emissiveStrength,
 * and the camera sits at (0, 0, 3.9) looking down -z with yfov 39.3077 deg.
 *
 * The dense objects are built in local coordinates (unit sphere, torus of
 * major radius 1) and placed by node matrices as well, with smooth vertex
 * normals.
 *
 *   make_big_scene --textured OUT.gltf
 *
 * writes the textured variant instead (issue 11's "heavy textured asset"):
 * the same geometry with TEXCOORD_0, the white sphere's base colour from a
 * 2048x2048 PNG and the blue torus emissive through a 2048x2048 emissive
 * texture (16 384 emissive triangles for the light sampler), the PNGs next
 * to the .gltf (OUT-base.png, OUT-emissive.png; written with stb, which
 * drender links anyway). */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <stb/stb_image_write.h>

#define PI 3.14159265358979323846

/* ---- a growable byte buffer: the contents of the .bin -------------------- */

static unsigned char *bin;
static size_t bin_len, bin_cap;

static size_t bin_append(const void *data, size_t n)
{
    if (bin_len + n > bin_cap) {
        size_t cap = bin_cap ? bin_cap : 1 << 20;
        while (cap < bin_len + n)
            cap *= 2;
        unsigned char *p = realloc(bin, cap);
        if (!p) {
            fprintf(stderr, "make_big_scene: out of memory\n");
            exit(1);
        }
        bin = p;
        bin_cap = cap;
    }
    size_t at = bin_len;
    memcpy(bin + at, data, n);
    bin_len += n;
    return at;
}

/* ---- meshes ------------------------------------------------------------- */

/* One indexed triangle mesh in local coordinates. */
struct mesh {
    float *pos, *nor, *uv;
    uint32_t *idx;
    size_t nv, nt;
};

static struct mesh mesh_alloc(size_t nv, size_t nt)
{
    struct mesh m = {malloc(nv * 3 * sizeof(float)), malloc(nv * 3 * sizeof(float)), malloc(nv * 2 * sizeof(float)),
                     malloc(nt * 3 * sizeof(uint32_t)), 0, 0};
    if (!m.pos || !m.nor || !m.uv || !m.idx) {
        fprintf(stderr, "make_big_scene: out of memory\n");
        exit(1);
    }
    return m;
}

static void put_vertex(struct mesh *m, double px, double py, double pz, double nx, double ny, double nz, double u,
                       double v)
{
    float *p = m->pos + 3 * m->nv, *n = m->nor + 3 * m->nv, *t = m->uv + 2 * m->nv;
    p[0] = (float)px, p[1] = (float)py, p[2] = (float)pz;
    n[0] = (float)nx, n[1] = (float)ny, n[2] = (float)nz;
    t[0] = (float)u, t[1] = (float)v;
    m->nv++;
}

static void put_tri(struct mesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    uint32_t *t = m->idx + 3 * m->nt++;
    t[0] = a, t[1] = b, t[2] = c;
}

/* The unit quad [-1,1]^2 at z = 0, normal +z, counter-clockwise seen from +z
 * (same vertex order as the peer scene's walls). */
static struct mesh make_quad(void)
{
    struct mesh m = mesh_alloc(4, 2);
    put_vertex(&m, -1, -1, 0, 0, 0, 1, 0, 1);
    put_vertex(&m, 1, -1, 0, 0, 0, 1, 1, 1);
    put_vertex(&m, 1, 1, 0, 0, 0, 1, 1, 0);
    put_vertex(&m, -1, 1, 0, 0, 0, 1, 0, 0);
    put_tri(&m, 0, 1, 2);
    put_tri(&m, 0, 2, 3);
    return m;
}

/* Unit sphere, nu segments around y, nv rings from pole to pole; the pole
 * rows are fans (no degenerate triangles): 2 nu (nv - 1) triangles. */
static struct mesh make_sphere(int nu, int nv)
{
    struct mesh m = mesh_alloc((size_t)(nu + 1) * (nv + 1), (size_t)2 * nu * (nv - 1));
    for (int j = 0; j <= nv; j++) {
        double th = PI * j / nv, y = cos(th), r = sin(th);
        for (int i = 0; i <= nu; i++) {
            double ph = 2 * PI * i / nu, x = r * sin(ph), z = r * cos(ph);
            put_vertex(&m, x, y, z, x, y, z, (double)i / nu, (double)j / nv);
        }
    }
    for (int j = 0; j < nv; j++)
        for (int i = 0; i < nu; i++) {
            uint32_t a = (uint32_t)(j * (nu + 1) + i), b = a + 1;
            uint32_t c = a + (uint32_t)(nu + 1), d = c + 1;
            /* outward-facing counter-clockwise: a (top) -> c (below) -> d */
            if (j != nv - 1)
                put_tri(&m, a, c, d);
            if (j != 0)
                put_tri(&m, a, d, b);
        }
    return m;
}

/* Torus around the y axis, major radius 1, minor radius r; nu segments along
 * the ring, nv around the tube: 2 nu nv triangles. */
static struct mesh make_torus(double r, int nu, int nv)
{
    struct mesh m = mesh_alloc((size_t)(nu + 1) * (nv + 1), (size_t)2 * nu * nv);
    for (int i = 0; i <= nu; i++) {
        double ph = 2 * PI * i / nu, cp = cos(ph), sp = sin(ph);
        for (int j = 0; j <= nv; j++) {
            double th = 2 * PI * j / nv, ct = cos(th), st = sin(th);
            /* normal: (cos th cos ph, sin th, cos th sin ph) */
            double nx = ct * cp, ny = st, nz = ct * sp;
            put_vertex(&m, cp + r * nx, r * ny, sp + r * nz, nx, ny, nz, (double)i / nu, (double)j / nv);
        }
    }
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            uint32_t a = (uint32_t)(i * (nv + 1) + j), b = a + 1;
            uint32_t c = a + (uint32_t)(nv + 1), d = c + 1;
            put_tri(&m, a, b, d);
            put_tri(&m, a, d, c);
        }
    return m;
}

/* ---- the scene description ---------------------------------------------- */

enum { WHITE, GREEN, RED, LIGHT, BLUE, ROUGH_GOLD, ROUGH_SILVER };

struct node {
    const char *name;
    int mesh;       /* index into meshes[] */
    int material;   /* the primitive's material */
    double m[16];   /* column-major node matrix */
};

/* The matrix of scale s, then rotation by angle a (radians) about the unit
 * axis (ax, ay, az), then translation t; column-major as glTF wants. */
static void trs(double out[16], double s, double ax, double ay, double az, double a, double tx, double ty, double tz)
{
    double c = cos(a), sn = sin(a), k = 1 - c;
    double r[3][3] = {
        {c + ax * ax * k, ax * ay * k - az * sn, ax * az * k + ay * sn},
        {ay * ax * k + az * sn, c + ay * ay * k, ay * az * k - ax * sn},
        {az * ax * k - ay * sn, az * ay * k + ax * sn, c + az * az * k},
    };
    memset(out, 0, 16 * sizeof(double));
    for (int col = 0; col < 3; col++)
        for (int row = 0; row < 3; row++)
            out[4 * col + row] = s * r[row][col];
    out[12] = tx, out[13] = ty, out[14] = tz, out[15] = 1;
}

/* Writes one material; lambertian ones turn the dielectric layer off. */
static void write_material(FILE *f, const char *name, double r, double g, double b, double metallic,
                           double roughness, int last)
{
    fprintf(f, "    {\"name\": \"%s\", \"pbrMetallicRoughness\": {\"baseColorFactor\": [%g, %g, %g, 1.0], "
               "\"metallicFactor\": %g, \"roughnessFactor\": %g}",
            name, r, g, b, metallic, roughness);
    if (metallic == 0)
        fprintf(f, ", \"extensions\": {\"KHR_materials_specular\": {\"specularFactor\": 0.0}}");
    fprintf(f, "}%s\n", last ? "" : ",");
}

static const char *base_name(const char *path)
{
    const char *s = strrchr(path, '/');
    return s ? s + 1 : path;
}

/* The file name of path without its directory and ".gltf" (the PNGs'
 * prefix), in a static buffer: the next call overwrites it. */
static const char *stem(const char *path)
{
    static char buf[1024];
    snprintf(buf, sizeof buf, "%s", base_name(path));
    size_t n = strlen(buf);
    if (n > 5 && strcmp(buf + n - 5, ".gltf") == 0)
        buf[n - 5] = '\0';
    return buf;
}

/* OUT-base.png (a two-tone checker with a gradient) and OUT-emissive.png
 * (bright stripes on black), 2048x2048 RGB, next to OUT.gltf. */
static int write_textures(const char *gltf_path)
{
    enum { S = 2048 };
    unsigned char *px = malloc((size_t)S * S * 3);
    char path[2048], dir[1024];
    snprintf(dir, sizeof dir, "%s", gltf_path);
    char *slash = strrchr(dir, '/');
    if (slash)
        slash[1] = '\0';
    else
        dir[0] = '\0';
    if (!px)
        return 1;
    for (int pass = 0; pass < 2; pass++) {
        for (int y = 0; y < S; y++)
            for (int x = 0; x < S; x++) {
                unsigned char *c = px + 3 * ((size_t)y * S + x);
                if (pass == 0) {
                    int on = ((x / 64) + (y / 64)) % 2;
                    c[0] = (unsigned char)(on ? 230 : 60 + x / 16);
                    c[1] = (unsigned char)(on ? 220 : 80 + y / 16);
                    c[2] = (unsigned char)(on ? 200 : 120);
                } else {
                    int lit = (x % 256) < 48;
                    c[0] = c[1] = (unsigned char)(lit ? 255 : 0);
                    c[2] = (unsigned char)(lit ? 180 : 0);
                }
            }
        snprintf(path, sizeof path, "%s%s-%s.png", dir, stem(gltf_path), pass ? "emissive" : "base");
        if (!stbi_write_png(path, S, S, 3, px, S * 3)) {
            fprintf(stderr, "make_big_scene: cannot write %s\n", path);
            free(px);
            return 1;
        }
    }
    free(px);
    return 0;
}

int main(int argc, char **argv)
{
    const bool textured = argc == 3 && strcmp(argv[1], "--textured") == 0;
    if (!(argc == 2 || textured) || argv[argc - 1][0] == '-') {
        fprintf(stderr, "usage: make_big_scene [--textured] OUT.gltf   (also writes OUT.bin next to it)\n");
        return 2;
    }
    const char *gltf_path = argv[argc - 1];
    size_t plen = strlen(gltf_path);
    char *bin_path = malloc(plen + 5);
    if (!bin_path)
        return 1;
    strcpy(bin_path, gltf_path);
    if (plen > 5 && strcmp(gltf_path + plen - 5, ".gltf") == 0)
        bin_path[plen - 5] = '\0';
    strcat(bin_path, ".bin");

    /* meshes: 0 the unit quad shared by walls and light, then the dense ones */
    struct mesh meshes[] = {
        make_quad(),
        make_sphere(192, 96),          /* 36 480 triangles: white sphere */
        make_torus(0.3, 256, 96),      /* 49 152: gold torus standing up */
        make_sphere(160, 80),          /* 25 280: silver sphere */
        make_torus(0.35, 128, 64),     /* 16 384: blue torus lying flat */
    };
    enum { N_MESHES = sizeof meshes / sizeof meshes[0] };

    /* nodes: walls and light with the peer scene's matrices, then objects.
     * Object sizes: torus major radius = scale, minor = scale * r. */
    const double e = 6.123233995736766e-17;  /* cos(90 deg) in double, as in the peer file */
    struct node nodes[] = {
        {"light", 0, LIGHT, {0.23, 0, 0, 0, 0, 0.19 * e, 0.19, 0, 0, -0.19, 0.19 * e, 0, 0, 0.99, 0.01, 1}},
        {"floor", 0, WHITE, {1, 0, 0, 0, 0, e, -1, 0, 0, 1, e, 0, 0, -1, 0, 1}},
        {"ceiling", 0, WHITE, {1, 0, 0, 0, 0, e, 1, 0, 0, -1, e, 0, 0, 1, 0, 1}},
        {"back", 0, WHITE, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, -1, 1}},
        {"green-wall", 0, GREEN, {e, 0, 1, 0, 0, 1, 0, 0, -1, 0, e, 0, 1, 0, 0, 1}},
        {"red-wall", 0, RED, {e, 0, -1, 0, 0, 1, 0, 0, 1, 0, e, 0, -1, 0, 0, 1}},
        {"white-sphere", 1, WHITE, {0}},
        {"gold-torus", 2, ROUGH_GOLD, {0}},
        {"silver-sphere", 3, ROUGH_SILVER, {0}},
        {"blue-torus", 4, BLUE, {0}},
    };
    enum { N_NODES = sizeof nodes / sizeof nodes[0] };
    /* white sphere, radius 0.35, resting on the floor at the back right */
    trs(nodes[6].m, 0.35, 0, 1, 0, 0, 0.42, -0.65, -0.38);
    /* gold torus (0.3 + 0.09) standing on its rim at the back left, its axis
     * horizontal: rotated 90 deg about x, then turned 35 deg about y. The two
     * rotations compose as one about an axis; simpler to build explicitly. */
    {
        double rx[16], ry[16], *m = nodes[7].m;
        trs(rx, 0.3, 1, 0, 0, PI / 2, 0, 0, 0);
        trs(ry, 1.0, 0, 1, 0, 35 * PI / 180, 0, 0, 0);
        memset(m, 0, 16 * sizeof(double));
        for (int c = 0; c < 4; c++)
            for (int r = 0; r < 4; r++)
                for (int k = 0; k < 4; k++)
                    m[4 * c + r] += ry[4 * k + r] * rx[4 * c + k];
        m[12] = -0.38, m[13] = -1.0 + 0.3 * 1.3, m[14] = -0.35;
    }
    /* silver sphere, radius 0.22, front left */
    trs(nodes[8].m, 0.22, 0, 1, 0, 0, -0.2, -0.78, 0.45);
    /* blue torus (0.2 + 0.07) lying flat on the floor, front right */
    trs(nodes[9].m, 0.2, 0, 1, 0, 0, 0.45, -1.0 + 0.2 * 0.35, 0.42);

    /* binary: per mesh positions, normals, indices (all 4-byte aligned), and
     * in the textured variant the UVs; A accessors (and buffer views) per mesh */
    const int A = textured ? 4 : 3;
    size_t off_pos[N_MESHES], off_nor[N_MESHES], off_idx[N_MESHES], off_uv[N_MESHES];
    size_t total_tris = 0;
    for (int i = 0; i < N_MESHES; i++) {
        off_pos[i] = bin_append(meshes[i].pos, meshes[i].nv * 3 * sizeof(float));
        off_nor[i] = bin_append(meshes[i].nor, meshes[i].nv * 3 * sizeof(float));
        off_idx[i] = bin_append(meshes[i].idx, meshes[i].nt * 3 * sizeof(uint32_t));
        off_uv[i] = textured ? bin_append(meshes[i].uv, meshes[i].nv * 2 * sizeof(float)) : 0;
    }
    if (textured && write_textures(gltf_path) != 0)
        return 1;
    for (int i = 0; i < N_NODES; i++)
        total_tris += meshes[nodes[i].mesh].nt;

    FILE *fb = fopen(bin_path, "wb");
    if (!fb || fwrite(bin, 1, bin_len, fb) != bin_len || fclose(fb) != 0) {
        fprintf(stderr, "make_big_scene: cannot write %s\n", bin_path);
        return 1;
    }

    FILE *f = fopen(gltf_path, "w");
    if (!f) {
        fprintf(stderr, "make_big_scene: cannot write %s\n", gltf_path);
        return 1;
    }
    fprintf(f, "{\n  \"asset\": {\"version\": \"2.0\", \"generator\": \"drender bench/make_big_scene.c\"},\n");
    fprintf(f, "  \"extensionsUsed\": [\"KHR_materials_specular\", \"KHR_materials_emissive_strength\"],\n");
    if (textured) {
        const char *st = stem(gltf_path);
        fprintf(f, "  \"images\": [{\"uri\": \"%s-base.png\"}, {\"uri\": \"%s-emissive.png\"}],\n"
                   "  \"samplers\": [{}],\n  \"textures\": [{\"source\": 0, \"sampler\": 0}, {\"source\": 1, \"sampler\": 0}],\n",
                st, st);
    }
    fprintf(f, "  \"scene\": 0,\n  \"scenes\": [{\"name\": \"big-cornell-box\", \"nodes\": [");
    for (int i = 0; i <= N_NODES; i++)
        fprintf(f, "%s%d", i ? ", " : "", i);
    fprintf(f, "]}],\n  \"nodes\": [\n");
    for (int i = 0; i < N_NODES; i++) {
        /* one mesh per node, so each node can carry its own material */
        fprintf(f, "    {\"name\": \"%s\", \"mesh\": %d, \"matrix\": [", nodes[i].name, i);
        for (int k = 0; k < 16; k++)
            fprintf(f, "%s%.17g", k ? ", " : "", nodes[i].m[k]);
        fprintf(f, "]},\n");
    }
    fprintf(f, "    {\"name\": \"camera\", \"camera\": 0, \"matrix\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, "
               "0, 0, 3.9, 1]}\n  ],\n");
    fprintf(f, "  \"cameras\": [{\"type\": \"perspective\", \"perspective\": {\"yfov\": 0.6860487863861751, "
               "\"aspectRatio\": 1.0, \"znear\": 0.001, \"zfar\": 1000}}],\n");

    /* meshes: node i uses mesh i, whose primitive reads geometry mesh
     * nodes[i].mesh's accessors (3 per geometry mesh: POSITION, NORMAL, indices) */
    fprintf(f, "  \"meshes\": [\n");
    for (int i = 0; i < N_NODES; i++) {
        int g = nodes[i].mesh;
        char uv[48] = "";
        if (textured)
            snprintf(uv, sizeof uv, ", \"TEXCOORD_0\": %d", A * g + 3);
        fprintf(f, "    {\"name\": \"%s\", \"primitives\": [{\"attributes\": {\"POSITION\": %d, \"NORMAL\": %d%s}, "
                   "\"indices\": %d, \"material\": %d}]}%s\n",
                nodes[i].name, A * g, A * g + 1, uv, A * g + 2, nodes[i].material, i + 1 < N_NODES ? "," : "");
    }
    fprintf(f, "  ],\n  \"materials\": [\n");
    if (textured)   /* the base colour texture on the white sphere's material (walls read it too) */
        fprintf(f, "    {\"name\": \"white\", \"pbrMetallicRoughness\": {\"baseColorFactor\": [0.885809, 0.698859, "
                   "0.666422, 1.0], \"baseColorTexture\": {\"index\": 0}, \"metallicFactor\": 0.0, "
                   "\"roughnessFactor\": 1.0}, \"extensions\": {\"KHR_materials_specular\": {\"specularFactor\": 0.0}}},\n");
    else
        write_material(f, "white", 0.885809, 0.698859, 0.666422, 0, 1, 0);
    write_material(f, "green", 0.105421, 0.37798, 0.076425, 0, 1, 0);
    write_material(f, "red", 0.570068, 0.0430135, 0.0443706, 0, 1, 0);
    fprintf(f, "    {\"name\": \"light\", \"pbrMetallicRoughness\": {\"baseColorFactor\": [0.885809, 0.698859, "
               "0.666422, 1.0], \"metallicFactor\": 0.0, \"roughnessFactor\": 1.0}, \"emissiveFactor\": "
               "[1.0, 0.7607168107902321, 0.36730135421765375], \"extensions\": {\"KHR_materials_specular\": "
               "{\"specularFactor\": 0.0}, \"KHR_materials_emissive_strength\": {\"emissiveStrength\": 18.387}}},\n");
    if (textured)   /* the blue torus glows through its emissive texture */
        fprintf(f, "    {\"name\": \"blue\", \"pbrMetallicRoughness\": {\"baseColorFactor\": [0.08, 0.18, 0.6, 1.0], "
                   "\"metallicFactor\": 0.0, \"roughnessFactor\": 1.0}, \"emissiveFactor\": [1.0, 1.0, 1.0], "
                   "\"emissiveTexture\": {\"index\": 1}, \"extensions\": {\"KHR_materials_specular\": "
                   "{\"specularFactor\": 0.0}, \"KHR_materials_emissive_strength\": {\"emissiveStrength\": 4.0}}},\n");
    else
        write_material(f, "blue", 0.08, 0.18, 0.6, 0, 1, 0);
    write_material(f, "rough-gold", 1.0, 0.78, 0.34, 1, 0.35, 0);
    write_material(f, "rough-silver", 0.95, 0.93, 0.88, 1, 0.2, 1);

    fprintf(f, "  ],\n  \"accessors\": [\n");
    for (int g = 0; g < N_MESHES; g++) {
        const struct mesh *m = &meshes[g];
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t v = 0; v < m->nv; v++)
            for (int k = 0; k < 3; k++) {
                lo[k] = fminf(lo[k], m->pos[3 * v + k]);
                hi[k] = fmaxf(hi[k], m->pos[3 * v + k]);
            }
        fprintf(f, "    {\"bufferView\": %d, \"componentType\": 5126, \"count\": %zu, \"type\": \"VEC3\", "
                   "\"min\": [%.9g, %.9g, %.9g], \"max\": [%.9g, %.9g, %.9g]},\n",
                A * g, m->nv, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
        fprintf(f, "    {\"bufferView\": %d, \"componentType\": 5126, \"count\": %zu, \"type\": \"VEC3\"},\n",
                A * g + 1, m->nv);
        fprintf(f, "    {\"bufferView\": %d, \"componentType\": 5125, \"count\": %zu, \"type\": \"SCALAR\"}%s\n",
                A * g + 2, 3 * m->nt, g + 1 < N_MESHES || textured ? "," : "");
        if (textured)
            fprintf(f, "    {\"bufferView\": %d, \"componentType\": 5126, \"count\": %zu, \"type\": \"VEC2\"}%s\n",
                    A * g + 3, m->nv, g + 1 < N_MESHES ? "," : "");
    }
    fprintf(f, "  ],\n  \"bufferViews\": [\n");
    for (int g = 0; g < N_MESHES; g++) {
        const struct mesh *m = &meshes[g];
        fprintf(f, "    {\"buffer\": 0, \"byteOffset\": %zu, \"byteLength\": %zu, \"target\": 34962},\n",
                off_pos[g], m->nv * 3 * sizeof(float));
        fprintf(f, "    {\"buffer\": 0, \"byteOffset\": %zu, \"byteLength\": %zu, \"target\": 34962},\n",
                off_nor[g], m->nv * 3 * sizeof(float));
        fprintf(f, "    {\"buffer\": 0, \"byteOffset\": %zu, \"byteLength\": %zu, \"target\": 34963}%s\n",
                off_idx[g], m->nt * 3 * sizeof(uint32_t), g + 1 < N_MESHES || textured ? "," : "");
        if (textured)
            fprintf(f, "    {\"buffer\": 0, \"byteOffset\": %zu, \"byteLength\": %zu, \"target\": 34962}%s\n",
                    off_uv[g], m->nv * 2 * sizeof(float), g + 1 < N_MESHES ? "," : "");
    }
    fprintf(f, "  ],\n  \"buffers\": [{\"uri\": \"%s\", \"byteLength\": %zu}]\n}\n", base_name(bin_path), bin_len);
    if (fclose(f) != 0) {
        fprintf(stderr, "make_big_scene: cannot write %s\n", gltf_path);
        return 1;
    }
    printf("%s: %zu triangles, %s: %zu bytes\n", gltf_path, total_tris, bin_path, bin_len);

    for (int i = 0; i < N_MESHES; i++) {
        free(meshes[i].pos);
        free(meshes[i].nor);
        free(meshes[i].uv);
        free(meshes[i].idx);
    }
    free(bin);
    free(bin_path);
    return 0;
}
