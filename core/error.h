/* Error reporting for core/: constructors return NULL and action functions a
 * negative code; the message is kept per thread and read with dr_last_error().
 * core/ never prints errors and never exits: cli/ decides what the user sees. */
#ifndef DR_ERROR_H
#define DR_ERROR_H

#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    DR_OK = 0,
    DR_ERR_IO = -1,      /* a file could not be read or written          */
    DR_ERR_FORMAT = -2,  /* the file's content is malformed or unsupported */
    DR_ERR_ARG = -3,     /* an impossible request (bad option value)       */
    DR_ERR_NOMEM = -4,
    DR_ERR_INTERNAL = -5
};

#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
void dr_set_error(const char *fmt, ...);
const char *dr_last_error(void);
/* True if the last error is an allocation that failed: its message says "out
 * of memory" (every such message in core/ does, and no other does; a request
 * refused for the memory it would need says "would need ... more than"). The
 * CLI exits 1 for it, as for any work that failed, where the same call's other
 * errors are bad input (3) or usage (2). */
bool dr_last_error_is_nomem(void);

/* Warnings (things the scene has that drender ignores) go through one hook so
 * the CLI can route them; the default prints "drender: warning: ..." to stderr. */
typedef void (*dr_warn_fn)(const char *msg);
void dr_set_warn_handler(dr_warn_fn fn);
#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
void dr_warn(const char *fmt, ...);

#ifdef __cplusplus
}
#endif
#endif
