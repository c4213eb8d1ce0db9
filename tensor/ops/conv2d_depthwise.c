/* conv2d_depthwise.c — direct-loop CPU path of conv2d when every group has one input channel
 * (groups == Cin; Cout = m*Cin, output channel co reads input channel co / m).
 * What it is: no im2col, no GEMM (a depthwise "GEMM" has inner size kh*kw only): for each
 * kernel tap, a row of the output gets w * a shifted row of the input, vectorised along the
 * row. Parallel over planes: forward over (image, output channel), input gradient over
 * (image, input channel), weight gradient over output channels; each element is written by
 * one thread in a fixed order, so results do not depend on the thread count. The stride-1
 * forward, input gradient (one output channel per input channel) and 3x3 weight gradient
 * have faster stencil forms (below; the per-tap loops stay as their reference).
 * What it is not: the general path (conv2d_tiled.c) or the reference (conv2d.c). */
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/simd.h"
#include "tensor/ops/op_paths.h"
#include <math.h>
#include <omp.h>
#include <string.h>

/* yp (Ho x Wo) += wv * (xp shifted by tap (i, j)); xp is H x W. Taps outer, rows inner: both
 * planes stay in L1 and the column range is computed once per tap. */
static void tap_fwd(const lm_conv_geom *g, const float *restrict xp, float wv, int i, int j,
                    float *restrict yp)
{
    int lo, hi;
    lm_conv_valid_range(g->Wo, g->W, g->sw, g->pw, j * g->dw, &lo, &hi);
    for (int oy = 0; oy < g->Ho; oy++) {
        int iy = oy * g->sh - g->ph + i * g->dh;
        if (iy < 0 || iy >= g->H) continue;
        const float *restrict s = xp + (long)iy * g->W + j * g->dw - g->pw;
        float *restrict d = yp + (long)oy * g->Wo;
        if (g->sw == 1) {
#pragma omp simd
            for (int ox = lo; ox < hi; ox++) d[ox] += wv * s[ox];
        } else {
            for (int ox = lo; ox < hi; ox++) d[ox] += wv * s[(long)ox * g->sw];
        }
    }
}

/* yp (Ho x Wo) = bias + sum over taps of wk[tap] * shifted xp. */
static void fwd_plane(const lm_conv_geom *g, const float *xp, const float *wk, float bv,
                      float *yp)
{
    long n = (long)g->Ho * g->Wo;
    for (long p = 0; p < n; p++) yp[p] = bv;
    for (int i = 0; i < g->kh; i++)
        for (int j = 0; j < g->kw; j++) tap_fwd(g, xp, wk[i * g->kw + j], i, j, yp);
}

/* ---- stride-1 stencil forward --------------------------------------------------------------
 * For stride 1, dilation 1 (the 3x3 depthwise convs of the attention / FFN blocks): each input
 * plane is copied once into a zero-bordered per-thread buffer, then every block of VL output
 * pixels of a row keeps its accumulator in a register over all taps (one load and one
 * multiply-add per tap; no per-tap pass over the plane, no bounds checks). Same order of
 * summation as the per-tap loops (bias, then taps in (i, j) order, zero taps outside the
 * image), so the result is the same (bit for bit where multiply-adds are fused, as with
 * -march=native on x86-64); lm_op_set_path(c, LM_OP_PATH_REFERENCE) selects the per-tap loops
 * (tests compare the two). */
static int stencil_applies(const lm_ctx *c, const lm_conv_geom *g)
{
    return lm_op_path(c) == LM_OP_PATH_FAST && g->sh == 1 && g->sw == 1 && g->dh == 1 &&
           g->dw == 1;
}

/* Padded plane geometry: Hp rows of Wp floats, the image at (ph, pw); Wp also holds every
 * vector load of the last block of a row. */
static void stencil_dims(const lm_conv_geom *g, int *Hp, int *Wp)
{
    int wp = (g->Wo + LM_VLN - 1) / LM_VLN * LM_VLN + g->kw - 1;
    if (wp < g->W + 2 * g->pw) wp = g->W + 2 * g->pw;
    *Hp = g->H + 2 * g->ph;
    *Wp = wp;
}

/* yp = bias + sum over taps of wk * the padded plane buf, 3x3 taps (weights in registers). */
static void stencil_plane_3x3(const lm_conv_geom *g, const float *buf, int Wp, const float *wk,
                              float bv, float *yp)
{
    const float w0 = wk[0], w1 = wk[1], w2 = wk[2], w3 = wk[3], w4 = wk[4], w5 = wk[5],
                w6 = wk[6], w7 = wk[7], w8 = wk[8];
    for (int oy = 0; oy < g->Ho; oy++) {
        const float *r0 = buf + (long)oy * Wp, *r1 = r0 + Wp, *r2 = r1 + Wp;
        float *d = yp + (long)oy * g->Wo;
        for (int x0 = 0; x0 < g->Wo; x0 += LM_VLN) {
            lm_vfn acc = (lm_vfn){0} + bv;
            acc += w0 * lm_loadn(r0 + x0);
            acc += w1 * lm_loadn(r0 + x0 + 1);
            acc += w2 * lm_loadn(r0 + x0 + 2);
            acc += w3 * lm_loadn(r1 + x0);
            acc += w4 * lm_loadn(r1 + x0 + 1);
            acc += w5 * lm_loadn(r1 + x0 + 2);
            acc += w6 * lm_loadn(r2 + x0);
            acc += w7 * lm_loadn(r2 + x0 + 1);
            acc += w8 * lm_loadn(r2 + x0 + 2);
            lm_storen(d + x0, acc, g->Wo - x0 < LM_VLN ? g->Wo - x0 : LM_VLN);
        }
    }
}

/* The same for any kernel size (explicit fmaf, as the per-tap loops are contracted). */
static void stencil_plane(const lm_conv_geom *g, const float *buf, int Wp, const float *wk,
                          float bv, float *yp)
{
    for (int oy = 0; oy < g->Ho; oy++) {
        float *d = yp + (long)oy * g->Wo;
        for (int x0 = 0; x0 < g->Wo; x0 += LM_VLN) {
            float acc[LM_VLN];
            for (int l = 0; l < LM_VLN; l++) acc[l] = bv;
            for (int i = 0; i < g->kh; i++) {
                const float *r = buf + (long)(oy + i) * Wp + x0;
                for (int j = 0; j < g->kw; j++) {
                    const float wv = wk[i * g->kw + j];
#pragma omp simd
                    for (int l = 0; l < LM_VLN; l++) acc[l] = fmaf(wv, r[j + l], acc[l]);
                }
            }
            int n = g->Wo - x0 < LM_VLN ? g->Wo - x0 : LM_VLN;
            memcpy(d + x0, acc, sizeof(float) * (size_t)n);
        }
    }
}

static int stencil_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                       const float *bias, float *y)
{
    int mult = g->Cout / g->Cin, khw = g->kh * g->kw, nt = lm_nthreads(c), Hp, Wp;
    stencil_dims(g, &Hp, &Wp);
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo, planes = (long)g->B * g->Cout;
    long pad = (long)Hp * Wp;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *bufs = lm_ctx_alloc(c, sizeof(float) * (size_t)pad * (size_t)nt);
    if (!bufs) return c->status;
#pragma omp parallel num_threads(nt)
    {
        float *buf = bufs + pad * omp_get_thread_num();
        const float *held = NULL; /* the input plane now in buf */
        memset(buf, 0, sizeof(float) * (size_t)pad);
#pragma omp for schedule(static)
        for (long pl = 0; pl < planes; pl++) {
            int b = (int)(pl / g->Cout), co = (int)(pl % g->Cout);
            const float *xp = x + ((long)b * g->Cin + co / mult) * hw;
            if (xp != held) {
                for (int iy = 0; iy < g->H; iy++)
                    memcpy(buf + (long)(iy + g->ph) * Wp + g->pw, xp + (long)iy * g->W,
                           sizeof(float) * (size_t)g->W);
                held = xp;
            }
            const float *wk = w + (long)co * khw;
            float bv = bias ? bias[co] : 0.0f;
            if (g->kh == 3 && g->kw == 3) stencil_plane_3x3(g, buf, Wp, wk, bv, y + pl * ohw);
            else stencil_plane(g, buf, Wp, wk, bv, y + pl * ohw);
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

int lm_conv2d_dw_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                     const float *bias, float *y)
{
    if (stencil_applies(c, g)) return stencil_fwd(c, g, x, w, bias, y);
    int mult = g->Cout / g->Cin, khw = g->kh * g->kw;
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo, planes = (long)g->B * g->Cout;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long pl = 0; pl < planes; pl++) {
        int b = (int)(pl / g->Cout), co = (int)(pl % g->Cout);
        fwd_plane(g, x + ((long)b * g->Cin + co / mult) * hw, w + (long)co * khw,
                  bias ? bias[co] : 0.0f, y + pl * ohw);
    }
    return 0;
}

/* dxp (H x W) += wv * dyp scattered back through tap (i, j): the adjoint of tap_fwd. */
static void tap_bwd_x(const lm_conv_geom *g, const float *restrict dyp, float wv, int i, int j,
                      float *restrict dxp)
{
    int lo, hi;
    lm_conv_valid_range(g->Wo, g->W, g->sw, g->pw, j * g->dw, &lo, &hi);
    for (int oy = 0; oy < g->Ho; oy++) {
        int iy = oy * g->sh - g->ph + i * g->dh;
        if (iy < 0 || iy >= g->H) continue;
        const float *restrict s = dyp + (long)oy * g->Wo;
        float *restrict d = dxp + (long)iy * g->W + j * g->dw - g->pw;
        if (g->sw == 1) {
#pragma omp simd
            for (int ox = lo; ox < hi; ox++) d[ox] += wv * s[ox];
        } else {
            for (int ox = lo; ox < hi; ox++) d[(long)ox * g->sw] += wv * s[ox];
        }
    }
}

/* Stride-1 input gradient with one output channel per input channel: dx += the stencil of
 * dy (padded by k - 1 - p) with the kernel rotated 180 degrees, into a per-thread plane that
 * is then added to dx. Sums the taps before adding (the per-tap loops add tap by tap), so it
 * agrees with them to rounding. */
static int stencil_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                         float *dx)
{
    lm_conv_geom r = *g; /* the adjoint as a forward: dy (Ho x Wo) -> dx (H x W) */
    r.H = g->Ho, r.W = g->Wo, r.Ho = g->H, r.Wo = g->W;
    r.ph = g->kh - 1 - g->ph, r.pw = g->kw - 1 - g->pw;
    int khw = g->kh * g->kw, nt = lm_nthreads(c), Hp, Wp;
    stencil_dims(&r, &Hp, &Wp);
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo, planes = (long)g->B * g->Cin;
    long pad = (long)Hp * Wp, per = pad + hw + khw;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *bufs = lm_ctx_alloc(c, sizeof(float) * (size_t)per * (size_t)nt);
    if (!bufs) return c->status;
#pragma omp parallel num_threads(nt)
    {
        float *buf = bufs + per * omp_get_thread_num(), *tmp = buf + pad, *wr = tmp + hw;
        memset(buf, 0, sizeof(float) * (size_t)pad);
#pragma omp for schedule(static)
        for (long pl = 0; pl < planes; pl++) {
            int ci = (int)(pl % g->Cin);
            const float *dyp = dy + pl * ohw;
            for (int oy = 0; oy < g->Ho; oy++)
                memcpy(buf + (long)(oy + r.ph) * Wp + r.pw, dyp + (long)oy * g->Wo,
                       sizeof(float) * (size_t)g->Wo);
            for (int t = 0; t < khw; t++) wr[t] = w[(long)ci * khw + khw - 1 - t];
            if (g->kh == 3 && g->kw == 3) stencil_plane_3x3(&r, buf, Wp, wr, 0.0f, tmp);
            else stencil_plane(&r, buf, Wp, wr, 0.0f, tmp);
            float *d = dx + pl * hw;
#pragma omp simd
            for (long p = 0; p < hw; p++) d[p] += tmp[p];
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

int lm_conv2d_dw_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                       float *dx)
{
    if (stencil_applies(c, g) && g->Cout == g->Cin && g->ph < g->kh && g->pw < g->kw)
        return stencil_bwd_x(c, g, dy, w, dx);
    int mult = g->Cout / g->Cin, khw = g->kh * g->kw;
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo, planes = (long)g->B * g->Cin;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long pl = 0; pl < planes; pl++) {
        int b = (int)(pl / g->Cin), ci = (int)(pl % g->Cin);
        for (int m = 0; m < mult; m++) {
            int co = ci * mult + m;
            for (int tap = 0; tap < khw; tap++)
                tap_bwd_x(g, dy + ((long)b * g->Cout + co) * ohw, w[(long)co * khw + tap],
                          tap / g->kw, tap % g->kw, dx + pl * hw);
        }
    }
    return 0;
}

/* sum over output pixels of dyp * (input shifted by tap (i, j)) for one plane pair. Column
 * ox accumulates in acc[ox] (Wo floats of scratch) over the rows, summed in double at the
 * end: no horizontal reduction per row. */
static double tap_dot(const lm_conv_geom *g, const float *restrict dyp, const float *restrict xp,
                      int i, int j, float *restrict acc)
{
    int lo, hi;
    lm_conv_valid_range(g->Wo, g->W, g->sw, g->pw, j * g->dw, &lo, &hi);
    for (int ox = lo; ox < hi; ox++) acc[ox] = 0.0f;
    for (int oy = 0; oy < g->Ho; oy++) {
        int iy = oy * g->sh - g->ph + i * g->dh;
        if (iy < 0 || iy >= g->H) continue;
        const float *restrict s = xp + (long)iy * g->W + j * g->dw - g->pw;
        const float *restrict d = dyp + (long)oy * g->Wo;
        if (g->sw == 1) {
#pragma omp simd
            for (int ox = lo; ox < hi; ox++) acc[ox] += d[ox] * s[ox];
        } else {
            for (int ox = lo; ox < hi; ox++) acc[ox] += d[ox] * s[(long)ox * g->sw];
        }
    }
    double sum = 0.0;
    for (int ox = lo; ox < hi; ox++) sum += acc[ox];
    return sum;
}

/* Stride-1 3x3 weight gradient: one pass over each (dy, padded x) plane pair with the nine
 * taps' products accumulated in nine vector registers (lane l sums the columns l mod VL over
 * all rows and images), summed across lanes in double at the end, per output channel. Agrees
 * with the per-tap loops to rounding. */
static int stencil_bwd_w_3x3(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                             float *dw)
{
    int mult = g->Cout / g->Cin, nt = lm_nthreads(c), Hp, Wp;
    stencil_dims(g, &Hp, &Wp);
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo, pad = (long)Hp * Wp;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *bufs = lm_ctx_alloc(c, sizeof(float) * (size_t)pad * (size_t)nt);
    if (!bufs) return c->status;
#pragma omp parallel num_threads(nt)
    {
        float *buf = bufs + pad * omp_get_thread_num();
        memset(buf, 0, sizeof(float) * (size_t)pad);
#pragma omp for schedule(static)
        for (int co = 0; co < g->Cout; co++) {
            lm_vfn acc[9];
            for (int t = 0; t < 9; t++) acc[t] = (lm_vfn){0};
            for (int b = 0; b < g->B; b++) {
                const float *xp = x + ((long)b * g->Cin + co / mult) * hw;
                const float *dyp = dy + ((long)b * g->Cout + co) * ohw;
                for (int iy = 0; iy < g->H; iy++)
                    memcpy(buf + (long)(iy + g->ph) * Wp + g->pw, xp + (long)iy * g->W,
                           sizeof(float) * (size_t)g->W);
                for (int oy = 0; oy < g->Ho; oy++) {
                    const float *r0 = buf + (long)oy * Wp, *r1 = r0 + Wp, *r2 = r1 + Wp;
                    const float *drow = dyp + (long)oy * g->Wo;
                    for (int x0 = 0; x0 < g->Wo; x0 += LM_VLN) {
                        lm_vfn d;
                        if (g->Wo - x0 >= LM_VLN) {
                            d = lm_loadn(drow + x0);
                        } else {
                            float t[LM_VLN] = {0};
                            memcpy(t, drow + x0, sizeof(float) * (size_t)(g->Wo - x0));
                            d = lm_loadn(t);
                        }
                        acc[0] += d * lm_loadn(r0 + x0);
                        acc[1] += d * lm_loadn(r0 + x0 + 1);
                        acc[2] += d * lm_loadn(r0 + x0 + 2);
                        acc[3] += d * lm_loadn(r1 + x0);
                        acc[4] += d * lm_loadn(r1 + x0 + 1);
                        acc[5] += d * lm_loadn(r1 + x0 + 2);
                        acc[6] += d * lm_loadn(r2 + x0);
                        acc[7] += d * lm_loadn(r2 + x0 + 1);
                        acc[8] += d * lm_loadn(r2 + x0 + 2);
                    }
                }
            }
            for (int t = 0; t < 9; t++) {
                double sum = 0.0;
                for (int l = 0; l < LM_VLN; l++) sum += acc[t][l];
                dw[(long)co * 9 + t] += (float)sum;
            }
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

int lm_conv2d_dw_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                       float *dw)
{
    if (stencil_applies(c, g) && g->kh == 3 && g->kw == 3) return stencil_bwd_w_3x3(c, g, dy, x, dw);
    int mult = g->Cout / g->Cin, khw = g->kh * g->kw, nt = lm_nthreads(c);
    long hw = (long)g->H * g->W, ohw = (long)g->Ho * g->Wo;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *scratch = lm_ctx_alloc(c, sizeof(float) * (size_t)g->Wo * (size_t)nt);
    if (!scratch) return c->status;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int co = 0; co < g->Cout; co++) {
        float *acc = scratch + (long)g->Wo * omp_get_thread_num();
        for (int tap = 0; tap < khw; tap++) {
            double sum = 0.0;
            for (int b = 0; b < g->B; b++)
                sum += tap_dot(g, dy + ((long)b * g->Cout + co) * ohw,
                               x + ((long)b * g->Cin + co / mult) * hw, tap / g->kw, tap % g->kw,
                               acc);
            dw[(long)co * khw + tap] += (float)sum;
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}
