/* gemm_bf16.h — bf16 operands, fp32 accumulation: the packed panel product of the
 * convolution fast paths in mixed precision (gemm_bf16.c). Private to the ops, tests and
 * benchmarks.
 *
 * What it is: C (M x n, ld ldc) = bias + A B (accumulate 0) or C += A B (1), with A and B
 * rounded to bf16 (round to nearest even) when packed and every product summed in fp32.
 * A (M x K) is packed once (per weight update, for weights), B (K x n, an activation) per call.
 * Three kernels, one chosen per process at the first call (tensor/isa.h, lm_bf16_kernel_active):
 *   - AMX tiles (level amx, the kernel granting the tile state): tdpbf16ps on 16 x 32 bf16
 *     tiles of A and 16 pair-rows x 16 columns of B, 2 x 2 fp32 accumulator tiles (a 32 x 32
 *     block of C) per pass over K; 16 x 16 x 32 = 8,192 multiply-adds (16,384 FLOP) per
 *     instruction;
 *   - AVX-512-BF16 (level avx512 or amx without tiles): one vdpbf16ps does 32 multiply-adds,
 *     6 rows x 32 columns of C in registers;
 *   - the fp32 twin elsewhere: the same sums from the bf16 values, in fp32 (the products of
 *     two bf16 values are exact in fp32, so it agrees with the others to fp32 rounding).
 * Each kernel has its own packed layout (gemm_bf16.c): pack with the kernel that multiplies.
 * The plain functions use the process's kernel; the _for functions name one (tests, benchmarks).
 * Each C element: bias (or C), then the products summed in fp32, in the order the kernel's
 * instruction adds them (AMX: round to nearest even, bf16 denormal inputs read as zero and fp32
 * denormal results flushed to zero, whatever MXCSR says).
 * What it is not: a general GEMM (no transposes, no alpha/beta), or threaded (one call, one
 * thread: the convolutions call it from their OpenMP threads). */
#ifndef LM_OPS_GEMM_BF16_H
#define LM_OPS_GEMM_BF16_H
#include <stddef.h>
#include <stdint.h>

typedef uint16_t lm_bf16;

#define LM_BF16_MR 6 /* rows per panel of A (AVX-512-BF16 kernel and fp32 twin) */

typedef enum lm_bf16_kernel {
    LM_BF16_FP32 = 0,   /* the fp32 twin (portable C) */
    LM_BF16_DPBF16 = 1, /* AVX-512-BF16, vdpbf16ps */
    LM_BF16_AMX = 2     /* AMX-BF16 tiles, tdpbf16ps */
} lm_bf16_kernel;

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

/* The kernel of this process: AMX when the level (tensor/isa.h) is amx and the operating
 * system grants the tile state (lm_amx_tile_granted), else AVX-512-BF16 when the level is
 * avx512 or above and the CPU has it, else the fp32 twin. Fixed at the first call. */
lm_bf16_kernel lm_bf16_kernel_active(void);
/* 1 when this process runs kernel k with its instructions: the CPU has them, the level of
 * tensor/isa.h allows them (LM_ISA=avx512: no AMX; avx2 and below: neither) and, for AMX, the
 * operating system grants the tile state; the fp32 twin always. A kernel that does not run is
 * still accepted by the _for functions: its layout, multiplied by the fp32 twin (the same
 * results to fp32 rounding, never an illegal instruction). */
int lm_bf16_kernel_runs(lm_bf16_kernel k);
/* "AMX tiles", "AVX-512-BF16 (vdpbf16ps)", "fp32 twin". */
const char *lm_bf16_kernel_name(lm_bf16_kernel k);

/* Sizes in bf16 elements of the packed A (M x K) and B (K x n). */
size_t lm_bf16_pack_a_size(int M, int K);
size_t lm_bf16_pack_b_size(int K, int n);
/* Pack A (row-major, ld lda) / B (row-major, ld ldb), rounding to bf16; padding is zero. */
void lm_bf16_pack_a(int M, int K, const float *A, long lda, lm_bf16 *Ap);
void lm_bf16_pack_b(int K, int n, const float *B, long ldb, lm_bf16 *Bp);

/* C = bias + Ap Bp (accumulate 0; bias may be NULL) or C += Ap Bp (1). Single-threaded.
 * Writes only C's M x n elements. */
void lm_gemm_bf16_panel(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                        const float *bias, int accumulate, float *C, long ldc);

/* The same with a named kernel (its layout: pack with the same k). */
size_t lm_bf16_pack_a_size_for(lm_bf16_kernel k, int M, int K);
size_t lm_bf16_pack_b_size_for(lm_bf16_kernel k, int K, int n);
void lm_bf16_pack_a_for(lm_bf16_kernel k, int M, int K, const float *A, long lda, lm_bf16 *Ap);
void lm_bf16_pack_b_for(lm_bf16_kernel k, int K, int n, const float *B, long ldb, lm_bf16 *Bp);
void lm_gemm_bf16_panel_for(lm_bf16_kernel k, int M, int n, int K, const lm_bf16 *Ap,
                            const lm_bf16 *Bp, const float *bias, int accumulate, float *C,
                            long ldc);

/* 1 when lm_gemm_bf16_panel uses bf16 instructions (AMX tiles or AVX-512-BF16), 0 for the
 * fp32 twin. */
int lm_gemm_bf16_native(void);

#endif
