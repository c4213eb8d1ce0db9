/* mat_check.c — structural checks of .mat files before matio sees them (see mat_check.h).
 * What it is: the MAT header, the HDF5 superblock fields that locate the end of a v7.3 file,
 * and a walk over the tags of a v5 file (MATLAB "MAT-File Format", Level 5: 8-byte tags, small
 * data elements, miMATRIX sub-elements, miCOMPRESSED = one zlib stream of a miMATRIX).
 * What it is not: a reader of values, cells, structs or sparse arrays. */
#include "data/mat_check.h"
#include "data/limits.h"
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#define MAT_HEADER_BYTES 128
#define HDF5_AT 512          /* MATLAB v7.3: a 512-byte user block, then the HDF5 superblock */
#define MAT_MAX_VARS 100000  /* top-level variables walked */
#define MAT_HEAD_BYTES 512   /* the start of a matrix: flags, dimensions, name, data tag */
#define MAT_MAX_DIMS 32
#define ZCHUNK 65536

enum { MI_INT8 = 1, MI_UINT8, MI_INT16, MI_UINT16, MI_INT32, MI_UINT32, MI_SINGLE,
       MI_DOUBLE = 9, MI_INT64 = 12, MI_UINT64, MI_MATRIX, MI_COMPRESSED, MI_UTF8 };
enum { MX_DOUBLE = 6, MX_UINT64 = 15 }; /* the numeric classes are 6..15 */

typedef struct mat_file {
    FILE *f;
    const char *path;
    long long size;
    int be; /* big-endian file */
} mat_file;

typedef struct mat_tag {
    uint32_t type, nbytes;
    int small; /* small data element: the data is in the tag's second word */
} mat_tag;

typedef struct mat_var {
    char name[64];
    int mclass, complex, rank;
    uint64_t dims[MAT_MAX_DIMS];
    size_t data_at; /* offset of the real part's tag in the matrix content */
    mat_tag data;
} mat_var;

static uint32_t get32(const unsigned char *p, int be)
{
    return be ? (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3]
              : (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | p[0];
}

/* An n-byte little-endian HDF5 address or length. */
static uint64_t get_le(const unsigned char *p, int n)
{
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

static int read_at(const mat_file *m, long long at, void *buf, size_t n)
{
    return at >= 0 && at + (long long)n <= m->size && fseeko(m->f, (off_t)at, SEEK_SET) == 0 &&
                   fread(buf, 1, n, m->f) == n
               ? 0
               : -1;
}

static int parse_tag(const unsigned char *p, int be, mat_tag *t)
{
    uint32_t w = get32(p, be);
    t->small = (w >> 16) != 0;
    t->type = t->small ? w & 0xffff : w;
    t->nbytes = t->small ? w >> 16 : get32(p + 4, be);
    return t->small && t->nbytes > 4 ? -1 : 0;
}

/* Bytes an element takes: 8 for a small one, else the tag and the data padded to 8. */
static uint64_t elem_span(const mat_tag *t)
{
    return t->small ? 8 : 8 + ((uint64_t)t->nbytes + 7) / 8 * 8;
}

static int type_size(uint32_t type)
{
    switch (type) {
    case MI_INT8: case MI_UINT8: return 1;
    case MI_INT16: case MI_UINT16: return 2;
    case MI_INT32: case MI_UINT32: case MI_SINGLE: return 4;
    case MI_DOUBLE: case MI_INT64: case MI_UINT64: return 8;
    default: return 0;
    }
}

/* The next sub-element at *o of h (hn bytes): its tag, its data pointer; advances *o. */
static const unsigned char *next_elem(const unsigned char *h, size_t hn, size_t *o, int be,
                                      mat_tag *t)
{
    if (*o + 8 > hn || parse_tag(h + *o, be, t) != 0) return NULL;
    const unsigned char *d = h + *o + (t->small ? 4 : 8);
    if ((t->small ? *o + 8 : *o + 8 + (uint64_t)t->nbytes) > hn) return NULL;
    *o += elem_span(t);
    return d;
}

/* The matrix header at the start of a miMATRIX's content. 0, or -1 if it is not readable. */
static int parse_matrix(const unsigned char *h, size_t hn, int be, mat_var *v)
{
    size_t o = 0;
    mat_tag t;
    const unsigned char *d = next_elem(h, hn, &o, be, &t);
    if (!d || t.type != MI_UINT32 || t.nbytes != 8) return -1;
    uint32_t flags = get32(d, be);
    v->mclass = (int)(flags & 0xff);
    v->complex = (flags >> 11) & 1;
    d = next_elem(h, hn, &o, be, &t);
    if (!d || t.type != MI_INT32 || t.nbytes % 4 || t.nbytes < 8 || t.nbytes > 4 * MAT_MAX_DIMS)
        return -1;
    v->rank = (int)(t.nbytes / 4);
    for (int i = 0; i < v->rank; i++) {
        int32_t x = (int32_t)get32(d + 4 * i, be);
        if (x < 0) return -1;
        v->dims[i] = (uint64_t)x;
    }
    d = next_elem(h, hn, &o, be, &t);
    if (!d || (t.type != MI_INT8 && t.type != MI_UTF8)) return -1;
    snprintf(v->name, sizeof v->name, "%.*s", t.nbytes < 63 ? (int)t.nbytes : 63,
             (const char *)d);
    if (t.nbytes >= 64 || strlen(v->name) != t.nbytes) v->name[0] = 0; /* not one of ours */
    v->data_at = o;
    return o + 8 <= hn && parse_tag(h + o, be, &v->data) == 0 ? 0 : -1;
}

/* The first bytes of an uncompressed or compressed variable's matrix content into head (up to
 * MAT_HEAD_BYTES), *content its declared size. For a compressed one with count set, *got is
 * how much of the content the stream really holds (inflated, at most *content + 8). */
typedef struct var_read {
    unsigned char head[MAT_HEAD_BYTES];
    size_t hn;
    uint64_t content, got;
    int zerr; /* zlib error (not Z_OK / Z_STREAM_END / Z_BUF_ERROR), 0 if none */
} var_read;

static int inflate_var(const mat_file *m, long long at, uint32_t nbytes, int count, var_read *r)
{
    unsigned char tag[8], *in = malloc(2 * ZCHUNK), *out = in + ZCHUNK;
    z_stream z;
    memset(&z, 0, sizeof z);
    if (!in || inflateInit(&z) != Z_OK) {
        free(in);
        return -1;
    }
    uint64_t total = 0, want = 8 + MAT_HEAD_BYTES;
    long long left = nbytes, pos = at;
    int zr = Z_OK;
    while (zr != Z_STREAM_END && total < want) {
        if (z.avail_in == 0 && left > 0) {
            size_t k = left < ZCHUNK ? (size_t)left : ZCHUNK;
            if (read_at(m, pos, in, k) != 0) break;
            z.next_in = in, z.avail_in = (uInt)k, pos += (long long)k, left -= (long long)k;
        }
        z.next_out = out, z.avail_out = ZCHUNK;
        zr = inflate(&z, Z_NO_FLUSH);
        size_t made = ZCHUNK - z.avail_out;
        for (size_t i = 0; i < made; i++) {
            uint64_t p = total + i;
            if (p < 8) tag[p] = out[i];
            else if (p - 8 < MAT_HEAD_BYTES) r->head[p - 8] = out[i];
            else break;
        }
        if (total < 8 && total + made >= 8) {
            mat_tag t;
            if (parse_tag(tag, m->be, &t) != 0 || t.small || t.type != MI_MATRIX) break;
            r->content = t.nbytes;
            if (count) want = 8 + (uint64_t)t.nbytes + 8;
        }
        total += made;
        if (zr != Z_OK && zr != Z_STREAM_END && zr != Z_BUF_ERROR) {
            r->zerr = zr;
            break;
        }
        if (zr == Z_BUF_ERROR && z.avail_in == 0 && left == 0) break; /* input ended */
    }
    inflateEnd(&z);
    free(in);
    if (total < 8) return -1;
    r->hn = total - 8 < MAT_HEAD_BYTES ? (size_t)(total - 8) : MAT_HEAD_BYTES;
    r->got = total - 8;
    return 0;
}

static lm_status var_error(const mat_file *m, const char *name, const char *what, lm_err *e)
{
    return lm_err_set(e, LM_ERR_FORMAT, "%s: variable '%s' %s: corrupt or truncated file",
                      m->path, name, what);
}

/* A numeric variable's real part must cover its dimensions, inside the variable. */
static lm_status check_data(const mat_file *m, const mat_var *v, uint64_t content,
                            uint64_t got, lm_err *e)
{
    if (v->mclass < MX_DOUBLE || v->mclass > MX_UINT64 || v->complex) return LM_OK;
    uint64_t n = 1;
    for (int i = 0; i < v->rank; i++) {
        if (v->dims[i] && n > (1ULL << 50) / v->dims[i])
            return var_error(m, v->name, "has impossible dimensions", e);
        n *= v->dims[i];
    }
    int sz = type_size(v->data.type);
    if (!sz) return var_error(m, v->name, "stores its values in an unknown type", e);
    char what[160];
    if ((uint64_t)v->data.nbytes < n * (uint64_t)sz) {
        snprintf(what, sizeof what, "holds %u bytes of data for %llu values of %d bytes",
                 v->data.nbytes, (unsigned long long)n, sz);
        return var_error(m, v->name, what, e);
    }
    uint64_t end = v->data_at + (v->data.small ? 8 : 8 + (uint64_t)v->data.nbytes);
    if (end > content) return var_error(m, v->name, "has data beyond its end", e);
    if (end > got) {
        snprintf(what, sizeof what, "has %llu of its %llu bytes", (unsigned long long)got,
                 (unsigned long long)end);
        return var_error(m, v->name, what, e);
    }
    return LM_OK;
}

/* One top-level variable at `at` (tag t, within the file): if it is the first one named by a
 * key, check it is whole. */
static lm_status check_var(const mat_file *m, long long at, const mat_tag *t,
                           const char *const *keys, int *seen, lm_err *e)
{
    var_read r;
    memset(&r, 0, sizeof r);
    int zip = t->type == MI_COMPRESSED;
    if (zip) {
        if (inflate_var(m, at + 8, t->nbytes, 0, &r) != 0) return LM_OK; /* not ours to judge */
    } else {
        r.content = r.got = t->nbytes;
        r.hn = t->nbytes < MAT_HEAD_BYTES ? t->nbytes : MAT_HEAD_BYTES;
        if (read_at(m, at + 8, r.head, r.hn) != 0) return LM_OK;
    }
    mat_var v;
    memset(&v, 0, sizeof v);
    if (parse_matrix(r.head, r.hn, m->be, &v) != 0) return LM_OK;
    int k = 0;
    while (k < LM_MAT_CHECK_MAX_KEYS && keys[k] && strcmp(keys[k], v.name) != 0) k++;
    if (k == LM_MAT_CHECK_MAX_KEYS || !keys[k] || seen[k]) return LM_OK;
    seen[k] = 1;
    if (zip) {
        uint64_t declared = r.content;
        if (declared > (uint64_t)LM_MAX_CUBE_VALUES * 8 + LM_DECODE_SLACK)
            return var_error(m, v.name, "declares more data than any cube holds", e);
        memset(&r, 0, sizeof r);
        if (inflate_var(m, at + 8, t->nbytes, 1, &r) != 0 || r.zerr)
            return var_error(m, v.name, "has a corrupt compressed stream", e);
    }
    return check_data(m, &v, r.content, r.got, e);
}

static lm_status check_v5(const mat_file *m, const char *const *keys, lm_err *e)
{
    int seen[LM_MAT_CHECK_MAX_KEYS] = {0};
    long long at = MAT_HEADER_BYTES;
    for (int n = 0; n < MAT_MAX_VARS && at + 8 <= m->size; n++) {
        unsigned char b[8];
        mat_tag t;
        if (read_at(m, at, b, 8) != 0 || parse_tag(b, m->be, &t) != 0 || t.small ||
            (t.type != MI_MATRIX && t.type != MI_COMPRESSED))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: corrupt file: no variable at byte %lld",
                              m->path, at);
        if (at + 8 + (long long)t.nbytes > m->size)
            return lm_err_set(e, LM_ERR_FORMAT, "%s: truncated: the variable at byte %lld "
                              "declares %u bytes, the file ends %lld bytes after it", m->path,
                              at, t.nbytes, m->size - at - 8);
        lm_status s = check_var(m, at, &t, keys, seen, e);
        if (s != LM_OK) return s;
        at += 8 + (long long)t.nbytes;
    }
    if (at < m->size && m->size - at < 8)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: truncated: %lld stray bytes at the end",
                          m->path, m->size - at);
    return LM_OK;
}

/* The superblock's end-of-file address must lie within the file (HDF5 stores it absolute). */
static lm_status check_v73(const mat_file *m, lm_err *e)
{
    unsigned char sb[96] = {0};
    if (m->size < HDF5_AT + 48 ||
        read_at(m, HDF5_AT, sb, m->size - HDF5_AT < 96 ? (size_t)(m->size - HDF5_AT) : 96) != 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: truncated: a v7.3 file of %lld bytes has no "
                          "HDF5 superblock", m->path, m->size);
    if (memcmp(sb, "\x89HDF\r\n\x1a\n", 8) != 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: corrupt file: a v7.3 header without an HDF5 "
                          "signature at byte 512", m->path);
    int ver = sb[8], so = ver <= 1 ? sb[13] : sb[9], sl = ver <= 1 ? sb[14] : sb[10];
    size_t at = ver <= 1 ? (ver == 1 ? 28 : 24) : 12;
    if (ver > 3 || (so != 2 && so != 4 && so != 8) || (sl != 2 && sl != 4 && sl != 8) ||
        at + 3 * (size_t)so > sizeof sb)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: corrupt HDF5 superblock (version %d, %d-byte "
                          "addresses, %d-byte lengths)", m->path, ver, so, sl);
    uint64_t eof = get_le(sb + at + 2 * (size_t)so, so);
    if (eof > (uint64_t)m->size)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: truncated: the HDF5 superblock says the file "
                          "is %llu bytes, it has %lld", m->path, (unsigned long long)eof,
                          m->size);
    return LM_OK;
}

lm_status lm_mat_check(const char *path, const char *const *keys, lm_mat_kind *kind,
                       long long *file_bytes, lm_err *e)
{
    *kind = LM_MAT_UNKNOWN;
    *file_bytes = 0;
    lm_status fchk = lm_file_check(path, "a .mat file", e);
    if (fchk) return fchk;
    *file_bytes = lm_file_bytes(path);
    mat_file m = {fopen(path, "rb"), path, *file_bytes, 0};
    if (!m.f || m.size < 0) {
        if (m.f) fclose(m.f);
        return lm_err_set(e, LM_ERR_IO, "%s: cannot open", path);
    }
    unsigned char h[MAT_HEADER_BYTES];
    lm_status s = LM_OK;
    if (read_at(&m, 0, h, sizeof h) == 0 &&
        (!memcmp(h + 126, "IM", 2) || !memcmp(h + 126, "MI", 2))) {
        m.be = h[126] == 'M';
        int version = m.be ? h[124] << 8 | h[125] : h[125] << 8 | h[124];
        *kind = version == 0x0100 ? LM_MAT_V5 : version == 0x0200 ? LM_MAT_V73 : LM_MAT_UNKNOWN;
        if (*kind == LM_MAT_V5) s = check_v5(&m, keys, e);
        if (*kind == LM_MAT_V73) s = check_v73(&m, e);
    }
    fclose(m.f);
    return s;
}
