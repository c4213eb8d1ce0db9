/* test_sgemm.c — lm_sgemm_st (sgemm_avx512.c) against a double-precision naive reference:
 * many shapes (1x1x1, primes, sizes not multiples of the micro-tile or the K / M / N blocks),
 * all four transposes, leading dimensions wider than the matrices (the gap must stay
 * untouched), alpha 0.5, beta 0 / 1 / -2, beta 0 over NaN-filled C, K 0 and alpha 0; both
 * implementations (LM_SGEMM=blas from the environment, then the AVX-512 kernel when the CPU
 * has it), and lm_gemm_mt split over 2 threads equal to one thread bit for bit. */
#include "tests/check.h"
#include "tensor/ops/gemm_internal.h"
#include <stdlib.h>

typedef struct shape {
    int M, N, K;
} shape;

static const shape SHAPES[] = {
    {1, 1, 1},    {1, 7, 3},     {5, 1, 9},     {2, 3, 0},      {7, 13, 17},   {8, 48, 256},
    {9, 49, 257}, {31, 37, 41},  {16, 4224 / 8, 144}, {64, 97, 600}, {129, 50, 513},
    {3, 3100, 5}, {130, 47, 33}, {17, 3073, 2},  {200, 20, 1},
};
#define NSHAPES ((int)(sizeof SHAPES / sizeof SHAPES[0]))

static float frand(lm_rng *r) { return lm_rng_uniform(r) * 2.0f - 1.0f; }

/* op(X)[i][k] for a matrix stored row-major with leading dimension ld. */
static double at(const float *X, int trans, int ld, int i, int k)
{
    return trans ? X[(long)k * ld + i] : X[(long)i * ld + k];
}

/* One case: returns nothing, reports through CHECK. pad = extra leading-dimension floats. */
static void run_case(const shape *s, int ta, int tb, float alpha, float beta, int nan_c,
                     int pad, lm_rng *r)
{
    int M = s->M, N = s->N, K = s->K;
    int ar = ta ? K : M, ac = ta ? M : K, br = tb ? N : K, bc = tb ? K : N;
    int lda = ac + pad, ldb = bc + pad, ldc = N + pad;
    long na = (long)ar * lda + 1, nb = (long)br * ldb + 1, nc = (long)M * ldc;
    float *A = malloc(sizeof(float) * na), *B = malloc(sizeof(float) * nb);
    float *C = malloc(sizeof(float) * nc), *C0 = malloc(sizeof(float) * nc);
    for (long i = 0; i < na; i++) A[i] = frand(r);
    for (long i = 0; i < nb; i++) B[i] = frand(r);
    for (long i = 0; i < nc; i++) C0[i] = C[i] = nan_c ? NAN : frand(r);
    lm_sgemm_st(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc);
    long bad = 0, gap = 0;
    double worst = 0.0;
    for (int i = 0; i < M; i++) {
        for (int j = 0; j < N; j++) {
            double ref = 0.0, mag = 0.0;
            for (int k = 0; k < K; k++) {
                double p = at(A, ta, lda, i, k) * at(B, !tb, ldb, j, k);
                ref += p, mag += fabs(p);
            }
            double c0 = C0[(long)i * ldc + j];
            double bc = beta == 0.0f ? 0.0 : beta * c0; /* beta 0: C (maybe NaN) unread */
            ref = alpha * ref + bc;
            /* float rounding: each of K products and sums errs by ~eps relative to sum |p| */
            double tol = 4e-7 * (K + 4) * (fabs(alpha) * mag + fabs(bc)) + 1e-6;
            double e = fabs((double)C[(long)i * ldc + j] - ref);
            if (!(e <= tol)) bad++;
            if (e > worst || e != e) worst = e;
        }
        for (int j = N; j < ldc; j++) /* the gap between rows is not C */
            if (memcmp(&C[(long)i * ldc + j], &C0[(long)i * ldc + j], sizeof(float))) gap++;
    }
    CHECK_MSG(bad == 0 && gap == 0,
              "M %d N %d K %d ta %d tb %d alpha %g beta %g nan %d pad %d: %ld wrong (worst "
              "%.3g), %ld gap writes", M, N, K, ta, tb, alpha, beta, nan_c, pad, bad, worst, gap);
    free(A), free(B), free(C), free(C0);
}

static void run_all(void)
{
    lm_rng r;
    lm_rng_seed(&r, 11);
    const float betas[3] = {0.0f, 1.0f, -2.0f};
    for (int s = 0; s < NSHAPES; s++)
        for (int t = 0; t < 4; t++) {
            int ta = t & 1, tb = t >> 1;
            run_case(&SHAPES[s], ta, tb, 1.0f, betas[(s + t) % 3], 0, (s + t) % 2 ? 5 : 0, &r);
            run_case(&SHAPES[s], ta, tb, 0.5f, betas[(s + t + 1) % 3], 0, 3, &r);
            run_case(&SHAPES[s], ta, tb, -1.5f, 0.0f, 1, s % 2 ? 0 : 2, &r);
        }
    run_case(&SHAPES[4], 0, 0, 0.0f, -2.0f, 0, 1, &r); /* alpha 0: C = beta C */
    run_case(&SHAPES[4], 1, 1, 0.0f, 0.0f, 1, 0, &r);
}

static void test_blas_from_env(void)
{
    CHECK(lm_sgemm_impl() == LM_SGEMM_BLAS); /* main() set LM_SGEMM=blas before any call */
    run_all();
}

static void test_avx512(void)
{
    int prev = lm_sgemm_set_impl(LM_SGEMM_AVX512);
    CHECK(prev == LM_SGEMM_BLAS);
    if (lm_sgemm_impl() != LM_SGEMM_AVX512) {
        printf("     (no AVX-512 on this CPU: OpenBLAS path again)\n");
    }
    run_all();
    lm_sgemm_set_impl(-1);
}

/* lm_gemm_mt: the same thread count gives the same bits; with our kernel 2 threads also equal
 * 1 thread bit for bit (each element computed by one call with the same K order), for a split
 * over columns and one over rows. OpenBLAS (CPUs without AVX-512) may pick another edge
 * kernel for a narrower block, so there 1 and 2 threads need only agree to rounding. */
static void test_mt_deterministic(void)
{
    lm_sgemm_set_impl(LM_SGEMM_AVX512);
    int own = lm_sgemm_impl() == LM_SGEMM_AVX512;
    lm_ctx c1, c2;
    lm_ctx_init(&c1, 1);
    lm_ctx_init(&c2, 2);
    lm_rng r;
    lm_rng_seed(&r, 5);
    const shape sh[2] = {{40, 1000, 300}, {300, 20, 260}};
    for (int s = 0; s < 2; s++) {
        int M = sh[s].M, N = sh[s].N, K = sh[s].K;
        float *A = malloc(sizeof(float) * M * K), *B = malloc(sizeof(float) * K * N);
        float *C1 = malloc(sizeof(float) * M * N), *C2 = malloc(sizeof(float) * M * N);
        float *C3 = malloc(sizeof(float) * M * N);
        for (long i = 0; i < (long)M * K; i++) A[i] = frand(&r);
        for (long i = 0; i < (long)K * N; i++) B[i] = frand(&r);
        lm_gemm_mt(&c1, 0, 0, M, N, K, 1.0f, A, K, B, N, 0.0f, C1, N);
        lm_gemm_mt(&c2, 0, 0, M, N, K, 1.0f, A, K, B, N, 0.0f, C2, N);
        lm_gemm_mt(&c2, 0, 0, M, N, K, 1.0f, A, K, B, N, 0.0f, C3, N);
        CHECK(memcmp(C2, C3, sizeof(float) * M * N) == 0);
        if (own)
            CHECK(memcmp(C1, C2, sizeof(float) * M * N) == 0);
        else
            CHECK_ARRAY_CLOSE(C1, C2, (long)M * N, 1e-4, 1e-5);
        free(A), free(B), free(C1), free(C2), free(C3);
    }
    lm_ctx_free(&c1);
    lm_ctx_free(&c2);
    lm_sgemm_set_impl(-1);
}

int main(void)
{
    setenv("LM_SGEMM", "blas", 1);
    RUN(test_blas_from_env);
    RUN(test_avx512);
    RUN(test_mt_deterministic);
    return check_summary();
}
