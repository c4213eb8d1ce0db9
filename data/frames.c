/* frames.c — coded frames: one frame in/out through the OpenImageIO shim, and sequences.
 * What it is: see frames.h (format by extension, single channel, [0, 1] for integers, atomic
 * writes; sequences from a folder, a `%0Nd` pattern, or one file). Every frame's header is
 * checked (size, channels, sample type, data/limits.h) before its pixels are allocated, and a
 * sequence checks all its frames' headers when it is opened.
 * What it is not: image decoding (image_oiio.cpp) or any processing of the frames. */
#include "data/frames.h"
#include "data/image.h"
#include "data/limits.h"
#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#define FRAME_PATH_MAX 4096

typedef enum frame_kind { FRAME_NONE = 0, FRAME_INT16, FRAME_EXR } frame_kind;

static frame_kind kind_of(const char *path)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash)) return FRAME_NONE;
    if (!strcasecmp(dot, ".png") || !strcasecmp(dot, ".tif") || !strcasecmp(dot, ".tiff"))
        return FRAME_INT16;
    return strcasecmp(dot, ".exr") == 0 ? FRAME_EXR : FRAME_NONE;
}

static lm_status unknown_ext(const char *path, lm_err *e)
{
    return lm_err_set(e, LM_ERR_UNSUPPORTED, "%s: unknown frame format (expected .png, .tif, "
                      ".tiff or .exr)", path);
}

/* Before the extension: a directory gets a clearer message than "unknown format". */
static lm_status check_file(const char *path, lm_err *e)
{
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected a frame file", path);
    return kind_of(path) == FRAME_NONE ? unknown_ext(path, e) : LM_OK;
}

/* One frame, at most max_pixels (its header checked before any allocation). */
static lm_status read_frame(const char *path, long long max_pixels, lm_frame *f, lm_err *e)
{
    memset(f, 0, sizeof *f);
    lm_status s = check_file(path, e);
    if (s != LM_OK) return s;
    lm_image im;
    lm_image_want want = {1, max_pixels};
    s = lm_image_read(path, &want, &im, e);
    if (s != LM_OK) return s;
    if (im.channels != 1)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: has %d channels, expected a single-channel frame",
                       path, im.channels);
    else if (!im.is_float && im.bits < 8)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: a %d-bit image; a coded frame is 8- or 16-bit "
                       "(or float) sensor data", path, im.bits);
    size_t n = (size_t)im.width * im.height;
    for (size_t i = 0; s == LM_OK && i < n; i++)
        if (!isfinite(im.data[i]))
            s = lm_err_set(e, LM_ERR_NUMERIC, "%s: non-finite value at (x=%d, y=%d)", path,
                           (int)(i % (size_t)im.width), (int)(i / (size_t)im.width));
    if (s != LM_OK) {
        lm_image_free(&im);
        return s;
    }
    f->height = im.height;
    f->width = im.width;
    f->bits = im.bits;
    f->is_float = im.is_float;
    f->data = im.data; /* adopt the buffer */
    im.data = NULL;
    lm_image_free(&im);
    return LM_OK;
}

lm_status lm_frame_read(const char *path, lm_frame *f, lm_err *e)
{
    return read_frame(path, LM_MAX_FRAME_PIXELS, f, e);
}

void lm_frame_free(lm_frame *f)
{
    if (!f) return;
    free(f->data);
    memset(f, 0, sizeof *f);
}

lm_status lm_frame_write(const char *path, int height, int width, const float *data,
                         lm_err *e)
{
    if (!path || height <= 0 || width <= 0 || !data)
        return lm_err_set(e, LM_ERR_ARG, "%s: invalid frame (%d x %d)", path ? path : "(null)",
                          width, height);
    frame_kind k = kind_of(path);
    if (k == FRAME_NONE) return unknown_ext(path, e);
    if (k == FRAME_INT16) return lm_image_write_gray16(path, width, height, data, e);
    size_t n = (size_t)width * height;
    for (size_t i = 0; i < n; i++)
        if (!isfinite(data[i]))
            return lm_err_set(e, LM_ERR_NUMERIC, "%s: non-finite value at (x=%d, y=%d), "
                              "refusing to write", path, (int)(i % (size_t)width),
                              (int)(i / (size_t)width));
    return lm_image_write_exr(path, width, height, 1, NULL, data, NULL, e);
}

/* ---- sequences ----------------------------------------------------------------------- */

typedef struct name_list {
    char **v;
    int n, cap;
} name_list;

static int list_push(name_list *l, const char *s)
{
    if (l->n == l->cap) {
        int cap = l->cap ? 2 * l->cap : 16;
        char **v = realloc(l->v, (size_t)cap * sizeof *v);
        if (!v) return -1;
        l->v = v;
        l->cap = cap;
    }
    if (!(l->v[l->n] = strdup(s))) return -1;
    l->n++;
    return 0;
}

static void list_free(name_list *l)
{
    for (int i = 0; i < l->n; i++) free(l->v[i]);
    free(l->v);
    memset(l, 0, sizeof *l);
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every frame file of a folder, sorted by name. */
static lm_status list_folder(const char *dir, name_list *out, lm_err *e)
{
    DIR *d = opendir(dir);
    if (!d) return lm_err_set(e, LM_ERR_IO, "%s: cannot open folder", dir);
    struct dirent *de;
    lm_status s = LM_OK;
    while (s == LM_OK && (de = readdir(d)) != NULL) {
        char full[FRAME_PATH_MAX];
        if (de->d_name[0] == '.' || kind_of(de->d_name) == FRAME_NONE) continue;
        snprintf(full, sizeof full, "%s/%s", dir, de->d_name);
        struct stat st;
        if (stat(full, &st) == 0 && S_ISDIR(st.st_mode)) continue;
        if (list_push(out, full) != 0) s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", dir);
    }
    closedir(d);
    if (s == LM_OK && out->n == 0)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: no frames (.png, .tif, .tiff, .exr) in folder", dir);
    if (s == LM_OK) qsort(out->v, (size_t)out->n, sizeof *out->v, cmp_str);
    return s;
}

typedef struct frame_pattern {
    char dir[FRAME_PATH_MAX];    /* folder of the files ("." if none) */
    char lead[FRAME_PATH_MAX];   /* what precedes file names in paths: "" or "<dir>/" */
    char prefix[FRAME_PATH_MAX]; /* file-name text before the number */
    char suffix[FRAME_PATH_MAX]; /* file-name text after the number */
    int width;                   /* zero-padding width (0: none) */
} frame_pattern;

/* Split "dir/pre%04dpost" -> dir, pre, 4, post. 1 if spec is such a pattern, 0 if it has no
 * '%', -1 if it is malformed. */
static int parse_pattern(const char *spec, frame_pattern *p)
{
    const char *pct = strchr(spec, '%');
    if (!pct) return 0;
    const char *slash = strrchr(spec, '/');
    if ((slash && slash > pct) || strchr(pct + 1, '%')) return -1;
    const char *q = pct + 1;
    int w = 0;
    if (*q == '0') {
        q++;
        while (*q >= '0' && *q <= '9' && w < 100) w = 10 * w + (*q++ - '0');
        if (w == 0 || w > 18) return -1;
    }
    if (*q != 'd') return -1;
    const char *name = slash ? slash + 1 : spec;
    snprintf(p->lead, sizeof p->lead, "%.*s", (int)(name - spec), spec);
    if (!slash) snprintf(p->dir, sizeof p->dir, ".");
    else if (slash == spec) snprintf(p->dir, sizeof p->dir, "/");
    else snprintf(p->dir, sizeof p->dir, "%.*s", (int)(slash - spec), spec);
    snprintf(p->prefix, sizeof p->prefix, "%.*s", (int)(pct - name), name);
    snprintf(p->suffix, sizeof p->suffix, "%s", q + 1);
    p->width = w;
    return 1;
}

/* 0, or -1 if the name does not fit in n bytes. */
static int pattern_name(const frame_pattern *p, long k, char *buf, size_t n)
{
    int len = snprintf(buf, n, "%s%s%0*ld%s", p->lead, p->prefix, p->width, k, p->suffix);
    return (len < 0 || (size_t)len >= n) ? -1 : 0;
}

/* Number of a file name under the pattern, or -1 if the pattern does not produce it. */
static long pattern_number(const frame_pattern *p, const char *name)
{
    size_t lp = strlen(p->prefix), ls = strlen(p->suffix), ln = strlen(name);
    if (ln <= lp + ls || strncmp(name, p->prefix, lp) || strcmp(name + ln - ls, p->suffix))
        return -1;
    long k = 0;
    for (size_t i = lp; i < ln - ls; i++) {
        if (name[i] < '0' || name[i] > '9' || k > 100000000L) return -1;
        k = 10 * k + (name[i] - '0');
    }
    char again[FRAME_PATH_MAX];
    int len = snprintf(again, sizeof again, "%s%0*ld%s", p->prefix, p->width, k, p->suffix);
    return (len > 0 && (size_t)len < sizeof again && strcmp(again, name) == 0) ? k : -1;
}

static int cmp_long(const void *a, const void *b)
{
    long x = *(const long *)a, y = *(const long *)b;
    return (x > y) - (x < y);
}

static lm_status collect_numbers(const frame_pattern *p, const char *spec, long **nums, int *n,
                                 lm_err *e)
{
    DIR *d = opendir(p->dir);
    if (!d) return lm_err_set(e, LM_ERR_IO, "%s: cannot open folder %s", spec, p->dir);
    int cap = 0;
    struct dirent *de;
    lm_status s = LM_OK;
    while (s == LM_OK && (de = readdir(d)) != NULL) {
        long k = pattern_number(p, de->d_name);
        if (k < 0) continue;
        if (*n == cap) {
            cap = cap ? 2 * cap : 64;
            long *v = realloc(*nums, (size_t)cap * sizeof *v);
            if (!v) s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", spec);
            else *nums = v;
        }
        if (s == LM_OK) (*nums)[(*n)++] = k;
    }
    closedir(d);
    return s;
}

/* The files a pattern produces, in number order; a gap is an error naming the missing file. */
static lm_status list_pattern(const char *spec, const frame_pattern *p, name_list *out,
                              int *first, lm_err *e)
{
    long *nums = NULL;
    int n = 0;
    lm_status s = collect_numbers(p, spec, &nums, &n, e);
    if (s == LM_OK && n == 0) s = lm_err_set(e, LM_ERR_IO, "%s: no file matches this pattern",
                                             spec);
    if (s == LM_OK) qsort(nums, (size_t)n, sizeof *nums, cmp_long);
    char name[3 * FRAME_PATH_MAX + 32];
    for (int i = 0; s == LM_OK && i < n; i++) {
        if (i > 0 && nums[i] != nums[i - 1] + 1) {
            if (pattern_name(p, nums[i - 1] + 1, name, sizeof name) != 0) name[0] = 0;
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: frame %ld missing (%s) in a sequence of "
                           "%ld..%ld", spec, nums[i - 1] + 1, name, nums[0], nums[n - 1]);
            break;
        }
        if (pattern_name(p, nums[i], name, sizeof name) != 0)
            s = lm_err_set(e, LM_ERR_ARG, "%s: path too long", spec);
        else if (list_push(out, name) != 0)
            s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", spec);
    }
    if (s == LM_OK) *first = (int)nums[0];
    free(nums);
    return s;
}

static lm_status list_spec(const char *spec, name_list *l, int *first, lm_err *e)
{
    struct stat st;
    if (stat(spec, &st) == 0 && S_ISDIR(st.st_mode)) return list_folder(spec, l, e);
    frame_pattern *p = malloc(sizeof *p);
    if (!p) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", spec);
    lm_status s;
    int kind = parse_pattern(spec, p);
    if (kind < 0)
        s = lm_err_set(e, LM_ERR_ARG, "%s: bad frame pattern (use one %%d or %%0Nd in the file "
                       "name, e.g. frame_%%04d.png)", spec);
    else if (kind > 0)
        s = list_pattern(spec, p, l, first, e);
    else if ((s = check_file(spec, e)) == LM_OK && list_push(l, spec) != 0)
        s = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", spec);
    free(p);
    return s;
}

/* Every frame's header, before any pixel is read: a frame file, single channel, within the
 * limits, the size of the first frame (whose size fills s). */
static lm_status check_headers(const name_list *l, lm_frame_seq *s, lm_err *e)
{
    lm_image_want want = {1, LM_MAX_FRAME_PIXELS};
    for (int i = 0; i < l->n; i++) {
        lm_image info;
        lm_status st = check_file(l->v[i], e);
        if (st == LM_OK) st = lm_image_info(l->v[i], &want, &info, e);
        if (st != LM_OK) return st;
        if (i == 0) {
            s->height = info.height;
            s->width = info.width;
        } else if (info.height != s->height || info.width != s->width) {
            st = lm_err_set(e, LM_ERR_FORMAT, "%s: frame is %d x %d but the first frame (%s) is "
                            "%d x %d", l->v[i], info.width, info.height, l->v[0], s->width,
                            s->height);
        }
        lm_image_free(&info);
        if (st != LM_OK) return st;
    }
    return LM_OK;
}

lm_status lm_frame_seq_open(const char *spec, lm_frame_seq *s, lm_err *e)
{
    memset(s, 0, sizeof *s);
    if (!spec || !spec[0]) return lm_err_set(e, LM_ERR_ARG, "frame sequence: empty path");
    name_list l = {0};
    int first = 0;
    lm_status st = list_spec(spec, &l, &first, e);
    if (st == LM_OK) st = check_headers(&l, s, e);
    if (st != LM_OK) {
        list_free(&l);
        memset(s, 0, sizeof *s);
        return st;
    }
    s->count = l.n;
    s->paths = l.v; /* adopt the list */
    s->first_index = first;
    return LM_OK;
}

lm_status lm_frame_seq_read(const lm_frame_seq *s, int i, lm_frame *f, lm_err *e)
{
    memset(f, 0, sizeof *f);
    if (!s || i < 0 || i >= s->count)
        return lm_err_set(e, LM_ERR_ARG, "frame sequence: index %d out of range (%d frames)", i,
                          s ? s->count : 0);
    /* no more pixels than the first frame's, even if the file changed since it was opened */
    lm_status st = read_frame(s->paths[i], (long long)s->height * s->width, f, e);
    if (st == LM_OK && (f->height != s->height || f->width != s->width)) {
        st = lm_err_set(e, LM_ERR_FORMAT, "%s: frame is %d x %d but the first frame (%s) is "
                        "%d x %d", s->paths[i], f->width, f->height, s->paths[0], s->width,
                        s->height);
        lm_frame_free(f);
    }
    return st;
}

void lm_frame_seq_free(lm_frame_seq *s)
{
    if (!s) return;
    for (int i = 0; i < s->count; i++) free(s->paths[i]);
    free(s->paths);
    memset(s, 0, sizeof *s);
}
