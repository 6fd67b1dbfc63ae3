#include "cut_short.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/statvfs.h>

bool dr_png_complete(const char *path)
{
    /* the last chunk: length 0, "IEND", its CRC */
    static const unsigned char iend[12] = {0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82};
    unsigned char tail[12];
    FILE *f = fopen(path, "rb");
    bool ok = f && fseek(f, -12, SEEK_END) == 0 && fread(tail, 1, 12, f) == 12 && memcmp(tail, iend, 12) == 0;
    if (f)
        fclose(f);
    return ok;
}

const char *dr_why_cut_short(const char *path, char *buf, size_t size)
{
    /* (a file stops at the limit, or short of it when its writer seeks past
     * it: a process under a limit is taken to have met it) */
    struct rlimit rl;
    if (getrlimit(RLIMIT_FSIZE, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) {
        snprintf(buf, size, "%s (the file-size limit, ulimit -f: %llu bytes)", strerror(EFBIG),
                 (unsigned long long)rl.rlim_cur);
        return buf;
    }
    char dir[4096];
    const char *slash = strrchr(path, '/');
    if (slash)
        snprintf(dir, sizeof dir, "%.*s", (int)(slash - path + 1), path);
    else
        snprintf(dir, sizeof dir, ".");
    struct statvfs fs;
    if (statvfs(dir, &fs) == 0 && (unsigned long long)fs.f_bavail * fs.f_frsize < (1ull << 20))
        snprintf(buf, size, "%s", strerror(ENOSPC));
    else
        snprintf(buf, size, "the written file is incomplete (disk full?)");
    return buf;
}
