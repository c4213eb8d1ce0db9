/* test_align_infer.c — temporal alignment as `lumosaic infer` applies it (system.md §9): a
 * smooth 41-bin scene translating a few pixels per frame is simulated with the video model
 * (data/video.h, noise 0) on the default system; each frame is unshuffled into LED sub-images,
 * aligned with its neighbours (lm_align_frame) and re-mosaicked. The aligned coded frame must be
 * much closer (RMS over the interior) than the raw one to the coded frame of the still scene at
 * the frame's lime instant — for the middle frame (both neighbours) and for the edge frames
 * (one neighbour). The same holds after reconstruction with a randomly initialised linear model
 * (lm_tile_infer). RMS values are printed. Also: alignment is the identity on a still scene,
 * and too-small sub-images fail with a message naming the plane. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "tests/check.h"
#include "data/video.h"
#include "data/align.h"
#include "infer/tile.h"
#include "models/model.h"
#include "data/mosaic.h"

#define H 96
#define W 128
#define NF 3
#define MARGIN 12 /* border pixels left out of the RMS (translation brings in clamped edges) */

static lm_system g_sys;
static int g_ok;
static lm_err g_err;

/* A smooth scene: 3 low-frequency spatial textures (periods >= 40 px, i.e. >= 10 sub-image
 * pixels: well sampled by every LED's sub-image) mixed by smooth spectra (41 bins). */
static void scene(lm_cube *c)
{
    CHECK(lm_cube_alloc(c, 41, H, W, 380, 10) == LM_OK);
    for (int b = 0; b < 41; b++) {
        double l = b / 40.0;
        double m0 = 0.5 + 0.5 * cos(3.0 * l), m1 = exp(-20 * (l - 0.5) * (l - 0.5)), m2 = l * l;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                double t0 = sin(0.105 * x + 0.065 * y) * cos(0.085 * y - 0.025 * x);
                double t1 = sin(0.055 * x - 0.115 * y + 1.0);
                double t2 = cos(0.155 * x + 0.035 * y) * sin(0.095 * y + 0.4);
                c->data[((size_t)b * H + y) * W + x] =
                    (float)(0.5 + 0.3 * (m0 * t0 + m1 * t1 + m2 * t2));
            }
    }
}

static double rms_interior(const float *a, const float *b, int bands)
{
    double s = 0;
    long n = 0;
    for (int k = 0; k < bands; k++)
        for (int y = MARGIN; y < H - MARGIN; y++)
            for (int x = MARGIN; x < W - MARGIN; x++) {
                size_t i = ((size_t)k * H + y) * W + x;
                double d = (double)a[i] - b[i];
                s += d * d;
                n++;
            }
    return sqrt(s / n);
}

typedef struct seq {
    float raw[NF][H * W];   /* coded frames (bucket 1) */
    float gtm[NF][H * W];   /* coded frame of the still scene at each frame's lime instant */
    float planes[NF][H * W];
} seq;

/* Simulate NF frames of the scene moving by (vx, vy) px/s, their ground-truth mosaics and
 * sub-images. */
static void simulate(seq *s, double vx, double vy)
{
    lm_cube c;
    scene(&c);
    lm_video_opts vo = {0};
    vo.motion.vx = vx;
    vo.motion.vy = vy;
    vo.nthreads = 1;
    for (int i = 0; i < NF; i++) {
        lm_cube gt;
        lm_err e;
        lm_err_clear(&e);
        CHECK_MSG(lm_video_frame(&g_sys, &c, &vo, i, NULL, s->raw[i], NULL, &gt, &e) == LM_OK,
                  "%s", e.msg);
        CHECK_MSG(lm_forward_clean(&g_sys, &gt, 0, 0, s->gtm[i], NULL, 1, &e) == LM_OK, "%s",
                  e.msg);
        CHECK(lm_align_unshuffle(s->raw[i], H, W, g_sys.tile_rows, g_sys.tile_cols,
                                 s->planes[i], &e) == LM_OK);
        lm_cube_free(&gt);
    }
    lm_cube_free(&c);
}

/* Align frame i with its available neighbours and re-mosaic into out. */
static lm_status align(const seq *s, int i, float *out, lm_err *e)
{
    int ty = g_sys.tile_rows, tx = g_sys.tile_cols, ref;
    float t[64], aligned[H * W];
    CHECK(lm_align_phase_times(&g_sys, t, &ref, e) == LM_OK);
    lm_flow_opts fo;
    lm_flow_default_opts(&fo, LM_FLOW_MEDIUM);
    lm_status st = lm_align_frame(i > 0 ? s->planes[i - 1] : NULL, s->planes[i],
                                  i + 1 < NF ? s->planes[i + 1] : NULL, ty * tx, H / ty, W / tx,
                                  t, ref, &fo, NULL, aligned, e);
    if (st) return st;
    return lm_align_remosaic(aligned, H / ty, W / tx, ty, tx, out, e);
}

static void test_default_system_loads(void) { CHECK_MSG(g_ok, "default system: %s", g_err.msg); }

/* 150 px/s, -60 px/s: about 5 px and 2 px per frame (30 fps). */
static void test_aligned_mosaic_closer(void)
{
    if (!g_ok) return;
    seq *s = malloc(sizeof *s);
    simulate(s, 150.0, -60.0);
    for (int i = 0; i < NF; i++) {
        float al[H * W];
        lm_err e;
        lm_err_clear(&e);
        CHECK_MSG(align(s, i, al, &e) == LM_OK, "%s", e.msg);
        double r0 = rms_interior(s->raw[i], s->gtm[i], 1), r1 = rms_interior(al, s->gtm[i], 1);
        printf("  frame %d: mosaic RMS vs lime-time still scene: unaligned %.5f, aligned %.5f "
               "(x%.1f)\n", i, r0, r1, r0 / r1);
        CHECK_MSG(r0 > 5e-3, "the motion is visible: %g", r0);
        CHECK_MSG(r1 * 3.0 < r0, "frame %d: aligned %g vs unaligned %g", i, r1, r0);
    }
    free(s);
}

/* The middle frame through a randomly initialised linear model: the cube from the aligned frame
 * is closer to the cube from the lime-time mosaic than the cube from the raw frame. */
static void test_linear_reconstruction_closer(void)
{
    if (!g_ok) return;
    seq *s = malloc(sizeof *s);
    simulate(s, 150.0, -60.0);
    lm_err e;
    lm_err_clear(&e);
    lm_mosaic mo;
    CHECK_MSG(lm_mosaic_from_system(&g_sys, &mo, &e) == LM_OK, "%s", e.msg);
    lm_model *m = lm_model_create("linear", &mo, 7, &e);
    CHECK_MSG(m, "%s", e.msg);
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 1) == 0);
    static float al[H * W];
    CHECK_MSG(align(s, 1, al, &e) == LM_OK, "%s", e.msg);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_cube cg = {0}, cu = {0}, ca = {0};
    CHECK_MSG(m && lm_tile_infer(&c, m, s->gtm[1], H, W, &to, &cg, &e) == LM_OK, "%s", e.msg);
    CHECK_MSG(m && lm_tile_infer(&c, m, s->raw[1], H, W, &to, &cu, &e) == LM_OK, "%s", e.msg);
    CHECK_MSG(m && lm_tile_infer(&c, m, al, H, W, &to, &ca, &e) == LM_OK, "%s", e.msg);
    if (cg.data && cu.data && ca.data) {
        CHECK(cg.bands == 31 && cg.height == H && cg.width == W);
        double r0 = rms_interior(cu.data, cg.data, 31), r1 = rms_interior(ca.data, cg.data, 31);
        printf("  linear model, frame 1: cube RMS vs lime-time reconstruction: unaligned %.5f, "
               "aligned %.5f (x%.1f)\n", r0, r1, r0 / r1);
        CHECK_MSG(r1 * 3.0 < r0, "aligned %g vs unaligned %g", r1, r0);
    }
    lm_cube_free(&cg);
    lm_cube_free(&cu);
    lm_cube_free(&ca);
    lm_ctx_free(&c);
    lm_model_free(m);
    free(s);
}

/* A still scene: every frame equals its lime-time mosaic, and alignment keeps it (up to the
 * flow's residual on identical images). */
static void test_still_scene_unchanged(void)
{
    if (!g_ok) return;
    seq *s = malloc(sizeof *s);
    simulate(s, 0.0, 0.0);
    CHECK(memcmp(s->raw[1], s->gtm[1], sizeof s->raw[1]) == 0);
    float al[H * W];
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(align(s, 1, al, &e) == LM_OK, "%s", e.msg);
    double r = rms_interior(al, s->gtm[1], 1);
    printf("  still scene: aligned RMS %.2e\n", r);
    CHECK_MSG(r < 1e-3, "still scene moved by alignment: %g", r);
    free(s);
}

/* Sub-images below the flow's minimum size: an error naming the plane, not a crash. */
static void test_too_small_fails(void)
{
    if (!g_ok) return;
    const int np = 12, h = 8, w = 8;
    float *a = calloc((size_t)np * h * w, sizeof(float)), *b = calloc((size_t)np * h * w, 4),
          *o = calloc((size_t)np * h * w, 4), t[12];
    int ref;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_align_phase_times(&g_sys, t, &ref, &e) == LM_OK);
    for (size_t i = 0; i < (size_t)np * h * w; i++) a[i] = b[i] = (float)(i % 7) / 7.0f;
    CHECK(lm_align_frame(a, b, NULL, np, h, w, t, ref, NULL, NULL, o, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "align: plane"), "%s", e.msg);
    free(a);
    free(b);
    free(o);
}

int main(void)
{
    lm_err_clear(&g_err);
    g_ok = lm_system_default(&g_sys, &g_err) == LM_OK;
    RUN(test_default_system_loads);
    RUN(test_aligned_mosaic_closer);
    RUN(test_linear_reconstruction_closer);
    RUN(test_still_scene_unchanged);
    RUN(test_too_small_fails);
    lm_system_free(&g_sys);
    return check_summary();
}
