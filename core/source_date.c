#include "source_date.h"

#include <errno.h>
#include <stdlib.h>
#include <time.h>

#include "error.h"

int dr_source_date_epoch(long long *secs)
{
    const char *env = getenv("SOURCE_DATE_EPOCH");
    if (!env || !*env)
        return 0;
    /* (digits only: strtoll would take a sign, spaces and "0x") */
    for (const char *c = env; *c; c++)
        if (*c < '0' || *c > '9')
            goto malformed;
    errno = 0;
    long long v = strtoll(env, NULL, 10);
    time_t t = (time_t)v;
    struct tm tm;
    if (errno != 0 || (long long)t != v || !gmtime_r(&t, &tm) || tm.tm_year + 1900 > 9999)
        goto malformed;
    *secs = v;
    return 1;
malformed:
    dr_set_error("SOURCE_DATE_EPOCH='%s' is not a number of seconds since 1970-01-01 (up to the year 9999); "
                 "unset it or give one such as 1700000000",
                 env);
    return -1;
}

bool dr_source_date_string(char *buf, size_t size)
{
    long long secs;
    if (dr_source_date_epoch(&secs) != 1)
        return false;
    time_t t = (time_t)secs;
    struct tm tm;
    return gmtime_r(&t, &tm) && strftime(buf, size, "%Y:%m:%d %H:%M:%S", &tm) > 0;
}
