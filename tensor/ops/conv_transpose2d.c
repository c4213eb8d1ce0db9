/* conv_transpose2d.c — transposed 2-D convolution (PyTorch ConvTranspose2d), forward and
 * backward for the input, the weight and the bias.
 *
 * What it is: y = the adjoint of conv2d w.r.t. its input, with stride, zero padding, dilation,
 * output padding and groups. Weight layout Cin x Cout/groups x kh x kw (PyTorch). CPU kernels
 * are GEMM + col2im (darknet style):
 *   forward   col (Cog kh kw x H W)  = W_g^T x_g, then col2im scatters col into y;
 *   d/dx      im2col of dy (same geometry), then dx_g += W_g col;
 *   d/dw      im2col of dy, then dW_g += x_g col^T;
 *   d/dbias   sum of dy over batch and pixels.
 * Threads: GEMM columns (pixels) or GEMM rows are split in a fixed static partition; col2im /
 * im2col are split by output channel. Results are deterministic for a given thread count.
 * What it is not: conv2d (tensor/ops/conv2d.c), nor an output-size-inferring layer: the
 * caller passes output_padding explicitly. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include "tensor/ops/gemm_internal.h"
#include <omp.h>
#include <string.h>

/* Work (multiply-adds) below which a kernel runs on one thread: a parallel region costs more. */
#define CONVT_PAR_MIN 65536L

/* Multiply-adds of the GEMMs of one pass (forward, d/dx or d/dw). */
static long convt_macs(const lm_convt_params *p)
{
    return (long)p->B * p->Cin * (p->Cout / p->groups) * p->kh * p->kw * p->H * p->W;
}

/* Indices i in [*lo, *hi) within [0, n) such that 0 <= i*s + off < lim (s >= 1). */
static void valid_range(int n, int s, int off, int lim, int *lo, int *hi)
{
    int a = off >= 0 ? 0 : (-off + s - 1) / s;
    int b = lim - off <= 0 ? 0 : (lim - off + s - 1) / s;
    if (b > n) b = n;
    *lo = a;
    *hi = b > a ? b : a;
}

/* Part `id` of `parts` of [0, n), split in units of `align` elements. */
static void split_range(long n, int parts, int id, long align, long *lo, long *hi)
{
    long units = (n + align - 1) / align;
    long a = units * id / parts * align, b = units * (id + 1) / parts * align;
    *lo = a < n ? a : n;
    *hi = b < n ? b : n;
}

/* y (Ho x Wo, one output channel) += col2im(col), col = kh kw rows of H W (this channel). */
static void col2im_add(const lm_convt_params *p, const float *col, float *y)
{
    long HW = (long)p->H * p->W;
    for (int ky = 0; ky < p->kh; ky++)
        for (int kx = 0; kx < p->kw; kx++) {
            const float *r = col + (long)(ky * p->kw + kx) * HW;
            int y0, y1, x0, x1, oy0 = ky * p->dh - p->ph, ox0 = kx * p->dw - p->pw;
            valid_range(p->H, p->sh, oy0, p->Ho, &y0, &y1);
            valid_range(p->W, p->sw, ox0, p->Wo, &x0, &x1);
            for (int iy = y0; iy < y1; iy++) {
                float *yr = y + (long)(iy * p->sh + oy0) * p->Wo + ox0;
                const float *rr = r + (long)iy * p->W;
                for (int ix = x0; ix < x1; ix++) yr[(long)ix * p->sw] += rr[ix];
            }
        }
}

/* col (kh kw rows of H W, one channel of dy) = im2col(dy channel, Ho x Wo); zero outside. */
static void im2col_chan(const lm_convt_params *p, const float *dy, float *col)
{
    long HW = (long)p->H * p->W;
    for (int ky = 0; ky < p->kh; ky++)
        for (int kx = 0; kx < p->kw; kx++) {
            float *r = col + (long)(ky * p->kw + kx) * HW;
            int y0, y1, x0, x1, oy0 = ky * p->dh - p->ph, ox0 = kx * p->dw - p->pw;
            valid_range(p->H, p->sh, oy0, p->Ho, &y0, &y1);
            valid_range(p->W, p->sw, ox0, p->Wo, &x0, &x1);
            memset(r, 0, (size_t)HW * sizeof(float));
            for (int iy = y0; iy < y1; iy++) {
                const float *dr = dy + (long)(iy * p->sh + oy0) * p->Wo + ox0;
                float *rr = r + (long)iy * p->W;
                for (int ix = x0; ix < x1; ix++) rr[ix] = dr[(long)ix * p->sw];
            }
        }
}

/* t = {x (B x Cin x H x W), w (Cin x Cog x kh x kw), y (B x Cout x Ho x Wo) [, bias (Cout)]}.
 * Writes y = (bias). */
static int convt_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    const lm_convt_params *p = pp;
    const float *x = t[0]->data, *w = t[1]->data, *bias = nt > 3 ? t[3]->data : NULL;
    float *y = t[2]->data;
    int G = p->groups, Cig = p->Cin / G, Cog = p->Cout / G, kk = p->kh * p->kw, M = Cog * kk;
    long HW = (long)p->H * p->W, HWo = (long)p->Ho * p->Wo;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    float *col = lm_ctx_alloc(c, (size_t)M * (size_t)HW * sizeof(float));
    if (!col) return c->status;
#pragma omp parallel num_threads(lm_nthreads(c)) if (convt_macs(p) >= CONVT_PAR_MIN)
    {
        int T = omp_get_num_threads(), id = omp_get_thread_num();
        long n0, n1;
        split_range(HW, T, id, 16, &n0, &n1);
        for (int bg = 0; bg < p->B * G; bg++) {
            int b = bg / G, g = bg % G;
            const float *xg = x + ((long)b * p->Cin + (long)g * Cig) * HW;
            const float *wg = w + (long)g * Cig * M;
            if (n1 > n0)
                lm_sgemm_st(1, 0, M, (int)(n1 - n0), Cig, 1.0f,
                            wg, M, xg + n0, (int)HW, 0.0f, col + n0, (int)HW);
#pragma omp barrier
#pragma omp for schedule(static)
            for (int co = 0; co < Cog; co++) {
                int oc = g * Cog + co;
                float *yc = y + ((long)b * p->Cout + oc) * HWo, bv = bias ? bias[oc] : 0.0f;
                for (long i = 0; i < HWo; i++) yc[i] = bv;
                col2im_add(p, col + (long)co * kk * HW, yc);
            }
        }
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

/* t = {dy (B x Cout x Ho x Wo), w, dx (B x Cin x H x W)}. dx += conv2d(dy, w). */
static int convt_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_convt_params *p = pp;
    const float *dy = t[0]->data, *w = t[1]->data;
    float *dx = t[2]->data;
    int G = p->groups, Cig = p->Cin / G, Cog = p->Cout / G, kk = p->kh * p->kw, M = Cog * kk;
    long HW = (long)p->H * p->W, HWo = (long)p->Ho * p->Wo;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    float *col = lm_ctx_alloc(c, (size_t)M * (size_t)HW * sizeof(float));
    if (!col) return c->status;
#pragma omp parallel num_threads(lm_nthreads(c)) if (convt_macs(p) >= CONVT_PAR_MIN)
    {
        int T = omp_get_num_threads(), id = omp_get_thread_num();
        long n0, n1;
        split_range(HW, T, id, 16, &n0, &n1);
        for (int bg = 0; bg < p->B * G; bg++) {
            int b = bg / G, g = bg % G;
#pragma omp for schedule(static)
            for (int co = 0; co < Cog; co++)
                im2col_chan(p, dy + ((long)b * p->Cout + (long)g * Cog + co) * HWo,
                            col + (long)co * kk * HW);
            float *dxg = dx + ((long)b * p->Cin + (long)g * Cig) * HW;
            if (n1 > n0)
                lm_sgemm_st(0, 0, Cig, (int)(n1 - n0), M,
                            1.0f, w + (long)g * Cig * M, M, col + n0, (int)HW, 1.0f, dxg + n0,
                            (int)HW);
#pragma omp barrier
        }
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

/* t = {x, dy, dw (Cin x Cog x kh x kw)}. dw += sum over batch of x_g im2col(dy_g)^T. */
static int convt_bwd_w_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_convt_params *p = pp;
    const float *x = t[0]->data, *dy = t[1]->data;
    float *dw = t[2]->data;
    int G = p->groups, Cig = p->Cin / G, Cog = p->Cout / G, kk = p->kh * p->kw, M = Cog * kk;
    long HW = (long)p->H * p->W, HWo = (long)p->Ho * p->Wo;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    float *col = lm_ctx_alloc(c, (size_t)M * (size_t)HW * sizeof(float));
    if (!col) return c->status;
#pragma omp parallel num_threads(lm_nthreads(c)) if (convt_macs(p) >= CONVT_PAR_MIN)
    {
        int T = omp_get_num_threads(), id = omp_get_thread_num();
        long m0, m1;
        split_range(M, T, id, 1, &m0, &m1);
        for (int bg = 0; bg < p->B * G; bg++) {
            int b = bg / G, g = bg % G;
#pragma omp for schedule(static)
            for (int co = 0; co < Cog; co++)
                im2col_chan(p, dy + ((long)b * p->Cout + (long)g * Cog + co) * HWo,
                            col + (long)co * kk * HW);
            const float *xg = x + ((long)b * p->Cin + (long)g * Cig) * HW;
            if (m1 > m0)
                lm_sgemm_st(0, 1, Cig, (int)(m1 - m0),
                            (int)HW, 1.0f, xg, (int)HW, col + m0 * HW, (int)HW, 1.0f,
                            dw + (long)g * Cig * M + m0, M);
#pragma omp barrier
        }
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

/* Sum of n floats: float partial sums in 16 lanes over blocks of 1024, added in double. */
static double sum_floats(const float *r, long n)
{
    double s = 0.0;
    for (long i0 = 0; i0 < n; i0 += 1024) {
        long m = n - i0 < 1024 ? n - i0 : 1024, i = 0;
        float acc[16] = {0};
        for (; i + 16 <= m; i += 16)
            for (int l = 0; l < 16; l++) acc[l] += r[i0 + i + l];
        for (; i < m; i++) acc[0] += r[i0 + i];
        for (int l = 0; l < 16; l++) s += acc[l];
    }
    return s;
}

/* t = {dy (B x Cout x Ho x Wo), db (Cout)}. db += sum of dy over batch and pixels. */
static int convt_bwd_b_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_convt_params *p = pp;
    const float *dy = t[0]->data;
    float *db = t[1]->data;
    long HWo = (long)p->Ho * p->Wo;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) \
    if ((long)p->B * p->Cout * HWo >= CONVT_PAR_MIN)
    for (int co = 0; co < p->Cout; co++) {
        double s = 0.0;
        for (int b = 0; b < p->B; b++)
            s += sum_floats(dy + ((long)b * p->Cout + co) * HWo, HWo);
        db[co] += (float)s;
    }
    return 0;
}

LM_KERNEL(conv_transpose2d_fwd, convt_fwd_cpu);
LM_KERNEL(conv_transpose2d_bwd_x, convt_bwd_x_cpu);
LM_KERNEL(conv_transpose2d_bwd_w, convt_bwd_w_cpu);
LM_KERNEL(conv_transpose2d_bwd_b, convt_bwd_b_cpu);

/* in = {x, w [, bias]} */
static void convt_backward(lm_ctx *c, lm_node *n)
{
    const lm_convt_params *p = n->params;
    lm_tensor *x = n->in[0], *w = n->in[1], *bias = n->nin > 2 ? n->in[2] : NULL;
    lm_tensor *dy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {dy, w, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv_transpose2d_bwd_x, t, 3, p);
    }
    if (lm_requires_grad(w)) {
        lm_tensor *t[3] = {x, dy, lm_grad(c, w)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv_transpose2d_bwd_w, t, 3, p);
    }
    if (lm_requires_grad(bias)) {
        lm_tensor *t[2] = {dy, lm_grad(c, bias)};
        if (t[1]) lm_kernel_run(c, &lm_kernel_conv_transpose2d_bwd_b, t, 2, p);
    }
}

/* Options with 0 read as 1; invalid values set the ctx error. Returns 0 on success. */
static int convt_options(lm_ctx *c, const lm_conv2d_opts *o, int oph, int opw, lm_convt_params *p)
{
    lm_conv2d_opts d = {0, 0, 0, 0, 0, 0, 0};
    if (!o) o = &d;
    p->sh = o->stride_h ? o->stride_h : 1;
    p->sw = o->stride_w ? o->stride_w : 1;
    p->dh = o->dil_h ? o->dil_h : 1;
    p->dw = o->dil_w ? o->dil_w : 1;
    p->groups = o->groups ? o->groups : 1;
    p->ph = o->pad_h;
    p->pw = o->pad_w;
    if (p->sh < 1 || p->sw < 1 || p->dh < 1 || p->dw < 1 || p->groups < 1 || p->ph < 0 ||
        p->pw < 0) {
        lm_ctx_fail(c, LM_ERR_ARG, "conv_transpose2d: invalid options: stride %dx%d, padding "
                    "%dx%d, dilation %dx%d, groups %d", p->sh, p->sw, p->ph, p->pw, p->dh,
                    p->dw, p->groups);
        return -1;
    }
    if (oph < 0 || opw < 0 || (oph >= p->sh && oph >= p->dh) || (opw >= p->sw && opw >= p->dw)) {
        lm_ctx_fail(c, LM_ERR_ARG, "conv_transpose2d: output_padding %dx%d must be >= 0 and "
                    "smaller than stride (%dx%d) or dilation (%dx%d)", oph, opw, p->sh, p->sw,
                    p->dh, p->dw);
        return -1;
    }
    return 0;
}

/* Shape checks and output size. Returns 0 on success (params filled), else sets the error. */
static int convt_shapes(lm_ctx *c, const lm_tensor *x, const lm_tensor *w, const lm_tensor *bias,
                        int oph, int opw, lm_convt_params *p)
{
    char sx[64], sw[64], sb[64];
    lm_shape_str(x, sx, sizeof sx);
    lm_shape_str(w, sw, sizeof sw);
    if (x->ndim != 4 || w->ndim != 4 || w->shape[0] != x->shape[1] ||
        x->shape[1] % p->groups != 0) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv_transpose2d: x %s and weight %s do not match (need "
                    "x B x Cin x H x W, weight Cin x Cout/groups x kh x kw, Cin divisible by "
                    "groups %d)", sx, sw, p->groups);
        return -1;
    }
    p->B = x->shape[0], p->Cin = x->shape[1], p->H = x->shape[2], p->W = x->shape[3];
    p->Cout = w->shape[1] * p->groups, p->kh = w->shape[2], p->kw = w->shape[3];
    if (bias && (bias->ndim != 1 || bias->shape[0] != p->Cout)) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv_transpose2d: bias %s, expected %d (Cout) for weight "
                    "%s, groups %d", lm_shape_str(bias, sb, sizeof sb), p->Cout, sw, p->groups);
        return -1;
    }
    p->has_bias = bias != NULL;
    p->Ho = (p->H - 1) * p->sh - 2 * p->ph + p->dh * (p->kh - 1) + oph + 1;
    p->Wo = (p->W - 1) * p->sw - 2 * p->pw + p->dw * (p->kw - 1) + opw + 1;
    if (p->Ho < 1 || p->Wo < 1) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv_transpose2d: empty output %dx%d for x %s, weight %s, "
                    "padding %dx%d", p->Ho, p->Wo, sx, sw, p->ph, p->pw);
        return -1;
    }
    return 0;
}

lm_tensor *lm_conv_transpose2d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias,
                               const lm_conv2d_opts *o, int out_pad_h, int out_pad_w)
{
    if (!lm_check_inputs(c, "conv_transpose2d", 2, x, w)) return NULL;
    lm_convt_params p;
    memset(&p, 0, sizeof p);
    if (convt_options(c, o, out_pad_h, out_pad_w, &p) ||
        convt_shapes(c, x, w, bias, out_pad_h, out_pad_w, &p))
        return NULL;
    x = lm_contiguous(c, x);
    w = lm_contiguous(c, w);
    if (bias) bias = lm_contiguous(c, bias);
    lm_tensor *y = lm_tensor_new4(c, p.B, p.Cout, p.Ho, p.Wo);
    if (!y) return NULL;
    lm_tensor *t[4] = {x, w, y, bias};
    if (lm_kernel_run(c, &lm_kernel_conv_transpose2d_fwd, t, bias ? 4 : 3, &p)) return NULL;
    lm_tensor *in[3] = {x, w, bias};
    lm_record(c, "conv_transpose2d", convt_backward, y, in, bias ? 3 : 2, &p, sizeof p);
    return y;
}
