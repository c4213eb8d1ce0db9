/* gemm_parallel.c — single-precision GEMM split over the ctx's OpenMP threads.
 * What it is: a large product is cut into fixed column (or row) blocks of C, one per
 * thread, each computed by one single-threaded lm_sgemm_st call (sgemm_avx512.c);
 * batches of independent products are spread over threads instead. Every element of C is
 * computed by exactly one call, so results depend only on the thread count.
 * What it is not: an op (see matmul.c, conv2d.c); no shape checks. */
#include "tensor/ops/gemm_internal.h"
#include <omp.h>

/* Below this many multiply-adds a product runs on one thread. */
#define GEMM_PAR_MIN_MACS (1L << 17)

static void sgemm1(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda,
                   const float *B, int ldb, float beta, float *C, int ldc)
{
    lm_sgemm_st(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc);
}

/* Block t of nparts over [0, n): multiples of `align` except the last. */
static void part_range(int n, int nparts, int t, int align, int *lo, int *hi)
{
    int units = (n + align - 1) / align;
    int a = (int)((long)units * t / nparts) * align;
    int b = (int)((long)units * (t + 1) / nparts) * align;
    *lo = a < n ? a : n;
    *hi = b < n ? b : n;
}

void lm_gemm_mt(lm_ctx *c, int ta, int tb, int M, int N, int K, float alpha, const float *A,
                int lda, const float *B, int ldb, float beta, float *C, int ldc)
{
    int nt = lm_nthreads(c);
    if (nt == 1 || (long)M * N * K < GEMM_PAR_MIN_MACS || (M < 2 * nt && N < 16 * nt)) {
        sgemm1(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc);
        return;
    }
    int split_n = N >= 16 * nt && (N >= M || M < 2 * nt);
#pragma omp parallel num_threads(nt)
    {
        int nthr = omp_get_num_threads();
        /* logical parts depend on nt only, whatever number of threads the runtime gives */
        for (int t = omp_get_thread_num(); t < nt; t += nthr) {
            int lo, hi;
            if (split_n) {
                part_range(N, nt, t, 16, &lo, &hi);
                const float *Bp = tb ? B + (long)lo * ldb : B + lo;
                sgemm1(ta, tb, M, hi - lo, K, alpha, A, lda, Bp, ldb, beta, C + lo, ldc);
            } else {
                part_range(M, nt, t, 1, &lo, &hi);
                const float *Ap = ta ? A + lo : A + (long)lo * lda;
                sgemm1(ta, tb, hi - lo, N, K, alpha, Ap, lda, B, ldb, beta, C + (long)lo * ldc,
                       ldc);
            }
        }
    }
}

void lm_gemm_batched(lm_ctx *c, int batch, int ta, int tb, int M, int N, int K, float alpha,
                     const float *A, long sa, int lda, const float *B, long sb, int ldb,
                     float beta, float *C, long sc, int ldc)
{
    int nt = lm_nthreads(c);
    int spread = batch % nt == 0 || batch >= 4 * nt;
    if (sc == 0 || !spread || (long)M * N * K * batch < GEMM_PAR_MIN_MACS) {
        /* shared C (a sum over the batch) or few products: one after the other, each split */
        for (int i = 0; i < batch; i++)
            lm_gemm_mt(c, ta, tb, M, N, K, alpha, A + i * sa, lda, B + i * sb, ldb,
                       (sc == 0 && i > 0) ? 1.0f : beta, C + i * sc, ldc);
        return;
    }
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int i = 0; i < batch; i++)
        sgemm1(ta, tb, M, N, K, alpha, A + i * sa, lda, B + i * sb, ldb, beta, C + i * sc, ldc);
}
