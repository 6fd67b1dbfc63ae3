/* Minimal test harness: one process per test file. CHECK records a failure
 * and keeps going; TEST_END() returns non-zero if anything failed. */
#ifndef DR_TEST_H
#define DR_TEST_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

static int test_failures = 0;
static int test_checks = 0;

#define CHECK(cond, ...)                                                           \
    do {                                                                           \
        test_checks++;                                                             \
        if (!(cond)) {                                                             \
            test_failures++;                                                       \
            fprintf(stderr, "%s:%d: CHECK failed: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                          \
            fprintf(stderr, "\n");                                                 \
        }                                                                          \
    } while (0)

/* |a - b| <= tol */
#define CHECK_NEAR(a, b, tol, what)                                                \
    CHECK(fabs((double)(a) - (double)(b)) <= (tol), "%s: %.10g vs %.10g (tol %.3g)", \
          what, (double)(a), (double)(b), (double)(tol))

/* A test binary that ran no check fails: it tested nothing. */
#define TEST_END()                                                                 \
    (fprintf(stderr, "%s: %d checks, %d failed%s\n", __FILE__, test_checks, test_failures, \
             test_checks == 0 ? " (no check ran: failing)" : ""),                   \
     test_failures != 0 || test_checks == 0)

/* NAME in directory $ENV (default DEF); four buffers in turn, so a few
 * results can be held at once. */
static inline const char *path_in(const char *env, const char *def, const char *name)
{
    static char buf[4][4096];
    static int k;
    const char *dir = getenv(env);
    char *b = buf[k++ & 3];
    snprintf(b, sizeof buf[0], "%s/%s", dir && *dir ? dir : def, name);
    return b;
}

/* A bundled scene: $DR_SCENES/NAME, default scenes/NAME. */
static inline const char *scene_path(const char *name) { return path_in("DR_SCENES", "scenes", name); }

/* A shared glTF sample, REL under ../shared/gltf-samples beside the checkout
 * (the tests' directory is $DR_TESTDIR, default tests; the checkout may be
 * one level deeper, as a worktree); NULL if it is not there. One buffer:
 * copy the result to hold two. */
static inline const char *shared_sample(const char *rel)
{
    static char buf[4096];
    const char *dir = getenv("DR_TESTDIR");
    const char *roots[] = {"/../../shared/gltf-samples/", "/../../../shared/gltf-samples/"};
    for (int i = 0; i < 2; i++) {
        snprintf(buf, sizeof buf, "%s%s%s", dir && *dir ? dir : "tests", roots[i], rel);
        if (access(buf, R_OK) == 0)
            return buf;
    }
    return NULL;
}

#endif
