/* io_cave.c — the CAVE reader: a folder of 31 band images `<scene>_ms_NN.png`, 400-700 nm.
 * What it is: find the bands by their `_ms_NN` suffix (in the folder, or in its single
 * sub-folder that holds bands, as CAVE zips unpack to scene/scene/), read them through the
 * OpenImageIO shim (8-bit / 255, 16-bit / 65535; each header checked before its pixels are
 * allocated: grey, grey + alpha, RGB or RGBA, within data/limits.h), check they agree in size,
 * are greyscale (see cube_io.h for multi-channel bands) and hold finite non-negative values.
 * What it is not: a writer (cubes are written as spectral EXR). */
#include "data/cube_io.h"
#include "data/image.h"
#include "data/limits.h"
#include "data/util.h"
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#define CAVE_PATH_MAX 4096

typedef struct cave_bands {
    char *path[LM_CAVE_BANDS]; /* malloc'd full paths, NULL where missing */
    int nfound;
} cave_bands;

static void cave_bands_free(cave_bands *cb)
{
    for (int i = 0; i < LM_CAVE_BANDS; i++) free(cb->path[i]);
    memset(cb, 0, sizeof *cb);
}

/* Band number of a file name `<anything>_ms_<digits>.<png|tif|tiff>`, or 0 if it is not one. */
static int band_number(const char *name)
{
    const char *dot = strrchr(name, '.');
    if (!dot || (strcasecmp(dot, ".png") && strcasecmp(dot, ".tif") && strcasecmp(dot, ".tiff")))
        return 0;
    const char *p = dot;
    while (p > name && p[-1] >= '0' && p[-1] <= '9') p--;
    if (p == dot || dot - p > 3 || p - name < 4 || strncasecmp(p - 4, "_ms_", 4) != 0) return 0;
    return atoi(p) > 0 ? atoi(p) : -1;
}

/* Collect the band files of one folder. Band numbers outside 1..31 and duplicates are errors. */
static lm_status scan_bands(const char *dir, cave_bands *cb, lm_err *e)
{
    memset(cb, 0, sizeof *cb);
    DIR *d = opendir(dir);
    if (!d) return lm_err_set(e, LM_ERR_IO, "%s: cannot open folder", dir);
    lm_status s = LM_OK;
    struct dirent *de;
    while (s == LM_OK && (de = readdir(d)) != NULL) {
        if (de->d_name[0] == '.') continue;
        int b = band_number(de->d_name);
        if (b == 0) continue;
        char full[CAVE_PATH_MAX];
        snprintf(full, sizeof full, "%s/%s", dir, de->d_name);
        if (b < 0 || b > LM_CAVE_BANDS)
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: band number out of range: CAVE scenes have "
                           "%d bands (_ms_01 .. _ms_%02d)", full, LM_CAVE_BANDS, LM_CAVE_BANDS);
        else if (cb->path[b - 1])
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: two files for band %02d (also %s)", dir, b,
                           cb->path[b - 1]);
        else if (!(cb->path[b - 1] = strdup(full)))
            s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", dir);
        else
            cb->nfound++;
    }
    closedir(d);
    if (s != LM_OK) cave_bands_free(cb);
    return s;
}

/* No band in dir itself: use the one sub-folder that has bands (scene/scene/ layout). */
static lm_status scan_nested(const char *dir, cave_bands *cb, lm_err *e)
{
    DIR *d = opendir(dir);
    if (!d) return lm_err_set(e, LM_ERR_IO, "%s: cannot open folder", dir);
    lm_status s = LM_OK;
    char chosen[CAVE_PATH_MAX] = "";
    struct dirent *de;
    while (s == LM_OK && (de = readdir(d)) != NULL) {
        char sub[CAVE_PATH_MAX];
        if (de->d_name[0] == '.') continue;
        snprintf(sub, sizeof sub, "%s/%s", dir, de->d_name);
        if (!lm_is_dir(sub)) continue;
        cave_bands t;
        lm_err ignore = {LM_OK, ""};
        lm_status st = scan_bands(sub, &t, &ignore); /* a failing folder is still a candidate:
                                                       * the final scan reports its error */
        int has_bands = st != LM_OK || t.nfound > 0;
        cave_bands_free(&t);
        if (!has_bands) continue;
        if (chosen[0])
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: several sub-folders hold CAVE bands (%s, %s); "
                           "pass one scene folder", dir, chosen, sub);
        snprintf(chosen, sizeof chosen, "%s", sub);
    }
    closedir(d);
    if (s != LM_OK) return s;
    if (!chosen[0])
        return lm_err_set(e, LM_ERR_FORMAT, "%s: no CAVE band images (<scene>_ms_01.png .. "
                          "_ms_%02d.png) in this folder or one level below", dir, LM_CAVE_BANDS);
    return scan_bands(chosen, cb, e);
}

/* Name the first missing band after the scene prefix of a band that exists. */
static lm_status check_complete(const char *dir, const cave_bands *cb, lm_err *e)
{
    const char *any = NULL;
    for (int i = 0; i < LM_CAVE_BANDS && !any; i++) any = cb->path[i];
    for (int i = 0; i < LM_CAVE_BANDS; i++) {
        if (cb->path[i]) continue;
        const char *base = strrchr(any, '/') ? strrchr(any, '/') + 1 : any;
        int prefix = (int)(strlen(base) - strlen(strrchr(base, '_')));
        return lm_err_set(e, LM_ERR_FORMAT, "%s: band %02d missing (%.*s_%02d%s); found %d of "
                          "%d bands", dir, i + 1, prefix, base, i + 1, strrchr(base, '.'),
                          cb->nfound, LM_CAVE_BANDS);
    }
    return LM_OK;
}

/* Copy channel 0 of a band into dst after checking that its colour channels agree. */
static lm_status take_grey(const char *path, const lm_image *im, float *dst, lm_err *e)
{
    int C = im->channels, colour = C >= 3 ? 3 : 1;
    size_t n = (size_t)im->width * im->height;
    for (size_t i = 0; i < n; i++) {
        const float *px = im->data + i * (size_t)C;
        for (int c = 1; c < colour; c++)
            if (px[c] != px[0])
                return lm_err_set(e, LM_ERR_FORMAT, "%s: not a greyscale band (%d channels that "
                                  "differ at x=%d, y=%d)", path, C, (int)(i % (size_t)im->width),
                                  (int)(i / (size_t)im->width));
        dst[i] = px[0];
    }
    return LM_OK;
}

/* Band 01 may be as large as a cube allows; the others no larger than band 01 (each header is
 * checked before its pixels are allocated). */
static lm_status read_bands(const cave_bands *cb, lm_cube *cube, lm_err *e)
{
    for (int b = 0; b < LM_CAVE_BANDS; b++) {
        lm_image im;
        lm_image_want want = {4, b == 0 ? LM_MAX_CUBE_VALUES / LM_CAVE_BANDS
                                        : (long long)cube->height * cube->width};
        lm_status s = lm_image_read(cb->path[b], &want, &im, e);
        if (s != LM_OK) return s;
        if (b == 0) {
            s = lm_cube_alloc(cube, LM_CAVE_BANDS, im.height, im.width, 400.0f, 10.0f);
            if (s != LM_OK) s = lm_err_set(e, s, "%s: cannot allocate a %d x %d x %d cube",
                                           cb->path[b], LM_CAVE_BANDS, im.height, im.width);
        } else if (im.width != cube->width || im.height != cube->height) {
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: band is %d x %d but band 01 is %d x %d",
                           cb->path[b], im.width, im.height, cube->width, cube->height);
        }
        if (s == LM_OK) s = take_grey(cb->path[b], &im, lm_cube_band(cube, b), e);
        lm_image_free(&im);
        if (s != LM_OK) return s;
    }
    return LM_OK;
}

lm_status lm_cube_read_cave(const char *dir, lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    if (!lm_is_dir(dir)) {
        struct stat st;
        return lm_err_set(e, LM_ERR_IO, stat(dir, &st) == 0
                          ? "%s: is a file, expected a CAVE scene folder" : "%s: no such folder",
                          dir);
    }
    cave_bands cb;
    lm_status s = scan_bands(dir, &cb, e);
    if (s == LM_OK && cb.nfound == 0) s = scan_nested(dir, &cb, e);
    if (s == LM_OK) s = check_complete(dir, &cb, e);
    if (s == LM_OK) s = read_bands(&cb, cube, e);
    if (s == LM_OK) s = lm_cube_apply_sidecar(dir, cube, e);
    if (s == LM_OK) s = lm_cube_check_values(cube, dir, e);
    cave_bands_free(&cb);
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}
