/* conv2d.c — 2-D convolution (cross-correlation, PyTorch Conv2d semantics): any kernel size,
 * stride, zero padding, dilation, groups, optional bias; backward for x, w and bias.
 * What it is: the op (checks, kernels, tape) and the SIMPLE reference path: whole-image
 * im2col + GEMM for the forward and the weight gradient, GEMM + col2im for the input
 * gradient, one (image, group) at a time. The fast CPU paths live in conv2d_tiled.c (tiled
 * im2col + GEMM, cache-sized column blocks), conv2d_winograd.c (3x3 stride 1, F(4x4, 3x3)),
 * conv2d_pointwise.c (1x1 forward and input gradient), conv2d_direct.c (few output channels) and
 * conv2d_depthwise.c (direct loops); the kernel
 * picks one (lm_conv2d_set_path() forces the reference on a context, for tests).
 * What it is not: transposed or 3-D convolution (conv_transpose2d.c, conv3d.c). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/ops/gemm_internal.h"
#include <omp.h>
#include <string.h>

int lm_conv2d_set_path(lm_ctx *c, int path)
{
    int old = c->conv_path;
    c->conv_path = path;
    return old;
}

/* ---- simple reference path ------------------------------------------------------------- */
/* col (Cig*kh*kw x Ho*Wo, row (ci, i, j), column (oy, ox)) = patches of one image group. */
static void im2col_full(const lm_conv_geom *g, const float *x, float *col)
{
    int cig = g->Cin / g->groups;
    long hw = (long)g->Ho * g->Wo;
    for (int ci = 0; ci < cig; ci++)
        for (int i = 0; i < g->kh; i++)
            for (int j = 0; j < g->kw; j++) {
                float *row = col + ((long)(ci * g->kh + i) * g->kw + j) * hw;
                for (int oy = 0; oy < g->Ho; oy++)
                    for (int ox = 0; ox < g->Wo; ox++) {
                        int iy = oy * g->sh - g->ph + i * g->dh;
                        int ix = ox * g->sw - g->pw + j * g->dw;
                        int in = iy >= 0 && iy < g->H && ix >= 0 && ix < g->W;
                        row[oy * g->Wo + ox] = in ? x[((long)ci * g->H + iy) * g->W + ix] : 0.0f;
                    }
            }
}

/* dx (one image group) += col2im(col): the adjoint of im2col_full. */
static void col2im_full(const lm_conv_geom *g, const float *col, float *dx)
{
    int cig = g->Cin / g->groups;
    long hw = (long)g->Ho * g->Wo;
    for (int ci = 0; ci < cig; ci++)
        for (int i = 0; i < g->kh; i++)
            for (int j = 0; j < g->kw; j++) {
                const float *row = col + ((long)(ci * g->kh + i) * g->kw + j) * hw;
                for (int oy = 0; oy < g->Ho; oy++)
                    for (int ox = 0; ox < g->Wo; ox++) {
                        int iy = oy * g->sh - g->ph + i * g->dh;
                        int ix = ox * g->sw - g->pw + j * g->dw;
                        if (iy >= 0 && iy < g->H && ix >= 0 && ix < g->W)
                            dx[((long)ci * g->H + iy) * g->W + ix] += row[oy * g->Wo + ox];
                    }
            }
}

/* which: 0 forward (y = W col + bias), 1 input gradient (dx += col2im(W^T dy)),
 * 2 weight gradient (dw += dy col^T). a = x or dy, out = y, dx or dw. */
static int simple_run(lm_ctx *c, const lm_conv_geom *g, int which, const float *a,
                      const float *w, const float *bias, const float *dy, float *out)
{
    int G = g->groups, cig = g->Cin / G, cog = g->Cout / G;
    int K = cig * g->kh * g->kw, hw = g->Ho * g->Wo;
    long xs = (long)cig * g->H * g->W, ys = (long)cog * hw, ws = (long)cog * K;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *col = lm_ctx_alloc(c, sizeof(float) * (size_t)K * (size_t)hw);
    if (!col) return c->status;
    for (int b = 0; b < g->B; b++)
        for (int q = 0; q < G; q++) {
            long xo = (long)(b * G + q) * xs, yo = (long)(b * G + q) * ys;
            if (which == 0) {
                im2col_full(g, a + xo, col);
                lm_gemm_mt(c, 0, 0, cog, hw, K, 1.0f, w + q * ws, K, col, hw, 0.0f, out + yo, hw);
                for (int o = 0; bias && o < cog; o++)
                    for (int p = 0; p < hw; p++) out[yo + (long)o * hw + p] += bias[q * cog + o];
            } else if (which == 1) {
                lm_gemm_mt(c, 1, 0, K, hw, cog, 1.0f, w + q * ws, K, a + yo, hw, 0.0f, col, hw);
                col2im_full(g, col, out + xo);
            } else {
                im2col_full(g, a + xo, col);
                lm_gemm_mt(c, 0, 1, cog, K, hw, 1.0f, dy + yo, hw, col, hw, 1.0f, out + q * ws, K);
            }
        }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

/* ---- kernels ------------------------------------------------------------------------------ */
/* One input channel per group, and the fast paths allowed. */
static int depthwise(const lm_ctx *c, const lm_conv_geom *g)
{
    return g->groups == g->Cin && c->conv_path != LM_CONV_PATH_SIMPLE;
}

static int winograd(const lm_ctx *c, const lm_conv_geom *g)
{
    return c->conv_path == LM_CONV_PATH_AUTO && lm_conv2d_winograd_applies(g);
}

/* t = {x, w, y[, bias]}: y = conv(x, w) + bias (writes =). */
static int conv2d_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    const lm_conv_geom *g = params;
    const float *x = t[0]->data, *w = t[1]->data, *bias = nt > 3 ? t[3]->data : NULL;
    float *y = t[2]->data;
    if (c->conv_path == LM_CONV_PATH_SIMPLE) return simple_run(c, g, 0, x, w, bias, NULL, y);
    if (depthwise(c, g)) return lm_conv2d_dw_fwd(c, g, x, w, bias, y);
    if (winograd(c, g)) return lm_conv2d_winograd_fwd(c, g, x, w, bias, y);
    if (lm_conv2d_pointwise_applies(g)) return lm_conv2d_pointwise_fwd(c, g, x, w, bias, y);
    if (lm_conv2d_direct_applies(g)) return lm_conv2d_direct_fwd(c, g, x, w, bias, y);
    return lm_conv2d_tiled_fwd(c, g, x, w, bias, y);
}

/* t = {dy, w, dx}: dx += conv2d input gradient. */
static int conv2d_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_conv_geom *g = params;
    if (c->conv_path == LM_CONV_PATH_SIMPLE)
        return simple_run(c, g, 1, t[0]->data, t[1]->data, NULL, NULL, t[2]->data);
    if (depthwise(c, g)) return lm_conv2d_dw_bwd_x(c, g, t[0]->data, t[1]->data, t[2]->data);
    if (winograd(c, g)) return lm_conv2d_winograd_bwd_x(c, g, t[0]->data, t[1]->data, t[2]->data);
    if (lm_conv2d_pointwise_applies(g))
        return lm_conv2d_pointwise_bwd_x(c, g, t[0]->data, t[1]->data, t[2]->data);
    return lm_conv2d_tiled_bwd_x(c, g, t[0]->data, t[1]->data, t[2]->data);
}

/* t = {dy, x, dw}: dw += conv2d weight gradient. */
static int conv2d_bwd_w_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_conv_geom *g = params;
    if (c->conv_path == LM_CONV_PATH_SIMPLE)
        return simple_run(c, g, 2, t[1]->data, NULL, NULL, t[0]->data, t[2]->data);
    if (depthwise(c, g)) return lm_conv2d_dw_bwd_w(c, g, t[0]->data, t[1]->data, t[2]->data);
    if (winograd(c, g)) return lm_conv2d_winograd_bwd_w(c, g, t[0]->data, t[1]->data, t[2]->data);
    return lm_conv2d_tiled_bwd_w(c, g, t[0]->data, t[1]->data, t[2]->data);
}

/* t = {dy (B x Cout x Ho x Wo), db (Cout)}: db[o] += sum over images and pixels of dy[., o].
 * Parallel over channels; each channel summed in double in a fixed order. */
static int conv2d_bwd_bias_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_conv_geom *g = params;
    const float *dy = t[0]->data;
    float *db = t[1]->data;
    long hw = (long)g->Ho * g->Wo;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (int o = 0; o < g->Cout; o++) {
        double s = 0.0;
        for (int b = 0; b < g->B; b++) {
            const float *p = dy + ((long)b * g->Cout + o) * hw;
            float part = 0.0f;
#pragma omp simd reduction(+ : part)
            for (long i = 0; i < hw; i++) part += p[i];
            s += part;
        }
        db[o] += (float)s;
    }
    return 0;
}

LM_KERNEL(conv2d_fwd, conv2d_fwd_cpu);
LM_KERNEL(conv2d_bwd_x, conv2d_bwd_x_cpu);
LM_KERNEL(conv2d_bwd_w, conv2d_bwd_w_cpu);
LM_KERNEL(conv2d_bwd_bias, conv2d_bwd_bias_cpu);

/* ---- op ------------------------------------------------------------------------------------ */
static void conv2d_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0], *w = n->in[1], *bias = n->nin > 2 ? n->in[2] : NULL;
    lm_tensor *dy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {dy, w, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv2d_bwd_x, t, 3, n->params);
    }
    if (lm_requires_grad(w)) {
        lm_tensor *t[3] = {dy, x, lm_grad(c, w)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv2d_bwd_w, t, 3, n->params);
    }
    if (lm_requires_grad(bias)) {
        lm_tensor *t[2] = {dy, lm_grad(c, bias)};
        if (t[1]) lm_kernel_run(c, &lm_kernel_conv2d_bwd_bias, t, 2, n->params);
    }
}

/* Fill g from the shapes and options; sets the ctx error and returns 0 if invalid. */
static int conv2d_geom(lm_ctx *c, const lm_tensor *x, const lm_tensor *w, const lm_tensor *bias,
                       const lm_conv2d_opts *o, lm_conv_geom *g)
{
    char sx[64], sw[64], sb[64];
    lm_conv2d_opts d = {0};
    if (!o) o = &d;
    lm_shape_str(x, sx, sizeof sx);
    lm_shape_str(w, sw, sizeof sw);
    if (x->ndim != 4 || w->ndim != 4) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv2d: x %s and w %s must both be 4-D", sx, sw);
        return 0;
    }
    memset(g, 0, sizeof *g);
    g->sh = o->stride_h ? o->stride_h : 1, g->sw = o->stride_w ? o->stride_w : 1;
    g->dh = o->dil_h ? o->dil_h : 1, g->dw = o->dil_w ? o->dil_w : 1;
    g->ph = o->pad_h, g->pw = o->pad_w, g->groups = o->groups ? o->groups : 1;
    if (g->sh < 1 || g->sw < 1 || g->dh < 1 || g->dw < 1 || g->ph < 0 || g->pw < 0 ||
        g->groups < 1) {
        lm_ctx_fail(c, LM_ERR_ARG, "conv2d: invalid options stride %dx%d pad %dx%d dilation "
                    "%dx%d groups %d", g->sh, g->sw, g->ph, g->pw, g->dh, g->dw, g->groups);
        return 0;
    }
    g->B = x->shape[0], g->Cin = x->shape[1], g->H = x->shape[2], g->W = x->shape[3];
    g->Cout = w->shape[0], g->kh = w->shape[2], g->kw = w->shape[3];
    if (g->Cin % g->groups || g->Cout % g->groups || w->shape[1] != g->Cin / g->groups) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv2d: x %s and w %s do not match with %d groups (need "
                    "Cin, Cout divisible by groups and w.shape[1] = Cin/groups)", sx, sw,
                    g->groups);
        return 0;
    }
    if (bias && (bias->ndim != 1 || bias->shape[0] != g->Cout)) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv2d: bias %s must have %d elements (w %s)",
                    lm_shape_str(bias, sb, sizeof sb), g->Cout, sw);
        return 0;
    }
    long eh = (long)g->H + 2L * g->ph - (long)g->dh * (g->kh - 1) - 1;
    long ew = (long)g->W + 2L * g->pw - (long)g->dw * (g->kw - 1) - 1;
    if (eh < 0 || ew < 0) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv2d: kernel %dx%d (dilation %dx%d) larger than the "
                    "padded input of x %s (pad %dx%d)", g->kh, g->kw, g->dh, g->dw, sx, g->ph,
                    g->pw);
        return 0;
    }
    g->Ho = (int)(eh / g->sh + 1), g->Wo = (int)(ew / g->sw + 1);
    return 1;
}

lm_tensor *lm_conv2d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias,
                     const lm_conv2d_opts *o)
{
    if (!lm_check_inputs(c, "conv2d", 2, x, w)) return NULL;
    lm_conv_geom g;
    if (!conv2d_geom(c, x, w, bias, o, &g)) return NULL;
    x = lm_contiguous(c, x);
    w = lm_contiguous(c, w);
    if (bias) bias = lm_contiguous(c, bias);
    if (!x || !w || c->status) return NULL;
    lm_tensor *y = lm_tensor_new4(c, g.B, g.Cout, g.Ho, g.Wo);
    if (!y) return NULL;
    lm_tensor *t[4] = {x, w, y, bias};
    if (lm_kernel_run(c, &lm_kernel_conv2d_fwd, t, bias ? 4 : 3, &g)) return NULL;
    lm_tensor *in[3] = {x, w, bias};
    lm_record(c, "conv2d", conv2d_backward, y, in, bias ? 3 : 2, &g, sizeof g);
    return y;
}
