/* What loading the image library costs in resident memory: the share of a
 * render's peak memory that is OpenImageIO's, for part d of bench/run.sh.
 *
 *   image_lib_rss PLUGIN
 *
 * loads PLUGIN (libdrender-image.so) as drender does (dlopen, RTLD_NOW,
 * core/image_plugin.c) into a process that has no other image code, and
 * prints one JSON object: resident memory before and after the load, the
 * process's peak, the largest parts after it by mapping (the heap,
 * libraries by file) from /proc/self/smaps, and the dlopen's wall time
 * (part e: what a textured scene's load, or an image write, waits for). This program links drender's own
 * functions the plugin calls back into (error reporting, sRGB curves, image
 * release, the SOURCE_DATE_EPOCH stamp, the cause of a cut-short file;
 * `nm -D --undefined-only libdrender-image.so | grep dr_` lists them) and exports them (-rdynamic, as the drender binary does), but not
 * image_io.o: OpenImageIO is loaded only by the dlopen. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "error.h"
#include "cut_short.h"
#include "image.h"
#include "source_date.h"

/* VmRSS or VmHWM of this process, KiB (-1: unreadable). */
static long status_kib(const char *field)
{
    FILE *f = fopen("/proc/self/status", "r");
    if (!f)
        return -1;
    char line[256];
    long v = -1;
    size_t n = strlen(field);
    while (fgets(line, sizeof line, f))
        if (strncmp(line, field, n) == 0 && line[n] == ':')
            v = strtol(line + n + 1, NULL, 10);
    fclose(f);
    return v;
}

#define TOP 6

/* The TOP mappings (by name: a file, [heap], or "anonymous") with the most
 * resident memory, as JSON members. */
static void print_largest(void)
{
    FILE *f = fopen("/proc/self/smaps", "r");
    if (!f)
        return;
    enum { MAX = 2048 };
    static char name[MAX][256];
    static long kib[MAX];
    int n = 0, cur = -1;
    char line[1024];
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        char path[256] = "";
        if (sscanf(line, "%lx-%lx %*s %*s %*s %*s %255s", &lo, &hi, path) >= 2 && strchr(line, '-') < strchr(line, ' ')) {
            const char *key = path[0] ? path : "anonymous";
            for (cur = 0; cur < n && strcmp(name[cur], key) != 0; cur++)
                ;
            if (cur == n && n < MAX) {
                snprintf(name[n], sizeof name[n], "%s", key);
                kib[n++] = 0;
            }
            if (cur >= MAX)
                cur = -1;
        } else if (cur >= 0 && strncmp(line, "Rss:", 4) == 0) {
            kib[cur] += strtol(line + 4, NULL, 10);
        }
    }
    fclose(f);
    printf(", \"largest_kib\": {");
    for (int t = 0; t < TOP && t < n; t++) {
        int best = t;
        for (int i = t + 1; i < n; i++)
            if (kib[i] > kib[best])
                best = i;
        long k = kib[best];
        char s[256];
        memcpy(s, name[best], sizeof s);
        kib[best] = kib[t], memcpy(name[best], name[t], sizeof s);
        kib[t] = k, memcpy(name[t], s, sizeof s);
        const char *base = strrchr(name[t], '/');
        printf("%s\"%s\": %ld", t ? ", " : "", base ? base + 1 : name[t], kib[t]);
    }
    printf("}, \"mappings\": %d", n);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: image_lib_rss PLUGIN\n");
        return 2;
    }
    /* drender's functions the plugin calls, called once here so that the
     * linker takes them from libdrender.a (for -rdynamic to export) */
    struct dr_image none = {0};
    dr_image_release(&none);
    dr_set_error("%s", "");
    if (dr_linear_to_srgb(dr_srgb_to_linear(0.5)) < 0.0)
        return 1;
    char stamp[32], cause[64];
    (void)dr_source_date_string(stamp, sizeof stamp);
    (void)dr_why_cut_short("", cause, sizeof cause);
    long before = status_kib("VmRSS");
    double t0 = dr_clock_seconds();
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    double load_seconds = dr_clock_seconds() - t0;
    if (!h) {
        fprintf(stderr, "image_lib_rss: %s\n", dlerror());
        return 1;
    }
    long after = status_kib("VmRSS"), peak = status_kib("VmHWM");
    printf("{\"rss_before_kib\": %ld, \"rss_after_kib\": %ld, \"peak_kib\": %ld, \"load_seconds\": %.4f", before, after,
           peak, load_seconds);
    print_largest();
    printf("}\n");
    return 0;
}
