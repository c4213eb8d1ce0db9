/* io_mat.c — the MATLAB .mat cube reader (matio): ARAD `cube` (v7.3) and KAUST `hsi` (v5).
 * What it is: read the cube variable H x W x B (MATLAB column-major: element (y, x, b) at
 * y + H*(x + W*b); an HDF5 tool shows the same data as B x W x H), convert it to the band-major
 * lm_cube without transposing the image, apply the dataset's scaling (KAUST counts / 4095) and
 * band selection, and validate the values. See cube_io.h for the exact rules.
 * How: the file's structure is checked first (mat_check.c: truncation, v5 variables whose data
 * do not cover their dimensions); then matio runs in a child process (isolate.h), because
 * libmatio/libhdf5 read out of bounds or allocate gigabytes on some corrupt files: the child
 * checks the variable's header against data/limits.h before reading it and sends the raw values
 * through a pipe; the parent checks the reply and converts it. A fault, a hang or an
 * allocation over the child's limits is an error naming the file.
 * What it is not: a writer, or a reader of other keys / struct or cell variables. */
#include "data/cube_io.h"
#include "data/isolate.h"
#include "data/limits.h"
#include "data/mat_check.h"
#include <hdf5.h>
#include <matio.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define KAUST_SCALE 4095.0
#define CHILD_MEM_BASE (256u << 20) /* the child's address space beyond its data */
#define CHILD_CPU_BASE 30           /* seconds, plus one per 4 MB of file */
#define CHUNK_VALUES 65536

static const char *const mat_keys[] = {"cube", "hsi", NULL};

/* ---- the child: matio ------------------------------------------------------------------ */

typedef struct mat_job {
    const char *path;
    lm_mat_kind kind;
    long long file_bytes;
} mat_job;

/* The reply's fixed part; nbytes of raw values (class_type's C type, column-major) and nbands
 * doubles (ARAD `bands`) follow when status is LM_OK. */
typedef struct mat_reply {
    int32_t status, arad, class_type, rank, nbands;
    uint64_t dims[3], nbytes;
    char msg[480];
} mat_reply;

/* matio reports problems through a log function: keep the last message (the child has one
 * thread) so errors can quote it, and print nothing. */
static char mat_last_msg[256];

static void mat_log_quiet(int level, char *message)
{
    (void)level;
    snprintf(mat_last_msg, sizeof mat_last_msg, "%s", message ? message : "");
    char *nl = strchr(mat_last_msg, '\n');
    if (nl) *nl = 0;
}

static const char *mat_why(void) { return mat_last_msg[0] ? mat_last_msg : "no detail"; }

static int is_real_numeric(const matvar_t *v)
{
    return v->class_type >= MAT_C_DOUBLE && v->class_type <= MAT_C_UINT64 && !v->isComplex;
}

static size_t var_count(const matvar_t *v)
{
    size_t n = 1;
    for (int d = 0; d < v->rank; d++) n *= v->dims[d];
    return n;
}

/* Shape rules: ARAD exactly 31 bands; KAUST at least 31 (first 31 kept); the image within
 * LM_MAX_IMAGE_SIDE and the variable within LM_MAX_CUBE_VALUES. */
static lm_status check_shape(int rank, const uint64_t *dims, const char *path, int arad,
                             lm_err *e)
{
    const char *key = arad ? "cube" : "hsi";
    if (rank != 3)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has %d dimensions, expected H x W x bands",
                          path, key, rank);
    uint64_t B = dims[2];
    if ((arad && B != LM_CAVE_BANDS) || (!arad && B < LM_CAVE_BANDS))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' is %llu x %llu x %llu: wrong band count, "
                          "expected %s31 bands", path, key, (unsigned long long)dims[0],
                          (unsigned long long)dims[1], (unsigned long long)B,
                          arad ? "" : "at least ");
    if (dims[0] == 0 || dims[1] == 0 || dims[0] > LM_MAX_IMAGE_SIDE ||
        dims[1] > LM_MAX_IMAGE_SIDE)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has an invalid image size %llu x %llu",
                          path, key, (unsigned long long)dims[0], (unsigned long long)dims[1]);
    if ((double)dims[0] * (double)dims[1] * (double)B > (double)LM_MAX_CUBE_VALUES)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' is %llu x %llu x %llu, over the limit of "
                          "%lld values", path, key, (unsigned long long)dims[0],
                          (unsigned long long)dims[1], (unsigned long long)B, LM_MAX_CUBE_VALUES);
    return LM_OK;
}

/* The variable's header, before its values are read: numeric, the shape rules, and no more
 * bytes than the file can hold. */
static lm_status child_check_info(const mat_job *j, const matvar_t *v, int arad, lm_err *e)
{
    const char *key = arad ? "cube" : "hsi";
    if (!is_real_numeric(v))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' is not a real numeric array",
                          j->path, key);
    uint64_t dims[3] = {0, 0, 0};
    for (int d = 0; d < v->rank && d < 3; d++) dims[d] = v->dims[d];
    lm_status s = check_shape(v->rank, dims, j->path, arad, e);
    if (s != LM_OK) return s;
    int plain = j->kind == LM_MAT_V5 && v->compression == MAT_COMPRESSION_NONE;
    char what[96];
    snprintf(what, sizeof what, "variable '%s' (%llu x %llu x %llu)", key,
             (unsigned long long)dims[0], (unsigned long long)dims[1],
             (unsigned long long)dims[2]);
    return lm_limit_decoded(j->path, what,
                            (double)var_count(v) * (double)Mat_SizeOfClass(v->class_type),
                            j->file_bytes, plain ? "none" : "deflate",
                            plain ? LM_RATIO_NONE : LM_RATIO_DEFLATE, e);
}

/* v7.3: the dataset's storage must be allocated and hold what its size needs (HDF5 reads
 * unallocated chunks as fill values, silently). */
static lm_status child_check_hdf5(const mat_job *j, const char *key, double need, lm_err *e)
{
    hid_t f = H5Fopen(j->path, H5F_ACC_RDONLY, H5P_DEFAULT);
    hid_t d = f >= 0 ? H5Dopen2(f, key, H5P_DEFAULT) : -1;
    hid_t p = d >= 0 ? H5Dget_create_plist(d) : -1;
    H5D_space_status_t st = H5D_SPACE_STATUS_ERROR;
    int ok = d >= 0 && p >= 0 && H5Dget_space_status(d, &st) >= 0;
    double stored = ok ? (double)H5Dget_storage_size(d) : 0.0;
    int contiguous = ok && H5Pget_layout(p) == H5D_CONTIGUOUS;
    if (p >= 0) H5Pclose(p);
    if (d >= 0) H5Dclose(d);
    if (f >= 0) H5Fclose(f);
    if (!ok) return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot open dataset '%s'", j->path, key);
    if (st != H5D_SPACE_STATUS_ALLOCATED ||
        stored * (contiguous ? 1.0 : LM_RATIO_DEFLATE) + LM_DECODE_SLACK < need)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' has %.0f bytes stored for %.0f "
                          "bytes of values%s: corrupt or truncated", j->path, key, stored, need,
                          st == H5D_SPACE_STATUS_ALLOCATED ? "" : " (partly unallocated)");
    return LM_OK;
}

/* Which dataset: `cube` (ARAD) wins over `hsi` (KAUST). 1 ARAD, 0 KAUST, -1 neither. */
static int find_key(mat_t *m)
{
    for (int k = 0; k < 2; k++) {
        matvar_t *v = Mat_VarReadInfo(m, mat_keys[k]);
        if (v) {
            Mat_VarFree(v);
            return k == 0;
        }
    }
    return -1;
}

/* The error when neither key exists: list what the file holds. */
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

/* A real numeric variable's values as doubles (ARAD `bands`), at most LM_CUBE_MAX_BANDS. */
static lm_status child_bands(mat_t *m, const char *path, double *wl, int *n, lm_err *e)
{
    *n = 0;
    matvar_t *v = Mat_VarReadInfo(m, "bands");
    if (!v) return LM_OK;
    size_t k = var_count(v);
    int ok = is_real_numeric(v) && k <= LM_CUBE_MAX_BANDS;
    Mat_VarFree(v);
    v = ok ? Mat_VarRead(m, "bands") : NULL;
    ok = v && v->data && var_count(v) == k && (size_t)v->nbytes >= k * Mat_SizeOfClass(v->class_type);
#define TO_DOUBLE(T) for (size_t i = 0; i < k; i++) wl[i] = (double)((const T *)v->data)[i]; break
    if (ok) switch (v->class_type) {
        case MAT_C_DOUBLE: TO_DOUBLE(double);
        case MAT_C_SINGLE: TO_DOUBLE(float);
        case MAT_C_INT8: TO_DOUBLE(signed char);
        case MAT_C_UINT8: TO_DOUBLE(unsigned char);
        case MAT_C_INT16: TO_DOUBLE(short);
        case MAT_C_UINT16: TO_DOUBLE(unsigned short);
        case MAT_C_INT32: TO_DOUBLE(int);
        case MAT_C_UINT32: TO_DOUBLE(unsigned int);
        case MAT_C_INT64: TO_DOUBLE(long long);
        case MAT_C_UINT64: TO_DOUBLE(unsigned long long);
        default: ok = 0;
        }
#undef TO_DOUBLE
    if (v) Mat_VarFree(v);
    if (!ok) return lm_err_set(e, LM_ERR_FORMAT, "%s: 'bands' is not a real numeric array of "
                               "at most %d values", path, LM_CUBE_MAX_BANDS);
    *n = (int)k;
    return LM_OK;
}

/* Open, find the key, check the header, read the values (and `bands`). */
static lm_status child_read(const mat_job *j, mat_t **m, matvar_t **v, mat_reply *r,
                            double *wl, lm_err *e)
{
    if (j->kind == LM_MAT_V73 && H5Fis_hdf5(j->path) <= 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: a v7.3 .mat file that HDF5 does not "
                          "recognise: corrupt", j->path);
    if (!(*m = Mat_Open(j->path, MAT_ACC_RDONLY)))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: not a readable MATLAB .mat file (corrupt or "
                          "truncated?): %s", j->path, mat_why());
    int arad = find_key(*m);
    if (arad < 0) return no_key(*m, j->path, e);
    const char *key = mat_keys[arad ? 0 : 1];
    matvar_t *info = Mat_VarReadInfo(*m, key);
    if (!info) return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s'", j->path, key);
    lm_status s = child_check_info(j, info, arad, e);
    Mat_VarFree(info);
    if (s != LM_OK) return s;
    if (!(*v = Mat_VarRead(*m, key)))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s' (truncated or "
                          "corrupt file?): %s", j->path, key, mat_why());
    if ((s = child_check_info(j, *v, arad, e)) != LM_OK) return s; /* may disagree with info */
    size_t bytes = var_count(*v) * Mat_SizeOfClass((*v)->class_type);
    if (!(*v)->data || (*v)->data_size != (int)Mat_SizeOfClass((*v)->class_type) ||
        (size_t)(*v)->nbytes < bytes)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' has no or short data", j->path,
                          key);
    if (j->kind == LM_MAT_V73 && (s = child_check_hdf5(j, key, (double)bytes, e)) != LM_OK)
        return s;
    r->arad = arad;
    r->class_type = (*v)->class_type;
    r->rank = (*v)->rank;
    for (int d = 0; d < 3; d++) r->dims[d] = (*v)->dims[d];
    r->nbytes = bytes;
    return arad ? child_bands(*m, j->path, wl, &r->nbands, e) : LM_OK;
}

static void mat_child(int fd, void *arg)
{
    const mat_job *j = arg;
    Mat_LogInitFunc("lumosaic", mat_log_quiet);
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    mat_reply r;
    memset(&r, 0, sizeof r);
    lm_err e = {LM_OK, ""};
    mat_t *m = NULL;
    matvar_t *v = NULL;
    double wl[LM_CUBE_MAX_BANDS];
    r.status = child_read(j, &m, &v, &r, wl, &e);
    snprintf(r.msg, sizeof r.msg, "%s", e.msg);
    if (lm_isolate_write(fd, &r, sizeof r) == 0 && r.status == LM_OK &&
        lm_isolate_write(fd, v->data, (size_t)r.nbytes) == 0)
        lm_isolate_write(fd, wl, sizeof(double) * (size_t)r.nbands);
    if (v) Mat_VarFree(v);
    if (m) Mat_Close(m);
}

/* ---- the parent: check the reply, convert ---------------------------------------------- */

/* n values of a matio class as float, divided by div. 0 for classes we do not read. */
static int to_float(const void *src, int class_type, size_t n, float div, float *out)
{
#define CONVERT(T)                                                                    \
    for (size_t i = 0; i < n; i++) out[i] = (float)((double)((const T *)src)[i] / div); \
    return 1
    switch (class_type) {
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

/* The reply's values, column-major H x W x B, into the band-major cube (bands [0, 31)), a
 * chunk at a time. 1 if the reply ended early. */
static int receive_values(lm_isolate *c, const mat_reply *r, size_t csize, lm_cube *cube)
{
    unsigned char *raw = malloc(CHUNK_VALUES * 8);
    float *val = malloc(CHUNK_VALUES * sizeof(float));
    size_t H = r->dims[0], W = r->dims[1], n = H * W * r->dims[2], y = 0, x = 0, b = 0;
    float div = r->arad ? 1.0f : (float)KAUST_SCALE;
    int early = !raw || !val;
    for (size_t i = 0; !early && i < n; i += CHUNK_VALUES) {
        size_t k = n - i < CHUNK_VALUES ? n - i : CHUNK_VALUES;
        if ((early = lm_isolate_read(c, raw, k * csize) != 0)) break;
        to_float(raw, r->class_type, k, div, val);
        for (size_t t = 0; t < k; t++) {
            if (b < LM_CAVE_BANDS) lm_cube_band(cube, (int)b)[y * W + x] = val[t];
            if (++y < H) continue;
            y = 0;
            if (++x == W) x = 0, b++;
        }
    }
    free(raw);
    free(val);
    return early;
}

/* Optional ARAD `bands`: B wavelengths in nm, strictly increasing. */
static lm_status take_bands(const double *wl, int n, const char *path, lm_cube *cube, lm_err *e)
{
    if (n == 0) return LM_OK;
    if (n != cube->bands)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: 'bands' has %d entries but the cube has %d "
                          "bands", path, n, cube->bands);
    for (int b = 0; b < n; b++) {
        float w = (float)wl[b];
        if (!(w > 0.0f) || (b > 0 && !(w > cube->wavelength[b - 1])))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: 'bands' must be positive and increasing "
                              "(entry %d is %g)", path, b + 1, w);
        cube->wavelength[b] = w;
    }
    return LM_OK;
}

/* The reply: status, then a header that must describe what was checked, then the values.
 * 1 if the reply ended early (the child's end says why), else the status. */
static int receive(lm_isolate *c, const char *path, lm_cube *cube, lm_err *e, lm_status *s)
{
    mat_reply r;
    if (lm_isolate_read(c, &r, sizeof r) != 0) return 1;
    r.msg[sizeof r.msg - 1] = 0;
    if (r.status != LM_OK) {
        lm_status st = r.status >= LM_ERR_UNSUPPORTED && r.status < 0 ? (lm_status)r.status
                                                                       : LM_ERR_FORMAT;
        *s = lm_err_set(e, st, "%s", r.msg[0] ? r.msg : "unreadable .mat file");
        return 0;
    }
    size_t csize = r.class_type >= MAT_C_DOUBLE && r.class_type <= MAT_C_UINT64
                       ? Mat_SizeOfClass(r.class_type)
                       : 0;
    if ((*s = check_shape(r.rank, r.dims, path, r.arad == 1, e)) != LM_OK) return 0;
    if (csize == 0 || (r.arad != 0 && r.arad != 1) || r.nbands < 0 ||
        r.nbands > LM_CUBE_MAX_BANDS || r.nbytes != r.dims[0] * r.dims[1] * r.dims[2] * csize) {
        *s = lm_err_set(e, LM_ERR_FORMAT, "%s: the .mat reader sent an inconsistent reply", path);
        return 0;
    }
    *s = lm_cube_alloc(cube, LM_CAVE_BANDS, (int)r.dims[0], (int)r.dims[1], 400.0f, 10.0f);
    if (*s != LM_OK) {
        *s = lm_err_set(e, *s, "%s: cannot allocate a %d x %llu x %llu cube", path,
                        LM_CAVE_BANDS, (unsigned long long)r.dims[0],
                        (unsigned long long)r.dims[1]);
        return 0;
    }
    double wl[LM_CUBE_MAX_BANDS];
    if (receive_values(c, &r, csize, cube) ||
        lm_isolate_read(c, wl, sizeof(double) * (size_t)r.nbands) != 0)
        return 1;
    *s = r.arad ? take_bands(wl, r.nbands, path, cube, e) : LM_OK;
    return 0;
}

lm_status lm_cube_read_mat(const char *path, lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected a .mat file", path);
    mat_job j = {path, LM_MAT_UNKNOWN, 0};
    lm_status s = lm_mat_check(path, mat_keys, &j.kind, &j.file_bytes, e);
    if (s != LM_OK) return s;
    double most = (double)j.file_bytes * LM_RATIO_DEFLATE;
    if (most > (double)LM_MAX_CUBE_VALUES * 8) most = (double)LM_MAX_CUBE_VALUES * 8;
    lm_isolate_limits lim = {CHILD_MEM_BASE + (size_t)(2 * most),
                             CHILD_CPU_BASE + (int)(j.file_bytes >> 22)};
    lm_isolate c;
    if ((s = lm_isolate_start(&c, mat_child, &j, &lim, path, e)) != LM_OK) return s;
    int early = receive(&c, path, cube, e, &s);
    lm_status end = lm_isolate_finish(&c, path, "reading the .mat file", early ? e : NULL);
    if (early) s = end != LM_OK ? end : lm_err_set(e, LM_ERR_FORMAT, "%s: the .mat reader's "
                                                   "reply ended early", path);
    if (s == LM_OK) s = lm_cube_check_values(cube, path, e);
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}
