/* Shared pieces of the command-line layer: exit codes, option value parsing,
 * locating bundled data, and a tiny JSON writer. */
#ifndef DR_CLI_H
#define DR_CLI_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "clock.h"

/* Exit codes (documented in man/drender.1). */
enum {
    DR_EXIT_OK = 0,
    DR_EXIT_FAILURE = 1,  /* the work failed (cannot write output, out of memory, ...) */
    DR_EXIT_USAGE = 2,    /* unknown subcommand or option, impossible option value */
    DR_EXIT_INPUT = 3,    /* a scene or image could not be read or is malformed */
    DR_EXIT_DISAGREE = 4  /* fdcheck: some gradient disagrees with finite differences */
};

#define DR_VERSION "0.1.0"

struct dr_command {
    const char *name;
    const char *summary;
    int (*run)(int argc, char **argv);   /* argv[0] is the subcommand name */
    void (*usage)(FILE *out);
};

extern const struct dr_command dr_commands[];
const struct dr_command *dr_command_find(const char *name);

/* "drender CMD: message" on stderr. */
void cli_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Flushes and closes standard output at the end of a command (cmd: its name,
 * or NULL): when that, or an earlier write to it, failed (a full disk, a
 * closed file), says so and returns DR_EXIT_FAILURE in place of rc's success. */
int cli_close_stdout(const char *cmd, int rc);
/* The same without closing (batch: after each job), clearing the error. */
int cli_flush_stdout(const char *cmd, int rc);
/* Closes a file written with stdio: 0, or -1 with errno set when any write
 * to it failed (an earlier one leaves only the error flag: EIO then), its
 * flush or its close. */
int cli_fclose_checked(FILE *f);
/* The exit code for core/'s last error where the call's failures are
 * otherwise `code` (bad input or usage): an allocation that failed is the
 * work failing (DR_EXIT_FAILURE), whatever the call was. */
int cli_error_exit(int code);

/* Parse option values; on failure print a message naming the option and
 * return false. */
bool cli_parse_int(const char *cmd, const char *opt, const char *text, long min, long max, long *out);
bool cli_parse_u64(const char *cmd, const char *opt, const char *text, uint64_t *out);
/* A finite real number greater than min_exclusive. */
bool cli_parse_double(const char *cmd, const char *opt, const char *text, double min_exclusive, double *out);
bool cli_parse_res(const char *cmd, const char *opt, const char *text, int *w, int *h);

/* Path of a scene shipped with drender (e.g. "cornell-box.gltf"), looked up
 * in $DRENDER_DATA, next to the binary (../scenes), and in the install
 * prefix's share/drender/scenes. Returns a malloc'd path or NULL. */
char *cli_find_bundled_scene(const char *name);

/* The directory an output file goes to exists and is writable (checked before
 * any work, so a long render does not end in "cannot write"). Prints the
 * error naming the file. */
bool cli_output_dir_writable(const char *cmd, const char *path);

/* Start-up accounting: main() calls cli_mark_start() first thing;
 * cli_seconds_since_start() is the time since the process was created
 * (exec, dynamic linking and all; 10 ms resolution for the part before main). */
void cli_mark_start(void);
double cli_seconds_since_start(void);
/* The start of one job of a batch (cmd_batch.c): from here on the time since
 * start counts from now. */
void cli_mark_job_start(void);

/* Peak resident memory of this process, bytes. */
uint64_t cli_peak_rss_bytes(void);

/* Minimal JSON output: the caller prints structure, these escape values. */
void json_string(FILE *f, const char *s);
/* "a,b,c" as a JSON array of strings (names: no characters that need escaping). */
void json_name_list(FILE *f, const char *names);
void json_number(FILE *f, double v);   /* NaN/Inf written as null */
/* ", \"stage_seconds\": {...}": the array tracer's time by stage (path.h),
 * each thread's seconds summed; null where it did not run. */
struct dr_stage_seconds;
void json_stage_seconds(FILE *f, const struct dr_stage_seconds *c);

#endif
