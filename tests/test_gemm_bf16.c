/* test_gemm_bf16.c — the bf16 panel product (tensor/ops/gemm_bf16.h): rounding to bf16
 * (nearest even, NaN and infinities kept), each kernel's packing, and lm_gemm_bf16_panel_for
 * with every kernel this process runs (AMX tiles, AVX-512-BF16, the fp32 twin; a kernel that
 * does not run at this level is multiplied by the fp32 twin from its own layout, and tested
 * so) against a double reference, over shapes that cut every edge (M not a multiple of the
 * 6-row panel or the 16-row tile, K odd or not a multiple of 32, n not a multiple of 16 or 32),
 * with and without bias, writing and accumulating, C's leading dimension odd or a multiple of
 * 256 (the AMX kernel's prefetching path), packed A under and over 32 KiB (its two orders):
 *   - against the sums of the bf16-rounded operands: within fp32 summation error. A product of
 *     two bf16 values (8 significant bits each) is exact in fp32, so only the sums round: at
 *     most K + 1 additions, each off by at most 2^-24 of a partial sum bounded by
 *     |start| + sum |a_k b_k|, so |error| <= (K + 1) 2^-24 (|start| + sum |a_k b_k|) (first
 *     order; 1.01 times that is allowed), whatever order or internal width the kernel adds in.
 *     AMX reads bf16 denormals as zero and flushes fp32 denormal results: below 2^-126 each,
 *     K 2^-126 more is allowed (the operands here are never denormal);
 *   - against the exact fp32 operands: within the bf16 bound 2^-7 of the magnitude (a value
 *     rounded to bf16's 8 significant bits is off by at most 2^-8 of itself, a product of two
 *     by 2^-7), plus the summation bound;
 *   - every kernel against the first one run (AMX on a CPU with tiles): within twice the
 *     summation bound (each is within it of the same sums);
 *   - columns past n and rows past M of C untouched.
 * On a CPU with AMX (and the level amx) it checks that the process's kernel is AMX. */
#include "tests/check.h"
#include "tensor/ops/gemm_bf16.h"
#include <stdlib.h>

static float frand(lm_rng *r) { return lm_rng_uniform(r) * 2.0f - 1.0f; }

static const lm_bf16_kernel all_kernels[3] = {LM_BF16_AMX, LM_BF16_DPBF16, LM_BF16_FP32};

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

/* Which kernels run here, and the process's own: AMX wherever the CPU, the level and the
 * operating system allow it. */
static void test_kernel_choice(void)
{
    const lm_cpu_features *f = lm_cpu_features_get();
    const lm_bf16_kernel act = lm_bf16_kernel_active();
    printf("     (bf16 kernel of this process: %s; runs:", lm_bf16_kernel_name(act));
    for (int k = 0; k < 3; k++)
        if (lm_bf16_kernel_runs(all_kernels[k])) printf(" [%s]", lm_bf16_kernel_name(all_kernels[k]));
    printf("; %s)\n", lm_precision_describe(LM_PRECISION_BF16));
    CHECK(lm_bf16_kernel_runs(act));
    CHECK(lm_bf16_kernel_runs(LM_BF16_FP32));
    if (f->amx_bf16 && lm_isa_active() >= LM_ISA_AMX && lm_amx_tile_granted()) {
        CHECK(act == LM_BF16_AMX);
        CHECK(strstr(lm_precision_describe(LM_PRECISION_BF16), "AMX tiles") != NULL);
    } else if (f->avx512_bf16 && lm_isa_active() >= LM_ISA_AVX512) {
        CHECK(act == LM_BF16_DPBF16);
    } else {
        CHECK(act == LM_BF16_FP32);
    }
    if (lm_isa_active() < LM_ISA_AMX) CHECK(!lm_bf16_kernel_runs(LM_BF16_AMX));
    if (lm_isa_active() < LM_ISA_AVX512) CHECK(!lm_bf16_kernel_runs(LM_BF16_DPBF16));
    CHECK(lm_gemm_bf16_native() == (act != LM_BF16_FP32));
}

/* C = bias + A B or C += A B with kernel k; C (M + 1 rows of ldc) starts as C0. */
static void product(lm_bf16_kernel k, int M, int n, int K, const float *A, const float *B,
                    const float *bias, int accumulate, const float *C0, float *C, long ldc)
{
    lm_bf16 *Ap = malloc(sizeof(lm_bf16) * lm_bf16_pack_a_size_for(k, M, K));
    lm_bf16 *Bp = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size_for(k, K, n));
    lm_bf16_pack_a_for(k, M, K, A, K, Ap);
    lm_bf16_pack_b_for(k, K, n, B, n, Bp);
    memcpy(C, C0, sizeof(float) * (size_t)(M + 1) * ldc);
    lm_gemm_bf16_panel_for(k, M, n, K, Ap, Bp, bias, accumulate, C, ldc);
    free(Ap), free(Bp);
}

static long cases_run[3];

static void run_case(int M, int n, int K, long ldc, int use_bias, int accumulate, lm_rng *r)
{
    float *A = malloc(sizeof(float) * (size_t)M * K), *B = malloc(sizeof(float) * (size_t)K * n);
    float *bias = malloc(sizeof(float) * (size_t)M);
    float *C0 = malloc(sizeof(float) * (size_t)(M + 1) * ldc);
    float *C[3];
    for (int k = 0; k < 3; k++) C[k] = malloc(sizeof(float) * (size_t)(M + 1) * ldc);
    for (long i = 0; i < (long)M * K; i++) A[i] = frand(r);
    for (long i = 0; i < (long)K * n; i++) B[i] = frand(r);
    for (int i = 0; i < M; i++) bias[i] = frand(r);
    for (long i = 0; i < (long)(M + 1) * ldc; i++) C0[i] = frand(r);
    for (int k = 0; k < 3; k++) {
        product(all_kernels[k], M, n, K, A, B, use_bias ? bias : NULL, accumulate, C0, C[k], ldc);
        cases_run[k]++;
    }
    const double u = 1.0 / (1 << 24);
    for (int k = 0; k < 3; k++) {
        long bad_r = 0, bad_x = 0, bad_edge = 0, bad_k = 0;
        double worst = 0;
        for (int m = 0; m < M; m++)
            for (int j = 0; j < n; j++) {
                double s0 = accumulate ? C0[(long)m * ldc + j] : use_bias ? bias[m] : 0.0;
                double sr = s0, sx = s0, mag = fabs(s0);
                for (int q = 0; q < K; q++) {
                    double a = A[(long)m * K + q], b = B[(long)q * n + j];
                    double ar = lm_bf16_to_f32(lm_bf16_round((float)a));
                    double br = lm_bf16_to_f32(lm_bf16_round((float)b));
                    sr += ar * br, sx += a * b, mag += fabs(ar * br);
                }
                const double sum_tol = 1.01 * (K + 1) * u * mag + K * 0x1p-126;
                const double got = C[k][(long)m * ldc + j];
                if (!(fabs(got - sr) <= sum_tol)) bad_r++;
                if (!(fabs(got - sx) <= (1.0 / 128) * mag + sum_tol)) bad_x++;
                if (!(fabs(got - C[0][(long)m * ldc + j]) <= 2 * sum_tol)) bad_k++;
                if (fabs(got - sr) / (sum_tol) > worst) worst = fabs(got - sr) / sum_tol;
            }
        for (int m = 0; m <= M; m++)
            for (int j = m < M ? n : 0; j < ldc; j++)
                if (C[k][(long)m * ldc + j] != C0[(long)m * ldc + j]) bad_edge++;
        CHECK_MSG(bad_r == 0 && bad_x == 0 && bad_edge == 0 && bad_k == 0,
                  "%s: M %d n %d K %d ldc %ld bias %d acc %d: %ld off the rounded sums, %ld off "
                  "the bf16 bound, %ld off the first kernel, %ld written outside (worst %.3g of "
                  "the summation bound)", lm_bf16_kernel_name(all_kernels[k]), M, n, K, ldc,
                  use_bias, accumulate, bad_r, bad_x, bad_k, bad_edge, worst);
    }
    for (int k = 0; k < 3; k++) free(C[k]);
    free(A), free(B), free(bias), free(C0);
}

static void test_shapes(void)
{
    static const int Ms[] = {1, 6, 7, 15, 16, 17, 33, 96};
    static const int Ks[] = {1, 2, 31, 32, 33, 96, 97};
    static const int Ns[] = {1, 15, 16, 17, 32, 33, 100};
    lm_rng r;
    lm_rng_seed(&r, 3);
    for (int a = 0; a < 8; a++)
        for (int b = 0; b < 7; b++)
            for (int c = 0; c < 7; c++)
                run_case(Ms[a], Ns[c], Ks[b], Ns[c] + 3, (a + c) % 2, (a + b + c) % 3 == 0, &r);
    /* C's rows 1 KiB apart (the AMX kernel fetches them for writing ahead) */
    run_case(96, 100, 64, 256, 0, 0, &r);
    run_case(33, 256, 97, 256, 1, 0, &r);
    run_case(64, 256, 33, 512, 0, 1, &r);
    run_case(64, 1024, 144, 1027, 1, 0, &r); /* a Winograd-sized product */
    /* A over 32 KiB packed (the AMX kernel's row-pairs-outer order), edges on every side */
    run_case(96, 100, 200, 103, 1, 0, &r);
    run_case(65, 70, 301, 256, 0, 1, &r);
    printf("     (cases per kernel: %ld, run as", cases_run[0]);
    for (int k = 0; k < 3; k++)
        printf(" [%s: %s]", lm_bf16_kernel_name(all_kernels[k]),
               lm_bf16_kernel_runs(all_kernels[k]) ? "its own instructions" : "the fp32 twin");
    printf(")\n");
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

/* Where element (row, k) of A and (k, col) of B sit in kernel kern's packing (gemm_bf16.c). */
static size_t a_index(lm_bf16_kernel kern, int K, int m, int k)
{
    const int K2 = (K + 1) / 2, q = k / 2, t = k % 2;
    if (kern != LM_BF16_AMX)
        return (((size_t)(m / LM_BF16_MR) * K2 + q) * LM_BF16_MR + m % LM_BF16_MR) * 2 + t;
    const int S = (K2 + 15) / 16, kb = (K2 + S - 1) / S;
    return (((size_t)(m / 16) * S + q / kb) * 16 + m % 16) * 2 * kb + 2 * (q % kb) + t;
}

static size_t b_index(lm_bf16_kernel kern, int K, int n, int k, int j)
{
    const int K2 = (K + 1) / 2, NP = (n + 15) / 16 * 16, q = k / 2, t = k % 2;
    if (kern != LM_BF16_AMX) return ((size_t)q * NP + j) * 2 + t;
    const int S = (K2 + 15) / 16, kb = (K2 + S - 1) / S, BS = S * kb + 1;
    return (((size_t)(j / 16) * BS + q) * 16 + j % 16) * 2 + t;
}

/* The packed A and B hold exactly lm_bf16_round of each value (the vector path included):
 * ties, infinities, NaN (stays NaN), denormals, both rows of a pair and the odd last row;
 * and zeros everywhere else (the padding of the rows, pairs and columns), in each layout. */
static void test_pack_exact(void)
{
    const int K = 37, n = 37, M = 19;
    float B[37 * 37], A[19 * 37];
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (int i = 0; i < K * n; i++) B[i] = frand(&r) * 1e3f;
    for (int i = 0; i < M * K; i++) A[i] = frand(&r) * 1e3f;
    B[3] = INFINITY, B[40] = -INFINITY, B[41] = NAN, B[77] = 1e-40f, B[100] = 1.0f + 1.0f / 256;
    B[101] = -(1.0f + 3.0f / 256), B[20] = 3.4e38f, B[K * n - 1] = NAN;
    A[5] = INFINITY, A[40] = NAN, A[M * K - 1] = 1.0f + 3.0f / 256;
    for (int kk = 0; kk < 2; kk++) {
        const lm_bf16_kernel kern = kk ? LM_BF16_AMX : LM_BF16_DPBF16;
        const size_t nb = lm_bf16_pack_b_size_for(kern, K, n);
        const size_t na = lm_bf16_pack_a_size_for(kern, M, K);
        lm_bf16 *Bp = malloc(sizeof(lm_bf16) * nb), *Ap = malloc(sizeof(lm_bf16) * na);
        char *seen_b = calloc(nb, 1), *seen_a = calloc(na, 1);
        memset(Bp, 0x55, sizeof(lm_bf16) * nb); /* no zero by chance */
        memset(Ap, 0x55, sizeof(lm_bf16) * na);
        lm_bf16_pack_b_for(kern, K, n, B, n, Bp);
        lm_bf16_pack_a_for(kern, M, K, A, K, Ap);
        long bad = 0, bad_pad = 0;
        for (int k = 0; k < K; k++)
            for (int j = 0; j < n; j++) {
                const size_t at = b_index(kern, K, n, k, j);
                lm_bf16 want = lm_bf16_round(B[k * n + j]), got = Bp[at];
                float wf = lm_bf16_to_f32(want), gf = lm_bf16_to_f32(got);
                if (at >= nb || (got != want && !(wf != wf && gf != gf))) bad++;
                if (at < nb) seen_b[at] = 1;
            }
        for (int m = 0; m < M; m++)
            for (int k = 0; k < K; k++) {
                const size_t at = a_index(kern, K, m, k);
                lm_bf16 want = lm_bf16_round(A[m * K + k]), got = Ap[at];
                float wf = lm_bf16_to_f32(want), gf = lm_bf16_to_f32(got);
                if (at >= na || (got != want && !(wf != wf && gf != gf))) bad++;
                if (at < na) seen_a[at] = 1;
            }
        for (size_t i = 0; i < nb; i++) bad_pad += !seen_b[i] && Bp[i] != 0;
        for (size_t i = 0; i < na; i++) bad_pad += !seen_a[i] && Ap[i] != 0;
        CHECK_MSG(bad == 0 && bad_pad == 0, "%s layout: %ld packed values differ from "
                  "lm_bf16_round, %ld padding values not zero", lm_bf16_kernel_name(kern), bad,
                  bad_pad);
        free(Bp), free(Ap), free(seen_b), free(seen_a);
    }
}

int main(void)
{
    RUN(test_kernel_choice);
    RUN(test_pack_exact);
    RUN(test_round);
    RUN(test_shapes);
    RUN(test_error_size);
    return check_summary();
}
