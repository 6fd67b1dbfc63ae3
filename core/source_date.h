/* SOURCE_DATE_EPOCH (reproducible-builds.org's convention): the time to
 * stamp into outputs instead of now, so that the same render gives the same
 * bytes. drender's images carry a time only where the format has a DateTime
 * field (OpenImageIO writes one into EXR and TIFF files). */
#ifndef DR_SOURCE_DATE_H
#define DR_SOURCE_DATE_H

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* 0: unset or empty; 1: *secs holds its value; -1: malformed (not a
 * decimal number of seconds since 1970-01-01 UTC, or one past the year
 * 9999), with dr_set_error's message naming the variable and its value. */
int dr_source_date_epoch(long long *secs);

/* The DateTime string ("YYYY:MM:DD HH:MM:SS", UTC) of SOURCE_DATE_EPOCH
 * into buf (at least 20 bytes); false (buf untouched) when it is unset or
 * malformed. */
bool dr_source_date_string(char *buf, size_t size);

#ifdef __cplusplus
}
#endif

#endif
