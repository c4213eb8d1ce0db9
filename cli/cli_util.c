/* cli_util.c — option parsing and staging folders for the cli/cmd_*.c commands (see
 * cli_util.h). */
#define _GNU_SOURCE /* nftw flags */
#include "cli/cli_util.h"
#include "tensor/tensor.h"
#include <dirent.h>
#include <errno.h>
#include <ftw.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

void lm_cli_init(lm_cli *c, const char *prog, int argc, char **argv)
{
    c->prog = prog;
    c->argc = argc;
    c->argv = argv;
    c->i = 1;
}

int lm_cli_done(const lm_cli *c) { return c->i >= c->argc; }

int lm_cli_is_help(const lm_cli *c)
{
    const char *a = c->argv[c->i];
    return !strcmp(a, "--help") || !strcmp(a, "-h");
}

int lm_cli_error(const lm_cli *c, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    for (char *p = msg; *p; p++) /* one line, whatever the message holds */
        if (*p == '\n' || *p == '\r') *p = ' ';
    fprintf(stderr, "%s: %s\n", c->prog, msg);
    return 2;
}

int lm_cli_unknown(const lm_cli *c)
{
    return lm_cli_error(c, "unknown option '%s' (see '%s --help')", c->argv[c->i], c->prog);
}

int lm_cli_value(lm_cli *c, const char *name, const char **value)
{
    const char *a = c->argv[c->i];
    size_t n = strlen(name);
    if (strncmp(a, name, n) != 0) return 0;
    if (a[n] == '=') {
        *value = a + n + 1;
        c->i++;
        return 1;
    }
    if (a[n] != 0) return 0;
    if (c->i + 1 >= c->argc) {
        lm_cli_error(c, "%s needs a value", name);
        return -1;
    }
    *value = c->argv[c->i + 1];
    c->i += 2;
    return 1;
}

int lm_cli_flag(lm_cli *c, const char *name, int *flag)
{
    const char *a = c->argv[c->i];
    size_t n = strlen(name);
    if (strncmp(a, name, n) != 0 || (a[n] != 0 && a[n] != '=')) return 0;
    if (a[n] == '=') {
        lm_cli_error(c, "%s takes no value", name);
        return -1;
    }
    *flag = 1;
    c->i++;
    return 1;
}

int lm_cli_parse_ll(const char *s, long long *out)
{
    char *end;
    errno = 0;
    long long v = strtoll(s, &end, 10);
    if (!*s || *end || errno) return -1;
    *out = v;
    return 0;
}

int lm_cli_parse_real(const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (!*s || *end || errno || !isfinite(v)) return -1;
    *out = v;
    return 0;
}

int lm_cli_int(lm_cli *c, const char *name, long long lo, long long hi, long long *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    long long v;
    if (lm_cli_parse_ll(s, &v) != 0) {
        lm_cli_error(c, "%s: '%s' is not an integer in %lld..%lld", name, s, lo, hi);
        return -1;
    }
    if (v < lo || v > hi) {
        lm_cli_error(c, "%s: %lld is out of range (%lld..%lld)", name, v, lo, hi);
        return -1;
    }
    *out = v;
    return 1;
}

int lm_cli_real(lm_cli *c, const char *name, double lo, double hi, double *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    double v;
    if (lm_cli_parse_real(s, &v) != 0) {
        lm_cli_error(c, "%s: '%s' is not a finite number in %g..%g", name, s, lo, hi);
        return -1;
    }
    if (v < lo || v > hi) {
        lm_cli_error(c, "%s: %g is out of range (%g..%g)", name, v, lo, hi);
        return -1;
    }
    *out = v;
    return 1;
}

int lm_cli_threads(lm_cli *c, long long *out)
{
    return lm_cli_int(c, "--threads", 1, LM_MAX_THREADS, out);
}

int lm_cli_choice(lm_cli *c, const char *name, const char *const *choices, int *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    char list[256] = "";
    for (int k = 0; choices[k]; k++) {
        if (!strcmp(s, choices[k])) {
            *out = k;
            return 1;
        }
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s", k ? ", " : "", choices[k]);
    }
    lm_cli_error(c, "%s: unknown value '%s' (one of: %s)", name, s, list);
    return -1;
}

int lm_cli_parse_size(const char *s, long long lo, long long hi, int *h, int *w)
{
    char buf[64], *x;
    long long a, b;
    if (snprintf(buf, sizeof buf, "%s", s) >= (int)sizeof buf || !(x = strchr(buf, 'x')))
        return -1;
    *x = 0;
    if (lm_cli_parse_ll(buf, &a) || lm_cli_parse_ll(x + 1, &b) || a < lo || a > hi || b < lo ||
        b > hi)
        return -1;
    *h = (int)a, *w = (int)b;
    return 0;
}

int lm_cli_has_ext(const char *path, const char *ext)
{
    size_t n = strlen(path), m = strlen(ext);
    return n >= m && strcasecmp(path + n - m, ext) == 0;
}

/* 1 if dir is a folder with no entries but . and .. */
static int dir_is_empty(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return 0;
    struct dirent *e;
    int empty = 1;
    while (empty && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) empty = 0;
    closedir(d);
    return empty;
}

int lm_cli_stage_dir(const lm_cli *c, const char *dir, char *tmp, size_t n)
{
    struct stat st;
    if (stat(dir, &st) == 0 && !(S_ISDIR(st.st_mode) && dir_is_empty(dir))) {
        lm_cli_error(c, "%s: output already exists and is not an empty folder", dir);
        return -1;
    }
    int k = snprintf(tmp, n, "%s.tmp.%ld", dir, (long)getpid());
    if (k < 0 || (size_t)k >= n) {
        lm_cli_error(c, "%s: output path is too long", dir);
        return -1;
    }
    if (mkdir(tmp, 0777) != 0) {
        lm_cli_error(c, "%s: cannot create a folder: %s", tmp, strerror(errno));
        return -1;
    }
    return 0;
}

static int rm_entry(const char *p, const struct stat *st, int flag, struct FTW *f)
{
    (void)st, (void)flag, (void)f;
    return remove(p);
}

void lm_cli_remove_tree(const char *dir)
{
    nftw(dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
}

int lm_cli_commit_dir(const lm_cli *c, const char *tmp, const char *dir)
{
    if (rename(tmp, dir) != 0) {
        lm_cli_error(c, "%s: cannot move the output into place: %s", dir, strerror(errno));
        lm_cli_remove_tree(tmp);
        return -1;
    }
    return 0;
}

int lm_cli_positional(lm_cli *c, const char **out, int *n)
{
    const char *a = c->argv[c->i];
    if (a[0] == '-' && a[1] == '-') return lm_cli_unknown(c);
    out[(*n)++] = a;
    c->i++;
    return 0;
}
