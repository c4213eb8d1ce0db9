/* conv2d_pointwise.c — forward CPU path of 1x1 stride-1 unpadded convolutions with one group
 * (SRNet's and MST++'s projections, the heads of the real-time models): per image, y = bias
 * + W x is a product of the Cout x Cin weights with the Cin x H*W image read in place, done
 * by lm_sgemm_panel on column blocks (weights packed once per call). Work items (image,
 * column block) are split statically over the threads; each output element is one sum in a
 * fixed order (bias, then input channels ascending), so results do not depend on the thread
 * count. The input gradient is the same product with the transposed weights, added into dx.
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

int lm_conv2d_pointwise_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                            const float *bias, float *y)
{
    long hw = (long)g->H * g->W, nblk = (hw + NB - 1) / NB, items = g->B * nblk;
    int nt = lm_nthreads(c);
    if (items < nt) nt = (int)items;
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *wp = lm_ctx_alloc(c, sizeof(float) * (size_t)lm_panel_size(g->Cout, g->Cin));
    if (!wp) return c->status;
    lm_panel_pack(g->Cout, g->Cin, w, g->Cin, wp);
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        for (int t = omp_get_thread_num(); t < nt; t += nthr)
            for (long it = items * t / nt; it < items * (t + 1) / nt; it++) {
                long b = it / nblk, j0 = it % nblk * NB;
                int n = hw - j0 < NB ? (int)(hw - j0) : NB;
                lm_sgemm_panel(g->Cout, n, g->Cin, wp, x + b * g->Cin * hw + j0, hw, bias, 0,
                               y + b * g->Cout * hw + j0, hw);
            }
    }
    lm_arena_rewind(&c->arena, mk);
    return 0;
}

int lm_conv2d_pointwise_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                              float *dx)
{
    long hw = (long)g->H * g->W, nblk = (hw + NB - 1) / NB, items = g->B * nblk;
    int nt = lm_nthreads(c);
    if (items < nt) nt = (int)items;
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *wp = lm_ctx_alloc(c, sizeof(float) * (size_t)lm_panel_size(g->Cin, g->Cout));
    if (!wp) return c->status;
    memset(wp, 0, sizeof(float) * (size_t)lm_panel_size(g->Cin, g->Cout));
    for (int co = 0; co < g->Cout; co++) /* W^T: row ci, column co */
        for (int ci = 0; ci < g->Cin; ci++)
            wp[lm_panel_at(g->Cout, ci, co)] = w[(long)co * g->Cin + ci];
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        for (int t = omp_get_thread_num(); t < nt; t += nthr)
            for (long it = items * t / nt; it < items * (t + 1) / nt; it++) {
                long b = it / nblk, j0 = it % nblk * NB;
                int n = hw - j0 < NB ? (int)(hw - j0) : NB;
                lm_sgemm_panel(g->Cin, n, g->Cout, wp, dy + b * g->Cout * hw + j0, hw, NULL, 1,
                               dx + b * g->Cin * hw + j0, hw);
            }
    }
    lm_arena_rewind(&c->arena, mk);
    return 0;
}
