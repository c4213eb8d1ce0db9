/* bench_bf16.c — the bf16 panel product (tensor/ops/gemm_bf16.h), each kernel this CPU runs
 * (AMX tiles, AVX-512-BF16 vdpbf16ps), against the fp32 panel product (lm_sgemm_panel) and
 * the fp32 blocked SGEMM (lm_sgemm_st), one thread, on the convolution shapes (M = output
 * channels, K = input channels, n = tiles or pixels) and on 512 x 512 x 512. Interleaved:
 * every repetition runs each kernel once, in turn; min and median per kernel. GFLOP/s count
 * 2 M n K. "pack B" is the time to round and interleave B (an activation: once per call, in
 * each kernel's layout) and is not in the products' times; "with pack" adds it. Each bf16
 * product runs right after its packing (B fresh in cache, as in a convolution) and then 5
 * times more back to back ("again": the fastest of those, A, B and C in cache from the run
 * before, no other kernel in between); for 512^3 the AMX product also runs 200 times back to
 * back after the rounds ("alone"). Buffers are 64-byte aligned.
 * The peaks the products are measured against are measured too, on this core, each the best
 * of 40 short register-only rounds (a busy core only lowers them):
 *   - vdpbf16ps: 12 independent zmm accumulators, 64 FLOP per instruction (32 pair products,
 *     32 adds); fp32 FMA: the same with vfmadd231ps, 32 FLOP each;
 *   - AMX: tdpbf16ps back to back into 6 independent accumulator tiles from 2 source tiles
 *     (no loads or stores in the loop); one instruction multiplies a 16 x 32 bf16 tile by a
 *     32 x 16 one into 16 x 16 fp32 sums: 16 x 16 x 32 = 8,192 multiply-adds = 16,384 FLOP,
 *     so the peak is 16,384 x instructions per second.
 * Each product's "% peak" is its GFLOP/s over its own unit's peak (AMX, vdpbf16ps, FMA).
 * Usage: build/bench_bf16 [repeats]   (LM_ISA=avx512 hides the AMX kernel, LM_ISA=avx2 both) */
#include "tensor/isa.h"
#include "tensor/ops/gemm_bf16.h"
#include "tensor/ops/gemm_internal.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* 64-byte aligned (whole tile rows per cache line), rounded up to a multiple of 64 bytes */
static void *alloc64(size_t bytes) { return aligned_alloc(64, (bytes + 63) / 64 * 64); }

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

#if defined(__x86_64__) && defined(__GNUC__) &&                                              \
    ((defined(__clang__) && __clang_major__ >= 12) || (!defined(__clang__) && __GNUC__ >= 11))
#define HAVE_AMX_PEAK 1
#define AMX_PEAK_ITERS 20000L /* 6 tile instructions each: ~2 ms a round */
/* GFLOP/s of tdpbf16ps into 6 independent accumulators (tiles 0-5) from tiles 6 and 7. */
__attribute__((target("amx-tile,amx-bf16,avx512f"))) static double peak_amx(void)
{
    struct {
        unsigned char palette, start_row, reserved[14];
        unsigned short colsb[16];
        unsigned char rows[16];
    } cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.palette = 1;
    for (int t = 0; t < 8; t++) cfg.rows[t] = 16, cfg.colsb[t] = 64;
    static unsigned short src[16 * 32] __attribute__((aligned(64)));
    for (int i = 0; i < 16 * 32; i++) src[i] = i % 2 ? 0x3a80 : 0x3f80; /* 2^-10, 1 */
    static float out[16 * 16] __attribute__((aligned(64)));
    __asm__ volatile("" ::: "memory");
    _tile_loadconfig(&cfg);
    _tile_loadd(6, src, 64);
    _tile_loadd(7, src, 64);
    _tile_zero(0);
    _tile_zero(1);
    _tile_zero(2);
    _tile_zero(3);
    _tile_zero(4);
    _tile_zero(5);
    double t0 = now();
    for (long it = 0; it < AMX_PEAK_ITERS; it++) {
        _tile_dpbf16ps(0, 6, 7);
        _tile_dpbf16ps(1, 6, 7);
        _tile_dpbf16ps(2, 6, 7);
        _tile_dpbf16ps(3, 6, 7);
        _tile_dpbf16ps(4, 6, 7);
        _tile_dpbf16ps(5, 6, 7);
    }
    _tile_stored(0, out, 64); /* the result leaves the tiles: the loop is not dead */
    double t = now() - t0;
    _tile_release();
    if (out[0] == 12345.0f) printf(" ");
    return 6.0 * 16384.0 * AMX_PEAK_ITERS / t * 1e-9;
}
#else
#define HAVE_AMX_PEAK 0
#endif

/* min and median of reps times, in ms */
static void stats(double *t, int reps, double *mn, double *md)
{
    qsort(t, (size_t)reps, sizeof(double), cmp);
    *mn = t[0] * 1e3, *md = t[reps / 2] * 1e3;
}

int main(int argc, char **argv)
{
    const int reps = argc > 1 ? atoi(argv[1]) : 9;
    char isa[256];
    lm_isa_describe(isa, sizeof isa);
    printf("isa %s; bf16 product of this process: %s\n", isa,
           lm_bf16_kernel_name(lm_bf16_kernel_active()));
    /* the bf16 kernels measured: those this CPU runs at the active level */
    lm_bf16_kernel ks[2];
    int nk = 0;
    if (lm_bf16_kernel_active() == LM_BF16_AMX) ks[nk++] = LM_BF16_AMX;
    if (lm_bf16_kernel_active() != LM_BF16_FP32 && lm_bf16_kernel_runs(LM_BF16_DPBF16))
        ks[nk++] = LM_BF16_DPBF16;
    if (nk == 0) ks[nk++] = LM_BF16_FP32;
    double pk_bf = 0, pk_fp = 0, pk_amx = 0; /* measured single-core peaks (0: not here) */
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
#if HAVE_AMX_PEAK
            if (lm_bf16_kernel_active() == LM_BF16_AMX) {
                double a = peak_amx();
                if (a > pk_amx) pk_amx = a;
            }
#endif
        }
    }
    printf("measured peak, one core: fp32 FMA %.1f GFLOP/s; ", pk_fp);
    if (pk_bf > 0) printf("vdpbf16ps %.1f GFLOP/s; ", pk_bf);
    else printf("vdpbf16ps n/a (no AVX-512-BF16 at this level); ");
    if (pk_amx > 0)
        printf("AMX tdpbf16ps %.1f GFLOP/s (%.1f M tile instructions/s x 16,384 FLOP)\n",
               pk_amx, pk_amx * 1e3 / 16384.0);
    else
        printf("AMX %s\n", !cf->amx_bf16 ? "absent on this CPU"
                           : lm_isa_active() < LM_ISA_AMX ? "not used at this level (LM_ISA)"
                                                          : "tile state refused by the kernel");
#endif
    static const int shapes[][3] = {{16, 2048, 16}, {32, 2048, 32}, {64, 2048, 64},
                                    {128, 1024, 128}, {64, 4096, 144}, {512, 512, 512}};
    printf("times in ms (min / median over %d interleaved rounds); GFLOP/s and %% of the unit's "
           "peak from the min\n", reps);
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const int M = shapes[s][0], n = shapes[s][1], K = shapes[s][2];
        float *A = alloc64(sizeof(float) * (size_t)M * K), *B = alloc64(sizeof(float) * (size_t)K * n);
        float *C = alloc64(sizeof(float) * (size_t)M * n);
        float *Ap = alloc64(sizeof(float) * (size_t)lm_panel_size(M, K));
        lm_bf16 *Ah[2], *Bh[2];
        for (long i = 0; i < (long)M * K; i++) A[i] = (float)((i * 7919) % 1000) / 1000 - 0.5f;
        for (long i = 0; i < (long)K * n; i++) B[i] = (float)((i * 104729) % 1000) / 1000 - 0.5f;
        lm_panel_pack(M, K, A, K, Ap);
        for (int k = 0; k < nk; k++) {
            Ah[k] = alloc64(sizeof(lm_bf16) * lm_bf16_pack_a_size_for(ks[k], M, K));
            Bh[k] = alloc64(sizeof(lm_bf16) * lm_bf16_pack_b_size_for(ks[k], K, n));
            lm_bf16_pack_a_for(ks[k], M, K, A, K, Ah[k]);
            lm_bf16_pack_b_for(ks[k], K, n, B, n, Bh[k]);
        }
        /* rows: fp32 panel, sgemm_st, then per bf16 kernel: product, pack B, product again */
        const int nr = 2 + 3 * nk;
        double *t[8];
        for (int k = 0; k < nr; k++) t[k] = malloc(sizeof(double) * (size_t)reps);
        for (int r = 0; r < reps; r++) {
            double t0 = now();
            lm_sgemm_panel(M, n, K, Ap, B, n, NULL, 0, C, n);
            double t1 = now();
            lm_sgemm_st(0, 0, M, n, K, 1.0f, A, K, B, n, 0.0f, C, n);
            double t2 = now();
            t[0][r] = t1 - t0, t[1][r] = t2 - t1;
            for (int k = 0; k < nk; k++) { /* pack B, multiply (B fresh, as in a convolution),
                                              * then 5 more back to back (all in cache): the
                                              * fastest of those */
                t0 = now();
                lm_bf16_pack_b_for(ks[k], K, n, B, n, Bh[k]);
                t1 = now();
                lm_gemm_bf16_panel_for(ks[k], M, n, K, Ah[k], Bh[k], NULL, 0, C, n);
                t2 = now();
                double again = 1e30;
                for (int a = 0; a < 5; a++) {
                    double ta = now();
                    lm_gemm_bf16_panel_for(ks[k], M, n, K, Ah[k], Bh[k], NULL, 0, C, n);
                    ta = now() - ta;
                    if (ta < again) again = ta;
                }
                t[2 + 3 * k][r] = t2 - t1, t[3 + 3 * k][r] = t1 - t0, t[4 + 3 * k][r] = again;
            }
        }
        double mn[8], md[8];
        for (int k = 0; k < nr; k++) stats(t[k], reps, &mn[k], &md[k]);
        const double gf = 2.0 * M * n * K * 1e-9;
        printf("%d x %d x %d\n", M, n, K);
        printf("  %-26s %8.3f / %8.3f  %7.1f GFLOP/s", "fp32 panel (lm_sgemm_panel)", mn[0],
               md[0], gf / mn[0] * 1e3);
        if (pk_fp > 0) printf("  %3.0f %% of FMA peak", 100 * gf / mn[0] * 1e3 / pk_fp);
        printf("\n  %-26s %8.3f / %8.3f  %7.1f GFLOP/s\n", "fp32 sgemm_st", mn[1], md[1],
               gf / mn[1] * 1e3);
        for (int k = 0; k < nk; k++) {
            const double *mk = mn + 2 + 3 * k, *dk = md + 2 + 3 * k, p = gf / mk[0] * 1e3;
            const double pk = ks[k] == LM_BF16_AMX ? pk_amx : ks[k] == LM_BF16_DPBF16 ? pk_bf : 0;
            printf("  %-26s %8.3f / %8.3f  %7.1f GFLOP/s", lm_bf16_kernel_name(ks[k]), mk[0],
                   dk[0], p);
            if (pk > 0) printf("  %3.0f %% of its peak", 100 * p / pk);
            printf("\n  %-26s %8.3f / %8.3f  %7.1f GFLOP/s", "  again (back to back)", mk[2], dk[2],
                   gf / mk[2] * 1e3);
            if (pk > 0) printf("  %3.0f %% of its peak", 100 * gf / mk[2] * 1e3 / pk);
            printf("\n  %-26s %8.3f / %8.3f  with pack %.1f GFLOP/s, %.2fx the fp32 panel\n",
                   "  pack B", mk[1], dk[1], gf / (mk[0] + mk[1]) * 1e3, mn[0] / (mk[0] + mk[1]));
        }
        if (M == 512 && nk > 0 && ks[0] == LM_BF16_AMX) { /* the tile kernel alone */
            enum { ALONE = 200 };
            double *ta = malloc(sizeof(double) * ALONE);
            for (int a = 0; a < ALONE; a++) {
                double t0 = now();
                lm_gemm_bf16_panel_for(LM_BF16_AMX, M, n, K, Ah[0], Bh[0], NULL, 0, C, n);
                ta[a] = now() - t0;
            }
            double mna, mda;
            stats(ta, ALONE, &mna, &mda);
            printf("  %-26s %8.3f / %8.3f  %7.1f GFLOP/s", "  alone, 200 back to back", mna,
                   mda, gf / mna * 1e3);
            if (pk_amx > 0) printf("  %3.0f %% of its peak", 100 * gf / mna * 1e3 / pk_amx);
            printf("\n");
            free(ta);
        }
        for (int k = 0; k < nr; k++) free(t[k]);
        for (int k = 0; k < nk; k++) free(Ah[k]), free(Bh[k]);
        free(A), free(B), free(C), free(Ap);
    }
    return 0;
}
