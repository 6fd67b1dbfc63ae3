/* See stale_temps.h. */
#include "stale_temps.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

/* NAME.tmpPID or .NAME.tmpPID.EXT: the writer's process id, 0 if not such a name. */
static long temp_pid(const char *name)
{
    const char *p = strstr(name, ".tmp");
    while (p) {
        const char *d = p + 4;
        char *end;
        long pid = strtol(d, &end, 10);
        if (end > d && pid > 0 && (*end == '\0' || (*end == '.' && name[0] == '.' && !strchr(end + 1, '/'))))
            return pid;
        p = strstr(p + 1, ".tmp");
    }
    return 0;
}

static bool process_gone(long pid)
{
    return pid != (long)getpid() && kill((pid_t)pid, 0) != 0 && errno == ESRCH;
}

/* Removes the files of a directory, then the directory (not recursive). */
static bool remove_flat_dir(const char *path)
{
    DIR *d = opendir(path);
    if (!d)
        return false;
    struct dirent *e;
    char sub[PATH_MAX];
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0) {
            snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
            unlink(sub);
        }
    closedir(d);
    return rmdir(path) == 0;
}

int cli_remove_stale_temps(const char *dir, const char *output)
{
    int removed = 0;
    char path[PATH_MAX];
    DIR *d = opendir(dir);
    if (d) {
        struct dirent *e;
        while ((e = readdir(d))) {
            const char *n = e->d_name;
            bool stale = strcmp(n, "loss.csv.tmp") == 0 || strcmp(n, ".loss.tmp.png") == 0;
            long pid = stale ? 0 : temp_pid(n);
            if (pid > 0)
                stale = process_gone(pid);
            if (!stale)
                continue;
            snprintf(path, sizeof path, "%s/%s", dir, n);
            struct stat st;
            if (lstat(path, &st) == 0 && S_ISREG(st.st_mode) && unlink(path) == 0)
                removed++;
        }
        closedir(d);
    }
    if (output) {
        /* the glTF writer's private directory: .BASE.tmpXXXXXX beside OUTPUT */
        char odir[PATH_MAX], prefix[PATH_MAX];
        const char *slash = strrchr(output, '/');
        const char *base = slash ? slash + 1 : output;
        if (!slash)
            snprintf(odir, sizeof odir, ".");
        else
            snprintf(odir, sizeof odir, "%.*s", slash == output ? 1 : (int)(slash - output), output);
        snprintf(prefix, sizeof prefix, ".%s.tmp", base);
        size_t pl = strlen(prefix);
        DIR *od = opendir(odir);
        if (od) {
            struct dirent *e;
            while ((e = readdir(od)))
                if (strncmp(e->d_name, prefix, pl) == 0 && strlen(e->d_name) == pl + 6) {
                    snprintf(path, sizeof path, "%s/%s", odir, e->d_name);
                    struct stat st;
                    if (lstat(path, &st) == 0 && S_ISDIR(st.st_mode) && remove_flat_dir(path))
                        removed++;
                }
            closedir(od);
        }
    }
    return removed;
}
