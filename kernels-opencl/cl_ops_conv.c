/* cl_ops_conv.c — typed launchers of the convolutions: tensor/ops/conv2d.c ("conv2d_fwd",
 * "conv2d_bwd_x", "conv2d_bwd_w", "conv2d_bwd_bias"), conv_transpose2d.c
 * ("conv_transpose2d_fwd/_bwd_x/_bwd_w/_bwd_b") and conv3d.c ("conv3d_fwd/_bwd_x/_bwd_w/
 * _bwd_b").
 * conv2d runs as im2col (conv.cl) + batched GEMM (gemm.cl) over chunks of columns that fit a
 * device scratch (4M floats, or env LM_OPENCL_CONV_SCRATCH); the input gradient is GEMM + a
 * gathering col2im. conv_transpose2d is conv2d's adjoint on the same weight layout
 * (Cin x Cout/groups x kh x kw): its forward is conv2d's input gradient, its input gradient
 * conv2d's forward, its weight gradient conv2d's with input and output exchanged. conv3d uses direct
 * kernels (the channel counts used are tiny). Bias gradients are sums (lm_cl_reduce). */
#include "kernels-opencl/cl_impl.h"
#include "kernels-opencl/cl_params.h"
#include "tensor/ops/gemm_internal.h"
#include <string.h>

_Static_assert(sizeof(lm_conv_geom) == 16 * sizeof(int), "lm_conv_geom as int16");

/* tensor/ops/conv_transpose2d.c: convt_params */
typedef struct convt_params {
    int B, Cin, H, W, Cout, Ho, Wo, kh, kw, sh, sw, ph, pw, dh, dw, groups, has_bias;
} convt_params;
_Static_assert(sizeof(convt_params) == 68, "convt_params mirror");

/* tensor/ops/conv3d.c: conv3d_params */
typedef struct conv3d_params {
    int B, Cin, D, H, W, Cout, Do, Ho, Wo, kd, kh, kw, pd, ph, pw, has_bias;
} conv3d_params;
_Static_assert(sizeof(conv3d_params) == 64, "conv3d_params mirror");

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

/* which 0: y (=, or += when acc) conv(x, w) [+ bias]; 1: dx += input gradient (a = dy);
 * 2: dw += weight gradient (a = dy, x = input). */
static int conv2d_run(lm_cl *b, lm_ctx *c, const lm_conv_geom *g, int which, const lm_tensor *a,
                      const lm_tensor *x, const lm_tensor *w, const lm_tensor *bias,
                      lm_tensor *out, int acc)
{
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

/* db[co] += sum of dy over batch and the vol positions of each channel. */
static int bias_grad(lm_cl *b, lm_ctx *c, const lm_tensor *dy, lm_tensor *db, int B, int C,
                     long vol)
{
    lm_cl_reduction r;
    lm_cl_reduction_init(&r);
    r.kshp.s[4] = C, r.kst.s[4] = (cl_int)vol, r.ny = C;
    r.rshp.s[3] = B, r.rst.s[3] = (cl_int)(C * vol);
    r.rshp.s[4] = (cl_int)vol, r.rst.s[4] = 1, r.nr = B * vol;
    return lm_cl_reduce(b, c, dy, &r, db, 1.0f, 1);
}

/* ---- conv2d ------------------------------------------------------------------------------ */
/* t = {x, w, y[, bias]} */
static int launch_conv2d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    return conv2d_run(b, c, pp, 0, t[0], NULL, t[1], nt > 3 ? t[3] : NULL, t[2], 0);
}
/* t = {dy, w, dx} */
static int launch_conv2d_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return conv2d_run(b, c, pp, 1, t[0], NULL, t[1], NULL, t[2], 1);
}
/* t = {dy, x, dw} */
static int launch_conv2d_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return conv2d_run(b, c, pp, 2, t[0], t[1], NULL, NULL, t[2], 1);
}
/* t = {dy, db} */
static int launch_conv2d_bwd_bias(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                  const void *pp)
{
    (void)nt;
    const lm_conv_geom *g = pp;
    return bias_grad(b, c, t[0], t[1], g->B, g->Cout, (long)g->Ho * g->Wo);
}

/* ---- conv_transpose2d --------------------------------------------------------------------- */
/* The conv2d whose input gradient this transposed conv is (input and output exchanged). */
static lm_conv_geom adjoint_geom(const convt_params *p)
{
    lm_conv_geom g = {p->B, p->Cout, p->Ho, p->Wo, p->Cin, p->H, p->W, p->kh, p->kw,
                      p->sh, p->sw, p->ph, p->pw, p->dh, p->dw, p->groups};
    return g;
}

/* t = {x, w, y[, bias]}: y = bias (or 0), then y += conv2d input gradient of x. */
static int launch_convt_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    const convt_params *p = pp;
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
static int launch_convt_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_conv_geom g = adjoint_geom(pp);
    return conv2d_run(b, c, &g, 0, t[0], NULL, t[1], NULL, t[2], 1);
}
/* t = {x, dy, dw}: dw += conv2d weight gradient with dy as the input and x as the output
 * gradient */
static int launch_convt_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_conv_geom g = adjoint_geom(pp);
    return conv2d_run(b, c, &g, 2, t[0], t[1], NULL, NULL, t[2], 1);
}
/* t = {dy, db} */
static int launch_convt_bwd_b(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const convt_params *p = pp;
    return bias_grad(b, c, t[0], t[1], p->B, p->Cout, (long)p->Ho * p->Wo);
}

/* ---- conv3d ------------------------------------------------------------------------------- */
/* Tensors in order, then the geometry, then n (work-items) unless groups is set. */
static int run_conv3d(lm_cl *b, lm_ctx *c, const char *kname, lm_tensor *const *ts, int nts,
                      const conv3d_params *p, long n, int groups)
{
    cl_int16 g16;
    memcpy(&g16, p, sizeof g16);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, kname)) return c->status;
    for (int i = 0; i < nts; i++) lm_cl_arg_tensor_opt(&a, ts[i]);
    lm_cl_arg_raw(&a, sizeof g16, &g16);
    if (groups) return lm_cl_run_groups(&a, (size_t)n);
    lm_cl_arg_int(&a, (int)n);
    return lm_cl_run_1d(&a, (size_t)n);
}

/* t = {x, w, y[, bias]} */
static int launch_conv3d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    conv3d_params p = *(const conv3d_params *)pp;
    p.has_bias = nt > 3;
    lm_tensor *ts[4] = {t[0], t[1], t[2], nt > 3 ? t[3] : NULL};
    return run_conv3d(b, c, "conv3d_fwd", ts, 4, &p, lm_tensor_numel(t[2]), 0);
}
/* t = {dy, w, dx} */
static int launch_conv3d_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_conv3d(b, c, "conv3d_bwd_x", t, 3, pp, lm_tensor_numel(t[2]), 0);
}
/* t = {x, dy, dw} */
static int launch_conv3d_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_conv3d(b, c, "conv3d_bwd_w", t, 3, pp, lm_tensor_numel(t[2]), 1);
}
/* t = {dy, db} */
static int launch_conv3d_bwd_b(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const conv3d_params *p = pp;
    return bias_grad(b, c, t[0], t[1], p->B, p->Cout, (long)p->Do * p->Ho * p->Wo);
}

const lm_cl_entry lm_cl_entries_conv[] = {
    {"conv2d_bwd_bias", launch_conv2d_bwd_bias},
    {"conv2d_bwd_w", launch_conv2d_bwd_w},
    {"conv2d_bwd_x", launch_conv2d_bwd_x},
    {"conv2d_fwd", launch_conv2d_fwd},
    {"conv3d_bwd_b", launch_conv3d_bwd_b},
    {"conv3d_bwd_w", launch_conv3d_bwd_w},
    {"conv3d_bwd_x", launch_conv3d_bwd_x},
    {"conv3d_fwd", launch_conv3d_fwd},
    {"conv_transpose2d_bwd_b", launch_convt_bwd_b},
    {"conv_transpose2d_bwd_w", launch_convt_bwd_w},
    {"conv_transpose2d_bwd_x", launch_convt_bwd_x},
    {"conv_transpose2d_fwd", launch_convt_fwd},
    {NULL, NULL},
};
