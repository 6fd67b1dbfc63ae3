/* The image library as a plugin.
 *
 * OpenImageIO links about 260 shared libraries; resolving them costs a process
 * about 0.23 s before main() runs, which every `drender --help`, every failed
 * option check and every batch-script call paid. So image_io.cpp and vis.cpp
 * (the only code that touches OpenImageIO) are built into
 * libdrender-image.so, and the functions of image_io.h / vis.h are small
 * trampolines (image_plugin.c) that load it on first use: help, option
 * errors and untextured scenes reach their first ray without it.
 *
 * Why not load it in the background from the start, to overlap it with scene
 * loading? Tried and measured: glibc holds a lock during dlopen that
 * pthread_create also takes, so the render's (and Embree's) thread creation
 * waited for the whole load (0.34 s in a 4-line test) and nothing overlapped.
 * So the load starts later, once a render's workers exist: the CLI sets
 * dr_image_library_preload as the parallel runs' started hook (parallel.h),
 * and the render overlaps the load instead of the write waiting for it.
 * A scene with images starts the load as soon as its file is parsed, on
 * the thread that then decodes them (gltf_load.cpp's dr_pending_images),
 * and builds its ray structure meanwhile (scene.c): that build makes no
 * thread of its own before Embree's task system has started, and starting
 * it waits for the dlopen too (it loads a library), so dr_scene_load_opts
 * starts it first (accel.h's dr_accel_warm_up).
 *
 * The load itself is mostly the dynamic loader's symbol search through those
 * libraries; the Makefile names the ones most bound to as the plugin's first
 * dependencies so that the search meets them early (167 -> 111 ms;
 * scripts/image-lib-order.sh).
 *
 * Programs that link image_io.o and vis.o directly (tests, fuzz targets) get
 * the table through the weak symbol below and never dlopen anything. */
#ifndef DR_IMAGE_PLUGIN_H
#define DR_IMAGE_PLUGIN_H

#include <stdbool.h>
#include <stddef.h>

#include "image.h"
#include "image_io.h"

#ifdef __cplusplus
extern "C" {
#endif

#define DR_IMAGE_PLUGIN_VERSION 4
#define DR_IMAGE_PLUGIN_FILE "libdrender-image.so"

/* The plugin's functions; same contracts as image_io.h and vis.h. */
struct dr_image_plugin {
    int version;   /* DR_IMAGE_PLUGIN_VERSION of the plugin's build */
    int (*read)(const char *path, struct dr_image *img);
    int (*read_memory)(const void *bytes, size_t size, const char *name_hint, struct dr_image *img);
    void (*set_max_bytes)(unsigned long long bytes);
    bool (*can_write)(const char *path);
    int (*write_encoded)(const char *path, int width, int height, int channels, const float *pixels,
                         bool srgb_encode);
    int (*colormap_diverging)(const float *t, int width, int height, float *rgb);
    int (*read_volume)(const char *path, const char *grid, struct dr_volume *vol);
    int (*read_memory8)(const void *bytes, size_t size, const char *name_hint, struct dr_image *img);
    void (*set_threads)(int threads);
};

/* Exported by the plugin (image_io.cpp): its table. */
const struct dr_image_plugin *dr_image_plugin_table(void);

/* vis.cpp's colour map, put in the table by image_io.cpp. */
int drp_colormap_diverging(const float *t, int width, int height, float *rgb);

/* File-name extensions (lower case, NULL-terminated) for which
 * dr_image_can_write answers true without loading the library. */
extern const char *const dr_image_common_write_formats[];


#ifdef __cplusplus
}
#endif
#endif
