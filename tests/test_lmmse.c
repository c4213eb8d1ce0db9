/* test_lmmse.c — the closed-form linear floor (models/lmmse.c, train/fit_lmmse.c) and residual
 * models (lm_model_create_residual): the forward against a direct per-pixel double loop (with
 * the tile-reflected borders), noise-level interpolation, finite-difference gradients, the
 * fit's optimality on the very samples it was fitted on, and a residual that starts at its base;
 * the same for the two-bucket form ("-b2": a second K x K window on the bucket-0 plane) and the
 * panchromatic guide ("-gG-b2": bucket 1's share of the local panchromatic mean, read out);
 * the guided interpolation ("-riN-b2": each LED's plane by a guided filter on g, read out:
 * its features against a double-precision loop written from the definition);
 * the guide's fit is deterministic and beats a constant spectrum on held-out patches. */
#include "data/dataset.h"
#include "data/system.h"
#include "data/spectra.h"
#include "models/model.h"
#include "tests/check.h"
#include "tests/model_fixture.h"
#include "train/fit_lmmse.h"
#include "train/train.h"
#include "data/mosaic.h"
#include "infer/whole.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define O LM_MODEL_OUT_CHANNELS

/* Tile-resolution reflect (PyTorch 'reflect' on the phase planes) of a raw coordinate. */
static int reflect_raw(int v, int n, int t)
{
    int q = v >= 0 ? v / t : -((-v + t - 1) / t), ph = v - q * t, nt = n / t;
    if (q < 0) q = -q;
    if (q >= nt) q = 2 * (nt - 1) - q;
    return q * t + ph;
}

/* The panchromatic image at (Y, X), white = 1. */
static double ref_gs(const lm_model *m, const float *raw, int H, int W, int Y, int X)
{
    const int P = m->mosaic.ty * m->mosaic.tx;
    return (raw[Y * W + X] + (P - 1.0) * raw[(size_t)H * W + Y * W + X]) / P;
}

/* Guide feature d at (Y, X): g(Y, X) x bucket 1's share at the window position d (phases
 * reflected), the last one g(Y, X). */
static double ref_guide(const lm_model *m, const float *raw, int H, int W, int Y, int X, int d)
{
    const int G = lm_lmmse_guide(m), gr = G / 2, ty = m->mosaic.ty, tx = m->mosaic.tx;
    const int P = ty * tx;
    const double g = ref_gs(m, raw, H, W, Y, X);
    if (d == G * G) return g;
    const int sy = reflect_raw(Y + d / G - gr, H, ty), sx = reflect_raw(X + d % G - gr, W, tx);
    const double gi = ref_gs(m, raw, H, W, sy, sx);
    double rho = raw[sy * W + sx] / (gi > 0.01 ? gi : 0.01);
    rho = rho < -1 ? -1 : rho > P ? P : rho;
    return g * rho;
}

/* Guided-interpolation feature d at (Y, X), from the definition: on the frame padded by
 * whole tiles (phases reflected; where a frame is too small to reflect 2R, samples beyond it
 * are absent), for each window centre c within R of the pixel, LED d's samples s (bucket 1)
 * within R of c regressed on their g: a_c = cov(s, g) / (var(g) + 1e-4), b_c = mean s -
 * a_c mean g; the feature is mean_c(a_c) g(Y, X) + mean_c(b_c). The last feature is g. */
static double ref_gri(const lm_model *m, const float *raw, int H, int W, int Y, int X, int d)
{
    const int R = lm_lmmse_gri(m) / 2, ty = m->mosaic.ty, tx = m->mosaic.tx, P = ty * tx;
    const double g = ref_gs(m, raw, H, W, Y, X);
    if (d == P) return g;
    const int reflect = H / ty > (2 * R + ty - 1) / ty && W / tx > (2 * R + tx - 1) / tx;
    double sa = 0, sb = 0;
    for (int cy = Y - R; cy <= Y + R; cy++)
        for (int cx = X - R; cx <= X + R; cx++) {
            double n = 0, ss = 0, sg = 0, sgg = 0, ssg = 0;
            for (int qy = cy - R; qy <= cy + R; qy++)
                for (int qx = cx - R; qx <= cx + R; qx++) {
                    if (((qy % ty + ty) % ty) * tx + (qx % tx + tx) % tx != d) continue;
                    const int in = qy >= 0 && qy < H && qx >= 0 && qx < W;
                    if (!in && !reflect) continue;
                    const int sy = reflect_raw(qy, H, ty), sx = reflect_raw(qx, W, tx);
                    const double sv = raw[sy * W + sx], gv = ref_gs(m, raw, H, W, sy, sx);
                    n += 1, ss += sv, sg += gv, sgg += gv * gv, ssg += sv * gv;
                }
            if (n == 0) continue; /* a = b = 0 */
            const double ms = ss / n, mg = sg / n, vg = sgg / n - mg * mg;
            const double a = (ssg / n - ms * mg) / ((vg > 0 ? vg : 0) + 1e-4);
            sa += a, sb += ms - a * mg;
        }
    return (sa * g + sb) / ((2.0 * R + 1) * (2.0 * R + 1));
}

/* Pixels the guided interpolation's reference is checked at (it is slow): every other pixel of
 * the two outer rows and columns, and a scatter inside. */
static int gri_chosen(int H, int W, int Y, int X)
{
    if (Y < 2 || Y >= H - 2 || X < 2 || X >= W - 2) return (Y + X) % 2 == 0;
    return (Y * 7 + X * 3) % 17 == 0;
}

/* y[c] at (Y, X) for level weights (level l, blend t with l + 1), in double. */
static double ref_pixel(const lm_model *m, const float *raw, int H, int W, int Y, int X, int c,
                        int l, double t)
{
    const lm_param *wp = lm_params_find(&m->params, "filters.weight");
    const lm_param *bp = lm_params_find(&m->params, "filters.bias");
    const int K = lm_lmmse_window(m), r = K / 2, ty = m->mosaic.ty, tx = m->mosaic.tx;
    const int P = ty * tx, p = (Y % ty) * tx + X % tx;
    const int D = lm_lmmse_features(m), G = lm_lmmse_guide(m);
    const int host = G || lm_lmmse_gri(m);
    const lm_param *fw = D && !host ? lm_params_find(&m->params, "features.weight") : NULL;
    const lm_param *fb = D && !host ? lm_params_find(&m->params, "features.bias") : NULL;
    const lm_param *rw = D ? lm_params_find(&m->params, "readout.weight") : NULL;
    /* two buckets: plane 1 (bucket 0) through its own filters */
    const lm_param *w0p = lm_params_find(&m->params, "filters.bucket0");
    const float *raw0 = raw + (size_t)H * W;
    double acc = 0;
    for (int lv = l; lv <= l + 1; lv++) {
        double a = lv == l ? 1 - t : t;
        if (a == 0) continue;
        const float *w = wp->t.data + (((size_t)lv * P + p) * O + c) * K * K;
        double s = bp->t.data[((size_t)lv * P + p) * O + c];
        for (int u = 0; u < K; u++)
            for (int v = 0; v < K; v++)
                s += w[u * K + v] * raw[reflect_raw(Y - r + u, H, ty) * W + reflect_raw(X - r + v, W, tx)];
        const float *w0 = w0p ? w0p->t.data + (((size_t)lv * P + p) * O + c) * K * K : NULL;
        for (int u = 0; w0 && u < K; u++)
            for (int v = 0; v < K; v++)
                s += w0[u * K + v] *
                     raw0[reflect_raw(Y - r + u, H, ty) * W + reflect_raw(X - r + v, W, tx)];
        for (int d = 0; d < D; d++) { /* random or guide feature d at (Y, X), read out */
            if (lm_lmmse_gri(m)) {
                s += ref_gri(m, raw, H, W, Y, X, d) *
                     rw->t.data[(((size_t)lv * P + p) * O + c) * D + d];
                continue;
            }
            if (G) {
                s += ref_guide(m, raw, H, W, Y, X, d) *
                     rw->t.data[(((size_t)lv * P + p) * O + c) * D + d];
                continue;
            }
            double h = fb->t.data[d];
            for (int u = 0; u < K; u++)
                for (int v = 0; v < K; v++)
                    h += fw->t.data[((size_t)d * K + u) * K + v] *
                         raw[reflect_raw(Y - r + u, H, ty) * W + reflect_raw(X - r + v, W, tx)];
            s += (h > 0 ? h : 0) * rw->t.data[(((size_t)lv * P + p) * O + c) * D + d];
        }
        acc += a * s;
    }
    return acc;
}

/* grad 1: the tile-unit conv gradients flow through; 0: the direct no-gradient path */
static const float *g_levels; /* non-NULL: the levels check_forward_mode gives its model */

static void check_forward_mode(const char *preset, int H, int W, float sigma, int l, double t,
                               int grad)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 3, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    if (g_levels) CHECK_MSG(lm_lmmse_set_levels(m, g_levels, &e) == LM_OK, "%s", e.msg);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 4);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, m->in_channels, H, W}, &r, 0.0f, 1.0f);
    m->noise_sigma = sigma;
    lm_ctx_set_grad(&c, grad);
    lm_tensor *y = lm_model_forward(&c, m, x);
    CHECK_MSG(y && y->shape[1] == O && y->shape[2] == H && y->shape[3] == W, "%s", c.msg);
    double worst = 0;
    for (int ch = 0; y && ch < O; ch += 4)
        for (int Y = 0; Y < H; Y++)
            for (int X = 0; X < W; X++) {
                if (lm_lmmse_gri(m) && !gri_chosen(H, W, Y, X)) continue;
                double d = fabs(ref_pixel(m, x->data, H, W, Y, X, ch, l, t) -
                                y->data[((size_t)ch * H + Y) * W + X]);
                worst = d > worst ? d : worst;
            }
    CHECK_MSG(worst < 2e-5, "%s sigma %g grad %d: forward differs from the direct loop by %g",
              preset, sigma, grad, worst);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void check_forward(const char *preset, int H, int W, float sigma, int l, double t)
{
    check_forward_mode(preset, H, W, sigma, l, t, 1);
    check_forward_mode(preset, H, W, sigma, l, t, 0);
}

/* The direct path (no gradients) against the tile-unit conv on a batch whose items have their
 * own noise levels, on frames large enough to reflect and too small (zero padding). */
static void test_direct_matches_tile_path(void)
{
    const int sizes[3][2] = {{24, 32}, {6, 8}, {30, 20}};
    for (int k = 0; k < 6; k++) { /* one bucket, then both (the direct path over two planes) */
        const int H = sizes[k % 3][0], W = sizes[k % 3][1];
        lm_err e = {0};
        lm_model *m = lm_model_create(k < 3 ? "lmmse" : "lmmse-b2", NULL, 11, &e);
        CHECK_MSG(m != NULL, "%s", e.msg);
        if (!m) return;
        lm_ctx c;
        lm_ctx_init(&c, 2);
        lm_rng r;
        lm_rng_seed(&r, 7 + k);
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){3, m->in_channels, H, W}, &r, 0.0f, 1.0f);
        const float sig[3] = {0.0f, 0.04f, 0.04f};
        m->noise_sigma_items = sig;
        lm_tensor *yt = lm_contiguous(&c, lm_model_forward(&c, m, x));
        lm_ctx_set_grad(&c, 0);
        lm_tensor *yd = lm_model_forward(&c, m, x);
        CHECK_MSG(yt && yd, "%s", c.msg);
        if (yt && yd) CHECK_ARRAY_CLOSE(yd->data, yt->data, lm_tensor_numel(yt), 1e-5, 1e-5);
        lm_ctx_free(&c);
        lm_model_free(m);
    }
}

/* The whole-frame host path (frame_forward, through lm_whole_forward: channel ranges of up to
 * 32 in 16-lane vectors, 33 in 8-lane ones; rows whose phase count is not a multiple of the
 * pixel block) against the tile-unit conv, at the noise level lm_whole_forward estimated. */
static void test_whole_frame_path(void)
{
    const int sizes[4][2] = {{24, 32}, {6, 8}, {30, 20}, {48, 100}};
    const int ranges[3][2] = {{1, 31}, {0, 33}, {5, 7}};
    for (int k = 0; k < 4; k++)
        for (int q = 0; q < 3; q++) {
            const int H = sizes[k][0], W = sizes[k][1], ch0 = ranges[q][0], nch = ranges[q][1];
            lm_err e = {0};
            lm_model *m = lm_model_create("lmmse", NULL, 11, &e);
            CHECK_MSG(m && m->frame_forward, "%s", e.msg);
            if (!m) return;
            lm_ctx c;
            lm_ctx_init(&c, 2);
            lm_rng r;
            lm_rng_seed(&r, 17 + k);
            lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, 1, H, W}, &r, 0.0f, 1.0f);
            float *out = calloc((size_t)nch * H * W, sizeof *out);
            m->noise_given = k == 3 ? -1.0f : 0.03f; /* estimated on the largest frame */
            lm_status st = lm_whole_forward(&c, m, x->data, H, W, NULL, ch0, nch, out, &e);
            CHECK_MSG(st == LM_OK, "%s", e.msg);
            lm_ctx_set_grad(&c, 1); /* the tile-unit conv, at the level the whole path used */
            lm_tensor *yt = lm_contiguous(&c, lm_model_forward(&c, m, x));
            CHECK_MSG(yt != NULL, "%s", c.msg);
            if (yt && !st)
                CHECK_ARRAY_CLOSE(out, yt->data + (size_t)ch0 * H * W, (long)nch * H * W, 1e-5,
                                  1e-5);
            free(out);
            lm_ctx_free(&c);
            lm_model_free(m);
        }
}

static void test_forward_matches_direct_loop(void)
{
    check_forward("lmmse", 18, 24, 0.0f, 0, 0.0);           /* K 11, 6 x 6 tiles */
    check_forward("lmmse-5", 12, 16, 0.0f, 0, 0.0);
    check_forward("lmmse-3", 9, 12, lm_lmmse_sigmas[3], 3, 0.0);
    /* halfway between two levels: the filters blend linearly */
    float s = 0.5f * (lm_lmmse_sigmas[4] + lm_lmmse_sigmas[5]);
    check_forward("lmmse-5", 12, 16, s, 4, 0.5);
    check_forward("lmmse-3", 9, 12, 10.0f, LM_LMMSE_LEVELS - 2, 1.0); /* clamped at the top */
    check_forward("lmmse-5-rf6", 12, 16, 0.0f, 0, 0.0);               /* random features */
    check_forward("lmmse-3-rf4", 9, 12, s, 4, 0.5);
    /* both buckets: the bucket-0 window adds its own filters */
    check_forward("lmmse-b2", 18, 24, 0.0f, 0, 0.0);
    check_forward("lmmse-5-b2", 12, 16, s, 4, 0.5);
    check_forward("lmmse-3-b2", 6, 8, lm_lmmse_sigmas[3], 3, 0.0); /* zero-padded borders */
    /* the panchromatic guide: its features read out beside both buckets' windows */
    check_forward("lmmse-5-g3-b2", 12, 16, 0.0f, 0, 0.0);
    check_forward("lmmse-7-g5-b2", 18, 24, s, 4, 0.5);
    /* the guided interpolation: each LED's plane and g read out beside both buckets' windows
     * (reflected borders; and a frame too small to reflect the windows' reach) */
    check_forward("lmmse-5-ri7-b2", 18, 24, 0.0f, 0, 0.0);
    check_forward("lmmse-3-ri11-b2", 24, 32, s, 4, 0.5);
    check_forward("lmmse-3-ri11-b2", 12, 16, lm_lmmse_sigmas[3], 3, 0.0);
}

/* Guide preset names: odd windows of at most K, both buckets only; no OpenCL (host
 * features); D = G^2 + 1 readout features, no random-feature conv. */
static void test_guide_presets(void)
{
    lm_err e = {0};
    const char *bad[] = {"lmmse-5-g7-b2", "lmmse-5-g2-b2", "lmmse-5-g3", "lmmse-5-g0-b2",
                         "lmmse-5-gx-b2"};
    for (int i = 0; i < 5; i++) {
        CHECK_MSG(!lm_model_preset_known(bad[i]), "%s", bad[i]);
        lm_model *m = lm_model_create(bad[i], NULL, 1, &e);
        CHECK_MSG(m == NULL && e.status == LM_ERR_ARG, "%s", bad[i]);
        lm_model_free(m);
    }
    const char *good[] = {"lmmse-guide-b2", "lmmse-5-g3-b2"};
    const int G[2] = {7, 3};
    for (int i = 0; i < 2; i++) {
        lm_model *m = lm_model_create(good[i], NULL, 1, &e);
        CHECK_MSG(m != NULL, "%s: %s", good[i], e.msg);
        if (!m) continue;
        CHECK(lm_lmmse_guide(m) == G[i] && lm_lmmse_features(m) == G[i] * G[i] + 1);
        CHECK(lm_model_buckets(m) == 2 && m->in_channels == 2 && m->noise_input);
        CHECK(lm_model_has(m, LM_CAP_CLOSED_FORM) && lm_model_has(m, LM_CAP_OPENCL));
        CHECK(lm_params_find(&m->params, "features.weight") == NULL &&
              lm_params_find(&m->params, "readout.weight") != NULL);
        lm_model_free(m);
    }
    CHECK(strlen(lm_model_preset_purpose("lmmse-guide-b2")) > 0);
}

/* Guided-interpolation names: "lmmse-gri-b2" (K 11, N 15) and "lmmse-K-riN-b2" with odd N in
 * 3..31, both buckets only; a bad window is refused with its reason. D = P + 1; OpenCL
 * through the host (the frames read back, the maps written to the device). */
static void test_gri_presets(void)
{
    const char *bad[] = {"lmmse-5-ri12-b2", "lmmse-5-ri33-b2", "lmmse-5-ri1-b2", "lmmse-5-ri7",
                         "lmmse-5-rix-b2", "lmmse-4-ri7-b2", "lmmse-5-ri7-b3"};
    const int odd[7] = {1, 1, 1, 0, 0, 1, 0}; /* refused with the window's reason */
    for (int i = 0; i < 7; i++) {
        lm_err e = {0};
        CHECK_MSG(!lm_model_preset_known(bad[i]), "%s", bad[i]);
        lm_model *m = lm_model_create(bad[i], NULL, 1, &e);
        CHECK_MSG(m == NULL && e.status == LM_ERR_ARG && !strchr(e.msg, '\n'), "%s", bad[i]);
        CHECK_MSG(!odd[i] || (strstr(e.msg, "must be odd") && lm_model_preset_why(bad[i])),
                  "%s: %s", bad[i], e.msg);
        lm_model_free(m);
    }
    const char *good[] = {"lmmse-gri-b2", "lmmse-5-ri7-b2", "lmmse-3-ri31-b2"};
    const int N[3] = {15, 7, 31}, K[3] = {11, 5, 3};
    for (int i = 0; i < 3; i++) {
        lm_err e = {0};
        lm_model *m = lm_model_create(good[i], NULL, 1, &e);
        CHECK_MSG(m != NULL && lm_model_preset_why(good[i]) == NULL, "%s: %s", good[i], e.msg);
        if (!m) continue;
        CHECK(lm_lmmse_gri(m) == N[i] && lm_lmmse_window(m) == K[i] && !lm_lmmse_guide(m) &&
              lm_lmmse_features(m) == 13);
        CHECK(lm_model_buckets(m) == 2 && m->in_channels == 2 && m->noise_input);
        CHECK(lm_model_has(m, LM_CAP_CLOSED_FORM) && lm_model_has(m, LM_CAP_OPENCL));
        CHECK(lm_params_find(&m->params, "features.weight") == NULL &&
              lm_params_find(&m->params, "readout.weight") != NULL);
        CHECK(m->conv_rows >= 2 * (N[i] / 2)); /* strips keep the windows of windows */
        lm_model_free(m);
    }
    CHECK(strlen(lm_model_preset_purpose("lmmse-gri-b2")) > 0);
}

/* The model's feature maps (lm_lmmse_feature_maps) against the definition at chosen pixels,
 * borders included, on random frames (reflected, and too small to reflect); and on a frame
 * where each LED's response is a constant times g (c_l g), the features give c_l g at every
 * pixel: the regressions are exact but for the slope's regularisation (a wrong phase would be
 * off by 0.1 g, 0.02 at least). */
static void test_gri_features(void)
{
    const int sizes[3][2] = {{24, 32}, {12, 16}, {27, 28}};
    const char *names[3] = {"lmmse-5-ri11-b2", "lmmse-3-ri11-b2", "lmmse-5-ri7-b2"};
    for (int k = 0; k < 4; k++) {
        const int H = sizes[k % 3][0], W = sizes[k % 3][1];
        lm_err e = {0};
        lm_model *m = lm_model_create(names[k % 3], NULL, 3, &e);
        CHECK_MSG(m != NULL, "%s", e.msg);
        if (!m) return;
        const int P = 12, D = lm_lmmse_features(m);
        lm_ctx c;
        lm_ctx_init(&c, 1);
        lm_rng r;
        lm_rng_seed(&r, 21 + k);
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 2, H, W}, &r, 0.0f, 1.0f);
        if (k == 3) /* bucket 1 = c_l g, bucket 0 what makes g the panchromatic image */
            for (int b = 0; b < 2; b++)
                for (int Y = 0; Y < H; Y++)
                    for (int X = 0; X < W; X++) {
                        float *b1 = x->data + (size_t)b * 2 * H * W + Y * W + X;
                        const float g = 0.2f + 0.8f * b1[(size_t)H * W];
                        const float cl = 0.3f + 0.1f * (float)((Y % 3) * 4 + X % 4);
                        b1[0] = cl * g;
                        b1[(size_t)H * W] = (P * g - b1[0]) / (P - 1);
                    }
        lm_tensor *h = lm_lmmse_feature_maps(&c, m, x);
        CHECK_MSG(h && h->shape[0] == 2 && h->shape[1] == D && h->shape[2] == H &&
                  h->shape[3] == W, "%s", c.msg);
        double worst = 0, worst_prop = 0, sum_prop = 0;
        long n = 0, n_prop = 0;
        for (int b = 0; h && b < 2; b++)
            for (int Y = 0; Y < H; Y++)
                for (int X = 0; X < W; X++) {
                    const float *raw = x->data + (size_t)b * 2 * H * W;
                    const double g = ref_gs(m, raw, H, W, Y, X);
                    for (int d = 0; d < D; d++) {
                        const double v = h->data[(((size_t)b * D + d) * H + Y) * W + X];
                        if (k == 3 && d < P) { /* LED d's plane: c_d g */
                            const double want = (0.3 + 0.1 * d) * g;
                            double err = fabs(v - want);
                            worst_prop = err > worst_prop ? err : worst_prop;
                            sum_prop += err, n_prop++;
                        }
                        if (!gri_chosen(H, W, Y, X) || (b && d % 3)) continue;
                        const double want = ref_gri(m, raw, H, W, Y, X, d);
                        double err = fabs(v - want) / (1 + fabs(want));
                        worst = err > worst ? err : worst;
                        n++;
                    }
                }
        CHECK_MSG(n > 100 && worst < 1e-5, "%s %dx%d: features differ from the definition by "
                  "%g (%ld checked)", names[k % 3], H, W, worst, n);
        if (k == 3) /* the slope's regularisation: ~0.1 % off on average, 1 % at worst */
            CHECK_MSG(worst_prop < 1.5e-2 && sum_prop < 1.5e-3 * n_prop, "c_l g world: features "
                      "off by %g at worst, %g on average", worst_prop, sum_prop / n_prop);
        lm_ctx_free(&c);
        lm_model_free(m);
    }
}

/* Whole frames in strips (lm_whole_forward, the halo from conv_rows) equal one forward over
 * the frame: the windows of windows reach 2R rows, beyond K's; a halo short of that differs. */
static void test_gri_strips(void)
{
    const int H = 60, W = 64;
    lm_err e = {0};
    lm_model *m = lm_model_create("lmmse-3-ri11-b2", NULL, 5, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 31);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, 2, H, W}, &r, 0.0f, 1.0f);
    float *frame = malloc(sizeof(float) * 2 * H * W), *one = malloc(sizeof(float) * O * H * W);
    float *strips = malloc(sizeof(float) * O * H * W);
    memcpy(frame, x->data, sizeof(float) * 2 * H * W);
    float mx = 0.0f; /* the whole path's level: noise_given x the frame's maximum */
    for (int k = 0; k < H * W; k++) mx = frame[k] > mx ? frame[k] : mx;
    m->noise_given = 0.01f;
    m->noise_sigma = 0.01f * mx;
    lm_ctx_set_grad(&c, 0);
    lm_tensor *y = lm_model_forward(&c, m, x);
    CHECK_MSG(y != NULL, "%s", c.msg);
    if (y) memcpy(one, y->data, sizeof(float) * O * H * W);
    lm_ctx_reset(&c);
    lm_whole_opts o;
    lm_whole_default_opts(&o);
    o.strip_rows = 12;
    CHECK_MSG(lm_whole_forward(&c, m, frame, H, W, &o, 0, O, strips, &e) == LM_OK, "%s", e.msg);
    CHECK_ARRAY_CLOSE(strips, one, (long)O * H * W, 1e-5, 1e-5);
    o.halo = 6; /* two tile rows: short of the 10 rows the windows of windows read */
    CHECK_MSG(lm_whole_forward(&c, m, frame, H, W, &o, 0, O, strips, &e) == LM_OK, "%s", e.msg);
    double worst = 0;
    for (long k = 0; k < (long)O * H * W; k++)
        worst = fabs(strips[k] - one[k]) > worst ? fabs(strips[k] - one[k]) : worst;
    CHECK_MSG(worst > 1e-4, "a short halo changed nothing (%g)", worst);
    free(frame), free(one), free(strips);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_counts_and_capabilities(void)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("lmmse", NULL, 1, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    CHECK(lm_params_count(&m->params, 0) == (long)LM_LMMSE_LEVELS * 12 * (11 * 11 + 1) * 33);
    CHECK(lm_lmmse_window(m) == 11 && m->noise_input && m->conv_rows == 6);
    lm_model_free(m);
    CHECK(lm_model_create("lmmse-4", NULL, 1, &e) == NULL && e.status == LM_ERR_ARG);
    CHECK(lm_model_preset_known("lmmse-7") && !lm_model_preset_known("lmmse-x"));
    /* two buckets: a second filter bank of the same size, in_channels 2, no host paths */
    m = lm_model_create("lmmse-b2", NULL, 1, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (m) {
        CHECK(lm_params_count(&m->params, 0) ==
              (long)LM_LMMSE_LEVELS * 12 * (2 * 11 * 11 + 1) * 33);
        CHECK(m->in_channels == 2 && lm_model_buckets(m) == 2 && !m->frame_forward &&
              lm_model_has(m, LM_CAP_CLOSED_FORM | LM_CAP_TWO_BUCKETS));
    }
    lm_model_free(m);
    CHECK(lm_model_preset_known("lmmse-7-b2") && !lm_model_preset_known("lmmse-7-b3") &&
          !lm_model_preset_known("lmmse-4-b2") && !lm_model_preset_known("lmmse-7-rf4-b2"));
    /* one-bucket input to a two-bucket model (and back): a one-line shape error */
    lm_ctx c1;
    lm_ctx_init(&c1, 1);
    m = lm_model_create("lmmse-3-b2", NULL, 1, &e);
    if (m) m->noise_sigma = 0.0f;
    lm_tensor *x1 = lm_tensor_zeros(&c1, 4, (int[]){1, 1, 6, 8});
    CHECK(m && lm_model_forward(&c1, m, x1) == NULL && strstr(c1.msg, "B x 2 x H x W") &&
          !strchr(c1.msg, '\n'));
    lm_model_free(m);
    lm_ctx_free(&c1);
    /* no noise level set: a clear error, not the clean filter */
    m = lm_model_create("lmmse-3", NULL, 1, &e);
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 1, 6, 8});
    CHECK(m && lm_model_forward(&c, m, x) == NULL && strstr(c.msg, "noise level"));
    lm_ctx_free(&c);
    lm_model_free(m);
}

typedef struct gc_user { lm_model *m; } gc_user;
static lm_tensor *model_fn(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    return lm_model_forward(c, ((gc_user *)u)->m, in[0]);
}

/* kinks: the model has ReLUs (random features), so a central difference may straddle a kink
 * somewhere in the summed output and show the mean of two slopes: at most 10 % of the
 * elements may miss (as test_models allows); else all must pass. */
static void gradcheck(lm_model *m, const float *sig, int kinks)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 2);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){3, m->in_channels, 9, 12}, &r, 0.1f, 1.0f);
    lm_tensor_set_requires_grad(x, 1);
    m->noise_sigma_items = sig;
    int np = m->params.n;
    lm_tensor *in[8];
    in[0] = x;
    for (int i = 0; i < np && i < 7; i++) in[i + 1] = &m->params.items[i]->t;
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.max_checks = 40;
    o.atol = 2e-3;
    o.rtol = 2e-2;
    gc_user u = {m};
    if (!kinks) {
        CHECK_GRAD(&c, model_fn, in, (np < 7 ? np : 7) + 1, &u, &o);
    } else {
        lm_gradcheck_result res;
        lm_status st = lm_gradcheck(&c, model_fn, in, (np < 7 ? np : 7) + 1, &u, &o, &res);
        CHECK_MSG((st == LM_OK || st == LM_ERR_NUMERIC) && res.checked > 100 &&
                  res.failed * 10 <= res.checked, "%ld of %ld gradient elements off (%s)",
                  res.failed, res.checked, c.msg);
        lm_ctx_clear_error(&c);
    }
    lm_ctx_free(&c);
}

static void test_gradients(void)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("lmmse-5", NULL, 7, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    /* three items, two of them sharing a level, one between levels */
    const float sig[3] = {0.0f, 0.0f, 0.5f * (lm_lmmse_sigmas[2] + lm_lmmse_sigmas[3])};
    gradcheck(m, sig, 0);
    lm_model_free(m);
    /* a residual net (linear) on an lmmse base, the base trainable, gates non-zero */
    m = lm_model_create("lmmse-3-rf4", NULL, 7, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (m) gradcheck(m, sig, 1);
    lm_model_free(m);
    lm_model *rm = lm_model_create_residual("linear", "lmmse-3", NULL, 7, 1, 0.5f, &e);
    CHECK_MSG(rm != NULL, "%s", e.msg);
    if (rm) gradcheck(rm, sig, 0);
    lm_model_free(rm);
    /* both buckets: the input's two planes and both filter banks (and the bias) */
    m = lm_model_create("lmmse-5-b2", NULL, 7, &e);
    CHECK_MSG(m && m->in_channels == 2 && lm_params_find(&m->params, "filters.bucket0"), "%s",
              e.msg);
    if (m) gradcheck(m, sig, 0);
    lm_model_free(m);
    /* an rt-8-b2 residual on a trainable lmmse-3-b2 (rt has ReLUs: kinks allowed) */
    rm = lm_model_create_residual("rt-8-b2", "lmmse-3-b2", NULL, 7, 1, 0.5f, &e);
    CHECK_MSG(rm != NULL, "%s", e.msg);
    if (rm) gradcheck(rm, sig, 1);
    lm_model_free(rm);
    /* an rt-8-mf3 residual on a trainable one-frame lmmse-3 (the base reads plane 0) */
    rm = lm_model_create_residual("rt-8-mf3", "lmmse-3", NULL, 7, 1, 0.5f, &e);
    CHECK_MSG(rm && rm->in_channels == 3 && lm_model_frames(rm) == 3, "%s", e.msg);
    if (rm) gradcheck(rm, sig, 1);
    lm_model_free(rm);
}

/* A residual starts as its base exactly (the net's output layer is zero); the base's parameters
 * are frozen, named base.* */
static void test_residual_starts_at_base(void)
{
    lm_err e = {0};
    lm_model *rm = lm_model_create_residual("rt-8", "lmmse-5", NULL, 3, 0, 1.0f, &e);
    lm_model *b = lm_model_create("lmmse-5", NULL, 9, &e);
    CHECK_MSG(rm && b, "%s", e.msg);
    if (!rm || !b) return lm_model_free(rm), lm_model_free(b);
    const lm_param *bw = lm_params_find(&rm->params, "base.filters.weight");
    CHECK(bw && !bw->trainable && lm_params_find(&rm->params, "res_scale"));
    CHECK(rm->noise_input && rm->conv_rows == 3); /* lmmse-5 reaches one tile row */
    /* same base weights in both */
    for (int i = 0; i < b->params.n; i++) {
        char nm[LM_PARAM_NAME_MAX + 8];
        snprintf(nm, sizeof nm, "base.%s", b->params.items[i]->name);
        lm_param *dst = lm_params_find(&rm->params, nm);
        CHECK(dst != NULL);
        if (dst) memcpy(dst->t.data, b->params.items[i]->t.data,
                        sizeof(float) * lm_tensor_numel(&dst->t));
    }
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 5);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 1, 12, 16}, &r, 0.0f, 1.0f);
    rm->noise_sigma = b->noise_sigma = 0.02f;
    lm_ctx_set_grad(&c, 0); /* one path for both (the frozen base and b) */
    lm_tensor *y1 = lm_model_forward(&c, rm, x), *y2 = lm_model_forward(&c, b, x);
    CHECK_MSG(y1 && y2, "%s", c.msg);
    if (y1 && y2) CHECK_ARRAY_CLOSE(y1->data, y2->data, lm_tensor_numel(y2), 0.0, 0.0);
    lm_ctx_free(&c);
    lm_model_free(rm);
    lm_model_free(b);
    /* a multi-frame net on a one-frame base starts at the base applied to plane 0 (frame i) */
    rm = lm_model_create_residual("rt-8-mf3", "lmmse-5", NULL, 3, 0, 1.0f, &e);
    b = lm_model_create("lmmse-5", NULL, 9, &e);
    CHECK_MSG(rm && b, "%s", e.msg);
    if (!rm || !b) return lm_model_free(rm), lm_model_free(b);
    for (int i = 0; i < b->params.n; i++) {
        char nm[LM_PARAM_NAME_MAX + 8];
        snprintf(nm, sizeof nm, "base.%s", b->params.items[i]->name);
        lm_param *dst = lm_params_find(&rm->params, nm);
        if (dst) memcpy(dst->t.data, b->params.items[i]->t.data,
                        sizeof(float) * lm_tensor_numel(&dst->t));
    }
    lm_ctx_init(&c, 2);
    lm_rng_seed(&r, 5);
    lm_tensor *x3 = lm_tensor_uniform(&c, 4, (int[]){2, 3, 12, 16}, &r, 0.0f, 1.0f);
    lm_tensor *x1 = lm_tensor_zeros(&c, 4, (int[]){2, 1, 12, 16});
    for (int k = 0; k < 2; k++) /* plane 0 of each item */
        memcpy(x1->data + k * 192, x3->data + k * 3 * 192, sizeof(float) * 192);
    rm->noise_sigma = b->noise_sigma = 0.02f;
    lm_ctx_set_grad(&c, 0);
    lm_tensor *z1 = lm_model_forward(&c, rm, x3), *z2 = lm_model_forward(&c, b, x1);
    CHECK_MSG(z1 && z2, "%s", c.msg);
    if (z1 && z2) CHECK_ARRAY_CLOSE(z1->data, z2->data, lm_tensor_numel(z2), 0.0, 0.0);
    lm_ctx_free(&c);
    lm_model_free(rm);
    lm_model_free(b);
}

/* The fit minimises the squared error on the patches it saw: on those interior pixels the
 * fitted model beats the same model with any one filter coefficient nudged. */
static void fit_least_squares(const char *preset)
{
    char sysp[1024], cave[1024];
    lm_err e = {0};
    const char *sh = getenv("LM_SHARED_DIR");
    snprintf(cave, sizeof cave, "%s/data/cave", sh ? sh : "../shared");
    lm_system sys;
    CHECK_MSG(lm_data_path("systems/default.json", sysp, sizeof sysp, &e) == LM_OK &&
              lm_system_load(sysp, &sys, &e) == LM_OK, "%s", e.msg);
    lm_mosaic mo;
    CHECK(lm_mosaic_from_system(&sys, &mo, &e) == LM_OK);
    lm_model *m = lm_model_create(preset, &mo, 1, &e);
    const char *paths[1] = {cave};
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths, dc.npaths = 1, dc.sys = &sys, dc.workers = 0;
    dc.patch_h = 24, dc.patch_w = 32, dc.noise_min = dc.noise_max = 0.0f;
    const int C = m && lm_model_buckets(m) == 2 ? 2 : 1;
    dc.buckets = C;
    lm_dataset *d = lm_dataset_open(&dc, &e);
    CHECK_MSG(m && d, "%s", e.msg);
    lm_lmmse_fit_report rep;
    const int NP = 48, B = 16;
    CHECK_MSG(lm_lmmse_fit(m, d, 24, 32, NP, B, -1.0, NULL, &rep, &e) == LM_OK, "%s", e.msg);
    CHECK(rep.patches == NP && rep.rows == (long)NP * (24 - 4) * (32 - 4));
    /* no validation split: the statistics mix real and synthetic patches as sampled */
    int nsyn = 0;
    for (long i = 0; i < NP; i++) {
        lm_dataset_sample_info in;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &in, &e) == LM_OK);
        nsyn += in.kind != LM_SAMPLE_SCENE;
    }
    CHECK_MSG(nsyn > 0 && nsyn < NP && fabs(rep.synth_weight[0] - (double)nsyn / NP) < 1e-12,
              "%s: synthetic share %g, sampled %d of %d", preset, rep.synth_weight[0], nsyn, NP);
    /* ridge without validation is the small default: nudging must not help, clean level */
    float *raw = malloc(sizeof(float) * NP * C * 24 * 32), *tgt = malloc(sizeof(float) * NP * O * 24 * 32);
    for (int k = 0; k < NP / B; k++)
        CHECK(lm_dataset_batch(d, k, B, raw + (size_t)k * B * C * 24 * 32,
                               tgt + (size_t)k * B * O * 24 * 32, &e) == LM_OK);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    m->noise_sigma = 0.0f;
    double base = 0, nudged[4] = {0, 0, 0, 0};
    /* phase 1, channel 5, centre tap of bucket 1's filter; with two buckets also bucket 0's
     * (phase 2, channel 9, a tap off centre) */
    lm_param *w1 = lm_params_find(&m->params, "filters.weight");
    lm_param *w0 = lm_params_find(&m->params, "filters.bucket0");
    CHECK((C == 2) == (w0 != NULL));
    for (int pass = 0; pass < (C == 2 ? 5 : 3); pass++) {
        lm_param *w = pass < 3 ? w1 : w0;
        const size_t coef = pass < 3 ? (size_t)(1 * O + 5) * 25 + 12 : (size_t)(2 * O + 9) * 25 + 7;
        float keep = w->t.data[coef];
        if (pass) w->t.data[coef] = keep * (pass % 2 ? 1.02f : 0.98f) + (pass % 2 ? 1e-3f : -1e-3f);
        double sse = 0;
        lm_ctx_reset(&c);
        lm_tensor *x = lm_tensor_from(&c, 4, (int[]){NP, C, 24, 32}, raw);
        lm_tensor *y = lm_model_forward(&c, m, x);
        for (int b = 0; y && b < NP; b++)
            for (int ch = 0; ch < O; ch++)
                for (int Y = 2; Y < 22; Y++)
                    for (int X = 2; X < 30; X++) {
                        size_t i = (((size_t)b * O + ch) * 24 + Y) * 32 + X;
                        double dd = (double)y->data[i] - tgt[i];
                        sse += dd * dd;
                    }
        if (pass) nudged[pass - 1] = sse;
        else base = sse;
        w->t.data[coef] = keep;
    }
    CHECK_MSG(base > 0 && base < nudged[0] && base < nudged[1], "%s: fit SSE %.9g, nudged %.9g / "
              "%.9g", preset, base, nudged[0], nudged[1]);
    if (C == 2)
        CHECK_MSG(base < nudged[2] && base < nudged[3], "%s: fit SSE %.9g, bucket-0 filter "
                  "nudged %.9g / %.9g", preset, base, nudged[2], nudged[3]);
    free(raw), free(tgt);
    lm_ctx_free(&c);
    lm_dataset_close(d);
    lm_model_free(m);
    lm_system_free(&sys);
}

static void test_fit_is_least_squares(void)
{
    fit_least_squares("lmmse-5");
    fit_least_squares("lmmse-5-rf6"); /* random features: the readout is still least squares */
    fit_least_squares("lmmse-5-b2");  /* both buckets: two windows per pixel */
    fit_least_squares("lmmse-5-g3-b2"); /* the guide: its readout fitted with the windows */
    fit_least_squares("lmmse-5-ri7-b2"); /* the guided interpolation's readout, likewise */
}

/* The guide's fit: the same parameters twice (deterministic), and on held-out training
 * patches (after those fitted) far better than the best constant spectrum (the targets' mean
 * over the held-out pixels, an oracle); lmmse-5-b2 fitted the same way is printed beside it. */
static void test_guide_fit(void)
{
    char sysp[1024], cave[1024];
    lm_err e = {0};
    const char *sh = getenv("LM_SHARED_DIR");
    snprintf(cave, sizeof cave, "%s/data/cave", sh ? sh : "../shared");
    lm_system sys;
    CHECK_MSG(lm_data_path("systems/default.json", sysp, sizeof sysp, &e) == LM_OK &&
              lm_system_load(sysp, &sys, &e) == LM_OK, "%s", e.msg);
    lm_mosaic mo;
    CHECK(lm_mosaic_from_system(&sys, &mo, &e) == LM_OK);
    const char *paths[1] = {cave};
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths, dc.npaths = 1, dc.sys = &sys, dc.workers = 0;
    dc.patch_h = 24, dc.patch_w = 32, dc.noise_min = dc.noise_max = 0.0f;
    dc.buckets = 2;
    const int NP = 64, B = 16, HO = 16; /* fitted, then held out */
    lm_model *m[3] = {NULL, NULL, NULL};
    for (int k = 0; k < 3; k++) {
        lm_dataset *d = lm_dataset_open(&dc, &e);
        m[k] = lm_model_create(k < 2 ? "lmmse-5-g3-b2" : "lmmse-5-b2", &mo, 1, &e);
        CHECK_MSG(d && m[k], "%s", e.msg);
        lm_lmmse_fit_report rep;
        if (d && m[k])
            CHECK_MSG(lm_lmmse_fit(m[k], d, 24, 32, NP, B, -1.0, NULL, &rep, &e) == LM_OK, "%s",
                      e.msg);
        lm_dataset_close(d);
    }
    if (!m[0] || !m[1] || !m[2]) goto out;
    const char *names[4] = {"filters.weight", "filters.bucket0", "filters.bias", "readout.weight"};
    for (int i = 0; i < 4; i++) {
        const lm_param *a = lm_params_find(&m[0]->params, names[i]);
        const lm_param *b = lm_params_find(&m[1]->params, names[i]);
        CHECK_MSG(a && b && !memcmp(a->t.data, b->t.data, sizeof(float) * lm_tensor_numel(&a->t)),
                  "%s differs between two fits", names[i]);
    }
    lm_dataset *d = lm_dataset_open(&dc, &e);
    float *raw = malloc(sizeof(float) * HO * 2 * 24 * 32), *tgt = malloc(sizeof(float) * HO * O * 24 * 32);
    CHECK(d && lm_dataset_batch(d, NP / HO, HO, raw, tgt, &e) == LM_OK);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    m[0]->noise_sigma = m[2]->noise_sigma = 0.0f;
    lm_tensor *y = lm_model_forward(&c, m[0], lm_tensor_from(&c, 4, (int[]){HO, 2, 24, 32}, raw));
    lm_tensor *yl = lm_model_forward(&c, m[2], lm_tensor_from(&c, 4, (int[]){HO, 2, 24, 32}, raw));
    CHECK_MSG(y && yl, "%s", c.msg);
    double sse = 0, sse0 = 0, ssel = 0;
    long n = 0;
    for (int ch = 1; y && yl && ch <= 31; ch++) {
        double mean = 0;
        for (int b = 0; b < HO; b++)
            for (int Y = 0; Y < 24; Y++)
                for (int X = 0; X < 32; X++) mean += tgt[(((size_t)b * O + ch) * 24 + Y) * 32 + X];
        mean /= HO * 24 * 32;
        for (int b = 0; b < HO; b++)
            for (int Y = 0; Y < 24; Y++)
                for (int X = 0; X < 32; X++, n++) {
                    size_t i = (((size_t)b * O + ch) * 24 + Y) * 32 + X;
                    sse += (y->data[i] - tgt[i]) * (double)(y->data[i] - tgt[i]);
                    sse0 += (mean - tgt[i]) * (mean - tgt[i]);
                    ssel += (yl->data[i] - tgt[i]) * (double)(yl->data[i] - tgt[i]);
                }
    }
    double psnr = -10 * log10(sse / n), psnr0 = -10 * log10(sse0 / n);
    printf("     held-out patches: lmmse-5-g3-b2 %.2f dB, lmmse-5-b2 %.2f dB, best constant "
           "spectrum %.2f dB\n", psnr, -10 * log10(ssel / n), psnr0);
    CHECK_MSG(psnr > psnr0 + 5, "guide %.2f dB, constant %.2f dB", psnr, psnr0);
    free(raw), free(tgt);
    lm_ctx_free(&c);
    lm_dataset_close(d);
out:
    lm_model_free(m[0]), lm_model_free(m[1]), lm_model_free(m[2]);
    lm_system_free(&sys);
}

/* Levels other than the bundled ones (bench_lmmse_levels' exact-level filters): checked,
 * interpolated between the model's own levels, and refused by checkpoints. */
static void test_custom_levels(void)
{
    float lv[LM_LMMSE_LEVELS];
    for (int l = 0; l < LM_LMMSE_LEVELS; l++) lv[l] = 0.003f * (float)(l * l);
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create("lmmse-3", &mo, 3, &e);
    CHECK(m && !lm_lmmse_custom_levels(m) && lm_lmmse_levels(m)[5] == lm_lmmse_sigmas[5]);
    float bad[LM_LMMSE_LEVELS];
    memcpy(bad, lv, sizeof bad);
    bad[0] = 0.001f;
    CHECK(lm_lmmse_set_levels(m, bad, &e) == LM_ERR_ARG && strstr(e.msg, "first"));
    memcpy(bad, lv, sizeof bad);
    bad[7] = bad[6];
    e = (lm_err){0};
    CHECK(lm_lmmse_set_levels(m, bad, &e) == LM_ERR_ARG && strstr(e.msg, "increasing"));
    bad[7] = NAN;
    CHECK(lm_lmmse_set_levels(m, bad, &e) == LM_ERR_ARG);
    e = (lm_err){0};
    CHECK(!lm_lmmse_custom_levels(m));
    CHECK(lm_lmmse_set_levels(m, lv, &e) == LM_OK && lm_lmmse_custom_levels(m) &&
          lm_lmmse_levels(m)[5] == lv[5]);
    lm_train_cfg cfg;
    lm_train_cfg_default(&cfg);
    char dir[] = "/tmp/lm_test_lmmse_XXXXXX";
    CHECK(mkdtemp(dir) != NULL);
    CHECK(lm_train_save_checkpoint(dir, m, NULL, 0, 0, NULL, &cfg, &e) == LM_ERR_ARG &&
          strstr(e.msg, "noise levels"));
    char path[64];
    snprintf(path, sizeof path, "%s/model.safetensors", dir);
    CHECK(access(path, F_OK) != 0); /* nothing written */
    rmdir(dir);
    CHECK(lm_lmmse_set_levels(m, lm_lmmse_sigmas, &e) == LM_OK && !lm_lmmse_custom_levels(m));
    lm_model_free(m);
    g_levels = lv; /* the forward blends the model's own levels: halfway between 4 and 5 */
    check_forward("lmmse-3", 9, 12, 0.5f * (lv[4] + lv[5]), 4, 0.5);
    check_forward("lmmse-3", 9, 12, lv[6], 6, 0.0);
    g_levels = NULL;
}

int main(void)
{
    RUN(test_forward_matches_direct_loop);
    RUN(test_direct_matches_tile_path);
    RUN(test_whole_frame_path);
    RUN(test_counts_and_capabilities);
    RUN(test_gradients);
    RUN(test_residual_starts_at_base);
    RUN(test_guide_presets);
    RUN(test_gri_presets);
    RUN(test_gri_features);
    RUN(test_gri_strips);
    RUN(test_fit_is_least_squares);
    RUN(test_guide_fit);
    RUN(test_custom_levels);
    return check_summary();
}
