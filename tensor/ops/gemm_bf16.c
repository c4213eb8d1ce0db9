/* gemm_bf16.c — the bf16 panel product (gemm_bf16.h): packing, an AVX-512-BF16 kernel
 * (vdpbf16ps, compiled with a target attribute and chosen at run time) and its fp32 twin.
 *
 * Layouts (K2 = ceil(K / 2) pairs, NP = n rounded up to 16):
 *   Ap[((p K2 + q) MR + r) 2 + t] = A[p MR + r][2 q + t]   (panel p, pair q, row r)
 *   Bp[(q NP + j) 2 + t]          = B[2 q + t][j]
 * so one 64-byte load of Bp holds 16 columns x one pair of k, and one 32-bit broadcast of Ap
 * one row's pair: vdpbf16ps adds a0 b0 + a1 b1 into each column's fp32 accumulator. The
 * micro-tile is MR = 6 rows x 32 columns (12 accumulators), as the fp32 panel kernel's. */
#include "tensor/ops/gemm_bf16.h"
#include "tensor/isa.h"
#include "tensor/tensor.h"
#include <string.h>

#if defined(__x86_64__) && defined(__GNUC__)
#define LM_HAVE_BF16_KERNEL 1
#include <immintrin.h>
#else
#define LM_HAVE_BF16_KERNEL 0
#endif

#define MR LM_BF16_MR

void lm_bf16_from_f32(const float *x, lm_bf16 *y, long n)
{
    for (long i = 0; i < n; i++) y[i] = lm_bf16_round(x[i]);
}

static int pad16(int n) { return (n + 15) / 16 * 16; }

size_t lm_bf16_pack_a_size(int M, int K)
{
    return (size_t)((M + MR - 1) / MR) * MR * (size_t)((K + 1) / 2) * 2;
}

size_t lm_bf16_pack_b_size(int K, int n) { return (size_t)((K + 1) / 2) * pad16(n) * 2; }

void lm_bf16_pack_a(int M, int K, const float *A, long lda, lm_bf16 *Ap)
{
    const int K2 = (K + 1) / 2, P = (M + MR - 1) / MR;
    for (int p = 0; p < P; p++)
        for (int q = 0; q < K2; q++)
            for (int r = 0; r < MR; r++)
                for (int t = 0; t < 2; t++) {
                    const int m = p * MR + r, k = 2 * q + t;
                    Ap[(((size_t)p * K2 + q) * MR + r) * 2 + t] =
                        m < M && k < K ? lm_bf16_round(A[(long)m * lda + k]) : 0;
                }
}

#if LM_HAVE_BF16_KERNEL
/* lm_bf16_round of 16 floats, each in the low half of its 32-bit lane. */
__attribute__((target("avx512f"))) static inline __m512i round16(const float *p)
{
    const __m512i u = _mm512_castps_si512(_mm512_loadu_ps(p));
    const __m512i one = _mm512_set1_epi32(1);
    __m512i r = _mm512_add_epi32(u, _mm512_set1_epi32(0x7fff));
    r = _mm512_srli_epi32(_mm512_add_epi32(r, _mm512_and_si512(_mm512_srli_epi32(u, 16), one)), 16);
    const __mmask16 nan = _mm512_cmpgt_epu32_mask(_mm512_and_si512(u, _mm512_set1_epi32(0x7fffffff)),
                                                  _mm512_set1_epi32(0x7f800000));
    const __m512i quiet = _mm512_or_si512(_mm512_srli_epi32(u, 16), _mm512_set1_epi32(0x40));
    return _mm512_mask_mov_epi32(r, nan, quiet);
}

/* 16 columns of one pair of rows (b1 may be NULL: zeros), rounded and interleaved: 32 bf16. */
__attribute__((target("avx512f"))) static void pack_pair16(const float *b0, const float *b1,
                                                           lm_bf16 *d)
{
    __m512i r = round16(b0);
    if (b1) r = _mm512_or_si512(r, _mm512_slli_epi32(round16(b1), 16));
    _mm512_storeu_si512(d, r);
}
#endif

void lm_bf16_pack_b(int K, int n, const float *B, long ldb, lm_bf16 *Bp)
{
    const int K2 = (K + 1) / 2, NP = pad16(n);
#if LM_HAVE_BF16_KERNEL
    const int vec = lm_isa_active() >= LM_ISA_AVX512;
#endif
    for (int q = 0; q < K2; q++) {
        lm_bf16 *d = Bp + (size_t)q * NP * 2;
        const float *b0 = B + (long)(2 * q) * ldb, *b1 = 2 * q + 1 < K ? b0 + ldb : NULL;
        int j = 0;
#if LM_HAVE_BF16_KERNEL
        if (vec)
            for (; j + 16 <= n; j += 16) pack_pair16(b0 + j, b1 ? b1 + j : NULL, d + 2 * j);
#endif
        for (; j < n; j++) {
            d[2 * j] = lm_bf16_round(b0[j]);
            d[2 * j + 1] = b1 ? lm_bf16_round(b1[j]) : 0;
        }
        memset(d + 2 * n, 0, sizeof(lm_bf16) * 2 * (size_t)(NP - n));
    }
}

/* ---- fp32 twin: the same sums, pair by pair (a1 b1 first, then a0 b0, as vdpbf16ps) ----- */
static void panel_fp32(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                       const float *bias, int accumulate, float *C, long ldc)
{
    const int K2 = (K + 1) / 2, NP = pad16(n);
    for (int m = 0; m < M; m++) {
        const lm_bf16 *a = Ap + ((size_t)(m / MR) * K2 * MR + m % MR) * 2;
        float *c = C + (long)m * ldc;
        for (int j = 0; j < n; j++) {
            float s = accumulate ? c[j] : bias ? bias[m] : 0.0f;
            for (int q = 0; q < K2; q++) {
                const lm_bf16 *aq = a + (size_t)q * MR * 2, *bq = Bp + ((size_t)q * NP + j) * 2;
                s += lm_bf16_to_f32(aq[1]) * lm_bf16_to_f32(bq[1]);
                s += lm_bf16_to_f32(aq[0]) * lm_bf16_to_f32(bq[0]);
            }
            c[j] = s;
        }
    }
}

#if LM_HAVE_BF16_KERNEL
#define BF16 __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,avx512bf16")))

/* Rows [p MR, p MR + rows) x columns [j, j + 16 nv) (nv 1 or 2; the last block masked). */
BF16 static void tile(int K2, int NP, const lm_bf16 *a, const lm_bf16 *Bp, int j, int nv,
                      int rows, int n, const float *bias, int accumulate, float *C, long ldc)
{
    __m512 acc[MR][2];
    __mmask16 mk[2];
    for (int v = 0; v < 2; v++) {
        int left = n - j - 16 * v;
        mk[v] = left >= 16 ? (__mmask16)0xffff : left > 0 ? (__mmask16)((1u << left) - 1u) : 0;
    }
#pragma GCC unroll 6
    for (int r = 0; r < MR; r++) {
        const float b0 = bias && r < rows ? bias[r] : 0.0f;
        acc[r][0] = _mm512_set1_ps(b0), acc[r][1] = acc[r][0];
        if (accumulate && r < rows) {
            acc[r][0] = _mm512_maskz_loadu_ps(mk[0], C + (long)r * ldc + j);
            if (nv == 2) acc[r][1] = _mm512_maskz_loadu_ps(mk[1], C + (long)r * ldc + j + 16);
        }
    }
    const lm_bf16 *b = Bp + (size_t)j * 2;
    if (nv == 2) {
        for (int q = 0; q < K2; q++, a += MR * 2, b += (size_t)NP * 2) {
            __m512bh b0 = (__m512bh)_mm512_loadu_si512(b), b1 = (__m512bh)_mm512_loadu_si512(b + 32);
#pragma GCC unroll 6
            for (int r = 0; r < MR; r++) {
                int32_t pr;
                memcpy(&pr, a + 2 * r, 4);
                __m512bh av = (__m512bh)_mm512_set1_epi32(pr);
                acc[r][0] = _mm512_dpbf16_ps(acc[r][0], av, b0);
                acc[r][1] = _mm512_dpbf16_ps(acc[r][1], av, b1);
            }
        }
    } else {
        for (int q = 0; q < K2; q++, a += MR * 2, b += (size_t)NP * 2) {
            __m512bh b0 = (__m512bh)_mm512_loadu_si512(b);
#pragma GCC unroll 6
            for (int r = 0; r < MR; r++) {
                int32_t pr;
                memcpy(&pr, a + 2 * r, 4);
                acc[r][0] = _mm512_dpbf16_ps(acc[r][0], (__m512bh)_mm512_set1_epi32(pr), b0);
            }
        }
    }
    for (int r = 0; r < rows; r++) {
        _mm512_mask_storeu_ps(C + (long)r * ldc + j, mk[0], acc[r][0]);
        if (nv == 2) _mm512_mask_storeu_ps(C + (long)r * ldc + j + 16, mk[1], acc[r][1]);
    }
}

BF16 static void panel_avx512bf16(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                                  const float *bias, int accumulate, float *C, long ldc)
{
    const int K2 = (K + 1) / 2, NP = pad16(n);
    for (int j = 0; j < n; j += 32) {
        const int nv = n - j > 16 ? 2 : 1;
        for (int p = 0; p < M; p += MR) {
            const int rows = M - p < MR ? M - p : MR;
            tile(K2, NP, Ap + (size_t)p * K2 * 2, Bp, j, nv, rows, n, bias ? bias + p : NULL,
                 accumulate, C + (long)p * ldc, ldc);
        }
    }
}
#endif

int lm_gemm_bf16_native(void)
{
#if LM_HAVE_BF16_KERNEL
    return lm_cpu_features_get()->avx512_bf16 && lm_isa_active() >= LM_ISA_AVX512;
#else
    return 0;
#endif
}

const char *lm_precision_describe(int precision)
{
    if (precision != LM_PRECISION_BF16) return "fp32";
    if (lm_gemm_bf16_native()) return "bf16 (AVX-512-BF16 products, fp32 sums)";
    return lm_cpu_features_get()->avx512_bf16
               ? "bf16 (operands rounded to bf16, products in fp32: LM_ISA is below avx512)"
               : "bf16 (operands rounded to bf16, products in fp32: this CPU has no AVX-512-BF16)";
}

void lm_gemm_bf16_panel(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                        const float *bias, int accumulate, float *C, long ldc)
{
#if LM_HAVE_BF16_KERNEL
    if (lm_gemm_bf16_native()) {
        panel_avx512bf16(M, n, K, Ap, Bp, bias, accumulate, C, ldc);
        return;
    }
#endif
    panel_fp32(M, n, K, Ap, Bp, bias, accumulate, C, ldc);
}
