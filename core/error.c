#include "error.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static _Thread_local char error_buf[1024];

void dr_set_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(error_buf, sizeof error_buf, fmt, ap);
    va_end(ap);
}

const char *dr_last_error(void) { return error_buf[0] ? error_buf : "unknown error"; }

bool dr_last_error_is_nomem(void) { return strstr(error_buf, "out of memory") != NULL; }

static void default_warn(const char *msg) { fprintf(stderr, "drender: warning: %s\n", msg); }
static dr_warn_fn warn_handler = default_warn;

void dr_set_warn_handler(dr_warn_fn fn) { warn_handler = fn ? fn : default_warn; }

void dr_warn(const char *fmt, ...)
{
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    warn_handler(buf);
}
