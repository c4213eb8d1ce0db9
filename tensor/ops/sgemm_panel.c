/* sgemm_panel.c — the small-GEMM kernel of the convolution fast paths (Winograd products,
 * pointwise convolutions): C (M x n, ld ldc) = bias + A B with A packed once by the caller
 * in panels of LM_PANEL_MR rows (or C += A B), k-major ([panel][k][r], rows past M zero: lm_panel_at /
 * lm_panel_size), and B (K x n, ld ldb) read in place. An MR x 16 register tile (12 vector
 * accumulators) runs over the whole K while its 16 columns of B (K x 64 bytes) stay in L1 for
 * every panel of A; columns past the last multiple of 8 are done one by one. No packing of
 * B, no pass over C before the product, no library call: for the conv shapes (M, K = 8..128,
 * n = hundreds to thousands) OpenBLAS spent about a third of its time outside its kernel.
 * Each C element is a sum over k in ascending order (bias first), whatever n or the caller's
 * column blocking, so results do not depend on how work is split.
 * What it is not: a general GEMM (no transposes, no alpha/beta; see sgemm_avx512.c). */
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/simd.h"
#include <string.h>

#define VL 8
#define MR LM_PANEL_MR
void lm_panel_pack(int M, int K, const float *A, long lda, float *Ap)
{
    memset(Ap, 0, sizeof(float) * (size_t)lm_panel_size(M, K));
    for (int m = 0; m < M; m++)
        for (int k = 0; k < K; k++) Ap[lm_panel_at(K, m, k)] = A[(long)m * lda + k];
}

void lm_sgemm_panel(int M, int n, int K, const float *Ap, const float *B, long ldb,
                    const float *bias, int accumulate, float *C, long ldc)
{
    int nv = n / VL * VL;
    for (int j = 0; j < nv; j += 2 * VL) {
        int two = j + 2 * VL <= nv;
        for (int p = 0; p < M; p += MR) {
            const float *a = Ap + (long)p * K, *b = B + j;
            int rows = M - p < MR ? M - p : MR;
            lm_vf8 acc0[MR], acc1[MR];
#pragma GCC unroll 6
            for (int r = 0; r < MR; r++) {
                float b0 = bias && r < rows ? bias[p + r] : 0.0f;
                acc0[r] = LM_SPLAT8(b0), acc1[r] = LM_SPLAT8(b0);
                if (accumulate && r < rows) {
                    acc0[r] = lm_load8(C + (long)(p + r) * ldc + j);
                    if (two) acc1[r] = lm_load8(C + (long)(p + r) * ldc + j + VL);
                }
            }
            if (two) {
                for (int k = 0; k < K; k++, a += MR, b += ldb) {
                    lm_vf8 b0 = lm_load8(b), b1 = lm_load8(b + VL);
#pragma GCC unroll 6
                    for (int r = 0; r < MR; r++) {
                        lm_vf8 av = LM_SPLAT8(a[r]);
                        acc0[r] += av * b0;
                        acc1[r] += av * b1;
                    }
                }
            } else {
                for (int k = 0; k < K; k++, a += MR, b += ldb) {
                    lm_vf8 b0 = lm_load8(b);
#pragma GCC unroll 6
                    for (int r = 0; r < MR; r++) acc0[r] += LM_SPLAT8(a[r]) * b0;
                }
            }
            for (int r = 0; r < rows; r++) {
                float *c = C + (long)(p + r) * ldc + j;
                lm_store8(c, acc0[r]);
                if (two) lm_store8(c + VL, acc1[r]);
            }
        }
    }
    for (int j = nv; j < n; j++) /* the last n % 8 columns */
        for (int m = 0; m < M; m++) {
            const float *a = Ap + (long)(m / MR) * MR * K + m % MR;
            float s = accumulate ? C[(long)m * ldc + j] : bias ? bias[m] : 0.0f;
            for (int k = 0; k < K; k++) s += a[(long)k * MR] * B[(long)k * ldb + j];
            C[(long)m * ldc + j] = s;
        }
}
