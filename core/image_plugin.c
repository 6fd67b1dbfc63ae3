/* The functions of image_io.h and vis.h as trampolines into the image plugin
 * (why: image_plugin.h). Loading happens once, under pthread_once, on the
 * first call that needs the library; every later call is one indirect call. */
#include "image_plugin.h"

#include <dlfcn.h>
#include <limits.h>
#include <stdbool.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "error.h"
#include "image_io.h"
#include "vis.h"

#ifndef DR_LIBDIR
#define DR_LIBDIR "/usr/local/lib/drender"
#endif

/* Defined when image_io.o is linked into this program (tests, fuzzing). */
extern const struct dr_image_plugin *dr_image_plugin_table(void) __attribute__((weak));

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static const struct dr_image_plugin *_Atomic plugin;   /* set once by load() */
static char load_error[1024];
/* dr_image_set_max_bytes and dr_image_set_threads before the plugin is
 * loaded: kept and handed over. */
static _Atomic unsigned long long max_bytes;
static atomic_bool max_bytes_set;
static _Atomic int threads;
static atomic_bool threads_set;

/* Directory of the running executable, with a trailing '/'; "" if unknown. */
static void exe_dir(char *dir, size_t size)
{
    ssize_t n = readlink("/proc/self/exe", dir, size - 1);
    dir[n > 0 ? n : 0] = '\0';
    char *slash = strrchr(dir, '/');
    if (slash)
        slash[1] = '\0';
    else
        dir[0] = '\0';
}

/* Tries one candidate file; on failure says why in load_error. */
static const struct dr_image_plugin *try_open(const char *path)
{
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    const bool opened = h != NULL;
    const char *why = NULL;
    if (opened) {
        const struct dr_image_plugin *(*get)(void);
        *(void **)&get = dlsym(h, "dr_image_plugin_table");
        if (get && get()->version == DR_IMAGE_PLUGIN_VERSION)
            return get();   /* the handle stays open for the process's life */
        why = get ? "built for another drender version" : "no dr_image_plugin_table";
        dlclose(h);
    } else {
        why = dlerror();
    }
    if (opened)   /* dlerror() names the file itself; our own reasons do not */
        snprintf(load_error, sizeof load_error, "%s: %s", path, why);
    else
        snprintf(load_error, sizeof load_error, "%s", why ? why : path);
    return NULL;
}

/* Search order: $DRENDER_IMAGE_LIB; beside the executable (the build tree,
 * where tests/ and bench/ programs sit one level down); the install
 * directory ../lib/drender relative to the executable; DR_LIBDIR. */
static const struct dr_image_plugin *find_plugin(void)
{
    const struct dr_image_plugin *found = NULL;
    if (dr_image_plugin_table) {
        found = dr_image_plugin_table();
    } else {
        const char *env = getenv("DRENDER_IMAGE_LIB");
        if (env && *env) {
            found = try_open(env);
        } else {
            char dir[PATH_MAX], path[PATH_MAX + 64];
            exe_dir(dir, sizeof dir);
            const char *rel[] = {"", "../", "../lib/drender/"};
            for (size_t i = 0; !found && dir[0] && i < sizeof rel / sizeof *rel; i++) {
                snprintf(path, sizeof path, "%s%s%s", dir, rel[i], DR_IMAGE_PLUGIN_FILE);
                if (access(path, F_OK) == 0)
                    found = try_open(path);
            }
            if (!found && access(DR_LIBDIR "/" DR_IMAGE_PLUGIN_FILE, F_OK) == 0)
                found = try_open(DR_LIBDIR "/" DR_IMAGE_PLUGIN_FILE);
            else if (!found && !load_error[0])
                snprintf(load_error, sizeof load_error,
                         "%s not found in %s, %s../, %s../lib/drender/ or %s (set DRENDER_IMAGE_LIB to its path)",
                         DR_IMAGE_PLUGIN_FILE, dir, dir, dir, DR_LIBDIR);
        }
    }
    return found;
}

/* Publishes the plugin, then hands over the settings made before it was
 * there (dr_image_set_max_bytes and _threads do the other half of this
 * hand-shake). */
static void load(void)
{
    const struct dr_image_plugin *p = find_plugin();
    atomic_store(&plugin, p);
    if (p && atomic_load(&max_bytes_set))
        p->set_max_bytes(atomic_load(&max_bytes));
    if (p && atomic_load(&threads_set))
        p->set_threads(atomic_load(&threads));
}

/* The plugin, loading it if needed; NULL with dr_last_error set if it
 * cannot be loaded (an installation problem, so the message says where it
 * looked). */
static const struct dr_image_plugin *get_plugin(void)
{
    pthread_once(&load_once, load);
    const struct dr_image_plugin *p = atomic_load(&plugin);
    if (!p)
        dr_set_error("cannot load drender's image library (OpenImageIO): %s", load_error);
    return p;
}

int dr_image_read(const char *path, struct dr_image *img)
{
    const struct dr_image_plugin *p = get_plugin();
    if (!p) {
        if (img)
            memset(img, 0, sizeof *img);
        return DR_ERR_IO;
    }
    return p->read(path, img);
}

int dr_image_read_memory(const void *bytes, size_t size, const char *name_hint, struct dr_image *img)
{
    const struct dr_image_plugin *p = get_plugin();
    if (!p) {
        if (img)
            memset(img, 0, sizeof *img);
        return DR_ERR_IO;
    }
    return p->read_memory(bytes, size, name_hint, img);
}

int dr_image_read_memory8(const void *bytes, size_t size, const char *name_hint, struct dr_image *img)
{
    const struct dr_image_plugin *p = get_plugin();
    if (!p) {
        if (img)
            memset(img, 0, sizeof *img);
        return DR_ERR_IO;
    }
    return p->read_memory8(bytes, size, name_hint, img);
}

/* Does not load the plugin: the limit is set at start-up by every command. */
void dr_image_set_max_bytes(unsigned long long bytes)
{
    atomic_store(&max_bytes, bytes);
    atomic_store(&max_bytes_set, true);
    /* Loaded already: forward. Being loaded: load() sees the flag after
     * publishing, so at least one of the two forwards (both: harmless). */
    const struct dr_image_plugin *p = atomic_load(&plugin);
    if (p)
        p->set_max_bytes(bytes);
}

unsigned long long dr_image_max_bytes(void)
{
    if (atomic_load(&max_bytes_set))
        return atomic_load(&max_bytes);
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    return pages > 0 && page > 0 ? (unsigned long long)pages * (unsigned long long)page : 0;
}

void dr_image_set_threads(int n)
{
    atomic_store(&threads, n > 0 ? n : 0);
    atomic_store(&threads_set, true);
    const struct dr_image_plugin *p = atomic_load(&plugin);   /* (as dr_image_set_max_bytes) */
    if (p)
        p->set_threads(n > 0 ? n : 0);
}

bool dr_image_library_ok(void)
{
    return get_plugin() != NULL;
}

static void *preload_main(void *arg)
{
    (void)arg;
    pthread_once(&load_once, load);
    return NULL;
}

void dr_image_library_preload(void)
{
    static atomic_flag asked = ATOMIC_FLAG_INIT;
    if (atomic_flag_test_and_set(&asked))
        return;
    pthread_attr_t attr;
    pthread_t t;
    if (pthread_attr_init(&attr) != 0)
        return;
    pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
    pthread_create(&t, &attr, preload_main, NULL);   /* (failing: the first use loads it) */
    pthread_attr_destroy(&attr);
}

/* Formats every OpenImageIO build drender supports writes (tests/test_image.c
 * checks each against the library). Answering for these without the library
 * lets `render` of an untextured scene trace its first ray without it. */
const char *const dr_image_common_write_formats[] = {"exr", "png", "jpg", "jpeg", "hdr", "tif", "tiff",
                                                     NULL};

static bool common_write_format(const char *path)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash) || dot == path || (slash && dot == slash + 1))
        return false;
    for (int i = 0; dr_image_common_write_formats[i]; i++)
        if (strcasecmp(dot + 1, dr_image_common_write_formats[i]) == 0)
            return true;
    return false;
}

bool dr_image_can_write(const char *path)
{
    if (!path || !*path)
        return false;
    if (common_write_format(path))
        return true;
    const struct dr_image_plugin *p = get_plugin();
    return p && p->can_write(path);
}

int dr_image_write(const char *path, int width, int height, int channels, const float *pixels)
{
    return dr_image_write_encoded(path, width, height, channels, pixels, true);
}

int dr_image_write_encoded(const char *path, int width, int height, int channels, const float *pixels,
                           bool srgb_encode)
{
    const struct dr_image_plugin *p = get_plugin();
    return p ? p->write_encoded(path, width, height, channels, pixels, srgb_encode) : DR_ERR_IO;
}

int dr_volume_read(const char *path, const char *grid, struct dr_volume *vol)
{
    const struct dr_image_plugin *p = get_plugin();
    if (!p) {
        if (vol)
            memset(vol, 0, sizeof *vol);
        return DR_ERR_IO;
    }
    return p->read_volume(path, grid, vol);
}

int dr_colormap_diverging(const float *t, int width, int height, float *rgb)
{
    const struct dr_image_plugin *p = get_plugin();
    return p ? p->colormap_diverging(t, width, height, rgb) : DR_ERR_IO;
}
