/* drender batch: many drender command lines in one process.
 *
 * Why: writing or reading the first image loads OpenImageIO, whose Debian
 * build pulls in about 260 shared libraries (0.4-0.6 s of dynamic linking
 * here, see core/image_plugin.h). A script that renders a hundred small
 * images as a hundred processes pays that a hundred times; as the lines of
 * one batch it pays it once.
 *
 * The whole list is read and split into words before the first job runs, so
 * a typo on line 900 stops the batch before any output is written. */
#include <errno.h>
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

#define MAX_WORDS 256

void cmd_batch_usage(FILE *out)
{
    fprintf(out,
            "usage: drender batch [--keep-going] [FILE]\n"
            "\n"
            "Runs the drender command lines of FILE (standard input when FILE is absent\n"
            "or '-') one after another in this one process, so that the image library is\n"
            "loaded once rather than once per command (about half a second each time here).\n"
            "\n"
            "One command per line, without or with the leading 'drender', e.g.\n"
            "  render scene.gltf --spp 64 -o 'out/a b.exr'\n"
            "Words are split as a shell splits them: blanks separate, '...' and \"...\"\n"
            "quote, a backslash escapes the next character, # starts a comment. There\n"
            "is no expansion, globbing, redirection or pipe: a line holding an unquoted\n"
            "one of | & ; < > ( ) $ ` * ? is refused. Blank lines are skipped.\n"
            "\n"
            "Every line is checked (quoting, a known command) before the first runs.\n"
            "Each job prints what it prints alone; --json timings count a job's\n"
            "start-up from the job's start, peak memory is the process's so far.\n"
            "\n"
            "options:\n"
            "  -k, --keep-going    run the remaining lines after a failed one (a job\n"
            "                      stopped by a signal still ends the batch)\n"
            "  -h, --help          show this help\n"
            "\n"
            "exit status: 0 when every job succeeded; otherwise the status of the first\n"
            "that failed (FILE:LINE and the command are named on stderr); 2 for a bad\n"
            "line in FILE (nothing runs).\n");
}

struct job {
    long line;          /* in the file, from 1 */
    int argc;
    char *argv[MAX_WORDS + 1];
    char *text;         /* the line, split in place */
};

static bool shell_syntax(char c)
{
    return c != '\0' && strchr("|&;<>()$`*?", c) != NULL;
}

/* Splits s in place into words (shell quoting, no expansions). Returns the
 * number of words, or -1 with *why set. */
static int split_words(char *s, char **argv, const char **why, char *bad)
{
    int n = 0;
    char *out = s;
    for (;;) {
        while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\n')
            s++;
        if (*s == '\0' || *s == '#')
            return n;
        if (n == MAX_WORDS) {
            *why = "more than 256 words";
            return -1;
        }
        argv[n++] = out;
        while (*s && *s != ' ' && *s != '\t' && *s != '\r' && *s != '\n') {
            if (*s == '\'') {
                char *end = strchr(s + 1, '\'');
                if (!end) {
                    *why = "unterminated ' quote";
                    return -1;
                }
                memmove(out, s + 1, (size_t)(end - s - 1));
                out += end - s - 1;
                s = end + 1;
            } else if (*s == '"') {
                for (s++; *s != '"'; s++) {
                    if (*s == '\0') {
                        *why = "unterminated \" quote";
                        return -1;
                    }
                    if (*s == '\\' && s[1] && strchr("\"\\$`", s[1]))
                        s++;
                    *out++ = *s;
                }
                s++;
            } else if (*s == '\\') {
                if (s[1] == '\0' || s[1] == '\n') {
                    *why = "a line ending in '\\' (continuation lines are not supported)";
                    return -1;
                }
                *out++ = s[1];
                s += 2;
            } else if (shell_syntax(*s)) {
                *bad = *s;
                *why = "shell syntax is not supported (quote the character, or run the line through a shell)";
                return -1;
            } else {
                *out++ = *s++;
            }
        }
        if (*s)
            s++;
        *out++ = '\0';
    }
}

/* Reads and checks every line; the jobs go to *jobs. Returns an exit code,
 * or -1 when every line is good. */
static int read_jobs(FILE *in, const char *name, struct job **jobs, int *n_jobs)
{
    char *line = NULL;
    size_t cap = 0;
    int rc = -1, cap_jobs = 0;
    *jobs = NULL;
    *n_jobs = 0;
    for (long lineno = 1; getline(&line, &cap, in) >= 0; lineno++) {
        struct job j = {.line = lineno, .text = strdup(line)};
        const char *why = NULL;
        char bad = 0;
        if (!j.text) {
            cli_error("batch", "out of memory");
            rc = DR_EXIT_FAILURE;
            break;
        }
        j.argc = split_words(j.text, j.argv, &why, &bad);
        if (j.argc > 0 && strcmp(j.argv[0], "drender") == 0) {
            memmove(j.argv, j.argv + 1, (size_t)j.argc * sizeof j.argv[0]);
            if (--j.argc == 0) {
                j.argc = -1;
                why = "'drender' without a command";
            }
        }
        const struct dr_command *c = j.argc > 0 ? dr_command_find(j.argv[0]) : NULL;
        if (j.argc < 0) {
            if (bad)
                cli_error("batch", "%s:%ld: '%c': %s", name, lineno, bad, why);
            else
                cli_error("batch", "%s:%ld: %s", name, lineno, why);
        } else if (j.argc > 0 && !c) {
            cli_error("batch", "%s:%ld: '%s' is not a drender command (see 'drender help')", name, lineno,
                      j.argv[0]);
        } else if (c && strcmp(c->name, "batch") == 0) {
            cli_error("batch", "%s:%ld: a batch cannot run 'batch'", name, lineno);
        } else if (j.argc > 0) {
            j.argv[j.argc] = NULL;
            if (*n_jobs == cap_jobs) {
                cap_jobs = cap_jobs ? 2 * cap_jobs : 16;
                struct job *grown = realloc(*jobs, (size_t)cap_jobs * sizeof **jobs);
                if (!grown) {
                    free(j.text);
                    cli_error("batch", "out of memory");
                    rc = DR_EXIT_FAILURE;
                    break;
                }
                *jobs = grown;
            }
            (*jobs)[(*n_jobs)++] = j;
            continue;
        } else {
            free(j.text);   /* blank or comment */
            continue;
        }
        free(j.text);
        rc = DR_EXIT_USAGE;
        break;
    }
    if (rc < 0 && ferror(in)) {
        cli_error("batch", "%s: %s", name, strerror(errno));
        rc = DR_EXIT_INPUT;
    }
    free(line);
    return rc;
}

/* Runs one job as main() would run its command. */
static int run_job(const struct job *j)
{
    const struct dr_command *c = dr_command_find(j->argv[0]);
    optind = 0;   /* glibc: a full re-initialisation of getopt for the job's own parse */
    cli_mark_job_start();
    fflush(stdout);
    int rc = cli_flush_stdout(c->name, c->run(j->argc, (char **)j->argv));
    fflush(stderr);
    return rc;
}

/* Returns -1 to go on, or an exit code. */
static int parse_args(int argc, char **argv, bool *keep_going, const char **file)
{
    static const struct option longopts[] = {
        {"keep-going", no_argument, NULL, 'k'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    int c;
    opterr = 0;
    while ((c = getopt_long(argc, argv, "+kh", longopts, NULL)) != -1) {
        switch (c) {
        case 'k': *keep_going = true; break;
        case 'h': cmd_batch_usage(stdout); return DR_EXIT_OK;
        default:
            cli_error("batch", "unknown option '%s' (see 'drender batch --help')", argv[optind - 1]);
            return DR_EXIT_USAGE;
        }
    }
    if (argc - optind > 1) {
        cli_error("batch", "one FILE at most (got '%s' after '%s')", argv[optind + 1], argv[optind]);
        return DR_EXIT_USAGE;
    }
    *file = optind < argc ? argv[optind] : "-";
    return -1;
}

int cmd_batch(int argc, char **argv)
{
    bool keep_going = false;
    const char *file = "-";
    int rc = parse_args(argc, argv, &keep_going, &file);
    if (rc >= 0)
        return rc;
    bool from_stdin = strcmp(file, "-") == 0;
    FILE *in = from_stdin ? stdin : fopen(file, "r");
    if (!in) {
        cli_error("batch", "%s: %s", file, strerror(errno));
        return DR_EXIT_INPUT;
    }
    const char *name = from_stdin ? "(stdin)" : file;
    struct job *jobs;
    int n_jobs;
    rc = read_jobs(in, name, &jobs, &n_jobs);
    if (!from_stdin)
        fclose(in);
    int first_failure = DR_EXIT_OK;
    for (int k = 0; rc < 0 && k < n_jobs; k++) {
        int job_rc = run_job(&jobs[k]);
        if (job_rc == DR_EXIT_OK)
            continue;
        cli_error("batch", "%s:%ld: '%s' failed (exit status %d)%s", name, jobs[k].line, jobs[k].argv[0], job_rc,
                  keep_going && job_rc < 128 && k + 1 < n_jobs ? "; going on" : "");
        if (first_failure == DR_EXIT_OK)
            first_failure = job_rc;
        if (!keep_going || job_rc >= 128)   /* >= 128: stopped by a signal (optimize) */
            break;
    }
    for (int k = 0; k < n_jobs; k++)
        free(jobs[k].text);
    free(jobs);
    return rc >= 0 ? rc : first_failure;
}
