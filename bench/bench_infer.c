/* bench_infer.c — seconds per 640 x 480 coded frame of `lumosaic infer` per model preset, split
 * into stages, min and median over repetitions:
 *   align     temporal alignment of the middle frame of a 3-frame sequence (unshuffle, flow +
 *             warp of the 12 LED sub-images with both neighbours, medium preset, re-mosaic);
 *             model-independent, measured once per repetition and shown on every row;
 *   demosaic  the demosaic op alone on the same windows and batches (lm_tile_fold_timed with a
 *             demosaic-only network: its "network" time); it is also part of `network`;
 *   network   the model on every window (lm_tile_fold_timed's network stage: upload, forward
 *             including its demosaic, read-back);
 *   fold      window extraction + K-weighting + accumulation + normalisation;
 *   write     clamp, spectral EXR + sRGB PNG into /tmp;
 *   total     align + network + fold + write (demosaic is inside network).
 * Inputs: a smooth synthetic 31-band scene translating at 120 px/s, simulated noise-free with
 * the bundled system (not timed); models randomly initialised (time does not depend on the
 * weights). Repetitions are interleaved over presets (A, B, A, B, ...) after one warm-up.
 *
 * Usage: bench_infer [threads [repeats [preset ...]]]
 *   threads default LM_BENCH_THREADS or 2; repeats default 3; presets default linear mcan-tiny
 *   han-tiny srnet-tiny mcan srnet han-small (han-paper only when named).
 * Not a test: prints figures. */
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "bench/bench_util.h"
#include "data/cube_io.h"
#include "data/image.h"
#include "data/spectra.h"
#include "data/srgb.h"
#include "data/video.h"
#include "data/align.h"
#include "infer/tile.h"
#include "models/model.h"
#include "data/mosaic.h"

#define H 480
#define W 640
#define NF 3
#define MAXREP 64
#define MAXP 16

enum { S_ALIGN, S_DEMOSAIC, S_NETWORK, S_FOLD, S_WRITE, S_TOTAL, NSTAGE };
static const char *const stage_names[NSTAGE] = {"align", "demosaic", "network", "fold", "write",
                                               "total"};

typedef struct bench_env {
    lm_system sys;
    lm_mosaic mo;
    lm_ctx ctx;
    lm_srgb srgb;
    float *raw[NF];   /* coded frames */
    float *aligned;   /* frame 1 aligned, re-mosaicked */
    float *planes[NF], *al_planes, *rgb, *full;
    int threads;
} bench_env;

/* A smooth 31-band scene (textures mixed by smooth spectra), mirrored to the 41-bin grid. */
static int make_scene(lm_cube *c41, lm_err *e)
{
    lm_cube c;
    if (lm_cube_alloc(&c, 31, H, W, 400, 10)) return -1;
    for (int b = 0; b < 31; b++) {
        double l = b / 30.0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                double t0 = sin(0.05 * x + 0.03 * y) * cos(0.04 * y - 0.02 * x);
                double t1 = sin(0.11 * x - 0.07 * y + 1.0);
                c.data[((size_t)b * H + y) * W + x] =
                    (float)(0.5 + 0.25 * cos(3 * l) * t0 + 0.2 * exp(-9 * (l - 0.6) * (l - 0.6)) * t1);
            }
    }
    int rc = lm_cube_mirror41(&c, c41, e) ? -1 : 0;
    lm_cube_free(&c);
    return rc;
}

static int env_init(bench_env *b, int threads, lm_err *e)
{
    memset(b, 0, sizeof *b);
    b->threads = threads;
    if (lm_system_default(&b->sys, e) || lm_mosaic_from_system(&b->sys, &b->mo, e)) return -1;
    if (lm_ctx_init(&b->ctx, threads)) return -1;
    float wl[31];
    for (int i = 0; i < 31; i++) wl[i] = 400.0f + 10.0f * i;
    if (lm_srgb_init(&b->srgb, wl, 31, e)) return -1;
    size_t n = (size_t)H * W;
    for (int i = 0; i < NF; i++) {
        b->raw[i] = malloc(sizeof(float) * n);
        b->planes[i] = malloc(sizeof(float) * n);
    }
    b->aligned = malloc(sizeof(float) * n);
    b->al_planes = malloc(sizeof(float) * n);
    b->rgb = malloc(sizeof(float) * 3 * n);
    b->full = malloc(sizeof(float) * n * 64);
    lm_cube c41;
    if (make_scene(&c41, e)) return -1;
    lm_video_opts vo;
    memset(&vo, 0, sizeof vo);
    vo.motion.vx = 120.0 * 0.8;
    vo.motion.vy = 120.0 * 0.6;
    vo.nthreads = threads;
    int rc = 0;
    for (int i = 0; i < NF && !rc; i++)
        rc = lm_video_frame(&b->sys, &c41, &vo, i, NULL, b->raw[i], NULL, NULL, e) ? -1 : 0;
    lm_cube_free(&c41);
    return rc;
}

static void env_free(bench_env *b)
{
    for (int i = 0; i < NF; i++) {
        free(b->raw[i]);
        free(b->planes[i]);
    }
    free(b->aligned);
    free(b->al_planes);
    free(b->rgb);
    free(b->full);
    lm_ctx_free(&b->ctx);
    lm_system_free(&b->sys);
}

/* Align frame 1 with frames 0 and 2 into b->aligned; returns seconds or < 0. */
static double time_align(bench_env *b, lm_err *e)
{
    int ty = b->sys.tile_rows, tx = b->sys.tile_cols, ref;
    float t[LM_SYSTEM_MAX_TILE];
    lm_flow_opts fo;
    lm_flow_default_opts(&fo, LM_FLOW_MEDIUM);
    fo.nthreads = b->threads;
    double t0 = bench_now();
    int bad = lm_align_phase_times(&b->sys, t, &ref, e) != LM_OK;
    for (int i = 0; i < NF && !bad; i++)
        bad = lm_align_unshuffle(b->raw[i], H, W, ty, tx, b->planes[i], e) != LM_OK;
    bad = bad || lm_align_frame(b->planes[0], b->planes[1], b->planes[2], ty * tx, H / ty,
                                W / tx, t, ref, &fo, NULL, b->al_planes, e) != LM_OK;
    bad = bad || lm_align_remosaic(b->al_planes, H / ty, W / tx, ty, tx, b->aligned, e) != LM_OK;
    return bad ? -1.0 : bench_now() - t0;
}

static lm_tensor *model_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    return lm_model_forward(c, (lm_model *)user, raw);
}

static lm_tensor *demosaic_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    return lm_mosaic_demosaic(c, &((lm_model *)user)->mosaic, raw);
}

/* Clamp, write the EXR and the sRGB PNG of the 31 bands in b->full (channels 1..31). */
static int write_outputs(bench_env *b, const char *preset, lm_err *e)
{
    lm_cube cube;
    if (lm_cube_alloc(&cube, 31, H, W, 400, 10)) return -1;
    size_t n = (size_t)31 * H * W;
    memcpy(cube.data, b->full + (size_t)H * W, sizeof(float) * n);
    for (size_t i = 0; i < n; i++)
        if (cube.data[i] < 0.0f) cube.data[i] = 0.0f;
    char path[256];
    snprintf(path, sizeof path, "/tmp/bench_infer_%d_%s.exr", (int)getpid(), preset);
    int rc = lm_cube_write_exr(path, &cube, e) ? -1 : 0;
    remove(path);
    snprintf(path, sizeof path, "/tmp/bench_infer_%d_%s.png", (int)getpid(), preset);
    if (!rc) rc = lm_srgb_render(&b->srgb, &cube, 1.0f, NULL, b->rgb, e) ||
                  lm_image_write_rgb8(path, W, H, b->rgb, e) ? -1 : 0;
    remove(path);
    lm_cube_free(&cube);
    return rc;
}

/* One frame through one model: the stage times into s (align given). */
static int run_frame(bench_env *b, lm_model *m, double align, double *s, lm_err *e)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_tile_timing td = {0}, tm = {0};
    if (lm_tile_fold_timed(&b->ctx, b->aligned, H, W, m->mosaic.ty, m->mosaic.tx, &to,
                           demosaic_fn, m, m->mosaic.nch, b->full, &td, e))
        return -1;
    if (lm_tile_fold_timed(&b->ctx, b->aligned, H, W, m->mosaic.ty, m->mosaic.tx, &to, model_fn,
                           m, LM_MODEL_OUT_CHANNELS, b->full, &tm, e))
        return -1;
    double t0 = bench_now();
    if (write_outputs(b, m->preset, e)) return -1;
    s[S_ALIGN] = align;
    s[S_DEMOSAIC] = td.network;
    s[S_NETWORK] = tm.network;
    s[S_FOLD] = tm.gather + tm.fold;
    s[S_WRITE] = bench_now() - t0;
    s[S_TOTAL] = align + tm.network + s[S_FOLD] + s[S_WRITE];
    return 0;
}

static void print_row(const char *preset, double (*t)[NSTAGE], int reps)
{
    printf("%-10s", preset);
    for (int k = 0; k < NSTAGE; k++) {
        double v[MAXREP];
        for (int r = 0; r < reps; r++) v[r] = t[r][k];
        printf(" %8.3f %8.3f", bench_min(v, reps), bench_median(v, reps));
    }
    printf("\n");
}

int main(int argc, char **argv)
{
    const char *envt = getenv("LM_BENCH_THREADS");
    int threads = argc > 1 ? atoi(argv[1]) : envt ? atoi(envt) : 2;
    int reps = argc > 2 ? atoi(argv[2]) : 3;
    if (threads < 1) threads = 1;
    if (reps < 1) reps = 1;
    if (reps > MAXREP) reps = MAXREP;
    static const char *dflt[] = {"linear", "mcan-tiny", "han-tiny", "srnet-tiny", "mcan",
                                 "srnet", "han-small"};
    const char *const *names = argc > 3 ? (const char *const *)argv + 3 : dflt;
    int np = argc > 3 ? argc - 3 : 7;
    if (np > MAXP) np = MAXP;
    omp_set_num_threads(threads);
    lm_err e = {0};
    bench_env b;
    lm_model *m[MAXP] = {0};
    if (env_init(&b, threads, &e)) {
        fprintf(stderr, "bench_infer: %s\n", e.msg);
        return 1;
    }
    for (int p = 0; p < np; p++)
        if (!(m[p] = lm_model_create(names[p], &b.mo, 1, &e)))
            fprintf(stderr, "bench_infer: %s\n", e.msg);
    static double t[MAXP][MAXREP][NSTAGE];
    int ok[MAXP];
    for (int p = 0; p < np; p++) ok[p] = m[p] != NULL;
    for (int r = -1; r < reps; r++) { /* r = -1: warm-up, not recorded */
        double align = time_align(&b, &e);
        if (align < 0) {
            fprintf(stderr, "bench_infer: align: %s\n", e.msg);
            return 1;
        }
        for (int p = 0; p < np; p++) {
            double s[NSTAGE];
            if (!ok[p]) continue;
            if (run_frame(&b, m[p], align, s, &e)) {
                fprintf(stderr, "bench_infer: %s: %s\n", names[p], e.msg);
                ok[p] = 0;
                continue;
            }
            if (r >= 0) memcpy(t[p][r], s, sizeof s);
        }
    }
    printf("seconds per %d x %d coded frame (66 x 64 windows, stride 30 x 32, batch 8), %d "
           "threads, %d repetitions after a warm-up: min / median\n", W, H, threads, reps);
    printf("%-10s", "preset");
    for (int k = 0; k < NSTAGE; k++) printf(" %17s", stage_names[k]);
    printf("\n");
    for (int p = 0; p < np; p++)
        if (ok[p]) print_row(names[p], t[p], reps);
    printf("demosaic is also inside network; total = align + network + fold + write\n");
    for (int p = 0; p < np; p++) lm_model_free(m[p]);
    env_free(&b);
    return 0;
}
