/* Free-flight sampling, transmittance and the phase function (medium.h). */
#include "medium.h"

#include <math.h>
#include <stddef.h>

dr_vec3 dr_medium_sigma_t(const struct dr_medium *m, dr_vec3 p)
{
    double d = m->has_grid ? dr_grid_density(&m->grid, p, NULL, NULL) : 1.0;
    return dr_scale(m->extinction, m->density_scale * d);
}

/* ------------------------------------------------------ majorant segments */

/* Walks the ray through the majorant cells: each call yields the next
 * segment [t0, t1) with one majorant (extinction, 1/m). A homogeneous medium
 * is one segment. */
struct majorant_walk {
    const struct dr_medium *m;
    double scale;            /* density -> extinction majorant */
    double t, t_end;
    bool done;
    /* DDA state (grids only) */
    int cell[3], step[3], n_cells[3];
    double t_next[3], t_delta[3];
};

static double axis_get(dr_vec3 v, int a) { return a == 0 ? v.x : (a == 1 ? v.y : v.z); }

/* Clips [*t0, *t1) to the box; false when nothing is left. */
static bool clip_to_box(dr_vec3 bmin, dr_vec3 bmax, dr_vec3 o, dr_vec3 d, double *t0, double *t1)
{
    for (int a = 0; a < 3; a++) {
        double oa = axis_get(o, a), da = axis_get(d, a), lo = axis_get(bmin, a), hi = axis_get(bmax, a);
        if (da == 0.0) {
            if (oa < lo || oa > hi)
                return false;
            continue;
        }
        double ta = (lo - oa) / da, tb = (hi - oa) / da;
        if (ta > tb) {
            double tmp = ta;
            ta = tb;
            tb = tmp;
        }
        *t0 = ta > *t0 ? ta : *t0;
        *t1 = tb < *t1 ? tb : *t1;
    }
    return *t0 < *t1;
}

static void walk_start(struct majorant_walk *w, const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax)
{
    w->m = m;
    w->scale = m->density_scale * dr_max3(m->extinction);
    w->t = 0.0;
    w->t_end = tmax;
    w->done = false;
    if (m->bounded && !clip_to_box(m->bmin, m->bmax, o, d, &w->t, &w->t_end)) {
        w->done = true;
        return;
    }
    if (!m->has_grid)
        return;
    const struct dr_grid *g = &m->grid;
    if (!clip_to_box(g->bmin, g->bmax, o, d, &w->t, &w->t_end)) {
        w->done = true;
        return;
    }
    const int n[3] = {g->nx, g->ny, g->nz};
    w->n_cells[0] = g->mx;
    w->n_cells[1] = g->my;
    w->n_cells[2] = g->mz;
    for (int a = 0; a < 3; a++) {
        double lo = axis_get(g->bmin, a), ext = axis_get(g->bmax, a) - lo;
        double vo = (axis_get(o, a) - lo) / ext * n[a];      /* voxel coordinates */
        double vd = axis_get(d, a) / ext * n[a];
        double v_in = vo + vd * w->t;
        int c = (int)floor(v_in / DR_MAJORANT_CELL);
        w->cell[a] = c < 0 ? 0 : (c >= w->n_cells[a] ? w->n_cells[a] - 1 : c);
        if (vd > 0.0) {
            w->step[a] = 1;
            w->t_next[a] = ((w->cell[a] + 1) * DR_MAJORANT_CELL - vo) / vd;
            w->t_delta[a] = DR_MAJORANT_CELL / vd;
        } else if (vd < 0.0) {
            w->step[a] = -1;
            w->t_next[a] = (w->cell[a] * DR_MAJORANT_CELL - vo) / vd;
            w->t_delta[a] = -DR_MAJORANT_CELL / vd;
        } else {
            w->step[a] = 0;
            w->t_next[a] = INFINITY;
            w->t_delta[a] = INFINITY;
        }
    }
}

static bool walk_next(struct majorant_walk *w, double *t0, double *t1, double *majorant)
{
    if (w->done || !(w->t < w->t_end))
        return false;
    if (!w->m->has_grid) {
        *t0 = w->t;
        *t1 = w->t_end;
        *majorant = w->scale;
        w->done = true;
        return true;
    }
    const struct dr_grid *g = &w->m->grid;
    int a = w->t_next[0] < w->t_next[1] ? (w->t_next[0] < w->t_next[2] ? 0 : 2) : (w->t_next[1] < w->t_next[2] ? 1 : 2);
    *t0 = w->t;
    *t1 = w->t_next[a] < w->t_end ? w->t_next[a] : w->t_end;
    *majorant = w->scale * g->majorant[((size_t)w->cell[2] * g->my + w->cell[1]) * g->mx + w->cell[0]];
    w->t = *t1;
    w->cell[a] += w->step[a];
    w->t_next[a] += w->t_delta[a];
    if (w->cell[a] < 0 || w->cell[a] >= w->n_cells[a])
        w->done = true;
    return true;
}

/* ------------------------------------------------------------- tracking */

/* Free flight with spectral MIS (Miller et al. 2019, "A null-scattering
 * path integral formulation of light transport"; the one-sample form pbrt-v4
 * uses with a hero wavelength). All channels share the scalar majorant, so
 * tentative collisions are the same for all; the path's hero channel c
 * decides each collision with its own probabilities sigma_a[c], sigma_s[c],
 * sigma_n[c] over the majorant. The analog probability of the path's event
 * sequence for channel i is the product of its own coefficients, p_i, so
 * channel i is weighted p_i / mean_j(p_j) (the balance heuristic over the
 * three channels as strategies, dr_spectral_mis_weight): at most 3 whatever
 * the ratio of extinctions. r[j] is p_j up to a common factor. */
static enum dr_medium_event collide(const struct dr_medium *m, dr_vec3 x, double maj, double u,
                                    struct dr_spectral_mis *mis)
{
    dr_vec3 st = dr_medium_sigma_t(m, x);
    int c = mis->hero;
    /* the majorant is a maximum over the same voxels: sigma_n >= 0 up to rounding */
    double t[3] = {dr_min(st.x, maj), dr_min(st.y, maj), dr_min(st.z, maj)};
    double a[3] = {m->albedo.x, m->albedo.y, m->albedo.z};
    double ps = t[c] * a[c] / maj, pa = t[c] * (1.0 - a[c]) / maj;
    if (u < pa)
        return DR_MEDIUM_ABSORB;
    bool scatter = u < pa + ps;
    double big = 0.0;
    for (int j = 0; j < 3; j++) {
        mis->r[j] *= scatter ? t[j] * a[j] / (t[c] * a[c]) : (maj - t[j]) / (maj - t[c]);
        big = dr_max(big, mis->r[j]);
    }
    if (big > 1e100)   /* only ratios matter */
        for (int j = 0; j < 3; j++)
            mis->r[j] *= 1e-100;
    return scatter ? DR_MEDIUM_SCATTER : DR_MEDIUM_PASS;
}

dr_vec3 dr_spectral_mis_weight(const struct dr_spectral_mis *mis)
{
    double mean = (mis->r[0] + mis->r[1] + mis->r[2]) * (1.0 / 3.0);
    if (!(mean > 0.0))
        return dr_v3s(0.0);
    return dr_scale(dr_v3(mis->r[0], mis->r[1], mis->r[2]), 1.0 / mean);
}

/* Keeps the channels' probabilities (which only matter as ratios) away
 * from overflow and underflow. */
static void rescale(struct dr_spectral_mis *mis)
{
    const double big = dr_max(mis->r[0], dr_max(mis->r[1], mis->r[2]));
    if (big > 1e100 || (big > 0.0 && big < 1e-100))
        for (int j = 0; j < 3; j++)
            mis->r[j] /= big;
}

double dr_medium_least_extinction(const struct dr_medium *m)
{
    const dr_vec3 st = dr_scale(m->extinction, m->density_scale);
    return dr_max(0.0, dr_min(st.x, dr_min(st.y, st.z)));
}

/* The ray's stretch [t0, t1) of the medium up to tmax (false: none, and
 * no number drawn), and then the hero channel c's flight s from t0 and the
 * event's number u_event, drawn from rng: homogeneous_sample's and
 * dr_medium_collision_ahead's, the same operations. */
static bool homogeneous_flight(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax, int c,
                               struct dr_sampler *rng, double *t0, double *t1, double *s, double *u_event)
{
    *t0 = 0.0, *t1 = tmax;
    if (m->bounded && !clip_to_box(m->bmin, m->bmax, o, d, t0, t1))
        return false;   /* (no collision outside the box: walk_start's clip) */
    if (!(*t0 < *t1))
        return false;
    const double u_flight = dr_sampler_next(rng);
    *u_event = dr_sampler_next(rng);
    const double sig = m->density_scale * dr_v3_get(m->extinction, c);   /* (dr_scale's product) */
    *s = sig > 0.0 ? -log1p(-u_flight) / sig : INFINITY;
    return true;
}

/* Free flight in a homogeneous medium: the hero channel c's own flight,
 * exponential at its extinction, no null collisions. Delta tracking against
 * the largest channel's extinction took a step per tentative collision:
 * (largest / hero's) steps per real one, which made a dense medium with
 * chromatic extinction (10^4 / 10^3 / 10^2) walk a hundred steps for each,
 * and a channel that does not attenuate at all (extinction 0) walk for ever
 * along a ray leaving an unbounded medium. Each channel's probability of the
 * same events, sigma_s,j exp(-sigma_t,j s) for a scattering at s and
 * exp(-sigma_t,j len) for a pass, goes into mis->r; taken relative to the
 * least extinction's exp(-sigma_min s), a common factor, so that no
 * exponent is positive (only ratios of r matter). Two uniforms a call. */
static enum dr_medium_event homogeneous_sample(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                               struct dr_sampler *rng, struct dr_spectral_mis *mis, double *t_out)
{
    const int c = mis->hero;
    double t0, t1, s, u_event;
    if (!homogeneous_flight(m, o, d, tmax, c, rng, &t0, &t1, &s, &u_event))
        return DR_MEDIUM_PASS;
    const dr_vec3 st = dr_scale(m->extinction, m->density_scale);
    const double sig[3] = {st.x, st.y, st.z}, a[3] = {m->albedo.x, m->albedo.y, m->albedo.z};
    const double least = dr_min(sig[0], dr_min(sig[1], sig[2]));
    const bool collides = t0 + s < t1;
    const double len = collides ? s : t1 - t0;
    if (collides && u_event < 1.0 - a[c]) {
        *t_out = t0 + s;
        return DR_MEDIUM_ABSORB;   /* (the path ends: its weights no longer matter) */
    }
    for (int j = 0; j < 3; j++) {
        const double excess = sig[j] - least;   /* >= 0; 0 x infinity is no decay */
        mis->r[j] *= excess > 0.0 ? exp(-excess * len) : 1.0;
        if (collides)
            mis->r[j] *= a[j] * sig[j] / (a[c] * sig[c]);   /* (a[c] sig[c] > 0: it scattered) */
    }
    rescale(mis);
    if (!collides)
        return DR_MEDIUM_PASS;
    *t_out = t0 + s;
    return DR_MEDIUM_SCATTER;
}

double dr_medium_collision_ahead(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, struct dr_sampler rng, int hero)
{
    double t0, t1, s, u_event;
    if (m->has_grid || !homogeneous_flight(m, o, d, INFINITY, hero, &rng, &t0, &t1, &s, &u_event))
        return INFINITY;
    return t0 + s < t1 ? t0 + s : INFINITY;
}

enum dr_medium_event dr_medium_sample(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                      struct dr_sampler *rng, struct dr_spectral_mis *mis, double *t_out)
{
    if (!m->has_grid)
        return homogeneous_sample(m, o, d, tmax, rng, mis, t_out);
    struct majorant_walk walk;
    double t0, t1, maj;
    walk_start(&walk, m, o, d, tmax);
    while (walk_next(&walk, &t0, &t1, &maj)) {
        if (!(maj > 0.0))
            continue;
        for (double t = t0;;) {
            t -= log1p(-dr_sampler_next(rng)) / maj;
            if (!(t < t1))
                break;
            enum dr_medium_event ev = collide(m, dr_madd(o, d, t), maj, dr_sampler_next(rng), mis);
            if (ev != DR_MEDIUM_PASS) {
                *t_out = t;
                return ev;
            }
        }
    }
    return DR_MEDIUM_PASS;
}

/* Ratio tracking with Russian roulette once the estimate is small, so a
 * dense grid does not walk thousands of null collisions for nothing.
 * visit (may be NULL) sees every collision: the baseline derivative replays
 * the same collisions with the same random numbers. */
static dr_vec3 ratio_tracking(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax, struct dr_sampler *rng,
                              dr_medium_visit_fn visit, void *ctx)
{
    struct majorant_walk w;
    double t0, t1, maj;
    dr_vec3 T = dr_v3s(1.0);
    walk_start(&w, m, o, d, tmax);
    while (walk_next(&w, &t0, &t1, &maj)) {
        if (!(maj > 0.0))
            continue;
        for (double t = t0;;) {
            t -= log1p(-dr_sampler_next(rng)) / maj;
            if (!(t < t1))
                break;
            dr_vec3 x = dr_madd(o, d, t);
            dr_vec3 st = dr_medium_sigma_t(m, x);
            if (visit)
                visit(ctx, x, maj);
            T = dr_mul(T, dr_v3(dr_max(1.0 - st.x / maj, 0.0), dr_max(1.0 - st.y / maj, 0.0),
                                dr_max(1.0 - st.z / maj, 0.0)));
            double tm = dr_max3(T);
            if (tm == 0.0)
                return T;
            if (tm < 0.1) {
                if (dr_sampler_next(rng) >= 0.5)
                    return dr_v3s(0.0);
                T = dr_scale(T, 2.0);
            }
        }
    }
    return T;
}

void dr_medium_replay_ratio_tracking(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                     struct dr_sampler *rng, dr_medium_visit_fn visit, void *ctx)
{
    if (m->has_grid)
        ratio_tracking(m, o, d, tmax, rng, visit, ctx);
}

void dr_medium_replay_nulls(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double len, struct dr_sampler *rng,
                            dr_medium_visit_fn visit, void *ctx)
{
    if (!m->has_grid)
        return;   /* a homogeneous medium's free flight has no null collisions (homogeneous_sample) */
    struct majorant_walk walk;
    double t0, t1, maj;
    walk_start(&walk, m, o, d, len);
    while (walk_next(&walk, &t0, &t1, &maj)) {
        if (!(maj > 0.0))
            continue;
        for (double t = t0;;) {
            t -= log1p(-dr_sampler_next(rng)) / maj;
            if (!(t < t1))
                break;
            dr_sampler_next(rng);   /* the event's number: it was a null collision */
            visit(ctx, dr_madd(o, d, t), maj);
        }
    }
}

bool dr_medium_clip(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double *t0, double *t1)
{
    if (m->bounded && !clip_to_box(m->bmin, m->bmax, o, d, t0, t1))
        return false;
    if (m->has_grid && !clip_to_box(m->grid.bmin, m->grid.bmax, o, d, t0, t1))
        return false;
    return *t0 < *t1;
}

dr_vec3 dr_medium_transmittance(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax, struct dr_sampler *rng)
{
    if (m->has_grid)
        return ratio_tracking(m, o, d, tmax, rng, NULL, NULL);
    dr_vec3 s = dr_scale(m->extinction, m->density_scale);
    if (isinf(tmax))
        return dr_v3(s.x > 0.0 ? 0.0 : 1.0, s.y > 0.0 ? 0.0 : 1.0, s.z > 0.0 ? 0.0 : 1.0);
    return dr_v3(exp(-s.x * tmax), exp(-s.y * tmax), exp(-s.z * tmax));
}

/* ----------------------------------------------------------------- phase */

double dr_hg_eval(double g, double cos_theta)
{
    double denom = 1.0 + g * g - 2.0 * g * cos_theta;
    return (1.0 - g * g) / (4.0 * M_PI * denom * sqrt(denom));
}

/* p = (1 - g^2) / (4 pi D^1.5), D = 1 + g^2 - 2 g mu:
 * d ln p / dg = -2 g / (1 - g^2) - 1.5 (2 g - 2 mu) / D. */
double dr_hg_dlog_dg(double g, double mu)
{
    double D = 1.0 + g * g - 2.0 * g * mu;
    return -2.0 * g / (1.0 - g * g) - 3.0 * (g - mu) / D;
}

double dr_hg_sample(double g, dr_vec3 d, double u1, double u2, dr_vec3 *wi)
{
    double cos_theta;
    if (fabs(g) < 1e-3) {
        cos_theta = 1.0 - 2.0 * u1;
    } else {
        double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1);
        cos_theta = (1.0 + g * g - s * s) / (2.0 * g);
    }
    cos_theta = dr_clamp(cos_theta, -1.0, 1.0);
    double sin_theta = sqrt(dr_max(0.0, 1.0 - cos_theta * cos_theta));
    double phi = 2.0 * M_PI * u2;
    dr_frame f = dr_frame_from_normal(d);
    *wi = dr_frame_to_world(&f, dr_v3(sin_theta * cos(phi), sin_theta * sin(phi), cos_theta));
    return dr_hg_eval(g, cos_theta);
}

double dr_albedo_from_multiscatter(double a)
{
    a = dr_clamp(a, 0.0, 1.0);
    double k = 4.09712 + 4.20863 * a - sqrt(9.59217 + 41.6808 * a + 17.7126 * a * a);
    return dr_clamp(1.0 - k * k, 0.0, 1.0);
}

double dr_fresnel_dielectric(double cos_i, double eta, double *cos_t)
{
    cos_i = dr_clamp(cos_i, 0.0, 1.0);
    double sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0) {
        *cos_t = 0.0;
        return 1.0;
    }
    double ct = sqrt(1.0 - sin2_t);
    double rs = (cos_i - eta * ct) / (cos_i + eta * ct), rp = (eta * cos_i - ct) / (eta * cos_i + ct);
    *cos_t = ct;
    return 0.5 * (rs * rs + rp * rp);
}

dr_vec3 dr_refract(dr_vec3 d, dr_vec3 n, double cos_i, double cos_t, double eta)
{
    /* Snell: the tangential part scales by 1/eta, the normal part is cos_t */
    return dr_normalize(dr_madd(dr_scale(d, 1.0 / eta), n, cos_i / eta - cos_t));
}
