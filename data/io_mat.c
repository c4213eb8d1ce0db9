/* io_mat.c — the MATLAB .mat cube reader (matio): ARAD `cube` (v7.3), KAUST `hsi` (v5), ICVL
 * `rad`, Harvard `ref` and the other keys of LM_MAT_CUBE_KEYS, or a key the caller names.
 * What it is: read the cube variable H x W x B (MATLAB column-major: element (y, x, b) at
 * y + H*(x + W*b); an HDF5 tool shows the same data as B x W x H) and its wavelengths (a
 * variable of LM_MAT_WL_KEYS, a sidecar, or the key's default), convert it to the band-major
 * lm_cube without transposing the image, apply the dataset's scaling (KAUST counts / 4095),
 * and validate the values; each band is resampled (resample.h) as it arrives, so a 519-band
 * cube is never held whole in the parent. See cube_io.h for the exact rules.
 * How: the file's structure is checked first (mat_check.c: truncation, v5 variables whose data
 * do not cover their dimensions); then matio runs in a child process (isolate.h), because
 * libmatio/libhdf5 read out of bounds or allocate gigabytes on some corrupt files: the child
 * checks the variable's header against data/limits.h before reading it and sends the raw values
 * through a pipe; the parent checks the reply and converts it. A fault, a hang or an
 * allocation over the child's limits is an error naming the file.
 * What it is not: a writer, a reader of struct or cell variables, or the resampling method
 * (resample.c). */
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

static const char *const mat_keys[] = {LM_MAT_CUBE_KEYS, NULL};
static const char *const wl_keys[] = {LM_MAT_WL_KEYS, NULL};
#define KEY_LEN 64

/* ---- the child: matio ------------------------------------------------------------------ */

typedef struct mat_job {
    const char *path;
    const char *key; /* the caller's, or NULL: the first of mat_keys */
    lm_mat_kind kind;
    long long file_bytes;
} mat_job;

/* The reply's fixed part; nbytes of raw values (class_type's C type, column-major) and nbands
 * doubles (the wavelength variable wl_key, if any) follow when status is LM_OK. */
typedef struct mat_reply {
    int32_t status, class_type, rank, nbands;
    uint64_t dims[3], nbytes;
    char key[KEY_LEN], wl_key[KEY_LEN];
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

/* Shape rules: H x W x B with 1 <= B <= LM_RESAMPLE_MAX_BANDS, the image within
 * LM_MAX_IMAGE_SIDE and the variable within LM_MAX_CUBE_VALUES. */
static lm_status check_shape(int rank, const uint64_t *dims, const char *path, const char *key,
                             lm_err *e)
{
    if (rank != 3)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has %d dimensions, expected H x W x bands",
                          path, key, rank);
    uint64_t B = dims[2];
    if (B < 1 || B > LM_RESAMPLE_MAX_BANDS)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' is %llu x %llu x %llu: wrong band count, "
                          "expected 1 to %d bands", path, key, (unsigned long long)dims[0],
                          (unsigned long long)dims[1], (unsigned long long)B,
                          LM_RESAMPLE_MAX_BANDS);
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
static lm_status child_check_info(const mat_job *j, const matvar_t *v, const char *key,
                                  lm_err *e)
{
    if (!is_real_numeric(v))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' is not a real numeric array",
                          j->path, key);
    uint64_t dims[3] = {0, 0, 0};
    for (int d = 0; d < v->rank && d < 3; d++) dims[d] = v->dims[d];
    lm_status s = check_shape(v->rank, dims, j->path, key, e);
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

/* The first of keys the file holds, or NULL. */
static const char *first_key(mat_t *m, const char *const *keys)
{
    for (int k = 0; keys[k]; k++) {
        matvar_t *v = Mat_VarReadInfo(m, keys[k]);
        if (v) {
            Mat_VarFree(v);
            return keys[k];
        }
    }
    return NULL;
}

/* The error when the key is missing: list what the file holds. */
static lm_status no_key(mat_t *m, const mat_job *j, lm_err *e)
{
    size_t n = 0;
    char **dir = Mat_GetDir(m, &n); /* owned by m */
    if (!dir || n == 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: no readable variable (truncated or corrupt "
                          "file?): %s", j->path, mat_why());
    char list[200] = "";
    for (size_t i = 0; i < n && strlen(list) < sizeof list - 40; i++)
        if (dir[i]) snprintf(list + strlen(list), sizeof list - strlen(list), "%s%.32s",
                             i ? ", " : "", dir[i]);
    if (j->key)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: no variable '%.64s'; the file holds: %s",
                          j->path, j->key, list);
    return lm_err_set(e, LM_ERR_FORMAT, "%s: no cube variable (cube, hsi, rad, ref, ...: "
                      "choose one with --mat-key); the file holds: %s", j->path, list);
}

/* The wavelength variable (the first of wl_keys) as doubles, at most LM_RESAMPLE_MAX_BANDS. */
static lm_status child_bands(mat_t *m, const char *path, double *wl, mat_reply *r, lm_err *e)
{
    r->nbands = 0;
    const char *key = first_key(m, wl_keys);
    if (!key) return LM_OK;
    snprintf(r->wl_key, sizeof r->wl_key, "%s", key);
    matvar_t *v = Mat_VarReadInfo(m, key);
    size_t k = v ? var_count(v) : 0;
    int ok = v && is_real_numeric(v) && k <= LM_RESAMPLE_MAX_BANDS;
    if (v) Mat_VarFree(v);
    v = ok ? Mat_VarRead(m, key) : NULL;
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
    if (!ok) return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' is not a real numeric array of "
                               "at most %d wavelengths", path, key, LM_RESAMPLE_MAX_BANDS);
    r->nbands = (int)k;
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
    const char *one[2] = {j->key, NULL};
    const char *key = first_key(*m, j->key ? one : mat_keys);
    if (!key) return no_key(*m, j, e);
    matvar_t *info = Mat_VarReadInfo(*m, key);
    if (!info) return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s'", j->path, key);
    lm_status s = child_check_info(j, info, key, e);
    Mat_VarFree(info);
    if (s != LM_OK) return s;
    if (!(*v = Mat_VarRead(*m, key)))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read variable '%s' (truncated or "
                          "corrupt file?): %s", j->path, key, mat_why());
    if ((s = child_check_info(j, *v, key, e)) != LM_OK) return s; /* may disagree with info */
    size_t bytes = var_count(*v) * Mat_SizeOfClass((*v)->class_type);
    if (!(*v)->data || (*v)->data_size != (int)Mat_SizeOfClass((*v)->class_type) ||
        (size_t)(*v)->nbytes < bytes)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' has no or short data", j->path,
                          key);
    if (j->kind == LM_MAT_V73 && (s = child_check_hdf5(j, key, (double)bytes, e)) != LM_OK)
        return s;
    snprintf(r->key, sizeof r->key, "%s", key);
    r->class_type = (*v)->class_type;
    r->rank = (*v)->rank;
    for (int d = 0; d < 3; d++) r->dims[d] = (*v)->dims[d];
    r->nbytes = bytes;
    return child_bands(*m, j->path, wl, r, e);
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
    double wl[LM_RESAMPLE_MAX_BANDS];
    r.status = child_read(j, &m, &v, &r, wl, &e);
    snprintf(r.msg, sizeof r.msg, "%s", e.msg);
    if (lm_isolate_write(fd, &r, sizeof r) == 0 && r.status == LM_OK &&
        lm_isolate_write(fd, wl, sizeof(double) * (size_t)r.nbands) == 0)
        lm_isolate_write(fd, v->data, (size_t)r.nbytes);
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

/* The parent's side of one read: the options, the reply, the map to the output bands. */
typedef struct mat_recv {
    const char *path;
    const lm_cube_read_opts *o;
    int resample;
    mat_reply r;
    size_t csize;
    lm_resample map;
    double wl[LM_RESAMPLE_MAX_BANDS];
} mat_recv;

/* Source band b's plane (already in the output's row-major layout): checked if it is used,
 * then resampled into the cube. */
static lm_status take_plane(const mat_recv *q, int b, const float *plane, lm_cube *cube,
                            lm_err *e)
{
    if (!lm_resample_uses(&q->map, b)) return LM_OK;
    lm_status s = lm_cube_check_plane(plane, cube->width, cube->height, b + 1, (float)q->wl[b],
                                      q->path, e);
    if (s == LM_OK) lm_resample_band(&q->map, b, plane, cube);
    return s;
}

/* The reply's values, column-major H x W x B, a chunk at a time, into one band's plane at a
 * time, each resampled into the cube. 1 if the reply ended early (or out of memory: *s). */
static int receive_values(lm_isolate *c, const mat_recv *q, lm_cube *cube, lm_err *e,
                          lm_status *s)
{
    const mat_reply *r = &q->r;
    size_t H = r->dims[0], W = r->dims[1], n = H * W * r->dims[2], y = 0, x = 0, b = 0;
    unsigned char *raw = malloc(CHUNK_VALUES * 8);
    float *val = malloc(CHUNK_VALUES * sizeof(float)), *plane = malloc(H * W * sizeof(float));
    float div = strcmp(r->key, "hsi") == 0 ? (float)KAUST_SCALE : 1.0f;
    int early = 0;
    if (!raw || !val || !plane)
        *s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", q->path);
    for (size_t i = 0; *s == LM_OK && i < n; i += CHUNK_VALUES) {
        size_t k = n - i < CHUNK_VALUES ? n - i : CHUNK_VALUES;
        if ((early = lm_isolate_read(c, raw, k * q->csize) != 0)) break;
        to_float(raw, r->class_type, k, div, val);
        for (size_t t = 0; t < k && *s == LM_OK; t++) {
            plane[y * W + x] = val[t];
            if (++y < H) continue;
            y = 0;
            if (++x < W) continue;
            x = 0;
            *s = take_plane(q, (int)b++, plane, cube, e);
        }
    }
    free(raw);
    free(val);
    free(plane);
    return early;
}

/* The cube's wavelengths: the sidecar, else the file's variable, else the key's default
 * (cube_io.h). Into q->wl. */
static lm_status wavelengths(mat_recv *q, int nfile, lm_err *e)
{
    int B = (int)q->r.dims[2], n = 0;
    const char *key = q->r.key;
    lm_status s = lm_wavelengths_sidecar(q->path, q->wl, &n, e);
    if (s != LM_OK) return s;
    if (n > 0 && n != B)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: its wavelength sidecar lists %d wavelengths "
                          "but '%s' has %d bands", q->path, n, key, B);
    if (n > 0) return LM_OK;
    if (nfile > 0 && nfile != B)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has %d entries but '%s' has %d bands",
                          q->path, q->r.wl_key, nfile, key, B);
    if (nfile > 0) return lm_wavelengths_check(q->wl, B, q->path, e);
    int kaust = strcmp(key, "hsi") == 0, harvard = strcmp(key, "ref") == 0 && B == 31;
    if (!kaust && B != LM_CAVE_BANDS)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: '%s' has %d bands and no wavelength list (a "
                          "variable 'bands' in nm, or a sidecar %s.wavelengths.txt); only a "
                          "31-band cube is taken as 400-700 nm", q->path, key, B, q->path);
    for (int b = 0; b < B; b++) q->wl[b] = (harvard ? 420.0 : 400.0) + 10.0 * b;
    return LM_OK;
}
/* The reply's header: what was checked, and names that are strings. */
static lm_status check_reply(mat_recv *q, lm_err *e)
{
    mat_reply *r = &q->r;
    r->key[KEY_LEN - 1] = r->wl_key[KEY_LEN - 1] = 0;
    q->csize = r->class_type >= MAT_C_DOUBLE && r->class_type <= MAT_C_UINT64
                   ? Mat_SizeOfClass(r->class_type)
                   : 0;
    lm_status s = check_shape(r->rank, r->dims, q->path, r->key, e);
    if (s != LM_OK) return s;
    if (q->csize == 0 || !r->key[0] || r->nbands < 0 || r->nbands > LM_RESAMPLE_MAX_BANDS ||
        r->nbytes != r->dims[0] * r->dims[1] * r->dims[2] * q->csize)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: the .mat reader sent an inconsistent reply",
                          q->path);
    return LM_OK;
}

/* The reply: status, then a header that must describe what was checked, the wavelengths,
 * then the values. 1 if the reply ended early (the child's end says why), else the status. */
static int receive(lm_isolate *c, mat_recv *q, lm_cube *cube, lm_err *e, lm_status *s)
{
    mat_reply *r = &q->r;
    if (lm_isolate_read(c, r, sizeof *r) != 0) return 1;
    r->msg[sizeof r->msg - 1] = 0;
    if (r->status != LM_OK) {
        lm_status st = r->status >= LM_ERR_UNSUPPORTED && r->status < 0 ? (lm_status)r->status
                                                                         : LM_ERR_FORMAT;
        *s = lm_err_set(e, st, "%s", r->msg[0] ? r->msg : "unreadable .mat file");
        return 0;
    }
    if ((*s = check_reply(q, e)) != LM_OK) return 0;
    if (lm_isolate_read(c, q->wl, sizeof(double) * (size_t)r->nbands) != 0) return 1;
    if ((*s = wavelengths(q, r->nbands, e)) != LM_OK) return 0;
    *s = lm_resample_init(&q->map, q->wl, (int)r->dims[2], !q->resample, q->o->keep, q->path, e);
    if (*s != LM_OK) return 0;
    *s = lm_cube_alloc(cube, q->map.nout, (int)r->dims[0], (int)r->dims[1], 0.0f, 0.0f);
    if (*s != LM_OK) {
        *s = lm_err_set(e, *s, "%s: cannot allocate a %d x %llu x %llu cube", q->path,
                        q->map.nout, (unsigned long long)r->dims[0],
                        (unsigned long long)r->dims[1]);
        return 0;
    }
    memcpy(cube->wavelength, q->map.wavelength, sizeof(float) * (size_t)q->map.nout);
    return receive_values(c, q, cube, e, s);
}

lm_status lm_cube_read_mat(const char *path, lm_cube *cube, lm_err *e)
{
    return lm_cube_read_mat_with(path, NULL, 0, cube, e);
}

lm_status lm_cube_read_mat_with(const char *path, const lm_cube_read_opts *o, int resample,
                                lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected a .mat file", path);
    lm_cube_read_opts def;
    if (!o) lm_cube_read_opts_default(&def), o = &def;
    const char *key = o->mat_key && o->mat_key[0] ? o->mat_key : NULL;
    if (key && strlen(key) >= KEY_LEN)
        return lm_err_set(e, LM_ERR_ARG, "%s: .mat key '%.64s...' is too long", path, key);
    mat_job j = {path, key, LM_MAT_UNKNOWN, 0};
    const char *one[2] = {key, NULL};
    lm_status s = lm_mat_check(path, key ? one : mat_keys, &j.kind, &j.file_bytes, e);
    if (s != LM_OK) return s;
    double most = (double)j.file_bytes * LM_RATIO_DEFLATE;
    if (most > (double)LM_MAX_CUBE_VALUES * 8) most = (double)LM_MAX_CUBE_VALUES * 8;
    lm_isolate_limits lim = {CHILD_MEM_BASE + (size_t)(2 * most),
                             CHILD_CPU_BASE + (int)(j.file_bytes >> 22)};
    mat_recv *q = calloc(1, sizeof *q);
    if (!q) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    q->path = path, q->o = o, q->resample = resample;
    lm_isolate c;
    if ((s = lm_isolate_start(&c, mat_child, &j, &lim, path, e)) != LM_OK) return free(q), s;
    int early = receive(&c, q, cube, e, &s);
    lm_status end = lm_isolate_finish(&c, path, "reading the .mat file", early ? e : NULL);
    if (early) s = end != LM_OK ? end : lm_err_set(e, LM_ERR_FORMAT, "%s: the .mat reader's "
                                                   "reply ended early", path);
    if (s == LM_OK) s = lm_cube_check_values(cube, path, e);
    lm_resample_free(&q->map);
    free(q);
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}
