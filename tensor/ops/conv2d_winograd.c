/* conv2d_winograd.c — Winograd F(4x4, 3x3) CPU path of conv2d: 3x3 kernels, stride 1,
 * dilation 1, one group, padding 0..2, enough channels (the HAN/MCAN body convolutions).
 * What it is: the output is cut into 4 x 4 tiles; each tile needs a 6 x 6 input patch d,
 * and Y = A^T [(G g G^T) (.) (B^T d B)] A (Lavin & Gray 2016, points 0, +-1, +-2, inf), so
 * the 36 products per (output channel, input channel) of a tile become 36 independent
 * GEMMs over channels: M_xi (Cout x tiles) = U_xi (Cout x Cin) V_xi (Cin x tiles),
 * 144 -> 36 multiplies per 16 outputs. Tiles are processed in chunks small enough to stay
 * in cache (input transform -> 36 GEMMs -> output transform, per chunk, one thread per
 * chunk), so nothing of size 36/16 x the image is ever stored.
 *   forward      y = bias + conv(x, w)
 *   input grad   dx += conv(dy, w') with w'[ci][co] = w[co][ci] rotated 180 degrees and
 *                padding 2 - p (the same forward code, accumulating)
 *   weight grad  dw += G^T [sum over tiles (A dY A^T) (.) (B^T d B)] G: per chunk the 36
 *                products dU_xi += Mdy_xi V_xi^T go into the partial of the chunk's group
 *                (up to 4 per thread), the partials added in group order.
 * The transforms run on VL tiles at a time (one per vector lane: 16 with AVX-512, else 8).
 * Chunks (and the weight gradient's groups of chunks) are handed out to threads as they come
 * free, so a thread that shares its core with another process takes fewer; every output
 * element is still computed by one thread in a fixed order, so results depend only on the
 * thread count.
 * Accuracy: a few 1e-6 relative to the magnitude of the sums (tested against the reference).
 * What it is not: strided, dilated, grouped or non-3x3 convolution (conv2d_tiled.c). */
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/simd.h"
#include "tensor/ops/gemm_bf16.h"
#include "tensor/ops/wcache.h"
#include "tensor/isa.h"
#if defined(__AVX__) || defined(__AVX512F__)
#include <immintrin.h>
#endif
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Lanes: one tile per lane, as wide as the machine's vectors (16 with AVX-512, else 8). */
#define VL LM_VLN
typedef lm_vfn wv;
#if LM_VLN == 16
typedef int wvi __attribute__((vector_size(16 * sizeof(int))));
#else
typedef int wvi __attribute__((vector_size(8 * sizeof(int))));
#endif
#if defined(__clang__)
#define WSHUF(a, b, ...) __builtin_shufflevector(a, b, __VA_ARGS__)
#else
#define WSHUF(a, b, ...) __builtin_shuffle(a, b, (wvi){__VA_ARGS__})
#endif

static inline wv wsplat(float x)
{
    wv v = {0};
    for (int i = 0; i < VL; i++) v[i] = x;
    return v;
}

static inline void wstore(float *p, wv v) { memcpy(p, &v, sizeof v); }

/* Tiles per chunk: the transformed input and output of a chunk take 36 x (Cin + Cout) x TC
 * floats (chunk_bytes). Measured with build/bench_conv / bench_train at 1 thread: on Zen 3
 * (512 KiB L2 + 32 MiB L3) 2.5 MB chunks beat 0.3-1.3 MB ones (wider GEMMs amortise their
 * packing; the chunk lives in L3 either way) and 10 MB ones; on a Xeon with 2 MiB of L2 per core,
 * chunks held in L2 with the packed weights win: per 2-thread training step, 2.5 MB -> 1 MB
 * took han-tiny 8-20 % and mcan 7-17 % off, and 1 MB -> 640 KB another 9 % and 3 % (256-640 KB
 * alike; 1.5-2 MB worse). So: 5/16 of the L2 when the L2 holds at least 1 MiB, else 2.5 MB.
 * LM_WINOGRAD_CHUNK_KB overrides it (for tuning on another machine). */
#define CHUNK_BYTES (2560 * 1024)
#define CHUNK_L2_MIN (1024 * 1024)
#define TC_MIN 32
#define TC_MAX 1024

int lm_conv2d_winograd_applies(const lm_conv_geom *g)
{
    return g->kh == 3 && g->kw == 3 && g->sh == 1 && g->sw == 1 && g->dh == 1 && g->dw == 1 &&
           g->groups == 1 && g->ph <= 2 && g->pw <= 2 && g->Cin >= LM_CONV_WINOGRAD_MIN_C &&
           g->Cout >= LM_CONV_WINOGRAD_MIN_C && g->Ho >= 4 && g->Wo >= 4;
}

/* ---- transforms -------------------------------------------------------------------------- */
/* The kernel transform of F(4x4, 3x3) (points 0, +-1, +-2, inf). */
static const double G[6][3] = {{1.0 / 4, 0, 0},           {-1.0 / 6, -1.0 / 6, -1.0 / 6},
                               {-1.0 / 6, 1.0 / 6, -1.0 / 6}, {1.0 / 24, 1.0 / 12, 1.0 / 6},
                               {1.0 / 24, -1.0 / 12, 1.0 / 6}, {0, 0, 1}};

/* U (6x6) = G g G^T for a 3x3 kernel g (row-major, element (i, j) at g[i*si + j*sj]). */
static void weight_transform(const float *g, int si, int sj, float U[36])
{
    double t[6][3];
    for (int a = 0; a < 6; a++)
        for (int j = 0; j < 3; j++)
            t[a][j] = G[a][0] * g[j * sj] + G[a][1] * g[si + j * sj] + G[a][2] * g[2 * si + j * sj];
    for (int a = 0; a < 6; a++)
        for (int b = 0; b < 6; b++)
            U[a * 6 + b] = (float)(t[a][0] * G[b][0] + t[a][1] * G[b][1] + t[a][2] * G[b][2]);
}

/* dg (3x3, added at dg[i*si + j*sj]) += G^T dU G. */
static void weight_transform_adjoint(const float dU[36], float *dg, int si, int sj)
{
    double t[3][6];
    for (int i = 0; i < 3; i++)
        for (int b = 0; b < 6; b++) {
            double s = 0;
            for (int a = 0; a < 6; a++) s += G[a][i] * dU[a * 6 + b];
            t[i][b] = s;
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0;
            for (int b = 0; b < 6; b++) s += t[i][b] * G[b][j];
            dg[i * si + j * sj] += (float)s;
        }
}

/* B^T d along one axis: 6 values in, 6 out (any lane type). */
#define BT6(o, d)                                                                               \
    do {                                                                                        \
        o[0] = 4 * d[0] - 5 * d[2] + d[4];                                                      \
        o[1] = d[3] + d[4] - 4 * (d[1] + d[2]);                                                 \
        o[2] = d[4] - d[3] + 4 * (d[1] - d[2]);                                                 \
        o[3] = d[4] - d[2] + 2 * (d[3] - d[1]);                                                 \
        o[4] = d[4] - d[2] - 2 * (d[3] - d[1]);                                                 \
        o[5] = 4 * d[1] - 5 * d[3] + d[5];                                                      \
    } while (0)

/* A^T m along one axis: 6 values in, 4 out. */
#define AT4(o, m)                                                                               \
    do {                                                                                        \
        wv s12 = m[1] + m[2], d12 = m[1] - m[2], s34 = m[3] + m[4], d34 = m[3] - m[4];          \
        o[0] = m[0] + s12 + s34;                                                                \
        o[1] = d12 + 2 * d34;                                                                   \
        o[2] = s12 + 4 * s34;                                                                   \
        o[3] = d12 + 8 * d34 + m[5];                                                            \
    } while (0)

/* A m along one axis (the adjoint of AT4): 4 values in, 6 out. */
#define A6(o, m)                                                                                \
    do {                                                                                        \
        o[0] = m[0];                                                                            \
        o[1] = m[0] + m[1] + m[2] + m[3];                                                       \
        o[2] = m[0] - m[1] + m[2] - m[3];                                                       \
        o[3] = m[0] + 2 * m[1] + 4 * m[2] + 8 * m[3];                                           \
        o[4] = m[0] - 2 * m[1] + 4 * m[2] - 8 * m[3];                                           \
        o[5] = m[3];                                                                            \
    } while (0)

/* Geometry of the tile grid of one convolution. Tiles are numbered row by row, each row
 * padded to a multiple of VL tiles (txp), so that a group of VL tiles (one per vector lane)
 * always lies in one tile row; tiles past the output's right edge are computed and dropped
 * (they read zeros). Within a group, lane l holds tile LANE_TILE(l) (8 lanes: 0,2,4,6,1,3,5,7;
 * 16: 0,4,8,12,1,5,...): the order an in-register 4 x 4 transpose per 128-bit quarter
 * produces; every transform and the GEMM columns use the same order. */
typedef struct wgrid {
    int C, H, W;        /* input channels and size (the one the patches are read from) */
    int Ho, Wo, ph, pw; /* output size and padding */
    int ty, tx, txp;    /* tiles per column, per row, per row padded to a multiple of VL */
    long T;             /* tiles in all (B * ty * txp) */
} wgrid;

#define LANE_TILE(l) ((VL / 4) * ((l) % 4) + (l) / 4)

static wgrid make_grid(int C, int H, int W, int Ho, int Wo, int ph, int pw, int B)
{
    wgrid r = {C, H, W, Ho, Wo, ph, pw, (Ho + 3) / 4, (Wo + 3) / 4, 0, 0};
    r.txp = (r.tx + VL - 1) / VL * VL;
    r.T = (long)B * r.ty * r.txp;
    return r;
}

/* Image, tile row and first tile column of the group of VL tiles starting at tile t. */
static inline void group_of(const wgrid *g, long t, int *b, int *ty, int *tx0)
{
    long row = t / g->txp;
    *tx0 = (int)(t % g->txp);
    *b = (int)(row / g->ty);
    *ty = (int)(row % g->ty);
}

/* 4 x 4 transpose inside each 128-bit quarter of (a, b, c, d): r[q] quarter h = element q of
 * the four 4-float groups a, b, c, d of quarter h (in-lane permutes only). Its own inverse. */
static inline void transpose4q(wv a, wv b, wv c, wv d, wv r[4])
{
#if LM_VLN == 16
#define LO 0, 16, 1, 17, 4, 20, 5, 21, 8, 24, 9, 25, 12, 28, 13, 29
#define HI 2, 18, 3, 19, 6, 22, 7, 23, 10, 26, 11, 27, 14, 30, 15, 31
#define ML 0, 1, 16, 17, 4, 5, 20, 21, 8, 9, 24, 25, 12, 13, 28, 29
#define MH 2, 3, 18, 19, 6, 7, 22, 23, 10, 11, 26, 27, 14, 15, 30, 31
#else
#define LO 0, 8, 1, 9, 4, 12, 5, 13
#define HI 2, 10, 3, 11, 6, 14, 7, 15
#define ML 0, 1, 8, 9, 4, 5, 12, 13
#define MH 2, 3, 10, 11, 6, 7, 14, 15
#endif
    wv t0 = WSHUF(a, b, LO), t1 = WSHUF(a, b, HI);
    wv t2 = WSHUF(c, d, LO), t3 = WSHUF(c, d, HI);
    r[0] = WSHUF(t0, t2, ML), r[1] = WSHUF(t0, t2, MH);
    r[2] = WSHUF(t1, t3, ML), r[3] = WSHUF(t1, t3, MH);
#undef LO
#undef HI
#undef ML
#undef MH
}

/* VL floats of one input row (row: its first element, W floats) from column u on; lanes
 * outside 0..W-1 read 0. Used only where the group of tiles meets the image's left or right
 * edge: masked loads touch no memory outside the row (AVX-512 / AVX), else lane by lane. */
static inline wv load_edge(const float *row, int u, int W)
{
    int lo = u < 0 ? -u : 0, hi = W - u < VL ? W - u : VL;
    if (hi <= lo) return wsplat(0.0f);
    const float *p = (const float *)((uintptr_t)row + (intptr_t)u * (intptr_t)sizeof(float));
    wv r;
#if LM_VLN == 16
    __mmask16 m = (__mmask16)(((1u << hi) - 1u) & ~((1u << lo) - 1u));
    __m512 v = _mm512_maskz_loadu_ps(m, p);
    memcpy(&r, &v, sizeof r);
#elif defined(__AVX__)
    wvi lane = {0, 1, 2, 3, 4, 5, 6, 7};
    wvi on = (lane >= lo) & (lane < hi);
    __m256i mi;
    memcpy(&mi, &on, sizeof mi);
    __m256 v = _mm256_maskload_ps(p, mi);
    memcpy(&r, &v, sizeof r);
#else
    (void)p;
    for (int l = 0; l < VL; l++) r[l] = l >= lo && l < hi ? row[u + l] : 0.0f;
#endif
    return r;
}

/* V[xi][c][j] (36 blocks of C rows, ld ldv) = B^T d B for the tiles t0 .. t0+n-1 (n and t0
 * multiples of VL; column j0 + l = tile j0 + LANE_TILE(l)) of every channel of x
 * (B x C x H x W), zero-padded: tile (ty, tx) reads rows 4 ty - ph .. +5 and columns
 * 4 tx - pw .. +5 of x. Read straight from x: plain vector loads inside the image, masked ones
 * at its left and right edges, zeros for rows above and below it (an earlier version copied the
 * rows into a zero-padded buffer first: 4 % of a MCAN training step in memcpy). */
static void input_transform(const wgrid *g, const float *x, long t0, int n, float *V, int ldv)
{
    long xis = (long)g->C * ldv, cs = (long)g->H * g->W;
    for (int j0 = 0; j0 < n; j0 += VL) {
        int b, ty, tx0;
        group_of(g, t0 + j0, &b, &ty, &tx0);
        int y0 = 4 * ty - g->ph, u0 = 4 * tx0 - g->pw;
        int inside = u0 >= 0 && u0 + 4 + 4 * VL <= g->W; /* every load of a row in the image */
        for (int c = 0; c < g->C; c++) {
            const float *xc = x + ((long)b * g->C + c) * cs;
            wv d[6][6], o[6], t[6][6], col[6];
            #pragma GCC unroll 6
            for (int r = 0; r < 6; r++) {
                int yy = y0 + r;
                wv q[8], q4[4];
                if (yy < 0 || yy >= g->H) {
                    #pragma GCC unroll 8
                    for (int k = 0; k < 8; k++) q[k] = wsplat(0.0f);
                } else {
                    const float *row = xc + (long)yy * g->W;
                    if (inside) {
                        #pragma GCC unroll 8
                        for (int k = 0; k < 8; k++) q[k] = lm_loadn(row + u0 + 4 * (k / 4) + VL * (k % 4));
                    } else {
                        #pragma GCC unroll 8
                        for (int k = 0; k < 8; k++) q[k] = load_edge(row, u0 + 4 * (k / 4) + VL * (k % 4), g->W);
                    }
                }
                transpose4q(q[0], q[1], q[2], q[3], d[r]);
                transpose4q(q[4], q[5], q[6], q[7], q4);
                d[r][4] = q4[0], d[r][5] = q4[1];
            }
            #pragma GCC unroll 6
            for (int qq = 0; qq < 6; qq++) { /* columns: t[.][q] = B^T d[.][q] */
                #pragma GCC unroll 6
                for (int r = 0; r < 6; r++) col[r] = d[r][qq];
                BT6(o, col);
                #pragma GCC unroll 6
                for (int r = 0; r < 6; r++) t[r][qq] = o[r];
            }
            float *dst = V + (long)c * ldv + j0;
            #pragma GCC unroll 6
            for (int r = 0; r < 6; r++) { /* rows: V[r][.] = t[r][.] B */
                BT6(o, t[r]);
                #pragma GCC unroll 6
                for (int qq = 0; qq < 6; qq++) wstore(dst + (r * 6 + qq) * xis, o[qq]);
            }
        }
    }
}

/* For output channels of y (B x C x Ho x Wo, g->C = output channels here): tiles t0.. of
 * M[xi][c][j] -> A^T M A, written (accumulate 0: y = bias + value) or added (accumulate 1). */
static void output_transform(const wgrid *g, const float *M, int ldm, long t0, int n,
                             const float *bias, int accumulate, float *y)
{
    long cs = (long)g->Ho * g->Wo, xis = (long)g->C * ldm;
    for (int j0 = 0; j0 < n; j0 += VL) {
        int b, ty, tx0;
        group_of(g, t0 + j0, &b, &ty, &tx0);
        if (tx0 >= g->tx) continue; /* padding tiles only */
        int oy = 4 * ty, ox = 4 * tx0, rh = g->Ho - oy < 4 ? g->Ho - oy : 4;
        int full = ox + 4 * VL <= g->Wo;
        for (int c = 0; c < g->C; c++) {
            const float *src = M + (long)c * ldm + j0;
            wv t[6][4], m[6], o[4], out[4][4];
            #pragma GCC unroll 6
            for (int r = 0; r < 6; r++) { /* rows: t[r][.] = M[r][.] A */
                #pragma GCC unroll 6
                for (int q = 0; q < 6; q++) m[q] = lm_loadn(src + (r * 6 + q) * xis);
                AT4(o, m);
                #pragma GCC unroll 6
                for (int q = 0; q < 4; q++) t[r][q] = o[q];
            }
            #pragma GCC unroll 6
            for (int q = 0; q < 4; q++) { /* columns: out[.][q] = A^T t[.][q] */
                #pragma GCC unroll 6
                for (int r = 0; r < 6; r++) m[r] = t[r][q];
                AT4(o, m);
                #pragma GCC unroll 6
                for (int r = 0; r < 4; r++) out[r][q] = o[r];
            }
            float bv = bias ? bias[c] : 0.0f;
            wv bvv = wsplat(bv);
            float *yc = y + ((long)b * g->C + c) * cs + (long)oy * g->Wo + ox;
            #pragma GCC unroll 6
            for (int r = 0; r < rh; r++) {
                float *yr = yc + (long)r * g->Wo;
                wv row[4]; /* row[k]: output columns VL k .. VL k + VL - 1 of the group, in order */
                transpose4q(out[r][0], out[r][1], out[r][2], out[r][3], row);
                if (full) {
                    #pragma GCC unroll 6
                    for (int k = 0; k < 4; k++) {
                        wv v = row[k] + (accumulate ? lm_loadn(yr + VL * k) : bvv);
                        wstore(yr + VL * k, v);
                    }
                } else {
                    float tmp[4 * VL];
                    #pragma GCC unroll 6
                    for (int k = 0; k < 4; k++) wstore(tmp + VL * k, row[k]);
                    int nw = g->Wo - ox;
                    for (int u = 0; u < nw; u++) yr[u] = tmp[u] + (accumulate ? yr[u] : bv);
                }
            }
        }
    }
}

/* Mdy[xi][c][j] = A dY A^T for the output tiles t0.. (dy: B x C x Ho x Wo; zero outside). */
static void grad_transform(const wgrid *g, const float *dy, long t0, int n, float *Md, int ldm,
                           int C)
{
    long cs = (long)g->Ho * g->Wo, xis = (long)C * ldm;
    for (int j0 = 0; j0 < n; j0 += VL) {
        int b, ty, tx0;
        group_of(g, t0 + j0, &b, &ty, &tx0);
        int oy = 4 * ty, ox = 4 * tx0, rh = g->Ho - oy < 4 ? g->Ho - oy : 4;
        int nw = g->Wo - ox < 4 * VL ? g->Wo - ox : 4 * VL;
        if (nw < 0) nw = 0;
        for (int c = 0; c < C; c++) {
            const float *yc = dy + ((long)b * C + c) * cs + (long)oy * g->Wo + ox;
            wv e[4][4];
            #pragma GCC unroll 6
            for (int r = 0; r < 4; r++) {
                wv row[4];
                if (r < rh && nw == 4 * VL) {
                    #pragma GCC unroll 6
                    for (int k = 0; k < 4; k++) row[k] = lm_loadn(yc + (long)r * g->Wo + VL * k);
                } else {
                    float tmp[4 * VL] = {0};
                    for (int u = 0; r < rh && u < nw; u++) tmp[u] = yc[(long)r * g->Wo + u];
                    #pragma GCC unroll 6
                    for (int k = 0; k < 4; k++) row[k] = lm_loadn(tmp + VL * k);
                }
                transpose4q(row[0], row[1], row[2], row[3], e[r]);
            }
            wv t[6][4], m[4], o[6];
            #pragma GCC unroll 6
            for (int q = 0; q < 4; q++) { /* columns: t[.][q] = A e[.][q] */
                #pragma GCC unroll 6
                for (int r = 0; r < 4; r++) m[r] = e[r][q];
                A6(o, m);
                #pragma GCC unroll 6
                for (int r = 0; r < 6; r++) t[r][q] = o[r];
            }
            float *dst = Md + (long)c * ldm + j0;
            #pragma GCC unroll 6
            for (int r = 0; r < 6; r++) { /* rows: Mdy[r][.] = t[r][.] A^T */
                A6(o, t[r]);
                #pragma GCC unroll 6
                for (int q = 0; q < 6; q++) wstore(dst + (r * 6 + q) * xis, o[q]);
            }
        }
    }
}

/* ---- drivers ----------------------------------------------------------------------------- */
/* Tiles per chunk: at most the cache-sized count, and the chunks a multiple of the thread
 * count (all threads get equal work) when there are enough tiles. */
static long chunk_bytes(void)
{
    const char *e = getenv("LM_WINOGRAD_CHUNK_KB");
    long kb = e ? atol(e) : 0;
    if (kb >= 16 && kb <= 1L << 20) return kb * 1024;
    long l2 = sysconf(_SC_LEVEL2_CACHE_SIZE);
    return l2 >= CHUNK_L2_MIN ? l2 / 16 * 5 : CHUNK_BYTES;
}

static int chunk_tiles(int Cin, int Cout, long T, int nt)
{
    long tc = chunk_bytes() / (36L * (Cin + Cout) * (long)sizeof(float));
    tc = tc / VL * VL;
    if (tc < TC_MIN) tc = TC_MIN;
    if (tc > TC_MAX) tc = TC_MAX;
    long nch = (T + tc - 1) / tc;
    nch = (nch + nt - 1) / nt * nt;
    long even = (T + nch - 1) / nch;
    even = (even + VL - 1) / VL * VL;
    return (int)(even < tc ? even : tc);
}

/* y (B x Cout x Ho x Wo) = bias + conv or += conv, from x (B x Cin x H x W) and the
 * transformed weights: 36 products with weights packed in panels, U for lm_sgemm_panel (fp32)
 * or, when Uh is not NULL, Uh for lm_gemm_bf16_panel (bf16 operands: each chunk's transformed
 * input rounded and paired as it goes in; fp32 sums and output transform). */
static int winograd_run(lm_ctx *c, const wgrid *gi, const wgrid *go, const float *x,
                        const float *U, long pu, const lm_bf16 *Uh, long puh, const float *bias,
                        int accumulate, float *y)
{
    int Cin = gi->C, Cout = go->C, nt = lm_nthreads(c);
    long T = gi->T;
    int tc = chunk_tiles(Cin, Cout, T, nt);
    long nchunks = (T + tc - 1) / tc;
    if (nchunks < nt) nt = (int)nchunks;
    size_t per = 36 * (size_t)(Cin + Cout) * (size_t)tc;
    size_t perh = Uh ? (lm_bf16_pack_b_size(Cin, tc) + 1) / 2 + 16 : 0; /* floats of room */
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *buf = lm_ctx_alloc(c, sizeof(float) * (per + perh) * (size_t)nt);
    if (!buf) return c->status;
    /* chunks handed out as threads come free: a thread slowed by another process on its core
     * takes fewer. Each chunk's outputs are computed whole by one thread, the same way
     * whichever thread it is, so the result does not depend on the hand-out. */
#pragma omp parallel num_threads(nt)
    {
        float *V = buf + (per + perh) * (size_t)omp_get_thread_num();
        float *M = V + 36 * (size_t)Cin * (size_t)tc;
        lm_bf16 *Vh = (lm_bf16 *)(M + 36 * (size_t)Cout * (size_t)tc);
#pragma omp for schedule(dynamic, 1)
        for (long ch = 0; ch < nchunks; ch++) {
            long t0 = ch * tc;
            int n = T - t0 < tc ? (int)(T - t0) : tc;
            input_transform(gi, x, t0, n, V, tc);
            for (int xi = 0; xi < 36; xi++) {
                if (Uh) {
                    lm_bf16_pack_b(Cin, n, V + (long)xi * Cin * tc, tc, Vh);
                    lm_gemm_bf16_panel(Cout, n, Cin, Uh + xi * puh, Vh, NULL, 0,
                                       M + (long)xi * Cout * tc, tc);
                } else {
                    lm_sgemm_panel(Cout, n, Cin, U + xi * pu, V + (long)xi * Cin * tc, tc, NULL,
                                   0, M + (long)xi * Cout * tc, tc);
                }
            }
            output_transform(go, M, tc, t0, n, bias, accumulate, y);
        }
    }
    lm_arena_rewind(&c->arena, mk);
    return 0;
}

/* Transformed weights, packed for lm_sgemm_panel: for the forward (flip 0) U_xi[co][ci] from
 * w[co][ci]; for the input gradient (flip 1) U_xi[ci][co] from w[co][ci] rotated 180 degrees.
 * Returns NULL with the ctx error set when out of memory. */
static float *packed_weights(lm_ctx *c, const lm_conv_geom *g, const float *w, int flip,
                             long *pu_out)
{
    int rows = flip ? g->Cin : g->Cout, K = flip ? g->Cout : g->Cin;
    long pu = lm_panel_size(rows, K);
    float *U = lm_ctx_alloc(c, sizeof(float) * 36 * (size_t)pu);
    if (!U) return NULL;
    memset(U, 0, sizeof(float) * 36 * (size_t)pu);
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) if (g->Cout * g->Cin >= 256)
    for (int co = 0; co < g->Cout; co++)
        for (int ci = 0; ci < g->Cin; ci++) {
            const float *k = w + ((long)co * g->Cin + ci) * 9;
            float u[36];
            if (flip)
                weight_transform(k + 8, -3, -1, u);
            else
                weight_transform(k, 3, 1, u);
            long at = flip ? lm_panel_at(K, ci, co) : lm_panel_at(K, co, ci);
            for (int xi = 0; xi < 36; xi++) U[xi * pu + at] = u[xi];
        }
    *pu_out = pu;
    return U;
}

/* flip 0: y = bias + conv(x, w); flip 1: dx += conv(dy, w') with w' the transposed, rotated
 * weights and padding 2 - p, whose tiles cover dx (H x W). */
static int forward_like(lm_ctx *c, const lm_conv_geom *g, const float *in, const float *w,
                        int flip, const float *bias, float *out)
{
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    const int bf = c->precision == LM_PRECISION_BF16;
    const int rows = flip ? g->Cin : g->Cout, K = flip ? g->Cout : g->Cin;
    long pu = lm_panel_size(rows, K), puh = bf ? (long)lm_bf16_pack_a_size(rows, K) : 0;
    /* the packed operand depends on the weights, the direction, the precision and (through
     * the panel layout) the instruction-set level; kept while the weights are unchanged */
    const long nw = (long)g->Cout * g->Cin * 9;
    const unsigned long tag = ((unsigned long)lm_isa_active() << 2) | ((unsigned long)bf << 1) |
                              (unsigned long)flip;
    size_t have = 0;
    const void *hit = lm_wcache_find(c, w, nw, tag, &have);
    const float *U = NULL;
    const lm_bf16 *Uh = NULL;
    const size_t bytes = bf ? sizeof(lm_bf16) * 36 * (size_t)puh : sizeof(float) * 36 * (size_t)pu;
    if (hit && have == bytes) {
        if (bf) Uh = hit;
        else U = hit;
    } else {
        float *Uf = packed_weights(c, g, w, flip, &pu);
        if (!Uf) return c->status;
        U = Uf;
        if (bf) { /* the same U, rounded and paired per product */
            lm_bf16 *Ub = lm_ctx_alloc(c, bytes);
            float *row = lm_ctx_alloc(c, sizeof(float) * (size_t)rows * K);
            if (!Ub || !row) return c->status;
            for (int xi = 0; xi < 36; xi++) {
                for (int m = 0; m < rows; m++)
                    for (int k = 0; k < K; k++)
                        row[(long)m * K + k] = U[xi * pu + lm_panel_at(K, m, k)];
                lm_bf16_pack_a(rows, K, row, K, Ub + xi * puh);
            }
            Uh = Ub;
        }
        lm_wcache_put(c, w, nw, tag, bf ? (const void *)Uh : (const void *)U, bytes);
    }
    wgrid gi = flip ? make_grid(g->Cout, g->Ho, g->Wo, g->H, g->W, 2 - g->ph, 2 - g->pw, g->B)
                    : make_grid(g->Cin, g->H, g->W, g->Ho, g->Wo, g->ph, g->pw, g->B);
    wgrid go = gi;
    go.C = flip ? g->Cin : g->Cout;
    int st = winograd_run(c, &gi, &go, in, U, pu, Uh, puh, bias, flip, out);
    lm_arena_rewind(&c->arena, mk);
    return st;
}

int lm_conv2d_winograd_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                           const float *bias, float *y)
{
    return forward_like(c, g, x, w, 0, bias, y);
}

int lm_conv2d_winograd_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                             float *dx)
{
    return forward_like(c, g, dy, w, 1, NULL, dx);
}

int lm_conv2d_winograd_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                             float *dw)
{
    int Cin = g->Cin, Cout = g->Cout, nt = lm_nthreads(c);
    wgrid gi = make_grid(Cin, g->H, g->W, g->Ho, g->Wo, g->ph, g->pw, g->B);
    long T = gi.T, nw = (long)Cout * Cin;
    int tc = chunk_tiles(Cin, Cout, T, nt);
    long nchunks = (T + tc - 1) / tc;
    if (nchunks < nt) nt = (int)nchunks;
    /* the chunks fall into ng fixed groups (a function of the thread count and the shape), each
     * summed by one thread in chunk order into its own partial; groups are handed out as
     * threads come free (a thread slowed by another process takes fewer), and the partials are
     * added in group order: the result depends on the thread count only */
    long ng = nchunks < 4L * nt ? nchunks : 4L * nt;
    size_t per = 36 * (size_t)(Cin + Cout) * (size_t)tc;
    lm_arena_mark mk = lm_arena_get_mark(&c->arena);
    float *dUs = lm_ctx_alloc(c, sizeof(float) * (36 * (size_t)nw * (size_t)ng + per * (size_t)nt));
    if (!dUs) return c->status;
    float *scratch = dUs + 36 * (size_t)nw * (size_t)ng;
#pragma omp parallel num_threads(nt)
    {
        float *V = scratch + per * (size_t)omp_get_thread_num();
        float *Md = V + 36 * (size_t)Cin * (size_t)tc;
#pragma omp for schedule(dynamic, 1)
        for (long gr = 0; gr < ng; gr++) {
            float *dU = dUs + 36 * (size_t)nw * (size_t)gr;
            long c0 = nchunks * gr / ng, c1 = nchunks * (gr + 1) / ng;
            for (long ch = c0; ch < c1; ch++) {
                long t0 = ch * tc;
                int n = T - t0 < tc ? (int)(T - t0) : tc;
                input_transform(&gi, x, t0, n, V, tc);
                grad_transform(&gi, dy, t0, n, Md, tc, Cout);
                /* the group's first chunk writes its partial (beta 0: no zeroing pass) */
                for (int xi = 0; xi < 36; xi++)
                    lm_sgemm_st(0, 1, Cout, Cin, n, 1.0f, Md + (long)xi * Cout * tc, tc,
                                V + (long)xi * Cin * tc, tc, ch == c0 ? 0.0f : 1.0f,
                                dU + (long)xi * nw, Cin);
            }
        }
        /* (the implicit barrier of the loop) partials added in group order into the first
         * one, contiguous runs of weights at a time (((g0 + g1) + g2) ..., the same sums as
         * from zero), then dw += G^T dU G; weights split over threads */
        int me = omp_get_thread_num(), nthr = omp_get_num_threads();
        long k0 = nw * me / nthr, k1 = nw * (me + 1) / nthr;
        for (int xi = 0; xi < 36; xi++) {
            float *d0 = dUs + (size_t)xi * nw;
            for (long gr = 1; gr < ng; gr++) {
                const float *dg = dUs + 36 * (size_t)nw * (size_t)gr + (size_t)xi * nw;
                for (long k = k0; k < k1; k++) d0[k] += dg[k];
            }
        }
        for (long k = k0; k < k1; k++) {
            float u[36];
            for (int xi = 0; xi < 36; xi++) u[xi] = dUs[(size_t)xi * nw + k];
            weight_transform_adjoint(u, dw + k * 9, 3, 1);
        }
    }
    lm_arena_rewind(&c->arena, mk);
    return 0;
}
