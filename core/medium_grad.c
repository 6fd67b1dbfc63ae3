/* Derivatives with respect to media parameters (extinction, albedo, g,
 * density scale, voxels), detached sampling (path.h).
 *
 * Marginalising the null collisions, a path's contribution in channel i is a
 * product of segment transmittances T_i = exp(-int sigma_t,i), sigma_s,i at
 * medium vertices, phase values, and the surface terms; the spectral-MIS
 * pdfs are constants of the derivative. So with R = the radiance the path
 * gathers from vertex k on (k's own terms included) and c_nee = k's
 * next-event contribution:
 *   dL/dtheta = sum_k [ -R_k int_seg(k) d sigma_t / dtheta dt            (segment into k)
 *                       + R_k (d sigma_s / dtheta) / sigma_s (x_k)       (scattering at k)
 *                       + R_{k+1} d ln p(g) / dtheta + c_nee d ln p_nee(g) / dtheta
 *                       - c_nee int_shadow(k) d sigma_t / dtheta dt ]
 * The estimators pass R and c_nee (times the adjoint); prb has them from the
 * replay's remaining radiance, tape from its backward sweep: linear time.
 *
 * The segment integrals, two ways (dr_path_opts.medium_grad):
 *  - DRT (default): int d sigma dt estimated with positions drawn uniformly
 *    over the part of the segment where the medium can be non-zero (exact
 *    for homogeneous media), independent of the path's own collisions. In
 *    expectation over those positions this is -T int d sigma, the derivative
 *    of the transmittance the path carries, so it is unbiased everywhere,
 *    including where the density (and so the majorant) is 0: the point of
 *    differential ratio tracking (Nimier-David et al. 2022), whose
 *    reservoir variant picks the position among ratio-tracking collisions.
 *    The gain of sigma_t from gain paths (drt_gain), except in a medium
 *    that is thick or where many stretches end in a collision, where the
 *    path's own collisions estimate it with less noise (gain_at_collisions;
 *    a grid's voxels keep gain paths: gain_from_collisions).
 *  - baseline: differentiate the sampled null collisions of a grid as they
 *    are: sum over the segment's null collisions of -d sigma_t / (majorant -
 *    sigma_t) (and the same for the ratio-tracking factors of shadow rays).
 *    Where the majorant is 0 (empty cells) there are no collisions and no
 *    derivative, and where it is tight (a constant density) there are no
 *    null collisions: biased, as the seed warns; kept to show it. The gain
 *    at the collisions. A homogeneous medium's free flight has no null
 *    collisions (medium.c): there both methods take the exact segment
 *    derivative, and the baseline is unbiased. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "medium_scene.h"
#include "medium_grad.h"

const char *dr_medium_grad_name(enum dr_medium_grad m)
{
    return m == DR_MEDIUM_GRAD_BASELINE ? "baseline" : "drt";
}

int dr_medium_grad_parse(const char *name)
{
    return strcmp(name, "drt") == 0 ? DR_MEDIUM_GRAD_DRT : strcmp(name, "baseline") == 0 ? DR_MEDIUM_GRAD_BASELINE : -1;
}

/* Positions per medium piece for the DRT integral. */
#define DRT_SAMPLES 4

struct dsigma_ctx {
    const struct dr_scene *s;
    const struct dr_param_set *ps;
    struct dr_grad_sink *sink;
    int medium;
    dr_vec3 w;            /* per-channel weight of d sigma_t (x) / dtheta */
    bool over_sigma_n;    /* baseline: divide by majorant - sigma_t */
};

/* The parameters sigma_t depends on, as sets for add_dsigma_t_of. */
enum { DSIGMA_SCALE = 1, DSIGMA_EXTINCTION = 2, DSIGMA_VOXELS = 4, DSIGMA_ALL = 7 };

/* w * d sigma_t,c (x) / dtheta into the requested parameters of the medium
 * among `which` (DSIGMA_*). */
static void add_dsigma_t_of(const struct dr_scene *s, const struct dr_param_set *ps, struct dr_grad_sink *sink,
                            int medium, dr_vec3 x, int c, double w, unsigned which)
{
    const struct dr_medium *m = &s->media[medium];
    int64_t idx[8];
    double wt[8];
    double dens = m->has_grid ? dr_grid_density(&m->grid, x, idx, wt) : 1.0;
    double ext = dr_v3_get(m->extinction, c);
    sink->channel = c;
    if ((which & DSIGMA_SCALE) && ps->med_density_scale[medium] >= 0)
        dr_sink_add(sink, ps->med_density_scale[medium], w * ext * dens);
    if ((which & DSIGMA_EXTINCTION) && ps->med_extinction[medium] >= 0)
        dr_sink_add(sink, ps->med_extinction[medium] + c, w * m->density_scale * dens);
    if ((which & DSIGMA_VOXELS) && m->has_grid && ps->med_density[medium] >= 0)
        for (int k = 0; k < 8; k++)
            if (idx[k] >= 0)
                dr_sink_add(sink, ps->med_density[medium] + idx[k], w * m->density_scale * ext * wt[k]);
}

/* ... into every requested parameter of the medium. */
static void add_dsigma_t(const struct dr_scene *s, const struct dr_param_set *ps, struct dr_grad_sink *sink,
                         int medium, dr_vec3 x, int c, double w)
{
    add_dsigma_t_of(s, ps, sink, medium, x, c, w, DSIGMA_ALL);
}

static void visit_null(void *vctx, dr_vec3 x, double maj)
{
    const struct dsigma_ctx *k = vctx;
    dr_vec3 st = dr_medium_sigma_t(&k->s->media[k->medium], x);
    for (int c = 0; c < 3; c++) {
        double w = dr_v3_get(k->w, c), sn = maj - dr_v3_get(st, c);
        if (w != 0.0 && sn > 0.0)
            add_dsigma_t(k->s, k->ps, k->sink, k->medium, x, c, -w / sn);
    }
}

/* DRT: -w int d sigma_t over the piece, with DRT_SAMPLES stratified positions. */
static void drt_piece(const struct dsigma_ctx *k, const struct dr_medium_piece *pc, dr_vec3 d,
                      struct dr_sampler *rng)
{
    const struct dr_medium *m = &k->s->media[pc->medium];
    double t0 = 0.0, t1 = pc->len;
    if (!dr_medium_clip(m, pc->o, d, &t0, &t1) || isinf(t1))
        return;   /* nothing there, or an unbounded ray whose transmittance is 0 */
    int n = m->has_grid ? DRT_SAMPLES : 1;   /* homogeneous: the integrand is constant */
    double step = (t1 - t0) / n;
    for (int j = 0; j < n; j++) {
        double t = t0 + step * (j + (m->has_grid ? dr_sampler_next(rng) : 0.5));
        dr_vec3 x = dr_madd(pc->o, d, t);
        for (int c = 0; c < 3; c++) {
            double w = dr_v3_get(k->w, c);
            if (w != 0.0)
                add_dsigma_t(k->s, k->ps, k->sink, pc->medium, x, c, -w * step);
        }
    }
}

static bool sigma_t_requested(const struct dr_param_set *ps, int medium)
{
    return ps->med_density[medium] >= 0 || ps->med_density_scale[medium] >= 0 || ps->med_extinction[medium] >= 0;
}

/* The optical thickness (least extinction x mean chord, dr_medium) from
 * which DRT takes a homogeneous medium's gain at the path's collisions
 * without asking the pilot. */
#define COLLISION_GAIN_THICKNESS 1.0
/* Below it, the share of the pilot's stretches through the medium that end
 * in a collision from which the collisions are taken, and the stretches the
 * pilot must have seen there to decide (fewer: gain paths). */
#define COLLISION_GAIN_SHARE 0.4
#define PILOT_MIN_STRETCHES 64

/* Why medium m's gain comes from where it does, under DRT. A channel
 * that does not scatter (no extinction or no albedo) has no collisions to
 * take its gain at; grids and thick homogeneous media need no pilot. */
static enum dr_gain_reason gain_reason(const struct dr_medium *m)
{
    const double least = dr_medium_least_extinction(m);
    if (!(least > 0.0 && m->albedo.x > 0.0 && m->albedo.y > 0.0 && m->albedo.z > 0.0))
        return DR_GAIN_NONSCATTERING;
    if (m->has_grid)
        return DR_GAIN_GRID;
    return least * m->mean_chord >= COLLISION_GAIN_THICKNESS ? DR_GAIN_THICK : DR_GAIN_PILOT;
}

/* Where does the sigma_t share of the scattering derivative come from in
 * medium m: the path's own collisions (d_scatter: R_k d sigma_t / sigma_t),
 * or DRT's gain paths (drt_gain)? Both are unbiased in a homogeneous medium
 * in which every channel scatters (extinction and albedo > 0: free flight
 * can end anywhere in it, and a collision keeps every channel's weight);
 * which is better is the seed's "which when" for media. A gain path
 * estimates the gain apart from the segment's loss (-R int d sigma_t), and
 * in a thick medium the two nearly cancel: measured on a 2 m cube at albedo
 * 0.999 (depth 1000), stderr^2 x seconds of DRT's gain paths over the
 * collisions' was 0.73 at extinction 0.3, 2.2 at 1, 31 at 3, 1.7e3 at 10,
 * 5e4 at 30 (albedo 0.5: 0.41, 3.1, 8.7, 18 at 0.3, 1, 3, 10); in a thin
 * medium collisions are rare and a gain path on every segment wins. So DRT
 * takes the collisions from thickness 1 on, in grids (gain_from_collisions
 * says for which parameters), and in a thinner homogeneous medium where
 * the pilot (estimators/common.c, dr_medium_gain_decide) saw at least
 * COLLISION_GAIN_SHARE of the stretches through it end in a collision:
 * thickness alone misjudged a thin global fog crossed many times a path,
 * and a chromatic medium whose hero channels collide far more often than
 * its least extinction says. Measured in reverse mode (grad --target, L2
 * against a render at 1.5 x the extinction (1.3 x for the cube), 64x64,
 * 512 spp in 64 batches), stderr^2 x seconds of gain paths over collisions
 * per channel, and the pilot's share: fog-khr 0.13-0.21 (0.26), the 0.3
 * cube 0.24-0.27 (0.28), glass-fog 1.2-1.4 (0.24: its paths bounce inside
 * the glass), a 0.5 / 3 / 9 cube 4-44 (0.79), fog-global's global fog
 * (thickness 0.43) 3.4-33 (0.83). Forward-mode images can rank otherwise:
 * fog-global's derivative image had 1.6 x less variance per second per
 * pixel with gain paths (compare, 64x64, 16 x 16 spp). The baseline takes
 * the collisions everywhere, a grid's voxels too (where the density is 0
 * no collision can be: their gain there is missing, part of its bias). */
static bool gain_at_collisions(const struct dr_path_opts *opts, const struct dr_scene *s, int medium)
{
    if (opts->medium_grad == DR_MEDIUM_GRAD_BASELINE)
        return true;
    switch (gain_reason(&s->media[medium])) {
    case DR_GAIN_THICK:
    case DR_GAIN_GRID:
        return true;
    case DR_GAIN_PILOT:
        return opts->collision_gain && opts->collision_gain[medium];
    default:
        return false;
    }
}

bool dr_medium_gain_pilot_wanted(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    if (opts->medium_grad != DR_MEDIUM_GRAD_DRT || !opts->params)
        return false;
    for (int i = 0; i < s->n_media; i++)
        if (sigma_t_requested(opts->params, i) && gain_reason(&s->media[i]) == DR_GAIN_PILOT)
            return true;
    return false;
}

int dr_medium_gain_choices(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_medium_tally *t,
                           struct dr_medium_gain_choice *out, int max)
{
    int n = 0;
    for (int i = 0; opts->medium_grad == DR_MEDIUM_GRAD_DRT && opts->params && i < s->n_media && n < max; i++) {
        if (!sigma_t_requested(opts->params, i))
            continue;
        const enum dr_gain_reason why = gain_reason(&s->media[i]);
        out[n++] = (struct dr_medium_gain_choice){.material = s->media[i].material,
                                                  .collisions = gain_at_collisions(opts, s, i),
                                                  .grid = s->media[i].has_grid, .why = why,
                                                  .stretches = why == DR_GAIN_PILOT && t ? t[i].stretches : 0,
                                                  .collided = why == DR_GAIN_PILOT && t ? t[i].collisions : 0};
    }
    return n;
}

const char *dr_gain_reason_name(enum dr_gain_reason r)
{
    static const char *const names[] = {"nonscattering_channel", "thick", "grid", "pilot"};
    return names[r];
}

void dr_medium_tally_vertex(const struct dr_path_vertex *v, struct dr_medium_tally *t)
{
    if (!v->mrec)
        return;
    const struct dr_medium_trace *tr = &v->mrec->seg;   /* (a crossing without a vertex included) */
    for (int i = 0; i < tr->n; i++)
        t[tr->p[i].medium].stretches++;
    if (v->kind == DR_VERTEX_MEDIUM && v->medium >= 0)
        t[v->medium].collisions++;
}

void dr_media_plan_free(struct dr_media_plan *plan)
{
    free(plan->collision_gain);
    free(plan->tally);
    *plan = (struct dr_media_plan){0};
}

uint64_t dr_media_values_hash(const struct dr_scene *s, uint64_t h)
{
    for (int i = 0; i < s->n_media; i++) {
        const struct dr_medium *m = &s->media[i];
        const double v[] = {m->extinction.x, m->extinction.y, m->extinction.z, m->albedo.x, m->albedo.y,
                            m->albedo.z, m->g, m->density_scale, m->mean_chord, m->ior};
        for (size_t k = 0; k < sizeof v / sizeof v[0]; k++) {
            uint64_t bits;
            memcpy(&bits, &v[k], sizeof bits);
            h = dr_hash64(h ^ bits);
        }
    }
    return h;
}

void dr_medium_gain_decide(const struct dr_scene *s, const struct dr_medium_tally *t, unsigned char *collision_gain)
{
    for (int i = 0; i < s->n_media; i++)
        collision_gain[i] = t[i].stretches >= PILOT_MIN_STRETCHES &&
                            (double)t[i].collisions >= COLLISION_GAIN_SHARE * (double)t[i].stretches;
}

/* Which of medium i's sigma_t parameters (DSIGMA_*) take their gain from
 * the path's collisions (d_scatter), the others' coming from DRT's gain
 * paths: all of them where gain_at_collisions says so, except a grid's
 * voxels. In a grid the collisions fall where the density is, while a gain
 * path's uniform position mostly does not: extinction and density scale,
 * whose share of sigma_t at a collision is a constant (1 / extinction,
 * 1 / density scale; and 0 where the density is 0, where no collision can
 * be), measured on the smoke grid (reverse mode, 64x64, 256 spp in 32
 * batches, stderr^2 x seconds of gain paths over collisions) 4.7 to 7.2 at
 * its density, 10.5 to 12 at 5 x, and 0.86 to 1.5 at 0.2 x (where 0.09 of
 * the stretches collide). A voxel's share, its trilinear weight / the
 * density there, is unbounded where the density is small (near an empty
 * region: where it is 0 only gain paths see it), and at 5 x the voxels'
 * gradient had 4.2 x the variance per second with collisions. */
static unsigned gain_from_collisions(const struct dr_path_opts *opts, const struct dr_scene *s, int i)
{
    if (!gain_at_collisions(opts, s, i))
        return 0;
    return opts->medium_grad == DR_MEDIUM_GRAD_DRT && s->media[i].has_grid ? DSIGMA_SCALE | DSIGMA_EXTINCTION
                                                                           : DSIGMA_ALL;
}

/* ... and the others, of those requested (0: none). */
static unsigned gain_from_paths(const struct dr_path_opts *opts, const struct dr_scene *s, int i)
{
    const struct dr_param_set *ps = opts->params;
    const unsigned requested = (ps->med_density_scale[i] >= 0 ? DSIGMA_SCALE : 0) |
                               (ps->med_extinction[i] >= 0 ? DSIGMA_EXTINCTION : 0) |
                               (s->media[i].has_grid && ps->med_density[i] >= 0 ? DSIGMA_VOXELS : 0);
    return requested & ~gain_from_collisions(opts, s, i);
}

/* Does some medium take DRT's gain paths anywhere? */
static bool gain_paths_needed(const struct dr_scene *s, const struct dr_path_opts *opts)
{
    for (int i = 0; i < s->n_media; i++)
        if (gain_from_paths(opts, s, i))
            return true;
    return false;
}

/* A position in the stretch [t0, t1) of medium m for the gain term, and
 * 1 / its density: uniform when the stretch is finite; exponential at the
 * medium's smallest non-zero extinction when it is not (an unbounded
 * homogeneous medium: every channel's transmittance decays at least that
 * fast, so the weights T / pdf stay bounded). False: nothing to sample. */
static bool stretch_sample(const struct dr_medium *m, double t0, double t1, double u, double *t, double *inv_pdf)
{
    if (!isinf(t1)) {
        *t = t0 + (t1 - t0) * u;
        *inv_pdf = t1 - t0;
        return true;
    }
    double rate = INFINITY;
    for (int c = 0; c < 3; c++)
        if (dr_v3_get(m->extinction, c) > 0.0)
            rate = dr_min(rate, m->density_scale * dr_v3_get(m->extinction, c));
    if (!(rate > 0.0) || isinf(rate))
        return false;   /* a clear unbounded medium: infinitely long, transmittance 1: not differentiable */
    double s = -log1p(-u) / rate;
    *t = t0 + s;
    *inv_pdf = exp(rate * s) / rate;
    return isfinite(*inv_pdf);
}

/* DRT's gain term of the segment into v: scattering that a change of
 * sigma_t would add anywhere along the ray the segment started on (up to the
 * first opaque surface, through every medium on the way, beyond where this
 * path happened to stop, and where there is no medium yet: where the path's
 * own collisions cannot go), for the parameters gain_from_paths names. Per
 * medium stretch [t0, t1), x uniform in it:
 *   d_beta T(start, x) (d sigma_s(x) / dtheta) L_s(x) (t1 - t0),
 * with T by ratio tracking (exact when homogeneous) and L_s, the light
 * scattered at x per unit sigma_s, from a fresh path (dr_medium_inscattered). */
static void drt_gain(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                     const struct dr_medium_trace *tr, dr_vec3 d_beta, struct dr_grad_sink *sink)
{
    struct dr_sampler rng = {.key = dr_hash64(tr->rng_key ^ 0x7f4a7c159e3779b9ULL), .dim = 0};
    dr_vec3 o = tr->o0, d = tr->d, T = d_beta;
    int medium = tr->medium0;
    for (int crossing = 0; crossing < 64 && !dr_is_black(T); crossing++) {
        int64_t tri = dr_accel_intersect_key(s->accel, o, d, 0.0, INFINITY, dr_hash64(tr->rng_key ^ 0x2545f4914f6cdd1dULL));
        struct dr_hit h;
        double seg = INFINITY;
        if (tri >= 0) {
            dr_hit_locate(&s->mesh, tri, o, d, &h);   /* (a boundary: no shading) */
            seg = dr_dot(dr_sub(h.p, o), d);
        }
        if (medium >= 0) {
            const struct dr_medium *m = &s->media[medium];
            double t0 = 0.0, t1 = seg, t, inv_pdf;
            const unsigned which = gain_from_paths(opts, s, medium);
            if (which && dr_medium_clip(m, o, d, &t0, &t1) &&
                stretch_sample(m, t0, t1, dr_sampler_next(&rng), &t, &inv_pdf)) {
                dr_vec3 x = dr_madd(o, d, t);
                dr_vec3 w = dr_mul(dr_mul(T, dr_medium_transmittance(m, o, d, t, &rng)), m->albedo);
                if (!dr_is_black(w)) {
                    struct dr_ray_counts counts = {0};
                    uint64_t key = dr_hash64(tr->rng_key ^ (0x9e3779b97f4a7c15ULL * (uint64_t)(crossing + 1)));
                    dr_vec3 Ls = dr_medium_inscattered(s, opts, x, d, medium, v->depth, key, &counts);
                    for (int c = 0; c < 3; c++) {
                        double wc = dr_v3_get(w, c) * dr_v3_get(Ls, c) * inv_pdf;
                        if (wc != 0.0)
                            add_dsigma_t_of(s, opts->params, sink, medium, x, c, wc, which);
                    }
                }
            }
            T = dr_mul(T, dr_medium_transmittance(m, o, d, seg, &rng));
        }
        int med = tri >= 0 ? dr_boundary_medium(s, tri) : -1;
        if (tri < 0 || med < 0 || dr_boundary_dielectric(s, med))
            return;   /* the ray ends there (a dielectric: the segment's vertex; the next segment has its own) */
        medium = h.front ? med : s->global_medium;
        o = dr_offset_origin(&h, h.ng, d);
    }
}

/* The transmittance derivative of a recorded crossing, weighted by w. */
static void d_trace(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_medium_trace *tr,
                    bool shadow, dr_vec3 w, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    for (int i = 0; i < tr->n; i++) {
        const struct dr_medium_piece *pc = &tr->p[i];
        if (!ps->med_active[pc->medium])
            continue;
        struct dsigma_ctx k = {s, ps, sink, pc->medium, w, false};
        const struct dr_medium *m = &s->media[pc->medium];
        /* homogeneous: exact transmittance (shadow rays) or a free flight
         * without null collisions (homogeneous_sample): the exact derivative */
        bool exact = !m->has_grid;
        if (opts->medium_grad == DR_MEDIUM_GRAD_DRT || exact) {
            struct dr_sampler rng = {.key = dr_hash64(tr->rng_key ^ 0x5bd1e9955bd1e995ULL), .dim = (uint32_t)i << 16};
            drt_piece(&k, pc, tr->d, &rng);
            continue;
        }
        struct dr_sampler rng = {.key = tr->rng_key, .dim = pc->rng_dim};
        if (shadow)
            dr_medium_replay_ratio_tracking(m, pc->o, tr->d, pc->len, &rng, visit_null, &k);
        else
            dr_medium_replay_nulls(m, pc->o, tr->d, pc->len, &rng, visit_null, &k);
    }
}

/* Scattering at a medium vertex: (d sigma_s / dtheta) / sigma_s, and g.
 * The sigma_t parameters' share of sigma_s is taken here where the gain
 * comes from the collisions (gain_from_collisions: the baseline, and DRT in
 * a medium that is thick or often collided in, a grid's voxels aside);
 * the others' is the gain paths' (drt_gain). */
static void d_scatter(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                      dr_vec3 d_R, dr_vec3 d_Rn, dr_vec3 d_nee, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    const int mi = v->medium;
    const struct dr_medium *m = &s->media[mi];
    dr_vec3 st = dr_medium_sigma_t(m, v->hit.p);
    const unsigned sigma_t_here = sigma_t_requested(ps, mi) ? gain_from_collisions(opts, s, mi) : 0;
    for (int c = 0; c < 3; c++) {
        double w = dr_v3_get(d_R, c), a = dr_v3_get(m->albedo, c), t = dr_v3_get(st, c);
        if (w == 0.0)
            continue;
        sink->channel = c;
        if (ps->med_albedo[mi] >= 0 && a > 0.0)
            dr_sink_add(sink, ps->med_albedo[mi] + c, w / a);
        if (t > 0.0 && sigma_t_here)
            add_dsigma_t_of(s, ps, sink, mi, v->hit.p, c, w / t, sigma_t_here);
    }
    if (ps->med_g[mi] < 0)
        return;
    double dcont = v->cont ? dr_hg_dlog_dg(m->g, dr_dot(v->d, v->wi)) : 0.0;
    double dnee = v->nee ? dr_hg_dlog_dg(m->g, dr_dot(v->d, v->nee_wi)) : 0.0;
    for (int c = 0; c < 3; c++) {
        sink->channel = c;
        dr_sink_add(sink, ps->med_g[mi], dr_v3_get(d_Rn, c) * dcont + dr_v3_get(d_nee, c) * dnee);
    }
}

/* DRT's gain term traces a path from a point of the segment: done at every
 * vertex, a path of n vertices would cost n^2. So a vertex does it with
 * probability min(1, GAIN_PATHS / n), weighted by the inverse: about
 * GAIN_PATHS gain paths per path, linear time, unbiased; every vertex of
 * paths of up to GAIN_PATHS vertices. */
#define GAIN_PATHS 8

bool dr_medium_vertex_has_derivative(const struct dr_param_set *ps, const struct dr_path_vertex *v)
{
    if (!v->media || !v->mrec || !ps || !ps->media_active)
        return false;
    const bool scattered = v->kind == DR_VERTEX_MEDIUM && v->shaded && ps->med_active[v->medium];
    return scattered || v->mrec->seg.n > 0 || (v->nee && v->mrec->shadow.n > 0);
}

void d_medium_vertex(const struct dr_scene *s, const struct dr_path_opts *opts, const struct dr_path_vertex *v,
                     const struct dr_medium_record *rec, int path_vertices, dr_vec3 d_beta, dr_vec3 d_R,
                     dr_vec3 d_Rn, dr_vec3 d_nee, struct dr_grad_sink *sink)
{
    const struct dr_param_set *ps = opts->params;
    if (!v->media || !rec || !ps || !ps->media_active)
        return;
    if (!dr_is_black(d_R))
        d_trace(s, opts, &rec->seg, false, d_R, sink);
    if (opts->medium_grad == DR_MEDIUM_GRAD_DRT && !dr_is_black(d_beta) && gain_paths_needed(s, opts)) {
        double p = path_vertices > GAIN_PATHS ? (double)GAIN_PATHS / path_vertices : 1.0;
        double u = dr_hash_unit(dr_hash64(rec->seg.rng_key ^ 0x2545f4914f6cdd1dULL));
        if (u < p)
            drt_gain(s, opts, v, &rec->seg, dr_scale(d_beta, 1.0 / p), sink);
    }
    if (v->kind == DR_VERTEX_MEDIUM && v->shaded && ps->med_active[v->medium])
        d_scatter(s, opts, v, d_R, d_Rn, d_nee, sink);
    if (v->nee && !dr_is_black(d_nee))
        d_trace(s, opts, &rec->shadow, true, d_nee, sink);
}
