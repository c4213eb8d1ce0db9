/* cl_ops_conv.c — typed launchers of the convolutions: tensor/ops/conv2d.c ("conv2d_fwd",
 * "conv2d_bwd_x", "conv2d_bwd_w", "conv2d_bwd_bias"), conv_transpose2d.c
 * ("conv_transpose2d_fwd/_bwd_x/_bwd_w/_bwd_b") and conv3d.c ("conv3d_fwd/_bwd_x/_bwd_w/
 * _bwd_b").
 * Stride-1 conv2d runs without im2col (conv.cl: a zero-padded copy of the input, then one
 * launch of a direct "implicit GEMM" kernel over the whole batch, bias in its epilogue; the
 * input gradient is the same kernel on dy with flipped weights; the weight gradient a direct
 * kernel over the padded input). Other strides run as im2col (conv.cl) + batched GEMM
 * (gemm.cl) over chunks of columns that fit a device scratch (4M floats, or env
 * LM_OPENCL_CONV_SCRATCH); their input gradient is GEMM + a gathering col2im.
 * conv_transpose2d is conv2d's adjoint on the same weight layout (Cin x Cout/groups x kh x kw):
 * its forward is conv2d's input gradient, its input gradient conv2d's forward, its weight
 * gradient conv2d's with input and output exchanged. conv3d uses direct kernels (the channel
 * counts used are tiny). Bias gradients: one work-group per channel. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"
#include <string.h>

_Static_assert(sizeof(lm_conv_geom) == 16 * sizeof(int), "lm_conv_geom as int16");
_Static_assert(sizeof(lm_conv3d_params) == 16 * sizeof(int), "lm_conv3d_params as int16");

/* ---- conv2d building blocks ------------------------------------------------------------- */
typedef struct conv_plan {
    int K, HW, cog, nimg, P; /* per chunk: nimg images, or one image's P columns */
} conv_plan;

/* Chunks whose im2col columns fit `budget` floats. */
static conv_plan plan_of(const lm_conv_geom *g, long budget)
{
    conv_plan p;
    p.K = g->Cin / g->groups * g->kh * g->kw;
    p.HW = g->Ho * g->Wo;
    p.cog = g->Cout / g->groups;
    long per_img = (long)g->groups * p.K * p.HW;
    if (per_img <= budget) {
        long n = budget / per_img;
        p.nimg = (int)(n < g->B ? n : g->B);
        p.P = p.HW;
    } else {
        long cols = budget / ((long)g->groups * p.K) / 64 * 64;
        p.nimg = 1;
        p.P = (int)(cols < 64 ? 64 : (cols < p.HW ? cols : p.HW));
    }
    return p;
}

/* im2col (as "im2col") or the gathering col2im (as "col2im_gather") of one chunk. */
static int run_col(lm_cl *b, lm_ctx *c, const char *kname, const lm_tensor *src,
                   const lm_tensor *dst, const lm_conv_geom *g, int b0, int ni, int p0, int P)
{
    cl_int16 g16;
    memcpy(&g16, g, sizeof g16);
    int n = !strcmp(kname, "im2col") ? ni * g->Cin * g->kh * g->kw * P
                                     : ni * g->Cin * g->H * g->W;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, kname)) return c->status;
    lm_cl_arg_tensor(&a, src);
    lm_cl_arg_tensor(&a, dst);
    lm_cl_arg_raw(&a, sizeof g16, &g16);
    lm_cl_arg_int(&a, b0);
    lm_cl_arg_int(&a, p0);
    lm_cl_arg_int(&a, P);
    lm_cl_arg_int(&a, n);
    /* work-items: (segment of 64 columns / pixels, row); see conv.cl */
    int len = !strcmp(kname, "im2col") ? P : g->W;
    size_t global[2] = {(size_t)(len + 63) / 64, (size_t)(n / len)}, local[2] = {1, 16};
    return lm_cl_run_nd(&a, 2, global, local);
}

/* Operands of one chunk (images b0.., columns p0.. of width P) for the three products. */
static lm_cl_mat chunk_y(const lm_tensor *y, const lm_conv_geom *g, const conv_plan *p, int b0,
                         int p0, int trans)
{
    lm_cl_mat m = {y, (long)b0 * g->Cout * p->HW + p0, p->HW, trans, (long)g->Cout * p->HW,
                   (long)p->cog * p->HW};
    return m;
}
static lm_cl_mat chunk_col(const lm_tensor *col, const lm_conv_geom *g, const conv_plan *p,
                           int P, int trans)
{
    lm_cl_mat m = {col, 0, P, trans, (long)g->groups * p->K * P, (long)p->K * P};
    return m;
}
static lm_cl_mat weights(const lm_tensor *w, const conv_plan *p, int trans)
{
    lm_cl_mat m = {w, 0, p->K, trans, 0, (long)p->cog * p->K};
    return m;
}

/* ---- stride-1 conv2d without im2col (conv.cl "conv_pad", "conv_fwd_implicit", ...) ---- */
/* Whether the implicit kernels take this product: stride 1, no negative padding; the input
 * gradient (a convolution of dy with flipped weights and padding (k - 1) d - p) also needs
 * p <= (k - 1) d. Env LM_OPENCL_CONV_IM2COL=1 at backend creation forces im2col (tests). */
static int implicit_ok(const lm_cl *b, const lm_conv_geom *g, int which)
{
    if (b->conv_im2col || g->sh != 1 || g->sw != 1 || g->ph < 0 || g->pw < 0) return 0;
    return which != 1 || (g->ph <= (g->kh - 1) * g->dh && g->pw <= (g->kw - 1) * g->dw);
}

/* The padded copy of x (B x C x H x W) for geometry g (see conv.cl); NULL on error. */
static lm_tensor *pad_input(lm_cl *b, lm_ctx *c, const lm_tensor *x, const lm_conv_geom *g,
                            int *Hp, int *Wp)
{
    *Hp = g->H + 2 * g->ph;
    *Wp = (g->Wo + 31) / 32 * 32 + (g->kw - 1) * g->dw;
    int n = g->B * g->Cin * *Hp * *Wp;
    lm_tensor *xp = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1, &n);
    lm_cl_args a;
    if (!xp || lm_cl_begin(&a, b, c, "conv_pad")) return NULL;
    lm_cl_arg_tensor(&a, x);
    lm_cl_arg_tensor(&a, xp);
    int v[7] = {g->H, g->W, *Hp, *Wp, g->ph, g->pw, g->B * g->Cin * *Hp};
    for (int i = 0; i < 7; i++) lm_cl_arg_int(&a, v[i]);
    size_t global = (size_t)v[6], local = 16;
    return lm_cl_run_nd(&a, 1, &global, &local) ? NULL : xp;
}

/* wt for conv_fwd_implicit of geometry g (conv.cl "conv_wprep"); flip: w is the weight of
 * the forward conv whose input gradient g computes. NULL on error. */
static lm_tensor *prep_weights(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, const lm_tensor *w,
                               int flip, int *cogp)
{
    int cog = g->Cout / g->groups, cig = g->Cin / g->groups;
    *cogp = (cog + 7) / 8 * 8;
    int n = g->groups * cig * g->kh * g->kw * *cogp;
    lm_tensor *wt = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1, &n);
    lm_cl_args a;
    if (!wt || lm_cl_begin(&a, b, c, "conv_wprep")) return NULL;
    lm_cl_arg_tensor(&a, w);
    lm_cl_arg_tensor(&a, wt);
    int v[7] = {cog, cig, g->kh, g->kw, *cogp, flip, n};
    for (int i = 0; i < 7; i++) lm_cl_arg_int(&a, v[i]);
    return lm_cl_run_1d(&a, (size_t)n) ? NULL : wt;
}

/* y (= when beta 0, else +=) stride-1 conv2d(x, w) [+ bias]; flip as prep_weights. */
static int conv_fwd_implicit(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, const lm_tensor *x,
                             const lm_tensor *w, int flip, const lm_tensor *bias, lm_tensor *y,
                             float beta)
{
    int Hp, Wp, cogp;
    lm_tensor *xp = pad_input(b, c, x, g, &Hp, &Wp);
    lm_tensor *wt = xp ? prep_weights(b, c, g, w, flip, &cogp) : NULL;
    cl_int16 g16;
    memcpy(&g16, g, sizeof g16);
    lm_cl_args a;
    if (!wt || lm_cl_begin(&a, b, c, "conv_fwd_implicit")) return c->status;
    lm_cl_arg_tensor(&a, xp);
    lm_cl_arg_tensor(&a, wt);
    lm_cl_arg_tensor(&a, y);
    lm_cl_arg_tensor_opt(&a, bias);
    lm_cl_arg_raw(&a, sizeof g16, &g16);
    int v[4] = {Hp, Wp, cogp, bias != NULL};
    for (int i = 0; i < 4; i++) lm_cl_arg_int(&a, v[i]);
    lm_cl_arg_float(&a, beta);
    size_t nb = (size_t)(g->Wo + 31) / 32 * (size_t)g->Ho;
    size_t global[3] = {(size_t)cogp / 8, nb, (size_t)g->B * (size_t)g->groups};
    size_t local[3] = {1, 1, 1}; /* PoCL: single-item groups beat 2, 4 and 8 here */
    return lm_cl_run_nd(&a, 3, global, local);
}

/* dx += stride-1 conv2d input gradient: conv2d(dy, flipped w) with padding (k - 1) d - p. */
static int conv_bwd_x_implicit(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, const lm_tensor *dy,
                               const lm_tensor *w, lm_tensor *dx)
{
    lm_conv_geom t = {g->B, g->Cout, g->Ho, g->Wo, g->Cin, g->H, g->W, g->kh, g->kw, 1, 1,
                      (g->kh - 1) * g->dh - g->ph, (g->kw - 1) * g->dw - g->pw, g->dh, g->dw,
                      g->groups};
    return conv_fwd_implicit(b, c, &t, dy, w, 1, NULL, dx, 1.0f);
}

/* dw += stride-1 conv2d weight gradient of dy and x. */
static int conv_bwd_w_implicit(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, const lm_tensor *dy,
                               const lm_tensor *x, lm_tensor *dw)
{
    int Hp, Wp;
    lm_tensor *xp = pad_input(b, c, x, g, &Hp, &Wp);
    cl_int16 g16;
    memcpy(&g16, g, sizeof g16);
    lm_cl_args a;
    if (!xp || lm_cl_begin(&a, b, c, "conv_bwd_w_implicit")) return c->status;
    lm_cl_arg_tensor(&a, xp);
    lm_cl_arg_tensor(&a, dy);
    lm_cl_arg_tensor(&a, dw);
    lm_cl_arg_raw(&a, sizeof g16, &g16);
    lm_cl_arg_int(&a, Hp);
    lm_cl_arg_int(&a, Wp);
    size_t K = (size_t)(g->Cin / g->groups * g->kh * g->kw), cog = (size_t)(g->Cout / g->groups);
    size_t global[3] = {(K + 3) / 4, (cog + 3) / 4, (size_t)g->groups}, local[3] = {1, 1, 1};
    return lm_cl_run_nd(&a, 3, global, local);
}

/* which 0: y (=, or += when acc) conv(x, w) [+ bias]; 1: dx += input gradient (a = dy);
 * 2: dw += weight gradient (a = dy, x = input). */
static int conv2d_run(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, int which, const lm_tensor *a,
                      const lm_tensor *x, const lm_tensor *w, const lm_tensor *bias,
                      lm_tensor *out, int acc)
{
    if (implicit_ok(b, g, which))
        return which == 0 ? conv_fwd_implicit(b, c, g, a, w, 0, bias, out, acc ? 1.0f : 0.0f)
             : which == 1 ? conv_bwd_x_implicit(b, c, g, a, w, out)
                          : conv_bwd_w_implicit(b, c, g, a, x, out);
    conv_plan p = plan_of(g, b->conv_scratch);
    lm_tensor *col = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1,
                                      (int[]){p.nimg * g->groups * p.K * p.P});
    if (!col) return c->status;
    float beta = acc ? 1.0f : 0.0f;
    if (which == 0 && bias) { /* y = bias broadcast, then the products add */
        lm_tensor bv = *bias, yv = *out;
        int sh[3] = {g->B, g->Cout, p.HW};
        ptrdiff_t bs[3] = {0, 1, 0}, ys[3] = {(ptrdiff_t)g->Cout * p.HW, p.HW, 1};
        bv.ndim = yv.ndim = 3;
        for (int i = 0; i < 3; i++)
            bv.shape[i] = yv.shape[i] = sh[i], bv.stride[i] = bs[i], yv.stride[i] = ys[i];
        if (lm_cl_view_copy(b, c, &bv, &yv, 0)) return c->status;
        beta = 1.0f;
    }
    for (int b0 = 0; b0 < g->B; b0 += p.nimg) {
        int ni = g->B - b0 < p.nimg ? g->B - b0 : p.nimg;
        for (int p0 = 0; p0 < p.HW; p0 += p.P) {
            int P = p.HW - p0 < p.P ? p.HW - p0 : p.P;
            if (which == 1) {
                if (lm_cl_gemm(b, c, ni, g->groups, 0, p.K, P, p.cog, 1.0f, weights(w, &p, 1),
                               chunk_y(a, g, &p, b0, p0, 0), 0.0f, chunk_col(col, g, &p, P, 0)) ||
                    run_col(b, c, "col2im_gather", col, out, g, b0, ni, p0, P))
                    return c->status;
                continue;
            }
            if (run_col(b, c, "im2col", which == 0 ? a : x, col, g, b0, ni, p0, P))
                return c->status;
            if (which == 0 ? lm_cl_gemm(b, c, ni, g->groups, 0, p.cog, P, p.K, 1.0f,
                                        weights(w, &p, 0), chunk_col(col, g, &p, P, 0), beta,
                                        chunk_y(out, g, &p, b0, p0, 0))
                           : lm_cl_gemm(b, c, ni, g->groups, 1, p.cog, p.K, P, 1.0f,
                                        chunk_y(a, g, &p, b0, p0, 0),
                                        chunk_col(col, g, &p, P, 1), 1.0f, weights(out, &p, 0)))
                return c->status;
        }
    }
    return 0;
}

/* db[co] += sum of dy over batch and the vol positions of each channel: one work-group per
 * channel (conv.cl "bias_grad_wg", a fixed-order sum). */
static int bias_grad(lm_cl *b, lm_ctx *c, const lm_tensor *dy, lm_tensor *db, int B, int C,
                     long vol)
{
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "bias_grad_wg")) return c->status;
    lm_cl_arg_tensor(&a, dy);
    lm_cl_arg_tensor(&a, db);
    lm_cl_arg_int(&a, B);
    lm_cl_arg_int(&a, C);
    lm_cl_arg_int(&a, (int)vol);
    return lm_cl_run_groups(&a, (size_t)C);
}

/* ---- conv2d ------------------------------------------------------------------------------ */
/* t = {x, w, y[, bias]} */
int lm_cl_launch_conv2d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    return conv2d_run(b, c, pp, 0, t[0], NULL, t[1], nt > 3 ? t[3] : NULL, t[2], 0);
}
/* t = {dy, w, dx} */
int lm_cl_launch_conv2d_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return conv2d_run(b, c, pp, 1, t[0], NULL, t[1], NULL, t[2], 1);
}
/* t = {dy, x, dw} */
int lm_cl_launch_conv2d_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return conv2d_run(b, c, pp, 2, t[0], t[1], NULL, NULL, t[2], 1);
}
/* t = {dy, db} */
int lm_cl_launch_conv2d_bwd_bias(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv_geom *g = pp;
    return bias_grad(b, c, t[0], t[1], g->B, g->Cout, (long)g->Ho * g->Wo);
}

/* ---- conv_transpose2d --------------------------------------------------------------------- */
/* The conv2d whose input gradient this transposed conv is (input and output exchanged). */
static lm_conv_geom adjoint_geom(const lm_convt_params *p)
{
    lm_conv_geom g = {p->B, p->Cout, p->Ho, p->Wo, p->Cin, p->H, p->W, p->kh, p->kw,
                      p->sh, p->sw, p->ph, p->pw, p->dh, p->dw, p->groups};
    return g;
}

/* t = {x, w, y[, bias]}: y = bias (or 0), then y += conv2d input gradient of x. */
int lm_cl_launch_conv_transpose2d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                      const void *pp)
{
    const lm_convt_params *p = pp;
    lm_conv_geom g = adjoint_geom(p);
    if (nt > 3) {
        lm_tensor bv = *t[3], yv = *t[2];
        int sh[3] = {p->B, p->Cout, p->Ho * p->Wo};
        ptrdiff_t bs[3] = {0, 1, 0}, ys[3] = {(ptrdiff_t)p->Cout * sh[2], sh[2], 1};
        bv.ndim = yv.ndim = 3;
        for (int i = 0; i < 3; i++)
            bv.shape[i] = yv.shape[i] = sh[i], bv.stride[i] = bs[i], yv.stride[i] = ys[i];
        if (lm_cl_view_copy(b, c, &bv, &yv, 0)) return c->status;
    } else {
        float zero = 0.0f;
        if (lm_cl_launch(b, c, "fill", &t[2], 1, &zero)) return c->status;
    }
    return conv2d_run(b, c, &g, 1, t[0], NULL, t[1], NULL, t[2], 1);
}
/* t = {dy, w, dx}: dx += conv2d(dy, w) */
int lm_cl_launch_conv_transpose2d_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                        const void *pp)
{
    (void)nt;
    lm_conv_geom g = adjoint_geom(pp);
    return conv2d_run(b, c, &g, 0, t[0], NULL, t[1], NULL, t[2], 1);
}
/* t = {x, dy, dw}: dw += conv2d weight gradient with dy as the input and x as the output
 * gradient */
int lm_cl_launch_conv_transpose2d_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                        const void *pp)
{
    (void)nt;
    lm_conv_geom g = adjoint_geom(pp);
    return conv2d_run(b, c, &g, 2, t[0], t[1], NULL, NULL, t[2], 1);
}
/* t = {dy, db} */
int lm_cl_launch_conv_transpose2d_bwd_b(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                        const void *pp)
{
    (void)nt;
    const lm_convt_params *p = pp;
    return bias_grad(b, c, t[0], t[1], p->B, p->Cout, (long)p->Ho * p->Wo);
}

/* ---- conv3d ------------------------------------------------------------------------------- */
/* Tensors in order, then the geometry, then: groups set: n work-groups (conv3d_bwd_w); else
 * n rows of width `width`, one work-item per 16 of a row (conv3d_fwd, conv3d_bwd_x). */
static int run_conv3d(lm_cl *b, lm_ctx *c, const char *kname, lm_tensor *const *ts, int nts,
                      const lm_conv3d_params *p, long n, int groups, int width)
{
    cl_int16 g16;
    memcpy(&g16, p, sizeof g16);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, kname)) return c->status;
    for (int i = 0; i < nts; i++) lm_cl_arg_tensor_opt(&a, ts[i]);
    lm_cl_arg_raw(&a, sizeof g16, &g16);
    if (groups) return lm_cl_run_groups(&a, (size_t)n);
    lm_cl_arg_int(&a, (int)n);
    size_t global[2] = {(size_t)(width + 15) / 16, (size_t)n}, local[2] = {1, 4};
    return lm_cl_run_nd(&a, 2, global, local);
}

/* t = {x, w, y[, bias]} */
int lm_cl_launch_conv3d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    lm_conv3d_params p = *(const lm_conv3d_params *)pp;
    p.has_bias = nt > 3;
    lm_tensor *ts[4] = {t[0], t[1], t[2], nt > 3 ? t[3] : NULL};
    return run_conv3d(b, c, "conv3d_fwd", ts, 4, &p, lm_tensor_numel(t[2]) / p.Wo, 0, p.Wo);
}
/* t = {dy, w, dx} */
int lm_cl_launch_conv3d_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv3d_params *p = pp;
    return run_conv3d(b, c, "conv3d_bwd_x", t, 3, p, lm_tensor_numel(t[2]) / p->W, 0, p->W);
}
/* t = {x, dy, dw} */
int lm_cl_launch_conv3d_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_conv3d(b, c, "conv3d_bwd_w", t, 3, pp, lm_tensor_numel(t[2]), 1, 0);
}
/* t = {dy, db} */
int lm_cl_launch_conv3d_bwd_b(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv3d_params *p = pp;
    return bias_grad(b, c, t[0], t[1], p->B, p->Cout, (long)p->Do * p->Ho * p->Wo);
}
