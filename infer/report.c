/* report.c — the HTML report of an infer or eval output folder (see report.h).
 * What it is not: the page's drawing, which is the script in infer/report_page.html. */
#include "infer/report.h"
#include <dirent.h>
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <png.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "data/cube_io.h"
#include "data/srgb.h"
#include "data/util.h"

/* The page around the data (generated from infer/report_page.html, cmake/EmbedText.cmake). */
extern const char lm_report_page[];
#define DATA_MARK "<!--LM-DATA-->"

void lm_report_default_opts(lm_report_opts *o)
{
    o->max_side = LM_REPORT_DEFAULT_SIDE;
    o->frame = -1;
}

/* ---- a growing byte buffer ---------------------------------------------------------------- */
typedef struct sbuf {
    char *p;
    size_t n, cap;
    int oom;
} sbuf;

static void sb_add(sbuf *b, const void *d, size_t n)
{
    if (b->oom) return;
    if (b->n + n + 1 > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->n + n + 1) cap *= 2;
        char *p = realloc(b->p, cap);
        if (!p) {
            b->oom = 1;
            return;
        }
        b->p = p, b->cap = cap;
    }
    memcpy(b->p + b->n, d, n);
    b->n += n;
    b->p[b->n] = '\0';
}

static void sb_b64(sbuf *b, const unsigned char *d, size_t n)
{
    static const char t[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char q[4];
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)d[i] << 16 | (i + 1 < n ? (uint32_t)d[i + 1] << 8 : 0) |
                     (i + 2 < n ? d[i + 2] : 0);
        q[0] = t[v >> 18], q[1] = t[(v >> 12) & 63];
        q[2] = i + 1 < n ? t[(v >> 6) & 63] : '=';
        q[3] = i + 2 < n ? t[v & 63] : '=';
        sb_add(b, q, 4);
    }
}

/* ---- PNG in memory (libpng) --------------------------------------------------------------- */
static void png_put(png_structp p, png_bytep d, png_size_t n) { sb_add(png_get_io_ptr(p), d, n); }
static void png_flush_none(png_structp p) { (void)p; }

/* An 8-bit RGB image (H x W x 3) as a "data:image/png;base64,..." URL into out. */
static lm_status png_data_url(const uint8_t *rgb, int w, int h, sbuf *out, lm_err *err)
{
    sbuf png = {0};
    png_structp p = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = p ? png_create_info_struct(p) : NULL;
    if (!info || setjmp(png_jmpbuf(p))) {
        png_destroy_write_struct(&p, info ? &info : NULL);
        free(png.p);
        return lm_err_set(err, LM_ERR_NOMEM, "report: cannot encode a PNG preview");
    }
    png_set_write_fn(p, &png, png_put, png_flush_none);
    png_set_IHDR(p, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(p, info);
    for (int y = 0; y < h; y++) png_write_row(p, (png_const_bytep)(rgb + (size_t)y * w * 3));
    png_write_end(p, NULL);
    png_destroy_write_struct(&p, &info);
    static const char head[] = "data:image/png;base64,";
    sb_add(out, head, sizeof head - 1);
    sb_b64(out, (const unsigned char *)png.p, png.n);
    int oom = png.oom;
    free(png.p);
    return oom || out->oom ? lm_err_set(err, LM_ERR_NOMEM, "report: out of memory") : LM_OK;
}

/* ---- files -------------------------------------------------------------------------------- */
/* data (n bytes) to path through "<path>.tmp.<pid>" and a rename. */
static lm_status write_atomic(const char *path, const void *data, size_t n, lm_err *err)
{
    char tmp[4200];
    if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid()) >= sizeof tmp)
        return lm_err_set(err, LM_ERR_WRITE, "%s: path too long", path);
    FILE *f = fopen(tmp, "wb");
    if (!f) return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", path, strerror(errno));
    int bad = fwrite(data, 1, n, f) != n;
    bad |= fclose(f) != 0;
    if (bad || rename(tmp, path) != 0) {
        int e = errno;
        unlink(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", path, strerror(e));
    }
    return LM_OK;
}

static int exists(const char *dir, const char *name, char *path, size_t n)
{
    struct stat st;
    return (size_t)snprintf(path, n, "%s/%s", dir, name) < n && stat(path, &st) == 0;
}

/* A 31-band cube on the 400-700 nm grid (other grids resampled, as eval reads scenes). */
static lm_status read_cube31(const char *path, lm_cube *c, lm_err *err)
{
    lm_cube_read_opts ro;
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    return lm_cube_read_with(path, &ro, c, err);
}

/* rainbow.csv: "row,true_nm,recovered_nm,error_nm" then one line per row from 0. */
static lm_status read_rainbow(const char *path, json_t *root, int *rows, lm_err *err)
{
    FILE *f = fopen(path, "r");
    if (!f) return lm_err_set(err, LM_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    char line[256];
    json_t *tr = json_array(), *rc = json_array();
    lm_status st = LM_OK;
    int n = 0;
    if (!fgets(line, sizeof line, f) || strncmp(line, "row,true_nm,recovered_nm", 24))
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: not a rainbow table (header "
                        "row,true_nm,recovered_nm,error_nm)", path);
    while (!st && fgets(line, sizeof line, f)) {
        int row;
        double t, r, e;
        if (sscanf(line, "%d,%lf,%lf,%lf", &row, &t, &r, &e) != 4 || row != n || !isfinite(t) ||
            !isfinite(r) || n >= LM_EVAL_RAINBOW_MAX_ROWS)
            st = lm_err_set(err, LM_ERR_FORMAT, "%s: line %d is not 'row,true_nm,"
                            "recovered_nm,error_nm' for row %d", path, n + 2, n);
        else {
            json_array_append_new(tr, json_real(t));
            json_array_append_new(rc, json_real(r));
            n++;
        }
    }
    fclose(f);
    if (!st && n == 0) st = lm_err_set(err, LM_ERR_FORMAT, "%s: no rows", path);
    if (!st) json_object_set_new(root, "rainbow_rows", json_pack("{s:o,s:o}", "true_nm", tr,
                                                                  "recovered_nm", rc));
    else json_decref(tr), json_decref(rc);
    *rows = st ? 0 : n;
    return st;
}

/* A JSON object from a file that must hold one (what: for the message). */
static lm_status read_json(const char *path, json_t **out, lm_err *err)
{
    json_error_t je;
    *out = json_load_file(path, 0, &je);
    if (!*out) {
        if (access(path, R_OK) != 0)
            return lm_err_set(err, LM_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
        return lm_err_set(err, LM_ERR_FORMAT, "%s: line %d: %s", path, je.line, je.text);
    }
    if (!json_is_object(*out)) {
        json_decref(*out);
        *out = NULL;
        return lm_err_set(err, LM_ERR_FORMAT, "%s: not a JSON object", path);
    }
    return LM_OK;
}

/* The fields of eval.json the page reads: noise levels, means, per-scene rows. */
static lm_status check_eval_json(const char *path, json_t *j, lm_err *err)
{
    json_t *noise = json_object_get(j, "noise_percent"), *mean = json_object_get(j, "mean"),
           *scenes = json_object_get(j, "scenes");
    if (!json_is_array(noise) || !json_is_array(mean) || !json_is_array(scenes) ||
        json_array_size(noise) == 0 || json_array_size(mean) != json_array_size(noise))
        return lm_err_set(err, LM_ERR_FORMAT, "%s: not an eval result (needs noise_percent, "
                          "mean and scenes, one mean per level)", path);
    for (size_t i = 0; i < json_array_size(mean); i++)
        if (!json_is_number(json_object_get(json_array_get(mean, i), "psnr")))
            return lm_err_set(err, LM_ERR_FORMAT, "%s: mean row %zu has no psnr", path, i);
    return LM_OK;
}

/* ---- the embedded cube -------------------------------------------------------------------- */
/* Box-average of c onto a w x h grid of f x f blocks (the last ones partial). */
static float *downsample(const lm_cube *c, int f, int w, int h)
{
    float *o = calloc((size_t)31 * w * h, sizeof *o);
    if (!o) return NULL;
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double s = 0.0;
                int n = 0;
                for (int yy = y * f; yy < (y + 1) * f && yy < c->height; yy++)
                    for (int xx = x * f; xx < (x + 1) * f && xx < c->width; xx++, n++)
                        s += lm_cube_band(c, b)[(size_t)yy * c->width + xx];
                o[((size_t)b * h + y) * w + x] = (float)(s / n);
            }
    return o;
}

/* v (n values) as base64 little-endian uint16 of round(clamp(v / scale, 0, 1) * 65535). */
static json_t *quantised(const float *v, size_t n, float scale)
{
    unsigned char *q = malloc(2 * n);
    if (!q) return NULL;
    for (size_t i = 0; i < n; i++) {
        float t = v[i] / scale;
        unsigned u = (unsigned)lrintf((t > 1.0f ? 1.0f : t > 0.0f ? t : 0.0f) * 65535.0f);
        q[2 * i] = (unsigned char)(u & 255), q[2 * i + 1] = (unsigned char)(u >> 8);
    }
    sbuf b = {0};
    sb_b64(&b, q, 2 * n);
    free(q);
    json_t *s = b.oom ? NULL : json_stringn(b.p, b.n);
    free(b.p);
    return s;
}

/* recon (and truth, may be NULL) into root: sizes, previews, the embedded cubes, PSNR per
 * band. The cubes have 31 bands at 400-700 nm and the same size. */
static lm_status add_cubes(json_t *root, const lm_cube *rec, const lm_cube *tru, int max_side,
                           lm_report_info *info, lm_err *err)
{
    int W = rec->width, H = rec->height, side = W > H ? W : H;
    int f = (side + max_side - 1) / max_side, w = (W + f - 1) / f, h = (H + f - 1) / f;
    size_t n = (size_t)31 * w * h;
    uint8_t *rgb = malloc((size_t)3 * W * H);
    float *dr = downsample(rec, f, w, h), *dt = tru ? downsample(tru, f, w, h) : NULL;
    lm_status st = rgb && dr && (!tru || dt) ? LM_OK
                                              : lm_err_set(err, LM_ERR_NOMEM, "report: out of memory");
    float scale = 0.0f;
    for (size_t i = 0; !st && i < n; i++) {
        scale = dr[i] > scale ? dr[i] : scale;
        if (dt) scale = dt[i] > scale ? dt[i] : scale;
    }
    if (!(scale > 0.0f)) scale = 1.0f;
    json_t *wl = json_array(), *cube = NULL;
    for (int b = 0; b < 31; b++) json_array_append_new(wl, json_integer(400 + 10 * b));
    cube = json_pack("{s:i,s:i,s:i,s:f,s:o}", "w", w, "h", h, "block", f, "scale", (double)scale,
                     "wl", wl);
    for (int k = 0; !st && k < (tru ? 2 : 1); k++) {
        const lm_cube *c = k ? tru : rec;
        sbuf url = {0};
        st = lm_srgb_render_cube(c, 1.0f, rgb, NULL, err);
        if (!st) st = png_data_url(rgb, W, H, &url, err);
        json_t *q = st ? NULL : quantised(k ? dt : dr, n, scale);
        if (!st && !q) st = lm_err_set(err, LM_ERR_NOMEM, "report: out of memory");
        if (!st) {
            json_object_set_new(root, k ? "srgb_truth" : "srgb", json_stringn(url.p, url.n));
            json_object_set_new(cube, k ? "truth" : "recon", q);
        }
        free(url.p);
    }
    if (!st && tru) {
        json_t *bp = json_array();
        for (int b = 0; b < 31; b++)
            json_array_append_new(bp, json_real(lm_metric_psnr(rec->data, tru->data, 31, H, W,
                                                               b, 1)));
        json_object_set_new(root, "band_psnr", bp);
    }
    json_object_set_new(root, "width", json_integer(W));
    json_object_set_new(root, "height", json_integer(H));
    json_object_set_new(root, "cube", cube);
    info->width = W, info->height = H, info->side_w = w, info->side_h = h;
    info->has_sample = 1, info->has_truth = tru != NULL;
    free(rgb), free(dr), free(dt);
    return st;
}

/* recon and truth as the same 31-band size (else LM_ERR_FORMAT naming both). */
static lm_status read_pair(const char *rp, const char *tp, lm_cube *rec, lm_cube *tru, lm_err *err)
{
    memset(tru, 0, sizeof *tru);
    lm_status st = read_cube31(rp, rec, err);
    if (!st) st = read_cube31(tp, tru, err);
    if (!st && (rec->width != tru->width || rec->height != tru->height))
        st = lm_err_set(err, LM_ERR_FORMAT, "%s (%d x %d) and %s (%d x %d) differ in size", rp,
                        rec->width, rec->height, tp, tru->width, tru->height);
    return st;
}

/* ---- the two kinds of folder -------------------------------------------------------------- */
static lm_status load_eval(const char *dir, json_t *root, const lm_report_opts *o,
                           lm_report_info *info, lm_err *err)
{
    char p[4200], rp[4200], tp[4200];
    json_t *ev = NULL, *sample = NULL;
    exists(dir, "eval.json", p, sizeof p);
    lm_status st = read_json(p, &ev, err);
    if (!st) st = check_eval_json(p, ev, err);
    if (!st) json_object_set(root, "eval", ev);
    json_decref(ev);
    int has_s = exists(dir, "sample.json", p, sizeof p), has_r = exists(dir, "sample_recon.exr",
                                                                        rp, sizeof rp);
    int has_t = exists(dir, "sample_truth.exr", tp, sizeof tp);
    if (!st && (has_s || has_r || has_t) && !(has_s && has_r && has_t))
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: sample.json, sample_recon.exr and "
                        "sample_truth.exr go together (%s is missing)", dir,
                        !has_s ? "sample.json" : !has_r ? "sample_recon.exr" : "sample_truth.exr");
    if (!st && has_s) {
        st = read_json(p, &sample, err);
        const char *scene = sample ? json_string_value(json_object_get(sample, "scene")) : NULL;
        if (!st && (!scene || !json_is_number(json_object_get(sample, "noise_percent"))))
            st = lm_err_set(err, LM_ERR_FORMAT, "%s: needs scene and noise_percent", p);
        if (!st && scene) snprintf(info->shown, sizeof info->shown, "%s", scene);
        if (!st) json_object_set(root, "sample", sample);
        json_decref(sample);
        lm_cube rec, tru;
        memset(&rec, 0, sizeof rec), memset(&tru, 0, sizeof tru);
        if (!st) st = read_pair(rp, tp, &rec, &tru, err);
        if (!st) st = add_cubes(root, &rec, &tru, o->max_side, info, err);
        lm_cube_free(&rec), lm_cube_free(&tru);
    }
    if (!st && exists(dir, "rainbow.csv", p, sizeof p))
        st = read_rainbow(p, root, &info->rainbow_rows, err);
    info->eval = 1;
    return st;
}

/* The number of a file named cube_NNNN.exr (-1 for any other name). */
static int cube_number(const char *name)
{
    int n, len = 0;
    if (sscanf(name, "cube_%d.exr%n", &n, &len) != 1 || name[len] != '\0' || n < 0) return -1;
    return n;
}

static lm_status load_infer(const char *dir, json_t *root, const lm_report_opts *o,
                            lm_report_info *info, lm_err *err)
{
    DIR *d = opendir(dir);
    if (!d) return lm_err_set(err, LM_ERR_IO, "%s: cannot read: %s", dir, strerror(errno));
    int best = -1, count = 0;
    char name[256] = "";
    struct dirent *de;
    while ((de = readdir(d))) {
        int n = cube_number(de->d_name);
        if (n < 0) continue;
        count++;
        if (o->frame >= 0 ? n == o->frame : best < 0 || n < best) {
            best = n;
            snprintf(name, sizeof name, "%s", de->d_name);
        }
    }
    closedir(d);
    if (!count)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: neither an eval folder (eval.json) nor an "
                          "infer folder (cube_NNNN.exr)", dir);
    if (best < 0)
        return lm_err_set(err, LM_ERR_ARG, "%s: no cube_%04d.exr (--frame %d)", dir, o->frame,
                          o->frame);
    char p[4200];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    lm_cube rec;
    lm_status st = read_cube31(p, &rec, err);
    if (st) return st;
    snprintf(info->shown, sizeof info->shown, "%s", name);
    json_object_set_new(root, "frame", json_pack("{s:s,s:i,s:i}", "file", name, "number", best,
                                                 "frames", count));
    st = add_cubes(root, &rec, NULL, o->max_side, info, err);
    lm_cube_free(&rec);
    return st;
}

/* The page: the template with the data (JSON, '/' escaped so no "</script>" can occur)
 * at its mark. */
static lm_status compose(json_t *root, sbuf *page, lm_err *err)
{
    const char *mark = strstr(lm_report_page, DATA_MARK);
    char *js = json_dumps(root, JSON_COMPACT | JSON_ESCAPE_SLASH | JSON_REAL_PRECISION(7));
    if (!mark || !js) {
        free(js);
        return lm_err_set(err, mark ? LM_ERR_NOMEM : LM_ERR_FORMAT,
                          mark ? "report: out of memory" : "report: page template has no mark");
    }
    sb_add(page, lm_report_page, (size_t)(mark - lm_report_page));
    sb_add(page, js, strlen(js));
    const char *rest = mark + strlen(DATA_MARK);
    sb_add(page, rest, strlen(rest));
    free(js);
    return page->oom ? lm_err_set(err, LM_ERR_NOMEM, "report: out of memory") : LM_OK;
}

lm_status lm_report_write(const char *dir, const char *out, const lm_report_opts *o,
                          lm_report_info *info, lm_err *err)
{
    lm_report_opts dflt;
    lm_report_info dummy;
    if (!o) lm_report_default_opts(&dflt), o = &dflt;
    if (!info) info = &dummy;
    memset(info, 0, sizeof *info);
    if (o->max_side < LM_REPORT_MIN_SIDE || o->max_side > LM_REPORT_MAX_SIDE)
        return lm_err_set(err, LM_ERR_ARG, "report: cube side %d (need %d..%d)", o->max_side,
                          LM_REPORT_MIN_SIDE, LM_REPORT_MAX_SIDE);
    struct stat sst;
    if (stat(dir, &sst) != 0 || !S_ISDIR(sst.st_mode))
        return lm_err_set(err, LM_ERR_IO, "%s: %s", dir,
                          stat(dir, &sst) != 0 ? strerror(errno) : "not a folder");
    char p[4200];
    json_t *root = json_object();
    if (!root) return lm_err_set(err, LM_ERR_NOMEM, "report: out of memory");
    int ev = exists(dir, "eval.json", p, sizeof p);
    if (ev && o->frame >= 0) {
        json_decref(root);
        return lm_err_set(err, LM_ERR_ARG, "%s: an eval folder (--frame is for infer folders)",
                          dir);
    }
    json_object_set_new(root, "kind", json_string(ev ? "eval" : "infer"));
    json_object_set_new(root, "version", json_string(LM_VERSION));
    lm_status st = ev ? load_eval(dir, root, o, info, err) : load_infer(dir, root, o, info, err);
    sbuf page = {0};
    if (!st) st = compose(root, &page, err);
    if (!st) st = write_atomic(out, page.p, page.n, err);
    if (!st) info->bytes = page.n;
    free(page.p);
    json_decref(root);
    return st;
}

/* ---- eval --report ------------------------------------------------------------------------ */
static lm_status write_sample_json(const char *dir, const char *name, float k,
                                   const lm_metrics *m, lm_err *err)
{
    char p[4200];
    snprintf(p, sizeof p, "%s/sample.json", dir);
    json_t *j = json_pack("{s:s,s:f,s:{s:f,s:f,s:f,s:f}}", "scene", name, "noise_percent",
                          round(100.0 * k * 1e6) / 1e6, "metrics", "psnr", m->psnr, "ssim", m->ssim, "mae", m->mae,
                          "sam", m->sam);
    char *s = j ? json_dumps(j, JSON_INDENT(2) | JSON_REAL_PRECISION(10)) : NULL;
    char *nl = s ? realloc(s, strlen(s) + 2) : NULL;
    if (nl) strcat(nl, "\n"), s = nl;
    lm_status st = nl ? write_atomic(p, s, strlen(s), err)
                     : lm_err_set(err, LM_ERR_NOMEM, "report: out of memory");
    free(s);
    json_decref(j);
    return st;
}

static lm_status write_rainbow_csv(const char *dir, const lm_eval_rainbow *rb, lm_err *err)
{
    char p[4200], line[128];
    snprintf(p, sizeof p, "%s/rainbow.csv", dir);
    sbuf b = {0};
    static const char head[] = "row,true_nm,recovered_nm,error_nm\n";
    sb_add(&b, head, sizeof head - 1);
    int rows = rb->height < LM_EVAL_RAINBOW_MAX_ROWS ? rb->height : LM_EVAL_RAINBOW_MAX_ROWS;
    for (int y = 0; y < rows; y++) {
        int n = snprintf(line, sizeof line, "%d,%.4f,%.4f,%.4f\n", y, rb->row_true_nm[y],
                         rb->row_peak_nm[y], fabs(rb->row_peak_nm[y] - rb->row_true_nm[y]));
        sb_add(&b, line, (size_t)n);
    }
    lm_status st = b.oom ? lm_err_set(err, LM_ERR_NOMEM, "report: out of memory")
                         : write_atomic(p, b.p, b.n, err);
    free(b.p);
    return st;
}

lm_status lm_report_eval_files(lm_ctx *c, const lm_infer_model *im, const char *path,
                               const char *name, const char *mat_key, long long seed, float k,
                               const lm_tile_opts *to, const lm_eval_rainbow *rb,
                               const char *dir, lm_err *err)
{
    lm_cube truth, pred;
    memset(&pred, 0, sizeof pred);
    lm_cube_read_opts ro; /* as eval_run.c reads scenes */
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    ro.mat_key = mat_key;
    lm_status st = lm_cube_read_with(path, &ro, &truth, err);
    if (st) return st;
    st = lm_eval_prepare(&truth, im->model->mosaic.ty, im->model->mosaic.tx, err);
    lm_rng base, rs;
    lm_rng_seed(&base, (uint64_t)seed);
    rs = lm_rng_split(&base, lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, name));
    lm_metrics m;
    if (!st) st = lm_eval_scene_one(c, im, &truth, k, to, &rs, &m, &pred, err);
    char p[4200];
    size_t n = (size_t)pred.bands * pred.height * pred.width;
    for (size_t i = 0; !st && i < n; i++) /* the EXR holds reflectances >= 0 */
        pred.data[i] = pred.data[i] > 0.0f ? pred.data[i] : 0.0f;
    if (!st) snprintf(p, sizeof p, "%s/sample_recon.exr", dir), st = lm_cube_write_exr(p, &pred, err);
    if (!st) snprintf(p, sizeof p, "%s/sample_truth.exr", dir), st = lm_cube_write_exr(p, &truth, err);
    if (!st) st = write_sample_json(dir, name, k, &m, err);
    if (!st && rb) st = write_rainbow_csv(dir, rb, err);
    lm_cube_free(&pred);
    lm_cube_free(&truth);
    return st;
}
