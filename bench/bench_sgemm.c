/* bench_sgemm.c — GFLOP/s of the project's sgemm (lm_sgemm_st, AVX-512 kernel) next to
 * OpenBLAS cblas_sgemm on one thread, on the conv shapes (M = Cout, N = pixels of a 66x64
 * tile or half of it, K = 9 Cin) and square 512 / 1024; then lm_gemm_mt (split over threads)
 * with either implementation underneath. Repetitions alternate the two implementations
 * (this VM loses CPU to its host at times); min and median reported. Not a test.
 *
 * Usage: bench_sgemm [repeats [threads]]   (defaults 7, 2) */
#include "bench/bench_util.h"
#include "tensor/ops/gemm_internal.h"
#include <cblas.h>
#include <stdio.h>
#include <stdlib.h>

#define MAXREP 64

typedef struct bshape {
    int M, N, K, ta, tb;
} bshape;

static double time_one(int impl, int mt, lm_ctx *c, const bshape *s, const float *A,
                       const float *B, float *C)
{
    int lda = s->ta ? s->M : s->K, ldb = s->tb ? s->K : s->N;
    double t0 = bench_now();
    if (mt) {
        lm_sgemm_set_impl(impl);
        lm_gemm_mt(c, s->ta, s->tb, s->M, s->N, s->K, 1.0f, A, lda, B, ldb, 0.0f, C, s->N);
    } else if (impl == LM_SGEMM_BLAS) {
        cblas_sgemm(CblasRowMajor, s->ta ? CblasTrans : CblasNoTrans,
                    s->tb ? CblasTrans : CblasNoTrans, s->M, s->N, s->K, 1.0f, A, lda, B, ldb,
                    0.0f, C, s->N);
    } else {
        lm_sgemm_set_impl(impl);
        lm_sgemm_st(s->ta, s->tb, s->M, s->N, s->K, 1.0f, A, lda, B, ldb, 0.0f, C, s->N);
    }
    return bench_now() - t0;
}

static void run_shape(const bshape *s, int reps, int mt, lm_ctx *c, lm_rng *r)
{
    long na = (long)s->M * s->K, nb = (long)s->K * s->N, nc = (long)s->M * s->N;
    float *A = malloc(sizeof(float) * na), *B = malloc(sizeof(float) * nb);
    float *C = malloc(sizeof(float) * nc);
    lm_rng_fill_uniform(r, A, na, -1.0f, 1.0f);
    lm_rng_fill_uniform(r, B, nb, -1.0f, 1.0f);
    /* repeat small products so one timing lasts >= ~20 ms */
    double flop = 2.0 * s->M * s->N * s->K;
    int inner = (int)(2e9 / flop) + 1;
    double tb[MAXREP], ta[MAXREP];
    time_one(LM_SGEMM_BLAS, mt, c, s, A, B, C), time_one(LM_SGEMM_AVX512, mt, c, s, A, B, C);
    for (int i = 0; i < reps; i++) {
        double t0 = 0, t1 = 0;
        for (int j = 0; j < inner; j++) t0 += time_one(LM_SGEMM_BLAS, mt, c, s, A, B, C);
        for (int j = 0; j < inner; j++) t1 += time_one(LM_SGEMM_AVX512, mt, c, s, A, B, C);
        tb[i] = t0 / inner, ta[i] = t1 / inner;
    }
    double gb = flop * 1e-9 / bench_min(tb, reps), gbm = flop * 1e-9 / bench_median(tb, reps);
    double ga = flop * 1e-9 / bench_min(ta, reps), gam = flop * 1e-9 / bench_median(ta, reps);
    printf("%-6s %5d %5d %5d  %s%s | %7.1f %7.1f | %7.1f %7.1f | %5.2f\n", mt ? "mt" : "st",
           s->M, s->N, s->K, s->ta ? "T" : "N", s->tb ? "T" : "N", gb, gbm, ga, gam, ga / gb);
    fflush(stdout);
    free(A), free(B), free(C);
    lm_sgemm_set_impl(-1);
}

int main(int argc, char **argv)
{
    int reps = argc > 1 ? atoi(argv[1]) : 7, nt = argc > 2 ? atoi(argv[2]) : 2;
    if (reps < 1) reps = 1;
    if (reps > MAXREP) reps = MAXREP;
    if (nt < 1) nt = 1;
    lm_ctx c1, cn;
    lm_ctx_init(&c1, 1); /* also sets OpenBLAS to one thread */
    lm_ctx_init(&cn, nt);
    lm_rng r;
    lm_rng_seed(&r, 3);
    printf("sgemm GFLOP/s, OpenBLAS core %s; st = one thread, mt = lm_gemm_mt on %d threads; "
           "%d repeats; avx512 kernel %s\n", openblas_get_corename(), nt, reps,
           lm_sgemm_set_impl(LM_SGEMM_AVX512) >= 0 && lm_sgemm_impl() == LM_SGEMM_AVX512
               ? "available" : "NOT available");
    lm_sgemm_set_impl(-1);
    printf("         M     N     K  op |  blas min    med |  ours min    med | ours/blas (min)\n");
    static const bshape st[] = {
        {16, 4224, 144, 0, 0},  {32, 4224, 288, 0, 0},  {64, 4224, 576, 0, 0},
        {128, 4224, 1152, 0, 0}, {64, 2112, 576, 0, 0}, {128, 2112, 1152, 0, 0},
        {64, 576, 2112, 0, 1},  {576, 2112, 64, 1, 0},  {128, 256, 1152, 0, 0},
        {512, 512, 512, 0, 0},  {1024, 1024, 1024, 0, 0}, {512, 512, 512, 1, 1},
        /* 16-channel conv backward: weight grad (dy col^T), input grad (W^T dy) */
        {16, 144, 688, 0, 1},   {144, 688, 16, 1, 0},
    };
    for (int i = 0; i < (int)(sizeof st / sizeof st[0]); i++) run_shape(&st[i], reps, 0, &c1, &r);
    static const bshape mt[] = {
        {128, 4224, 1152, 0, 0}, {64, 4224, 576, 0, 0}, {1024, 1024, 1024, 0, 0},
    };
    for (int i = 0; i < (int)(sizeof mt / sizeof mt[0]); i++) run_shape(&mt[i], reps, 1, &cn, &r);
    lm_ctx_free(&c1);
    lm_ctx_free(&cn);
    return 0;
}
