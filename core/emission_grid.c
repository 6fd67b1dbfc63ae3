/* Emissive textures' footprints on triangles (emission_grid.h). */
#include "emission_grid.h"

#include <math.h>
#include <stdlib.h>

#include "geometry.h"
#include "image.h"
#include "parallel.h"

struct dr_emission_grid {
    int w, h;          /* the image's texels */
    int s;             /* texels per cell side */
    int gw, gh;        /* cells */
    double *sum;       /* (gh + 1) x (gw + 1) summed-area table of the texels' emission */
    uint32_t *lit;     /* the same of their count of texels that are not zero */
};

/* Reads texels' emission as dr_emission reads them: the mean of their colour
 * channels' decoded values (their magnitudes: a test for zero must not let
 * values cancel). For eight-bit storage the colour channels' table is chosen
 * once (dr_image_value's choice: the decoded one where there is one) rather
 * than per value: a 2k texture's grid is built while the first ray waits. */
struct texel_reader {
    const struct dr_image *img;
    int c;                /* colour channels */
    const float *table;   /* eight-bit storage: a colour channel's value by byte */
};

static struct texel_reader texel_reader(const struct dr_image *img)
{
    struct texel_reader r = {.img = img, .c = dr_image_colour_channels(img->channels)};
    r.table = img->lut_linear ? img->lut_linear : img->lut;
    return r;
}

static double texel_emission(const struct texel_reader *r, size_t i)
{
    const struct dr_image *img = r->img;
    double e = 0.0;
    if (img->bytes) {
        const uint8_t *b = img->bytes + i * (size_t)img->channels;
        for (int k = 0; k < r->c; k++)
            e += fabs(r->table[b[k]]);
    } else {
        for (int k = 0; k < r->c; k++)
            e += fabs(dr_image_value(img, i * (size_t)img->channels + (size_t)k, true));
    }
    return e / r->c;
}

/* Row y's texels added to their cells' own sums (row cy + 1 of the tables),
 * cell by cell, each cell's sum kept in a register: the same additions in
 * the same order as texel by texel. */
static void add_row(struct dr_emission_grid *g, const struct texel_reader *r, int y)
{
    const size_t stride = (size_t)g->gw + 1, row = (size_t)(y / g->s + 1) * stride;
    for (int cx = 0; cx < g->gw; cx++) {
        const int x0 = cx * g->s, x1 = x0 + g->s < g->w ? x0 + g->s : g->w;
        double sum = g->sum[row + (size_t)cx + 1];
        uint32_t lit = g->lit[row + (size_t)cx + 1];
        for (int x = x0; x < x1; x++) {
            const double e = texel_emission(r, (size_t)y * (size_t)g->w + (size_t)x);
            sum += e;
            lit += e != 0.0;
        }
        g->sum[row + (size_t)cx + 1] = sum, g->lit[row + (size_t)cx + 1] = lit;
    }
}

/* Rows of cells [begin, end): their texel rows added (add_row). */
struct cell_rows {
    struct dr_emission_grid *g;
    struct texel_reader r;
};

static void add_cell_rows(void *ctx, int thread, int64_t begin, int64_t end)
{
    (void)thread;
    const struct cell_rows *x = ctx;
    const int s = x->g->s, h = x->g->h;
    for (int64_t cy = begin; cy < end; cy++)
        for (int y = (int)cy * s; y < (int)(cy + 1) * s && y < h; y++)
            add_row(x->g, &x->r, y);
}

struct dr_emission_grid *dr_emission_grid_create(const struct dr_image *img)
{
    struct dr_emission_grid *g = calloc(1, sizeof *g);
    if (!g)
        return NULL;
    g->w = img->width, g->h = img->height;
    const int side = g->w > g->h ? g->w : g->h;
    g->s = (side + DR_EMISSION_GRID_CELLS - 1) / DR_EMISSION_GRID_CELLS;
    g->gw = (g->w + g->s - 1) / g->s, g->gh = (g->h + g->s - 1) / g->s;
    const size_t stride = (size_t)g->gw + 1, n = stride * ((size_t)g->gh + 1);
    g->sum = calloc(n, sizeof *g->sum);
    g->lit = calloc(n, sizeof *g->lit);
    if (!g->sum || !g->lit) {
        dr_emission_grid_destroy(g);
        return NULL;
    }
    /* the cells' own sums at [cy + 1][cx + 1], a row of cells per task
     * (each writes its own row of the tables, adding its texel rows in
     * order: the same sums on any number of workers; a 2k texture's 4 M
     * texels were 20 ms of a textured scene's start on one), then the
     * running sums */
    struct cell_rows x = {g, texel_reader(img)};
    if (dr_parallel_for(g->gh, 1, 0, add_cell_rows, &x) != 0)
        add_cell_rows(&x, 0, 0, g->gh);
    for (size_t cy = 1; cy <= (size_t)g->gh; cy++)
        for (size_t cx = 1; cx <= (size_t)g->gw; cx++) {
            const size_t at = cy * stride + cx;
            g->sum[at] += g->sum[at - 1] + g->sum[at - stride] - g->sum[at - stride - 1];
            g->lit[at] += g->lit[at - 1] + g->lit[at - stride] - g->lit[at - stride - 1];
        }
    return g;
}

void dr_emission_grid_destroy(struct dr_emission_grid *g)
{
    if (g) {
        free(g->sum);
        free(g->lit);
    }
    free(g);
}

double dr_emission_grid_mean(const struct dr_emission_grid *g)
{
    return g->sum[((size_t)g->gw + 1) * ((size_t)g->gh + 1) - 1] / ((double)g->w * g->h);
}

/* Texel intervals [lo[k], hi[k]] of one axis (n texels) that bilinear
 * lookups at coordinates in [t0, t1] can read under wrap mode: the taps
 * floor(t n - 1/2) and the next, as dr_texture_taps takes them, one texel
 * more on each side for rounding (the lookup interpolates the vertices' uv
 * and transforms it; the bounds transform the vertices). Returns how many
 * intervals: 1, or 2 where REPEAT wraps. */
static int axis_texels(double t0, double t1, int n, enum dr_wrap mode, int lo[2], int hi[2])
{
    lo[0] = 0, hi[0] = n - 1;   /* every texel: the answer wherever the range is not simple */
    if (!isfinite(t0) || !isfinite(t1))
        return 1;
    if (mode == DR_WRAP_REPEAT) {   /* into [0, 2): the lookup reduces t - floor(t) */
        if (t1 - t0 >= 1.0)
            return 1;
        const double k = floor(t0);
        t0 -= k, t1 -= k;
    } else if (mode == DR_WRAP_CLAMP) {   /* (reduce_coord's clamp; the indices clamp below) */
        t0 = fmin(fmax(t0, -1.0), 2.0), t1 = fmin(fmax(t1, -1.0), 2.0);
    } else if (t0 < 0.0 || t1 > 1.0) {   /* MIRROR beyond one period: every texel */
        return 1;
    }
    const double a = floor(t0 * n - 0.5) - 1.0, b = floor(t1 * n - 0.5) + 2.0;
    if (mode != DR_WRAP_REPEAT) {   /* clamped (MIRROR in [0, 1] reflects the margin's into it) */
        lo[0] = (int)fmin(fmax(a, 0.0), n - 1.0);
        hi[0] = (int)fmin(fmax(b, 0.0), n - 1.0);
        return 1;
    }
    if (b - a + 1.0 >= n)
        return 1;
    const int first = (int)(a - n * floor(a / n)), last = first + (int)(b - a);   /* a mod n, to last */
    lo[0] = first, hi[0] = last < n ? last : n - 1;
    if (last < n)
        return 1;
    lo[1] = 0, hi[1] = last - n;
    return 2;
}

/* Cells [cx0, cx1] x [cy0, cy1]'s sums from the tables. */
static void cells(const struct dr_emission_grid *g, int cx0, int cx1, int cy0, int cy1, double *sum, uint64_t *lit)
{
    const size_t stride = (size_t)g->gw + 1;
    const size_t a = (size_t)cy0 * stride + (size_t)cx0, b = (size_t)cy0 * stride + (size_t)cx1 + 1,
                 c = ((size_t)cy1 + 1) * stride + (size_t)cx0, d = ((size_t)cy1 + 1) * stride + (size_t)cx1 + 1;
    *sum += g->sum[d] - g->sum[b] - g->sum[c] + g->sum[a];
    *lit += (uint64_t)g->lit[d] - g->lit[b] - g->lit[c] + g->lit[a];
}

bool dr_emission_footprint(const struct dr_emission_grid *g, const struct dr_mesh *m, const struct dr_texref *r,
                           const struct dr_texture *tex, uint32_t tri, double *mean)
{
    double corner[3][2] = {{0.0, 0.0}, {1.0, 0.0}, {0.0, 1.0}};   /* (b1, b2) of the vertices */
    struct dr_footprint f;
    const bool any = dr_emission_footprint_part(g, m, r, tex, tri, corner, &f);
    *mean = f.mean;
    return any;
}

bool dr_emission_footprint_part(const struct dr_emission_grid *g, const struct dr_mesh *m, const struct dr_texref *r,
                                const struct dr_texture *tex, uint32_t tri, double corner[3][2],
                                struct dr_footprint *out)
{
    double u0 = INFINITY, u1 = -INFINITY, v0 = INFINITY, v1 = -INFINITY;
    for (int k = 0; k < 3; k++) {
        struct dr_hit h;   /* the lookup's own uv at the vertex: its set, through its transform */
        double uv[2];
        dr_hit_at(m, tri, corner[k][0], corner[k][1], &h);
        dr_texref_uv(m, r, &h, uv);
        u0 = fmin(u0, uv[0]), u1 = fmax(u1, uv[0]);
        v0 = fmin(v0, uv[1]), v1 = fmax(v1, uv[1]);
    }
    int xl[2], xh[2], yl[2], yh[2];
    const int nx = axis_texels(u0, u1, g->w, tex->wrap_s, xl, xh), ny = axis_texels(v0, v1, g->h, tex->wrap_t, yl, yh);
    double sum = 0.0;
    uint64_t lit = 0, texels = 0;
    for (int i = 0; i < nx; i++)
        for (int j = 0; j < ny; j++) {
            const int cx0 = xl[i] / g->s, cx1 = xh[i] / g->s, cy0 = yl[j] / g->s, cy1 = yh[j] / g->s;
            cells(g, cx0, cx1, cy0, cy1, &sum, &lit);
            const int64_t tw = ((cx1 + 1) * g->s < g->w ? (cx1 + 1) * g->s : g->w) - cx0 * g->s;
            const int64_t th = ((cy1 + 1) * g->s < g->h ? (cy1 + 1) * g->s : g->h) - cy0 * g->s;
            texels += (uint64_t)(tw * th);
        }
    out->mean = texels > 0 && sum > 0.0 ? sum / (double)texels : 0.0;
    out->texels = (double)texels;
    out->lit = (double)lit;
    return lit > 0;
}
