/* gemm_bf16.h — bf16 operands, fp32 accumulation: the packed panel product of the
 * convolution fast paths in mixed precision (gemm_bf16.c). Private to the ops, tests and
 * benchmarks.
 *
 * What it is: C (M x n, ld ldc) = bias + A B (accumulate 0) or C += A B (1), with A and B
 * rounded to bf16 (round to nearest even) when packed and every product summed in fp32.
 * A (M x K) is packed once (per weight update, for weights) into panels of LM_BF16_MR rows
 * holding K in pairs; B (K x n) into pairs of rows interleaved column by column (the layout
 * of vdpbf16ps), n padded to a multiple of 16. With AVX-512-BF16 (chosen at run time,
 * tensor/isa.h) one vdpbf16ps does 32 multiply-adds; elsewhere the same sums run in fp32
 * from the bf16 values (identical products; the sums' order is the same, so the two agree to
 * fp32 rounding). Each C element: bias (or C), then k pairs in ascending order.
 * What it is not: a general GEMM (no transposes, no alpha/beta), or an AMX tile kernel. */
#ifndef LM_OPS_GEMM_BF16_H
#define LM_OPS_GEMM_BF16_H
#include <stddef.h>
#include <stdint.h>

typedef uint16_t lm_bf16;

#define LM_BF16_MR 6 /* rows per panel of A */

/* bf16 of x, rounded to nearest even (NaN stays NaN). */
static inline lm_bf16 lm_bf16_round(float x)
{
    uint32_t u;
    __builtin_memcpy(&u, &x, 4);
    if ((u & 0x7fffffffu) > 0x7f800000u) return (lm_bf16)((u >> 16) | 0x40); /* quiet NaN */
    u += 0x7fffu + ((u >> 16) & 1u);
    return (lm_bf16)(u >> 16);
}

static inline float lm_bf16_to_f32(lm_bf16 h)
{
    uint32_t u = (uint32_t)h << 16;
    float x;
    __builtin_memcpy(&x, &u, 4);
    return x;
}

/* y[i] = bf16(x[i]), i < n. */
void lm_bf16_from_f32(const float *x, lm_bf16 *y, long n);

/* Sizes in bf16 elements of the packed A (M x K) and B (K x n). */
size_t lm_bf16_pack_a_size(int M, int K);
size_t lm_bf16_pack_b_size(int K, int n);
/* Pack A (row-major, ld lda) / B (row-major, ld ldb), rounding to bf16; padding is zero. */
void lm_bf16_pack_a(int M, int K, const float *A, long lda, lm_bf16 *Ap);
void lm_bf16_pack_b(int K, int n, const float *B, long ldb, lm_bf16 *Bp);

/* C = bias + Ap Bp (accumulate 0; bias may be NULL) or C += Ap Bp (1). Single-threaded. */
void lm_gemm_bf16_panel(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                        const float *bias, int accumulate, float *C, long ldc);

/* 1 when lm_gemm_bf16_panel uses AVX-512-BF16 instructions (the CPU has them and the level
 * of tensor/isa.h is avx512 or above), 0 for the fp32 path. */
int lm_gemm_bf16_native(void);

#endif
