#include "film.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "error.h"

int dr_filter_parse(const char *text, struct dr_filter *f)
{
    if (strcmp(text, "box") == 0) {
        *f = (struct dr_filter){DR_FILTER_BOX, 0.0};
        return 0;
    }
    if (strcmp(text, "tent") == 0) {
        *f = (struct dr_filter){DR_FILTER_TENT, 0.0};
        return 0;
    }
    if (strncmp(text, "gaussian", 8) == 0 && (text[8] == '\0' || text[8] == ':')) {
        double s = DR_FILTER_GAUSSIAN_STDDEV;
        if (text[8] == ':') {
            char *end;
            s = strtod(text + 9, &end);
            if (end == text + 9 || *end != '\0' || !(s > 0.0) || s > 16.0) {
                dr_set_error("'%s': the gaussian's standard deviation must be a number of pixels in (0, 16]",
                             text);
                return DR_ERR_ARG;
            }
        }
        *f = (struct dr_filter){DR_FILTER_GAUSSIAN, s};
        return 0;
    }
    dr_set_error("unknown filter '%s' (available: box, tent, gaussian, gaussian:STDDEV)", text);
    return DR_ERR_ARG;
}

void dr_filter_format(const struct dr_filter *f, char *buf, size_t size)
{
    switch (f->kind) {
    case DR_FILTER_TENT: snprintf(buf, size, "tent"); return;
    case DR_FILTER_GAUSSIAN:
        snprintf(buf, size, "gaussian:%g", f->stddev > 0.0 ? f->stddev : DR_FILTER_GAUSSIAN_STDDEV);
        return;
    case DR_FILTER_BOX:
    default: snprintf(buf, size, "box"); return;
    }
}

int dr_film_check(const struct dr_film *f, int width, int height)
{
    int fw = dr_film_frame_w(f, width), fh = dr_film_frame_h(f, height);
    if (width < 1 || height < 1 || f->x0 < 0 || f->y0 < 0 || (int64_t)f->x0 + width > fw ||
        (int64_t)f->y0 + height > fh) {
        dr_set_error("the crop %d,%d,%d,%d does not lie inside the %dx%d frame", f->x0, f->y0, width, height, fw,
                     fh);
        return DR_ERR_ARG;
    }
    return 0;
}
