/* wl_sidecar.c — the wavelength sidecar of a cube: `<cube path>.wavelengths.txt` or
 * `<cube path>.wavelengths.json` (format: resample.h).
 * What it is: find the sidecar, read it (at most SIDECAR_MAX_BYTES), parse the numbers, check
 * the list. What it is not: the check that the list matches the cube's band count (the reader
 * does that, knowing the cube), or resampling (resample.c). */
#include "data/resample.h"
#include "data/util.h"
#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define SIDECAR_MAX_BYTES (1 << 20)
#define SIDECAR_PATH_MAX 4096

/* Anything at the path counts (a folder or a FIFO there is an error when it is read). */
static int is_file(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* The whole file, NUL-terminated, into *text (malloc'd). */
static lm_status slurp(const char *path, char **text, lm_err *e)
{
    *text = NULL;
    lm_status fchk = lm_file_check(path, "a wavelength list", e);
    if (fchk) return fchk;
    FILE *f = fopen(path, "rb");
    if (!f) return lm_err_set(e, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    char *buf = malloc(SIDECAR_MAX_BYTES + 1);
    size_t n = buf ? fread(buf, 1, SIDECAR_MAX_BYTES + 1, f) : 0;
    int bad = ferror(f);
    fclose(f);
    if (!buf) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    if (bad || n > SIDECAR_MAX_BYTES) {
        free(buf);
        return lm_err_set(e, bad ? LM_ERR_IO : LM_ERR_FORMAT, bad ? "%s: read error"
                          : "%s: larger than %d bytes: not a wavelength list", path,
                          SIDECAR_MAX_BYTES);
    }
    buf[n] = 0;
    *text = buf;
    return LM_OK;
}

/* Numbers separated by white space or commas; '#' starts a comment to the end of the line. */
static lm_status parse_txt(const char *path, const char *t, double *wl, int *n, lm_err *e)
{
    *n = 0;
    for (const char *s = t; *s;) {
        if (*s == '#') {
            s += strcspn(s, "\n");
            continue;
        }
        if (strchr(" \t\r\n,", *s)) {
            s++;
            continue;
        }
        size_t len = strcspn(s, " \t\r\n,#"); /* one token, in the strict decimal form */
        char tok[64];
        double v;
        snprintf(tok, sizeof tok, "%.*s", (int)(len < 63 ? len : 63), s);
        if (len > 63 || lm_parse_real(tok, &v))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: '%.20s%s' is not a number (expected "
                              "wavelengths in nm)", path, tok, len > 20 ? "..." : "");
        if (*n == LM_RESAMPLE_MAX_BANDS)
            return lm_err_set(e, LM_ERR_FORMAT, "%s: more than %d wavelengths", path,
                              LM_RESAMPLE_MAX_BANDS);
        wl[(*n)++] = v;
        s += len;
    }
    return LM_OK;
}

/* An array of numbers, or an object whose "wavelengths" is one. */
static lm_status parse_json(const char *path, const char *t, double *wl, int *n, lm_err *e)
{
    json_error_t je;
    json_t *root = json_loads(t, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: line %d: %s", path, je.line, je.text);
    json_t *a = json_is_object(root) ? json_object_get(root, "wavelengths") : root;
    lm_status s = LM_OK;
    if (!json_is_array(a) || json_array_size(a) > LM_RESAMPLE_MAX_BANDS)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: expected an array of at most %d wavelengths in "
                       "nm, or {\"wavelengths\": [...]}", path, LM_RESAMPLE_MAX_BANDS);
    *n = 0;
    for (size_t i = 0; s == LM_OK && i < json_array_size(a); i++) {
        json_t *v = json_array_get(a, i);
        if (!json_is_number(v))
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: wavelength %zu is not a number", path, i + 1);
        else
            wl[(*n)++] = json_number_value(v);
    }
    json_decref(root);
    return s;
}

lm_status lm_wavelengths_sidecar(const char *cube_path, double *wl, int *n, lm_err *e)
{
    char txt[SIDECAR_PATH_MAX], js[SIDECAR_PATH_MAX];
    *n = 0;
    size_t len = strlen(cube_path);
    while (len > 1 && cube_path[len - 1] == '/') len--; /* a CAVE folder given as "scene/" */
    int k1 = snprintf(txt, sizeof txt, "%.*s.wavelengths.txt", (int)len, cube_path);
    int k2 = snprintf(js, sizeof js, "%.*s.wavelengths.json", (int)len, cube_path);
    if (k1 < 0 || k2 < 0 || (size_t)k2 >= sizeof js) return LM_OK; /* no such sidecar */
    int has_txt = is_file(txt), has_json = is_file(js);
    if (has_txt && has_json)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: two wavelength sidecars (%s and %s): keep one",
                          cube_path, txt, js);
    if (!has_txt && !has_json) return LM_OK;
    const char *path = has_txt ? txt : js;
    char *text;
    lm_status s = slurp(path, &text, e);
    if (s != LM_OK) return s;
    s = has_txt ? parse_txt(path, text, wl, n, e) : parse_json(path, text, wl, n, e);
    free(text);
    if (s == LM_OK && *n == 0) s = lm_err_set(e, LM_ERR_FORMAT, "%s: no wavelengths", path);
    if (s == LM_OK) s = lm_wavelengths_check(wl, *n, path, e);
    if (s != LM_OK) *n = 0;
    return s;
}
