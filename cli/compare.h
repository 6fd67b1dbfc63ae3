/* drender compare: the shared picture of one comparison, between the
 * command (cmd_compare.c: options, the runs, the reference) and its outputs
 * (compare_output.c: results.csv, results.json, report.md, the plots;
 * compare_reference.c: the reference file).
 *
 * Every run estimates one vector v of length V, the same quantity for every
 * estimator, so errors are comparable:
 *   reverse mode (--target): v = d loss / d theta (params->total entries),
 *     the loss's adjoint taken from one primal image shared by all runs, or
 *     (--primal cross) each run's paths its own primal, as grad runs them;
 *   forward mode: v = the derivative images d image / d parameter (along all
 *     of a parameter's components), one w x h x 3 block per --param.
 * A parameter's part of v is its segment [seg_off[k], seg_off[k] + seg_len[k]). */
#ifndef DR_CLI_COMPARE_H
#define DR_CLI_COMPARE_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "estimator.h"
#include "grad_common.h"
#include "loss.h"
#include "sampler.h"

#define CMP_MAX_LIST 16
#define CMP_MAX_SAMPLERS 3   /* independent, stratified, sobol: each at most once */

/* One combination of the sweep. */
struct cmp_combo {
    const struct dr_estimator_ops *est;
    enum dr_sampling sampling;
    int max_depth, spp;
    enum dr_sampler_kind sampler;   /* the random numbers (--sampler, a list) */
    enum dr_medium_grad medium_grad;   /* media derivatives (--medium-grad, a list) */
};

/* What one parameter's estimate was, summarised: up to 3 components for a
 * scalar or colour in reverse mode; one number (the gradient's norm) for an
 * image parameter; one number (the derivative image's mean) in forward mode. */
struct cmp_param_result {
    int n;
    double value[3], se[3];   /* mean over batches and its standard error */
    double ref[3], ref_se[3]; /* the reference, summarised the same way */
    double rel_error;         /* of a single estimate, this parameter's segment */
    double rel_variance;      /* sum of the segment's per-entry variances / |its reference|^2 */
};

/* One combination's outcome (the same for every repeat: same random numbers). */
struct cmp_result {
    double *seconds;          /* per repeat: mean seconds of one estimate */
    double rays;              /* per estimate */
    uint64_t memory_bytes, record_bytes, invalid;
    double rel_error;         /* sqrt(mean over batches |v_b - ref|^2 / |ref|^2) */
    double rel_variance;      /* sum of per-entry variances of one estimate / |ref|^2 */
    struct cmp_param_result *params;
    struct dr_medium_gain_choice media_gain[DR_STATS_MEDIA_GAIN];   /* DRT's sources (dr_grad_stats) */
    int n_media_gain;
};

struct cmp_reference {
    char kind[32];            /* "spp:N", "fd:N", or the kind recorded in a file */
    char file[4096];          /* the file it was read from, or "" */
    char estimator[32], sampling[32];   /* "" for fd */
    int spp, batches, max_depth;
    double eps;               /* fd */
    double *mean, *se;        /* V entries */
    double norm2, rel_se;     /* |mean|^2; |se| / |mean| */
    double seconds;
};

/* Identity of a comparison, recorded in a reference file and checked when
 * one is read back: a reference applies only to the same question. */
struct cmp_fingerprint {
    uint64_t scene_hash, values_hash, target_hash;
    int width, height, camera, max_depth, rr_depth, primal_spp;   /* primal_spp 0: --primal cross */
    char mode[16], loss[16];
    char film[128];   /* "filter=F crop=X,Y,W,H|none sampler=S": the film and random numbers */
};

struct cmp_args {
    struct grad_common g;
    const char *out_dir, *target, *reference;
    enum dr_loss_kind loss;
    bool loss_given, est_given, sampling_given, spp_given;
    const struct dr_estimator_ops *ests[CMP_MAX_LIST];
    int n_ests;
    enum dr_sampling samplings[DR_SAMPLING_COUNT];
    int n_samplings;
    int spps[CMP_MAX_LIST], n_spps;
    enum dr_sampler_kind samplers[CMP_MAX_SAMPLERS];   /* --sampler's list; g.sampler is the first */
    int n_samplers;
    enum dr_medium_grad medium_grads[2];   /* --medium-grad's list (drt, baseline) */
    int n_medium_grads;
    int depths[CMP_MAX_LIST], n_depths;
    int batches, repeat;
    bool cross;   /* --primal cross: every run its own primal (dr_cross_loss), no shared image */
    double eps;
    /* the parsed --reference */
    enum { CMP_REF_SPP, CMP_REF_FD, CMP_REF_FILE } ref_kind;
    int ref_spp;
};

struct cmp_run {
    const struct cmp_args *a;
    const char *scene_path;
    const struct dr_param_set *ps;
    bool reverse;
    int64_t V;
    int64_t *seg_off, *seg_len;   /* per parameter */
    struct cmp_combo *combos;
    int n_combos;
    struct cmp_result *results;
    struct cmp_reference ref;
    struct cmp_fingerprint fp;
    char skipped[1024];           /* pairs left out because they do not apply */
    char as_detached[128];        /* modes left out of the default list because they would run as
                                     detached sampling here ("attached,mis"; drop_detached_twins) */
    char auto_sampling[32];       /* what grad and optimize's default, --sampling auto, would run here */
    char auto_why[DR_PARAM_NAME_MAX + 160];  /* ... and why (grad_auto_describe; "" without a small roughness) */
    double t_total;
};

/* compare_output.c. Each writes the file at path (cmd_compare.c's temporary,
 * renamed at the end): 0, or -1 with errno set and no message (the caller
 * names the file the user asked for). */
int cmp_write_csv(const struct cmp_run *r, const char *path);
void cmp_write_json(const struct cmp_run *r, FILE *f);
int cmp_write_report(const struct cmp_run *r, const char *path);
/* Writes DIR/plots.gp and runs gnuplot on it (a warning when gnuplot is
 * missing or fails: the PNGs are then not drawn). DR_EXIT_FAILURE, said,
 * when plots.gp or a plot could not be written whole (nothing half-written
 * is left under a plot's name); else 0. */
int cmp_write_plots(const struct cmp_run *r, const char *dir);
/* The combination's label, "prb detached d8"; with more than one --sampler
 * listed, the sampler too: "prb detached sobol d8"; with both media
 * derivative methods, the method: "prb detached (media baseline) d8". */
void cmp_combo_label(const struct cmp_run *r, const struct cmp_combo *c, char *buf, size_t size);
/* "prb detached" or, with several samplers, "prb detached sobol" (and the
 * media method, as above). */
void cmp_pair_label(const struct cmp_run *r, const struct cmp_combo *c, char *buf, size_t size);
/* Do a and b differ only in max depth and spp (the same estimator,
 * sampling, sampler and media method)? */
bool cmp_same_pair(const struct cmp_combo *a, const struct cmp_combo *b);

/* The efficiency 1 / (relative variance x seconds) of parameter k in combination c. */
double cmp_param_efficiency(const struct cmp_run *r, int c, int k);
/* Median / min / max of a combination's repeat timings. */
void cmp_seconds_spread(const struct cmp_run *r, int c, double *median, double *lo, double *hi);
double cmp_efficiency(const struct cmp_run *r, int c);

/* compare_reference.c */
uint64_t cmp_hash_file(const char *path, bool *ok);
uint64_t cmp_hash_bytes(uint64_t h, const void *data, size_t n);
int cmp_reference_write(const struct cmp_run *r, const char *path);   /* (as cmp_write_csv) */
/* Reads FILE and checks that it answers this run's question (scene,
 * parameters, mode and settings); fills r->ref. Returns -1 to go on or an
 * exit code after a message naming the file and what differs. */
int cmp_reference_read(struct cmp_run *r, const char *file);

#endif
