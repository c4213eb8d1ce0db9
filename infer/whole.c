/* whole.c — strip-wise whole-frame inference (see whole.h). */
#include "infer/whole.h"
#include "infer/model_io.h"
#include <stdlib.h>
#include <string.h>

void lm_whole_default_opts(lm_whole_opts *o)
{
    o->strip_rows = LM_WHOLE_STRIP_ROWS;
    o->halo = -1;
}

int lm_whole_halo(const lm_model *m)
{
    const int ty = m->mosaic.ty;
    if (m->conv_rows < 0 || lm_model_buckets(m) == 0) return -1; /* coded frames only */
    /* demosaic: up to ty - 1 rows at a strip edge see a clamped neighbour */
    int rows = ty - 1 + m->conv_rows;
    return (rows + ty - 1) / ty * ty;
}

static lm_status whole_check(const lm_model *m, int height, int width, const lm_whole_opts *o,
                             int ch0, int nch, lm_err *err)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx;
    if (lm_whole_halo(m) < 0)
        return lm_err_set(err, LM_ERR_ARG, "whole: model '%s' (family %s) has no declared finite "
                          "receptive field; use tiled inference", m->preset, m->family);
    if (o->strip_rows < 0 || (o->halo >= 0 && o->halo % ty))
        return lm_err_set(err, LM_ERR_ARG, "whole: strip rows %d must be >= 0 and halo %d a "
                          "multiple of %d", o->strip_rows, o->halo, ty);
    if (ch0 < 0 || nch < 1 || ch0 + nch > m->out_channels)
        return lm_err_set(err, LM_ERR_ARG, "whole: channels [%d, %d) outside the model's %d",
                          ch0, ch0 + nch, m->out_channels);
    if (height <= 0 || width <= 0 || height % ty || width % tx)
        return lm_err_set(err, LM_ERR_SHAPE, "whole: frame %dx%d must be a positive multiple of "
                          "the %dx%d tile", height, width, ty, tx);
    return LM_OK;
}

/* Rows [y0, y1) of channels [ch0, ch0 + nch) of y (1 x C x h x W, contiguous, frame row a at
 * row 0). A device tensor is read to the host first (scratch: *buf, grown as needed). */
static lm_status strip_store(lm_ctx *c, const lm_tensor *y, int a, int y0, int y1, int ch0,
                             int nch, int height, float *out, float **buf, size_t *cap,
                             lm_err *err)
{
    const int W = y->shape[3], h = y->shape[2];
    const size_t plane = (size_t)height * W, n = (size_t)(y1 - y0) * W;
    const float *src = y->data;
    if (y->device != LM_DEVICE_CPU) {
        size_t need = (size_t)lm_tensor_numel(y);
        if (need > *cap) {
            float *p = realloc(*buf, need * sizeof *p);
            if (!p) return lm_err_set(err, LM_ERR_NOMEM, "whole: out of memory (strip)");
            *buf = p, *cap = need;
        }
        if (lm_tensor_read(c, y, *buf))
            return lm_err_set(err, lm_ctx_status(c) ? lm_ctx_status(c) : LM_ERR_BACKEND,
                              "whole: reading a strip from the device: %s", lm_ctx_message(c));
        src = *buf;
    }
    #pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (int k = 0; k < nch; k++)
        memcpy(out + k * plane + (size_t)y0 * W,
               src + ((size_t)(ch0 + k) * h + (y0 - a)) * W, sizeof(float) * n);
    return LM_OK;
}

/* One strip: frame rows [a, b) through the model (of each of its input planes: a two-bucket
 * model's frame is bucket 1 then bucket 0, H x W each, copied into one strip tensor); ctx error
 * moved into err. */
static lm_status strip_run(lm_ctx *c, lm_model *m, const float *frame, int H, int W, int a,
                           int b, float *sbuf, lm_tensor **y, lm_err *err)
{
    const int C = m->in_channels; /* C > 1: the planes' rows gathered into sbuf (host) */
    for (int q = 0; C > 1 && q < C; q++)
        memcpy(sbuf + (size_t)q * (b - a) * W, frame + ((size_t)q * H + a) * W,
               sizeof(float) * (size_t)(b - a) * W);
    lm_tensor *raw = lm_tensor_from(c, 4, (int[]){1, C, b - a, W},
                                    C == 1 ? frame + (size_t)a * W : sbuf);
    *y = raw ? lm_model_forward(c, m, raw) : NULL;
    if (*y && !lm_ctx_status(c)) *y = lm_contiguous(c, *y);
    char buf[64];
    if (*y && !lm_ctx_status(c) && ((*y)->ndim != 4 || (*y)->shape[1] != m->out_channels ||
                                    (*y)->shape[2] != b - a || (*y)->shape[3] != W))
        return lm_err_set(err, LM_ERR_SHAPE, "whole: model '%s' returned %s for a 1x1x%dx%d "
                          "strip", m->preset, lm_shape_str(*y, buf, sizeof buf), b - a, W);
    if (!lm_ctx_status(c) && *y) return LM_OK;
    lm_status s = lm_ctx_status(c) ? lm_ctx_status(c) : LM_ERR_ARG;
    lm_err_set(err, s, "%s", lm_ctx_status(c) ? lm_ctx_message(c) : "whole: model failed");
    lm_ctx_clear_error(c);
    return s;
}

lm_status lm_whole_forward(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                           const lm_whole_opts *o, int ch0, int nch, float *out, lm_err *err)
{
    lm_whole_opts d;
    if (!o) lm_whole_default_opts(&d), o = &d;
    lm_status st = whole_check(m, height, width, o, ch0, nch, err);
    if (st) return st;
    const int ty = m->mosaic.ty, halo = o->halo >= 0 ? o->halo : lm_whole_halo(m);
    int S = o->strip_rows > 0 ? o->strip_rows : LM_WHOLE_STRIP_ROWS;
    S = (S + ty - 1) / ty * ty;
    lm_infer_set_noise(m, frame, height, width);
    int grad = lm_ctx_set_grad(c, 0);
    if (m->frame_forward && m->in_channels == 1 && (!c->backend || c->backend == lm_backend_cpu())) {
        st = m->frame_forward(c, m, frame, height, width, ch0, nch, out, err);
        lm_ctx_set_grad(c, grad);
        return st;
    }
    float *buf = NULL; /* a device's strip, read back */
    size_t cap = 0;
    float *sbuf = NULL; /* two-bucket models: one strip of both planes */
    if (m->in_channels > 1 &&
        !(sbuf = malloc(sizeof(float) * m->in_channels * (size_t)(S + 2 * halo) * width))) {
        lm_ctx_set_grad(c, grad);
        return lm_err_set(err, LM_ERR_NOMEM, "whole: out of memory (strip)");
    }
    for (int y0 = 0; y0 < height && !st; y0 += S) {
        int y1 = y0 + S < height ? y0 + S : height;
        int a = y0 - halo > 0 ? y0 - halo : 0, b = y1 + halo < height ? y1 + halo : height;
        lm_tensor *y;
        st = strip_run(c, m, frame, height, width, a, b, sbuf, &y, err);
        if (!st) st = strip_store(c, y, a, y0, y1, ch0, nch, height, out, &buf, &cap, err);
        lm_ctx_reset(c);
    }
    free(buf);
    free(sbuf);
    lm_ctx_set_grad(c, grad);
    return st;
}

lm_status lm_whole_infer(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                         lm_cube *cube, lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    if (m->out_channels != LM_MODEL_OUT_CHANNELS)
        return lm_err_set(err, LM_ERR_ARG, "whole: model '%s' has %d output channels, expected "
                          "%d", m->preset, m->out_channels, LM_MODEL_OUT_CHANNELS);
    if (height <= 0 || width <= 0 || lm_cube_alloc(cube, 31, height, width, 400.0f, 10.0f))
        return lm_err_set(err, height <= 0 || width <= 0 ? LM_ERR_SHAPE : LM_ERR_NOMEM,
                          "whole: cannot allocate a 31x%dx%d cube", height, width);
    lm_status st = lm_whole_forward(c, m, frame, height, width, NULL, 1, 31, cube->data, err);
    if (st) lm_cube_free(cube);
    return st;
}
