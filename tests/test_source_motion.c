/* test_source_motion.c — moving-scene training samples (train/source_motion.c): one rendered
 * patch against the video forward model (lm_video_frame on the same crop: LED images warped
 * instead of 41 bands, the same numbers), a still "moving" sample equal to the dataset's own,
 * moving samples that differ from it, and determinism. Multi-frame samples (frames 3): a still
 * sample's three raw frames equal three single-frame simulations (lm_forward_simulate31 of the
 * window, the documented noise streams), batches are pure functions of the index, and the
 * alignment brings a moving sample's neighbours closer to the current frame. */
#include "data/dataset.h"
#include "data/spectra.h"
#include "data/system.h"
#include "data/video.h"
#include "tests/check.h"
#include "tests/shared_dir.h"
#include "train/train.h"
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include "data/cube_io.h"
#include "data/forward.h"

static lm_system g_sys;

static void test_render_matches_video_frame(void)
{
    const int H = 36, W = 44, py = 9, px = 12, ph = 15, pw = 16;
    lm_cube c31;
    CHECK(lm_cube_alloc(&c31, 31, H, W, 400.0f, 10.0f) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                lm_cube_band(&c31, b)[y * W + x] =
                    0.5f + 0.4f * sinf(0.3f * x + 0.2f * y + 0.1f * b) * cosf(0.17f * y - 0.05f * b);
    lm_motion m = {0};
    m.vx = 300, m.vy = -150, m.rot_deg_s = 40;
    m.has_centre = 1, m.cx = px + 7.5, m.cy = py + 7;
    float *raw = malloc(sizeof(float) * ph * pw), *tgt = malloc(sizeof(float) * 33 * ph * pw);
    lm_err e = {0};
    CHECK_MSG(lm_train_motion_render(&g_sys, &c31, &m, 3, py, px, ph, pw, raw, tgt, &e) == LM_OK,
              "%s", e.msg);
    lm_cube c41, gt = {0}, g33;
    CHECK(lm_cube_mirror41(&c31, &c41, &e) == LM_OK);
    lm_video_opts o = {0};
    o.motion = m, o.samples = 3, o.nthreads = 1;
    float *b1 = malloc(sizeof(float) * H * W);
    CHECK_MSG(lm_video_frame(&g_sys, &c41, &o, 0, NULL, b1, NULL, &gt, &e) == LM_OK, "%s", e.msg);
    CHECK(lm_cube_target33(&gt, &g33, &e) == LM_OK);
    double wr = 0, wt = 0, moved = 0;
    for (int y = 0; y < ph; y++)
        for (int x = 0; x < pw; x++) {
            wr = fmax(wr, fabs(raw[y * pw + x] - b1[(py + y) * W + px + x]));
            moved = fmax(moved, fabs(raw[y * pw + x] - b1[(py + y) * W + px + x + 4]));
            for (int c = 0; c < 33; c++)
                wt = fmax(wt, fabs(tgt[(c * ph + y) * pw + x] -
                                   lm_cube_band(&g33, c)[(py + y) * W + px + x]));
        }
    CHECK_MSG(wr < 1e-5, "raw vs lm_video_frame: %g", wr);
    CHECK_MSG(wt < 1e-5, "target vs lm_video_frame's ground truth: %g", wt);
    CHECK(moved > 1e-3); /* the comparison can tell pixels apart */
    free(raw), free(tgt), free(b1);
    lm_cube_free(&c31), lm_cube_free(&c41), lm_cube_free(&gt), lm_cube_free(&g33);
}

static lm_dataset *open_cave_noise(float k)
{
    static char path[1024];
    snprintf(path, sizeof path, "%s/data/cave", shared_dir());
    const char *paths[1] = {path};
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = paths, cfg.npaths = 1, cfg.sys = &g_sys;
    cfg.synth_fraction = 0.0f, cfg.procedural_fraction = 0.0f;
    cfg.noise_min = cfg.noise_max = k, cfg.workers = 0;
    lm_err e = {0};
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    return d;
}

static lm_dataset *open_cave(void) { return open_cave_noise(0.0f); }

static void test_source(void)
{
    lm_dataset *d = open_cave();
    if (!d) return;
    const int B = 4, n = 66 * 64;
    float *r0 = malloc(sizeof(float) * B * n), *t0 = malloc(sizeof(float) * B * 33 * n);
    float *r1 = malloc(sizeof(float) * B * n), *t1 = malloc(sizeof(float) * B * 33 * n);
    float *r2 = malloc(sizeof(float) * B * n), *t2 = malloc(sizeof(float) * B * 33 * n);
    lm_err e = {0};
    CHECK(lm_dataset_batch(d, 3, B, r0, t0, &e) == LM_OK);
    /* still: the dataset's own samples */
    lm_train_motion_opts still = {1.0f, 0.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 1, 1};
    lm_train_source src;
    CHECK_MSG(lm_train_source_motion_open(&src, d, &g_sys, &still, 66, 64, 1, &e) == LM_OK, "%s",
              e.msg);
    CHECK_MSG(src.batch(src.user, 3, B, r1, t1, &e) == LM_OK, "%s", e.msg);
    lm_train_source_motion_close(&src);
    double wr = 0, wt = 0;
    for (long i = 0; i < (long)B * n; i++) wr = fmax(wr, fabs(r1[i] - r0[i]));
    for (long i = 0; i < (long)B * 33 * n; i++) wt = fmax(wt, fabs(t1[i] - t0[i]));
    CHECK_MSG(wr < 1e-5 && wt < 1e-6, "still moving samples: raw %g, target %g off", wr, wt);
    /* moving: every item differs from the still one; the same batch twice is the same */
    lm_train_motion_opts mv = {1.0f, 400.0f, 30.0f, 2, 0, 0, 0.0f, 0.0f, 1, 1};
    CHECK(lm_train_source_motion_open(&src, d, &g_sys, &mv, 66, 64, 1, &e) == LM_OK);
    CHECK(src.batch(src.user, 3, B, r1, t1, &e) == LM_OK);
    CHECK(src.batch(src.user, 3, B, r2, t2, &e) == LM_OK);
    CHECK(!memcmp(r1, r2, sizeof(float) * B * n) && !memcmp(t1, t2, sizeof(float) * B * 33 * n));
    int differ = 0;
    for (int j = 0; j < B; j++) {
        double s = 0;
        for (int i = 0; i < n; i++) s += fabs(r1[j * n + i] - r0[j * n + i]);
        differ += s / n > 1e-4;
    }
    CHECK_MSG(differ >= B - 1, "only %d of %d moving samples differ from the still ones", differ,
              B);
    /* a share: about half moved over 64 samples */
    lm_train_source_motion_close(&src);
    lm_train_motion_opts half = {0.5f, 400.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 1, 1};
    CHECK(lm_train_source_motion_open(&src, d, &g_sys, &half, 66, 64, 1, &e) == LM_OK);
    int moved = 0;
    for (int k = 0; k < 16; k++) {
        CHECK(lm_dataset_batch(d, k, B, r0, t0, &e) == LM_OK);
        CHECK(src.batch(src.user, k, B, r1, t1, &e) == LM_OK);
        for (int j = 0; j < B; j++) moved += memcmp(t0 + (size_t)j * 33 * n, t1 + (size_t)j * 33 * n,
                                                    sizeof(float) * 33 * n) != 0;
    }
    CHECK_MSG(moved >= 20 && moved <= 44, "fraction 0.5: %d of 64 samples moved", moved);
    lm_train_source_motion_close(&src);
    lm_train_motion_opts bad = {1.5f, 1.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 1, 1};
    CHECK(lm_train_source_motion_open(&src, d, &g_sys, &bad, 66, 64, 1, &e) == LM_ERR_ARG);
    free(r0), free(t0), free(r1), free(t1), free(r2), free(t2);
    lm_dataset_close(d);
}

/* Frame f of a still multi-frame sample, simulated directly: the sample's window (patch +
 * margins, flips, border repeated) through lm_forward_simulate31 with frame f's noise stream;
 * out = the patch (ph x pw) of it. */
static void simulate_mf_frame(lm_dataset *d, long i, int f, uint64_t seed, float *out)
{
    const int ph = 66, pw = 64;
    int my, mx;
    lm_train_mf_margins(&g_sys, ph, pw, &my, &mx);
    CHECK(my == LM_TRAIN_MF_MARGIN_Y && mx == LM_TRAIN_MF_MARGIN_X);
    const int wh = ph + 2 * my, ww = pw + 2 * mx;
    lm_err e = {0};
    lm_dataset_sample_info in;
    CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &in, &e) == LM_OK);
    lm_cube sc, win;
    lm_cube_read_opts ro;
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    CHECK(lm_cube_read_with(lm_dataset_scene_path(d, LM_SPLIT_TRAIN, in.scene), &ro, &sc, &e) ==
          LM_OK);
    float mx_ = lm_cube_max(&sc);
    CHECK(lm_cube_alloc(&win, 31, wh, ww, 400.0f, 10.0f) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < wh; y++)
            for (int x = 0; x < ww; x++) {
                int sy = in.flip_v ? in.y0 + ph - 1 - (y - my) : in.y0 + y - my;
                int sx = in.flip_h ? in.x0 + pw - 1 - (x - mx) : in.x0 + x - mx;
                sy = sy < 0 ? 0 : sy >= sc.height ? sc.height - 1 : sy;
                sx = sx < 0 ? 0 : sx >= sc.width ? sc.width - 1 : sx;
                lm_cube_band(&win, b)[y * ww + x] = lm_cube_band(&sc, b)[sy * sc.width + sx] / mx_;
            }
    lm_forward_opts fo = {0};
    fo.noise.gauss_k = in.noise_k, fo.nthreads = 1;
    lm_rng r;
    lm_train_mf_noise_rng(seed, i, f, &r);
    float *b1 = malloc(sizeof(float) * wh * ww);
    CHECK_MSG(lm_forward_simulate31(&g_sys, &win, &fo, &r, b1, NULL, &e) == LM_OK, "%s", e.msg);
    for (int y = 0; y < ph; y++)
        memcpy(out + y * pw, b1 + (y + my) * ww + mx, sizeof(float) * pw);
    free(b1);
    lm_cube_free(&sc), lm_cube_free(&win);
}

static void test_multi_frame(void)
{
    lm_dataset *d = open_cave_noise(0.1f);
    if (!d) return;
    const int B = 2, n = 66 * 64;
    const uint64_t seed = 7;
    lm_err e = {0};
    lm_train_source src;
    float *r1 = malloc(sizeof(float) * B * 3 * n), *r2 = malloc(sizeof(float) * B * 3 * n);
    float *t1 = malloc(sizeof(float) * B * 33 * n), *t2 = malloc(sizeof(float) * B * 33 * n);
    float *sim = malloc(sizeof(float) * n);
    /* still, not aligned: the raw frames are three single-frame simulations */
    lm_train_motion_opts still = {0.0f, 0.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 3, 0};
    CHECK_MSG(lm_train_source_motion_open(&src, d, &g_sys, &still, 66, 64, seed, &e) == LM_OK,
              "%s", e.msg);
    CHECK_MSG(src.batch(src.user, 3, B, r1, t1, &e) == LM_OK, "%s", e.msg);
    const int fi[3] = {1, 0, 2}; /* plane q holds frame fi[q] */
    for (int j = 0; j < B; j++) {
        double worst = 0, differ = 0;
        for (int q = 0; q < 3; q++) {
            simulate_mf_frame(d, 3L * B + j, fi[q], seed, sim);
            const float *p = r1 + ((size_t)j * 3 + q) * n;
            for (int k = 0; k < n; k++) {
                worst = fmax(worst, fabs(p[k] - sim[k]));
                if (q) differ = fmax(differ, fabs(p[k] - r1[(size_t)j * 3 * n + k]));
            }
        }
        CHECK_MSG(worst < 1e-4, "item %d: still frames vs simulations: %g", j, worst);
        CHECK_MSG(differ > 1e-2, "item %d: frames share their noise (%g)", j, differ);
    }
    lm_train_source_motion_close(&src);
    /* aligned, moving: the same batch twice (also after another index) is the same */
    lm_train_motion_opts mv = {1.0f, 240.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 3, 1};
    CHECK(lm_train_source_motion_open(&src, d, &g_sys, &mv, 66, 64, seed, &e) == LM_OK);
    CHECK_MSG(src.batch(src.user, 5, B, r1, t1, &e) == LM_OK, "%s", e.msg);
    CHECK(src.batch(src.user, 6, B, r2, t2, &e) == LM_OK);
    CHECK(memcmp(r1, r2, sizeof(float) * B * 3 * n) != 0);
    CHECK(src.batch(src.user, 5, B, r2, t2, &e) == LM_OK);
    CHECK(memcmp(r1, r2, sizeof(float) * B * 3 * n) == 0);
    CHECK(memcmp(t1, t2, sizeof(float) * B * 33 * n) == 0);
    lm_train_source_motion_close(&src);
    lm_dataset_close(d);
    /* noise-free, fast: the aligned neighbours are closer to frame i than the raw ones */
    d = open_cave();
    lm_train_motion_opts fast = {1.0f, 480.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 3, 1};
    double dal = 0, draw = 0;
    for (int al = 0; al < 2 && d; al++) {
        fast.align = al;
        CHECK(lm_train_source_motion_open(&src, d, &g_sys, &fast, 66, 64, seed, &e) == LM_OK);
        CHECK_MSG(src.batch(src.user, 0, B, r1, t1, &e) == LM_OK, "%s", e.msg);
        double acc = 0;
        for (int j = 0; j < B; j++) /* interior: the patch's border sees the crop's edge */
            for (int q = 1; q < 3; q++)
                for (int y = 6; y < 60; y++)
                    for (int x = 8; x < 56; x++)
                        acc += fabs(r1[((size_t)j * 3 + q) * n + y * 64 + x] -
                                    r1[(size_t)j * 3 * n + y * 64 + x]);
        *(al ? &dal : &draw) = acc;
        lm_train_source_motion_close(&src);
    }
    CHECK_MSG(dal < 0.5 * draw, "aligned neighbours |diff| %g vs raw %g", dal, draw);
    lm_train_motion_opts bad = {0.0f, 0.0f, 0.0f, 2, 0, 0, 0.0f, 0.0f, 2, 1};
    CHECK(lm_train_source_motion_open(&src, d, &g_sys, &bad, 66, 64, seed, &e) == LM_ERR_ARG);
    free(r1), free(r2), free(t1), free(t2), free(sim);
    lm_dataset_close(d);
}

int main(void)
{
    lm_err e = {0};
    if (lm_system_default(&g_sys, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    RUN(test_render_matches_video_frame);
    RUN(test_source);
    RUN(test_multi_frame);
    lm_system_free(&g_sys);
    return check_summary();
}
