/* io_mat.c — the MATLAB .mat cube reader (matio): ARAD `cube` (v7.3), KAUST `hsi` (v5), ICVL
 * `rad`, Harvard `ref` and the other keys of LM_MAT_CUBE_KEYS, or a key the caller names.
 * What it is: read the cube variable H x W x B (MATLAB column-major: element (y, x, b) at
 * y + H*(x + W*b); an HDF5 tool shows the same data as B x W x H) and its wavelengths (a
 * variable of LM_MAT_WL_KEYS, a sidecar, or the key's default), convert it to the band-major
 * lm_cube without transposing the image, apply the dataset's scaling (KAUST counts / 4095),
 * and validate the values; each band is resampled (resample.h) as it arrives, so a 519-band
 * cube is never held whole in the parent. See cube_io.h for the exact rules.
 * How: the file's structure is checked first (mat_check.c: truncation, v5 variables whose data
 * do not cover their dimensions); then matio runs in a child process (isolate.h; the child is
 * io_mat_child.c, in the helper program lumosaic-reader), because
 * libmatio/libhdf5 read out of bounds or allocate gigabytes on some corrupt files: the child
 * checks the variable's header against data/limits.h before reading it and sends the raw values
 * through a pipe; the parent checks the reply and converts it. A fault, a hang or an
 * allocation over the child's limits is an error naming the file.
 * What it is not: a writer, a reader of struct or cell variables, or the resampling method
 * (resample.c). */
#include "data/cube_io.h"
#include "data/io_mat_wire.h"
#include "data/limits.h"
#include "data/mat_check.h"
#include <hdf5.h>
#include <matio.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define KAUST_SCALE 4095.0
#define CHILD_MEM_BASE (256u << 20) /* the child's address space beyond its data */
#define CHILD_CPU_BASE 30           /* seconds, plus one per 4 MB of file */
#define CHUNK_VALUES 65536

static const char *const mat_keys[] = {LM_MAT_CUBE_KEYS, NULL};

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
    lm_status s = lm_mat_check_shape(r->rank, r->dims, q->path, r->key, e);
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
                             CHILD_CPU_BASE + (int)(j.file_bytes >> 22), 0};
    mat_recv *q = calloc(1, sizeof *q);
    if (!q) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    q->path = path, q->o = o, q->resample = resample;
    size_t plen = strlen(path) + 1, n = sizeof(mat_wire) + plen;
    if (n > LM_ISOLATE_MAX_ARG)
        return free(q), lm_err_set(e, LM_ERR_ARG, "%.200s...: the path is too long", path);
    unsigned char *wire = calloc(1, n);
    if (!wire) return free(q), lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    mat_wire w = {(int32_t)j.kind, key != NULL, j.file_bytes, ""};
    if (key) snprintf(w.key, sizeof w.key, "%s", key);
    memcpy(wire, &w, sizeof w);
    memcpy(wire + sizeof w, path, plen);
    lm_isolate c;
    s = lm_isolate_start(&c, &lm_mat_entry, wire, n, &lim, path, e);
    free(wire);
    if (s != LM_OK) return free(q), s;
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
