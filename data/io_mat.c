/* io_mat.c — the MATLAB .mat cube reader (matio): ARAD `cube` (v7.3) and KAUST `hsi` (v5).
 * What it is: read the cube variable H x W x B (MATLAB column-major: element (y, x, b) at
 * y + H*(x + W*b); an HDF5 tool shows the same data as B x W x H), convert it to the band-major
 * lm_cube without transposing the image, apply the dataset's scaling (KAUST counts / 4095) and
 * band selection, and validate the values. See cube_io.h for the exact rules. The file's
 * structure is checked first (mat_check.c: a truncated file, a v5 variable whose data do not
 * cover its dimensions), because matio reads those with zeros where data are missing.
 * What it is not: a writer, or a reader of other keys / struct or cell variables. */
#include "data/cube_io.h"
#include "data/mat_check.h"
#include <matio.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define KAUST_SCALE 4095.0

/* matio and HDF5 (serial build) keep global state: every matio call of this file runs under
 * this lock, so readers may be called from several threads. */
static pthread_mutex_t mat_lock = PTHREAD_MUTEX_INITIALIZER;

/* matio reports problems through a log function (default: stderr). Keep the last message so
 * errors can quote it (under mat_lock), and print nothing. */
static char mat_last_msg[256];

static void mat_log_quiet(int level, char *message)
{
    (void)level;
    snprintf(mat_last_msg, sizeof mat_last_msg, "%s", message ? message : "");
    char *nl = strchr(mat_last_msg, '\n');
    if (nl) *nl = 0;
}

static void mat_log_install(void) { Mat_LogInitFunc("lumosaic", mat_log_quiet); }

static void mat_log_setup(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, mat_log_install);
    mat_last_msg[0] = 0;
}

static const char *mat_why(void) { return mat_last_msg[0] ? mat_last_msg : "no detail"; }

/* The n elements of a real numeric variable as float, divided by scale_div. 0 for classes we
 * do not read. */
static int numeric_to_float(const matvar_t *v, size_t n, float scale_div, float *out)
{
#define CONVERT(T)                                                                    \
    for (size_t i = 0; i < n; i++) out[i] = (float)((double)((const T *)v->data)[i] / scale_div); \
    return 1
    switch (v->class_type) {
    case MAT_C_DOUBLE: CONVERT(double);
    case MAT_C_SINGLE: CONVERT(float);
    case MAT_C_INT8: CONVERT(signed char);
    case MAT_C_UINT8: CONVERT(unsigned char);
    case MAT_C_INT16: CONVERT(short);
    case MAT_C_UINT16: CONVERT(unsigned short);
    case MAT_C_INT32: CONVERT(int);
    case MAT_C_UINT32: CONVERT(unsigned int);
    case MAT_C_INT64: CONVERT(long long);
    case MAT_C_UINT64: CONVERT(unsigned long long);
    default: return 0;
    }
#undef CONVERT
}

static int is_real_numeric(const matvar_t *v)
{
    return v->class_type >= MAT_C_DOUBLE && v->class_type <= MAT_C_UINT64 && !v->isComplex;
}

/* A numeric variable fully read and converted to float (n values, column-major). */
static lm_status read_numeric(mat_t *m, const char *path, const char *key, float div,
                              float **out, matvar_t **info, lm_err *e)
{
    *out = NULL;
    *info = Mat_VarRead(m, key);
    matvar_t *v = *info;
    if (!v) return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s' (truncated or "
                              "corrupt file?): %s", path, key, mat_why());
    if (!is_real_numeric(v))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' is not a real numeric array",
                          path, key);
    size_t n = 1;
    for (int d = 0; d < v->rank; d++) n *= v->dims[d];
    if (!v->data || v->data_size != (int)Mat_SizeOfClass(v->class_type) ||
        (size_t)v->data_size * n > v->nbytes)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' has no or short data", path, key);
    *out = malloc((n ? n : 1) * sizeof(float));
    if (!*out) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    numeric_to_float(v, n, div, *out);
    return LM_OK;
}

/* Column-major H x W x B -> band-major cube, bands [0, keep). */
static void to_cube(const float *src, size_t H, size_t W, int keep, lm_cube *cube)
{
    for (int b = 0; b < keep; b++) {
        float *dst = lm_cube_band(cube, b);
        for (size_t x = 0; x < W; x++) {
            const float *col = src + H * (x + W * (size_t)b);
            for (size_t y = 0; y < H; y++) dst[y * W + x] = col[y];
        }
    }
}

/* Optional ARAD `bands`: B wavelengths in nm, strictly increasing. */
static lm_status read_bands(mat_t *m, const char *path, lm_cube *cube, lm_err *e)
{
    matvar_t *probe = Mat_VarReadInfo(m, "bands");
    if (!probe) return LM_OK;
    Mat_VarFree(probe);
    float *wl;
    matvar_t *v;
    lm_status s = read_numeric(m, path, "bands", 1.0f, &wl, &v, e);
    size_t n = 1;
    for (int d = 0; s == LM_OK && d < v->rank; d++) n *= v->dims[d];
    if (s == LM_OK && n != (size_t)cube->bands)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: 'bands' has %zu entries but the cube has %d bands",
                       path, n, cube->bands);
    for (int b = 0; s == LM_OK && b < cube->bands; b++) {
        if (!(wl[b] > 0.0f) || (b > 0 && !(wl[b] > wl[b - 1])))
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: 'bands' must be positive and increasing "
                           "(entry %d is %g)", path, b + 1, wl[b]);
        else
            cube->wavelength[b] = wl[b];
    }
    free(wl);
    Mat_VarFree(v);
    return s;
}

/* Shape rules: ARAD exactly 31 bands; KAUST at least 31 (first 31 kept). */
static lm_status check_shape(const matvar_t *v, const char *path, int arad, lm_err *e)
{
    const char *key = arad ? "cube" : "hsi";
    if (v->rank != 3)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has %d dimensions, expected H x W x bands",
                          path, key, v->rank);
    size_t B = v->dims[2];
    if ((arad && B != LM_CAVE_BANDS) || (!arad && B < LM_CAVE_BANDS))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' is %zu x %zu x %zu: wrong band count, "
                          "expected %s31 bands", path, key, v->dims[0], v->dims[1], B,
                          arad ? "" : "at least ");
    if (v->dims[0] == 0 || v->dims[1] == 0 || v->dims[0] > 65536 || v->dims[1] > 65536)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has an invalid image size %zu x %zu",
                          path, key, v->dims[0], v->dims[1]);
    return LM_OK;
}

static lm_status read_cube_var(mat_t *m, const char *path, int arad, lm_cube *cube, lm_err *e)
{
    const char *key = arad ? "cube" : "hsi";
    matvar_t *info = Mat_VarReadInfo(m, key);
    if (!info) return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s'", path, key);
    lm_status s = check_shape(info, path, arad, e);
    Mat_VarFree(info);
    if (s != LM_OK) return s;
    float *raw;
    matvar_t *v;
    s = read_numeric(m, path, key, arad ? 1.0f : (float)KAUST_SCALE, &raw, &v, e);
    if (s == LM_OK) s = check_shape(v, path, arad, e); /* the data may disagree with the info */
    if (s == LM_OK) {
        size_t H = v->dims[0], W = v->dims[1];
        s = lm_cube_alloc(cube, LM_CAVE_BANDS, (int)H, (int)W, 400.0f, 10.0f);
        if (s != LM_OK) s = lm_err_set(e, s, "%s: cannot allocate a %d x %zu x %zu cube", path,
                                       LM_CAVE_BANDS, H, W);
        else to_cube(raw, H, W, LM_CAVE_BANDS, cube);
    }
    free(raw);
    if (v) Mat_VarFree(v);
    if (s == LM_OK && arad) s = read_bands(m, path, cube, e);
    return s;
}

/* The error when neither key exists: list what the file holds (nothing readable usually
 * means a truncated or corrupt file). */
static lm_status no_key(mat_t *m, const char *path, lm_err *e)
{
    size_t n = 0;
    char **dir = Mat_GetDir(m, &n); /* owned by m */
    if (!dir || n == 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: no readable variable (truncated or corrupt "
                          "file?): %s", path, mat_why());
    char list[200] = "";
    for (size_t i = 0; i < n && strlen(list) < sizeof list - 40; i++)
        if (dir[i]) snprintf(list + strlen(list), sizeof list - strlen(list), "%s%.32s",
                             i ? ", " : "", dir[i]);
    return lm_err_set(e, LM_ERR_FORMAT, "%s: no variable 'cube' (ARAD) or 'hsi' (KAUST); the "
                      "file holds: %s", path, list);
}

/* Which dataset: `cube` (ARAD) wins over `hsi` (KAUST). 1 ARAD, 0 KAUST, -1 neither. */
static int find_key(mat_t *m)
{
    const char *keys[2] = {"cube", "hsi"};
    for (int k = 0; k < 2; k++) {
        matvar_t *v = Mat_VarReadInfo(m, keys[k]);
        if (v) {
            Mat_VarFree(v);
            return k == 0;
        }
    }
    return -1;
}

lm_status lm_cube_read_mat(const char *path, lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected a .mat file", path);
    static const char *const keys[] = {"cube", "hsi", NULL};
    lm_mat_kind kind;
    long long bytes;
    lm_status s = lm_mat_check(path, keys, &kind, &bytes, e);
    if (s != LM_OK) return s;
    pthread_mutex_lock(&mat_lock);
    mat_log_setup();
    mat_t *m = Mat_Open(path, MAT_ACC_RDONLY);
    if (!m) {
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: not a readable MATLAB .mat file (corrupt or "
                       "truncated?): %s", path, mat_why());
    } else {
        int arad = find_key(m);
        s = arad < 0 ? no_key(m, path, e) : read_cube_var(m, path, arad, cube, e);
        Mat_Close(m);
    }
    pthread_mutex_unlock(&mat_lock);
    if (s == LM_OK) s = lm_cube_check_values(cube, path, e);
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}
