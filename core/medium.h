/* Participating media: homogeneous or density-grid extinction, scattering
 * albedo and a Henyey-Greenstein phase function, bounded by closed meshes
 * (index-matched boundaries) or filling the space outside them (the global
 * medium of the DR_medium extension).
 *
 * Extinction at x is sigma_t(x) = density_scale * density(x) * extinction
 * (rgb, 1/m); density is 1 without a grid, else the trilinear interpolation of
 * the grid's voxels (centres at (i + 0.5) / n of the box, 0 outside it).
 *
 * Sampling:
 *  - free flight with spectral MIS: a hero channel per path decides the
 *    events, every channel is weighted by the balance heuristic over the
 *    three channels' event probabilities, so red, green and blue extinction
 *    may differ by orders of magnitude (the weight of a channel is at most
 *    3). In a homogeneous medium the hero channel's own exponential flight
 *    (no null collisions); in a grid, delta tracking against a scalar
 *    majorant (the largest extinction of any channel in the majorant cell);
 *  - transmittance for next-event estimation: exact exp(-sigma_t d) in a
 *    homogeneous medium, ratio tracking in a grid;
 *  - majorants: a coarse grid (DR_MAJORANT_CELL voxels a side) of the maxima
 *    over every voxel a trilinear lookup in the cell can touch, traversed with
 *    a 3D DDA, so empty space costs nothing and density can never exceed the
 *    majorant (it is built from the same voxels). */
#ifndef DR_MEDIUM_H
#define DR_MEDIUM_H

#include <stdbool.h>
#include <stdint.h>

#include "sampler.h"
#include "vec.h"

#ifdef __cplusplus
extern "C" {
#endif

#define DR_MAJORANT_CELL 4
#define DR_MEDIUM_NAME_MAX 64

struct dr_grid {
    int nx, ny, nz;        /* voxels */
    float *density;        /* nx * ny * nz, x fastest, then y, then z; >= 0 */
    dr_vec3 bmin, bmax;    /* world-space box the voxels fill */
    int mx, my, mz;        /* majorant cells */
    float *majorant;       /* mx * my * mz maxima of density (built by dr_grid_build_majorants) */
};

struct dr_medium {
    char name[DR_MEDIUM_NAME_MAX];  /* the material's name, or "global" */
    dr_vec3 extinction;    /* 1/m at density 1, per channel */
    dr_vec3 albedo;        /* single-scattering albedo sigma_s / sigma_t */
    double g;              /* Henyey-Greenstein asymmetry, (-1, 1) */
    double density_scale;
    bool has_grid;
    struct dr_grid grid;
    /* no collisions outside this box (a mesh medium: the mesh's bounds; a
     * ray that slips through its boundary by rounding cannot scatter far off) */
    bool bounded;
    dr_vec3 bmin, bmax;
    /* the mean length of a straight line across the medium: 4 V / S of its
     * box (the global medium's: the scene's box); 0 where unknown. Its
     * optical thickness at this length picks the gain estimator of DRT
     * (medium_grad.c). Set by dr_media_prepare. */
    double mean_chord;
    char grid_uri[512];
    int material;          /* the boundary material, -1: the global medium */
    /* the boundary: 0 index-matched (crossed without bending); else a smooth
     * dielectric interface, the index of refraction inside relative to
     * outside (KHR_materials_ior; the global medium's is 1) */
    double ior;
    /* glTF's KHR_materials_volume alone (no DR_medium): where its mesh is not
     * closed, dr_media_prepare makes the material thin-walled glass (scene.h)
     * and drops the medium, with a warning, instead of refusing the scene */
    bool thin_when_open;
};

/* Reads a density grid of nx x ny x nz voxels from file: raw little-endian
 * float32 (.raw, .f32, .bin: exactly nx*ny*nz*4 bytes), a single-channel
 * (or first-channel) EXR of width nx and height ny*nz (z slices stacked
 * top to bottom, each with y rows top to bottom), or an OpenVDB file (.vdb,
 * through the image library, image_io.h): the float grid `grid_name` (NULL:
 * "density", else the first float grid), whose active voxel bounding box
 * becomes the grid's voxels, index coordinate (x0 + i, y0 + j, z0 + k) voxel
 * (i, j, k); nx = 0 takes its size from the file, otherwise it must match.
 * 0 or DR_ERR_* with a message naming the file (negative or non-finite
 * density, wrong size, other formats, no float grid, an empty grid). */
int dr_grid_read(const char *file, const char *grid_name, int nx, int ny, int nz, struct dr_grid *grid);
/* Does the file name say OpenVDB (.vdb)? */
bool dr_grid_file_is_vdb(const char *file);
/* (Re)builds the majorant cells from the voxels. 0 or DR_ERR_NOMEM. */
int dr_grid_build_majorants(struct dr_grid *grid);
void dr_grid_release(struct dr_grid *grid);
/* Trilinear density at world point p (0 outside the box); idx/w: the 8 taps
 * (idx -1 where the weight is 0), for derivatives; may be NULL. */
double dr_grid_density(const struct dr_grid *grid, dr_vec3 p, int64_t idx[8], double w[8]);

/* A homogeneous medium's smallest extinction over the channels, density
 * scale applied (0 if some channel's is 0): its transmittance decays at
 * least this fast in every channel. */
double dr_medium_least_extinction(const struct dr_medium *m);

/* sigma_t at p. */
dr_vec3 dr_medium_sigma_t(const struct dr_medium *m, dr_vec3 p);

enum dr_medium_event {
    DR_MEDIUM_PASS,      /* no real collision before tmax */
    DR_MEDIUM_SCATTER,   /* a scattering collision at *t */
    DR_MEDIUM_ABSORB     /* absorbed at *t: the path ends */
};

/* Spectral MIS state of a path: the hero channel that decides collision
 * events, and each channel's probability of the events so far (up to a
 * common factor). */
struct dr_spectral_mis {
    int hero;
    double r[3];
};
/* Per-channel weight of everything the path gathers now: r / mean(r). */
dr_vec3 dr_spectral_mis_weight(const struct dr_spectral_mis *mis);

/* Free-flight sampling along o + t d (d unit) for t in [0, tmax) (infinite:
 * a ray leaving an unbounded medium), with spectral MIS over the channels
 * (medium.c: the hero's own flight when homogeneous, delta tracking in a
 * grid), updating mis; returns the event. rng supplies the uniforms (any
 * number). */
enum dr_medium_event dr_medium_sample(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                      struct dr_sampler *rng, struct dr_spectral_mis *mis, double *t);
/* Where dr_medium_sample's next call with this rng (not advanced: a copy)
 * and hero channel will put a collision if no surface comes first: in a
 * homogeneous medium the hero's flight does not depend on tmax, only
 * whether it ends before it. INFINITY where it may not collide at all (the
 * flight leaves the medium's box, a non-attenuating hero) and in a grid.
 * The walker traces only up to there (medium_path.c). */
double dr_medium_collision_ahead(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, struct dr_sampler rng, int hero);
/* Unbiased transmittance estimate over [0, tmax) (exact when homogeneous). */
dr_vec3 dr_medium_transmittance(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                struct dr_sampler *rng);

/* Replays for the baseline derivative (medium_grad.c): the same tentative
 * collisions as dr_medium_sample over [0, len) of a stretch that ended there
 * (so all of them were null collisions; none in a homogeneous medium) / as
 * the transmittance estimate, from the same random numbers; visit sees each
 * point and its majorant. */
typedef void (*dr_medium_visit_fn)(void *ctx, dr_vec3 x, double majorant);
void dr_medium_replay_nulls(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double len, struct dr_sampler *rng,
                            dr_medium_visit_fn visit, void *ctx);
void dr_medium_replay_ratio_tracking(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double tmax,
                                     struct dr_sampler *rng, dr_medium_visit_fn visit, void *ctx);
/* Clips [*t0, *t1) to where the medium can be non-zero; false: nowhere. */
bool dr_medium_clip(const struct dr_medium *m, dr_vec3 o, dr_vec3 d, double *t0, double *t1);
/* d/dg of dr_hg_eval, over its value. */
double dr_hg_dlog_dg(double g, double cos_theta);

/* Henyey-Greenstein: density of scattering from a ray travelling along d
 * into direction wi (both unit; cos = d . wi); it is its own sampling pdf. */
double dr_hg_eval(double g, double cos_theta);
/* Samples wi for a ray travelling along d; returns its density. */
double dr_hg_sample(double g, dr_vec3 d, double u1, double u2, dr_vec3 *wi);

/* Smooth dielectric boundaries (medium_path.c). Fresnel reflectance of
 * unpolarised light arriving at cos_i (> 0, on the incident side) on an
 * interface of relative index eta = n_transmitted / n_incident (exact: the
 * mean of the s and p reflectances); *cos_t: the refracted cosine, 0 at total
 * internal reflection (where the reflectance is 1). */
double dr_fresnel_dielectric(double cos_i, double eta, double *cos_t);
/* Direction refracted from d (unit, arriving) through an interface with
 * unit normal n on the incident side (dot(d, n) = -cos_i), given cos_t. */
dr_vec3 dr_refract(dr_vec3 d, dr_vec3 n, double cos_i, double cos_t, double eta);

/* KHR_materials_volume_scatter's multiscatterColor (the albedo a thick
 * slab shows) to single-scattering albedo, per channel (the inversion of
 * Chiang et al. 2016, "Practical and controllable subsurface scattering"). */
double dr_albedo_from_multiscatter(double a);

#ifdef __cplusplus
}
#endif
#endif
