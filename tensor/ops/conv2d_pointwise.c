/* conv2d_pointwise.c — forward CPU path of 1x1 stride-1 unpadded convolutions with one group
 * (SRNet's and MST++'s projections, the heads of the real-time models): per image, y = bias
 * + W x is a product of the Cout x Cin weights with the Cin x H*W image read in place, done
 * by lm_sgemm_panel on column blocks (weights packed once per call). Work items (image,
 * column block) are handed to threads as they come free (a thread slowed by another process
 * on its core takes fewer); each output element is one sum in a fixed order (bias, then input
 * channels ascending) by whichever thread, so results do not depend on the thread count. The input gradient is the same product with the transposed weights, added into dx.
 * What it is not: the weight gradient (the tiled path's pointwise GEMM does it: its
 * reduction runs over the pixels, a shape OpenBLAS handles well). */
#include "tensor/ops/gemm_internal.h"
#include <omp.h>
#include <string.h>

#define NB 512 /* columns per work item (a multiple of 16) */

int lm_conv2d_pointwise_applies(const lm_conv_geom *g)
{
    return g->kh == 1 && g->kw == 1 && g->sh == 1 && g->sw == 1 && g->ph == 0 && g->pw == 0 &&
           g->groups == 1;
}

/* Per image b and column block: out_b (M x hw) = bias + Ap in_b or += Ap in_b, with in_b
 * (K x hw) read in place; work items handed out dynamically. */
static void run_blocks(lm_ctx *c, int B, long hw, int M, int K, const float *Ap,
                       const float *in, const float *bias, int accumulate, float *out)
{
    long nblk = (hw + NB - 1) / NB, items = B * nblk;
    int nt = lm_nthreads(c);
    if (items < nt) nt = (int)items;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
    for (long it = 0; it < items; it++) {
        long b = it / nblk, j0 = it % nblk * NB;
        int n = hw - j0 < NB ? (int)(hw - j0) : NB;
        lm_sgemm_panel(M, n, K, Ap, in + b * K * hw + j0, hw, bias, accumulate,
                       out + b * M * hw + j0, hw);
    }
}

int lm_conv2d_pointwise_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                            const float *bias, float *y)
{
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *wp = lm_ctx_alloc(c, sizeof(float) * (size_t)lm_panel_size(g->Cout, g->Cin));
    if (!wp) return c->status;
    lm_panel_pack(g->Cout, g->Cin, w, g->Cin, wp);
    run_blocks(c, g->B, (long)g->H * g->W, g->Cout, g->Cin, wp, x, bias, 0, y);
    lm_arena_rewind(&c->arena, mk);
    return 0;
}

int lm_conv2d_pointwise_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                              float *dx)
{
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *wp = lm_ctx_alloc(c, sizeof(float) * (size_t)lm_panel_size(g->Cin, g->Cout));
    if (!wp) return c->status;
    memset(wp, 0, sizeof(float) * (size_t)lm_panel_size(g->Cin, g->Cout));
    for (int co = 0; co < g->Cout; co++) /* W^T: row ci, column co */
        for (int ci = 0; ci < g->Cin; ci++)
            wp[lm_panel_at(g->Cout, ci, co)] = w[(long)co * g->Cin + ci];
    run_blocks(c, g->B, (long)g->H * g->W, g->Cin, g->Cout, wp, dy, NULL, 1, dx);
    lm_arena_rewind(&c->arena, mk);
    return 0;
}
