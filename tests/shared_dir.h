/* shared_dir.h — where the tests find the shared data: $LM_SHARED_DIR, else ../shared next to
 * the repository (found from this header's path, tests/ in the checkout). Header-only. */
#ifndef LM_TESTS_SHARED_DIR_H
#define LM_TESTS_SHARED_DIR_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static inline const char *shared_dir(void)
{
    static char buf[1024];
    const char *env = getenv("LM_SHARED_DIR");
    if (env) return env;
    snprintf(buf, sizeof buf, "%s", __FILE__);
    for (int k = 0; k < 2; k++) {
        char *s = strrchr(buf, '/');
        if (s) *s = 0;
        else snprintf(buf, sizeof buf, "..");
    }
    strncat(buf, "/../shared", sizeof buf - strlen(buf) - 1);
    return buf;
}

#endif
