#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "error.h"
#include "clock.h"
#include "path.h"   /* dr_stage_seconds */

#ifndef DR_DATADIR
#define DR_DATADIR "/usr/local/share/drender"
#endif

void cli_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "drender%s%s: ", cmd ? " " : "", cmd ? cmd : "");
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
}

int cli_error_exit(int code) { return dr_last_error_is_nomem() ? DR_EXIT_FAILURE : code; }

bool cli_parse_int(const char *cmd, const char *opt, const char *text, long min, long max, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (errno || end == text || *end) {
        cli_error(cmd, "%s: '%s' is not a whole number", opt, text);
        return false;
    }
    if (v < min || v > max) {
        cli_error(cmd, "%s: %ld is out of range (%ld..%ld)", opt, v, min, max);
        return false;
    }
    *out = v;
    return true;
}

bool cli_parse_u64(const char *cmd, const char *opt, const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    if (text[0] == '-') {
        cli_error(cmd, "%s: '%s' must not be negative", opt, text);
        return false;
    }
    unsigned long long v = strtoull(text, &end, 10);
    if (errno || end == text || *end) {
        cli_error(cmd, "%s: '%s' is not a whole number", opt, text);
        return false;
    }
    *out = v;
    return true;
}

bool cli_parse_res(const char *cmd, const char *opt, const char *text, int *w, int *h)
{
    char *end;
    errno = 0;
    long a = strtol(text, &end, 10);
    if (errno || end == text || (*end != 'x' && *end != 'X')) {
        cli_error(cmd, "%s: '%s' is not of the form WIDTHxHEIGHT (e.g. 640x480)", opt, text);
        return false;
    }
    const char *p = end + 1;
    long b = strtol(p, &end, 10);
    if (errno || end == p || *end) {
        cli_error(cmd, "%s: '%s' is not of the form WIDTHxHEIGHT (e.g. 640x480)", opt, text);
        return false;
    }
    if (a < 1 || b < 1 || a > 32768 || b > 32768) {
        cli_error(cmd, "%s: %ldx%ld: width and height must be between 1 and 32768", opt, a, b);
        return false;
    }
    *w = (int)a;
    *h = (int)b;
    return true;
}

static char *try_path(const char *dir, const char *sub, const char *name)
{
    char buf[PATH_MAX];
    int n = snprintf(buf, sizeof buf, "%s%s/%s", dir, sub, name);
    if (n < 0 || (size_t)n >= sizeof buf)
        return NULL;   /* too long to be a real path */
    return access(buf, R_OK) == 0 ? strdup(buf) : NULL;
}

char *cli_find_bundled_scene(const char *name)
{
    char *p;
    const char *env = getenv("DRENDER_DATA");
    if (env && (p = try_path(env, "/scenes", name)))
        return p;
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
        exe[n] = '\0';
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = '\0';
            /* build tree (build/drender -> scenes/) or installed (bin/ -> share/drender) */
            if ((p = try_path(exe, "/../scenes", name)) || (p = try_path(exe, "/../share/drender/scenes", name)))
                return p;
        }
    }
    return try_path(DR_DATADIR, "/scenes", name);
}

bool cli_output_dir_writable(const char *cmd, const char *path)
{
    char dir[PATH_MAX];
    const char *slash = strrchr(path, '/');
    if (!slash)
        strcpy(dir, ".");
    else if (slash == path)
        strcpy(dir, "/");
    else
        snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path);
    if (access(dir, W_OK) != 0) {
        cli_error(cmd, "%s: cannot write into '%s': %s", path, dir, strerror(errno));
        return false;
    }
    return true;
}

/* Process age at main(), from the kernel's start time (clock ticks since
 * boot, so 1/CLK_TCK resolution, 10 ms here), and the monotonic clock then. */
static double age_at_main, clock_at_main;

static double process_age_seconds(void)
{
    char buf[1024];
    FILE *f = fopen("/proc/self/stat", "r");
    size_t n = f ? fread(buf, 1, sizeof buf - 1, f) : 0;
    if (f)
        fclose(f);
    buf[n] = '\0';
    const char *p = strrchr(buf, ')');   /* the command name may hold spaces */
    if (!p)
        return 0.0;
    unsigned long long start = 0;
    /* after ")" come fields 3, 4, ...; starttime is field 22 */
    if (sscanf(p + 1, " %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %*s %llu",
               &start) != 1)
        return 0.0;
    struct timespec now;
    clock_gettime(CLOCK_BOOTTIME, &now);
    double age = (double)now.tv_sec + 1e-9 * (double)now.tv_nsec - (double)start / (double)sysconf(_SC_CLK_TCK);
    return age > 0.0 ? age : 0.0;
}

void cli_mark_start(void)
{
    age_at_main = process_age_seconds();
    clock_at_main = dr_clock_seconds();
}

void cli_mark_job_start(void)
{
    age_at_main = 0.0;
    clock_at_main = dr_clock_seconds();
}

double cli_seconds_since_start(void)
{
    return age_at_main + (dr_clock_seconds() - clock_at_main);
}

uint64_t cli_peak_rss_bytes(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return (uint64_t)ru.ru_maxrss * 1024u;
}

void json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; s && *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\')
            fprintf(f, "\\%c", c);
        else if (c < 0x20)
            fprintf(f, "\\u%04x", c);
        else
            fputc(c, f);
    }
    fputc('"', f);
}

void json_number(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.17g", v);
    else
        fputs("null", f);
}

/* The array tracer's time by stage (path.h's dr_stage_seconds), each
 * thread's seconds in a stage summed over the threads; null where it did not run (a scene with a global
 * medium: every path walks one at a time, untimed by stage). */
void json_stage_seconds(FILE *f, const struct dr_stage_seconds *c)
{
    fprintf(f, ", \"stage_seconds\": ");
    if (!(c->start + c->queries + c->ends + c->shade + c->advance > 0.0)) {
        fprintf(f, "null");
        return;
    }
    const struct { const char *name; double v; } stage[] = {{"camera", c->start}, {"ray_queries", c->queries},
        {"escaped", c->ends}, {"shading", c->shade}, {"continuation", c->advance}};
    for (size_t i = 0; i < sizeof stage / sizeof *stage; i++) {
        fprintf(f, "%s\"%s\": ", i ? ", " : "{", stage[i].name);
        json_number(f, stage[i].v);
    }
    fputc('}', f);
}

bool cli_parse_double(const char *cmd, const char *opt, const char *text, double min_exclusive, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (errno == ERANGE || end == text || *end || !isfinite(v)) {
        cli_error(cmd, "%s: '%s' is not a finite number", opt, text);
        return false;
    }
    if (!(v > min_exclusive)) {
        cli_error(cmd, "%s: %s must be greater than %g", opt, text, min_exclusive);
        return false;
    }
    *out = v;
    return true;
}

void json_name_list(FILE *f, const char *names)
{
    fputc('[', f);
    for (const char *p = names; *p;) {
        const char *q = strchr(p, ',');
        size_t n = q ? (size_t)(q - p) : strlen(p);
        fprintf(f, "%s\"%.*s\"", p == names ? "" : ", ", (int)n, p);
        p += n + (q != NULL);
    }
    fputc(']', f);
}

/* Standard output goes through stdio's buffer, so a full disk shows only when
 * it is flushed: most often at exit, where nobody looks. A command whose
 * output was lost must not exit 0 (coreutils' close_stdout does the same).
 * An earlier failed write leaves only the stream's error flag; its cause is
 * then unknown unless the final flush fails again. */
static int stdout_failed(int rc, bool close_it, const char *cmd)
{
    errno = 0;
    int e = fflush(stdout) != 0 ? errno : 0;
    bool failed = e != 0 || ferror(stdout);
    if (close_it && fclose(stdout) != 0 && !failed)
        failed = true, e = errno;
    if (!failed)
        return rc;
    cli_error(cmd, "cannot write standard output: %s", e ? strerror(e) : "a write failed");
    if (!close_it)
        clearerr(stdout);   /* (reported: the next job starts clean) */
    return rc == DR_EXIT_OK ? DR_EXIT_FAILURE : rc;
}

int cli_flush_stdout(const char *cmd, int rc) { return stdout_failed(rc, false, cmd); }

int cli_close_stdout(const char *cmd, int rc) { return stdout_failed(rc, true, cmd); }

int cli_fclose_checked(FILE *f)
{
    errno = 0;
    int e = fflush(f) != 0 || ferror(f) ? (errno ? errno : EIO) : 0;
    if (fclose(f) != 0 && !e)
        e = errno ? errno : EIO;
    errno = e;
    return e ? -1 : 0;
}
