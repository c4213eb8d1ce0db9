/* mcan.c — MCAN (Mosaic Convolution-Attention Network) in the 3x4 / 12-phase / 33-band
 * adaptation of models.md §3.2: frozen weighted-bilinear (WB) depthwise 5x7 interpolation of the
 * sparse cube plus a learnable 1x1 spectral lift; a mosaic convolution (MCM) whose 5x5 kernel
 * depends on each pixel's tile phase through a small MLP; mosaic attention (MA); two
 * conv-attention blocks; output = back conv + lifted WB. Names follow the official `Net`. */
#include "models/model.h"
#include "tensor/device.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct ma_layer { lm_linear_layer fc0, fc2; } ma_layer;
typedef struct ca_block { lm_conv c0, c2, c4; ma_layer ma; } ca_block;

typedef struct mcan {
    int P, ty, tx;                         /* phases (12), tile rows, cols */
    lm_tensor *wb;                         /* frozen P x 1 x (2ty-1) x (2tx-1) */
    lm_conv lift, front, back;
    lm_linear_layer p2w0, p2w2;            /* MCM MLP 2 -> 128 -> 25 P */
    ma_layer front_ma;
    ca_block blocks[2];
} mcan;

/* Mosaic attention: squeeze-excite per (channel, phase); the phase ops (tensor/ops/phase.c) do
 * what space-to-channel by the tile, pooling, scaling and channel-to-space did, in place. */
static lm_tensor *mosaic_attention(lm_ctx *c, const mcan *n, const ma_layer *ma, lm_tensor *x)
{
    if (!x) return NULL;
    lm_tensor *s = lm_phase_mean(c, x, n->ty, n->tx);
    if (!s) return NULL;
    s = lm_reshape(c, s, 2, (int[]){s->shape[0], s->shape[1]});
    s = lm_relu(c, lm_linear_forward(c, &ma->fc0, s));
    s = lm_sigmoid(c, lm_linear_forward(c, &ma->fc2, s));
    return lm_phase_scale(c, x, s, n->ty, n->tx);
}

/* A constant built on the host: moved to the ctx's device when the backend is not the CPU. */
static lm_tensor *host_const(lm_ctx *c, int ndim, const int *shape)
{
    lm_tensor *t = lm_tensor_new_on(c, LM_DEVICE_CPU, ndim, shape);
    if (t) lm_tensor_fill(t, 0.0f);
    return t;
}
static lm_tensor *to_ctx_device(lm_ctx *c, lm_tensor *t)
{
    return c->backend->device == LM_DEVICE_CPU ? t : lm_tensor_to_device(c, t);
}

/* Sparse cube: channel k keeps the raw value at its phase's pixels, 0 elsewhere. */
static lm_tensor *sparse_cube(lm_ctx *c, const lm_model *m, lm_tensor *raw)
{
    int H = raw->shape[2], W = raw->shape[3], P = m->mosaic.nch;
    lm_tensor *mask = host_const(c, 4, (int[]){1, P, H, W});
    if (!mask) return NULL;
    for (int k = 0; k < P; k++)
        for (int y = m->mosaic.phase_y[k]; y < H; y += m->mosaic.ty)
            for (int x = m->mosaic.phase_x[k]; x < W; x += m->mosaic.tx)
                mask->data[((size_t)k * H + y) * W + x] = 1.0f;
    return lm_mul(c, raw, to_ctx_device(c, mask));
}

/* MCM: per-phase 5x5 kernels from the MLP, applied to the 5x5 neighbourhood of each pixel. */
static lm_tensor *mosaic_conv(lm_ctx *c, const mcan *n, lm_tensor *raw)
{
    int B = raw->shape[0], H = raw->shape[2], W = raw->shape[3], P = n->P;
    int h = H / n->ty, w = W / n->tx;
    lm_tensor *pos = host_const(c, 2, (int[]){P, 2}), *eye = host_const(c, 4, (int[]){25, 1, 5, 5});
    if (!pos || !eye) return NULL;
    for (int q = 0; q < P; q++) { /* phase q = i*tx + j, pos = ((i+1)/ty, (j+1)/tx) */
        pos->data[2 * q] = (float)(q / n->tx + 1) / (float)n->ty;
        pos->data[2 * q + 1] = (float)(q % n->tx + 1) / (float)n->tx;
    }
    for (int k = 0; k < 25; k++) eye->data[k * 25 + k] = 1.0f;
    pos = to_ctx_device(c, pos);
    eye = to_ctx_device(c, eye);
    lm_tensor *kw = lm_linear_forward(c, &n->p2w2, lm_relu(c, lm_linear_forward(c, &n->p2w0, pos)));
    kw = lm_transpose(c, lm_reshape(c, kw, 3, (int[]){P, 25, P}), 1, 2); /* q x o x k */
    lm_conv2d_opts o = {1, 1, 2, 2, 1, 1, 1};
    lm_tensor *cols = lm_conv2d(c, raw, eye, NULL, &o);                  /* B x 25 x H x W */
    cols = lm_pixel_unshuffle(c, cols, n->ty, n->tx);                    /* B x 25P x h x w */
    cols = lm_reshape(c, cols, 4, (int[]){B, 25, P, h * w});
    cols = lm_reshape(c, lm_permute(c, cols, (int[]){2, 1, 0, 3}), 3, (int[]){P, 25, B * h * w});
    lm_tensor *out = lm_matmul(c, kw, cols, 0, 0);                       /* q x o x B h w */
    out = lm_permute(c, lm_reshape(c, out, 4, (int[]){P, P, B, h * w}), (int[]){2, 1, 0, 3});
    out = lm_reshape(c, out, 4, (int[]){B, P * P, h, w});                /* ch o*P + q */
    return lm_pixel_shuffle(c, out, n->ty, n->tx);
}

static lm_tensor *mcan_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    mcan *n = m->impl;
    lm_conv2d_opts wbo = {1, 1, n->ty - 1, n->tx - 1, 1, 1, n->P};
    lm_tensor *wb = lm_conv2d(c, sparse_cube(c, m, raw), n->wb, NULL, &wbo);
    lm_tensor *base = lm_conv_forward(c, &n->lift, wb);
    lm_tensor *f = lm_leaky_relu(c, mosaic_conv(c, n, raw), 0.2f);
    f = lm_leaky_relu(c, mosaic_attention(c, n, &n->front_ma, f), 0.2f);
    f = lm_conv_forward(c, &n->front, f);
    for (int b = 0; b < 2; b++) {
        const ca_block *k = &n->blocks[b];
        lm_scope sc = lm_scope_begin(c);
        lm_tensor *t = lm_leaky_relu(c, lm_conv_forward(c, &k->c0, f), 0.2f);
        t = lm_leaky_relu(c, lm_conv_forward(c, &k->c2, t), 0.2f);
        t = mosaic_attention(c, n, &k->ma, lm_conv_forward(c, &k->c4, t));
        f = lm_scope_end(c, sc, lm_leaky_relu(c, lm_add(c, t, f), 0.2f));
    }
    return lm_add(c, lm_conv_forward(c, &n->back, f), base);
}

/* Official init: conv weights N(0, sqrt(2 / (kh kw cout))), biases 0; linears PyTorch default;
 * WB fixed to outer(r, c) / P with r, c the triangle weights of the tile period. */
static void he_init(lm_conv *l, lm_rng *r)
{
    lm_init_normal(l->w, r, sqrtf(2.0f / (float)(l->kh * l->kw * l->cout)));
    if (l->b) lm_init_const(l->b, 0.0f);
}

static void mcan_init(lm_model *m, lm_rng *r)
{
    mcan *n = m->impl;
    int kh = 2 * n->ty - 1, kw = 2 * n->tx - 1;
    for (int q = 0; q < n->P; q++)
        for (int u = 0; u < kh; u++)
            for (int v = 0; v < kw; v++) {
                float ru = (float)(n->ty - abs(u - (n->ty - 1)));
                float cv = (float)(n->tx - abs(v - (n->tx - 1)));
                n->wb->data[(q * kh + u) * kw + v] = ru * cv / (float)(n->ty * n->tx);
            }
    he_init(&n->lift, r);
    lm_linear_init_default(&n->p2w0, r);
    lm_linear_init_default(&n->p2w2, r);
    lm_linear_init_default(&n->front_ma.fc0, r);
    lm_linear_init_default(&n->front_ma.fc2, r);
    he_init(&n->front, r);
    for (int b = 0; b < 2; b++) {
        he_init(&n->blocks[b].c0, r);
        he_init(&n->blocks[b].c2, r);
        he_init(&n->blocks[b].c4, r);
        lm_linear_init_default(&n->blocks[b].ma.fc0, r);
        lm_linear_init_default(&n->blocks[b].ma.fc2, r);
    }
    he_init(&n->back, r);
}

static void mcan_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

static lm_status declare_ma(lm_params *p, ma_layer *ma, const char *name, int cp, int red,
                            lm_err *e)
{
    char nm[LM_PARAM_NAME_MAX];
    snprintf(nm, sizeof nm, "%s.fc.0", name);
    if (lm_linear_declare(p, &ma->fc0, nm, cp, cp / red, 0, e)) return e->status;
    snprintf(nm, sizeof nm, "%s.fc.2", name);
    return lm_linear_declare(p, &ma->fc2, nm, cp / red, cp, 0, e);
}

lm_status lm_mcan_build(lm_model *m, int feats, lm_err *err)
{
    mcan *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = mcan_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "mcan: out of memory");
    n->ty = m->mosaic.ty, n->tx = m->mosaic.tx, n->P = m->mosaic.nch;
    if (n->P != n->ty * n->tx || (n->P * feats) % 4)
        return lm_err_set(err, LM_ERR_ARG, "mcan: needs one channel per tile phase (%d x %d "
                          "tile, %d channels)", n->ty, n->tx, n->P);
    lm_params *p = &m->params;
    int P = n->P, F = feats, O = m->out_channels;
    n->wb = lm_params_add(p, "WB_Conv.weight", 4, (int[]){P, 1, 2 * n->ty - 1, 2 * n->tx - 1}, 0, err);
    lm_conv_spec lift = {P, O, 1, 1, 1, 0, 0, 1, 1}, back = {F, O, 3, 3, 1, 1, 1, 1, 1};
    if (!n->wb || lm_conv_declare(p, &n->lift, "WB_lift", lift, 1, err) ||
        lm_linear_declare(p, &n->p2w0, "P2W.meta_block.0", 2, 128, 1, err) ||
        lm_linear_declare(p, &n->p2w2, "P2W.meta_block.2", 128, 25 * P, 1, err) ||
        declare_ma(p, &n->front_ma, "convt_br1_front.0.se", P * P, 4, err) ||
        lm_conv3_declare(p, &n->front, "front_conv_input", P, F, err))
        return err->status;
    for (int b = 0; b < 2; b++) {
        char nm[LM_PARAM_NAME_MAX];
        ca_block *k = &n->blocks[b];
        const char *blk = b ? "convt_F2.0" : "convt_F1.0";
        snprintf(nm, sizeof nm, "%s.cov_block.0", blk);
        if (lm_conv3_declare(p, &k->c0, nm, F, F, err)) return err->status;
        snprintf(nm, sizeof nm, "%s.cov_block.2", blk);
        if (lm_conv3_declare(p, &k->c2, nm, F, F, err)) return err->status;
        snprintf(nm, sizeof nm, "%s.cov_block.4", blk);
        if (lm_conv3_declare(p, &k->c4, nm, F, F, err)) return err->status;
        snprintf(nm, sizeof nm, "%s.ma", blk);
        if (declare_ma(p, &k->ma, nm, P * F, 4, err)) return err->status;
    }
    if (lm_conv_declare(p, &n->back, "convt_br1_back.0.cov_block.0", back, 1, err))
        return err->status;
    m->forward = mcan_forward;
    m->out_layers[0] = &n->back; /* output = back(features) + lift(white-balanced mosaic) */
    m->out_layers[1] = &n->lift;
    m->n_out_layers = 2;
    m->init = mcan_init;
    snprintf(m->family, sizeof m->family, "mcan");
    return LM_OK;
}
