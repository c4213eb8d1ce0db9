/* conv2d_depthwise.c — direct-loop CPU path of conv2d when every group has one input channel
 * (groups == Cin; Cout = m*Cin, output channel co reads input channel co / m).
 * What it is: no im2col, no GEMM (a depthwise "GEMM" has inner size kh*kw only): for each
 * kernel tap, a row of the output gets w * a shifted row of the input, vectorised along the
 * row. Parallel over planes: forward over (image, output channel), input gradient over
 * (image, input channel), weight gradient over output channels; each element is written by
 * one thread in a fixed order, so results do not depend on the thread count.
 * What it is not: the general path (conv2d_tiled.c) or the reference (conv2d.c). */
#include "tensor/ops/gemm_internal.h"
#include <omp.h>

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

int lm_conv2d_dw_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                     const float *bias, float *y)
{
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

int lm_conv2d_dw_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                       float *dx)
{
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

int lm_conv2d_dw_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                       float *dw)
{
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
