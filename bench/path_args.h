/* The command line the bench's path-tracing programs share (path_rays.c,
 * soa_floor.c): SCENE [WIDTH HEIGHT SPP [THREADS [MAX_DEPTH]]]. */
#ifndef DR_BENCH_PATH_ARGS_H
#define DR_BENCH_PATH_ARGS_H

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>

#include "error.h"
#include "scene.h"

struct path_args {
    const char *scene;
    int width, height, spp, threads, max_depth;
};

/* Parses argv into a (spp_default when SPP is not given; 256x256, 2
 * threads, depth 8 otherwise). Prints the usage or the error under the
 * program's name and returns false when the line is wrong. */
static inline bool path_args_parse(int argc, char **argv, const char *program, int spp_default,
                                   struct path_args *a)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s SCENE [WIDTH HEIGHT SPP [THREADS [MAX_DEPTH]]]\n", program);
        return false;
    }
    *a = (struct path_args){argv[1], 256, 256, spp_default, 2, 8};
    if (argc > 4)
        a->width = atoi(argv[2]), a->height = atoi(argv[3]), a->spp = atoi(argv[4]);
    if (argc > 5)
        a->threads = atoi(argv[5]);
    if (argc > 6)
        a->max_depth = atoi(argv[6]);
    if (a->width < 1 || a->height < 1 || a->spp < 1 || a->threads < 1 || a->threads > 64 || a->max_depth < 1 ||
        a->max_depth > 255) {
        fprintf(stderr, "%s: bad size, spp, threads or depth\n", program);
        return false;
    }
    return true;
}

/* Parses the command line and loads its scene into *scene. Returns the
 * exit status for a failure (2: a wrong command line, 1: a scene that does
 * not load; the message printed under the program's name), 0 otherwise. */
static inline int path_args_open(int argc, char **argv, const char *program, int spp_default, struct path_args *a,
                                 struct dr_scene **scene)
{
    if (!path_args_parse(argc, argv, program, spp_default, a))
        return 2;
    *scene = dr_scene_load(a->scene);
    if (!*scene) {
        fprintf(stderr, "%s: %s\n", program, dr_last_error());   /* (the error names the file) */
        return 1;
    }
    return 0;
}

#endif
