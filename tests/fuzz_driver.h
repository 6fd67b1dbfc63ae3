/* Replays the inputs of a libFuzzer target without libFuzzer, as a unit test
 * of `make test` (and, under ASan/UBSan, of `make sanitize`): every file of
 * fuzz/corpus/TARGET, the seeds and the minimised crashers of earlier fuzzing
 * (regress-*), goes through the target's LLVMFuzzerTestOneInput, whose own
 * checks abort on a broken invariant. Include after the target's .c file:
 *
 *   #include "../fuzz/fuzz_gltf.c"
 *   #include "fuzz_driver.h"
 *   DR_FUZZ_DRIVER("gltf")
 *
 * Run from the top directory (tests/run.sh does). */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int fuzz_cmp(const void *a, const void *b) { return strcmp(*(char *const *)a, *(char *const *)b); }

static int fuzz_replay(const char *target)
{
    char dir[256];
    snprintf(dir, sizeof dir, "fuzz/corpus/%s", target);
    DIR *d = opendir(dir);
    if (!d) {
        fprintf(stderr, "FAIL: cannot open %s (run from the top directory)\n", dir);
        return 1;
    }
    char *names[4096];
    int n = 0, regress = 0;
    struct dirent *e;
    while ((e = readdir(d)) && n < 4096)
        if (e->d_name[0] != '.')
            names[n++] = strdup(e->d_name);
    closedir(d);
    qsort(names, (size_t)n, sizeof *names, fuzz_cmp);
    int argc = 1;
    char *args[] = {(char *)"fuzz-driver", NULL}, **argv = args;
    LLVMFuzzerInitialize(&argc, &argv);
    for (int i = 0; i < n; i++) {
        char path[600];
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        FILE *f = fopen(path, "rb");
        if (!f) {
            fprintf(stderr, "FAIL: cannot read %s\n", path);
            return 1;
        }
        fseek(f, 0, SEEK_END);
        long size = ftell(f);
        fseek(f, 0, SEEK_SET);
        uint8_t *buf = malloc(size > 0 ? (size_t)size : 1);
        if (!buf || fread(buf, 1, (size_t)size, f) != (size_t)size) {
            fprintf(stderr, "FAIL: cannot read %s\n", path);
            return 1;
        }
        fclose(f);
        printf("%s\n", path);
        fflush(stdout);
        LLVMFuzzerTestOneInput(buf, (size_t)size);
        free(buf);
        regress += strncmp(names[i], "regress-", 8) == 0;
        free(names[i]);
    }
    printf("%d inputs of fuzz/corpus/%s replayed (%d regression inputs)\n", n, target, regress);
    if (n == 0) {
        fprintf(stderr, "FAIL: no inputs in %s\n", dir);
        return 1;
    }
    return 0;
}

#define DR_FUZZ_DRIVER(target)                                                                                         \
    int main(void) { return fuzz_replay(target); }
