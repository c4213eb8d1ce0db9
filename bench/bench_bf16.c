/* bench_bf16.c — the bf16 panel product (tensor/ops/gemm_bf16.h) against the fp32 panel
 * product (lm_sgemm_panel) and the fp32 blocked SGEMM (lm_sgemm_st), one thread, on the
 * convolution shapes (M = output channels, K = input channels, n = tiles or pixels) and on
 * 512 x 512 x 512. Interleaved: every repetition runs each kernel once, in turn; min and
 * median per kernel. GFLOP/s count 2 M n K. "pack B" is the time to round and interleave B
 * (an activation: once per call) and is not in the bf16 product's time.
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

int main(int argc, char **argv)
{
    const int reps = argc > 1 ? atoi(argv[1]) : 9;
    char isa[256];
    lm_isa_describe(isa, sizeof isa);
    printf("isa %s; bf16 product: %s\n", isa,
           lm_gemm_bf16_native() ? "AVX-512-BF16 (vdpbf16ps)" : "fp32 twin");
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
               "medians %.3f %.3f %.3f %.3f)\n", name, mn[0], gf / mn[0] * 1e3, mn[1],
               gf / mn[1] * 1e3, mn[2], mn[3], mn[0] / mn[1], gf / mn[3] * 1e3, md[0], md[1],
               md[2], md[3]);
        for (int k = 0; k < 4; k++) free(t[k]);
        free(A), free(B), free(C), free(Ap), free(Ah), free(Bh);
    }
    return 0;
}
