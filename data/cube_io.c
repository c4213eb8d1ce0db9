/* cube_io.c — cube format detection, dispatch to the readers, wavelength sidecars applied to a
 * cube, resampling onto the program's grid, and value validation.
 * What it is: lm_cube_detect, lm_cube_read(_with), lm_cube_apply_sidecar, lm_cube_check_values
 * (see cube_io.h). What it is not: any format's parsing (io_cave.c, io_mat.c, io_exr.c), or the
 * resampling method (resample.c). */
#include "data/cube_io.h"
#include "data/spectra.h"
#include <math.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

static const char *extension(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    return (dot && (!slash || dot > slash)) ? dot : "";
}

lm_cube_format lm_cube_detect(const char *path)
{
    struct stat st;
    if (!path) return LM_CUBE_FMT_UNKNOWN;
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) return LM_CUBE_FMT_CAVE;
    const char *ext = extension(path);
    if (strcasecmp(ext, ".mat") == 0) return LM_CUBE_FMT_MAT;
    if (strcasecmp(ext, ".exr") == 0) return LM_CUBE_FMT_EXR;
    return LM_CUBE_FMT_UNKNOWN;
}

void lm_cube_read_opts_default(lm_cube_read_opts *o)
{
    memset(o, 0, sizeof *o);
    o->keep = (lm_grid){LM_GRID41_COUNT, LM_GRID41_START, LM_GRID41_STEP};
}

lm_status lm_cube_apply_sidecar(const char *path, lm_cube *cube, lm_err *e)
{
    double wl[LM_RESAMPLE_MAX_BANDS];
    int n = 0;
    lm_status s = lm_wavelengths_sidecar(path, wl, &n, e);
    if (s != LM_OK || n == 0) return s;
    if (n != cube->bands)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: its wavelength sidecar lists %d wavelengths "
                          "but the cube has %d bands", path, n, cube->bands);
    for (int b = 0; b < n; b++) cube->wavelength[b] = (float)wl[b];
    return LM_OK;
}

/* A cube read as it is onto the grid of o (it is replaced, or left as it is). */
static lm_status to_grid(const char *path, const lm_cube_read_opts *o, lm_cube *cube, lm_err *e)
{
    double wl[LM_CUBE_MAX_BANDS];
    for (int b = 0; b < cube->bands; b++) wl[b] = cube->wavelength[b];
    lm_resample r;
    lm_status s = lm_resample_init(&r, wl, cube->bands, 0, o->keep, path, e);
    int as_read = s == LM_OK && r.nout == cube->bands && !r.w;
    lm_cube out = {0};
    if (s == LM_OK && !as_read) s = lm_resample_cube(&r, cube, &out, e);
    lm_resample_free(&r);
    if (s == LM_OK && !as_read) {
        lm_cube_free(cube);
        *cube = out;
    }
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}

lm_status lm_cube_read(const char *path, lm_cube *cube, lm_err *e)
{
    return lm_cube_read_with(path, NULL, cube, e);
}

lm_status lm_cube_read_with(const char *path, const lm_cube_read_opts *o, lm_cube *cube,
                            lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    if (!path || !path[0]) return lm_err_set(e, LM_ERR_ARG, "cube path is empty");
    lm_cube_read_opts def;
    if (!o) lm_cube_read_opts_default(&def), o = &def;
    struct stat st;
    lm_status s;
    switch (lm_cube_detect(path)) {
    case LM_CUBE_FMT_CAVE:
        s = lm_cube_read_cave(path, cube, e);
        return s != LM_OK ? s : to_grid(path, o, cube, e);
    case LM_CUBE_FMT_MAT: return lm_cube_read_mat_with(path, o, 1, cube, e);
    case LM_CUBE_FMT_EXR:
        s = lm_cube_read_exr(path, cube, e);
        return s != LM_OK ? s : to_grid(path, o, cube, e);
    case LM_CUBE_FMT_UNKNOWN: break;
    }
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file or folder", path);
    return lm_err_set(e, LM_ERR_UNSUPPORTED,
                      "%s: unknown cube format '%s' (expected a CAVE folder, .mat or .exr)",
                      path, extension(path));
}

lm_status lm_cube_check_plane(const float *p, int width, int height, int band, float nm,
                              const char *what, lm_err *e)
{
    size_t plane = (size_t)height * width;
    for (size_t i = 0; i < plane; i++) {
        float v = p[i];
        if (isfinite(v) && v >= 0.0f) continue;
        const char *kind = isnan(v) ? "NaN" : isinf(v) ? "an infinite value" : "a negative value";
        return lm_err_set(e, LM_ERR_NUMERIC, "%s: band %d (%.1f nm) has %s (%g) at (x=%d, y=%d)",
                          what, band, nm, kind, v, (int)(i % (size_t)width),
                          (int)(i / (size_t)width));
    }
    return LM_OK;
}

lm_status lm_cube_check_values(const lm_cube *cube, const char *what, lm_err *e)
{
    for (int b = 0; b < cube->bands; b++) {
        lm_status s = lm_cube_check_plane(lm_cube_band(cube, b), cube->width, cube->height,
                                          b + 1, cube->wavelength[b], what, e);
        if (s != LM_OK) return s;
    }
    return LM_OK;
}
