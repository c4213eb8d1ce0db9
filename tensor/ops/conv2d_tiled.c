/* conv2d_tiled.c — the fast CPU path of conv2d: im2col + GEMM over spatial tiles.
 * What it is: the output pixels of each (image, group) are cut into tiles of n consecutive
 * pixels and the K = Cin/groups*kh*kw rows of the column matrix into chunks of kr rows, so
 * that one column buffer (kr x n floats) stays in the L2 cache while n stays wide enough for
 * an efficient GEMM (most layers have a single chunk); each OpenMP thread owns a fixed range
 * of work items and its own column buffer and calls single-threaded sgemm on it:
 *   forward        y_tile += W_g[:, chunk] col_chunk  (bias written first: the GEMM fuses it)
 *   weight grad    dW_part[thread][:, chunk] += dy_tile col_chunk^T, partials added in
 *                  thread order
 *   input grad     colg = W_g[:, chunk]^T dy_tile, then col2im += into dx; work items are
 *                  (image, group, channel block), so no two threads write the same dx element.
 * 1x1 stride-1 unpadded convs skip im2col (the image is already the column matrix).
 * What it is not: the reference (conv2d.c, compared against this in tests) nor the depthwise
 * path (conv2d_depthwise.c). Results depend only on the thread count. */
#include "tensor/ops/gemm_internal.h"
#include <omp.h>
#include <string.h>

/* Target size of one thread's column buffer (about 40% of a 1 MiB L2), and the narrowest
 * tile worth a GEMM call. */
#define COL_FLOATS (96 * 1024)
#define MIN_TILE 256

typedef struct tiling {
    int G, cig, cog, K, hw;  /* K = cig*kh*kw rows of the column matrix; hw = Ho*Wo pixels */
    int n, ntiles;           /* tile width in pixels, tiles per (image, group) */
    int kr;                  /* rows per chunk of the column matrix */
    int pointwise;           /* 1x1, stride 1, no padding: columns = the image itself */
} tiling;

/* n = ceil(total / parts) rounded up to `align`, at most total. */
static int even_split(int total, int parts, int align)
{
    int n = (total + parts - 1) / parts;
    n = (n + align - 1) / align * align;
    return n < total ? n : total;
}

/* Tiles of at least MIN_TILE pixels (all of them if fewer), equal up to 16; then chunks of
 * rows so that a chunk x tile buffer holds about COL_FLOATS. */
static tiling make_tiling(const lm_conv_geom *g)
{
    tiling t;
    t.G = g->groups, t.cig = g->Cin / t.G, t.cog = g->Cout / t.G;
    t.K = t.cig * g->kh * g->kw, t.hw = g->Ho * g->Wo;
    t.pointwise = g->kh == 1 && g->kw == 1 && g->sh == 1 && g->sw == 1 && g->ph == 0 &&
                  g->pw == 0;
    long n = COL_FLOATS / t.K;
    if (n < MIN_TILE) n = MIN_TILE;
    if (n > t.hw) n = t.hw;
    t.n = even_split(t.hw, (int)((t.hw + n - 1) / n), 16);
    t.ntiles = (t.hw + t.n - 1) / t.n;
    int kr = t.pointwise ? t.K : COL_FLOATS / t.n;
    if (kr < 16) kr = 16;
    t.kr = even_split(t.K, (t.K + kr - 1) / kr, 8);
    return t;
}

/* col (rows [r0, r0+nr) of the im2col matrix, ld n) = patches of output pixels [p0, p0+n)
 * of one image group xg (cig x H x W). Writes = (zeros where the patch is outside). */
static void im2col_tile(const lm_conv_geom *g, const float *xg, int r0, int nr, int p0, int n,
                        float *col)
{
    int khw = g->kh * g->kw;
    for (int r = r0; r < r0 + nr; r++) {
        int ci = r / khw, i = (r / g->kw) % g->kh, j = r % g->kw, lo, hi;
        lm_conv_valid_range(g->Wo, g->W, g->sw, g->pw, j * g->dw, &lo, &hi);
        const float *src = xg + (long)ci * g->H * g->W + j * g->dw - g->pw;
        float *dst = col + (long)(r - r0) * n - p0;
        for (int p = p0; p < p0 + n;) {
            int oy = p / g->Wo, ox0 = p % g->Wo;
            int ox1 = g->Wo < ox0 + (p0 + n - p) ? g->Wo : ox0 + (p0 + n - p);
            int iy = oy * g->sh - g->ph + i * g->dh;
            float *d = dst + (long)oy * g->Wo;
            if (iy < 0 || iy >= g->H) {
                memset(d + ox0, 0, sizeof(float) * (size_t)(ox1 - ox0));
            } else {
                const float *s = src + (long)iy * g->W;
                int a = lo > ox0 ? lo : ox0, b = hi < ox1 ? hi : ox1;
                if (b < a) b = a;
                for (int ox = ox0; ox < a; ox++) d[ox] = 0.0f;
                if (g->sw == 1) memcpy(d + a, s + a, sizeof(float) * (size_t)(b - a));
                else
                    for (int ox = a; ox < b; ox++) d[ox] = s[(long)ox * g->sw];
                for (int ox = b; ox < ox1; ox++) d[ox] = 0.0f;
            }
            p += ox1 - ox0;
        }
    }
}

/* dxg (one image group) += col2im of rows [r0, r0+nr) of a column tile (ld n) for output
 * pixels [p0, p0+n): the adjoint of im2col_tile. */
static void col2im_tile(const lm_conv_geom *g, const float *col, int r0, int nr, int p0, int n,
                        float *dxg)
{
    int khw = g->kh * g->kw;
    for (int r = r0; r < r0 + nr; r++) {
        int ci = r / khw, i = (r / g->kw) % g->kh, j = r % g->kw, lo, hi;
        lm_conv_valid_range(g->Wo, g->W, g->sw, g->pw, j * g->dw, &lo, &hi);
        float *dst = dxg + (long)ci * g->H * g->W + j * g->dw - g->pw;
        const float *src = col + (long)(r - r0) * n - p0;
        for (int p = p0; p < p0 + n;) {
            int oy = p / g->Wo, ox0 = p % g->Wo;
            int ox1 = g->Wo < ox0 + (p0 + n - p) ? g->Wo : ox0 + (p0 + n - p);
            int iy = oy * g->sh - g->ph + i * g->dh;
            p += ox1 - ox0;
            if (iy < 0 || iy >= g->H) continue;
            const float *s = src + (long)oy * g->Wo;
            float *d = dst + (long)iy * g->W;
            int a = lo > ox0 ? lo : ox0, b = hi < ox1 ? hi : ox1;
            if (g->sw == 1) {
#pragma omp simd
                for (int ox = a; ox < b; ox++) d[ox] += s[ox];
            } else {
                for (int ox = a; ox < b; ox++) d[(long)ox * g->sw] += s[ox];
            }
        }
    }
}

/* Logical part t of nt over [0, items). */
static void part(long items, int nt, int t, long *i0, long *i1)
{
    *i0 = items * t / nt;
    *i1 = items * (t + 1) / nt;
}

static void sgemm(int ta, int tb, int M, int N, int K, const float *A, int lda, const float *B,
                  int ldb, float beta, float *C, int ldc)
{
    lm_sgemm_st(ta, tb, M, N, K, 1.0f, A, lda, B, ldb, beta, C, ldc);
}

/* ---- forward --------------------------------------------------------------------------- */
static void fwd_item(const lm_conv_geom *g, const tiling *tl, long it, const float *x,
                     const float *w, const float *bias, float *y, float *col)
{
    int tile = (int)(it % tl->ntiles), q = (int)(it / tl->ntiles % tl->G);
    int b = (int)(it / tl->ntiles / tl->G);
    int p0 = tile * tl->n, n = tl->hw - p0 < tl->n ? tl->hw - p0 : tl->n;
    const float *xg = x + ((long)b * g->Cin + (long)q * tl->cig) * g->H * g->W;
    const float *wg = w + (long)q * tl->cog * tl->K;
    float *yt = y + ((long)b * g->Cout + (long)q * tl->cog) * tl->hw + p0;
    for (int o = 0; bias && o < tl->cog; o++) {
        float v = bias[q * tl->cog + o], *row = yt + (long)o * tl->hw;
        for (int p = 0; p < n; p++) row[p] = v;
    }
    if (tl->pointwise) {
        sgemm(0, 0, tl->cog, n, tl->K, wg, tl->K, xg + p0, tl->hw, bias ? 1.0f : 0.0f, yt,
              tl->hw);
        return;
    }
    for (int r0 = 0; r0 < tl->K; r0 += tl->kr) {
        int nr = tl->K - r0 < tl->kr ? tl->K - r0 : tl->kr;
        im2col_tile(g, xg, r0, nr, p0, n, col);
        sgemm(0, 0, tl->cog, n, nr, wg + r0, tl->K, col, n, (bias || r0) ? 1.0f : 0.0f, yt,
              tl->hw);
    }
}

int lm_conv2d_tiled_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                        const float *bias, float *y)
{
    int nt = lm_nthreads(c);
    tiling tl = make_tiling(g);
    long items = (long)g->B * tl.G * tl.ntiles;
    if (items < nt) nt = (int)items;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    size_t per = (size_t)tl.kr * (size_t)tl.n;
    float *cols = tl.pointwise ? NULL : lm_ctx_alloc(c, sizeof(float) * per * (size_t)nt);
    if (!tl.pointwise && !cols) return c->status;
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        for (int t = omp_get_thread_num(); t < nt; t += nthr) {
            long i0, i1;
            part(items, nt, t, &i0, &i1);
            for (long it = i0; it < i1; it++)
                fwd_item(g, &tl, it, x, w, bias, y, cols ? cols + per * (size_t)t : NULL);
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

/* ---- weight gradient ------------------------------------------------------------------- */
static void bwd_w_item(const lm_conv_geom *g, const tiling *tl, long it, const float *dy,
                       const float *x, float *dwp, float *col)
{
    int tile = (int)(it % tl->ntiles), q = (int)(it / tl->ntiles % tl->G);
    int b = (int)(it / tl->ntiles / tl->G);
    int p0 = tile * tl->n, n = tl->hw - p0 < tl->n ? tl->hw - p0 : tl->n;
    const float *xg = x + ((long)b * g->Cin + (long)q * tl->cig) * g->H * g->W;
    const float *dyt = dy + ((long)b * g->Cout + (long)q * tl->cog) * tl->hw + p0;
    float *dwg = dwp + (long)q * tl->cog * tl->K;
    if (tl->pointwise) {
        sgemm(0, 1, tl->cog, tl->K, n, dyt, tl->hw, xg + p0, tl->hw, 1.0f, dwg, tl->K);
        return;
    }
    for (int r0 = 0; r0 < tl->K; r0 += tl->kr) {
        int nr = tl->K - r0 < tl->kr ? tl->K - r0 : tl->kr;
        im2col_tile(g, xg, r0, nr, p0, n, col);
        sgemm(0, 1, tl->cog, nr, n, dyt, tl->hw, col, n, 1.0f, dwg + r0, tl->K);
    }
}

int lm_conv2d_tiled_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                          float *dw)
{
    int nt = lm_nthreads(c);
    tiling tl = make_tiling(g);
    long items = (long)g->B * tl.G * tl.ntiles, nw = (long)g->Cout * tl.K;
    if (items < nt) nt = (int)items;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    size_t per = tl.pointwise ? 0 : (size_t)tl.kr * (size_t)tl.n;
    float *cols = lm_ctx_alloc(c, sizeof(float) * (per + (size_t)nw) * (size_t)nt);
    if (!cols) return c->status;
    float *parts = cols + per * (size_t)nt;
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        for (int t = omp_get_thread_num(); t < nt; t += nthr) {
            long i0, i1;
            float *dwp = parts + (size_t)nw * (size_t)t;
            memset(dwp, 0, sizeof(float) * (size_t)nw);
            part(items, nt, t, &i0, &i1);
            for (long it = i0; it < i1; it++)
                bwd_w_item(g, &tl, it, dy, x, dwp, cols + per * (size_t)t);
        }
#pragma omp barrier
        /* dw += partials in thread order; elements split over threads */
        long e0, e1;
        part(nw, nthr, omp_get_thread_num(), &e0, &e1);
        for (int t = 0; t < nt; t++) {
            const float *src = parts + (size_t)nw * (size_t)t;
#pragma omp simd
            for (long e = e0; e < e1; e++) dw[e] += src[e];
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

/* ---- input gradient -------------------------------------------------------------------- */
/* Work item (image b, group q, channel block): channels [c0, c1) of dx for all pixels. */
static void bwd_x_item(const lm_conv_geom *g, const tiling *tl, int b, int q, int c0, int c1,
                       const float *dy, const float *w, float *dx, float *col)
{
    int khw = g->kh * g->kw, r0 = c0 * khw, nr = (c1 - c0) * khw;
    const float *wg = w + (long)q * tl->cog * tl->K;
    const float *dyg = dy + ((long)b * g->Cout + (long)q * tl->cog) * tl->hw;
    float *dxg = dx + ((long)b * g->Cin + (long)q * tl->cig) * g->H * g->W;
    if (tl->pointwise) { /* dx rows are the column rows: accumulate in place */
        sgemm(1, 0, nr, tl->hw, tl->cog, wg + r0, tl->K, dyg, tl->hw, 1.0f,
              dxg + (long)c0 * tl->hw, tl->hw);
        return;
    }
    for (int tile = 0; tile < tl->ntiles; tile++) {
        int p0 = tile * tl->n, n = tl->hw - p0 < tl->n ? tl->hw - p0 : tl->n;
        for (int r = r0; r < r0 + nr; r += tl->kr) {
            int m = r0 + nr - r < tl->kr ? r0 + nr - r : tl->kr;
            sgemm(1, 0, m, n, tl->cog, wg + r, tl->K, dyg + p0, tl->hw, 0.0f, col, n);
            col2im_tile(g, col, r, m, p0, n, dxg);
        }
    }
}

int lm_conv2d_tiled_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                          float *dx)
{
    int nt = lm_nthreads(c);
    tiling tl = make_tiling(g);
    long bg = (long)g->B * tl.G;
    int nblk = (int)((4L * nt + bg - 1) / bg);
    if (nblk > tl.cig) nblk = tl.cig;
    long items = bg * nblk;
    if (items < nt) nt = (int)items;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    size_t per = tl.pointwise ? 0 : (size_t)tl.kr * (size_t)tl.n;
    float *cols = per ? lm_ctx_alloc(c, sizeof(float) * per * (size_t)nt) : NULL;
    if (per && !cols) return c->status;
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        for (int t = omp_get_thread_num(); t < nt; t += nthr) {
            long i0, i1;
            part(items, nt, t, &i0, &i1);
            for (long it = i0; it < i1; it++) {
                int k = (int)(it % nblk), q = (int)(it / nblk % tl.G), b = (int)(it / nblk / tl.G);
                int c0 = (int)((long)tl.cig * k / nblk), c1 = (int)((long)tl.cig * (k + 1) / nblk);
                bwd_x_item(g, &tl, b, q, c0, c1, dy, w, dx, cols ? cols + per * (size_t)t : NULL);
            }
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}
