/* bench_conv.c — speed of lm_conv2d (3x3, pad 1, Cin = Cout) on 66x64 images, forward and
 * forward+backward (gradients for x, w and bias), next to the sgemm rate of this machine
 * measured in the same run.
 *
 * Usage: bench_conv [threads [repeats [channels]]]
 *   threads default LM_BENCH_THREADS or 2; repeats default 7; channels: only that Cin = Cout.
 *
 * The reference GEMM is M=128, N=4224, K=1152 (the 128-channel conv's per-image shape), split
 * by column blocks over the same OpenMP threads, each thread calling single-threaded OpenBLAS
 * sgemm on its block: the same way the conv splits its work. Conv and sgemm repetitions are
 * interleaved (this VM can lose CPU to its host for a while) and both are reported as min and
 * median. FLOPs = 2 * MACs; forward+backward = 3x the forward MACs (input, weight gradients).
 * Times are through the public API: forward in no-grad mode; forward+backward = forward in
 * grad mode + lm_backward (includes zero-filling the gradients). Each shape is timed twice,
 * interleaved: the default path (Winograd F(4x4, 3x3) where it applies: "auto") and the
 * im2col + GEMM path it replaces ("tiled"); GFLOP/s count the direct convolution's MACs for
 * both, so for Winograd they are an effective rate and may exceed the sgemm rate.
 * Not a test: prints figures. */
#include "autograd/autograd.h"
#include "tensor/ops.h"
#include "tensor/ops/gemm_internal.h"
#include <cblas.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "bench/bench_util.h"

#define GM 128
#define GN 4224
#define GK 1152
#define MAXREP 64

/* C = A B, 128 x 4224 x 1152, columns split over nt threads, one sgemm each. */
static double time_sgemm(int nt, const float *A, const float *B, float *C)
{
    double t0 = bench_now();
#pragma omp parallel num_threads(nt)
    {
        int T = omp_get_num_threads(), id = omp_get_thread_num();
        int lo = (int)((long)GN * id / T) / 16 * 16;
        int hi = id == T - 1 ? GN : (int)((long)GN * (id + 1) / T) / 16 * 16;
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, GM, hi - lo, GK, 1.0f, A, GK,
                    B + lo, GN, 0.0f, C + lo, GN);
    }
    return bench_now() - t0;
}

typedef struct bench_io {
    lm_tensor x, w, b, seed; /* caller-owned (outside the arena, kept across resets) */
} bench_io;

static float *filled(long n, lm_rng *r)
{
    float *p = malloc(sizeof(float) * (size_t)n);
    if (p) lm_rng_fill_uniform(r, p, n, -1.0f, 1.0f);
    return p;
}

static double time_conv(lm_ctx *c, bench_io *io, int backward)
{
    lm_conv2d_opts o = {1, 1, 1, 1, 1, 1, 1};
    lm_ctx_reset(c);
    io->x.grad = io->w.grad = io->b.grad = NULL;
    lm_ctx_set_grad(c, backward);
    double t0 = bench_now();
    lm_tensor *y = lm_conv2d(c, &io->x, &io->w, &io->b, &o);
    if (backward && y) lm_backward(c, y, &io->seed);
    double t = bench_now() - t0;
    if (c->status) {
        fprintf(stderr, "bench_conv: %s\n", c->msg);
        exit(1);
    }
    return t;
}

static void run_config(int nt, int reps, int B, int C, const float *A, const float *Bm, float *Cm)
{
    lm_ctx c;
    lm_ctx_init(&c, nt);
    lm_rng r;
    lm_rng_seed(&r, 1);
    bench_io io;
    int H = 66, W = 64;
    float *xd = filled((long)B * C * H * W, &r), *wd = filled((long)C * C * 9, &r);
    float *bd = filled(C, &r), *sd = filled((long)B * C * H * W, &r);
    lm_tensor_wrap(&io.x, xd, 4, (int[]){B, C, H, W});
    lm_tensor_wrap(&io.w, wd, 4, (int[]){C, C, 3, 3});
    lm_tensor_wrap(&io.b, bd, 1, &C);
    lm_tensor_wrap(&io.seed, sd, 4, (int[]){B, C, H, W});
    lm_tensor_set_requires_grad(&io.x, 1);
    lm_tensor_set_requires_grad(&io.w, 1);
    lm_tensor_set_requires_grad(&io.b, 1);
    double tf[2][MAXREP], tb[2][MAXREP], tg[MAXREP];
    static const int paths[2] = {LM_CONV_PATH_AUTO, LM_CONV_PATH_NO_WINOGRAD};
    static const char *names[2] = {"auto", "tiled"};
    for (int p = 0; p < 2; p++) { /* warm-up: arena blocks, page faults */
        int old = lm_conv2d_set_path(&c, paths[p]);
        time_conv(&c, &io, 1);
        lm_conv2d_set_path(&c, old);
    }
    time_sgemm(nt, A, Bm, Cm);
    for (int i = 0; i < reps; i++) {
        for (int p = 0; p < 2; p++) {
            int old = lm_conv2d_set_path(&c, paths[p]);
            tf[p][i] = time_conv(&c, &io, 0);
            lm_conv2d_set_path(&c, old);
        }
        tg[i] = time_sgemm(nt, A, Bm, Cm);
        for (int p = 0; p < 2; p++) {
            int old = lm_conv2d_set_path(&c, paths[p]);
            tb[p][i] = time_conv(&c, &io, 1);
            lm_conv2d_set_path(&c, old);
        }
    }
    double gf = 2.0 * B * C * H * W * C * 9 * 1e-9, gg = 2.0 * GM * GN * GK * 1e-9;
    double gmin = bench_min(tg, reps), gmed = bench_median(tg, reps);
    for (int p = 0; p < 2; p++) {
        double fmin = bench_min(tf[p], reps), fmed = bench_median(tf[p], reps);
        double bmin = bench_min(tb[p], reps), bmed = bench_median(tb[p], reps);
        printf("%3d %4d %-5s | %8.2f %8.2f %7.1f %7.1f | %8.2f %8.2f %7.1f %7.1f | %7.1f %7.1f"
               " | %5.2f %5.2f | %5.2f %5.2f\n",
               B, C, names[p], fmin * 1e3, fmed * 1e3, gf / fmin, gf / fmed, bmin * 1e3,
               bmed * 1e3, 3 * gf / bmin, 3 * gf / bmed, gg / gmin, gg / gmed,
               (gf / fmin) / (gg / gmin), (gf / fmed) / (gg / gmed), (3 * gf / bmin) / (gg / gmin),
               (3 * gf / bmed) / (gg / gmed));
    }
    fflush(stdout);
    free(xd), free(wd), free(bd), free(sd);
    lm_ctx_free(&c);
}

int main(int argc, char **argv)
{
    const char *env = getenv("LM_BENCH_THREADS");
    int nt = argc > 1 ? atoi(argv[1]) : env ? atoi(env) : 2;
    int reps = argc > 2 ? atoi(argv[2]) : 7;
    int only = argc > 3 ? atoi(argv[3]) : 0;
    if (nt < 1) nt = 1;
    if (reps < 1) reps = 1;
    if (reps > MAXREP) reps = MAXREP;
    lm_rng r;
    lm_rng_seed(&r, 2);
    float *A = filled((long)GM * GK, &r), *Bm = filled((long)GK * GN, &r);
    float *Cm = malloc(sizeof(float) * GM * GN);
    lm_ctx probe; /* sets OpenBLAS to one thread, as every ctx does */
    lm_ctx_init(&probe, nt);
    lm_ctx_free(&probe);
    printf("conv2d 3x3 pad 1, 66x64 images, Cin = Cout; %d threads, %d repeats; OpenBLAS core %s\n",
           nt, reps, openblas_get_corename());
    printf("reference: sgemm %dx%dx%d split by columns over %d threads (single-threaded "
           "OpenBLAS per thread)\n", GM, GN, GK, nt);
    printf("  B    C path  |   fwd ms (min/med)  GFLOP/s (min/med) | fwd+bwd ms (min/med) GFLOP/s "
           "(min/med) | sgemm GFLOP/s | fwd/sgemm | f+b/sgemm\n");
    int batches[2] = {4, 14}, chans[4] = {16, 32, 64, 128};
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 4; j++)
            if (!only || chans[j] == only) run_config(nt, reps, batches[i], chans[j], A, Bm, Cm);
    free(A), free(Bm), free(Cm);
    return 0;
}
