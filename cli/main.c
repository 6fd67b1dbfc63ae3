/* drender: the subcommand table and dispatch. */
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "mem_limits.h"
#include "error.h"
#include "source_date.h"

int cmd_render(int argc, char **argv);
void cmd_render_usage(FILE *out);
int cmd_params(int argc, char **argv);
void cmd_params_usage(FILE *out);
int cmd_grad(int argc, char **argv);
void cmd_grad_usage(FILE *out);
int cmd_fdcheck(int argc, char **argv);
void cmd_fdcheck_usage(FILE *out);
int cmd_optimize(int argc, char **argv);
void cmd_optimize_usage(FILE *out);
int cmd_compare(int argc, char **argv);
void cmd_compare_usage(FILE *out);
int cmd_batch(int argc, char **argv);
void cmd_batch_usage(FILE *out);
static int cmd_help(int argc, char **argv);
static void cmd_help_usage(FILE *out);

const struct dr_command dr_commands[] = {
    {"render", "render a glTF scene to an image (path tracing)", cmd_render, cmd_render_usage},
    {"params", "list a scene's differentiable parameters and their values", cmd_params, cmd_params_usage},
    {"grad", "derivatives: d image / d parameter, or d loss / d parameters", cmd_grad, cmd_grad_usage},
    {"fdcheck", "check a gradient estimator against finite differences", cmd_fdcheck, cmd_fdcheck_usage},
    {"optimize", "fit scene parameters to target images (Adam), write them as glTF", cmd_optimize,
     cmd_optimize_usage},
    {"compare", "what accuracy costs in time: estimators x sampling x spp, plotted", cmd_compare,
     cmd_compare_usage},
    {"batch", "run many command lines in one process (one image-library load)", cmd_batch,
     cmd_batch_usage},
    {"help", "show help for drender or one subcommand", cmd_help, cmd_help_usage},
    {NULL, NULL, NULL, NULL},
};

const struct dr_command *dr_command_find(const char *name)
{
    for (const struct dr_command *c = dr_commands; c->name; c++)
        if (strcmp(c->name, name) == 0)
            return c;
    return NULL;
}

static void main_usage(FILE *out)
{
    fprintf(out,
            "usage: drender [--version] [--help] COMMAND [ARGS]\n"
            "\n"
            "drender renders glTF 2.0 scenes with a path tracer and differentiates them.\n"
            "\n"
            "commands:\n");
    for (const struct dr_command *c = dr_commands; c->name; c++)
        fprintf(out, "  %-10s %s\n", c->name, c->summary);
    fprintf(out, "\n'drender help COMMAND' or 'drender COMMAND --help' describes one command;\n"
                 "'man drender' has the whole manual.\n"
                 "\nA request that would need more memory than the machine has (or than\n"
                 "$DRENDER_MEM_LIMIT, e.g. 8G) is refused before it starts (exit 2).\n");
}

static void cmd_help_usage(FILE *out)
{
    fprintf(out, "usage: drender help [COMMAND]\n\nShows the list of commands, or the options of COMMAND.\n");
}

static int cmd_help(int argc, char **argv)
{
    if (argc < 2) {
        main_usage(stdout);
        return DR_EXIT_OK;
    }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
        cmd_help_usage(stdout);
        return DR_EXIT_OK;
    }
    const struct dr_command *c = dr_command_find(argv[1]);
    if (!c) {
        cli_error("help", "unknown command '%s' (see 'drender help')", argv[1]);
        return DR_EXIT_USAGE;
    }
    c->usage(stdout);
    return DR_EXIT_OK;
}

static int run_command(int argc, char **argv)
{
    cli_mark_start();
    if (argc < 2) {
        main_usage(stderr);
        return DR_EXIT_USAGE;
    }
    const char *name = argv[1];
    if (strcmp(name, "--help") == 0 || strcmp(name, "-h") == 0) {
        main_usage(stdout);
        return DR_EXIT_OK;
    }
    if (strcmp(name, "--version") == 0 || strcmp(name, "-V") == 0) {
        printf("drender %s\n", DR_VERSION);
        return DR_EXIT_OK;
    }
    if (name[0] == '-') {
        cli_error(NULL, "unknown option '%s' (see 'drender --help')", name);
        return DR_EXIT_USAGE;
    }
    const struct dr_command *c = dr_command_find(name);
    if (!c) {
        cli_error(NULL, "'%s' is not a drender command (see 'drender help')", name);
        return DR_EXIT_USAGE;
    }
    cli_limits_init();
    long long epoch;
    if (dr_source_date_epoch(&epoch) < 0) {   /* (before any work: a bad stamp would make every output unreproducible) */
        cli_error(name, "%s", dr_last_error());
        return DR_EXIT_USAGE;
    }
    return c->run(argc - 1, argv + 1);
}

int main(int argc, char **argv)
{
    const char *cmd = argc >= 2 && dr_command_find(argv[1]) ? argv[1] : NULL;
    return cli_close_stdout(cmd, run_command(argc, argv));
}
