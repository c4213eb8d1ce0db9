/* auto.c — `--model auto`: difficulty measure, calibration fit and file, per-window model
 * choice and the mixed-model fold (see auto.h).
 * What it is not: model loading or the CLI. */
#include "infer/auto.h"
#include "infer/model_io.h"
#include "data/noise_est.h"
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *const measure_names[] = {"grad", "relgrad", "noise"};
#define NMEASURES 3

const char *lm_auto_measure_name(lm_auto_measure m)
{
    return (unsigned)m < NMEASURES ? measure_names[m] : "?";
}

int lm_auto_measure_parse(const char *name)
{
    for (int i = 0; i < NMEASURES; i++)
        if (name && !strcmp(name, measure_names[i])) return i;
    return -1;
}

/* The noise level k of a frame (0 without positive signal), or -1 with err set. */
static double frame_level(const float *frame, int height, int width, int ty, int tx, lm_err *err)
{
    lm_noise_info ni;
    lm_err e;
    lm_err_clear(&e);
    lm_status st = lm_noise_analyze(frame, height, width, ty, tx, &ni, &e);
    if (st == LM_OK) return ni.level;
    int finite = st == LM_ERR_NUMERIC; /* no positive signal (level 0), or NaN / inf */
    for (size_t i = 0; finite && i < (size_t)height * width; i++) finite = isfinite(frame[i]);
    if (finite) return 0.0;
    lm_err_set(err, st, "auto: the noise measure: %s", e.msg);
    return -1.0;
}

double lm_auto_difficulty(lm_auto_measure m, const float *frame, int width, int y0, int x0,
                          int wh, int ww, int ty, int tx)
{
    if (m == LM_AUTO_NOISE) { /* the window's own level (a copy: the estimator reads rows) */
        float *w = malloc(sizeof(float) * (size_t)wh * ww);
        if (!w) return NAN;
        for (int i = 0; i < wh; i++)
            memcpy(w + (size_t)i * ww, frame + (size_t)(y0 + i) * width + x0, sizeof(float) * ww);
        lm_err e;
        lm_err_clear(&e);
        const double k = frame_level(w, wh, ww, ty, tx, &e);
        free(w);
        return k >= 0.0 ? k : NAN;
    }
    double g = 0.0, s = 0.0;
    for (int i = 0; i < wh; i++) {
        const float *r = frame + (size_t)(y0 + i) * width + x0;
        const float *dn = i + ty < wh ? r + (size_t)ty * width : NULL;
        for (int j = 0; j < ww; j++) {
            s += fabsf(r[j]);
            if (j + tx < ww) g += fabsf(r[j + tx] - r[j]);
            if (dn) g += fabsf(dn[j] - r[j]);
        }
    }
    double n = (double)wh * ww;
    g /= n;
    return m == LM_AUTO_RELGRAD ? g / (s / n + 1e-3) : g;
}

int lm_auto_window_count(int height, int width, const lm_tile_opts *o)
{
    return lm_tile_positions(height, o->win_h, o->stride_y, NULL, 0) *
           lm_tile_positions(width, o->win_w, o->stride_x, NULL, 0);
}

/* Window positions of a frame: *ys (ny), *xs (nx), malloc'ed. */
static lm_status positions(int H, int W, const lm_tile_opts *o, int **ys, int *ny, int **xs,
                           int *nx, lm_err *err)
{
    *ny = lm_tile_positions(H, o->win_h, o->stride_y, NULL, 0);
    *nx = lm_tile_positions(W, o->win_w, o->stride_x, NULL, 0);
    *ys = malloc(sizeof(int) * (size_t)(*ny > 0 ? *ny : 1));
    *xs = malloc(sizeof(int) * (size_t)(*nx > 0 ? *nx : 1));
    if (!*ys || !*xs) {
        free(*ys);
        free(*xs);
        *ys = *xs = NULL;
        return lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory");
    }
    lm_tile_positions(H, o->win_h, o->stride_y, *ys, *ny);
    lm_tile_positions(W, o->win_w, o->stride_x, *xs, *nx);
    return LM_OK;
}

lm_status lm_auto_frame_difficulty(lm_auto_measure m, const float *frame, int height, int width,
                                   int ty, int tx, const lm_tile_opts *o, int nthreads,
                                   double *d, lm_err *err)
{
    if (lm_tile_check(o, height, width, ty, tx, err)) return err->status;
    if (m == LM_AUTO_NOISE) { /* one level for the frame */
        const double k = frame_level(frame, height, width, ty, tx, err);
        if (k < 0.0) return err->status;
        const int n = lm_auto_window_count(height, width, o);
        for (int i = 0; i < n; i++) d[i] = k;
        return LM_OK;
    }
    int *ys, *xs, ny, nx;
    if (positions(height, width, o, &ys, &ny, &xs, &nx, err)) return err->status;
    int nt = nthreads > 0 ? nthreads : omp_get_max_threads();
    #pragma omp parallel for schedule(static) num_threads(nt)
    for (int i = 0; i < ny * nx; i++)
        d[i] = lm_auto_difficulty(m, frame, width, ys[i / nx], xs[i % nx], o->win_h, o->win_w,
                                  ty, tx);
    free(ys);
    free(xs);
    return LM_OK;
}

/* ---- labels ---------------------------------------------------------------------------- */
void lm_auto_label(lm_auto_calib *a)
{
    for (int m = 0; m < a->nmodels; m++) {
        lm_auto_model *x = &a->models[m];
        int shared = 0;
        for (int k = 0; k < a->nmodels; k++)
            shared |= k != m && !strcmp(a->models[k].preset, x->preset);
        if (!shared) {
            snprintf(x->label, sizeof x->label, "%s", x->preset);
            continue;
        }
        char p[1024];
        snprintf(p, sizeof p, "%s", x->path);
        size_t n = strlen(p);
        while (n > 1 && p[n - 1] == '/') p[--n] = '\0';
        static const char tail[] = "/model.safetensors", ext[] = ".safetensors";
        if (n > sizeof tail - 1 && !strcmp(p + n - (sizeof tail - 1), tail))
            p[n -= sizeof tail - 1] = '\0';
        else if (n > sizeof ext - 1 && !strcmp(p + n - (sizeof ext - 1), ext))
            p[n -= sizeof ext - 1] = '\0';
        const char *s = strrchr(p, '/');
        snprintf(x->label, sizeof x->label, "%s", s ? s + 1 : p);
    }
}

/* ---- selection ------------------------------------------------------------------------- */
int lm_auto_bin(const lm_auto_calib *a, double d)
{
    int b = 0;
    while (b < a->nbins - 1 && d >= a->edges[b]) b++;
    return b;
}

void lm_auto_choose(const lm_auto_calib *a, double tol_db, int *choice)
{
    for (int b = 0; b < a->nbins; b++) {
        double best = -INFINITY;
        for (int m = 0; m < a->nmodels; m++)
            if (a->models[m].psnr[b] > best) best = a->models[m].psnr[b];
        int pick = -1;
        for (int m = 0; m < a->nmodels; m++) {
            const lm_auto_model *x = &a->models[m];
            if (x->psnr[b] < best - tol_db) continue;
            if (pick < 0 || x->cost < a->models[pick].cost ||
                (x->cost == a->models[pick].cost && x->psnr[b] > a->models[pick].psnr[b]))
                pick = m;
        }
        choice[b] = pick;
    }
}

double lm_auto_expected_psnr(const lm_auto_calib *a, const int *choice, int model)
{
    double mse = 0.0;
    long n = 0;
    for (int b = 0; b < a->nbins; b++) {
        int m = choice ? choice[b] : model;
        mse += a->windows[b] * pow(10.0, -a->models[m].psnr[b] / 10.0);
        n += a->windows[b];
    }
    return n ? -10.0 * log10(mse / n) : 0.0;
}

static int cmp_double(const void *x, const void *y)
{
    double a = *(const double *)x, b = *(const double *)y;
    return (a > b) - (a < b);
}

lm_status lm_auto_fit(lm_auto_calib *a, const double *d, const double *mse, long n,
                      int nbins_max, lm_err *err)
{
    if (nbins_max < 1 || nbins_max > LM_AUTO_MAX_BINS || a->nmodels < 1 ||
        a->nmodels > LM_AUTO_MAX_MODELS || n < nbins_max)
        return lm_err_set(err, LM_ERR_ARG, "auto: fit: %ld windows, %d models, %d bins (need "
                          "1..%d models, 1..%d bins, at least as many windows as bins)", n,
                          a->nmodels, nbins_max, LM_AUTO_MAX_MODELS, LM_AUTO_MAX_BINS);
    double *s = malloc(sizeof(double) * (size_t)n);
    double *sum = calloc((size_t)LM_AUTO_MAX_BINS * a->nmodels, sizeof(double));
    if (!s || !sum) {
        free(s);
        free(sum);
        return lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory");
    }
    memcpy(s, d, sizeof(double) * (size_t)n);
    qsort(s, (size_t)n, sizeof(double), cmp_double);
    a->nbins = 1;
    for (int k = 1; k < nbins_max; k++) {
        long i = (long)((double)k * n / nbins_max);
        double e = 0.5 * (s[i - 1] + s[i]);
        if (s[i] > s[i - 1] && (a->nbins == 1 || e > a->edges[a->nbins - 2]))
            a->edges[a->nbins++ - 1] = e;
    }
    memset(a->windows, 0, sizeof a->windows);
    for (long i = 0; i < n; i++) {
        int b = lm_auto_bin(a, d[i]);
        a->windows[b]++;
        for (int m = 0; m < a->nmodels; m++) sum[m * LM_AUTO_MAX_BINS + b] += mse[m * n + i];
    }
    for (int m = 0; m < a->nmodels; m++)
        for (int b = 0; b < a->nbins; b++) {
            double e = a->windows[b] ? sum[m * LM_AUTO_MAX_BINS + b] / a->windows[b] : 0.0;
            a->models[m].psnr[b] = -10.0 * log10(e > 1e-10 ? e : 1e-10);
        }
    free(s);
    free(sum);
    lm_auto_label(a);
    return LM_OK;
}

lm_status lm_auto_validate(const lm_auto_calib *a, lm_err *err)
{
    if (a->nmodels < 1 || a->nmodels > LM_AUTO_MAX_MODELS)
        return lm_err_set(err, LM_ERR_FORMAT, "auto: %d models (need 1..%d)", a->nmodels,
                          LM_AUTO_MAX_MODELS);
    if (a->nbins < 1 || a->nbins > LM_AUTO_MAX_BINS)
        return lm_err_set(err, LM_ERR_FORMAT, "auto: %d bins (need 1..%d)", a->nbins,
                          LM_AUTO_MAX_BINS);
    if (a->win_h <= 0 || a->win_w <= 0 || a->stride_y <= 0 || a->stride_x <= 0)
        return lm_err_set(err, LM_ERR_FORMAT, "auto: window and stride must be positive");
    for (int b = 0; b + 1 < a->nbins; b++)
        if (!isfinite(a->edges[b]) || (b > 0 && !(a->edges[b] > a->edges[b - 1])))
            return lm_err_set(err, LM_ERR_FORMAT, "auto: bin edges must be finite and "
                              "strictly increasing");
    for (int m = 0; m < a->nmodels; m++) {
        const lm_auto_model *x = &a->models[m];
        if (!(x->cost > 0.0) || !isfinite(x->cost))
            return lm_err_set(err, LM_ERR_FORMAT, "auto: model %d ('%s'): cost must be a "
                              "positive number", m, x->path);
        for (int b = 0; b < a->nbins; b++)
            if (!isfinite(x->psnr[b]))
                return lm_err_set(err, LM_ERR_FORMAT, "auto: model %d ('%s'): psnr[%d] is not "
                                  "finite", m, x->path, b);
    }
    return LM_OK;
}

/* ---- file ------------------------------------------------------------------------------ */
static json_t *jarray_d(const double *v, int n)
{
    json_t *a = json_array();
    for (int i = 0; i < n; i++) json_array_append_new(a, json_real(v[i]));
    return a;
}

lm_status lm_auto_save(const char *path, const lm_auto_calib *a, lm_err *err)
{
    return lm_auto_save_ext(path, a, NULL, err);
}

lm_status lm_auto_save_ext(const char *path, const lm_auto_calib *a, json_t *extra, lm_err *err)
{
    json_t *models = json_array(), *win = json_array();
    for (int b = 0; b < a->nbins; b++) json_array_append_new(win, json_integer(a->windows[b]));
    for (int m = 0; m < a->nmodels; m++) {
        const lm_auto_model *x = &a->models[m];
        json_array_append_new(models, json_pack("{s:s, s:s, s:f, s:f, s:o}", "model", x->path,
                                                "preset", x->preset, "cost_s_per_window",
                                                x->cost, "macs_per_window", x->macs, "psnr",
                                                jarray_d(x->psnr, a->nbins)));
    }
    json_t *root = json_pack("{s:i, s:s, s:[i,i], s:[i,i], s:o, s:o, s:o}", "version",
                             LM_AUTO_VERSION, "measure", lm_auto_measure_name(a->measure),
                             "window", a->win_h, a->win_w, "stride", a->stride_y, a->stride_x,
                             "edges", jarray_d(a->edges, a->nbins - 1), "windows", win,
                             "models", models);
    if (root && extra && json_object_update(root, extra)) {
        json_decref(root);
        root = NULL;
    }
    char tmp[4200]; /* written whole, then renamed into place */
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    errno = 0;
    int rc = root ? json_dump_file(root, tmp, JSON_INDENT(2) | JSON_REAL_PRECISION(10)) : -1;
    json_decref(root);
    if (rc || rename(tmp, path)) {
        int e = errno;
        remove(tmp);
        return lm_err_set(err, root ? LM_ERR_WRITE : LM_ERR_NOMEM, "auto: cannot write '%s': %s",
                          path, !root ? "out of memory" : e ? strerror(e) : "write failed");
    }
    return LM_OK;
}

/* Read array `key` of root into v (exactly n numbers, or any count up to max when n < 0):
 * returns the count, or -1. */
static int get_reals(json_t *o, const char *key, double *v, int n, int max)
{
    json_t *a = json_object_get(o, key);
    if (!json_is_array(a)) return -1;
    int k = (int)json_array_size(a);
    if ((n >= 0 && k != n) || k > max) return -1;
    for (int i = 0; i < k; i++) {
        json_t *e = json_array_get(a, i);
        if (!json_is_number(e)) return -1;
        v[i] = json_number_value(e);
    }
    return k;
}

static lm_status load_model(json_t *o, int nbins, lm_auto_model *x)
{
    json_t *p = json_object_get(o, "model"), *ps = json_object_get(o, "preset");
    json_t *c = json_object_get(o, "cost_s_per_window"), *mc = json_object_get(o, "macs_per_window");
    if (!json_is_string(p) || !json_is_number(c) || strlen(json_string_value(p)) >= sizeof x->path)
        return LM_ERR_FORMAT;
    snprintf(x->path, sizeof x->path, "%s", json_string_value(p));
    snprintf(x->preset, sizeof x->preset, "%s", json_is_string(ps) ? json_string_value(ps) : "");
    x->cost = json_number_value(c);
    x->macs = json_is_number(mc) ? json_number_value(mc) : 0.0;
    return get_reals(o, "psnr", x->psnr, nbins, LM_AUTO_MAX_BINS) < 0 ? LM_ERR_FORMAT : LM_OK;
}

static lm_status load_root(json_t *r, lm_auto_calib *a, const char **what)
{
    double win[2], str[2], cnt[LM_AUTO_MAX_BINS];
    json_t *v = json_object_get(r, "version"), *ms = json_object_get(r, "measure");
    int meas = json_is_string(ms) ? lm_auto_measure_parse(json_string_value(ms)) : -1;
    if ((*what = "version 1"), !json_is_integer(v) || json_integer_value(v) != LM_AUTO_VERSION)
        return LM_ERR_FORMAT;
    if ((*what = "measure (grad|relgrad|noise)"), meas < 0) return LM_ERR_FORMAT;
    a->measure = (lm_auto_measure)meas;
    if ((*what = "window / stride [h, w] (integers in 1..4096)"),
        get_reals(r, "window", win, 2, 2) < 0 || get_reals(r, "stride", str, 2, 2) < 0)
        return LM_ERR_FORMAT;
    for (int k = 0; k < 2; k++) /* in range before they become ints */
        if (!(win[k] >= 1 && win[k] <= 4096 && str[k] >= 1 && str[k] <= 4096) ||
            win[k] != floor(win[k]) || str[k] != floor(str[k]))
            return LM_ERR_FORMAT;
    a->win_h = (int)win[0], a->win_w = (int)win[1], a->stride_y = (int)str[0],
    a->stride_x = (int)str[1];
    *what = "edges (up to 31 numbers) / windows (one count per bin)";
    int ne = get_reals(r, "edges", a->edges, -1, LM_AUTO_MAX_BINS - 1);
    if (ne < 0 || get_reals(r, "windows", cnt, ne + 1, LM_AUTO_MAX_BINS) < 0)
        return LM_ERR_FORMAT;
    a->nbins = ne + 1;
    for (int b = 0; b < a->nbins; b++) /* counts: NaN and negatives as 0, at most 1e15 */
        a->windows[b] = cnt[b] > 0 ? (long)fmin(cnt[b], 1e15) : 0;
    json_t *ml = json_object_get(r, "models");
    *what = "models (2..8 objects with model, cost_s_per_window, psnr per bin: a choice needs "
            "two, as fit-auto writes)";
    if (!json_is_array(ml) || json_array_size(ml) < 2 || json_array_size(ml) > LM_AUTO_MAX_MODELS)
        return LM_ERR_FORMAT;
    a->nmodels = (int)json_array_size(ml);
    for (int m = 0; m < a->nmodels; m++)
        if (load_model(json_array_get(ml, m), a->nbins, &a->models[m])) return LM_ERR_FORMAT;
    return LM_OK;
}

/* A relative model path is the calibration's folder's when it names something there (a
 * calibration shipped beside its models), else the working folder's. */
static void relative_models(lm_auto_calib *a, const char *calib)
{
    const char *slash = strrchr(calib, '/');
    if (!slash) return; /* the calibration is in the working folder */
    for (int m = 0; m < a->nmodels; m++) {
        char *p = a->models[m].path, alt[sizeof a->models[m].path];
        if (p[0] == '/') continue;
        int n = snprintf(alt, sizeof alt, "%.*s/%s", (int)(slash - calib), calib, p);
        if (n > 0 && (size_t)n < sizeof alt && access(alt, F_OK) == 0) memcpy(p, alt, n + 1);
    }
}

lm_status lm_auto_load(const char *path, lm_auto_calib *a, lm_err *err)
{
    memset(a, 0, sizeof *a);
    lm_status fchk = lm_file_check(path, "a calibration (.json)", err);
    if (fchk) return fchk;
    FILE *f = fopen(path, "rb");
    if (!f) return lm_err_set(err, LM_ERR_IO, "auto: cannot open calibration '%s'", path);
    json_error_t je;
    json_t *r = json_loadf(f, JSON_REJECT_DUPLICATES, &je);
    fclose(f);
    if (!r)
        return lm_err_set(err, LM_ERR_FORMAT, "auto: '%s' is not JSON (line %d: %s)", path,
                          je.line, je.text);
    const char *what = "";
    lm_status st = json_is_object(r) ? load_root(r, a, &what) : LM_ERR_FORMAT;
    json_decref(r);
    if (st) {
        memset(a, 0, sizeof *a);
        return lm_err_set(err, st, "auto: '%s': missing or bad field: %s", path,
                          *what ? what : "not an object");
    }
    lm_err ve;
    lm_err_clear(&ve);
    if (lm_auto_validate(a, &ve)) {
        memset(a, 0, sizeof *a);
        return lm_err_set(err, ve.status, "auto: '%s': %s", path, ve.msg + 6);
    }
    relative_models(a, path);
    lm_auto_label(a);
    return LM_OK;
}

/* ---- running several models over the windows ------------------------------------------- */
typedef struct mix {
    lm_model *const *models;
    int nmodels, batch, next;  /* next: index of the first window of the coming fold batch */
    int planes;                /* input planes per window (a two-bucket model's 2) */
    const int *win_model;
    long *windows;
    int *idx;                  /* fold batch scratch */
    float *host;               /* host scratch: raw, a group's input, outputs, a group's output */
    size_t cap;                /* windows' pixels the scratch holds per plane */
} mix;

/* Model m on windows idx[0..k) of raw (nb x np x h x w floats, host), its outputs into y
 * (nb x oc x h x w floats, host). On the CPU the group is gathered straight into the input
 * tensor and scattered straight from the output; on a device (gin, gout: host scratch) it goes
 * in and out through lm_tensor_from / lm_tensor_read. */
static int run_group(lm_ctx *c, lm_model *m, const float *raw, int np, int h, int w,
                     const int *idx, int k, int oc, float *y, float *gin, float *gout)
{
    const size_t win = (size_t)h * w, iwin = (size_t)np * win;
    lm_tensor *in = gin ? NULL : lm_tensor_new(c, 4, (int[]){k, np, h, w});
    float *dst = gin ? gin : in ? in->data : NULL;
    if (!dst) return -1;
    for (int i = 0; i < k; i++) memcpy(dst + i * iwin, raw + idx[i] * iwin, sizeof(float) * iwin);
    if (gin) in = lm_tensor_from(c, 4, (int[]){k, np, h, w}, gin);
    lm_tensor *o = in ? lm_model_forward(c, m, in) : NULL;
    if (!o || lm_ctx_status(c)) return -1;
    if (o->ndim != 4 || o->shape[0] != k || o->shape[1] != oc || o->shape[2] != h ||
        o->shape[3] != w) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "auto: model '%s' returned the wrong shape", m->preset);
        return -1;
    }
    lm_tensor *oc_ = lm_contiguous(c, o);
    if (!oc_ || (gout && lm_tensor_read(c, oc_, gout))) return -1;
    const float *src = gout ? gout : oc_->data;
    for (int i = 0; i < k; i++)
        memcpy(y + (size_t)idx[i] * oc * win, src + (size_t)i * oc * win,
               sizeof(float) * oc * win);
    return 0;
}

/* One fold batch: the windows of each model in groups of at most x->batch. On a device, raw
 * (made by fold_batch with lm_tensor_from) is read to host scratch first and the result goes
 * back as a tensor of the ctx; on the CPU both are used in place. */
static lm_tensor *mix_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    mix *x = user;
    const int nb = raw->shape[0], np = raw->shape[1], h = raw->shape[2], w = raw->shape[3];
    int oc = x->models[0]->out_channels;
    const size_t win = (size_t)h * w;
    int dev = raw->device != LM_DEVICE_CPU;
    if (dev && (!x->host || x->cap < (size_t)nb * win)) {
        free(x->host);
        x->cap = (size_t)nb * win;
        x->host = malloc(x->cap * sizeof(float) * (2 * (size_t)np + 2 * (size_t)oc));
        if (!x->host) {
            lm_ctx_fail(c, LM_ERR_NOMEM, "auto: out of memory");
            return NULL;
        }
    }
    lm_tensor *y = dev ? NULL : lm_tensor_new(c, 4, (int[]){nb, oc, h, w});
    lm_tensor *rc = dev ? lm_contiguous(c, raw) : raw;
    if ((!dev && !y) || !rc) return NULL;
    float *hraw = dev ? x->host : raw->data, *gin = dev ? hraw + x->cap * np : NULL;
    float *hy = dev ? gin + x->cap * np : y->data, *gout = dev ? hy + x->cap * oc : NULL;
    if (dev && lm_tensor_read(c, rc, hraw)) return NULL;
    for (int m = 0; m < x->nmodels; m++) {
        int k = 0;
        for (int b = 0; b < nb; b++)
            if (x->win_model[x->next + b] == m) x->idx[k++] = b;
        for (int s = 0; s < k; s += x->batch) {
            int n = k - s < x->batch ? k - s : x->batch;
            if (run_group(c, x->models[m], hraw, np, h, w, x->idx + s, n, oc, hy, gin, gout))
                return NULL;
        }
        if (x->windows) x->windows[m] += k;
    }
    x->next += nb;
    return dev ? lm_tensor_from(c, 4, (int[]){nb, oc, h, w}, hy) : y;
}

lm_status lm_auto_fold(lm_ctx *c, lm_model *const *models, int nmodels, const int *win_model,
                       const float *frame, int height, int width, const lm_tile_opts *o,
                       int out_ch, float *out, long *windows, lm_err *err)
{
    if (nmodels < 1 || nmodels > LM_AUTO_MAX_MODELS)
        return lm_err_set(err, LM_ERR_ARG, "auto: %d models (need 1..%d)", nmodels,
                          LM_AUTO_MAX_MODELS);
    const int planes = lm_model_coded_planes(models[0]);
    for (int m = 0; m < nmodels; m++)
        if (models[m]->mosaic.ty != models[0]->mosaic.ty ||
            models[m]->mosaic.tx != models[0]->mosaic.tx || models[m]->out_channels != out_ch ||
            lm_model_coded_planes(models[m]) != planes)
            return lm_err_set(err, LM_ERR_ARG, "auto: models '%s' and '%s' differ in tile, "
                              "buckets or output channels", models[0]->preset,
                              models[m]->preset);
    if (lm_tile_check(o, height, width, models[0]->mosaic.ty, models[0]->mosaic.tx, err))
        return err->status;
    int nwin = lm_auto_window_count(height, width, o);
    for (int i = 0; i < nwin; i++)
        if (win_model[i] < 0 || win_model[i] >= nmodels)
            return lm_err_set(err, LM_ERR_ARG, "auto: window %d: model index %d out of 0..%d",
                              i, win_model[i], nmodels - 1);
    lm_tile_opts fo = *o;
    fo.batch = o->batch * nmodels;
    mix x = {models, nmodels, o->batch, 0, planes, win_model, windows,
             malloc(sizeof(int) * fo.batch), NULL, 0};
    if (!x.idx) return lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory");
    for (int k = 0; k < nmodels; k++) lm_infer_set_noise(models[k], frame, height, width);
    const lm_mosaic *mo = &models[0]->mosaic;
    lm_status st = lm_tile_fold_planes(c, frame, planes, height, width, mo->ty, mo->tx, &fo,
                                       mix_fn, &x, out_ch, out, NULL, err);
    free(x.idx);
    free(x.host);
    return st;
}

lm_status lm_auto_infer(lm_ctx *c, lm_model *const *models, int nmodels, const int *win_model,
                        const float *frame, int height, int width, const lm_tile_opts *o,
                        lm_cube *cube, long *windows, lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    const size_t plane = (size_t)height * width;
    float *full = malloc(sizeof(float) * plane * LM_MODEL_OUT_CHANNELS);
    if (!full) return lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory (%dx%d frame)",
                                 height, width);
    lm_status st = lm_auto_fold(c, models, nmodels, win_model, frame, height, width, o,
                                LM_MODEL_OUT_CHANNELS, full, windows, err);
    if (!st && lm_cube_alloc(cube, 31, height, width, 400.0f, 10.0f))
        st = lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory (31x%dx%d cube)", height, width);
    if (!st) memcpy(cube->data, full + plane, sizeof(float) * plane * 31);
    free(full);
    return st;
}

/* ---- calibration samples --------------------------------------------------------------- */
typedef struct calib_cb {
    lm_model *model;
    const float *truth;        /* 31 x H x W */
    int H, W, nx, next;
    const int *ys, *xs;
    const float *K;            /* wh x ww */
    double *mse;               /* this model's row */
    double secs;
} calib_cb;

static lm_tensor *calib_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    calib_cb *x = user;
    double t0 = omp_get_wtime();
    lm_tensor *y = lm_model_forward(c, x->model, raw);
    y = y && !lm_ctx_status(c) ? lm_contiguous(c, y) : NULL;
    x->secs += omp_get_wtime() - t0;
    if (!y || y->ndim != 4 || y->shape[1] != LM_MODEL_OUT_CHANNELS) return y;
    const int nb = raw->shape[0], wh = raw->shape[2], ww = raw->shape[3];
    const size_t win = (size_t)wh * ww, plane = (size_t)x->H * x->W;
    for (int b = 0; b < nb; b++) {
        int w = x->next + b, y0 = x->ys[w / x->nx], x0 = x->xs[w % x->nx];
        double se = 0.0, ks = 0.0;
        for (int ch = 0; ch < 31; ch++) {
            const float *r = y->data + ((size_t)b * LM_MODEL_OUT_CHANNELS + ch + 1) * win;
            const float *t = x->truth + ch * plane + (size_t)y0 * x->W + x0;
            for (int i = 0; i < wh; i++)
                for (int j = 0; j < ww; j++) {
                    double e = r[i * ww + j] - t[(size_t)i * x->W + j], k = x->K[i * ww + j];
                    se += k * e * e;
                    ks += k;
                }
        }
        x->mse[w] = se / ks;
    }
    x->next += nb;
    return y;
}

lm_status lm_auto_scene(lm_ctx *c, lm_model *const *models, int nmodels, lm_auto_measure meas,
                        const float *frame, const float *truth, int height, int width,
                        const lm_tile_opts *o, double *d, double *mse, double *secs,
                        lm_err *err)
{
    const int ty = models[0]->mosaic.ty, tx = models[0]->mosaic.tx;
    const int planes = lm_model_coded_planes(models[0]);
    for (int m = 1; m < nmodels; m++)
        if (lm_model_coded_planes(models[m]) != planes)
            return lm_err_set(err, LM_ERR_ARG, "auto: models '%s' and '%s' read other frames",
                              models[0]->preset, models[m]->preset);
    if (lm_auto_frame_difficulty(meas, frame, height, width, ty, tx, o, lm_nthreads(c), d, err))
        return err->status;
    int nwin = lm_auto_window_count(height, width, o), *ys, *xs, ny, nx;
    if (positions(height, width, o, &ys, &ny, &xs, &nx, err)) return err->status;
    float *K = malloc(sizeof(float) * (size_t)o->win_h * o->win_w);
    float *ky = malloc(sizeof(float) * o->win_h), *kx = malloc(sizeof(float) * o->win_w);
    float *out = malloc(sizeof(float) * LM_MODEL_OUT_CHANNELS * (size_t)height * width);
    lm_status st = K && ky && kx && out ? LM_OK
                                        : lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory");
    if (!st) {
        lm_tile_kernel_1d(o->win_h, ky);
        lm_tile_kernel_1d(o->win_w, kx);
        for (int i = 0; i < o->win_h; i++)
            for (int j = 0; j < o->win_w; j++) K[i * o->win_w + j] = ky[i] * kx[j];
    }
    for (int m = 0; m < nmodels && !st; m++) {
        lm_infer_set_noise(models[m], frame, height, width);
        calib_cb x = {models[m], truth, height, width, nx, 0, ys, xs, K, mse + (size_t)m * nwin, 0};
        st = lm_tile_fold_planes(c, frame, planes, height, width, ty, tx, o, calib_fn, &x,
                                 LM_MODEL_OUT_CHANNELS, out, NULL, err);
        if (secs) secs[m] += x.secs;
    }
    free(K);
    free(ky);
    free(kx);
    free(out);
    free(ys);
    free(xs);
    return st;
}

lm_status lm_auto_run(lm_ctx *c, const lm_auto_calib *a, const int *choice,
                      lm_model *const *models, const float *frame, int height, int width,
                      const lm_tile_opts *o, lm_cube *cube, int *nwin, long *windows,
                      lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    lm_tile_opts to = *o;
    to.win_h = a->win_h, to.win_w = a->win_w, to.stride_y = a->stride_y, to.stride_x = a->stride_x;
    to = lm_tile_fitted(&to, height, width);
    const lm_mosaic *mo = &models[0]->mosaic;
    if (lm_tile_check(&to, height, width, mo->ty, mo->tx, err)) return err->status;
    const int n = lm_auto_window_count(height, width, &to);
    double *d = malloc(sizeof(double) * n);
    int *wm = malloc(sizeof(int) * n);
    lm_status st = d && wm ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "auto: out of memory");
    if (!st) st = lm_auto_frame_difficulty(a->measure, frame, height, width, mo->ty, mo->tx, &to,
                                           lm_nthreads(c), d, err);
    for (int i = 0; i < n && !st; i++) wm[i] = choice[lm_auto_bin(a, d[i])];
    if (!st) st = lm_auto_infer(c, models, a->nmodels, wm, frame, height, width, &to, cube,
                                windows, err);
    if (nwin) *nwin = n;
    free(d);
    free(wm);
    return st;
}
