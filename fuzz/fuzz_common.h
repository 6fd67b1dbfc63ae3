/* Shared by the libFuzzer targets of fuzz/: a private scratch directory (in
 * /dev/shm when it exists, so the file-based APIs cost no disk I/O), writing
 * one input into it, and silencing core's warnings. */
#ifndef DR_FUZZ_COMMON_H
#define DR_FUZZ_COMMON_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "error.h"
#include "image_io.h"

#ifndef DR_FUZZ_DATA
#define DR_FUZZ_DATA "tests/data"
#endif

static char fuzz_dir[256];

static inline void fuzz_quiet_warn(const char *msg) { (void)msg; }

/* Creates the scratch directory (removed at exit) and points TMPDIR at it,
 * so temporary files of the image reader land there too. Images are limited
 * to 512 MiB decoded, as DRENDER_MEM_LIMIT=512M would: below libFuzzer's
 * -rss_limit_mb, so that a tiny file claiming a huge image exercises the
 * refusal instead of reporting an out-of-memory. */
static inline void fuzz_cleanup(void)
{
    char cmd[300];
    if (fuzz_dir[0]) {
        snprintf(cmd, sizeof cmd, "rm -rf '%s'", fuzz_dir);
        if (system(cmd) != 0) {
            /* nothing more to do */
        }
    }
}

static inline void fuzz_setup(void)
{
    const char *base = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : (getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    snprintf(fuzz_dir, sizeof fuzz_dir, "%s/drender-fuzz.XXXXXX", base);
    if (!mkdtemp(fuzz_dir)) {
        perror("mkdtemp");
        abort();
    }
    setenv("TMPDIR", fuzz_dir, 1);
    atexit(fuzz_cleanup);
    dr_set_warn_handler(fuzz_quiet_warn);
    dr_image_set_max_bytes(512ull << 20);
}

/* Writes the input to fuzz_dir/NAME; returns the path (static buffer). */
static inline const char *fuzz_write(const char *name, const uint8_t *data, size_t size)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/%s", fuzz_dir, name);
    FILE *f = fopen(path, "wb");
    if (!f) {
        perror(path);
        abort();
    }
    if (size && fwrite(data, 1, size, f) != size) {
        perror(path);
        abort();
    }
    fclose(f);
    return path;
}

/* Copies DR_FUZZ_DATA/REL into the scratch directory as NAME (so that a
 * .gltf input can reference external buffers and images by file name). */
static inline void fuzz_copy_aux(const char *rel, const char *name)
{
    char src[512];
    snprintf(src, sizeof src, "%s/%s", DR_FUZZ_DATA, rel);
    FILE *in = fopen(src, "rb");
    if (!in)
        return;
    char *buf = malloc(1 << 20);
    size_t n = buf ? fread(buf, 1, 1 << 20, in) : 0;
    fclose(in);
    if (buf)
        fuzz_write(name, (const uint8_t *)buf, n);
    free(buf);
}

#endif
