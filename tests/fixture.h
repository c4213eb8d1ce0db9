/* fixture.h — helpers for tests that write fixture files: a mkdtemp folder (`tmpdir`, removed
 * with fixture_cleanup), paths inside it, file sizes, and CHECK_ERR for lm_err results (status,
 * words the one-line message must contain). Include after tests/check.h, with _GNU_SOURCE. */
#ifndef LM_TESTS_FIXTURE_H
#define LM_TESTS_FIXTURE_H
#include <ftw.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include "tensor/status.h"

static char tmpdir[256];

static int rm_entry(const char *p, const struct stat *st, int flag, struct FTW *f)
{
    (void)st, (void)flag, (void)f;
    return remove(p);
}

/* Remove tmpdir and everything below it. */
static inline void fixture_cleanup(void) { nftw(tmpdir, rm_entry, 16, FTW_DEPTH | FTW_PHYS); }

/* buf (>= 1024 bytes) = tmpdir/name */
static inline const char *tpath(char *buf, const char *name)
{
    snprintf(buf, 1024, "%s/%s", tmpdir, name);
    return buf;
}

static inline int msg_has(const lm_err *e, const char *a, const char *b)
{
    return strstr(e->msg, a) && (!b || strstr(e->msg, b));
}

/* The error must have status s, mention `a` (and `b`), and be a single line. */
#define CHECK_ERR(e, s, a, b)                                                                 \
    CHECK_MSG((e).status == (s) && msg_has(&(e), (a), (b)) && !strchr((e).msg, '\n'),         \
              "status %d (want %d), msg '%s' should mention '%s' %s", (int)(e).status, (int)(s), \
              (e).msg, (a), (b) ? (b) : "")

static inline long file_size(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 ? (long)st.st_size : -1;
}

#endif
