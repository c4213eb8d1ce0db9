/* tile.c — patch-wise inference: window grid, weighting kernel, batched fold (see tile.h).
 * What it is not: a tensor op (no autograd: inference only) or model loading. */
#include "infer/tile.h"
#include "infer/model_io.h"
#include "tensor/device.h"
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

void lm_tile_default_opts(lm_tile_opts *o)
{
    *o = (lm_tile_opts){.win_h = 66, .win_w = 64, .stride_y = 30, .stride_x = 32, .batch = 8};
}

lm_status lm_tile_check(const lm_tile_opts *o, int height, int width, int ty, int tx,
                        lm_err *err)
{
    if (ty <= 0 || tx <= 0 || o->batch < 1 || o->win_h <= 0 || o->win_w <= 0 ||
        o->stride_y <= 0 || o->stride_x <= 0)
        return lm_err_set(err, LM_ERR_ARG, "tile: window %dx%d, stride %dx%d, batch %d, tile "
                          "%dx%d must all be positive", o->win_h, o->win_w, o->stride_y,
                          o->stride_x, o->batch, ty, tx);
    if (o->win_h % ty || o->win_w % tx || o->stride_y % ty || o->stride_x % tx)
        return lm_err_set(err, LM_ERR_ARG, "tile: window %dx%d and stride %dx%d must be "
                          "multiples of the %dx%d mosaic tile", o->win_h, o->win_w, o->stride_y,
                          o->stride_x, ty, tx);
    if (height % ty || width % tx)
        return lm_err_set(err, LM_ERR_SHAPE, "tile: frame %dx%d (HxW) is not a multiple of the "
                          "%dx%d mosaic tile", height, width, ty, tx);
    if (height < LM_TILE_MIN_TILES * ty || width < LM_TILE_MIN_TILES * tx)
        return lm_err_set(err, LM_ERR_SHAPE, "tile: frame %dx%d (HxW) is smaller than %d x %d "
                          "mosaic tiles (%dx%d)", height, width, LM_TILE_MIN_TILES,
                          LM_TILE_MIN_TILES, LM_TILE_MIN_TILES * ty, LM_TILE_MIN_TILES * tx);
    if (height < o->win_h || width < o->win_w)
        return lm_err_set(err, LM_ERR_SHAPE, "tile: frame %dx%d (HxW) is smaller than the "
                          "%dx%d window", height, width, o->win_h, o->win_w);
    return LM_OK;
}

lm_tile_opts lm_tile_fitted(const lm_tile_opts *o, int height, int width)
{
    lm_tile_opts f = *o;
    if (height > 0 && height < f.win_h) f.win_h = height;
    if (width > 0 && width < f.win_w) f.win_w = width;
    if (f.stride_y > f.win_h) f.stride_y = f.win_h;
    if (f.stride_x > f.win_w) f.stride_x = f.win_w;
    return f;
}

int lm_tile_positions(int n, int win, int stride, int *pos, int max)
{
    int count = 0, last = -1;
    for (int p = 0; p + win <= n; p += stride, count++) {
        if (pos && count < max) pos[count] = p;
        last = p;
    }
    if (last >= 0 && last + win < n) {
        if (pos && count < max) pos[count] = n - win;
        count++;
    }
    return count;
}

void lm_tile_kernel_1d(int n, float *k)
{
    const double pi = 3.14159265358979323846;
    for (int i = 0; i < n; i++) {
        double s = sin(pi * (i + 0.5) / n);
        k[i] = (float)(LM_TILE_FLOOR + (1.0 - LM_TILE_FLOOR) * s * s);
    }
}

/* Per-fold state: window grid, kernel, host buffers. */
typedef struct fold {
    int H, W, wh, ww, ny, nx, nwin, out_ch;
    int planes;   /* input planes of the frame (2: both buckets, 3: three frames) */
    int *ys, *xs;
    float *K;     /* wh * ww */
    float *in;    /* batch * wh * ww: windows of the frame */
    float *res;   /* batch * out_ch * wh * ww: network output */
    float *wsum;  /* H * W: accumulated K */
} fold;

static void fold_free(fold *f)
{
    free(f->ys);
    free(f->xs);
    free(f->K);
    free(f->in);
    free(f->res);
    free(f->wsum);
}

static lm_status fold_init(fold *f, int H, int W, const lm_tile_opts *o, int out_ch, int planes,
                           lm_err *err)
{
    memset(f, 0, sizeof *f);
    f->planes = planes;
    f->H = H, f->W = W, f->wh = o->win_h, f->ww = o->win_w, f->out_ch = out_ch;
    f->ny = lm_tile_positions(H, o->win_h, o->stride_y, NULL, 0);
    f->nx = lm_tile_positions(W, o->win_w, o->stride_x, NULL, 0);
    f->nwin = f->ny * f->nx;
    size_t win = (size_t)f->wh * f->ww;
    f->ys = malloc(sizeof(int) * f->ny);
    f->xs = malloc(sizeof(int) * f->nx);
    f->K = malloc(sizeof(float) * win);
    f->in = malloc(sizeof(float) * win * o->batch * planes);
    f->res = malloc(sizeof(float) * win * o->batch * out_ch);
    f->wsum = calloc((size_t)H * W, sizeof(float));
    float *ky = malloc(sizeof(float) * f->wh), *kx = malloc(sizeof(float) * f->ww);
    int ok = f->ys && f->xs && f->K && f->in && f->res && f->wsum && ky && kx;
    if (ok) {
        lm_tile_positions(H, f->wh, o->stride_y, f->ys, f->ny);
        lm_tile_positions(W, f->ww, o->stride_x, f->xs, f->nx);
        lm_tile_kernel_1d(f->wh, ky);
        lm_tile_kernel_1d(f->ww, kx);
        for (int i = 0; i < f->wh; i++)
            for (int j = 0; j < f->ww; j++) f->K[i * f->ww + j] = ky[i] * kx[j];
    }
    free(ky);
    free(kx);
    if (!ok) {
        fold_free(f);
        return lm_err_set(err, LM_ERR_NOMEM, "tile: out of memory (%dx%d frame, batch %d)", H,
                          W, o->batch);
    }
    return LM_OK;
}

/* Copy windows [w0, w0 + nb) of the frame (every plane) into f->in. */
static void fold_gather(fold *f, const float *frame, int w0, int nb)
{
    const size_t plane = (size_t)f->H * f->W;
    for (int b = 0; b < nb; b++) {
        int y0 = f->ys[(w0 + b) / f->nx], x0 = f->xs[(w0 + b) % f->nx];
        for (int q = 0; q < f->planes; q++)
            for (int i = 0; i < f->wh; i++)
                memcpy(f->in + (((size_t)b * f->planes + q) * f->wh + i) * f->ww,
                       frame + q * plane + (size_t)(y0 + i) * f->W + x0, sizeof(float) * f->ww);
    }
}

/* out += K * res for windows [w0, w0 + nb), in window order; channels in parallel (each channel
 * is summed by one thread in the same order, so the result is deterministic). */
static void fold_accumulate(const fold *f, float *out, int w0, int nb, int nthreads)
{
    const size_t win = (size_t)f->wh * f->ww, plane = (size_t)f->H * f->W;
    #pragma omp parallel for schedule(static) num_threads(nthreads)
    for (int ch = 0; ch < f->out_ch; ch++)
        for (int b = 0; b < nb; b++) {
            int y0 = f->ys[(w0 + b) / f->nx], x0 = f->xs[(w0 + b) % f->nx];
            const float *r = f->res + ((size_t)b * f->out_ch + ch) * win;
            for (int i = 0; i < f->wh; i++) {
                float *o = out + ch * plane + (size_t)(y0 + i) * f->W + x0;
                const float *k = f->K + (size_t)i * f->ww, *ri = r + (size_t)i * f->ww;
                for (int j = 0; j < f->ww; j++) o[j] += k[j] * ri[j];
            }
        }
    for (int b = 0; b < nb; b++) {
        int y0 = f->ys[(w0 + b) / f->nx], x0 = f->xs[(w0 + b) % f->nx];
        for (int i = 0; i < f->wh; i++)
            for (int j = 0; j < f->ww; j++)
                f->wsum[(size_t)(y0 + i) * f->W + x0 + j] += f->K[i * f->ww + j];
    }
}

/* One batch through fn into f->res; LM_OK or the error (ctx error moved into err). */
static lm_status fold_batch(lm_ctx *c, fold *f, int nb, lm_tile_fn fn, void *user, lm_err *err)
{
    int shape[4] = {nb, f->planes, f->wh, f->ww};
    lm_tensor *raw = lm_tensor_from(c, 4, shape, f->in);
    lm_tensor *y = raw ? fn(c, raw, user) : NULL;
    if (y && !lm_ctx_status(c) &&
        (y->ndim != 4 || y->shape[0] != nb || y->shape[1] != f->out_ch ||
         y->shape[2] != f->wh || y->shape[3] != f->ww)) {
        char buf[64];
        return lm_err_set(err, LM_ERR_SHAPE, "tile: the network returned %s, expected "
                          "%dx%dx%dx%d", lm_shape_str(y, buf, sizeof buf), nb, f->out_ch, f->wh,
                          f->ww);
    }
    if (y && !lm_ctx_status(c)) {
        lm_tensor *yc = lm_contiguous(c, y);
        if (yc) lm_tensor_read(c, yc, f->res);
    }
    if (lm_ctx_status(c) || !y) {
        lm_status s = lm_ctx_status(c) ? lm_ctx_status(c) : LM_ERR_ARG;
        lm_err_set(err, s, "%s", lm_ctx_status(c) ? lm_ctx_message(c) : "tile: network failed");
        lm_ctx_clear_error(c);
        return s;
    }
    return LM_OK;
}

lm_status lm_tile_fold(lm_ctx *c, const float *frame, int height, int width, int ty, int tx,
                       const lm_tile_opts *o, lm_tile_fn fn, void *user, int out_ch,
                       float *out, lm_err *err)
{
    return lm_tile_fold_timed(c, frame, height, width, ty, tx, o, fn, user, out_ch, out, NULL,
                              err);
}

static double now_s(lm_tile_timing *t) { return t ? omp_get_wtime() : 0.0; }

lm_status lm_tile_fold_timed(lm_ctx *c, const float *frame, int height, int width, int ty,
                             int tx, const lm_tile_opts *o, lm_tile_fn fn, void *user,
                             int out_ch, float *out, lm_tile_timing *t, lm_err *err)
{
    return lm_tile_fold_planes(c, frame, 1, height, width, ty, tx, o, fn, user, out_ch, out, t,
                               err);
}

lm_status lm_tile_fold_planes(lm_ctx *c, const float *frame, int planes, int height, int width,
                              int ty, int tx, const lm_tile_opts *o, lm_tile_fn fn, void *user,
                              int out_ch, float *out, lm_tile_timing *t, lm_err *err)
{
    const lm_tile_opts fo = lm_tile_fitted(o, height, width);
    o = &fo;
    if (lm_tile_check(o, height, width, ty, tx, err)) return err->status;
    if (out_ch <= 0) return lm_err_set(err, LM_ERR_ARG, "tile: %d output channels", out_ch);
    if (planes < 1 || planes > 3) return lm_err_set(err, LM_ERR_ARG, "tile: %d input planes", planes);
    fold f;
    if (fold_init(&f, height, width, o, out_ch, planes, err)) return err->status;
    const size_t plane = (size_t)height * width;
    memset(out, 0, sizeof(float) * plane * out_ch);
    int grad = lm_ctx_set_grad(c, 0);
    lm_status st = LM_OK;
    double t0 = now_s(t), t1, t2, t3;
    for (int w0 = 0; w0 < f.nwin && !st; w0 += o->batch) {
        int nb = f.nwin - w0 < o->batch ? f.nwin - w0 : o->batch;
        fold_gather(&f, frame, w0, nb);
        t1 = now_s(t);
        st = fold_batch(c, &f, nb, fn, user, err);
        t2 = now_s(t);
        if (!st) fold_accumulate(&f, out, w0, nb, lm_nthreads(c));
        lm_ctx_reset(c);
        t3 = now_s(t);
        if (t) {
            t->gather += t1 - t0;
            t->network += t2 - t1;
            t->fold += t3 - t2;
            t->batches++;
        }
        t0 = t3;
    }
    lm_ctx_set_grad(c, grad);
    if (!st) {
        #pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
        for (int ch = 0; ch < out_ch; ch++)
            for (size_t p = 0; p < plane; p++) out[ch * plane + p] /= f.wsum[p];
    }
    if (t) {
        t->fold += now_s(t) - t0;
        t->windows += f.nwin;
    }
    fold_free(&f);
    return st;
}

static lm_tensor *model_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    return lm_model_forward(c, (lm_model *)user, raw);
}

lm_status lm_tile_infer(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                        const lm_tile_opts *o, lm_cube *cube, lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    if (m->out_channels != LM_MODEL_OUT_CHANNELS)
        return lm_err_set(err, LM_ERR_ARG, "tile: model '%s' has %d output channels, expected %d",
                          m->preset, m->out_channels, LM_MODEL_OUT_CHANNELS);
    const lm_tile_opts fo = lm_tile_fitted(o, height, width);
    o = &fo;
    if (lm_tile_check(o, height, width, m->mosaic.ty, m->mosaic.tx, err)) return err->status;
    const size_t plane = (size_t)height * width;
    lm_infer_set_noise(m, frame, height, width);
    float *full = malloc(sizeof(float) * plane * LM_MODEL_OUT_CHANNELS);
    if (!full) return lm_err_set(err, LM_ERR_NOMEM, "tile: out of memory (%dx%d frame)", height,
                                 width);
    const int planes = lm_model_coded_planes(m);
    lm_status st = lm_tile_fold_planes(c, frame, planes, height, width, m->mosaic.ty,
                                       m->mosaic.tx, o, model_fn, m, LM_MODEL_OUT_CHANNELS, full,
                                       NULL, err);
    if (!st && lm_cube_alloc(cube, 31, height, width, 400.0f, 10.0f))
        st = lm_err_set(err, LM_ERR_NOMEM, "tile: out of memory (31x%dx%d cube)", height, width);
    if (!st) memcpy(cube->data, full + plane, sizeof(float) * plane * 31);
    free(full);
    return st;
}

lm_status lm_tile_device_open(lm_tile_device *d, const char *name, lm_model *m, lm_ctx *c,
                              lm_err *err)
{
    return lm_tile_device_open_models(d, name, &m, 1, c, err);
}

lm_status lm_tile_device_open_models(lm_tile_device *d, const char *name, lm_model *const *ms,
                                     int nm, lm_ctx *c, lm_err *err)
{
    memset(d, 0, sizeof *d);
    lm_err be;
    lm_err_clear(&be);
    lm_backend *b = lm_backend_open(name, &be);
    if (!b) return lm_err_set(err, be.status, "device: %s", be.msg);
    d->backend = b;
    d->ctx = c;
    if (b->device == LM_DEVICE_CPU) return LM_OK;
    lm_ctx_set_backend(c, b);
    int total = 0;
    for (int k = 0; k < nm; k++) total += ms[k]->params.n;
    d->ps = malloc(sizeof *d->ps * (size_t)(total > 0 ? total : 1));
    d->held = malloc(sizeof *d->held * (size_t)(total > 0 ? total : 1));
    if (!d->ps || !d->held || lm_ctx_init(&d->pctx, lm_nthreads(c)) != 0) {
        lm_tile_device_close(d);
        return lm_err_set(err, LM_ERR_NOMEM, "device: out of memory");
    }
    d->have_pctx = 1;
    lm_ctx_set_backend(&d->pctx, b);
    d->np = 0; /* every model's parameters, in model order */
    for (int k = 0; k < nm; k++)
        for (int i = 0; i < ms[k]->params.n; i++) d->ps[d->np++] = &ms[k]->params.items[i]->t;
    if (lm_tensors_swap_to_device(&d->pctx, d->ps, d->np, d->held)) {
        lm_status s = lm_err_set(err, lm_ctx_status(&d->pctx), "device: %s",
                                 lm_ctx_message(&d->pctx));
        for (int i = 0; i < d->np; i++) *d->ps[i] = d->held[i];
        d->np = 0;
        lm_tile_device_close(d);
        return s;
    }
    return LM_OK;
}

const char *lm_tile_device_name(const lm_tile_device *d)
{
    if (!d->backend || d->backend->device == LM_DEVICE_CPU) return "cpu";
    return lm_backend_device_name(d->backend);
}

void lm_tile_device_close(lm_tile_device *d)
{
    if (!d->backend) return;
    if (d->np) lm_tensors_swap_back(&d->pctx, d->ps, d->np, d->held);
    if (d->have_pctx) lm_ctx_free(&d->pctx);
    if (d->ctx) lm_ctx_set_backend(d->ctx, NULL);
    lm_backend_close(d->backend);
    free(d->ps);
    free(d->held);
    memset(d, 0, sizeof *d);
}
