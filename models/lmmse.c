/* lmmse.c — the closed-form linear floor (issue 13): per mosaic phase p (ty x tx phases), a
 * K x K window of the raw coded frame centred on the pixel, plus a bias, maps linearly to the
 * 33 output channels:
 *     y[c](Y, X) = sum_{u,v} W_l[p][c][u][v] raw(Y - r + u, X - r + v) + b_l[p][c],
 *     p = (Y mod ty) tx + (X mod tx), r = K / 2,
 * for a family of noise levels l (the input's Gaussian noise sd, absolute, in input units:
 * LM_LMMSE_SIGMAS); at a noise sd s between two levels the filters are interpolated linearly.
 * Fitted in closed form by train/fit_lmmse.c (normal equations + ridge), but also an ordinary
 * differentiable model built from existing ops, so Adam can fine-tune it:
 *   raw --pixel_unshuffle--> ty*tx phase planes, reflect-padded by whole tiles (phase kept)
 *       --conv (ty*tx -> 33*ty*tx, kernel kh x kw tiles)--> pixel_shuffle --> B x 33 x H x W,
 * where each phase's K x K filter is placed (zero-padded) into the tile-unit kernel by
 * pad2d + pixel_unshuffle of the parameter itself (so gradients reach the K x K weights).
 * Frame borders: the phase planes are reflected (PyTorch 'reflect' at tile resolution), so a
 * border pixel's window reads the same LED's samples mirrored; a finite receptive field of
 * r rows, so whole frames run in strips (infer/whole.h).
 * Noise level: the caller sets m->noise_sigma (or noise_sigma_items per batch item), as the
 * estimator of data/noise_est.h gives it; forward fails when neither is set.
 * What it is not: the fit (train/fit_lmmse.c) or the noise estimator. */
#include "models/model.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* up to 0.3: a frame at 20 % noise of a scene whose coded maximum is near 1 (eval's top
 * level) has sd 0.2, beyond the training range's 0.15 */
const float lm_lmmse_sigmas[LM_LMMSE_LEVELS] = {0.0f,  0.0025f, 0.005f, 0.01f, 0.02f, 0.035f,
                                                0.05f, 0.075f,  0.1f,   0.15f, 0.2f,  0.3f};

typedef struct lmmse_net {
    lm_tensor *w;              /* L x P x 33 x K x K */
    lm_tensor *b;              /* L x P x 33 */
    lm_conv feat;              /* D > 0: features 1 -> D, K x K (random at init) */
    lm_tensor *rw;             /* D > 0: readout L x P x 33 x D */
    int K, P, D;
    int lo_y, hi_y, lo_x, hi_x; /* tile offsets the windows reach (lo <= 0 <= hi) */
} lmmse_net;

static int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/* Level pair and weight for noise sd s: filter = (1 - t) level[i] + t level[i + 1]. */
static void level_pair(float s, int *i, float *t)
{
    const int L = LM_LMMSE_LEVELS;
    if (!(s > 0.0f)) { *i = 0; *t = 0.0f; return; }
    if (s >= lm_lmmse_sigmas[L - 1]) { *i = L - 2; *t = 1.0f; return; }
    int k = 0;
    while (k + 2 < L && s >= lm_lmmse_sigmas[k + 1]) k++;
    *i = k;
    *t = (s - lm_lmmse_sigmas[k]) / (lm_lmmse_sigmas[k + 1] - lm_lmmse_sigmas[k]);
}

/* Parameters of one level (or the blend of two) as views: w P x 33 x K x K, b P x 33. */
static void blend(lm_ctx *c, const lmmse_net *n, float s, lm_tensor **w, lm_tensor **b)
{
    int i;
    float t;
    level_pair(s, &i, &t);
    int ws[4] = {n->P, LM_MODEL_OUT_CHANNELS, n->K, n->K}, bs[2] = {n->P, LM_MODEL_OUT_CHANNELS};
    lm_tensor *w0 = lm_reshape(c, lm_slice(c, n->w, 0, i, 1), 4, ws);
    lm_tensor *b0 = lm_reshape(c, lm_slice(c, n->b, 0, i, 1), 2, bs);
    if (t == 0.0f) { *w = w0; *b = b0; return; }
    lm_tensor *w1 = lm_reshape(c, lm_slice(c, n->w, 0, i + 1, 1), 4, ws);
    lm_tensor *b1 = lm_reshape(c, lm_slice(c, n->b, 0, i + 1, 1), 2, bs);
    if (t == 1.0f) { *w = w1; *b = b1; return; }
    *w = lm_add(c, lm_affine(c, w0, 1.0f - t, 0.0f), lm_affine(c, w1, t, 0.0f));
    *b = lm_add(c, lm_affine(c, b0, 1.0f - t, 0.0f), lm_affine(c, b1, t, 0.0f));
}

/* The tile-unit conv weight (33 P) x P x kh x kw, output channel c P + p (pixel_shuffle order),
 * and bias (33 P), from per-phase K x K filters. */
static void tile_kernel(lm_ctx *c, const lm_model *m, const lmmse_net *n, lm_tensor *w,
                        lm_tensor *b, lm_tensor **cw, lm_tensor **cb)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, P = n->P, O = LM_MODEL_OUT_CHANNELS;
    const int kh = n->hi_y - n->lo_y + 1, kw = n->hi_x - n->lo_x + 1, r = n->K / 2;
    lm_tensor *parts[LM_MOSAIC_MAX_CH];
    int ps[4] = {O, 1, n->K, n->K};
    for (int p = 0; p < P; p++) {
        const int i = p / tx, j = p % tx;
        const int top = -r - ty * n->lo_y + i, left = -r - tx * n->lo_x + j;
        lm_tensor *wp = lm_reshape(c, lm_slice(c, w, 0, p, 1), 4, ps);
        wp = lm_pad2d(c, wp, top, ty * kh - n->K - top, left, tx * kw - n->K - left, LM_PAD_ZERO);
        parts[p] = lm_pixel_unshuffle(c, wp, ty, tx); /* O x P x kh x kw */
    }
    lm_tensor *all = lm_concat(c, parts, P, 0);        /* (P O) x P x kh x kw, row p O + c */
    int s3[3] = {P, O, P * kh * kw}, perm[3] = {1, 0, 2}, s4[4] = {O * P, P, kh, kw};
    *cw = lm_reshape(c, lm_permute(c, lm_reshape(c, all, 3, s3), perm), 4, s4);
    int s1[1] = {O * P};
    *cb = lm_reshape(c, lm_transpose(c, b, 0, 1), 1, s1);
}

/* The random-feature branch (D > 0) on the phase-padded raw frame rp (the padded phase planes
 * shuffled back): h = relu(features(window)) at every pixel, then per phase a readout D -> 33
 * (a grouped 1x1 conv at tile resolution), back to B x 33 x H x W. */
static lm_tensor *feature_branch(lm_ctx *c, const lm_model *m, const lmmse_net *n,
                                 lm_tensor *up, float s, int H, int W)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, P = n->P, D = n->D, O = LM_MODEL_OUT_CHANNELS;
    const int r = n->K / 2;
    lm_tensor *rp = lm_pixel_shuffle(c, up, ty, tx);
    lm_tensor *h = lm_relu(c, lm_conv_forward(c, &n->feat, rp)); /* (H + 2 pad - 2r) rows */
    h = lm_slice(c, lm_slice(c, h, 2, -ty * n->lo_y - r, H), 3, -tx * n->lo_x - r, W);
    lm_tensor *hu = lm_pixel_unshuffle(c, lm_contiguous(c, h), ty, tx); /* channel d P + p */
    if (!hu) return NULL;
    const int B = hu->shape[0], th = hu->shape[2], tw = hu->shape[3];
    int s5[5] = {B, D, P, th, tw}, pm[5] = {0, 2, 1, 3, 4}, s4[4] = {B, P * D, th, tw};
    hu = lm_reshape(c, lm_permute(c, lm_reshape(c, hu, 5, s5), pm), 4, s4); /* p D + d */
    int i;
    float t;
    level_pair(s, &i, &t);
    int rs[4] = {P * O, D, 1, 1};
    lm_tensor *rw = lm_reshape(c, lm_slice(c, n->rw, 0, i, 1), 4, rs);
    if (t > 0.0f) {
        lm_tensor *r1 = lm_reshape(c, lm_slice(c, n->rw, 0, i + 1, 1), 4, rs);
        rw = lm_add(c, lm_affine(c, rw, 1.0f - t, 0.0f), lm_affine(c, r1, t, 0.0f));
    }
    lm_conv ro = {.w = rw, .o = {1, 1, 0, 0, 1, 1, P}, .cin = P * D, .cout = P * O, .kh = 1,
                  .kw = 1}; /* through lm_conv_forward: profiles count it */
    if (rw) rw->name = "readout.weight";
    lm_tensor *y = lm_conv_forward(c, &ro, hu);                     /* channel p 33 + c */
    int y5[5] = {B, P, O, th, tw}, y4[4] = {B, O * P, th, tw};
    y = lm_reshape(c, lm_permute(c, lm_reshape(c, y, 5, y5), pm), 4, y4); /* c P + p */
    return lm_pixel_shuffle(c, y, ty, tx);
}

/* ---- inference without gradients: the filters applied directly ------------------------- */
/* The tile-unit conv above multiplies (kh ty) x (kw tx) taps per output (2-2.5x the K x K
 * window's, the rest zeros) and is what gradients flow through. When nothing needs a gradient
 * (inference; a frozen base under a training net) the K x K filters are applied directly: per
 * phase, the 33 outputs of a pixel accumulate in vector registers, two pixels of the phase at a
 * time, over the K x K window of a padded copy of the frame. Padding as the tile path's: the
 * phase planes reflected (a tile row / column mirrored about the edge tile; zeros when a plane
 * is smaller than the pad). Equal to the tile path up to float rounding (test_lmmse). */
#define OV 40 /* 33 outputs in 5 vectors of 8 */
typedef float v8 __attribute__((vector_size(32)));

static inline v8 v8_load(const float *p) { v8 v; memcpy(&v, p, sizeof v); return v; }

/* Raw row (or column) index that padded index y reads: phase planes mirrored, -1 = zero. */
static int pad_index(int y, int t, int n, int reflect)
{
    int q = floor_div(y, t), i = y - q * t, nt = n / t;
    if (q >= 0 && q < nt) return y;
    if (!reflect) return -1;
    q = q < 0 ? -q : 2 * (nt - 1) - q;
    return q * t + i;
}

/* out (33 x H x W) = the level-blended filters on one H x W frame. */
static void direct_frame(const lm_model *m, const lmmse_net *n, const float *wt, const float *raw,
                         int H, int W, float *pad, float *out, int nthreads)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, K = n->K, r = K / 2, O = LM_MODEL_OUT_CHANNELS;
    const int PW = W + 2 * r, PH = H + 2 * r;
    const int reflect = H / ty > n->hi_y && H / ty > -n->lo_y && W / tx > n->hi_x &&
                        W / tx > -n->lo_x;
    int lx[64], rx[64]; /* the r columns each side (K <= 31) */
    for (int x = 0; x < r; x++)
        lx[x] = pad_index(x - r, tx, W, reflect), rx[x] = pad_index(W + x, tx, W, reflect);
    for (int y = 0; y < PH; y++) {
        const int sy = pad_index(y - r, ty, H, reflect);
        float *d = pad + (size_t)y * PW;
        if (sy < 0) {
            memset(d, 0, sizeof(float) * (size_t)PW);
            continue;
        }
        const float *src = raw + (size_t)sy * W;
        memcpy(d + r, src, sizeof(float) * (size_t)W);
        for (int x = 0; x < r; x++) {
            d[x] = lx[x] < 0 ? 0.0f : src[lx[x]];
            d[r + W + x] = rx[x] < 0 ? 0.0f : src[rx[x]];
        }
    }
    const size_t plane = (size_t)H * W;
    #pragma omp parallel for schedule(static) num_threads(nthreads)
    for (int y = 0; y < H; y++) {
        const int i = y % ty;
        for (int j = 0; j < tx; j++) {
            const float *T = wt + (size_t)(i * tx + j) * (K * K + 1) * OV; /* taps, then bias */
            for (int x = j; x < W; x += 2 * tx) {
                const int two = x + tx < W, x1 = two ? x + tx : x; /* the last one alone */
                const float *B = T + K * K * OV;
                v8 a0 = v8_load(B), a1 = v8_load(B + 8), a2 = v8_load(B + 16);
                v8 a3 = v8_load(B + 24), a4 = v8_load(B + 32);
                v8 b0 = a0, b1 = a1, b2 = a2, b3 = a3, b4 = a4;
                for (int u = 0; u < K; u++) {
                    const float *p0 = pad + (size_t)(y + u) * PW + x;
                    const float *p1 = pad + (size_t)(y + u) * PW + x1;
                    const float *Tu = T + (size_t)u * K * OV;
                    for (int v = 0; v < K; v++, Tu += OV) {
                        const float s0 = p0[v], s1 = p1[v];
                        v8 t0 = v8_load(Tu), t1 = v8_load(Tu + 8), t2 = v8_load(Tu + 16);
                        v8 t3 = v8_load(Tu + 24), t4 = v8_load(Tu + 32);
                        a0 += s0 * t0, a1 += s0 * t1, a2 += s0 * t2, a3 += s0 * t3, a4 += s0 * t4;
                        b0 += s1 * t0, b1 += s1 * t1, b2 += s1 * t2, b3 += s1 * t3, b4 += s1 * t4;
                    }
                }
                float o0[OV], o1[OV];
                memcpy(o0, &a0, 32), memcpy(o0 + 8, &a1, 32), memcpy(o0 + 16, &a2, 32);
                memcpy(o0 + 24, &a3, 32), memcpy(o0 + 32, &a4, 32);
                memcpy(o1, &b0, 32), memcpy(o1 + 8, &b1, 32), memcpy(o1 + 16, &b2, 32);
                memcpy(o1 + 24, &b3, 32), memcpy(o1 + 32, &b4, 32);
                float *dst = out + (size_t)y * W + x;
                for (int ch = 0; ch < O; ch++) dst[ch * plane] = o0[ch];
                if (two)
                    for (int ch = 0; ch < O; ch++) dst[ch * plane + tx] = o1[ch];
            }
        }
    }
}

/* The fast path, or NULL when it does not apply (gradients needed, a device, features). */
static lm_tensor *run_direct(lm_ctx *c, lm_model *m, lmmse_net *n, lm_tensor *raw, float s)
{
    if (n->D || (c->grad_enabled && (lm_requires_grad(raw) || lm_requires_grad(n->w) ||
                                      lm_requires_grad(n->b))) ||
        (c->backend && c->backend != lm_backend_cpu()) || !raw->data || !n->w->data)
        return NULL;
    const int B = raw->shape[0], H = raw->shape[2], W = raw->shape[3], K = n->K, P = n->P;
    const int O = LM_MODEL_OUT_CHANNELS, r = K / 2;
    lm_tensor *x = lm_contiguous(c, raw);
    lm_tensor *y = x ? lm_tensor_new4(c, B, O, H, W) : NULL;
    float *wt = y ? lm_ctx_alloc(c, sizeof(float) * (size_t)P * (K * K + 1) * OV) : NULL;
    float *pad = wt ? lm_ctx_alloc(c, sizeof(float) * (size_t)(H + 2 * r) * (W + 2 * r)) : NULL;
    if (!pad) return NULL; /* the ctx has the error */
    int li;
    float t;
    level_pair(s, &li, &t);
    memset(wt, 0, sizeof(float) * (size_t)P * (K * K + 1) * OV);
    for (int p = 0; p < P; p++)
        for (int ch = 0; ch < O; ch++) {
            const size_t w0 = (((size_t)li * P + p) * O + ch) * K * K, w1 = w0 + (size_t)P * O * K * K;
            const size_t b0 = ((size_t)li * P + p) * O + ch, b1 = b0 + (size_t)P * O;
            float *T = wt + (size_t)p * (K * K + 1) * OV;
            for (int k = 0; k < K * K; k++)
                T[k * OV + ch] = t == 0.0f ? n->w->data[w0 + k] : t == 1.0f ? n->w->data[w1 + k]
                                 : n->w->data[w0 + k] * (1.0f - t) + n->w->data[w1 + k] * t;
            T[K * K * OV + ch] = t == 0.0f ? n->b->data[b0] : t == 1.0f ? n->b->data[b1]
                                 : n->b->data[b0] * (1.0f - t) + n->b->data[b1] * t;
        }
    for (int b = 0; b < B; b++)
        direct_frame(m, n, wt, x->data + (size_t)b * H * W, H, W, pad,
                     y->data + (size_t)b * O * H * W, lm_nthreads(c));
    return y;
}

/* Items [b0, b0 + nb) of raw with one noise level. */
static lm_tensor *run_group(lm_ctx *c, lm_model *m, lmmse_net *n, lm_tensor *raw, float s)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx;
    lm_tensor *d = run_direct(c, m, n, raw, s);
    if (d || lm_ctx_status(c)) return d;
    lm_tensor *w, *b, *cw, *cb;
    blend(c, n, s, &w, &b);
    tile_kernel(c, m, n, w, b, &cw, &cb);
    lm_tensor *u = lm_pixel_unshuffle(c, raw, ty, tx); /* B x P x h x w */
    if (!u) return NULL;
    const int h = u->shape[2], wd = u->shape[3];
    lm_pad_mode mode = (h > n->hi_y && h > -n->lo_y && wd > n->hi_x && wd > -n->lo_x)
                           ? LM_PAD_REFLECT : LM_PAD_ZERO; /* reflect needs pad < size */
    u = lm_pad2d(c, u, -n->lo_y, n->hi_y, -n->lo_x, n->hi_x, mode);
    lm_conv tk = {.w = cw, .b = cb, .cin = n->P, .kh = n->hi_y - n->lo_y + 1,
                  .kw = n->hi_x - n->lo_x + 1}; /* through lm_conv_forward: profiles count it */
    if (cw) cw->name = "filters.weight";
    lm_tensor *y = lm_pixel_shuffle(c, lm_conv_forward(c, &tk, u), ty, tx);
    if (n->D == 0) return y;
    return lm_add(c, y, feature_branch(c, m, n, u, s, raw->shape[2], raw->shape[3]));
}

static lm_tensor *lmmse_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    lmmse_net *n = m->impl;
    const float *sig = m->noise_sigma_items;
    if (!sig && !(m->noise_sigma >= 0.0f)) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: the input's noise level is not set (noise_sigma; the "
                    "caller estimates it, data/noise_est.h)", m->preset);
        return NULL;
    }
    const int B = raw->shape[0];
    if (!sig) return run_group(c, m, n, raw, m->noise_sigma);
    lm_tensor *outs[64];
    int nout = 0, b0 = 0;
    while (b0 < B) { /* runs of items with the same level share one conv */
        int b1 = b0 + 1;
        while (b1 < B && sig[b1] == sig[b0]) b1++;
        if (nout == 64) {
            lm_ctx_fail(c, LM_ERR_ARG, "%s: more than 64 distinct noise levels in a batch",
                        m->preset);
            return NULL;
        }
        outs[nout++] = run_group(c, m, n, lm_slice(c, raw, 0, b0, b1 - b0), sig[b0]);
        b0 = b1;
    }
    return nout == 1 ? outs[0] : lm_concat(c, outs, nout, 0);
}

/* Default initialisation: every level the same PyTorch-default conv init (fan_in K^2), so an
 * untrained lmmse behaves like a fresh K x K conv; the closed-form fit overwrites it. */
static void lmmse_init(lm_model *m, lm_rng *r)
{
    lmmse_net *n = m->impl;
    float bound = 1.0f / (float)n->K;
    lm_init_uniform(n->w, r, bound);
    lm_init_uniform(n->b, r, bound);
    if (n->D == 0) return;
    /* random features: N(0, 1/K^2) weights (unit gain on a window of comparable values),
     * N(0, 0.1^2) biases (a probe of linear vs random-feature ridge: +1.2 dB validation PSNR
     * clean with these); readout default-initialised */
    lm_init_normal(n->feat.w, r, 1.0f / (float)n->K);
    lm_init_normal(n->feat.b, r, 0.1f);
    lm_init_uniform(n->rw, r, 1.0f / sqrtf((float)n->D));
}

static void lmmse_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

lm_status lm_lmmse_build(lm_model *m, int K, int D, lm_err *err)
{
    lmmse_net *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = lmmse_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "lmmse: out of memory");
    if (K < 1 || K > 31 || K % 2 == 0)
        return lm_err_set(err, LM_ERR_ARG, "lmmse: window %d must be odd, 1..31", K);
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, r = K / 2;
    n->K = K;
    n->D = D;
    n->P = ty * tx;
    if (D < 0 || D > 4096) return lm_err_set(err, LM_ERR_ARG, "lmmse: %d features (0..4096)", D);
    if (n->P > LM_MOSAIC_MAX_CH)
        return lm_err_set(err, LM_ERR_ARG, "lmmse: %d x %d tile has too many phases", ty, tx);
    n->lo_y = floor_div(-r, ty);
    n->hi_y = floor_div(ty - 1 + r, ty);
    n->lo_x = floor_div(-r, tx);
    n->hi_x = floor_div(tx - 1 + r, tx);
    int ws[5] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS, K, K};
    int bs[3] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS};
    if (!(n->w = lm_params_add(&m->params, "filters.weight", 5, ws, 1, err)) ||
        !(n->b = lm_params_add(&m->params, "filters.bias", 3, bs, 1, err)))
        return err->status;
    int rws[4] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS, D};
    lm_conv_spec fs = {1, D, K, K, 1, 0, 0, 1, 1};
    if (D > 0 && (lm_conv_declare(&m->params, &n->feat, "features", fs, 1, err) ||
                  !(n->rw = lm_params_add(&m->params, "readout.weight", 4, rws, 1, err))))
        return err->status;
    m->forward = lmmse_forward;
    m->init = lmmse_init;
    m->conv_rows = ty * (n->hi_y > -n->lo_y ? n->hi_y : -n->lo_y);
    m->noise_input = 1;
    snprintf(m->family, sizeof m->family, "lmmse");
    return LM_OK;
}

int lm_lmmse_window(const lm_model *m)
{
    return m && m->forward == lmmse_forward ? ((const lmmse_net *)m->impl)->K : 0;
}

int lm_lmmse_features(const lm_model *m)
{
    return m && m->forward == lmmse_forward ? ((const lmmse_net *)m->impl)->D : 0;
}

lm_tensor *lm_lmmse_feature_maps(lm_ctx *c, const lm_model *m, lm_tensor *raw)
{
    const lmmse_net *n = lm_lmmse_features(m) ? m->impl : NULL;
    if (!n) {
        lm_ctx_fail(c, LM_ERR_ARG, "lmmse: model has no random features");
        return NULL;
    }
    lm_conv2d_opts o = {1, 1, n->K / 2, n->K / 2, 1, 1, 1};
    return lm_relu(c, lm_conv2d(c, raw, n->feat.w, n->feat.b, &o));
}

lm_status lm_lmmse_set_filter(lm_model *m, int level, int phase, const double *coef, lm_err *err)
{
    const int K = lm_lmmse_window(m);
    if (!K) return lm_err_set(err, LM_ERR_ARG, "lmmse: model %s is not an lmmse model",
                              m ? m->preset : "(null)");
    lmmse_net *n = m->impl;
    if (level < 0 || level >= LM_LMMSE_LEVELS || phase < 0 || phase >= n->P)
        return lm_err_set(err, LM_ERR_ARG, "lmmse: level %d / phase %d out of range", level,
                          phase);
    const int O = LM_MODEL_OUT_CHANNELS, F = K * K, D = n->D;
    float *w = n->w->data + ((size_t)level * n->P + phase) * O * F;
    float *b = n->b->data + ((size_t)level * n->P + phase) * O;
    float *rw = D ? n->rw->data + ((size_t)level * n->P + phase) * O * D : NULL;
    for (int c = 0; c < O; c++) {
        for (int f = 0; f < F; f++) w[(size_t)c * F + f] = (float)coef[(size_t)f * O + c];
        for (int d = 0; d < D; d++) rw[(size_t)c * D + d] = (float)coef[(size_t)(F + d) * O + c];
        b[c] = (float)coef[(size_t)(F + D) * O + c];
    }
    return LM_OK;
}
