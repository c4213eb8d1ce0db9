/* gemm_internal.h — private declarations shared by the matrix-product and convolution ops
 * (tensor/ops/matmul.c, conv2d*.c, gemm_parallel.c). Not part of the public API: only ops
 * and their tests include it.
 *
 * What it is: a thread-split single-precision GEMM on top of single-threaded CBLAS, the
 * geometry of a 2-D convolution, and the CPU paths of conv2d (simple reference, tiled
 * im2col + GEMM, depthwise direct) with their exact write semantics.
 * What it is not: ops (no shape checks, no tape); callers pass valid, contiguous buffers. */
#ifndef LM_GEMM_INTERNAL_H
#define LM_GEMM_INTERNAL_H
#include "tensor/tensor.h"
#include "tensor/op_params.h"

/* ---- GEMM ------------------------------------------------------------------------------ */
/* Row-major C = alpha op(A) op(B) + beta C with op(A) M x K, op(B) K x N (CBLAS semantics),
 * split over lm_nthreads(c) threads by column (or row) blocks of C; each thread calls
 * single-threaded sgemm on its block. Deterministic for a given thread count. */
void lm_gemm_mt(lm_ctx *c, int ta, int tb, int M, int N, int K, float alpha, const float *A,
                int lda, const float *B, int ldb, float beta, float *C, int ldc);

/* Single-threaded row-major SGEMM with CBLAS semantics (sgemm_avx512.c): C = alpha op(A)
 * op(B) + beta C, op(A) M x K, op(B) K x N; beta == 0 never reads C; K == 0 or alpha == 0
 * only scales C. An AVX-512 kernel when the CPU has one, else OpenBLAS. Deterministic: the
 * K order of each element is fixed. Every GEMM of the CPU ops goes through here. */
void lm_sgemm_st(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda,
                 const float *B, int ldb, float beta, float *C, int ldc);
/* Which implementation lm_sgemm_st uses: the AVX-512 kernel by default when the CPU supports
 * it, OpenBLAS when the environment has LM_SGEMM=blas (read once) or the CPU lacks AVX-512. */
enum { LM_SGEMM_BLAS = 0, LM_SGEMM_AVX512 = 1 };
int lm_sgemm_impl(void);
/* Force an implementation (AVX512 falls back to BLAS on CPUs without it; -1 restores the
 * default) for later calls, process-wide (tests, benchmarks). Returns the previous one. */
int lm_sgemm_set_impl(int impl);

/* `batch` products C_i = alpha op(A_i) op(B_i) + beta C_i with A_i = A + i*sa etc.
 * sa or sb may be 0 (a matrix shared by the batch). sc == 0 means every product accumulates
 * into the same C (a sum over the batch, in batch order); beta applies once, before. */
void lm_gemm_batched(lm_ctx *c, int batch, int ta, int tb, int M, int N, int K, float alpha,
                     const float *A, long sa, int lda, const float *B, long sb, int ldb,
                     float beta, float *C, long sc, int ldc);

/* ---- conv2d geometry and CPU paths ----------------------------------------------------- */
/* The params of a conv2d kernel: lm_conv_geom (tensor/op_params.h). */

/* Which CPU implementation conv2d kernels use. AUTO: depthwise direct loops when each output
 * channel reads one input channel, Winograd F(4x4, 3x3) for 3x3 stride-1 convs with enough
 * channels, the pointwise forward for 1x1 stride-1 unpadded convs, the direct forward for few
 * output channels, else the tiled im2col + GEMM path.
 * SIMPLE: the whole-image im2col + GEMM reference (tests compare the two). NO_WINOGRAD: AUTO
 * without the Winograd path (benchmarks and tests compare them). */
enum { LM_CONV_PATH_AUTO = 0, LM_CONV_PATH_SIMPLE = 1, LM_CONV_PATH_NO_WINOGRAD = 2 };
/* Select the path for later conv2d kernels run on c (c->conv_path; for tests and
 * benchmarks). Returns the previous setting. */
int lm_conv2d_set_path(lm_ctx *c, int path);

/* Per path: fwd writes y = conv(x, w) + bias (bias may be NULL); bwd_x ADDS into dx;
 * bwd_w ADDS into dw. Scratch comes from the ctx arena and is released before returning.
 * Return 0, or a negative status with the ctx error set. */
int lm_conv2d_tiled_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                        const float *bias, float *y);
int lm_conv2d_tiled_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                          float *dx);
int lm_conv2d_tiled_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                          float *dw);
/* Depthwise paths: valid only when Cin == groups (one input channel per group). */
int lm_conv2d_dw_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                     const float *bias, float *y);
int lm_conv2d_dw_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                       float *dx);
int lm_conv2d_dw_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                       float *dw);

/* Direct forward path (conv2d_direct.c): stride 1, dilation 1, one group, few output
 * channels. applies() says whether g qualifies; fwd writes y = conv(x, w) + bias. */
#define LM_CONV_DIRECT_MAX_COUT 48
int lm_conv2d_direct_applies(const lm_conv_geom *g);
int lm_conv2d_direct_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                         const float *bias, float *y);

/* Winograd F(4x4, 3x3) path (conv2d_winograd.c): 3x3, stride 1, dilation 1, one group,
 * padding <= 2, at least LM_CONV_WINOGRAD_MIN_C input and output channels (measured with
 * bench_conv / bench_rt: faster than the tiled and direct paths from 8 channels up). Same
 * write semantics as the tiled path (fwd writes, bwd_x / bwd_w add). */
#define LM_CONV_WINOGRAD_MIN_C 8
int lm_conv2d_winograd_applies(const lm_conv_geom *g);
int lm_conv2d_winograd_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                           const float *bias, float *y);
int lm_conv2d_winograd_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                             float *dx);
int lm_conv2d_winograd_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                             float *dw);

/* Pointwise path (conv2d_pointwise.c): 1x1, stride 1, no padding, one group; y = W x + bias
 * and dx += W^T dy per image through lm_sgemm_panel (the weight gradient stays tiled). */
int lm_conv2d_pointwise_applies(const lm_conv_geom *g);
int lm_conv2d_pointwise_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                            const float *bias, float *y);
int lm_conv2d_pointwise_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                              float *dx);

/* ---- panel GEMM (sgemm_panel.c) ----------------------------------------------------------
 * C (M x n, ld ldc) = bias + A B (accumulate 0) or C += A B (1), A (M x K) packed by lm_panel_pack into panels of
 * LM_PANEL_MR rows (k-major, zero rows past M; element (m, k) at lm_panel_at(K, m, k),
 * lm_panel_size(M, K) floats), B (K x n, ld ldb) read in place; bias (M) may be NULL.
 * Single-threaded; each element summed in the same order however n is split. */
#define LM_PANEL_MR 6
static inline long lm_panel_size(int M, int K)
{
    return (long)(M + LM_PANEL_MR - 1) / LM_PANEL_MR * LM_PANEL_MR * K;
}
static inline long lm_panel_at(int K, int m, int k)
{
    return ((long)(m / LM_PANEL_MR) * K + k) * LM_PANEL_MR + m % LM_PANEL_MR;
}
void lm_panel_pack(int M, int K, const float *A, long lda, float *Ap);
void lm_sgemm_panel(int M, int n, int K, const float *Ap, const float *B, long ldb,
                    const float *bias, int accumulate, float *C, long ldc);

/* Range of output columns ox in [*lo, *hi) whose input column ox*s - p + j*d lies in [0, n). */
static inline void lm_conv_valid_range(int n_out, int n_in, int s, int p, int off, int *lo,
                                       int *hi)
{
    /* input index = ox*s + (off - p), off = j*d */
    int a = p - off; /* need ox*s >= a */
    int l = a <= 0 ? 0 : (a + s - 1) / s;
    int b = n_in - 1 + p - off; /* need ox*s <= b */
    int h = b < 0 ? 0 : b / s + 1;
    if (l > n_out) l = n_out;
    if (h > n_out) h = n_out;
    if (h < l) h = l;
    *lo = l;
    *hi = h;
}

#endif
