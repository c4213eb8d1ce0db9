/* cube_io.c — cube format detection, dispatch to the readers, and value validation.
 * What it is: lm_cube_detect, lm_cube_read, lm_cube_check_values (see cube_io.h).
 * What it is not: any format's parsing (io_cave.c, io_mat.c, io_exr.c). */
#include "data/cube_io.h"
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

lm_status lm_cube_read(const char *path, lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    if (!path || !path[0]) return lm_err_set(e, LM_ERR_ARG, "cube path is empty");
    struct stat st;
    switch (lm_cube_detect(path)) {
    case LM_CUBE_FMT_CAVE: return lm_cube_read_cave(path, cube, e);
    case LM_CUBE_FMT_MAT: return lm_cube_read_mat(path, cube, e);
    case LM_CUBE_FMT_EXR: return lm_cube_read_exr(path, cube, e);
    case LM_CUBE_FMT_UNKNOWN: break;
    }
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file or folder", path);
    return lm_err_set(e, LM_ERR_UNSUPPORTED,
                      "%s: unknown cube format '%s' (expected a CAVE folder, .mat or .exr)",
                      path, extension(path));
}

lm_status lm_cube_check_values(const lm_cube *cube, const char *what, lm_err *e)
{
    size_t plane = (size_t)cube->height * cube->width;
    for (int b = 0; b < cube->bands; b++) {
        const float *p = lm_cube_band(cube, b);
        for (size_t i = 0; i < plane; i++) {
            float v = p[i];
            if (isfinite(v) && v >= 0.0f) continue;
            const char *kind = isnan(v) ? "NaN"
                               : isinf(v) ? "an infinite value" : "a negative value";
            return lm_err_set(e, LM_ERR_NUMERIC,
                              "%s: band %d (%.1f nm) has %s (%g) at (x=%d, y=%d)", what, b + 1,
                              cube->wavelength[b], kind, v, (int)(i % (size_t)cube->width),
                              (int)(i / (size_t)cube->width));
        }
    }
    return LM_OK;
}
