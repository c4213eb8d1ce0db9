/* fuzz_util.h — what the harnesses of tests/fuzz share: a private temporary folder (removed at
 * exit), the input written to a file there, and the check every harness makes of a failure:
 * the status is set, the message is one non-empty line and names the input.
 * Header-only; every harness is one translation unit defining LLVMFuzzerTestOneInput, linked
 * either with libFuzzer (clang, the fuzz build) or with replay_main.c (CTest). */
#ifndef LM_FUZZ_UTIL_H
#define LM_FUZZ_UTIL_H
#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* nftw, mkdtemp */
#endif
#include <ftw.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "tensor/status.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static char fz_dir_[64];

static int fz_rm_(const char *p, const struct stat *st, int flag, struct FTW *f)
{
    (void)st, (void)flag, (void)f;
    return remove(p);
}

static void fz_cleanup_(void)
{
    if (fz_dir_[0]) nftw(fz_dir_, fz_rm_, 8, FTW_DEPTH | FTW_PHYS);
}

/* The harness's folder, created on first use. */
static inline const char *fz_tmp(void)
{
    if (!fz_dir_[0]) {
        snprintf(fz_dir_, sizeof fz_dir_, "/tmp/lm_fuzz_XXXXXX");
        if (!mkdtemp(fz_dir_)) {
            perror("mkdtemp");
            abort();
        }
        atexit(fz_cleanup_);
    }
    return fz_dir_;
}

/* out (>= 512 bytes) = the folder + "/" + name. */
static inline const char *fz_path(char *out, const char *name)
{
    snprintf(out, 512, "%s/%s", fz_tmp(), name);
    return out;
}

/* Write n bytes to the folder's file `name`; its path in out (>= 512 bytes). */
static inline const char *fz_write(char *out, const char *name, const void *d, size_t n)
{
    FILE *f = fopen(fz_path(out, name), "wb");
    if (!f || (n && fwrite(d, 1, n, f) != n) || fclose(f) != 0) {
        perror(out);
        abort();
    }
    return out;
}

/* A failure must be reported as one non-empty line naming `what` (NULL: any). */
static inline void fz_check(lm_status s, const lm_err *e, const char *what)
{
    if (s == LM_OK) return;
    if (e->status != s || !e->msg[0] || strchr(e->msg, '\n') || (what && !strstr(e->msg, what))) {
        fprintf(stderr, "fuzz: bad error report: status %d (recorded %d), message '%s' should "
                "be one line naming '%s'\n", (int)s, (int)e->status, e->msg, what ? what : "");
        abort();
    }
}

/* The extension a file's first bytes call for: PNG, TIFF or OpenEXR, else fallback. */
static inline const char *fz_image_ext(const uint8_t *d, size_t n, const char *fallback)
{
    if (n >= 4 && !memcmp(d, "\x89PNG", 4)) return ".png";
    if (n >= 4 && (!memcmp(d, "II*", 4) || !memcmp(d, "MM\0*", 4) || !memcmp(d, "II+", 4)))
        return ".tif";
    if (n >= 4 && !memcmp(d, "\x76\x2f\x31\x01", 4)) return ".exr";
    return fallback;
}

#endif
