/* util.c — FNV-1a, is-a-folder, mkdir -p and field errors (see util.h).
 * What it is not: a file reader. */
#include "data/util.h"
#include <errno.h>
#include <math.h>
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

lm_status lm_err_fieldv(lm_err *e, lm_status s, const char *kind, const char *label,
                        const char *field, const char *fmt, va_list ap)
{
    char msg[400];
    vsnprintf(msg, sizeof msg, fmt, ap);
    return lm_err_set(e, s, "%s %s: %s: %s", kind, label, field, msg);
}

lm_status lm_err_field(lm_err *e, lm_status s, const char *kind, const char *label,
                       const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    lm_status r = lm_err_fieldv(e, s, kind, label, field, fmt, ap);
    va_end(ap);
    return r;
}

/* [+-]digits[.digits][e[+-]digits] over the whole text. */
static int decimal_syntax(const char *s, int integer)
{
    const char *p = s;
    if (*p == '+' || *p == '-') p++;
    int digits = 0;
    while (*p >= '0' && *p <= '9') p++, digits++;
    if (!integer && *p == '.') {
        p++;
        while (*p >= '0' && *p <= '9') p++, digits++;
    }
    if (!digits) return 0;
    if (!integer && (*p == 'e' || *p == 'E')) {
        p++;
        if (*p == '+' || *p == '-') p++;
        if (!(*p >= '0' && *p <= '9')) return 0;
        while (*p >= '0' && *p <= '9') p++;
    }
    return *p == 0;
}

int lm_parse_real(const char *s, double *v)
{
    if (!s || !decimal_syntax(s, 0)) return -1;
    errno = 0;
    double x = strtod(s, NULL);
    if (errno || !isfinite(x)) return -1;
    *v = x;
    return 0;
}

int lm_parse_int(const char *s, long long *v)
{
    if (!s || !decimal_syntax(s, 1)) return -1;
    errno = 0;
    long long x = strtoll(s, NULL, 10);
    if (errno) return -1;
    *v = x;
    return 0;
}

int lm_parse_list(const char *s, double lo, double hi, double *v, int max, char *why, size_t n)
{
    int k = 0;
    for (const char *p = s;; k++) {
        size_t len = strcspn(p, ",");
        char tok[64];
        if (len == 0) {
            snprintf(why, n, "element %d is empty", k + 1);
            return -1;
        }
        snprintf(tok, sizeof tok, "%.*s", (int)(len < 63 ? len : 63), p);
        if (k == max) {
            snprintf(why, n, "more than %d values", max);
            return -1;
        }
        if (len > 63 || lm_parse_real(tok, &v[k])) {
            snprintf(why, n, "'%s%s' is not a decimal number", tok, len > 63 ? "..." : "");
            return -1;
        }
        if (!(v[k] >= lo && v[k] <= hi)) {
            snprintf(why, n, "'%s' is out of range (%g..%g)", tok, lo, hi);
            return -1;
        }
        if (!p[len]) return k + 1;
        p += len + 1;
    }
}

int lm_path_relative(const char *from_dir, const char *to, char *out, size_t n)
{
    char *a = realpath(from_dir, NULL), *b = realpath(to, NULL);
    int rc = -1;
    if (a && b) {
        size_t i = 0, common = 0; /* where the shared folders end (at a '/' or the end) */
        while (a[i] == b[i]) {
            if (!a[i]) {
                common = i;
                break;
            }
            if (a[i] == '/') common = i;
            i++;
        }
        if (a[i] != b[i] && ((!a[i] && b[i] == '/') || (!b[i] && a[i] == '/'))) common = i;
        char buf[4096] = "";
        size_t k = 0;
        for (const char *p = a + common; *p; p++) /* one ".." per component left in a */
            if (*p == '/' && p[1] && k + 3 < sizeof buf)
                k += (size_t)snprintf(buf + k, sizeof buf - k, "../");
        const char *rest = b + common;
        while (*rest == '/') rest++;
        int m = snprintf(buf + k, sizeof buf - k, "%s", rest);
        k += (size_t)(m > 0 ? m : 0);
        if (k && buf[k - 1] == '/') buf[--k] = 0;
        if (!k) snprintf(buf, sizeof buf, ".");
        if (k < sizeof buf - 1 && strlen(buf) < n) {
            snprintf(out, n, "%s", buf);
            rc = 0;
        }
    }
    free(a);
    free(b);
    return rc;
}
