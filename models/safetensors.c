/* safetensors.c — save/load lm_params as safetensors: an 8-byte little-endian header length,
 * a JSON header {"name": {"dtype": "F32", "shape": [...], "data_offsets": [a, b]}, ...,
 * "__metadata__": {...}}, then the raw little-endian data. Writes are atomic. Tensors are
 * written F32 (or F16 for distribution) and read as F32, F16 or BF16 (widened exactly). */
#include "models/params.h"
#include "tensor/ops/gemm_bf16.h"
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* IEEE half from float, round to nearest even; |v| must be below 65520 (rounds to <= 65504)
 * and finite (the caller checks). Values under 2^-14 become subnormals (or 0). */
static uint16_t f16_from_f32(float v)
{
    uint32_t x;
    memcpy(&x, &v, 4);
    uint16_t sign = (uint16_t)((x >> 16) & 0x8000u);
    uint32_t ax = x & 0x7fffffffu;
    if (ax < 0x38800000u) /* below 2^-14: multiples of 2^-24, exact scaling, rint ties-to-even */
        return (uint16_t)(sign | (uint16_t)lrintf(fabsf(v) * 16777216.0f));
    uint32_t e = (ax >> 23) - 112, m = ax & 0x7fffffu, rest = m & 0x1fffu;
    uint32_t h = (e << 10) | (m >> 13);
    h += rest > 0x1000u || (rest == 0x1000u && (h & 1u)); /* a carry moves into the exponent */
    return (uint16_t)(sign | h);
}

static float f32_from_f16(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, e = (h >> 10) & 0x1fu, m = h & 0x3ffu, x;
    if (e == 0) {
        float v = ldexpf((float)m, -24);
        return sign ? -v : v;
    }
    x = sign | (e == 31 ? 0x7f800000u | (m << 13) : ((e + 112) << 23) | (m << 13));
    float v;
    memcpy(&v, &x, 4);
    return v;
}

static json_t *build_header(const lm_params *p, const char *const *meta, int n_meta,
                            lm_store_dtype dt)
{
    json_t *h = json_object();
    size_t off = 0, es = dt == LM_STORE_F16 ? 2 : 4;
    for (int i = 0; i < p->n; i++) {
        const lm_param *e = p->items[i];
        json_t *shape = json_array();
        for (int d = 0; d < e->t.ndim; d++) json_array_append_new(shape, json_integer(e->t.shape[d]));
        size_t len = (size_t)lm_tensor_numel(&e->t) * es;
        json_t *ent = json_pack("{s:s, s:o, s:[I,I]}", "dtype",
                                dt == LM_STORE_F16 ? "F16" : "F32", "shape", shape,
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

/* F16: every value finite and within fp16's range, else LM_ERR_ARG naming the tensor; the
 * report of what rounding changes. */
static lm_status f16_check(const lm_params *p, const char *path, lm_store_report *rep, lm_err *err)
{
    memset(rep, 0, sizeof *rep);
    for (int i = 0; i < p->n; i++) {
        const lm_param *e = p->items[i];
        const float *d = e->t.data;
        size_t cnt = (size_t)lm_tensor_numel(&e->t);
        double num = 0, den = 0;
        for (size_t j = 0; j < cnt; j++) {
            if (!isfinite(d[j]) || fabsf(d[j]) >= 65520.0f)
                return lm_err_set(err, LM_ERR_ARG, "%s: tensor %s holds %g, %s: store it as "
                                  "F32", path, e->name, d[j], isfinite(d[j]) ? "beyond fp16's "
                                  "largest value (65504)" : "not a finite number");
            float r = f32_from_f16(f16_from_f32(d[j]));
            num += ((double)r - d[j]) * ((double)r - d[j]);
            den += (double)d[j] * d[j];
            if (d[j] != 0.0f && fabsf(d[j]) < 6.103515625e-05f) {
                if (r == 0.0f) rep->zeroed++;
                else rep->subnormal++;
            }
        }
        double rel = den > 0 ? sqrt(num / den) : 0.0;
        if (rel > rep->max_rel) {
            rep->max_rel = rel;
            snprintf(rep->worst, sizeof rep->worst, "%s", e->name);
        }
    }
    return LM_OK;
}

lm_status lm_params_save_as(const lm_params *p, const char *path, const char *const *meta,
                            int n_meta, lm_store_dtype dt, lm_store_report *rep, lm_err *err)
{
    lm_store_report dummy;
    if (!rep) rep = &dummy;
    memset(rep, 0, sizeof *rep);
    if (dt != LM_STORE_F32 && dt != LM_STORE_F16)
        return lm_err_set(err, LM_ERR_ARG, "%s: unknown storage type %d", path, (int)dt);
    if (dt == LM_STORE_F16 && f16_check(p, path, rep, err)) return err->status;
    json_t *h = build_header(p, meta, n_meta, dt);
    char *js = json_dumps(h, JSON_COMPACT | JSON_PRESERVE_ORDER);
    json_decref(h);
    if (!js) return lm_err_set(err, LM_ERR_NOMEM, "%s: cannot build header", path);
    size_t jl = strlen(js), padded = (jl + 7) / 8 * 8;
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        free(js);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", path, strerror(errno));
    }
    uint64_t n = padded;
    unsigned char len8[8];
    for (int i = 0; i < 8; i++) len8[i] = (unsigned char)(n >> (8 * i));
    int ok = fwrite(len8, 1, 8, f) == 8 && fwrite(js, 1, jl, f) == jl;
    for (size_t i = jl; i < padded && ok; i++) ok = fputc(' ', f) != EOF;
    uint16_t half[1024];
    for (int i = 0; i < p->n && ok; i++) { /* the host is little-endian */
        const lm_param *e = p->items[i];
        size_t cnt = (size_t)lm_tensor_numel(&e->t);
        if (dt == LM_STORE_F32) {
            ok = fwrite(e->t.data, sizeof(float), cnt, f) == cnt;
            continue;
        }
        for (size_t j = 0; j < cnt && ok; j += 1024) {
            size_t k = cnt - j < 1024 ? cnt - j : 1024;
            for (size_t q = 0; q < k; q++) half[q] = f16_from_f32(e->t.data[j + q]);
            ok = fwrite(half, 2, k, f) == k;
        }
    }
    free(js);
    if (fclose(f) != 0) ok = 0;
    if (!ok || rename(tmp, path) != 0) {
        int e = errno;
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: write failed: %s", path, strerror(e));
    }
    return LM_OK;
}

lm_status lm_params_save(const lm_params *p, const char *path, const char *const *meta,
                         int n_meta, lm_err *err)
{
    return lm_params_save_as(p, path, meta, n_meta, LM_STORE_F32, NULL, err);
}

/* Read the header JSON and the data start offset. Every size and offset read from the file is
 * range-checked before any arithmetic on it (a hostile header must not overflow). */
static json_t *read_header(FILE *f, const char *path, int64_t *data_start, int64_t *file_size,
                           lm_err *err)
{
    unsigned char len8[8];
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    if (size < 0 || fseek(f, 0, SEEK_SET) != 0) {
        lm_err_set(err, LM_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
        return NULL;
    }
    *file_size = size;
    if (size < 8 || fread(len8, 1, 8, f) != 8) {
        lm_err_set(err, LM_ERR_FORMAT, "%s: not a safetensors file (too short)", path);
        return NULL;
    }
    uint64_t n = 0;
    for (int i = 7; i >= 0; i--) n = (n << 8) | len8[i];
    if (n == 0 || n > 100u * 1024 * 1024 || n > (uint64_t)(size - 8)) {
        lm_err_set(err, LM_ERR_FORMAT, "%s: not a safetensors file (header length %llu, file "
                   "size %ld)", path, (unsigned long long)n, size);
        return NULL;
    }
    char *buf = malloc(n);
    if (!buf || fread(buf, 1, n, f) != n) {
        free(buf);
        lm_err_set(err, buf ? LM_ERR_FORMAT : LM_ERR_NOMEM, "%s: %s", path,
                   buf ? "truncated safetensors header" : "out of memory for the header");
        return NULL;
    }
    json_error_t je;
    json_t *h = json_loadb(buf, n, 0, &je);
    free(buf);
    if (!h || !json_is_object(h)) {
        lm_err_set(err, LM_ERR_FORMAT, "%s: bad safetensors header: %s", path,
                   !h ? je.text : "not a JSON object");
        json_decref(h);
        return NULL;
    }
    *data_start = (int64_t)(8 + n);
    return h;
}

/* A data offset: a JSON integer >= 0. */
static int get_offset(json_t *v, int64_t *out)
{
    if (!json_is_integer(v) || json_integer_value(v) < 0) return 0;
    *out = (int64_t)json_integer_value(v);
    return 1;
}

static lm_status load_one(lm_param *e, json_t *ent, FILE *f, int64_t data_start,
                          int64_t file_size, const char *path, lm_err *err)
{
    const char *dtype = json_string_value(json_object_get(ent, "dtype"));
    json_t *shape = json_object_get(ent, "shape"), *offs = json_object_get(ent, "data_offsets");
    int f16 = dtype && !strcmp(dtype, "F16"), bf16 = dtype && !strcmp(dtype, "BF16");
    size_t es = f16 || bf16 ? 2 : 4;
    if (!dtype || (strcmp(dtype, "F32") && !f16 && !bf16) || !json_is_array(shape) ||
        json_array_size(offs) != 2)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s: expected dtype F32, F16 or BF16 "
                          "with shape and data_offsets", path, e->name);
    int same = (int)json_array_size(shape) == e->t.ndim;
    for (int d = 0; same && d < e->t.ndim; d++)
        same = json_integer_value(json_array_get(shape, (size_t)d)) == e->t.shape[d];
    if (!same) {
        char sb[64];
        return lm_err_set(err, LM_ERR_SHAPE, "%s: tensor %s has another shape than the model's %s",
                          path, e->name, lm_shape_str(&e->t, sb, sizeof sb));
    }
    size_t cnt = (size_t)lm_tensor_numel(&e->t);
    json_t *ja = json_array_get(offs, 0), *jb = json_array_get(offs, 1);
    int64_t a = 0, b = 0, end = 0;
    const char *why = NULL;
    /* checked before any arithmetic: a, b >= 0 and a <= b, so b - a cannot overflow */
    if (!json_is_integer(ja) || !json_is_integer(jb)) why = "are not integers";
    else if (!get_offset(ja, &a) || !get_offset(jb, &b) || b < a ||
             (uint64_t)(b - a) != (uint64_t)cnt * es)
        why = "do not span the tensor's bytes";
    else if (__builtin_add_overflow(data_start, b, &end))
        why = "run past any file";
    else if (end > file_size)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: truncated: tensor %s ends at byte %lld, the "
                          "file has %lld bytes", path, e->name, (long long)end,
                          (long long)file_size);
    if (why) {
        char sa[32] = "?", sb[32] = "?";
        if (json_is_integer(ja))
            snprintf(sa, sizeof sa, "%" JSON_INTEGER_FORMAT, json_integer_value(ja));
        if (json_is_integer(jb))
            snprintf(sb, sizeof sb, "%" JSON_INTEGER_FORMAT, json_integer_value(jb));
        return lm_err_set(err, LM_ERR_FORMAT, "%s: tensor %s: data offsets [%s, %s) %s (the "
                          "tensor has %zu bytes as %s)", path, e->name, sa, sb, why, cnt * es,
                          dtype);
    }
    if (fseek(f, (long)(data_start + a), SEEK_SET) != 0 || fread(e->t.data, es, cnt, f) != cnt)
        return lm_err_set(err, LM_ERR_IO, "%s: tensor %s: read failed", path, e->name);
    if (es == 2) { /* widened in place from the end: value i's 4 bytes cover halves 2i, 2i+1 */
        const uint16_t *h = (const uint16_t *)(void *)e->t.data;
        for (size_t j = cnt; j-- > 0;) {
            uint16_t v = h[j];
            e->t.data[j] = f16 ? f32_from_f16(v) : lm_bf16_to_f32(v);
        }
    }
    return LM_OK;
}

lm_status lm_params_load(lm_params *p, const char *path, int allow_extra, lm_err *err)
{
    lm_status fchk = lm_file_check(path, "a .safetensors file", err);
    if (fchk) return fchk;
    FILE *f = fopen(path, "rb");
    if (!f) return lm_err_set(err, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    int64_t data_start = 0, file_size = 0;
    json_t *h = read_header(f, path, &data_start, &file_size, err);
    lm_status st = h ? LM_OK : err ? err->status : LM_ERR_FORMAT;
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
    if (lm_file_check(path, "a .safetensors file", err)) return NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        lm_err_set(err, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
        return NULL;
    }
    int64_t ds, fs;
    json_t *h = read_header(f, path, &ds, &fs, err);
    fclose(f);
    const char *v = h ? json_string_value(json_object_get(json_object_get(h, "__metadata__"), key)) : NULL;
    char *out = v ? strdup(v) : NULL;
    json_decref(h);
    return out;
}

int lm_safetensors_meta_all(const char *path, char ***kv, lm_err *err)
{
    *kv = NULL;
    if (lm_file_check(path, "a .safetensors file", err)) return -1;
    FILE *f = fopen(path, "rb");
    if (!f) {
        lm_err_set(err, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    int64_t ds, fs;
    json_t *h = read_header(f, path, &ds, &fs, err);
    fclose(f);
    if (!h) return -1;
    json_t *m = json_object_get(h, "__metadata__");
    size_t cap = json_is_object(m) ? json_object_size(m) : 0;
    char **out = calloc(2 * cap + 1, sizeof *out);
    int n = 0;
    const char *key;
    json_t *v;
    if (out && cap) {
        json_object_foreach(m, key, v) {
            if (!json_is_string(v)) continue;
            out[2 * n] = strdup(key);
            out[2 * n + 1] = strdup(json_string_value(v));
            n++;
            if (!out[2 * n - 2] || !out[2 * n - 1]) {
                lm_safetensors_meta_free(out, n);
                out = NULL;
                break;
            }
        }
    }
    json_decref(h);
    if (!out) {
        lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory for the metadata", path);
        return -1;
    }
    *kv = out;
    return n;
}

void lm_safetensors_meta_free(char **kv, int count)
{
    if (!kv) return;
    for (int i = 0; i < 2 * count; i++) free(kv[i]);
    free(kv);
}
