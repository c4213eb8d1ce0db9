/* bench_rt.c — frames per second of whole-frame strip inference (infer/whole.h) on a 640x480
 * coded frame, demosaic included, for the linear baseline and the real-time presets.
 *
 * Usage: bench_rt [threads [repeats [strip_rows [height width]]]]
 *   threads default LM_BENCH_THREADS or 2; repeats default 15; strip_rows default
 *   LM_WHOLE_STRIP_ROWS; frame default 480 x 640.
 *
 * Two timings per model: "forward" = lm_whole_forward into a reused 31-band buffer (a video
 * loop reuses its output), "infer" = lm_whole_infer (allocates and frees the cube each call).
 * Repeats are interleaved over models and the two calls (A, B, A, B, ...) since this VM loses
 * CPU to its host at times; min and median are printed, fps from both. Then lmmse's two
 * forward paths on the whole frame at once, interleaved: the direct filters (no gradients,
 * what inference runs) and the tile-unit conv (what gradients flow through). Not a test. */
#include "infer/whole.h"
#include <stdio.h>
#include <stdlib.h>
#include "bench/bench_util.h"

#define MAXREP 64
static const char *models[] = {"linear", "rt-8", "rt-16", "lmmse"};
#define NM (int)(sizeof models / sizeof models[0])

int main(int argc, char **argv)
{
    const char *env = getenv("LM_BENCH_THREADS");
    int nt = argc > 1 ? atoi(argv[1]) : env ? atoi(env) : 2;
    int reps = argc > 2 ? atoi(argv[2]) : 15;
    lm_whole_opts o;
    lm_whole_default_opts(&o);
    if (argc > 3) o.strip_rows = atoi(argv[3]);
    int H = argc > 5 ? atoi(argv[4]) : 480, W = argc > 5 ? atoi(argv[5]) : 640;
    if (reps > MAXREP) reps = MAXREP;
    lm_ctx c;
    lm_ctx_init(&c, nt);
    lm_rng r;
    lm_rng_seed(&r, 7);
    float *frame = malloc(sizeof(float) * (size_t)H * W);
    float *out = malloc(sizeof(float) * 31 * (size_t)H * W);
    lm_model *m[NM];
    lm_err e = {0};
    for (int i = 0; i < NM; i++)
        if (!(m[i] = lm_model_create(models[i], NULL, 1, &e)))
            return fprintf(stderr, "%s\n", e.msg), 1;
    lm_rng_fill_uniform(&r, frame, (long)H * W, 0.0f, 1.0f);
    double tf[NM][MAXREP], ti[NM][MAXREP];
    for (int k = -1; k < reps; k++) /* k = -1: warm-up */
        for (int i = 0; i < NM; i++) {
            double t0 = bench_now();
            if (lm_whole_forward(&c, m[i], frame, H, W, &o, 1, 31, out, &e))
                return fprintf(stderr, "%s\n", e.msg), 1;
            double t1 = bench_now();
            lm_cube cube;
            if (lm_whole_infer(&c, m[i], frame, H, W, &cube, &e))
                return fprintf(stderr, "%s\n", e.msg), 1;
            double t2 = bench_now();
            lm_cube_free(&cube);
            if (k >= 0) tf[i][k] = t1 - t0, ti[i][k] = t2 - t1;
        }
    printf("whole-frame inference %dx%d, %d threads, strips of %d rows, %d repeats\n", W, H, nt,
           o.strip_rows, reps);
    printf("%-8s %7s %10s %10s %8s %8s | %10s %10s %8s\n", "model", "params", "fwd min ms",
           "fwd med ms", "fps min", "fps med", "inf min ms", "inf med ms", "fps med");
    for (int i = 0; i < NM; i++) {
        double a = bench_min(tf[i], reps), b = bench_median(tf[i], reps);
        double d = bench_min(ti[i], reps), f = bench_median(ti[i], reps);
        printf("%-8s %7ld %10.2f %10.2f %8.1f %8.1f | %10.2f %10.2f %8.1f\n", models[i],
               lm_params_count(&m[i]->params, 0), 1e3 * a, 1e3 * b, 1 / a, 1 / b, 1e3 * d, 1e3 * f,
               1 / f);
    }
    /* lmmse: direct path (grad off) against the tile-unit conv (grad on, params trainable) */
    lm_model *lm = m[NM - 1];
    lm->noise_sigma = 0.02f; /* between two levels: the filters blend */
    double td[MAXREP], tt[MAXREP];
    for (int k = -1; k < reps; k++)
        for (int g = 0; g < 2; g++) {
            lm_ctx_reset(&c);
            lm_ctx_set_grad(&c, g);
            lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, H, W}, frame);
            double t0 = bench_now();
            lm_tensor *y = lm_model_forward(&c, lm, x);
            double t1 = bench_now();
            if (!y) return fprintf(stderr, "%s\n", lm_ctx_message(&c)), 1;
            if (k >= 0) (g ? tt : td)[k] = t1 - t0;
        }
    lm_ctx_reset(&c);
    lm_ctx_set_grad(&c, 1);
    printf("lmmse whole frame at once: direct %.2f / %.2f ms (min / med), tile-unit conv %.2f / "
           "%.2f ms, ratio %.2f / %.2f\n", 1e3 * bench_min(td, reps), 1e3 * bench_median(td, reps),
           1e3 * bench_min(tt, reps), 1e3 * bench_median(tt, reps),
           bench_min(tt, reps) / bench_min(td, reps), bench_median(tt, reps) / bench_median(td, reps));
    for (int i = 0; i < NM; i++) lm_model_free(m[i]);
    free(frame);
    free(out);
    lm_ctx_free(&c);
    return 0;
}
