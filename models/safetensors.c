/* safetensors.c — save/load lm_params as safetensors: an 8-byte little-endian header length,
 * a JSON header {"name": {"dtype": "F32", "shape": [...], "data_offsets": [a, b]}, ...,
 * "__metadata__": {...}}, then the raw little-endian data. Writes are atomic. */
#include "models/params.h"
#include <errno.h>
#include <jansson.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static json_t *build_header(const lm_params *p, const char *const *meta, int n_meta)
{
    json_t *h = json_object();
    size_t off = 0;
    for (int i = 0; i < p->n; i++) {
        const lm_param *e = p->items[i];
        json_t *shape = json_array();
        for (int d = 0; d < e->t.ndim; d++) json_array_append_new(shape, json_integer(e->t.shape[d]));
        size_t len = (size_t)lm_tensor_numel(&e->t) * 4;
        json_t *ent = json_pack("{s:s, s:o, s:[I,I]}", "dtype", "F32", "shape", shape,
                                "data_offsets", (json_int_t)off, (json_int_t)(off + len));
        json_object_set_new(h, e->name, ent);
        off += len;
    }
    if (n_meta > 0) {
        json_t *m = json_object();
        for (int i = 0; i < n_meta; i++) json_object_set_new(m, meta[2 * i], json_string(meta[2 * i + 1]));
        json_object_set_new(h, "__metadata__", m);
    }
    return h;
}

lm_status lm_params_save(const lm_params *p, const char *path, const char *const *meta,
                         int n_meta, lm_err *err)
{
    json_t *h = build_header(p, meta, n_meta);
    char *js = json_dumps(h, JSON_COMPACT | JSON_PRESERVE_ORDER);
    json_decref(h);
    if (!js) return lm_err_set(err, LM_ERR_NOMEM, "%s: cannot build header", path);
    size_t jl = strlen(js), padded = (jl + 7) / 8 * 8;
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        free(js);
        return lm_err_set(err, LM_ERR_IO, "%s: cannot write: %s", path, strerror(errno));
    }
    uint64_t n = padded;
    unsigned char len8[8];
    for (int i = 0; i < 8; i++) len8[i] = (unsigned char)(n >> (8 * i));
    int ok = fwrite(len8, 1, 8, f) == 8 && fwrite(js, 1, jl, f) == jl;
    for (size_t i = jl; i < padded && ok; i++) ok = fputc(' ', f) != EOF;
    for (int i = 0; i < p->n && ok; i++) {
        const lm_param *e = p->items[i];
        size_t cnt = (size_t)lm_tensor_numel(&e->t);
        ok = fwrite(e->t.data, sizeof(float), cnt, f) == cnt; /* host is little-endian */
    }
    free(js);
    if (fclose(f) != 0) ok = 0;
    if (!ok || rename(tmp, path) != 0) {
        int e = errno;
        remove(tmp);
        return lm_err_set(err, LM_ERR_IO, "%s: write failed: %s", path, strerror(e));
    }
    return LM_OK;
}

/* Read the header JSON and the data start offset. */
static json_t *read_header(FILE *f, const char *path, long *data_start, long *file_size,
                           lm_err *err)
{
    unsigned char len8[8];
    fseek(f, 0, SEEK_END);
    *file_size = ftell(f);
    fseek(f, 0, SEEK_SET);
    if (fread(len8, 1, 8, f) != 8) {
        lm_err_set(err, LM_ERR_FORMAT, "%s: not a safetensors file (too short)", path);
        return NULL;
    }
    uint64_t n = 0;
    for (int i = 7; i >= 0; i--) n = (n << 8) | len8[i];
    if (n == 0 || n > 100u * 1024 * 1024 || (long)(8 + n) > *file_size) {
        lm_err_set(err, LM_ERR_FORMAT, "%s: not a safetensors file (header length %llu)", path,
                   (unsigned long long)n);
        return NULL;
    }
    char *buf = malloc(n + 1);
    if (!buf || fread(buf, 1, n, f) != n) {
        free(buf);
        lm_err_set(err, LM_ERR_FORMAT, "%s: truncated safetensors header", path);
        return NULL;
    }
    buf[n] = 0;
    json_error_t je;
    json_t *h = json_loads(buf, 0, &je);
    free(buf);
    if (!h || !json_is_object(h)) {
        json_decref(h);
        lm_err_set(err, LM_ERR_FORMAT, "%s: bad safetensors header: %s", path, je.text);
        return NULL;
    }
    *data_start = (long)(8 + n);
    return h;
}

static lm_status load_one(lm_param *e, json_t *ent, FILE *f, long data_start, long file_size,
                          const char *path, lm_err *err)
{
    const char *dtype = json_string_value(json_object_get(ent, "dtype"));
    json_t *shape = json_object_get(ent, "shape"), *offs = json_object_get(ent, "data_offsets");
    if (!dtype || strcmp(dtype, "F32") || !json_is_array(shape) || json_array_size(offs) != 2)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s: expected dtype F32 with shape "
                          "and data_offsets", path, e->name);
    int same = (int)json_array_size(shape) == e->t.ndim;
    for (int d = 0; same && d < e->t.ndim; d++)
        same = json_integer_value(json_array_get(shape, (size_t)d)) == e->t.shape[d];
    if (!same) {
        char sb[64];
        return lm_err_set(err, LM_ERR_SHAPE, "%s: tensor %s has another shape than the model's %s",
                          path, e->name, lm_shape_str(&e->t, sb, sizeof sb));
    }
    long a = (long)json_integer_value(json_array_get(offs, 0));
    long b = (long)json_integer_value(json_array_get(offs, 1));
    size_t cnt = (size_t)lm_tensor_numel(&e->t);
    if (b - a != (long)(cnt * 4) || a < 0 || data_start + b > file_size)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s: data offsets [%ld, %ld) invalid or "
                          "past the end of the file", path, e->name, a, b);
    if (fseek(f, data_start + a, SEEK_SET) != 0 || fread(e->t.data, 4, cnt, f) != cnt)
        return lm_err_set(err, LM_ERR_IO, "%s: tensor %s: read failed", path, e->name);
    return LM_OK;
}

lm_status lm_params_load(lm_params *p, const char *path, int allow_extra, lm_err *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) return lm_err_set(err, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    long data_start = 0, file_size = 0;
    json_t *h = read_header(f, path, &data_start, &file_size, err);
    lm_status st = h ? LM_OK : LM_ERR_FORMAT;
    for (int i = 0; st == LM_OK && i < p->n; i++) {
        json_t *ent = json_object_get(h, p->items[i]->name);
        if (!ent) st = lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s missing", path, p->items[i]->name);
        else st = load_one(p->items[i], ent, f, data_start, file_size, path, err);
    }
    if (st == LM_OK && !allow_extra) {
        const char *key;
        json_t *v;
        json_object_foreach(h, key, v) {
            if (strcmp(key, "__metadata__") && !lm_params_find(p, key)) {
                st = lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s is not part of this model",
                                path, key);
                break;
            }
        }
    }
    json_decref(h);
    fclose(f);
    return st;
}

char *lm_safetensors_meta(const char *path, const char *key, lm_err *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        lm_err_set(err, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
        return NULL;
    }
    long ds, fs;
    json_t *h = read_header(f, path, &ds, &fs, err);
    fclose(f);
    const char *v = h ? json_string_value(json_object_get(json_object_get(h, "__metadata__"), key)) : NULL;
    char *out = v ? strdup(v) : NULL;
    json_decref(h);
    return out;
}
