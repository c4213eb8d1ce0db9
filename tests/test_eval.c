/* test_eval.c — the library half of `lumosaic eval` (infer/eval.h, system.md §10):
 * lm_eval_peak_nm (parabola vertex exact on samples of a concave quadratic whose vertex lies
 * between samples; a maximum at the first / last sample is not refined; ties take the first
 * maximum; flat spectra; single sample), lm_eval_prepare (crop to the tile from the top-left,
 * divide by the maximum, shape / numeric errors with "eval:" messages) and lm_eval_scene on a
 * small smooth cube with a linear model fitted to it by least squares: noise 0 beats 20 %,
 * the noise-0 PSNR equals a plain-loop PSNR of lm_tile_infer's reconstruction of the clean
 * frame, a level draws the same noise wherever it sits in the list (and in lm_eval_scene_one,
 * whose kept reconstruction scores its metrics), and bad level lists fail;
 * lm_eval_motion_region (the in-view margin from the frame period) and lm_eval_motion_run on
 * the same model: a still scene scores the same aligned or not and equals the static
 * reference, at 60 px/s alignment is not worse than none, at 400 px/s the unaligned frame loses
 * >= 3 dB against the static reference and alignment wins at least half of it back; a
 * negative speed fails.
 * lm_eval_simulate: the coded frame equals lm_forward_simulate31's (noise-free, and with noise
 * for the same rng, which is not advanced); the RGB frame (mst-tiny) equals lm_rgbcam_render and
 * a plain loop over the camera weights; a 30-band cube fails. lm_eval_reconstruct: the linear
 * model equals lm_tile_infer (whole 0) and lm_whole_infer (whole 1); mst-tiny equals
 * lm_mst_reconstruct of the frame. The RGB path (mst-tiny, 24 x 32 cube) through lm_eval_scene
 * (noise 0 and 20 % against plain-loop PSNRs of independently simulated and reconstructed
 * frames), lm_eval_motion_run on a 48 x 64 cube (still scene = static reference, aligned =
 * unaligned, motion changes the score; the 24 x 32 cube keeps nothing in view at 400 px/s and
 * fails) and lm_eval_rainbow_run.
 * Multi-frame models (rt-8-mf3): lm_eval_motion_run_noise's aligned and unaligned scores equal
 * a reconstruction of lm_align_stack_frames's input (the path `infer` takes on a sequence) of
 * the same three video frames and noise draws, scored by hand over the in-view region; the
 * noise-free rows of a one-frame model equal lm_eval_motion_run's; the still rows of a
 * multi-frame model run; a one-frame input to it fails with a shape error. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "tests/check.h"
#include "data/align.h"
#include "data/forward.h"
#include "data/spectra.h"
#include "data/video.h"
#include "data/rgbcam.h"
#include "infer/eval.h"
#include "infer/whole.h"
#include "models/layers.h"
#include "data/mosaic.h"

static lm_system g_sys;
static int g_ok;

/* ---- lm_eval_peak_nm ------------------------------------------------------------------- */

static void test_peak_parabola_exact(void)
{
    const double v[3] = {3.3, 0.71, 5.5}; /* vertices in sample units, between samples */
    for (int k = 0; k < 3; k++) {
        float s[8];
        for (int i = 0; i < 8; i++) s[i] = (float)(7.0 - 0.8 * (i - v[k]) * (i - v[k]));
        double got = lm_eval_peak_nm(s, 8, 400.0, 10.0);
        CHECK_CLOSE(got, 400.0 + 10.0 * v[k], 2e-3, 0);
    }
    /* another grid: wl0 and step are applied */
    float s[5];
    for (int i = 0; i < 5; i++) s[i] = (float)(1.0 - (i - 2.25) * (i - 2.25));
    CHECK_CLOSE(lm_eval_peak_nm(s, 5, 500.0, 5.0), 500.0 + 5.0 * 2.25, 1e-3, 0);
}

static void test_peak_edges_not_refined(void)
{
    float dec[5] = {5, 4, 2, 1, 0}, inc[5] = {0, 1, 2, 4, 5};
    CHECK_CLOSE(lm_eval_peak_nm(dec, 5, 400.0, 10.0), 400.0, 0, 0);
    CHECK_CLOSE(lm_eval_peak_nm(inc, 5, 400.0, 10.0), 440.0, 0, 0);
    float one[1] = {3};
    CHECK_CLOSE(lm_eval_peak_nm(one, 1, 410.0, 10.0), 410.0, 0, 0);
}

static void test_peak_ties_and_flat(void)
{
    float tie[5] = {0, 5, 0, 5, 0}; /* first maximum (index 1), symmetric: no shift */
    CHECK_CLOSE(lm_eval_peak_nm(tie, 5, 400.0, 10.0), 410.0, 1e-9, 0);
    float flat[4] = {2, 2, 2, 2}; /* first sample, no left neighbour */
    CHECK_CLOSE(lm_eval_peak_nm(flat, 4, 400.0, 10.0), 400.0, 0, 0);
    float plateau[5] = {1, 3, 3, 3, 1}; /* first of the plateau, pulled half a step right */
    CHECK_CLOSE(lm_eval_peak_nm(plateau, 5, 400.0, 10.0), 415.0, 1e-9, 0);
    float neg[4] = {-4, -1, -2, -9}; /* negative values: vertex of (-4, -1, -2) */
    double want = 400.0 + 10.0 * (1.0 + 0.5 * (-4.0 + 2.0) / (-4.0 - 2.0 * -1.0 + -2.0));
    CHECK_CLOSE(lm_eval_peak_nm(neg, 4, 400.0, 10.0), want, 1e-9, 0);
}

/* ---- lm_eval_prepare ------------------------------------------------------------------- */

static float val(int b, int y, int x) { return (float)(1 + b + 3 * y + 7 * x); }

static void test_prepare_crops_and_normalises(void)
{
    const int B = 31, Hh = 11, Ww = 14, ty = 3, tx = 4;
    lm_cube c;
    CHECK(lm_cube_alloc(&c, B, Hh, Ww, 400, 10) == LM_OK);
    for (int b = 0; b < B; b++)
        for (int y = 0; y < Hh; y++)
            for (int x = 0; x < Ww; x++) c.data[((size_t)b * Hh + y) * Ww + x] = val(b, y, x);
    float mx = val(B - 1, Hh - 1, Ww - 1); /* in the cropped-away corner: still the divisor */
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_eval_prepare(&c, ty, tx, &e) == LM_OK, "%s", e.msg);
    CHECK(c.height == 9 && c.width == 12 && c.bands == 31);
    int bad = 0;
    for (int b = 0; b < B; b++)
        for (int y = 0; y < 9; y++)
            for (int x = 0; x < 12; x++)
                if (fabsf(c.data[((size_t)b * 9 + y) * 12 + x] - val(b, y, x) / mx) > 1e-6f) bad++;
    CHECK_MSG(bad == 0, "%d values differ", bad);
    lm_cube_free(&c);
}

static void test_prepare_errors(void)
{
    lm_err e;
    lm_cube c;
    CHECK(lm_cube_alloc(&c, 30, 6, 8, 400, 10) == LM_OK);
    for (int i = 0; i < 30 * 48; i++) c.data[i] = 1;
    lm_err_clear(&e);
    CHECK(lm_eval_prepare(&c, 3, 4, &e) == LM_ERR_SHAPE && strstr(e.msg, "eval:"));
    lm_cube_free(&c);
    CHECK(lm_cube_alloc(&c, 31, 6, 8, 410, 10) == LM_OK); /* 410..710 nm */
    for (int i = 0; i < 31 * 48; i++) c.data[i] = 1;
    lm_err_clear(&e);
    CHECK(lm_eval_prepare(&c, 3, 4, &e) == LM_ERR_SHAPE && strstr(e.msg, "eval:"));
    lm_cube_free(&c);
    CHECK(lm_cube_alloc(&c, 31, 2, 8, 400, 10) == LM_OK); /* fewer rows than the tile */
    for (int i = 0; i < 31 * 16; i++) c.data[i] = 1;
    lm_err_clear(&e);
    CHECK(lm_eval_prepare(&c, 3, 4, &e) == LM_ERR_SHAPE && strstr(e.msg, "tile"));
    lm_cube_free(&c);
    CHECK(lm_cube_alloc(&c, 31, 6, 8, 400, 10) == LM_OK);
    memset(c.data, 0, sizeof(float) * 31 * 48); /* all zero */
    lm_err_clear(&e);
    CHECK(lm_eval_prepare(&c, 3, 4, &e) == LM_ERR_NUMERIC && strstr(e.msg, "eval:"));
    c.data[5] = INFINITY;
    lm_err_clear(&e);
    CHECK(lm_eval_prepare(&c, 3, 4, &e) == LM_ERR_NUMERIC);
    CHECK(c.height == 6 && c.width == 8); /* untouched on error */
    lm_cube_free(&c);
}

/* ---- lm_eval_scene --------------------------------------------------------------------- */

#define SH 74
#define SW 99

/* Smooth textures mixed by smooth spectra, 31 bands at 400..700 nm, prepared (72 x 96:
 * sub-images of 24 x 24, the smallest the alignment accepts). */
static void small_scene(lm_cube *c)
{
    CHECK(lm_cube_alloc(c, 31, SH, SW, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++) {
        double l = b / 30.0;
        for (int y = 0; y < SH; y++)
            for (int x = 0; x < SW; x++) {
                double t0 = sin(0.11 * x + 0.07 * y), t1 = cos(0.05 * x - 0.13 * y);
                c->data[((size_t)b * SH + y) * SW + x] =
                    (float)(0.5 + 0.25 * cos(3 * l) * t0 + 0.2 * exp(-9 * (l - 0.6) * (l - 0.6)) * t1);
            }
    }
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_eval_prepare(c, 3, 4, &e) == LM_OK, "%s", e.msg);
}

/* Fit the linear model's 1x1 projection (12 demosaicked channels + bias -> bands 1..31) to the
 * clean frame of truth by least squares (normal equations in double, Gaussian elimination), so
 * that its reconstruction is meaningful. Output channels 0 and 32 are left at zero. */
static void fit_linear(lm_model *m, const lm_cube *truth)
{
    int Hh = truth->height, Ww = truth->width;
    size_t plane = (size_t)Hh * Ww;
    float *frame = malloc(sizeof(float) * plane);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_forward_simulate31(&g_sys, truth, &fo, NULL, frame, NULL, &e) == LM_OK);
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 1) == 0);
    lm_ctx_set_grad(&c, 0);
    lm_tensor *raw = lm_tensor_from(&c, 4, (int[]){1, 1, Hh, Ww}, frame);
    lm_tensor *d = lm_contiguous(&c, lm_mosaic_demosaic(&c, &m->mosaic, raw));
    CHECK_CTX_OK(&c);
    lm_tensor *w = NULL, *bias = NULL;
    for (int i = 0; i < m->params.n; i++) {
        lm_tensor *t = &m->params.items[i]->t;
        if (lm_tensor_numel(t) == 33 * 12) w = t;
        if (lm_tensor_numel(t) == 33) bias = t;
    }
    CHECK(w && bias && d && d->shape[1] == 12);
    if (w && bias && d) {
        double A[13][13] = {{0}}, rhs[31][13] = {{0}};
        for (size_t p = 0; p < plane; p++) {
            double f[13];
            for (int j = 0; j < 12; j++) f[j] = d->data[j * plane + p];
            f[12] = 1.0;
            for (int i = 0; i < 13; i++) {
                for (int j = 0; j < 13; j++) A[i][j] += f[i] * f[j];
                for (int b = 0; b < 31; b++) rhs[b][i] += f[i] * truth->data[b * plane + p];
            }
        }
        for (int i = 0; i < 13; i++) A[i][i] += 1e-6 * (A[i][i] + 1e-9);
        for (int k = 0; k < 13; k++) /* elimination without pivoting: A is SPD */
            for (int i = k + 1; i < 13; i++) {
                double r = A[i][k] / A[k][k];
                for (int j = k; j < 13; j++) A[i][j] -= r * A[k][j];
                for (int b = 0; b < 31; b++) rhs[b][i] -= r * rhs[b][k];
            }
        memset(w->data, 0, sizeof(float) * 33 * 12);
        memset(bias->data, 0, sizeof(float) * 33);
        for (int b = 0; b < 31; b++) {
            double x[13];
            for (int i = 12; i >= 0; i--) {
                double s = rhs[b][i];
                for (int j = i + 1; j < 13; j++) s -= A[i][j] * x[j];
                x[i] = s / A[i][i];
            }
            for (int j = 0; j < 12; j++) w->data[(b + 1) * 12 + j] = (float)x[j];
            bias->data[b + 1] = (float)x[12];
        }
    }
    lm_ctx_free(&c);
    free(frame);
}

static double plain_psnr(const float *a, const float *b, size_t n)
{
    double s = 0;
    for (size_t i = 0; i < n; i++) s += ((double)a[i] - b[i]) * ((double)a[i] - b[i]);
    return -10.0 * log10(s / (double)n);
}

/* The scored region: the margin is the motion over two frame periods plus two tiles, from
 * the system's frame period (a system with frames 50 ms apart gets a wider margin). */
static void test_motion_region(void)
{
    if (!g_ok) return;
    int y0, x0, h, w;
    lm_eval_motion_region(&g_sys, 400.0, 72, 96, &y0, &x0, &h, &w);
    /* 30 fps: span 66.7 ms; x: 320 px/s -> 21.3 -> 22 + 8; y: 240 px/s -> 16 + 6 */
    CHECK(x0 == 30 && y0 == 22 && w == 36 && h == 28);
    lm_eval_motion_region(&g_sys, 0.0, 72, 96, &y0, &x0, &h, &w);
    CHECK(x0 == 8 && y0 == 6 && w == 80 && h == 60);
    lm_system slow = g_sys;
    slow.frame_period_us = 50000.0; /* span 100 ms: x 32 + 8, y 24 + 6 */
    lm_eval_motion_region(&slow, 400.0, 72, 96, &y0, &x0, &h, &w);
    CHECK(x0 == 40 && y0 == 30 && w == 16 && h == 12);
    lm_eval_motion_region(&slow, 400.0, 40, 96, &y0, &x0, &h, &w);
    CHECK(h == 0);
}

/* Motion: still scene -> aligned and unaligned agree (within 0.1 dB) and equal the static
 * reference; slow motion -> alignment is not worse than none (within 0.1 dB); fast motion ->
 * the unaligned frame loses >= 3 dB against the static reference and alignment recovers at
 * least half of it. Scores cover the in-view region only. */
static void test_motion(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                        const lm_tile_opts *to)
{
    lm_err e;
    lm_err_clear(&e);
    lm_eval_motion m0, m1, ms;
    CHECK_MSG(lm_eval_motion_run(c, im, truth, 0.0, to, NULL, NULL, &m0, &e) == LM_OK, "%s",
              e.msg);
    CHECK_MSG(lm_eval_motion_run(c, im, truth, 60.0, to, NULL, NULL, &ms, &e) == LM_OK, "%s",
              e.msg);
    CHECK_MSG(lm_eval_motion_run(c, im, truth, 400.0, to, NULL, NULL, &m1, &e) == LM_OK, "%s",
              e.msg);
    printf("  motion 0 px/s: aligned %.3f dB, unaligned %.3f dB; 60 px/s: static %.3f, aligned "
           "%.3f, unaligned %.3f; 400 px/s: static %.3f, aligned %.3f, unaligned %.3f\n",
           m0.aligned.psnr, m0.unaligned.psnr, ms.still.psnr, ms.aligned.psnr,
           ms.unaligned.psnr, m1.still.psnr, m1.aligned.psnr, m1.unaligned.psnr);
    CHECK(m0.speed == 0.0 && m1.speed == 400.0);
    CHECK_CLOSE(m1.px_per_frame, 400.0 / 30.0, 1e-6, 0);
    CHECK(m1.x0 == 30 && m1.y0 == 22 && m1.width == 36 && m1.height == 28);
    CHECK(m0.still.psnr == m0.unaligned.psnr && m0.still.sam == m0.unaligned.sam);
    CHECK_MSG(m0.aligned.psnr > m0.unaligned.psnr - 0.1, "still: aligned %g vs %g",
              m0.aligned.psnr, m0.unaligned.psnr);
    CHECK_MSG(ms.aligned.psnr > ms.unaligned.psnr - 0.1, "60 px/s: aligned %g vs %g",
              ms.aligned.psnr, ms.unaligned.psnr);
    double loss = m1.still.psnr - m1.unaligned.psnr;
    CHECK_MSG(loss > 3.0, "motion costs: %g vs %g", m1.unaligned.psnr, m1.still.psnr);
    CHECK_MSG(m1.aligned.psnr > m1.unaligned.psnr + 0.5 * loss, "alignment recovers half: %g "
              "vs %g (static %g)", m1.aligned.psnr, m1.unaligned.psnr, m1.still.psnr);
    CHECK(lm_eval_motion_run(c, im, truth, -1.0, to, NULL, NULL, &m1, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "eval: motion") != NULL);
}

static void test_scene_linear_model(void)
{
    if (!g_ok) return;
    lm_err e;
    lm_err_clear(&e);
    lm_infer_model im;
    memset(&im, 0, sizeof im);
    im.sys = g_sys;
    lm_mosaic mo;
    CHECK_MSG(lm_mosaic_from_system(&g_sys, &mo, &e) == LM_OK, "%s", e.msg);
    im.model = lm_model_create("linear", &mo, 11, &e);
    CHECK_MSG(im.model, "%s", e.msg);
    if (!im.model) return;
    lm_cube truth;
    small_scene(&truth);
    CHECK(truth.height == 72 && truth.width == 96);
    fit_linear(im.model, &truth);
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 2) == 0);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_rng rng;
    lm_rng_seed(&rng, 5);
    float k[2] = {0.0f, 0.2f}, k2[2] = {0.2f, 0.1f};
    lm_metrics m[2], m2[2];
    CHECK_MSG(lm_eval_scene(&c, &im, &truth, k, 2, &to, &rng, m, &e) == LM_OK, "%s", e.msg);
    printf("  linear model: noise 0 %.3f dB, 20 %% %.3f dB\n", m[0].psnr, m[1].psnr);
    CHECK_MSG(m[0].psnr > m[1].psnr + 1.0, "%g vs %g", m[0].psnr, m[1].psnr);
    CHECK(m[0].mae < m[1].mae);
    /* the 20 % level draws the same noise at another position in the list */
    CHECK_MSG(lm_eval_scene(&c, &im, &truth, k2, 2, &to, &rng, m2, &e) == LM_OK, "%s", e.msg);
    CHECK(m2[0].psnr == m[1].psnr && m2[0].sam == m[1].sam);
    CHECK(m2[1].psnr != m[1].psnr);
    /* one level with its reconstruction kept: the same noise and metrics as in the list, and
     * the kept cube scores them */
    lm_metrics one;
    lm_cube kept;
    CHECK_MSG(lm_eval_scene_one(&c, &im, &truth, 0.2f, &to, &rng, &one, &kept, &e) == LM_OK,
              "%s", e.msg);
    CHECK(one.psnr == m[1].psnr && one.ssim == m[1].ssim && one.sam == m[1].sam);
    CHECK(kept.bands == 31 && kept.height == truth.height && kept.width == truth.width);
    if (kept.data)
        CHECK_CLOSE(one.psnr, plain_psnr(kept.data, truth.data, 31 * (size_t)truth.height *
                                                                     truth.width), 1e-6, 1e-6);
    lm_cube_free(&kept);
    CHECK(lm_eval_scene_one(&c, &im, &truth, -0.1f, &to, &rng, &one, &kept, &e) == LM_ERR_ARG);
    CHECK(kept.data == NULL);
    /* noise 0 against a plain-loop PSNR of the clean frame's reconstruction */
    size_t plane = (size_t)truth.height * truth.width;
    float *frame = malloc(sizeof(float) * plane);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    CHECK(lm_forward_simulate31(&g_sys, &truth, &fo, NULL, frame, NULL, &e) == LM_OK);
    lm_cube pred;
    CHECK_MSG(lm_tile_infer(&c, im.model, frame, truth.height, truth.width, &to, &pred, &e) ==
              LM_OK, "%s", e.msg);
    if (pred.data) CHECK_CLOSE(m[0].psnr, plain_psnr(pred.data, truth.data, 31 * plane), 1e-6, 1e-6);
    lm_cube_free(&pred);
    free(frame);
    /* bad level lists */
    float neg[1] = {-0.1f};
    CHECK(lm_eval_scene(&c, &im, &truth, neg, 1, &to, &rng, m, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "eval:") != NULL);
    CHECK(lm_eval_scene(&c, &im, &truth, k, 0, &to, &rng, m, &e) == LM_ERR_ARG);
    CHECK(lm_eval_scene(&c, &im, &truth, k, LM_EVAL_MAX_NOISE + 1, &to, &rng, m, &e) ==
          LM_ERR_ARG);
    test_motion(&c, &im, &truth, &to);
    lm_ctx_free(&c);
    lm_cube_free(&truth);
    lm_model_free(im.model);
}

/* ---- lm_eval_simulate / lm_eval_reconstruct -------------------------------------------- */

static lm_model *make_model(const char *preset, uint64_t seed)
{
    lm_err e;
    lm_err_clear(&e);
    lm_mosaic mo;
    CHECK_MSG(lm_mosaic_from_system(&g_sys, &mo, &e) == LM_OK, "%s", e.msg);
    lm_model *m = lm_model_create(preset, &mo, seed, &e);
    CHECK_MSG(m, "%s: %s", preset, e.msg);
    if (m) lm_params_set_requires_grad(&m->params, 0);
    return m;
}

static size_t count_diff(const float *a, const float *b, size_t n)
{
    size_t d = 0;
    for (size_t i = 0; i < n; i++) d += a[i] != b[i];
    return d;
}

static void test_simulate_coded(void)
{
    if (!g_ok) return;
    lm_infer_model im = {.model = make_model("linear", 3), .sys = g_sys};
    if (!im.model) return;
    lm_cube truth;
    small_scene(&truth);
    size_t plane = (size_t)truth.height * truth.width;
    float *want = malloc(sizeof(float) * plane), *f = NULL;
    size_t n = 0;
    lm_err e;
    lm_err_clear(&e);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    CHECK(lm_forward_simulate31(&g_sys, &truth, &fo, NULL, want, NULL, &e) == LM_OK);
    CHECK_MSG(lm_eval_simulate(&im, &truth, NULL, NULL, &f, &n, &e) == LM_OK, "%s", e.msg);
    CHECK(n == plane && f);
    if (f) CHECK(count_diff(f, want, plane) == 0);
    free(f);
    /* with noise: the same draws as lm_forward_simulate31 from the same rng state */
    lm_rng rng, r2;
    lm_rng_seed(&rng, 9);
    r2 = rng;
    fo.noise.gauss_k = 0.1f;
    CHECK(lm_forward_simulate31(&g_sys, &truth, &fo, &r2, want, NULL, &e) == LM_OK);
    CHECK_MSG(lm_eval_simulate(&im, &truth, &fo.noise, &rng, &f, &n, &e) == LM_OK, "%s", e.msg);
    if (f) CHECK(count_diff(f, want, plane) == 0);
    free(f);
    CHECK(lm_eval_simulate(&im, &truth, &fo.noise, &rng, &f, &n, &e) == LM_OK); /* not advanced */
    if (f) CHECK(count_diff(f, want, plane) == 0);
    free(f);
    lm_cube bad;
    CHECK(lm_cube_alloc(&bad, 30, 6, 8, 400, 10) == LM_OK);
    for (int i = 0; i < 30 * 48; i++) bad.data[i] = 0.5f;
    CHECK(lm_eval_simulate(&im, &bad, NULL, NULL, &f, &n, &e) == LM_ERR_SHAPE && !f && n == 0);
    CHECK(strstr(e.msg, "eval:") != NULL);
    lm_cube_free(&bad);
    free(want);
    lm_cube_free(&truth);
    lm_model_free(im.model);
}

/* reconstruct of the linear model = lm_tile_infer (whole 0) / lm_whole_infer (whole 1) */
static void test_reconstruct_linear(void)
{
    if (!g_ok) return;
    lm_infer_model im = {.model = make_model("linear", 4), .sys = g_sys};
    if (!im.model) return;
    lm_cube truth, a, b;
    small_scene(&truth);
    int H = truth.height, W = truth.width;
    size_t n = 0, cn = (size_t)31 * H * W;
    float *f = NULL;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_eval_simulate(&im, &truth, NULL, NULL, &f, &n, &e) == LM_OK);
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 2) == 0);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    for (int whole = 0; whole < 2 && f; whole++) {
        CHECK_MSG(lm_eval_reconstruct(&c, &im, f, H, W, &to, whole, &a, &e) == LM_OK, "%s", e.msg);
        lm_status st = whole ? lm_whole_infer(&c, im.model, f, H, W, &b, &e)
                             : lm_tile_infer(&c, im.model, f, H, W, &to, &b, &e);
        CHECK_MSG(st == LM_OK, "%s", e.msg);
        CHECK(a.bands == 31 && a.height == H && a.width == W);
        if (a.data && b.data) CHECK_MSG(count_diff(a.data, b.data, cn) == 0, "whole %d", whole);
        lm_cube_free(&a);
        lm_cube_free(&b);
    }
    /* the two paths differ (window blending vs one pass), so the flag is really followed */
    if (f && !lm_eval_reconstruct(&c, &im, f, H, W, &to, 0, &a, &e) &&
        !lm_eval_reconstruct(&c, &im, f, H, W, &to, 1, &b, &e))
        CHECK(count_diff(a.data, b.data, cn) > 0);
    lm_cube_free(&a);
    lm_cube_free(&b);
    lm_ctx_free(&c);
    free(f);
    lm_cube_free(&truth);
    lm_model_free(im.model);
}

/* A small prepared cube for MST++ (h x w after the 3 x 4 tile crop; h, w multiples of 3, 4). */
static void tiny_scene_sized(lm_cube *c, int h, int w)
{
    int H = h + 1, W = w + 2;
    CHECK(lm_cube_alloc(c, 31, H, W, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                c->data[((size_t)b * H + y) * W + x] =
                    (float)(0.4 + 0.3 * sin(0.3 * x + 0.2 * y + 0.1 * b) * cos(0.05 * b * y));
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_eval_prepare(c, 3, 4, &e) == LM_OK, "%s", e.msg);
}

/* 24 x 32 after the crop. */
static void tiny_scene(lm_cube *c) { tiny_scene_sized(c, 24, 32); }

/* RGB frame = lm_rgbcam_render = a plain loop over the camera weights */
static void check_rgb_frame(const lm_infer_model *im, const lm_cube *t)
{
    lm_err e;
    lm_err_clear(&e);
    lm_rgbcam cam;
    CHECK_MSG(lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, &e) == LM_OK, "%s", e.msg);
    size_t plane = (size_t)t->height * t->width, n = 0;
    float *f = NULL, *want = malloc(sizeof(float) * 3 * plane);
    CHECK_MSG(lm_eval_simulate(im, t, NULL, NULL, &f, &n, &e) == LM_OK, "%s", e.msg);
    CHECK(n == 3 * plane);
    lm_rgbcam_render(&cam, t->data, t->height, t->width, want, 1);
    if (f) CHECK(count_diff(f, want, 3 * plane) == 0);
    double maxd = 0;
    for (int ch = 0; ch < 3 && f; ch++)
        for (size_t p = 0; p < plane; p++) {
            double s = 0;
            for (int b = 0; b < 31; b++) s += (double)cam.w[ch][b] * t->data[b * plane + p];
            double d = fabs(s - f[ch * plane + p]);
            if (d > maxd) maxd = d;
        }
    CHECK_MSG(maxd < 1e-5, "rgb vs plain loop: %g", maxd);
    free(f);
    free(want);
}

/* PSNR of lm_mst_reconstruct(frame) against truth, plain loop */
static double mst_psnr(lm_model *m, const float *frame, const lm_cube *t)
{
    size_t cn = (size_t)31 * t->height * t->width;
    float *out = malloc(sizeof(float) * cn);
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_mst_reconstruct(m, frame, t->height, t->width, out, 1, &e) == LM_OK, "%s",
              e.msg);
    double p = plain_psnr(out, t->data, cn);
    free(out);
    return p;
}

static void test_rgb_scene(lm_ctx *c, const lm_infer_model *im, const lm_cube *t)
{
    lm_err e;
    lm_err_clear(&e);
    lm_rng rng;
    lm_rng_seed(&rng, 5);
    float k[2] = {0.0f, 0.2f};
    lm_metrics m[2];
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    CHECK_MSG(lm_eval_scene(c, im, t, k, 2, &to, &rng, m, &e) == LM_OK, "%s", e.msg);
    printf("  mst-tiny (untrained): noise 0 %.3f dB, 20 %% %.3f dB\n", m[0].psnr, m[1].psnr);
    lm_rgbcam cam;
    CHECK(lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, &e) == LM_OK);
    size_t plane = (size_t)t->height * t->width;
    float *rgb = malloc(sizeof(float) * 3 * plane);
    lm_rgbcam_render(&cam, t->data, t->height, t->width, rgb, 1);
    CHECK_CLOSE(m[0].psnr, mst_psnr(im->model, rgb, t), 1e-4, 1e-6);
    lm_noise_opts no = {.gauss_k = 0.2f};
    lm_rng r = lm_rng_split(&rng, 200000); /* the level's stream, as documented */
    CHECK(lm_rgbcam_simulate(&cam, t->data, t->height, t->width, &no, &r, rgb, 1, &e) == LM_OK);
    CHECK_CLOSE(m[1].psnr, mst_psnr(im->model, rgb, t), 1e-4, 1e-6);
    CHECK(m[1].psnr != m[0].psnr);
    /* motion: still = the static frame, nothing to align; moving = another score; a scene
     * too small to keep anything in view at that speed fails */
    lm_cube big;
    tiny_scene_sized(&big, 48, 64);
    lm_eval_motion m0, m1;
    CHECK_MSG(lm_eval_motion_run(c, im, &big, 0.0, &to, NULL, NULL, &m0, &e) == LM_OK, "%s",
              e.msg);
    CHECK_MSG(lm_eval_motion_run(c, im, &big, 150.0, &to, NULL, NULL, &m1, &e) == LM_OK, "%s",
              e.msg);
    printf("  mst-tiny motion: 0 px/s %.3f dB, 150 px/s %.3f dB (static %.3f)\n",
           m0.unaligned.psnr, m1.unaligned.psnr, m1.still.psnr);
    CHECK(m0.unaligned.psnr == m0.still.psnr && m0.unaligned.sam == m0.still.sam);
    CHECK(m0.aligned.psnr == m0.unaligned.psnr && m1.aligned.psnr == m1.unaligned.psnr);
    CHECK(m1.unaligned.psnr != m0.unaligned.psnr && isfinite(m1.unaligned.psnr));
    CHECK(m1.width == 32 && m1.height == 24);
    CHECK(lm_eval_motion_run(c, im, t, 400.0, &to, NULL, NULL, &m1, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "in view") != NULL);
    CHECK(lm_eval_motion_run(c, im, t, -1.0, &to, NULL, NULL, &m1, &e) == LM_ERR_ARG);
    lm_cube_free(&big);
    lm_eval_rainbow rb;
    CHECK_MSG(lm_eval_rainbow_run(c, im, 24, &to, &rb, &e) == LM_OK, "%s", e.msg);
    CHECK(rb.height == 24 && rb.width == 24 && isfinite(rb.m.psnr));
    CHECK(rb.mean_err_nm >= 0 && rb.mean_err_nm <= rb.max_err_nm && rb.max_err_nm <= 300);
    free(rgb);
}

static void test_rgb_model(void)
{
    if (!g_ok) return;
    lm_infer_model im = {.model = make_model("mst-tiny", 7), .sys = g_sys};
    if (!im.model) return;
    CHECK(im.model->in_channels == 3 && im.model->out_channels == 31);
    lm_cube t;
    tiny_scene(&t);
    CHECK(t.height == 24 && t.width == 32);
    check_rgb_frame(&im, &t);
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 2) == 0);
    /* reconstruct = lm_mst_reconstruct of the frame (whole frame; whole flag unused) */
    float *f = NULL;
    size_t n = 0, cn = (size_t)31 * t.height * t.width;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_eval_simulate(&im, &t, NULL, NULL, &f, &n, &e) == LM_OK);
    float *want = malloc(sizeof(float) * cn);
    lm_cube a;
    if (f) {
        CHECK(lm_mst_reconstruct(im.model, f, t.height, t.width, want, 2, &e) == LM_OK);
        CHECK_MSG(lm_eval_reconstruct(&c, &im, f, t.height, t.width, NULL, 1, &a, &e) == LM_OK,
                  "%s", e.msg);
        CHECK(a.bands == 31 && a.height == t.height && a.width == t.width);
        CHECK(a.wavelength[0] == 400.0f && a.wavelength[30] == 700.0f);
        if (a.data) CHECK(count_diff(a.data, want, cn) == 0);
        lm_cube_free(&a);
    }
    free(want);
    free(f);
    test_rgb_scene(&c, &im, &t);
    lm_ctx_free(&c);
    lm_cube_free(&t);
    lm_model_free(im.model);
}

/* PSNR over the motion test's region (31 bands) by lm_metrics_compute on copies. */
static double region_psnr(const float *pred, const float *truth, int H, int W,
                          const lm_eval_motion *r)
{
    size_t n = (size_t)31 * r->height * r->width;
    float *a = malloc(sizeof(float) * n), *b = malloc(sizeof(float) * n);
    for (int k = 0; k < 31; k++)
        for (int y = 0; y < r->height; y++) {
            memcpy(a + ((size_t)k * r->height + y) * r->width,
                   pred + ((size_t)k * H + r->y0 + y) * W + r->x0, sizeof(float) * r->width);
            memcpy(b + ((size_t)k * r->height + y) * r->width,
                   truth + ((size_t)k * H + r->y0 + y) * W + r->x0, sizeof(float) * r->width);
        }
    lm_metrics m;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_metrics_compute(a, b, 31, r->height, r->width, 0, 31, &m, &e) == LM_OK);
    free(a), free(b);
    return m.psnr;
}

static void test_multi_frame(void)
{
    if (!g_ok) return;
    lm_err e;
    lm_err_clear(&e);
    lm_infer_model im;
    memset(&im, 0, sizeof im);
    im.sys = g_sys;
    im.model = make_model("rt-8-mf3", 5);
    if (!im.model) return;
    CHECK(im.model->in_channels == 3 && lm_model_frames(im.model) == 3);
    lm_cube truth;
    small_scene(&truth);
    const int H = truth.height, W = truth.width;
    const size_t n = (size_t)H * W;
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 1) == 0);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    const double speed = 200.0;
    const float k = 0.05f;
    lm_rng rng;
    lm_rng_seed(&rng, 9);
    lm_eval_motion mo;
    CHECK_MSG(lm_eval_motion_run_noise(&c, &im, &truth, speed, k, &rng, &to, NULL, NULL, &mo,
                                       &e) == LM_OK, "%s", e.msg);
    /* by hand: the video's frames as eval simulates them, the documented noise draws */
    lm_cube c41, gt;
    CHECK(lm_cube_mirror41(&truth, &c41, &e) == LM_OK);
    lm_video_opts vo;
    memset(&vo, 0, sizeof vo);
    vo.motion.vx = speed * LM_EVAL_MOTION_DIR_X, vo.motion.vy = speed * LM_EVAL_MOTION_DIR_Y;
    vo.nthreads = 1;
    float *fr = malloc(sizeof(float) * 3 * n), *in = malloc(sizeof(float) * 3 * n);
    lm_noise_opts no;
    memset(&no, 0, sizeof no);
    no.gauss_k = k;
    lm_rng r = lm_rng_split(&rng, (uint64_t)llround(k * 1e6));
    for (int i = 0; i < 3; i++) {
        CHECK_MSG(lm_video_frame(&g_sys, &c41, &vo, i, NULL, fr + i * n, NULL, i == 1 ? &gt : NULL,
                                 &e) == LM_OK, "%s", e.msg);
        CHECK(lm_forward_noise(fr + i * n, H, W, &no, &r, 1, &e) == LM_OK);
    }
    lm_flow_opts fo;
    lm_flow_default_opts(&fo, LM_FLOW_MEDIUM);
    double got[2];
    for (int al = 0; al < 2; al++) {
        CHECK_MSG(lm_align_stack_frames(&g_sys, fr, fr + n, fr + 2 * n, H, W, al, &fo, NULL, in,
                                        &e) == LM_OK, "%s", e.msg);
        lm_cube pred;
        CHECK_MSG(lm_eval_reconstruct(&c, &im, in, H, W, &to, 0, &pred, &e) == LM_OK, "%s", e.msg);
        got[al] = region_psnr(pred.data, lm_cube_band(&gt, 2), H, W, &mo);
        lm_cube_free(&pred);
    }
    printf("  rt-8-mf3 (random) at %g px/s, %g %%: eval aligned %.4f / unaligned %.4f dB, by "
           "hand %.4f / %.4f dB\n", speed, 100.0 * k, mo.aligned.psnr, mo.unaligned.psnr,
           got[1], got[0]);
    CHECK(mo.aligned.psnr == got[1] && mo.unaligned.psnr == got[0]);
    CHECK(mo.aligned.psnr != mo.unaligned.psnr);
    /* the still rows run (three still frames with their own noise) */
    float kk[2] = {0.0f, 0.1f};
    lm_metrics ms[2];
    CHECK_MSG(lm_eval_scene(&c, &im, &truth, kk, 2, &to, &rng, ms, &e) == LM_OK, "%s", e.msg);
    CHECK(isfinite(ms[0].psnr) && ms[1].psnr < ms[0].psnr);
    /* a one-frame input: a shape error naming the three planes */
    lm_ctx_reset(&c);
    lm_tensor *one = lm_tensor_from(&c, 4, (int[]){1, 1, 24, 32}, fr);
    CHECK(one && lm_model_forward(&c, im.model, one) == NULL);
    CHECK(lm_ctx_status(&c) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(lm_ctx_message(&c), "frames i-1 and i+1") != NULL, "%s", lm_ctx_message(&c));
    lm_ctx_clear_error(&c);
    lm_ctx_reset(&c);
    free(fr), free(in);
    lm_cube_free(&c41), lm_cube_free(&gt), lm_cube_free(&truth);
    lm_ctx_free(&c);
    lm_model_free(im.model);
}

int main(void)
{
    lm_err e;
    lm_err_clear(&e);
    g_ok = lm_system_default(&g_sys, &e) == LM_OK;
    if (!g_ok) printf("default system: %s\n", e.msg);
    CHECK(g_ok);
    RUN(test_peak_parabola_exact);
    RUN(test_peak_edges_not_refined);
    RUN(test_peak_ties_and_flat);
    RUN(test_prepare_crops_and_normalises);
    RUN(test_prepare_errors);
    RUN(test_motion_region);
    RUN(test_scene_linear_model);
    RUN(test_simulate_coded);
    RUN(test_reconstruct_linear);
    RUN(test_rgb_model);
    RUN(test_multi_frame);
    return check_summary();
}
