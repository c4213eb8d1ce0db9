/* bench_opencl.c — the OpenCL backend (PoCL here) against the CPU backend: a per-kernel profile
 * of one training step and the whole training step, for model presets at batch 4 of 66x64.
 *
 * Usage: bench_opencl [repeats [preset ...]]   (default 5 repeats; han-tiny mcan)
 *   env LM_BENCH_THREADS: CPU threads (default 2).
 *
 * Training step = upload of the parameters (OpenCL only) + forward + L1 loss + backward +
 * gradients to the host parameter block + Adam on the host + zeroing the gradients, reported
 * as min and median, the backends in alternating blocks of repetitions; the time of the
 * OpenCL step spent in the parameter swaps (lm_tensors_swap_to_device / _swap_back) is
 * printed under it. Once PoCL's worker
 * threads exist in the process, the CPU backend's OpenMP threads spinning at barriers
 * (libgomp's default) fight them for the 2 cores and its steps measured 10-20x slow; so the
 * bench re-executes itself with OMP_WAIT_POLICY=passive unless that variable is set. The profile runs the same step through a wrapping backend that times
 * every kernel by its lm_kernel name (the device queue is drained after each, so profiled
 * steps are slower than plain ones); "not in kernels" is the rest of the profiled step
 * (transfers, parameter upload, Adam, host work). Not a test: prints figures. */
#include "autograd/autograd.h"
#include "kernels-opencl/cl_backend.h"
#include "models/model.h"
#include "train/adam.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include "bench/bench_util.h"

#define MAXREP 32
#define MAXK 160

/* ---- per-kernel profile: a backend wrapping the CPU or the OpenCL backend -------------- */
typedef struct kstat {
    const char *name;
    long calls;
    double t[2][MAXREP]; /* [backend][rep]: seconds in this kernel during one step */
} kstat;

static kstat kst[MAXK];
static int nkst, prof_side, prof_rep;
static lm_backend *prof_inner[2];
static lm_backend prof_wrap[2];

static kstat *kstat_of(const char *name)
{
    for (int i = 0; i < nkst; i++)
        if (!strcmp(kst[i].name, name)) return &kst[i];
    if (nkst == MAXK) return NULL;
    kst[nkst].name = name;
    return &kst[nkst++];
}

static int prof_run(lm_backend *b, lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt,
                    const void *params)
{
    lm_backend *in = prof_inner[b == &prof_wrap[1]];
    double t0 = bench_now();
    int r = in->run ? in->run(in, c, k, t, nt, params) : k->cpu(c, t, nt, params);
    lm_cl_backend_finish(in);
    kstat *s = kstat_of(k->name);
    if (s) {
        s->t[prof_side][prof_rep] += bench_now() - t0;
        if (prof_side == 1 && prof_rep == 0) s->calls++;
    }
    return r;
}

/* ---- one training step ------------------------------------------------------------------ */
typedef struct bench_model {
    lm_model *m;
    lm_adam opt;
    lm_tensor **ps, *saved;
    float *x, *target;
    int shape[4];
} bench_model;

static double swap_t; /* seconds of the last step in the parameter swaps (both ways) */

static double train_step(lm_ctx *c, bench_model *bm)
{
    lm_model *m = bm->m;
    int np = m->params.n, *s = bm->shape;
    double t0 = bench_now();
    lm_ctx_reset(c);
    double ts = bench_now();
    lm_tensors_swap_to_device(c, bm->ps, np, bm->saved);
    swap_t = bench_now() - ts;
    lm_tensor *x = lm_tensor_from(c, 4, s, bm->x);
    lm_tensor *tg = lm_tensor_from(c, 4, (int[]){s[0], 33, s[2], s[3]}, bm->target);
    lm_tensor *loss = lm_l1_loss(c, lm_model_forward(c, m, x), tg);
    lm_backward(c, loss, NULL);
    float l = 0;
    if (loss) lm_tensor_read(c, loss, &l);
    double t1 = bench_now();
    lm_tensors_swap_back(c, bm->ps, np, bm->saved);
    swap_t += bench_now() - t1;
    lm_adam_step(&bm->opt, &m->params, lm_nthreads(c));
    lm_params_zero_grad(&m->params);
    double t = bench_now() - t0;
    if (c->status) {
        fprintf(stderr, "bench_opencl: %s: %s\n", m->preset, c->msg);
        exit(1);
    }
    return t;
}

static int bench_model_init(bench_model *bm, const char *preset, int B, int H, int W)
{
    lm_err e = {0};
    lm_mosaic mo;
    lm_mosaic_default(&mo);
    bm->m = lm_model_create(preset, &mo, 1, &e);
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    if (!bm->m || lm_adam_init(&bm->opt, &bm->m->params, &cfg, &e)) {
        fprintf(stderr, "bench_opencl: %s\n", e.msg);
        return -1;
    }
    int np = bm->m->params.n;
    bm->ps = malloc((size_t)np * sizeof *bm->ps);
    bm->saved = malloc((size_t)np * sizeof *bm->saved);
    for (int i = 0; i < np; i++) bm->ps[i] = &bm->m->params.items[i]->t;
    int sh[4] = {B, 1, H, W};
    memcpy(bm->shape, sh, sizeof sh);
    long n = (long)B * H * W;
    bm->x = malloc((size_t)n * sizeof(float));
    bm->target = malloc((size_t)n * 33 * sizeof(float));
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_rng_fill_uniform(&r, bm->x, n, 0.0f, 1.0f);
    lm_rng_fill_uniform(&r, bm->target, n * 33, 0.0f, 1.0f);
    return 0;
}

static void bench_model_free(bench_model *bm)
{
    lm_adam_free(&bm->opt);
    lm_model_free(bm->m);
    free(bm->ps), free(bm->saved), free(bm->x), free(bm->target);
}

/* ---- reports ---------------------------------------------------------------------------- */
static int cmp_kstat(const void *a, const void *b)
{
    const kstat *x = a, *y = b;
    double u = x->t[1][0] + x->t[0][0], v = y->t[1][0] + y->t[0][0]; /* filled with medians */
    return u < v ? 1 : u > v ? -1 : 0;
}

static void profile(lm_ctx *ctx[2], bench_model *bm, int reps)
{
    nkst = 0;
    memset(kst, 0, sizeof kst);
    double tot[2][MAXREP];
    for (int s = 0; s < 2; s++) lm_ctx_set_backend(ctx[s], &prof_wrap[s]);
    for (prof_side = 0; prof_side < 2; prof_side++)
        for (prof_rep = 0; prof_rep < reps; prof_rep++)
            tot[prof_side][prof_rep] = train_step(ctx[prof_side], bm);
    for (int s = 0; s < 2; s++) lm_ctx_set_backend(ctx[s], prof_inner[s]);
    double ksum[2] = {0, 0};
    for (int i = 0; i < nkst; i++)
        for (int s = 0; s < 2; s++) {
            kst[i].t[s][0] = bench_median(kst[i].t[s], reps);
            ksum[s] += kst[i].t[s][0];
        }
    qsort(kst, (size_t)nkst, sizeof *kst, cmp_kstat);
    printf("\nper-kernel profile of one training step, %s, batch %d of %dx%d (median of %d; "
           "ms per step)\n", bm->m->preset, bm->shape[0], bm->shape[2], bm->shape[3], reps);
    printf("  %-24s %6s %10s %10s %8s\n", "kernel", "calls", "cpu ms", "opencl ms", "cl/cpu");
    for (int i = 0; i < nkst; i++) {
        if (kst[i].t[0][0] + kst[i].t[1][0] < 0.002 * (ksum[0] + ksum[1]) && i >= 12) continue;
        printf("  %-24s %6ld %10.2f %10.2f %8.2f\n", kst[i].name, kst[i].calls,
               kst[i].t[0][0] * 1e3, kst[i].t[1][0] * 1e3, kst[i].t[1][0] / kst[i].t[0][0]);
    }
    double m0 = bench_median(tot[0], reps), m1 = bench_median(tot[1], reps);
    printf("  %-24s %6s %10.2f %10.2f\n", "(not in kernels)", "", (m0 - ksum[0]) * 1e3,
           (m1 - ksum[1]) * 1e3);
    printf("  %-24s %6s %10.2f %10.2f %8.2f\n", "profiled step", "", m0 * 1e3, m1 * 1e3, m1 / m0);
}

static void step_times(lm_ctx *ctx[2], bench_model *bm, int reps)
{
    double t[2][MAXREP], sw[MAXREP];
    for (int half = 0; half < 2; half++) /* blocks: cpu, opencl, cpu, opencl */
        for (int s = 0; s < 2; s++) {
            train_step(ctx[s], bm); /* warm-up */
            for (int r = half * reps / 2; r < (half + 1) * reps / 2 + (half ? reps % 2 : 0); r++) {
                t[s][r] = train_step(ctx[s], bm);
                if (s) sw[r] = swap_t;
            }
        }
    double c0 = bench_min(t[0], reps), c1 = bench_min(t[1], reps);
    double d0 = bench_median(t[0], reps), d1 = bench_median(t[1], reps);
    printf("training step %-10s B=%d %dx%d | cpu ms %8.1f %8.1f | opencl ms %8.1f %8.1f | "
           "opencl/cpu %5.2f %5.2f (target <= 2)\n", bm->m->preset, bm->shape[0], bm->shape[2],
           bm->shape[3], c0 * 1e3, d0 * 1e3, c1 * 1e3, d1 * 1e3, c1 / c0, d1 / d0);
    printf("  of the opencl step: parameter swap (upload + gradients back, train.c's per-step "
           "swap) min %.1f median %.1f ms\n", bench_min(sw, reps) * 1e3,
           bench_median(sw, reps) * 1e3);
    fflush(stdout);
}

int main(int argc, char **argv)
{
    if (!getenv("OMP_WAIT_POLICY")) { /* read by libgomp at load time: re-execute */
        setenv("OMP_WAIT_POLICY", "passive", 1);
        execv("/proc/self/exe", argv);
        perror("bench_opencl: re-exec with OMP_WAIT_POLICY=passive");
    }
    const char *env = getenv("LM_BENCH_THREADS");
    int nt = env && atoi(env) > 0 ? atoi(env) : 2;
    int reps = argc > 1 ? atoi(argv[1]) : 5;
    if (reps < 1) reps = 1;
    if (reps > MAXREP) reps = MAXREP;
    const char *def[] = {"han-tiny", "mcan"};
    const char *const *presets = argc > 2 ? (const char *const *)argv + 2 : def;
    int npre = argc > 2 ? argc - 2 : 2;
    lm_err e = {0};
    lm_backend *cl = lm_cl_backend_create(&e);
    if (!cl) {
        fprintf(stderr, "bench_opencl: %s\n", e.msg);
        return 1;
    }
    prof_inner[0] = lm_backend_cpu(), prof_inner[1] = cl;
    for (int s = 0; s < 2; s++) {
        prof_wrap[s] = *prof_inner[s];
        prof_wrap[s].run = prof_run;
    }
    lm_ctx cc, gc;
    lm_ctx_init(&cc, nt);
    lm_ctx_init(&gc, nt);
    lm_ctx_set_backend(&gc, cl);
    lm_ctx *ctx[2] = {&cc, &gc};
    printf("OpenCL device: %s; CPU backend: %d threads, OMP_WAIT_POLICY=%s; %d repeats\n",
           lm_cl_backend_device_name(cl), nt, getenv("OMP_WAIT_POLICY"), reps);
    for (int i = 0; i < npre; i++) {
        bench_model bm;
        if (bench_model_init(&bm, presets[i], 4, 66, 64)) return 1;
        step_times(ctx, &bm, reps);
        profile(ctx, &bm, reps);
        bench_model_free(&bm);
    }
    lm_ctx_free(&cc);
    lm_ctx_free(&gc);
    lm_cl_backend_free(cl);
    return 0;
}
