/* Files written by another program or library that does not report its
 * write errors (tinygltf's std::ofstream, gnuplot): telling afterwards that
 * such a file is cut short, and why. */
#ifndef DR_CUT_SHORT_H
#define DR_CUT_SHORT_H

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Whether the PNG at path ends with its IEND chunk (a PNG cut short does not). */
bool dr_png_complete(const char *path);

/* Why the file at path stopped short, as a message in buf (returned): the
 * process's file-size limit when it has one ("File too large"), a
 * filesystem with next to no room left ("No space left on device"), or else
 * unknown ("disk full?"). */
const char *dr_why_cut_short(const char *path, char *buf, size_t size);

#ifdef __cplusplus
}
#endif

#endif
