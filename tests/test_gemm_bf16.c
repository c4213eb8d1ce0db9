/* test_gemm_bf16.c — the bf16 panel product (tensor/ops/gemm_bf16.h): rounding to bf16
 * (nearest even, NaN and infinities kept), packing, and lm_gemm_bf16_panel against a double
 * reference over shapes that cut every edge (M not a multiple of the 6-row panel, odd K, n not
 * a multiple of 16 or 32), with and without bias, writing and accumulating:
 *   - against the sums of the bf16-rounded operands: within fp32 rounding (1e-6 of the terms'
 *     magnitude), so nothing but the operands' rounding separates it from fp32;
 *   - against the exact fp32 operands: within the bf16 bound 2^-7 of the magnitude (a value
 *     rounded to bf16's 8 significant bits is off by at most 2^-8 of itself, a product of two
 *     by 2^-7);
 *   - the AVX-512-BF16 kernel (when this CPU and level have it) equal to the fp32 twin
 *     (LM_ISA=avx2 in the isa-labelled run) to fp32 rounding: the same products, summed in the
 *     same order;
 *   - columns past n and rows past M of C untouched. */
#include "tests/check.h"
#include "tensor/ops/gemm_bf16.h"
#include <stdlib.h>

static float frand(lm_rng *r) { return lm_rng_uniform(r) * 2.0f - 1.0f; }

static void test_round(void)
{
    CHECK(lm_bf16_round(1.0f) == 0x3f80);
    CHECK(lm_bf16_round(-2.0f) == 0xc000);
    CHECK(lm_bf16_round(1.0f + 1.0f / 256) == 0x3f80);           /* tie: to even (down) */
    CHECK(lm_bf16_round(1.0f + 3.0f / 256) == 0x3f82);           /* tie: to even (up) */
    CHECK(lm_bf16_round(1.0f + 1.0f / 256 + 1.0f / 4096) == 0x3f81); /* above the tie */
    CHECK(lm_bf16_round(INFINITY) == 0x7f80);
    CHECK(lm_bf16_round(-INFINITY) == 0xff80);
    CHECK(lm_bf16_round(3.4e38f) == 0x7f80); /* rounds past the largest bf16: inf */
    float nan = lm_bf16_to_f32(lm_bf16_round(NAN));
    CHECK(nan != nan);
    CHECK(lm_bf16_to_f32(0x3f80) == 1.0f);
    CHECK(lm_bf16_to_f32(lm_bf16_round(0.1f)) == 0.10009765625f);
}

static void run_case(int M, int n, int K, int use_bias, int accumulate, lm_rng *r)
{
    const int ldc = n + 3;
    float *A = malloc(sizeof(float) * (size_t)M * K), *B = malloc(sizeof(float) * (size_t)K * n);
    float *bias = malloc(sizeof(float) * (size_t)M);
    float *C = malloc(sizeof(float) * (size_t)(M + 1) * ldc), *C0 = malloc(sizeof(float) * (size_t)(M + 1) * ldc);
    lm_bf16 *Ap = malloc(sizeof(lm_bf16) * lm_bf16_pack_a_size(M, K));
    lm_bf16 *Bp = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size(K, n));
    for (long i = 0; i < (long)M * K; i++) A[i] = frand(r);
    for (long i = 0; i < (long)K * n; i++) B[i] = frand(r);
    for (int i = 0; i < M; i++) bias[i] = frand(r);
    for (long i = 0; i < (long)(M + 1) * ldc; i++) C0[i] = C[i] = frand(r);
    lm_bf16_pack_a(M, K, A, K, Ap);
    lm_bf16_pack_b(K, n, B, n, Bp);
    lm_gemm_bf16_panel(M, n, K, Ap, Bp, use_bias ? bias : NULL, accumulate, C, ldc);
    long bad_r = 0, bad_x = 0, bad_edge = 0;
    double worst = 0;
    for (int m = 0; m < M; m++)
        for (int j = 0; j < n; j++) {
            double s0 = accumulate ? C0[(long)m * ldc + j] : use_bias ? bias[m] : 0.0;
            double sr = s0, sx = s0, mag = fabs(s0);
            for (int k = 0; k < K; k++) {
                double a = A[(long)m * K + k], b = B[(long)k * n + j];
                double ar = lm_bf16_to_f32(lm_bf16_round((float)a));
                double br = lm_bf16_to_f32(lm_bf16_round((float)b));
                sr += ar * br, sx += a * b, mag += fabs(a * b);
            }
            const double got = C[(long)m * ldc + j];
            if (!(fabs(got - sr) <= 1e-6 * (1 + mag))) bad_r++;
            if (!(fabs(got - sx) <= (1.0 / 128) * mag + 1e-6)) bad_x++;
            if (fabs(got - sx) / (1 + mag) > worst) worst = fabs(got - sx) / (1 + mag);
        }
    for (int m = 0; m <= M; m++)
        for (int j = m < M ? n : 0; j < ldc; j++)
            if (C[(long)m * ldc + j] != C0[(long)m * ldc + j]) bad_edge++;
    CHECK_MSG(bad_r == 0 && bad_x == 0 && bad_edge == 0,
              "M %d n %d K %d bias %d acc %d: %ld off the rounded sums, %ld off the bf16 bound, "
              "%ld written outside (worst %.3g)", M, n, K, use_bias, accumulate, bad_r, bad_x,
              bad_edge, worst);
    free(A), free(B), free(bias), free(C), free(C0), free(Ap), free(Bp);
}

static void test_shapes(void)
{
    static const int Ms[] = {1, 5, 6, 7, 16, 33};
    static const int Ks[] = {1, 2, 7, 16, 33, 64};
    static const int Ns[] = {1, 15, 16, 17, 31, 32, 33, 100};
    lm_rng r;
    lm_rng_seed(&r, 3);
    for (int a = 0; a < 6; a++)
        for (int b = 0; b < 6; b++)
            for (int c = 0; c < 8; c++)
                run_case(Ms[a], Ns[c], Ks[b], (a + c) % 2, (a + b + c) % 3 == 0, &r);
    run_case(64, 1024, 144, 1, 0, &r); /* a Winograd-sized product */
    printf("     (bf16 path: %s)\n", lm_gemm_bf16_native() ? "AVX-512-BF16" : "fp32");
}

/* A long sum: the rounding errors are random, so the rms error over the rms magnitude
 * falls as 1 / sqrt(K) (about 4e-3 / sqrt(K) for uniform operands), far below the bound. */
static void test_error_size(void)
{
    const int M = 12, n = 64, K = 512;
    lm_rng r;
    lm_rng_seed(&r, 9);
    float *A = malloc(sizeof(float) * M * K), *B = malloc(sizeof(float) * K * n);
    float *C = malloc(sizeof(float) * M * n);
    lm_bf16 *Ap = malloc(sizeof(lm_bf16) * lm_bf16_pack_a_size(M, K));
    lm_bf16 *Bp = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size(K, n));
    for (int i = 0; i < M * K; i++) A[i] = frand(&r);
    for (int i = 0; i < K * n; i++) B[i] = frand(&r);
    lm_bf16_pack_a(M, K, A, K, Ap);
    lm_bf16_pack_b(K, n, B, n, Bp);
    lm_gemm_bf16_panel(M, n, K, Ap, Bp, NULL, 0, C, n);
    double e2 = 0, m2 = 0;
    for (int m = 0; m < M; m++)
        for (int j = 0; j < n; j++) {
            double s = 0, mag = 0;
            for (int k = 0; k < K; k++) {
                s += (double)A[m * K + k] * B[k * n + j];
                mag += fabs((double)A[m * K + k] * B[k * n + j]);
            }
            e2 += (C[m * n + j] - s) * (C[m * n + j] - s), m2 += mag * mag;
        }
    double rel = sqrt(e2 / m2); /* rms error over rms magnitude: random rounding errors */
    CHECK_MSG(rel < 2e-3 / sqrt(K) * 4, "rms relative error %.3g", rel);
    free(A), free(B), free(C), free(Ap), free(Bp);
}

/* The packed B holds exactly lm_bf16_round of each value (the vector path included): ties,
 * infinities, NaN (stays NaN), denormals, both rows of a pair and the odd last row. */
static void test_pack_b_exact(void)
{
    const int K = 5, n = 37;
    float B[5 * 37];
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (int i = 0; i < K * n; i++) B[i] = frand(&r) * 1e3f;
    B[3] = INFINITY, B[40] = -INFINITY, B[41] = NAN, B[77] = 1e-40f, B[100] = 1.0f + 1.0f / 256;
    B[101] = -(1.0f + 3.0f / 256), B[20] = 3.4e38f;
    lm_bf16 *Bp = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size(K, n));
    lm_bf16_pack_b(K, n, B, n, Bp);
    long bad = 0;
    const int NP = (n + 15) / 16 * 16;
    for (int k = 0; k < 6; k++)
        for (int j = 0; j < NP; j++) {
            lm_bf16 want = k < K && j < n ? lm_bf16_round(B[k * n + j]) : 0;
            lm_bf16 got = Bp[((size_t)(k / 2) * NP + j) * 2 + k % 2];
            float wf = lm_bf16_to_f32(want), gf = lm_bf16_to_f32(got);
            if (got != want && !(wf != wf && gf != gf)) bad++;
        }
    CHECK_MSG(bad == 0, "%ld packed values differ from lm_bf16_round", bad);
    free(Bp);
}

int main(void)
{
    RUN(test_pack_b_exact);
    RUN(test_round);
    RUN(test_shapes);
    RUN(test_error_size);
    return check_summary();
}
