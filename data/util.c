/* util.c — FNV-1a, is-a-folder and mkdir -p (see util.h). What it is not: a file reader. */
#include "data/util.h"
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

uint64_t lm_fnv1a(uint64_t h, const void *bytes, size_t n)
{
    const unsigned char *p = bytes;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

uint64_t lm_fnv1a_str(uint64_t h, const char *s) { return lm_fnv1a(h, s, strlen(s)); }

int lm_is_dir(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

int lm_make_dirs(const char *path, char *top, size_t tn, char *failed, size_t fn)
{
    if (top && tn) top[0] = 0;
    if (failed && fn) failed[0] = 0;
    char *buf = strdup(path);
    if (!buf) return errno = ENOMEM, -1;
    int rc = 0;
    for (char *p = buf + (buf[0] != 0); rc == 0; p++) {
        if (*p != '/' && *p != 0) continue;
        char ch = *p;
        *p = 0;
        int made = mkdir(buf, 0777) == 0;
        if (!made && errno != EEXIST) {
            if (failed && fn) snprintf(failed, fn, "%s", buf);
            rc = -1;
        } else if (made && top && tn && !top[0]) {
            snprintf(top, tn, "%s", buf);
        }
        *p = ch;
        if (!ch) break;
    }
    int e = errno;
    free(buf);
    errno = e;
    return rc;
}
