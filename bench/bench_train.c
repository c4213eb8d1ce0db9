/* bench_train.c — training-step time per model preset: forward, L1 loss, backward and the Adam
 * update at batch 4 of 66 x 64 (the paper's tile), min and median over repetitions, and
 * samples per second; the paper-size HAN forward only (no-grad). Inputs are random (the step
 * time does not depend on the values); the network front comes from the bundled system.
 *
 * Usage: bench_train [threads [repeats [preset ...]]]
 *   threads default LM_BENCH_THREADS or 2; repeats default 5; presets default linear han-tiny
 *   han-small mcan srnet, then han-paper (forward, 1 repetition). LM_BENCH_PRECISION=bf16: the
 *   3x3 convolutions' Winograd products with bf16 operands (tensor.h, lm_ctx.precision).
 * Not a test: prints figures. */
#include "autograd/autograd.h"
#include "models/model.h"
#include "train/adam.h"
#include "data/mosaic.h"
#include "data/system.h"
#include "tensor/isa.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "bench/bench_util.h"

#define B 4
#define H 66
#define W 64
#define MAXREP 64

typedef struct times { double fwd, bwd, adam, total; } times;

/* One step; returns 0 or prints the error. */
static int step(lm_ctx *c, lm_model *m, lm_adam *o, const float *raw, const float *tgt, int train,
                times *t)
{
    double t0 = bench_now();
    lm_ctx_reset(c);
    lm_ctx_set_grad(c, train);
    lm_tensor *x = lm_tensor_from(c, 4, (int[]){B, 1, H, W}, raw);
    lm_tensor *y = lm_tensor_from(c, 4, (int[]){B, 33, H, W}, tgt);
    lm_tensor *loss = lm_l1_loss(c, lm_model_forward(c, m, x), y);
    double t1 = bench_now();
    if (train) {
        lm_params_zero_grad(&m->params);
        lm_backward(c, loss, NULL);
    }
    double t2 = bench_now();
    if (train) lm_adam_step(o, &m->params, lm_nthreads(c));
    double t3 = bench_now();
    if (lm_ctx_status(c)) {
        fprintf(stderr, "%s: %s\n", m->preset, lm_ctx_message(c));
        return -1;
    }
    *t = (times){t1 - t0, t2 - t1, t3 - t2, t3 - t0};
    return 0;
}

static void bench(const char *preset, const lm_mosaic *mo, int threads, int reps, int train)
{
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, mo, 1, &e);
    if (!m) {
        fprintf(stderr, "%s\n", e.msg);
        return;
    }
    m->noise_sigma = 0.05f; /* "-nc" presets read the input's noise level */
    lm_ctx c;
    lm_ctx_init(&c, threads);
    const char *prec = getenv("LM_BENCH_PRECISION"); /* bf16: the bf16 Winograd products */
    if (prec && !strcmp(prec, "bf16")) c.precision = LM_PRECISION_BF16;
    lm_adam o;
    lm_adam_cfg ac;
    lm_adam_default_cfg(&ac);
    lm_adam_init(&o, &m->params, &ac, &e);
    float *raw = malloc(sizeof(float) * B * H * W), *tgt = malloc(sizeof(float) * B * 33 * H * W);
    lm_rng r;
    lm_rng_seed(&r, 7);
    lm_rng_fill_uniform(&r, raw, B * H * W, 0, 1);
    lm_rng_fill_uniform(&r, tgt, B * 33 * H * W, 0, 1);
    times t, sum = {0};
    double tot[MAXREP];
    int ok = reps > 1 ? step(&c, m, &o, raw, tgt, train, &t) == 0 : 1; /* warm-up */
    for (int i = 0; ok && i < reps; i++) {
        ok = step(&c, m, &o, raw, tgt, train, &t) == 0;
        tot[i] = t.total;
        sum.fwd += t.fwd, sum.bwd += t.bwd, sum.adam += t.adam;
    }
    if (ok) {
        qsort(tot, (size_t)reps, sizeof *tot, bench_cmp_double);
        printf("%-10s %-8s %10ld %9.1f %9.1f %8.1f %8.1f %8.1f %9.2f\n", preset,
               train ? "train" : "forward", lm_params_count(&m->params, 1), 1e3 * tot[0],
               1e3 * tot[reps / 2], 1e3 * sum.fwd / reps, 1e3 * sum.bwd / reps,
               1e3 * sum.adam / reps, B / tot[0]);
        fflush(stdout);
    }
    free(raw), free(tgt);
    lm_adam_free(&o);
    lm_ctx_free(&c);
    lm_model_free(m);
}

int main(int argc, char **argv)
{
    const char *env = getenv("LM_BENCH_THREADS");
    int threads = argc > 1 ? atoi(argv[1]) : env ? atoi(env) : 2;
    int reps = argc > 2 ? atoi(argv[2]) : 5;
    if (reps < 1) reps = 1;
    if (reps > MAXREP) reps = MAXREP;
    lm_system sys;
    lm_mosaic mo;
    lm_err e = {0};
    if (lm_system_default(&sys, &e) || lm_mosaic_from_system(&sys, &mo, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    lm_system_free(&sys);
    printf("training step (forward + L1 + backward + Adam), batch %d of %dx%d, %d threads, "
           "%d repetitions (ms; fwd/bwd/adam are means)\n", B, H, W, threads, reps);
    const char *prec = getenv("LM_BENCH_PRECISION");
    printf("precision: %s\n", lm_precision_describe(prec && !strcmp(prec, "bf16")
                                                        ? LM_PRECISION_BF16 : LM_PRECISION_FP32));
    printf("%-10s %-8s %10s %9s %9s %8s %8s %8s %9s\n", "preset", "mode", "params", "min",
           "median", "fwd", "bwd", "adam", "samples/s");
    static const char *dflt[] = {"linear", "han-tiny", "han-small", "mcan", "srnet"};
    if (argc > 3)
        for (int i = 3; i < argc; i++) bench(argv[i], &mo, threads, reps, 1);
    else {
        for (int i = 0; i < 5; i++) bench(dflt[i], &mo, threads, reps, 1);
        bench("han-paper", &mo, threads, 1, 0);
    }
    return 0;
}
