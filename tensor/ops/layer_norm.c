/* layer_norm.c — layer normalisation over the channels of each pixel of B x C x H x W:
 * y = (x - mean) * rstd * w + b, rstd = 1 / sqrt(var + eps), biased variance; w, b of shape C
 * or NULL. The forward saves mean and rstd (B x 2 x H x W: mean plane, rstd plane) for the
 * backward. Kernels work on blocks of pixels, looping channels outside so the inner loops run
 * over contiguous pixels. dw/db reduce each channel over B x H x W in one job per channel
 * (fixed order, double accumulation), so gradients do not depend on the thread count.
 * What it is not: LayerNorm over the last dim (use a permute first), nor batch/group norm. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <math.h>

enum { LN_BLOCK = 64 };

/* forward: t[0] = x, t[1] = y (B x C x H x W), t[2] = stats (B x 2 x H x W), t[3] = w or NULL,
 * t[4] = b or NULL (C); y =, stats = */
static int ln_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_ln_params *p = params;
    const int B = t[0]->shape[0], C = t[0]->shape[1];
    const long HW = (long)t[0]->shape[2] * t[0]->shape[3], nblk = (HW + LN_BLOCK - 1) / LN_BLOCK;
    const float *w = p->has_w ? t[3]->data : NULL, *bias = p->has_b ? t[4]->data : NULL;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long j = 0; j < B * nblk; j++) {
        const long b = j / nblk, p0 = (j % nblk) * LN_BLOCK;
        const int np = (int)(HW - p0 < LN_BLOCK ? HW - p0 : LN_BLOCK);
        const float *x = t[0]->data + b * C * HW + p0;
        float *y = t[1]->data + b * C * HW + p0, *st = t[2]->data + b * 2 * HW + p0;
        float mean[LN_BLOCK] = {0}, var[LN_BLOCK] = {0};
        for (int ch = 0; ch < C; ch++)
#pragma omp simd
            for (int q = 0; q < np; q++) mean[q] += x[ch * HW + q];
#pragma omp simd
        for (int q = 0; q < np; q++) mean[q] /= (float)C;
        for (int ch = 0; ch < C; ch++)
#pragma omp simd
            for (int q = 0; q < np; q++) {
                const float d = x[ch * HW + q] - mean[q];
                var[q] += d * d;
            }
#pragma omp simd
        for (int q = 0; q < np; q++) {
            var[q] = 1.0f / sqrtf(var[q] / (float)C + p->eps); /* now rstd */
            st[q] = mean[q];
            st[HW + q] = var[q];
        }
        for (int ch = 0; ch < C; ch++) {
            const float wc = w ? w[ch] : 1.0f, bc = bias ? bias[ch] : 0.0f;
#pragma omp simd
            for (int q = 0; q < np; q++)
                y[ch * HW + q] = (x[ch * HW + q] - mean[q]) * var[q] * wc + bc;
        }
    }
    return 0;
}

/* backward for x: t[0] = gx, t[1] = gy, t[2] = x, t[3] = stats, t[4] = w or NULL; gx +=
 * gx = rstd (d - mean_c(d) - xhat mean_c(d xhat)), d = gy w, xhat = (x - mean) rstd. */
static int ln_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_ln_params *p = params;
    const int B = t[0]->shape[0], C = t[0]->shape[1];
    const long HW = (long)t[0]->shape[2] * t[0]->shape[3], nblk = (HW + LN_BLOCK - 1) / LN_BLOCK;
    const float *w = p->has_w ? t[4]->data : NULL;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long j = 0; j < B * nblk; j++) {
        const long b = j / nblk, p0 = (j % nblk) * LN_BLOCK, off = b * C * HW + p0;
        const int np = (int)(HW - p0 < LN_BLOCK ? HW - p0 : LN_BLOCK);
        const float *x = t[2]->data + off, *gy = t[1]->data + off;
        const float *mean = t[3]->data + b * 2 * HW + p0, *rstd = mean + HW;
        float *gx = t[0]->data + off;
        float sd[LN_BLOCK] = {0}, sdx[LN_BLOCK] = {0};
        for (int ch = 0; ch < C; ch++) {
            const float wc = w ? w[ch] : 1.0f;
#pragma omp simd
            for (int q = 0; q < np; q++) {
                const float d = gy[ch * HW + q] * wc;
                sd[q] += d;
                sdx[q] += d * (x[ch * HW + q] - mean[q]) * rstd[q];
            }
        }
#pragma omp simd
        for (int q = 0; q < np; q++) {
            sd[q] /= (float)C;
            sdx[q] /= (float)C;
        }
        for (int ch = 0; ch < C; ch++) {
            const float wc = w ? w[ch] : 1.0f;
#pragma omp simd
            for (int q = 0; q < np; q++) {
                const float xh = (x[ch * HW + q] - mean[q]) * rstd[q];
                gx[ch * HW + q] += rstd[q] * (gy[ch * HW + q] * wc - sd[q] - xh * sdx[q]);
            }
        }
    }
    return 0;
}

/* backward for w and b: t[0] = gw or NULL, t[1] = gb or NULL (C), t[2] = gy, t[3] = x,
 * t[4] = stats; gw += sum gy xhat, gb += sum gy over B x H x W. One job per channel. */
static int ln_bwd_wb_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const lm_tensor *gy = t[2];
    const int B = gy->shape[0], C = gy->shape[1];
    const long HW = (long)gy->shape[2] * gy->shape[3];
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (int ch = 0; ch < C; ch++) {
        double sw = 0.0, sb = 0.0;
        for (int b = 0; b < B; b++) {
            const float *g = gy->data + ((long)b * C + ch) * HW;
            const float *x = t[3]->data + ((long)b * C + ch) * HW;
            const float *mean = t[4]->data + (long)b * 2 * HW, *rstd = mean + HW;
            for (long q = 0; q < HW; q++) {
                sw += (double)g[q] * (double)((x[q] - mean[q]) * rstd[q]);
                sb += (double)g[q];
            }
        }
        if (t[0]) t[0]->data[ch] += (float)sw;
        if (t[1]) t[1]->data[ch] += (float)sb;
    }
    return 0;
}
LM_KERNEL(layer_norm_channels_fwd, ln_fwd_cpu);
LM_KERNEL(layer_norm_channels_bwd_x, ln_bwd_x_cpu);
LM_KERNEL(layer_norm_channels_bwd_wb, ln_bwd_wb_cpu);

/* in = {x, w or NULL, b or NULL, stats} */
static void ln_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0], *w = n->in[1], *b = n->in[2], *st = n->in[3], *gy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[5] = {lm_grad(c, x), gy, x, st, w};
        if (!t[0]) return;
        lm_kernel_run(c, &lm_kernel_layer_norm_channels_bwd_x, t, 5, n->params);
    }
    if (lm_requires_grad(w) || lm_requires_grad(b)) {
        lm_tensor *gw = lm_requires_grad(w) ? lm_grad(c, w) : NULL;
        lm_tensor *gb = lm_requires_grad(b) ? lm_grad(c, b) : NULL;
        if (c->status) return;
        lm_tensor *t[5] = {gw, gb, gy, x, st};
        lm_kernel_run(c, &lm_kernel_layer_norm_channels_bwd_wb, t, 5, n->params);
    }
}

/* w or b must be NULL or hold C values in one dim. */
static int ln_affine_ok(lm_ctx *c, const lm_tensor *x, const lm_tensor *v, const char *what)
{
    char sa[64], sb[64];
    if (!v || (v->ndim == 1 && v->shape[0] == x->shape[1])) return 1;
    lm_ctx_fail(c, LM_ERR_SHAPE, "layer_norm_channels: %s %s does not match the %d channels of "
                "%s", what, lm_shape_str(v, sa, sizeof sa), x->shape[1],
                lm_shape_str(x, sb, sizeof sb));
    return 0;
}

lm_tensor *lm_layer_norm_channels(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *b, float eps)
{
    if (!lm_check_inputs(c, "layer_norm_channels", 1, x)) return NULL;
    char sb[64];
    if (x->ndim != 4) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "layer_norm_channels: input %s is not B x C x H x W",
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    if (!ln_affine_ok(c, x, w, "weight") || !ln_affine_ok(c, x, b, "bias")) return NULL;
    if (!(eps >= 0.0f) || isinf(eps)) {
        lm_ctx_fail(c, LM_ERR_ARG, "layer_norm_channels: eps %g must be finite and >= 0",
                    (double)eps);
        return NULL;
    }
    x = lm_contiguous(c, x);
    if (w) w = lm_contiguous(c, w);
    if (b) b = lm_contiguous(c, b);
    if (c->status) return NULL;
    lm_tensor *y = lm_tensor_new(c, 4, x->shape);
    int ss[4] = {x->shape[0], 2, x->shape[2], x->shape[3]};
    lm_tensor *st = y ? lm_tensor_new(c, 4, ss) : NULL;
    if (!st) return NULL;
    lm_ln_params p = {eps, w != NULL, b != NULL};
    lm_tensor *t[5] = {x, y, st, w, b};
    if (lm_kernel_run(c, &lm_kernel_layer_norm_channels_fwd, t, 5, &p)) return NULL;
    lm_tensor *in[4] = {x, w, b, st};
    lm_record(c, "layer_norm_channels", ln_backward, y, in, 4, &p, sizeof p);
    return y;
}
