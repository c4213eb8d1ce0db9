/* bench_bf16.c — the bf16 panel product (tensor/ops/gemm_bf16.h) against the fp32 panel
 * product (lm_sgemm_panel) and the fp32 blocked SGEMM (lm_sgemm_st), one thread, on the
 * convolution shapes (M = output channels, K = input channels, n = tiles or pixels) and on
 * 512 x 512 x 512. Interleaved: every repetition runs each kernel once, in turn; min and
 * median per kernel. GFLOP/s count 2 M n K. "pack B" is the time to round and interleave B
 * (an activation: once per call) and is not in the bf16 product's time.
 * The peak the products are measured against is measured too, on this core: a register-only
 * loop of independent vdpbf16ps (12 accumulators, 64 FLOP each) and of independent fp32 FMAs
 * (12 zmm accumulators, 32 FLOP each) -- the issue rate times the clock as the core runs it,
 * turbo and all. Each product's "% peak" is its GFLOP/s over that figure. AMX tile peaks are
 * printed only on a CPU with AMX (none here: the bf16 product has no tile kernel).
 * Usage: build/bench_bf16 [repeats]   (LM_ISA=avx2 shows the fp32 twin of the bf16 path) */
#include "tensor/isa.h"
#include "tensor/ops/gemm_bf16.h"
#include "tensor/ops/gemm_internal.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define PEAK_ITERS 400000L /* ~5 ms a round: short enough to fall between interruptions */
/* 12 independent accumulators in registers, OP(acc) per round, an empty asm keeping them
 * live (and the compiler from folding the rounds). */
#define PEAK_BODY(INIT, OP, FLOPS)                                                              \
    __m512 c0 = INIT, c1 = INIT, c2 = INIT, c3 = INIT, c4 = INIT, c5 = INIT, c6 = INIT,        \
           c7 = INIT, c8 = INIT, c9 = INIT, c10 = INIT, c11 = INIT;                             \
    double t0 = now();                                                                         \
    for (long it = 0; it < PEAK_ITERS; it++) {                                                 \
        c0 = OP(c0), c1 = OP(c1), c2 = OP(c2), c3 = OP(c3), c4 = OP(c4), c5 = OP(c5);          \
        c6 = OP(c6), c7 = OP(c7), c8 = OP(c8), c9 = OP(c9), c10 = OP(c10), c11 = OP(c11);      \
        __asm__ volatile("" : "+v"(c0), "+v"(c1), "+v"(c2), "+v"(c3), "+v"(c4), "+v"(c5),     \
                         "+v"(c6), "+v"(c7), "+v"(c8), "+v"(c9), "+v"(c10), "+v"(c11));        \
    }                                                                                          \
    double t = now() - t0;                                                                     \
    c0 = _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(c0, c1), _mm512_add_ps(c2, c3)),           \
                       _mm512_add_ps(_mm512_add_ps(c4, c5), _mm512_add_ps(c6, c7)));          \
    c0 = _mm512_add_ps(c0, _mm512_add_ps(_mm512_add_ps(c8, c9), _mm512_add_ps(c10, c11)));    \
    if (_mm512_reduce_add_ps(c0) == 12345.0f) printf(" ");                                    \
    return 12.0 * (FLOPS) * PEAK_ITERS / t * 1e-9;

/* GFLOP/s of independent vdpbf16ps (64 FLOP each: 32 pair products, 32 adds). */
__attribute__((target("avx512f,avx512bf16"))) static double peak_bf16(void)
{
    const __m512bh a = (__m512bh)_mm512_set1_epi16(0x3f80), b = (__m512bh)_mm512_set1_epi16(0x3c00);
#define DP(c) _mm512_dpbf16_ps(c, a, b)
    PEAK_BODY(_mm512_setzero_ps(), DP, 64.0)
#undef DP
}
/* The same with fp32 FMAs (vfmadd231ps zmm: 32 FLOP each). */
__attribute__((target("avx512f"))) static double peak_fma(void)
{
    const __m512 a = _mm512_set1_ps(1.0f), b = _mm512_set1_ps(0.5f);
#define FMA(c) _mm512_fmadd_ps(a, b, c)
    PEAK_BODY(_mm512_setzero_ps(), FMA, 32.0)
#undef FMA
}
#endif

int main(int argc, char **argv)
{
    const int reps = argc > 1 ? atoi(argv[1]) : 9;
    char isa[256];
    lm_isa_describe(isa, sizeof isa);
    printf("isa %s; bf16 product: %s\n", isa,
           lm_gemm_bf16_native() ? "AVX-512-BF16 (vdpbf16ps)" : "fp32 twin");
    double pk_bf = 0, pk_fp = 0; /* measured single-core peaks (0: not measurable here) */
#if defined(__x86_64__) && defined(__GNUC__)
    const lm_cpu_features *cf = lm_cpu_features_get();
    if (lm_isa_active() >= LM_ISA_AVX512) {
        for (int r = 0; r < 40; r++) { /* best of 40 short rounds: a busy core only lowers it */
            double f = peak_fma();
            if (f > pk_fp) pk_fp = f;
            if (cf->avx512_bf16) {
                double b = peak_bf16();
                if (b > pk_bf) pk_bf = b;
            }
        }
    }
    printf("measured peak, one core: fp32 FMA %.1f GFLOP/s; ", pk_fp);
    if (pk_bf > 0) printf("vdpbf16ps %.1f GFLOP/s; ", pk_bf);
    else printf("vdpbf16ps n/a (no AVX-512-BF16 at this level); ");
    printf("AMX tiles %s\n", cf->amx_bf16 ? "present (no tile kernel in this build)"
                                         : "absent on this CPU");
#endif
    static const int shapes[][3] = {{16, 2048, 16}, {32, 2048, 32}, {64, 2048, 64},
                                    {128, 1024, 128}, {64, 4096, 144}, {512, 512, 512}};
    printf("%-16s %10s %10s %10s %10s %10s %10s %8s %8s\n", "M x n x K", "fp32 panel",
           "GFLOP/s", "bf16", "GFLOP/s", "pack B", "sgemm_st", "bf16/fp32", "GFLOP/s");
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const int M = shapes[s][0], n = shapes[s][1], K = shapes[s][2];
        float *A = malloc(sizeof(float) * (size_t)M * K), *B = malloc(sizeof(float) * (size_t)K * n);
        float *C = malloc(sizeof(float) * (size_t)M * n);
        float *Ap = malloc(sizeof(float) * (size_t)lm_panel_size(M, K));
        lm_bf16 *Ah = malloc(sizeof(lm_bf16) * lm_bf16_pack_a_size(M, K));
        lm_bf16 *Bh = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size(K, n));
        for (long i = 0; i < (long)M * K; i++) A[i] = (float)((i * 7919) % 1000) / 1000 - 0.5f;
        for (long i = 0; i < (long)K * n; i++) B[i] = (float)((i * 104729) % 1000) / 1000 - 0.5f;
        lm_panel_pack(M, K, A, K, Ap);
        lm_bf16_pack_a(M, K, A, K, Ah);
        lm_bf16_pack_b(K, n, B, n, Bh);
        double *t[4];
        for (int k = 0; k < 4; k++) t[k] = malloc(sizeof(double) * (size_t)reps);
        for (int r = 0; r < reps; r++) {
            double t0 = now();
            lm_sgemm_panel(M, n, K, Ap, B, n, NULL, 0, C, n);
            double t1 = now();
            lm_gemm_bf16_panel(M, n, K, Ah, Bh, NULL, 0, C, n);
            double t2 = now();
            lm_bf16_pack_b(K, n, B, n, Bh);
            double t3 = now();
            lm_sgemm_st(0, 0, M, n, K, 1.0f, A, K, B, n, 0.0f, C, n);
            double t4 = now();
            t[0][r] = t1 - t0, t[1][r] = t2 - t1, t[2][r] = t3 - t2, t[3][r] = t4 - t3;
        }
        double mn[4], md[4];
        for (int k = 0; k < 4; k++) {
            qsort(t[k], (size_t)reps, sizeof(double), cmp);
            mn[k] = t[k][0] * 1e3, md[k] = t[k][reps / 2] * 1e3;
        }
        const double gf = 2.0 * M * n * K * 1e-9;
        char name[32];
        snprintf(name, sizeof name, "%dx%dx%d", M, n, K);
        printf("%-16s %10.3f %10.1f %10.3f %10.1f %10.3f %10.3f %8.2f %8.1f   (ms min; "
               "medians %.3f %.3f %.3f %.3f)", name, mn[0], gf / mn[0] * 1e3, mn[1],
               gf / mn[1] * 1e3, mn[2], mn[3], mn[0] / mn[1], gf / mn[3] * 1e3, md[0], md[1],
               md[2], md[3]);
        if (pk_fp > 0) printf(" fp32 panel %.0f %% of FMA peak", 100 * gf / mn[0] * 1e3 / pk_fp);
        if (pk_bf > 0 && lm_gemm_bf16_native())
            printf(", bf16 %.0f %% of vdpbf16ps peak", 100 * gf / mn[1] * 1e3 / pk_bf);
        printf("\n");
        for (int k = 0; k < 4; k++) free(t[k]);
        free(A), free(B), free(C), free(Ap), free(Ah), free(Bh);
    }
    return 0;
}
