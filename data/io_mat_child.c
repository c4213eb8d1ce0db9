/* io_mat_child.c — the .mat reader's child process (io_mat.c is the parent): open the file
 * with matio, find the cube variable, check its header against data/limits.h before reading it,
 * read it and the wavelength variable, and send them raw through the pipe (io_mat_wire.h).
 * It runs in the helper program lumosaic-reader (cli/reader/main.c), which links this file and
 * little else, or in a fresh image of the calling program (data/isolate.h).
 * What it is not: the conversion, resampling or value checks (the parent's). */
#include "data/cube_io.h"
#include "data/io_mat_wire.h"
#include "data/limits.h"
#include <hdf5.h>
#include <matio.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *const mat_keys[] = {LM_MAT_CUBE_KEYS, NULL};
static const char *const wl_keys[] = {LM_MAT_WL_KEYS, NULL};

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
lm_status lm_mat_check_shape(int rank, const uint64_t *dims, const char *path,
                             const char *key, lm_err *e)
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
    lm_status s = lm_mat_check_shape(v->rank, dims, j->path, key, e);
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

static void mat_child(int fd, const void *arg, size_t n)
{
    mat_wire w;
    if (n <= sizeof w || ((const char *)arg)[n - 1] != 0) _exit(96);
    memcpy(&w, arg, sizeof w);
    w.key[KEY_LEN - 1] = 0;
    const mat_job job = {(const char *)arg + sizeof w, w.has_key ? w.key : NULL,
                         (lm_mat_kind)w.kind, w.file_bytes};
    const mat_job *j = &job;
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

LM_ISOLATE_ENTRY(lm_mat_entry, "mat.1", "lumosaic-reader", mat_child)

/* The helper (cli/reader/main.c) names it, so that its link keeps this file. */
const char *lm_mat_reader_name(void) { return lm_mat_entry.name; }

