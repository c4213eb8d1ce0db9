/* lmmse.c — the closed-form linear floor: per mosaic phase p (ty x tx phases), a
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
 * Both buckets (LM_CAP_TWO_BUCKETS, "lmmse-b2", "lmmse-K-b2"): the input is B x 2 x H x W
 * (bucket 1, bucket 0 / (LEDs - 1)) and each phase's window covers both planes: a second filter
 * bank "filters.bucket0" (L x P x 33 x K x K) on the bucket-0 plane, added before the bias
 *     y[c] = sum W_l[p][c] * window(bucket 1) + sum W0_l[p][c] * window(bucket 0) + b_l[p][c];
 * in the tile-unit conv the pixel-unshuffled input has 2P phase planes (bucket 1's first) and
 * the two kernels are concatenated along the input channels; the direct path (below) runs the
 * taps over both planes' windows. The whole-frame host path (frame_forward) reads one plane:
 * none for a two-bucket model (whole frames of it run patch-wise).
 * Panchromatic guide ("lmmse-guide-b2", G > 0): both buckets give a full-resolution
 * panchromatic image g = (bucket 1 + (P - 1) bucket 0 / (LEDs - 1)) / P (white = 1, P phases,
 * one LED each), and rho = bucket 1 / g, the pixel's share of its own light (its LED's
 * response over the mean response of all LEDs: 1 for white), which stays constant across a
 * shading or texture edge of one material where the raw samples jump. The model is lmmse-b2
 * plus a ratio term: D = G^2 + 1 fixed features g(p) rho(p + d) (d over a G x G window, phases
 * reflected at frame borders as the raw windows are) and g(p), read out per phase and level
 * like the random features:
 *     y[c](p) = lmmse-b2(p) + g(p) (sum_d R_l[ph][c][d] rho(p + d) + r_l[ph][c]),
 * i.e. a closed-form guided interpolation of each LED's share, multiplied back by the pixel's
 * panchromatic level: nonlinear in the frame, linear in its parameters, so fitted in closed
 * form as lmmse-rf is (noise sampled at six levels). The features are computed on the host
 * (on a device ctx too: the frames read back, the maps written to the device for the readout)
 * and hold no parameters. (The share against a 3 x 3 mean of g instead: 1.0 dB
 * lower validation PSNR clean, the same from noise sd 0.02 up; docs/results.md.)
 * Guided interpolation ("lmmse-gri-b2": K 11, N 15; "lmmse-K-riN-b2", odd N 3..31): lmmse-b2
 * plus D = P + 1 fixed features: for each LED l, its plane estimated at every pixel by a guided
 * filter on g. Every N x N window (radius R = N / 2) regresses LED l's samples s (bucket 1 at
 * its phase) on their g, a = cov(s, g) / (var(g) + 1e-4), b = mean s - a mean g; each pixel
 * averages the (a, b) of the windows covering it (as the guided filter does: smooth across
 * window edges) and gives a g(p) + b; the last feature is g(p). Box sums in double (running
 * sums), O(P H W) whatever N; frame borders padded by 2R with phases reflected by whole tiles,
 * so strips need 2R rows of context (conv_rows). The regularisation is a fixed constant in
 * white^2 units: the features do not depend on the noise level (the per-level readout adapts
 * to it). Read out per phase and level (the spectral map from the P interpolated LED values
 * and g), fitted in closed form as the guide is; host features, as the guide's.
 * What it is not: the fit (train/fit_lmmse.c) or the noise estimator. */
#include "models/model.h"
#include "models/lmmse_direct.h"
#include "tensor/device.h"
#include "tensor/isa.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* up to 0.3: a frame at 20 % noise of a scene whose coded maximum is near 1 (eval's top
 * level) has sd 0.2, beyond the training range's 0.15 */
const float lm_lmmse_sigmas[LM_LMMSE_LEVELS] = {0.0f,  0.0025f, 0.005f, 0.01f, 0.02f, 0.035f,
                                                0.05f, 0.075f,  0.1f,   0.15f, 0.2f,  0.3f};

/* The readout features (D > 0): random ReLU features of the raw window (a conv, parameters of
 * the model), or fixed features computed on the host from both buckets (no parameters). */
typedef enum lmmse_feat {
    LMMSE_FEAT_NONE,
    LMMSE_FEAT_RANDOM, /* lmmse-rf */
    LMMSE_FEAT_GUIDE,  /* lmmse-guide-b2: the share of the panchromatic image */
    LMMSE_FEAT_GRI     /* lmmse-gri-b2: each LED's plane interpolated guided by g */
} lmmse_feat;

typedef struct lmmse_net {
    lm_tensor *w;              /* L x P x 33 x K x K */
    lm_tensor *w0;             /* two buckets: the bucket-0 plane's filters, same shape */
    lm_tensor *b;              /* L x P x 33 */
    lm_conv feat;              /* D > 0: features 1 -> D, K x K (random at init) */
    lm_tensor *rw;             /* D > 0: readout L x P x 33 x D */
    int K, P, D, C;            /* C: input planes (1, or 2 = both buckets) */
    lmmse_feat kind;           /* what the D readout features are */
    int G;                     /* LMMSE_FEAT_GUIDE: the share's window (D = G^2 + 1) */
    int RI;                    /* LMMSE_FEAT_GRI: the interpolation window (D = P + 1) */
    int lo_y, hi_y, lo_x, hi_x; /* tile offsets the windows reach (lo <= 0 <= hi) */
    float sig[LM_LMMSE_LEVELS]; /* the levels' noise sd: lm_lmmse_sigmas unless a measurement
                                 * set others (lm_lmmse_set_sigmas) */
    int custom_sig;             /* 1: sig is not lm_lmmse_sigmas (no checkpoint holds it) */
    float *scratch;            /* whole-frame host path: packed filters and padded frame */
    size_t scratch_cap;        /* floats */
} lmmse_net;

static int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/* Level pair and weight for noise sd s: filter = (1 - t) level[i] + t level[i + 1]. */
static void level_pair(const float *sig, float s, int *i, float *t)
{
    const int L = LM_LMMSE_LEVELS;
    if (!(s > sig[0])) { *i = 0; *t = 0.0f; return; }
    if (s >= sig[L - 1]) { *i = L - 2; *t = 1.0f; return; }
    int k = 0;
    while (k + 2 < L && s >= sig[k + 1]) k++;
    *i = k;
    *t = (s - sig[k]) / (sig[k + 1] - sig[k]);
}

/* Parameters of one level (or the blend of two) as views: w P x 33 x K x K, b P x 33; *w0 the
 * bucket-0 filters (NULL with one plane). */
static void blend(lm_ctx *c, const lmmse_net *n, float s, lm_tensor **w, lm_tensor **b,
                  lm_tensor **wz)
{
    int i;
    float t;
    level_pair(n->sig, s, &i, &t);
    int ws[4] = {n->P, LM_MODEL_OUT_CHANNELS, n->K, n->K}, bs[2] = {n->P, LM_MODEL_OUT_CHANNELS};
    *wz = NULL;
    if (n->C == 2) {
        lm_tensor *v0 = lm_reshape(c, lm_slice(c, n->w0, 0, i, 1), 4, ws);
        lm_tensor *v1 = t == 0.0f ? NULL : lm_reshape(c, lm_slice(c, n->w0, 0, i + 1, 1), 4, ws);
        *wz = t == 0.0f ? v0 : t == 1.0f ? v1
              : lm_add(c, lm_affine(c, v0, 1.0f - t, 0.0f), lm_affine(c, v1, t, 0.0f));
    }
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

/* The per-phase, per-level readout D -> 33 of feature maps h (B x D x H x W): a grouped 1x1
 * conv at tile resolution, back to B x 33 x H x W. */
static lm_tensor *readout(lm_ctx *c, const lm_model *m, const lmmse_net *n, lm_tensor *h,
                          float s)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, P = n->P, D = n->D, O = LM_MODEL_OUT_CHANNELS;
    lm_tensor *hu = lm_pixel_unshuffle(c, lm_contiguous(c, h), ty, tx); /* channel d P + p */
    if (!hu) return NULL;
    const int B = hu->shape[0], th = hu->shape[2], tw = hu->shape[3];
    int s5[5] = {B, D, P, th, tw}, pm[5] = {0, 2, 1, 3, 4}, s4[4] = {B, P * D, th, tw};
    hu = lm_reshape(c, lm_permute(c, lm_reshape(c, hu, 5, s5), pm), 4, s4); /* p D + d */
    int i;
    float t;
    level_pair(n->sig, s, &i, &t);
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

/* The random-feature branch (D > 0) on the phase-padded raw frame rp (the padded phase planes
 * shuffled back): h = relu(features(window)) at every pixel, then the readout. */
static lm_tensor *feature_branch(lm_ctx *c, const lm_model *m, const lmmse_net *n,
                                 lm_tensor *up, float s, int H, int W)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, r = n->K / 2;
    lm_tensor *rp = lm_pixel_shuffle(c, up, ty, tx);
    lm_tensor *h = lm_relu(c, lm_conv_forward(c, &n->feat, rp)); /* (H + 2 pad - 2r) rows */
    h = lm_slice(c, lm_slice(c, h, 2, -ty * n->lo_y - r, H), 3, -tx * n->lo_x - r, W);
    return readout(c, m, n, h, s);
}

/* ---- inference without gradients: the filters applied directly ------------------------- */
/* The tile-unit conv above multiplies (kh ty) x (kw tx) taps per output (2-2.5x the K x K
 * window's, the rest zeros) and is what gradients flow through. When nothing needs a gradient
 * (inference; a frozen base under a training net) the K x K filters are applied directly over
 * the K x K window of a padded copy of the frame: per phase, the outputs of a pixel accumulate
 * in vector registers, several pixels of the phase at a time sharing each tap's weight loads.
 * Up to 32 channels (a whole-frame call for the 31 bands): two 16-lane vectors, 6 pixels;
 * 33 (a tensor forward): five 8-lane vectors, 2 pixels. Padding as the tile path's: the phase
 * planes reflected (a tile row / column mirrored about the edge tile; zeros when a plane is
 * smaller than the pad). Equal to the tile path up to float rounding (test_lmmse). */
/* Raw row (or column) index that padded index y reads: phase planes mirrored, -1 = zero. */
static int pad_index(int y, int t, int n, int reflect)
{
    int q = floor_div(y, t), i = y - q * t, nt = n / t;
    if (q >= 0 && q < nt) return y;
    if (!reflect) return -1;
    q = q < 0 ? -q : 2 * (nt - 1) - q;
    return q * t + i;
}

/* pad ((H + 2r) x (W + 2r)) = the frame with its phase planes reflected by r pixels. */
static void build_pad(const lm_model *m, const lmmse_net *n, const float *raw, int H, int W,
                      float *pad)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, r = n->K / 2, PW = W + 2 * r;
    const int reflect = H / ty > n->hi_y && H / ty > -n->lo_y && W / tx > n->hi_x &&
                        W / tx > -n->lo_x;
    int lx[64], rx[64]; /* the r columns each side (K <= 31) */
    for (int x = 0; x < r; x++)
        lx[x] = pad_index(x - r, tx, W, reflect), rx[x] = pad_index(W + x, tx, W, reflect);
    for (int y = 0; y < H + 2 * r; y++) {
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
}

/* ---- the panchromatic guide's features (G > 0) ------------------------------------------ */
/* The share rho is clamped to [-1, P] (P: a pixel holding all the light; noise around dark
 * pixels makes it wild) and its denominator held at GUIDE_EPS of white at least. */
#define GUIDE_EPS 0.01f

/* The D = G^2 + 1 feature planes of one frame (b1, b0: bucket 1 and bucket 0 / (LEDs - 1),
 * H x W each) into out (D x H x W); g (the panchromatic image), rho: H x W scratch each. */
static void guide_frame(const lm_model *m, const lmmse_net *n, const float *b1, const float *b0,
                        int H, int W, float *g, float *rho, float *out)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, P = n->P, G = n->G, gr = G / 2;
    const size_t plane = (size_t)H * W;
    for (size_t k = 0; k < plane; k++) g[k] = (b1[k] + (float)(P - 1) * b0[k]) / (float)P;
    for (size_t k = 0; k < plane; k++) {
        float r = b1[k] / (g[k] > GUIDE_EPS ? g[k] : GUIDE_EPS);
        rho[k] = r < -1.0f ? -1.0f : r > (float)P ? (float)P : r;
    }
    const int reflect = H / ty > (gr + ty - 1) / ty && W / tx > (gr + tx - 1) / tx;
    for (int u = 0; u < G; u++)
        for (int v = 0; v < G; v++) {
            float *o = out + (size_t)(u * G + v) * plane;
            for (int y = 0; y < H; y++) {
                const int sy = pad_index(y + u - gr, ty, H, reflect);
                for (int x = 0; x < W; x++) {
                    const int sx = pad_index(x + v - gr, tx, W, reflect);
                    const size_t k = (size_t)y * W + x;
                    o[k] = sy < 0 || sx < 0 ? 0.0f : g[k] * rho[(size_t)sy * W + sx];
                }
            }
        }
    memcpy(out + (size_t)(G * G) * plane, g, sizeof(float) * plane);
}

/* ---- guided-filter interpolation of each LED's plane (RI > 0) ----------------------------- */
/* The regularisation of the local regressions' slope, in white^2 units of g: a fixed constant
 * (the features do not depend on the noise level; the per-level readout adapts to it). */
#define GRI_EPS 1e-4

/* Box sums of radius r: in (h x w) -> out ((h - 2r) x (w - 2r)); running sums in double along
 * the rows into tmp ((h x (w - 2r)), then down the columns. */
static void box_sum(const double *in, int h, int w, int r, double *tmp, double *out)
{
    const int ow = w - 2 * r, oh = h - 2 * r;
    for (int y = 0; y < h; y++) {
        const double *s = in + (size_t)y * w;
        double *t = tmp + (size_t)y * ow, acc = 0;
        for (int x = 0; x <= 2 * r; x++) acc += s[x];
        t[0] = acc;
        for (int x = 1; x < ow; x++) t[x] = acc += s[x + 2 * r] - s[x - 1];
    }
    memset(out, 0, sizeof(double) * (size_t)ow);
    for (int y = 0; y <= 2 * r; y++)
        for (int x = 0; x < ow; x++) out[x] += tmp[(size_t)y * ow + x];
    for (int y = 1; y < oh; y++) {
        const double *add = tmp + (size_t)(y + 2 * r) * ow, *sub = tmp + (size_t)(y - 1) * ow;
        double *o = out + (size_t)y * ow, *prev = o - ow;
        for (int x = 0; x < ow; x++) o[x] = prev[x] + add[x] - sub[x];
    }
}

/* Scratch doubles of gri_frame for an H x W frame (window radius R: the frame padded by 2R). */
static size_t gri_scratch(int H, int W, int R)
{
    const size_t PH = (size_t)H + 4 * R, PW = (size_t)W + 4 * R, CW = (size_t)W + 2 * R;
    return PH * PW + PH * CW + 5 * (H + 2 * (size_t)R) * CW + 2 * (size_t)H * W + PH + PW;
}

/* LED l's guided-filter plane of one frame (b1: bucket 1, g: panchromatic, H x W) into o. On
 * the frame padded by 2R (phases reflected by whole tiles; zero weight where a plane is too
 * small to reflect), every window of radius R regresses LED l's samples s on their g,
 * s ~ a g + b; each pixel averages the (a, b) of the (2R + 1)^2 windows covering it and gives
 * a(p) g(p) + b(p). iy / ix: the padded rows' / columns' frame index (-1: none). */
static void gri_plane(const lm_model *m, int R, int l, const float *b1, const float *g, int H,
                      int W, const int *iy, const int *ix, double *sc, float *o)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, PH = H + 4 * R, PW = W + 4 * R;
    const int CH = H + 2 * R, CW = W + 2 * R, pi = l / tx, pj = l % tx;
    const size_t cn = (size_t)CH * CW;
    double *pad = sc, *tmp = pad + (size_t)PH * PW, *sum = tmp + (size_t)PH * CW;
    double *ab = sum + 5 * cn; /* a, b averaged: 2 x H x W */
    for (int q = 0; q < 5; q++) { /* n, s, g, g g, s g over each window */
        memset(pad, 0, sizeof(double) * (size_t)PH * PW);
        for (int y = (pi + 2 * R) % ty; y < PH; y += ty) {
            if (iy[y] < 0) continue;
            for (int x = (pj + 2 * R) % tx; x < PW; x += tx) {
                if (ix[x] < 0) continue;
                const size_t k = (size_t)iy[y] * W + ix[x];
                const double sv = b1[k], gv = g[k];
                pad[(size_t)y * PW + x] = q == 0 ? 1 : q == 1 ? sv : q == 2 ? gv
                                          : q == 3 ? gv * gv : sv * gv;
            }
        }
        box_sum(pad, PH, PW, R, tmp, sum + q * cn);
    }
    for (size_t k = 0; k < cn; k++) { /* the regression of each window, a and b in place */
        const double n = sum[k];
        double a = 0, b = 0;
        if (n > 0) {
            const double ms = sum[cn + k] / n, mg = sum[2 * cn + k] / n;
            const double vg = sum[3 * cn + k] / n - mg * mg, cv = sum[4 * cn + k] / n - ms * mg;
            a = cv / ((vg > 0 ? vg : 0) + GRI_EPS);
            b = ms - a * mg;
        }
        sum[k] = a, sum[cn + k] = b;
    }
    const double inv = 1.0 / ((2.0 * R + 1) * (2.0 * R + 1));
    box_sum(sum, CH, CW, R, tmp, ab);
    box_sum(sum + cn, CH, CW, R, tmp, ab + (size_t)H * W);
    for (size_t k = 0; k < (size_t)H * W; k++)
        o[k] = (float)(inv * (ab[k] * g[k] + ab[(size_t)H * W + k]));
}

/* The D = P + 1 feature planes of one frame (b1, b0: bucket 1 and bucket 0 / (LEDs - 1)) into
 * out (D x H x W): LED l's guided-filter plane for l = 0..P-1 (tile position order), then g. */
static void gri_frame(const lm_model *m, const lmmse_net *n, const float *b1, const float *b0,
                      int H, int W, double *sc, float *out)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, P = n->P, R = n->RI / 2;
    const int PH = H + 4 * R, PW = W + 4 * R;
    const size_t plane = (size_t)H * W;
    float *g = out + (size_t)P * plane;
    for (size_t k = 0; k < plane; k++) g[k] = (b1[k] + (float)(P - 1) * b0[k]) / (float)P;
    const int reflect = H / ty > (2 * R + ty - 1) / ty && W / tx > (2 * R + tx - 1) / tx;
    int *iy = (int *)(sc + gri_scratch(H, W, R) - PH - PW), *ix = iy + PH;
    for (int y = 0; y < PH; y++) iy[y] = pad_index(y - 2 * R, ty, H, reflect);
    for (int x = 0; x < PW; x++) ix[x] = pad_index(x - 2 * R, tx, W, reflect);
    for (int l = 0; l < P; l++) gri_plane(m, R, l, b1, g, H, W, iy, ix, sc, out + l * plane);
}

/* The host features' maps of raw (B x 2 x H x W): B x D x H x W, no gradient; the guide's
 * (guide_frame) or the guided interpolation's (gri_frame), frame by frame, on the host. On a
 * device ctx the frames are read to the host and the maps written back to the device (the
 * readout and everything after it run there). */
static lm_tensor *host_maps(lm_ctx *c, const lm_model *m, const lmmse_net *n, lm_tensor *raw)
{
    const int gri = n->kind == LMMSE_FEAT_GRI;
    const char *what = gri ? "the guided interpolation" : "the panchromatic guide";
    const int dev = raw && raw->device != LM_DEVICE_CPU;
    if (!raw || raw->ndim != 4 || raw->shape[1] != 2) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: %s needs both buckets (B x 2 x H x W)", m->preset,
                    what);
        return NULL;
    }
    const int B = raw->shape[0], H = raw->shape[2], W = raw->shape[3];
    const size_t plane = (size_t)H * W;
    const size_t bytes = gri ? sizeof(double) * gri_scratch(H, W, n->RI / 2)
                             : sizeof(float) * 2 * plane;
    lm_tensor *x = dev ? lm_tensor_to_host(c, raw) : lm_contiguous(c, raw);
    const int shape[4] = {B, n->D, H, W};
    lm_tensor *h = x ? lm_tensor_new_on(c, LM_DEVICE_CPU, 4, shape) : NULL;
    void *sc = h ? lm_ctx_alloc(c, bytes) : NULL;
    if (!sc) return NULL; /* the ctx has the error */
    for (int b = 0; b < B; b++) {
        const float *in = x->data + (size_t)b * 2 * plane;
        float *out = h->data + (size_t)b * n->D * plane;
        if (gri) gri_frame(m, n, in, in + plane, H, W, sc, out);
        else guide_frame(m, n, in, in + plane, H, W, sc, (float *)sc + plane, out);
    }
    return dev ? lm_tensor_to_device(c, h) : h;
}

/* Packed filters of one phase: K x K taps of `lanes` floats (channels, zero beyond nch) for
 * each of the C input planes (bucket 1's, then bucket 0's), then the bias. */
static size_t packed_floats(int C, int K, int lanes) { return (size_t)(C * K * K + 1) * lanes; }

/* wt = the filters of channels [ch0, ch0 + nch) at noise sd s, every phase, `lanes` wide. */
static void pack_filters(const lmmse_net *n, float s, int ch0, int nch, int lanes, float *wt)
{
    const int O = LM_MODEL_OUT_CHANNELS, K = n->K, P = n->P, C = n->C;
    int li;
    float t;
    level_pair(n->sig, s, &li, &t);
    memset(wt, 0, sizeof(float) * (size_t)P * packed_floats(C, K, lanes));
    for (int p = 0; p < P; p++)
        for (int c = 0; c < nch; c++) {
            const int ch = ch0 + c;
            const size_t w0 = (((size_t)li * P + p) * O + ch) * K * K, w1 = w0 + (size_t)P * O * K * K;
            const size_t b0 = ((size_t)li * P + p) * O + ch, b1 = b0 + (size_t)P * O;
            float *T = wt + (size_t)p * packed_floats(C, K, lanes);
            for (int q = 0; q < C; q++) {
                const float *w = q ? n->w0->data : n->w->data;
                float *Tq = T + (size_t)q * K * K * lanes;
                for (int k = 0; k < K * K; k++)
                    Tq[k * lanes + c] = t == 0.0f ? w[w0 + k] : t == 1.0f ? w[w1 + k]
                                        : w[w0 + k] * (1.0f - t) + w[w1 + k] * t;
            }
            T[C * K * K * lanes + c] = t == 0.0f ? n->b->data[b0] : t == 1.0f ? n->b->data[b1]
                                   : n->b->data[b0] * (1.0f - t) + n->b->data[b1] * t;
        }
}

/* The loops of lmmse_direct.c, built once per instruction set (cmake/isa.cmake): the variant
 * of the active level (tensor/isa.h). */
#define LM_LMMSE_ROWS_ARGS                                                                    \
    (const float *wt, size_t packed, const float *pad, int PW, int PH, int C, int K, int ty,  \
     int tx, int H, int W, float *out, int nch, int lanes, int nthreads)
void lm_lmmse_direct_rows_generic LM_LMMSE_ROWS_ARGS;
#ifdef LM_ISA_X86_VARIANTS
void lm_lmmse_direct_rows_avx2 LM_LMMSE_ROWS_ARGS;
void lm_lmmse_direct_rows_avx512 LM_LMMSE_ROWS_ARGS;
#endif

void lm_lmmse_direct_rows(const float *wt, size_t packed, const float *pad, int PW, int PH, int C,
                          int K, int ty, int tx, int H, int W, float *out, int nch, int lanes,
                          int nthreads)
{
#ifdef LM_ISA_X86_VARIANTS
    lm_isa a = lm_isa_active();
    if (a >= LM_ISA_AVX512)
        lm_lmmse_direct_rows_avx512(wt, packed, pad, PW, PH, C, K, ty, tx, H, W, out, nch, lanes,
                                    nthreads);
    else if (a == LM_ISA_AVX2)
        lm_lmmse_direct_rows_avx2(wt, packed, pad, PW, PH, C, K, ty, tx, H, W, out, nch, lanes,
                                  nthreads);
    else
#endif
        lm_lmmse_direct_rows_generic(wt, packed, pad, PW, PH, C, K, ty, tx, H, W, out, nch,
                                     lanes, nthreads);
}

/* out (nch planes of H x W) = channels [ch0, ch0 + nch) of the filters at noise sd s on one
 * frame of C planes (C x H x W: bucket 1, then bucket 0 with two buckets). scratch:
 * direct_scratch_floats(...) floats. */
static size_t direct_scratch_floats(const lmmse_net *n, int H, int W)
{
    const int r = n->K / 2;
    return (size_t)n->P * packed_floats(n->C, n->K, 40) +
           (size_t)n->C * (H + 2 * r) * (W + 2 * r);
}

static void direct_frame(const lm_model *m, const lmmse_net *n, float s, const float *raw, int H,
                         int W, int ch0, int nch, float *out, float *scratch, int nthreads)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx, K = n->K, C = n->C;
    const int PW = W + 2 * (K / 2), PH = H + 2 * (K / 2);
    const int lanes = nch <= 32 ? 32 : 40;
    float *wt = scratch, *pad = scratch + (size_t)n->P * packed_floats(C, K, 40);
    pack_filters(n, s, ch0, nch, lanes, wt);
    for (int q = 0; q < C; q++)
        build_pad(m, n, raw + (size_t)q * H * W, H, W, pad + (size_t)q * PH * PW);
    lm_lmmse_direct_rows(wt, packed_floats(C, K, lanes), pad, PW, PH, C, K, ty, tx, H, W, out,
                         nch, lanes, nthreads);
}

/* Can the direct path run? (no gradients needed, no device, no features, host parameters) */
static int direct_ok(const lm_ctx *c, const lmmse_net *n, const lm_tensor *raw)
{
    return (!n->D || n->kind != LMMSE_FEAT_RANDOM) &&
           !(c->grad_enabled && ((raw && lm_requires_grad(raw)) || lm_requires_grad(n->w) ||
                                 lm_requires_grad(n->b) || (n->w0 && lm_requires_grad(n->w0)))) &&
           !(c->backend && c->backend != lm_backend_cpu()) && (!raw || raw->data) && n->w->data;
}

/* The fast path, or NULL when it does not apply (gradients needed, a device, random
 * features); with the guide, its linear part only. */
static lm_tensor *run_direct(lm_ctx *c, lm_model *m, lmmse_net *n, lm_tensor *raw, float s)
{
    if (!direct_ok(c, n, raw)) return NULL;
    const int B = raw->shape[0], H = raw->shape[2], W = raw->shape[3];
    const int O = LM_MODEL_OUT_CHANNELS;
    lm_tensor *x = lm_contiguous(c, raw);
    lm_tensor *y = x ? lm_tensor_new4(c, B, O, H, W) : NULL;
    float *scratch = y ? lm_ctx_alloc(c, sizeof(float) * direct_scratch_floats(n, H, W)) : NULL;
    if (!scratch) return NULL; /* the ctx has the error */
    for (int b = 0; b < B; b++)
        direct_frame(m, n, s, x->data + (size_t)b * n->C * H * W, H, W, 0, O,
                     y->data + (size_t)b * O * H * W, scratch, lm_nthreads(c));
    return y;
}

/* Whole-frame host path (lm_model.frame_forward): no tensors, no strips. */
static lm_status lmmse_frame_forward(lm_ctx *c, lm_model *m, const float *frame, int H, int W,
                                     int ch0, int nch, float *out, lm_err *err)
{
    lmmse_net *n = m->impl;
    if (!direct_ok(c, n, NULL))
        return lm_err_set(err, LM_ERR_ARG, "%s: the whole-frame host path needs host "
                          "parameters, no features and no gradients", m->preset);
    if (!(m->noise_sigma >= 0.0f))
        return lm_err_set(err, LM_ERR_ARG, "%s: the input's noise level is not set", m->preset);
    if (ch0 < 0 || nch < 1 || ch0 + nch > LM_MODEL_OUT_CHANNELS)
        return lm_err_set(err, LM_ERR_ARG, "%s: channels [%d, %d) outside [0, %d)", m->preset,
                          ch0, ch0 + nch, LM_MODEL_OUT_CHANNELS);
    const size_t need = direct_scratch_floats(n, H, W);
    if (need > n->scratch_cap) {
        float *p = realloc(n->scratch, need * sizeof *p);
        if (!p) return lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory (%zu floats)",
                                  m->preset, need);
        n->scratch = p, n->scratch_cap = need;
    }
    direct_frame(m, n, m->noise_sigma, frame, H, W, ch0, nch, out, n->scratch, lm_nthreads(c));
    return LM_OK;
}

/* Items [b0, b0 + nb) of raw with one noise level. */
static lm_tensor *run_group(lm_ctx *c, lm_model *m, lmmse_net *n, lm_tensor *raw, float s)
{
    const int ty = m->mosaic.ty, tx = m->mosaic.tx;
    lm_tensor *d = run_direct(c, m, n, raw, s);
    const int host = n->kind == LMMSE_FEAT_GUIDE || n->kind == LMMSE_FEAT_GRI;
    if (d && host) return lm_add(c, d, readout(c, m, n, host_maps(c, m, n, raw), s));
    if (d || lm_ctx_status(c)) return d;
    lm_tensor *w, *b, *w0, *cw, *cb;
    blend(c, n, s, &w, &b, &w0);
    tile_kernel(c, m, n, w, b, &cw, &cb);
    if (w0) { /* the bucket-0 plane's kernel: input channels P..2P-1 of the unshuffled raw */
        lm_tensor *cw0, *cb0, *ks[2];
        tile_kernel(c, m, n, w0, b, &cw0, &cb0);
        ks[0] = cw, ks[1] = cw0;
        cw = lm_concat(c, ks, 2, 1);
    }
    lm_tensor *u = lm_pixel_unshuffle(c, raw, ty, tx); /* B x C P x h x w, plane-major */
    if (!u) return NULL;
    const int h = u->shape[2], wd = u->shape[3];
    lm_pad_mode mode = (h > n->hi_y && h > -n->lo_y && wd > n->hi_x && wd > -n->lo_x)
                           ? LM_PAD_REFLECT : LM_PAD_ZERO; /* reflect needs pad < size */
    u = lm_pad2d(c, u, -n->lo_y, n->hi_y, -n->lo_x, n->hi_x, mode);
    lm_conv tk = {.w = cw, .b = cb, .cin = n->C * n->P, .kh = n->hi_y - n->lo_y + 1,
                  .kw = n->hi_x - n->lo_x + 1}; /* through lm_conv_forward: profiles count it */
    if (cw) cw->name = "filters.weight";
    lm_tensor *y = lm_pixel_shuffle(c, lm_conv_forward(c, &tk, u), ty, tx);
    if (n->D == 0) return y;
    if (host) return lm_add(c, y, readout(c, m, n, host_maps(c, m, n, raw), s));
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
    if (n->C == 2) lm_init_uniform(n->w0, r, bound);
    if (n->D == 0) return;
    if (n->kind != LMMSE_FEAT_RANDOM) {
        lm_init_uniform(n->rw, r, 1.0f / sqrtf((float)n->D));
        return;
    }
    /* random features: N(0, 1/K^2) weights (unit gain on a window of comparable values),
     * N(0, 0.1^2) biases (a probe of linear vs random-feature ridge: +1.2 dB validation PSNR
     * clean with these); readout default-initialised */
    lm_init_normal(n->feat.w, r, 1.0f / (float)n->K);
    lm_init_normal(n->feat.b, r, 0.1f);
    lm_init_uniform(n->rw, r, 1.0f / sqrtf((float)n->D));
}

static void lmmse_free(lm_model *m)
{
    if (m->impl) free(((lmmse_net *)m->impl)->scratch);
    free(m->impl);
    m->impl = NULL;
}

/* The host features' kind and window (win: G for the guide, RI for the interpolation). */
static lm_status build_features(lmmse_net *n, lmmse_feat kind, int win, lm_err *err)
{
    n->kind = kind;
    if (kind == LMMSE_FEAT_GUIDE) {
        if (n->C != 2 || win < 1 || win % 2 == 0 || win > n->K)
            return lm_err_set(err, LM_ERR_ARG, "lmmse: the panchromatic guide reads both "
                              "buckets, with an odd window of at most K = %d (got %d)", n->K, win);
        n->G = win;
        n->D = win * win + 1;
    } else if (kind == LMMSE_FEAT_GRI) {
        if (n->C != 2 || win < LM_LMMSE_GRI_MIN || win > LM_LMMSE_GRI_MAX || win % 2 == 0)
            return lm_err_set(err, LM_ERR_ARG, "lmmse: the guided interpolation reads both "
                              "buckets, with an odd window of %d..%d (got %d)", LM_LMMSE_GRI_MIN,
                              LM_LMMSE_GRI_MAX, win);
        n->RI = win;
        n->D = n->P + 1;
    } else if (n->D > 0) {
        n->kind = LMMSE_FEAT_RANDOM;
        if (n->C == 2)
            return lm_err_set(err, LM_ERR_ARG, "lmmse: random features read one plane: no "
                              "two-bucket lmmse-rf");
    }
    return LM_OK;
}

static lm_status build(lm_model *m, int K, int D, lmmse_feat kind, int win, lm_err *err)
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
    memcpy(n->sig, lm_lmmse_sigmas, sizeof n->sig);
    n->C = m->in_channels == 2 ? 2 : 1;
    if (n->P > LM_MOSAIC_MAX_CH)
        return lm_err_set(err, LM_ERR_ARG, "lmmse: %d x %d tile has too many phases", ty, tx);
    if (build_features(n, kind, win, err)) return err->status;
    D = n->D;
    if (D < 0 || D > 4096) return lm_err_set(err, LM_ERR_ARG, "lmmse: %d features (0..4096)", D);
    n->lo_y = floor_div(-r, ty);
    n->hi_y = floor_div(ty - 1 + r, ty);
    n->lo_x = floor_div(-r, tx);
    n->hi_x = floor_div(tx - 1 + r, tx);
    int ws[5] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS, K, K};
    int bs[3] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS};
    if (!(n->w = lm_params_add(&m->params, "filters.weight", 5, ws, 1, err)) ||
        !(n->b = lm_params_add(&m->params, "filters.bias", 3, bs, 1, err)) ||
        (n->C == 2 && !(n->w0 = lm_params_add(&m->params, "filters.bucket0", 5, ws, 1, err))))
        return err->status;
    int rws[4] = {LM_LMMSE_LEVELS, n->P, LM_MODEL_OUT_CHANNELS, D};
    lm_conv_spec fs = {1, D, K, K, 1, 0, 0, 1, 1};
    if (D > 0 && ((n->kind == LMMSE_FEAT_RANDOM &&
                   lm_conv_declare(&m->params, &n->feat, "features", fs, 1, err)) ||
                  !(n->rw = lm_params_add(&m->params, "readout.weight", 4, rws, 1, err))))
        return err->status;
    m->forward = lmmse_forward;
    /* the whole-frame host path reads one H x W frame: one-bucket models only */
    m->frame_forward = D || n->C == 2 ? NULL : lmmse_frame_forward;
    m->init = lmmse_init;
    m->conv_rows = ty * (n->hi_y > -n->lo_y ? n->hi_y : -n->lo_y);
    if (n->RI && m->conv_rows < 2 * (n->RI / 2)) /* windows of windows: 2R rows each side */
        m->conv_rows = 2 * (n->RI / 2);
    m->noise_input = 1;
    snprintf(m->family, sizeof m->family, "lmmse");
    return LM_OK;
}

lm_status lm_lmmse_build(lm_model *m, int K, int D, lm_err *err)
{
    return build(m, K, D, LMMSE_FEAT_NONE, 0, err);
}

lm_status lm_lmmse_guide_build(lm_model *m, int K, int G, lm_err *err)
{
    return build(m, K, 0, LMMSE_FEAT_GUIDE, G, err);
}

lm_status lm_lmmse_gri_build(lm_model *m, int K, int RI, lm_err *err)
{
    return build(m, K, 0, LMMSE_FEAT_GRI, RI, err);
}

int lm_lmmse_guide(const lm_model *m)
{
    return lm_lmmse_window(m) ? ((const lmmse_net *)m->impl)->G : 0;
}

int lm_lmmse_gri(const lm_model *m)
{
    return lm_lmmse_window(m) ? ((const lmmse_net *)m->impl)->RI : 0;
}

int lm_lmmse_window(const lm_model *m)
{
    return m && m->forward == lmmse_forward ? ((const lmmse_net *)m->impl)->K : 0;
}

const float *lm_lmmse_levels(const lm_model *m)
{
    return lm_lmmse_window(m) ? ((const lmmse_net *)m->impl)->sig : lm_lmmse_sigmas;
}

int lm_lmmse_custom_levels(const lm_model *m)
{
    return lm_lmmse_window(m) ? ((const lmmse_net *)m->impl)->custom_sig : 0;
}

lm_status lm_lmmse_set_levels(lm_model *m, const float *sig, lm_err *err)
{
    if (!lm_lmmse_window(m))
        return lm_err_set(err, LM_ERR_ARG, "lmmse: model %s is not an lmmse model",
                          m ? m->preset : "(null)");
    if (!sig || sig[0] != 0.0f)
        return lm_err_set(err, LM_ERR_ARG, "lmmse: the first noise level must be 0");
    for (int l = 1; l < LM_LMMSE_LEVELS; l++)
        if (!(sig[l] > sig[l - 1]) || !isfinite(sig[l]))
            return lm_err_set(err, LM_ERR_ARG, "lmmse: noise levels must be finite and strictly "
                              "increasing (level %d: %g after %g)", l, (double)sig[l],
                              (double)sig[l - 1]);
    lmmse_net *n = m->impl;
    memcpy(n->sig, sig, sizeof n->sig);
    n->custom_sig = memcmp(sig, lm_lmmse_sigmas, sizeof n->sig) != 0;
    return LM_OK;
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
    if (n->kind != LMMSE_FEAT_RANDOM) return host_maps(c, m, n, raw);
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
    const int O = LM_MODEL_OUT_CHANNELS, F = K * K, D = n->D, C = n->C;
    float *w = n->w->data + ((size_t)level * n->P + phase) * O * F;
    float *w0 = C == 2 ? n->w0->data + ((size_t)level * n->P + phase) * O * F : NULL;
    float *b = n->b->data + ((size_t)level * n->P + phase) * O;
    float *rw = D ? n->rw->data + ((size_t)level * n->P + phase) * O * D : NULL;
    for (int c = 0; c < O; c++) {
        for (int f = 0; f < F; f++) w[(size_t)c * F + f] = (float)coef[(size_t)f * O + c];
        for (int f = 0; w0 && f < F; f++)
            w0[(size_t)c * F + f] = (float)coef[(size_t)(F + f) * O + c];
        for (int d = 0; d < D; d++)
            rw[(size_t)c * D + d] = (float)coef[(size_t)(C * F + d) * O + c];
        b[c] = (float)coef[(size_t)(C * F + D) * O + c];
    }
    return LM_OK;
}
