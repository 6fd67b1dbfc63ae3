/* Density grids: reading, trilinear lookup, majorant cells (medium.h). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"
#include "image_io.h"
#include "medium.h"

static bool has_suffix(const char *s, const char *suffix)
{
    size_t n = strlen(s), k = strlen(suffix);
    if (n < k)
        return false;
    for (size_t i = 0; i < k; i++) {
        char c = s[n - k + i];
        if (c >= 'A' && c <= 'Z')
            c = (char)(c - 'A' + 'a');
        if (c != suffix[i])
            return false;
    }
    return true;
}

static int read_raw(const char *file, size_t count, float *out)
{
    FILE *f = fopen(file, "rb");
    if (!f) {
        dr_set_error("%s: cannot open the density grid: %s", file, strerror(errno));
        return DR_ERR_IO;
    }
    size_t got = fread(out, sizeof(float), count, f);
    int extra = fgetc(f);
    bool err = ferror(f);
    fclose(f);
    if (err) {
        dr_set_error("%s: read error", file);
        return DR_ERR_IO;
    }
    if (got != count || extra != EOF) {
        dr_set_error("%s: the resolution needs exactly %zu bytes of float32 (x fastest, then y, then z); the file "
                     "has %s", file, count * sizeof(float), got != count ? "fewer" : "more");
        return DR_ERR_FORMAT;
    }
    return 0;
}

/* EXR layout: width nx, height ny * nz, z slices top to bottom, first channel. */
static int read_exr(const char *file, int nx, int ny, int nz, float *out)
{
    struct dr_image img = {0};
    int rc = dr_image_read(file, &img);
    if (rc != 0)
        return rc;
    if (img.width != nx || img.height != ny * nz) {
        dr_set_error("%s: the density grid image is %dx%d; resolution [%d, %d, %d] needs width %d and height %d "
                     "(z slices stacked)", file, img.width, img.height, nx, ny, nz, nx, ny * nz);
        dr_image_release(&img);
        return DR_ERR_FORMAT;
    }
    size_t n = (size_t)nx * ny * nz;
    for (size_t i = 0; i < n; i++)
        out[i] = img.data[i * (size_t)img.channels];
    dr_image_release(&img);
    return 0;
}

/* OpenVDB through the image library: the active voxel bounding box of the
 * chosen float grid becomes the nx x ny x nz voxels (medium.h). */
static int read_vdb(const char *file, const char *grid_name, int *n, float **out)
{
    struct dr_volume vol;
    int rc = dr_volume_read(file, grid_name, &vol);
    if (rc != 0)
        return rc;
    if (n[0] > 0 && (vol.nx != n[0] || vol.ny != n[1] || vol.nz != n[2])) {
        dr_set_error("%s: grid '%s' has an active bounding box of %dx%dx%d voxels, but the resolution says "
                     "[%d, %d, %d] (leave resolution out for OpenVDB files)", file, vol.grid, vol.nx, vol.ny, vol.nz,
                     n[0], n[1], n[2]);
        free(vol.data);
        return DR_ERR_FORMAT;
    }
    n[0] = vol.nx;
    n[1] = vol.ny;
    n[2] = vol.nz;
    *out = vol.data;
    return 0;
}

static int read_raw_or_exr(const char *file, const int *n, float **out)
{
    bool raw = has_suffix(file, ".raw") || has_suffix(file, ".f32") || has_suffix(file, ".bin");
    if (!raw && !has_suffix(file, ".exr")) {
        dr_set_error("%s: unknown density grid format (expected .raw/.f32/.bin float32, .exr or .vdb)", file);
        return DR_ERR_FORMAT;
    }
    size_t count = (size_t)n[0] * n[1] * n[2];
    *out = malloc(count * sizeof(float));
    if (!*out) {
        dr_set_error("%s: out of memory for a %dx%dx%d grid", file, n[0], n[1], n[2]);
        return DR_ERR_NOMEM;
    }
    int rc = raw ? read_raw(file, count, *out) : read_exr(file, n[0], n[1], n[2], *out);
    if (rc != 0) {
        free(*out);
        *out = NULL;
    }
    return rc;
}

bool dr_grid_file_is_vdb(const char *file)
{
    return has_suffix(file, ".vdb");
}

int dr_grid_read(const char *file, const char *grid_name, int nx, int ny, int nz, struct dr_grid *g)
{
    memset(g, 0, sizeof *g);
    int n[3] = {nx, ny, nz};
    int rc = dr_grid_file_is_vdb(file) ? read_vdb(file, grid_name, n, &g->density)
                                       : read_raw_or_exr(file, n, &g->density);
    if (rc != 0)
        return rc;
    size_t count = (size_t)n[0] * n[1] * n[2];
    for (size_t i = 0; rc == 0 && i < count; i++)
        if (!(g->density[i] >= 0.0f) || !isfinite(g->density[i])) {
            dr_set_error("%s: voxel (%zu, %zu, %zu) has density %g; densities must be finite and >= 0", file,
                         i % (size_t)n[0], i / (size_t)n[0] % (size_t)n[1], i / ((size_t)n[0] * n[1]),
                         (double)g->density[i]);
            rc = DR_ERR_FORMAT;
        }
    if (rc != 0) {
        dr_grid_release(g);
        return rc;
    }
    g->nx = n[0];
    g->ny = n[1];
    g->nz = n[2];
    return 0;
}

static int ceil_div(int a, int b) { return (a + b - 1) / b; }

static int clampi(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* Largest voxel a trilinear lookup anywhere in cell (cx, cy, cz) can blend:
 * a point at voxel coordinate u blends voxels floor(u - 0.5) and the next. */
static float cell_max(const struct dr_grid *g, int cx, int cy, int cz)
{
    const int B = DR_MAJORANT_CELL;
    int x0 = clampi(cx * B - 1, 0, g->nx - 1), x1 = clampi((cx + 1) * B, 0, g->nx - 1);
    int y0 = clampi(cy * B - 1, 0, g->ny - 1), y1 = clampi((cy + 1) * B, 0, g->ny - 1);
    int z0 = clampi(cz * B - 1, 0, g->nz - 1), z1 = clampi((cz + 1) * B, 0, g->nz - 1);
    float m = 0.0f;
    for (int z = z0; z <= z1; z++)
        for (int y = y0; y <= y1; y++)
            for (int x = x0; x <= x1; x++) {
                float d = g->density[((size_t)z * g->ny + y) * g->nx + x];
                m = d > m ? d : m;
            }
    return m;
}

int dr_grid_build_majorants(struct dr_grid *g)
{
    int mx = ceil_div(g->nx, DR_MAJORANT_CELL), my = ceil_div(g->ny, DR_MAJORANT_CELL),
        mz = ceil_div(g->nz, DR_MAJORANT_CELL);
    if (!g->majorant || g->mx != mx || g->my != my || g->mz != mz) {
        free(g->majorant);
        g->majorant = malloc((size_t)mx * my * mz * sizeof(float));
        if (!g->majorant) {
            dr_set_error("out of memory for the majorant grid");
            return DR_ERR_NOMEM;
        }
    }
    g->mx = mx;
    g->my = my;
    g->mz = mz;
    for (int z = 0; z < mz; z++)
        for (int y = 0; y < my; y++)
            for (int x = 0; x < mx; x++)
                g->majorant[((size_t)z * my + y) * mx + x] = cell_max(g, x, y, z);
    return 0;
}

void dr_grid_release(struct dr_grid *g)
{
    free(g->density);
    free(g->majorant);
    g->density = g->majorant = NULL;
}

/* Voxel coordinate of world coordinate p along one axis (voxel i spans [i, i+1)). */
static double voxel_coord(double p, double lo, double hi, int n)
{
    return (p - lo) / (hi - lo) * n;
}

/* Lower tap and its weight along one axis for voxel coordinate u. */
static void axis_taps(double u, int n, int i[2], double w[2])
{
    double s = u - 0.5;
    double f = floor(s);
    double t = s - f;
    i[0] = clampi((int)f, 0, n - 1);
    i[1] = clampi((int)f + 1, 0, n - 1);
    w[0] = 1.0 - t;
    w[1] = t;
}

double dr_grid_density(const struct dr_grid *g, dr_vec3 p, int64_t idx[8], double w[8])
{
    double ux = voxel_coord(p.x, g->bmin.x, g->bmax.x, g->nx), uy = voxel_coord(p.y, g->bmin.y, g->bmax.y, g->ny),
           uz = voxel_coord(p.z, g->bmin.z, g->bmax.z, g->nz);
    if (!(ux >= 0.0 && ux <= g->nx && uy >= 0.0 && uy <= g->ny && uz >= 0.0 && uz <= g->nz)) {
        for (int k = 0; idx && k < 8; k++) {
            idx[k] = -1;
            w[k] = 0.0;
        }
        return 0.0;
    }
    int ix[2], iy[2], iz[2];
    double wx[2], wy[2], wz[2];
    axis_taps(ux, g->nx, ix, wx);
    axis_taps(uy, g->ny, iy, wy);
    axis_taps(uz, g->nz, iz, wz);
    double d = 0.0;
    for (int k = 0; k < 8; k++) {
        int a = k & 1, b = (k >> 1) & 1, c = (k >> 2) & 1;
        double wk = wx[a] * wy[b] * wz[c];
        int64_t i = ((int64_t)iz[c] * g->ny + iy[b]) * g->nx + ix[a];
        d += wk * g->density[i];
        if (idx) {
            idx[k] = wk != 0.0 ? i : -1;
            w[k] = wk;
        }
    }
    return d;
}
