/* test_conditions.c — adverse capture conditions (infer/conditions.h), each checked by hand on
 * a small frame: saturation (hand values, and the simulated frame equals min(x clean, 1) / x),
 * dead pixels (exact count of changed values, each 0 or full scale, both kinds present, seeded
 * and repeatable), Poisson shot noise (normalised residual (noisy - clean) / sqrt(clean / P)
 * has mean ~0 and variance ~1 over a 72 x 96 frame), LED gain mis-calibration (factors exactly
 * 1 +- p %, and the frame equals the clean frame times the factor of each pixel's LED: bucket 1
 * is linear in a_l), the 3-dB crossing interpolation on hand values, lm_cond_eval (clean levels
 * of every family score identically, 30 photons score lower, motion at 0 px/s runs and its
 * unaligned score equals its static reference), an RGB
 * model (MST++: 3 x H x W camera frame, saturation and dead pixels as by hand, LED gains
 * refused), names, and errors (levels out of range, families that do not apply to RGB). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "tests/check.h"
#include "data/forward.h"
#include "infer/conditions.h"
#include "data/mosaic.h"

#define SH 72
#define SW 96

static lm_system g_sys;
static lm_infer_model g_im;
static lm_cube g_truth;
static int g_ok;

static void small_scene(lm_cube *c)
{
    CHECK(lm_cube_alloc(c, 31, SH, SW, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < SH; y++)
            for (int x = 0; x < SW; x++)
                c->data[((size_t)b * SH + y) * SW + x] =
                    (float)(0.5 + 0.3 * sin(0.11 * x + 0.07 * y + 0.1 * b));
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_eval_prepare(c, 3, 4, &e) == LM_OK, "%s", e.msg);
}

/* The clean coded frame, computed directly with the forward model. */
static float *clean_frame(const lm_system *sys)
{
    float *f = malloc(sizeof(float) * SH * SW);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    lm_err e;
    CHECK_MSG(lm_forward_simulate31(sys, &g_truth, &fo, NULL, f, NULL, &e) == LM_OK, "%s", e.msg);
    return f;
}

static void test_saturate_hand(void)
{
    float v[5] = {0.1f, 0.3f, 0.5f, 0.9f, -0.2f};
    const float want[5] = {0.1f, 0.3f, 0.5f, 0.5f, -0.2f}; /* x2 clips at 1.0 -> 0.5 */
    lm_err e;
    CHECK(lm_cond_saturate(v, 5, 2.0, 1.0f, &e) == LM_OK);
    CHECK_ARRAY_CLOSE(v, want, 5, 1e-7, 0);
    float w[2] = {0.2f, 0.3f};
    CHECK(lm_cond_saturate(w, 2, 8.0, 2.0f, &e) == LM_OK); /* full scale 2: 1.6 ok, 2.4 -> 2 */
    CHECK_CLOSE(w[0], 0.2, 1e-7, 0);
    CHECK_CLOSE(w[1], 0.25, 1e-7, 0);
    lm_err_clear(&e);
    CHECK(lm_cond_saturate(w, 2, 0.5, 1.0f, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "conditions:") != NULL);
}

static void test_dead_pixels_hand(void)
{
    enum { N = 1000 };
    float a[N], b[N];
    for (int i = 0; i < N; i++) a[i] = b[i] = 0.25f + 0.5f * (float)i / N; /* never 0 or 2 */
    lm_rng r1, r2;
    lm_rng_seed(&r1, 3);
    lm_rng_seed(&r2, 3);
    size_t nd = 0;
    lm_err e;
    CHECK(lm_cond_dead_pixels(a, N, 5.0, 2.0f, &r1, &nd, &e) == LM_OK);
    CHECK(lm_cond_dead_pixels(b, N, 5.0, 2.0f, &r2, NULL, &e) == LM_OK);
    int changed = 0, zeros = 0, highs = 0, same = 1;
    for (int i = 0; i < N; i++) {
        float orig = 0.25f + 0.5f * (float)i / N;
        if (a[i] != orig) changed++, zeros += a[i] == 0.0f, highs += a[i] == 2.0f;
        same &= a[i] == b[i];
    }
    CHECK(nd == 50 && changed == 50 && zeros + highs == 50);
    CHECK_MSG(zeros > 10 && highs > 10, "zeros %d, stuck high %d", zeros, highs);
    CHECK(same); /* the seed decides */
    /* 0 % leaves the frame alone; 0.04 % of 1000 rounds to 0; 0.06 % to 1 */
    CHECK(lm_cond_dead_pixels(a, N, 0.0, 1.0f, &r1, &nd, &e) == LM_OK && nd == 0);
    CHECK(lm_cond_dead_pixels(a, N, 0.04, 1.0f, &r1, &nd, &e) == LM_OK && nd == 0);
    CHECK(lm_cond_dead_pixels(a, N, 0.06, 1.0f, &r1, &nd, &e) == LM_OK && nd == 1);
    CHECK(lm_cond_dead_pixels(a, N, 100.0, 1.0f, &r1, &nd, &e) == LM_OK && nd == N);
    int ok = 1;
    for (int i = 0; i < N; i++) ok &= a[i] == 0.0f || a[i] == 1.0f;
    CHECK(ok);
    lm_err_clear(&e);
    CHECK(lm_cond_dead_pixels(a, N, 101.0, 1.0f, &r1, &nd, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "conditions:") != NULL);
}

static void test_poisson_moments(void)
{
    if (!g_ok) return;
    float *clean = clean_frame(&g_sys), *noisy;
    size_t n;
    lm_rng rng;
    lm_rng_seed(&rng, 9);
    lm_err e;
    const double P = 500.0;
    CHECK_MSG(lm_cond_simulate(&g_im, &g_truth, LM_COND_PHOTONS, P, &rng, &noisy, &n, &e) ==
              LM_OK, "%s", e.msg);
    if (!noisy) return free(clean);
    CHECK(n == (size_t)SH * SW);
    double s = 0, s2 = 0;
    int m = 0;
    for (size_t i = 0; i < n; i++) {
        if (clean[i] < 0.02f) continue;
        double z = (noisy[i] - clean[i]) / sqrt(clean[i] / P);
        s += z, s2 += z * z, m++;
    }
    double mean = s / m, var = s2 / m - mean * mean;
    printf("  Poisson P=%g: normalised residual mean %.4f, variance %.4f over %d pixels\n", P,
           mean, var, m);
    CHECK(m > 6000);
    CHECK_CLOSE(mean, 0.0, 0.05, 0);  /* standard error ~0.011 */
    CHECK_CLOSE(var, 1.0, 0.08, 0);   /* standard error ~0.017 */
    /* photons 0 is the clean frame */
    float *z;
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_PHOTONS, 0.0, &rng, &z, &n, &e) == LM_OK);
    if (z) CHECK_ARRAY_CLOSE(z, clean, n, 0, 0);
    free(z), free(noisy), free(clean);
}

static void test_saturation_frame(void)
{
    if (!g_ok) return;
    float *clean = clean_frame(&g_sys), *sat;
    size_t n;
    lm_rng rng;
    lm_rng_seed(&rng, 9);
    lm_err e;
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_SATURATION, 1.6, &rng, &sat, &n, &e) ==
          LM_OK);
    if (!sat) return free(clean);
    int clipped = 0, ok = 1;
    for (size_t i = 0; i < n; i++) {
        double want = clean[i] * 1.6 > 1.0 ? 1.0 / 1.6 : clean[i];
        ok &= fabs(sat[i] - want) <= 1e-6;
        clipped += clean[i] * 1.6 > 1.0;
    }
    CHECK(ok);
    CHECK_MSG(clipped > 100 && clipped < (int)n, "%d of %zu clipped", clipped, n);
    free(sat), free(clean);
}

static void test_led_gain_linearity(void)
{
    if (!g_ok) return;
    double fac[LM_SYSTEM_MAX_LEDS];
    lm_rng rng, r;
    lm_rng_seed(&rng, 21);
    r = lm_rng_split(&rng, lm_cond_stream(LM_COND_LED_GAIN, 10.0)); /* replay the draws */
    lm_system ps;
    lm_err e;
    CHECK(lm_cond_led_gains(&g_sys, 10.0, &r, &ps, fac, &e) == LM_OK);
    int plus = 0, minus = 0;
    for (int l = 0; l < g_sys.nleds; l++) {
        plus += fabs(fac[l] - 1.1) < 1e-12, minus += fabs(fac[l] - 0.9) < 1e-12;
        CHECK_CLOSE(ps.leds[l].response[20], g_sys.leds[l].response[20] * fac[l], 1e-7, 1e-6);
    }
    CHECK(plus + minus == g_sys.nleds && plus > 0 && minus > 0);
    CHECK(g_sys.leds[0].response != ps.leds[0].response); /* the nominal system is untouched */
    lm_cond_system_free(&ps);
    float *clean = clean_frame(&g_sys), *got;
    size_t n;
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_LED_GAIN, 10.0, &rng, &got, &n, &e) == LM_OK);
    if (!got) return free(clean);
    int ok = 1, diff = 0;
    for (int y = 0; y < SH; y++)
        for (int x = 0; x < SW; x++) {
            size_t i = (size_t)y * SW + x;
            double want = clean[i] * fac[lm_system_pixel_led(&g_sys, y, x)];
            ok &= fabs(got[i] - want) <= 1e-5 * fabs(want) + 1e-7;
            diff += got[i] != clean[i];
        }
    CHECK(ok);
    CHECK(diff > SH * SW / 2);
    free(got), free(clean);
}

static void test_crossing_hand(void)
{
    double at;
    const double lv[4] = {0, 2, 5, 10}, p[4] = {40, 39, 37.5, 30};
    CHECK(lm_cond_crossing(lv, p, 4, 40.0, 3.0, &at) == 1);
    CHECK_CLOSE(at, 5.0 + 5.0 * 0.5 / 7.5, 1e-12, 0); /* 37 lies 0.5 / 7.5 of the way */
    CHECK(lm_cond_crossing(lv, p, 4, 45.0, 3.0, &at) == 1); /* already at the first level */
    CHECK(at == 0.0);
    CHECK(lm_cond_crossing(lv, p, 4, 32.0, 3.0, &at) == 0 && isnan(at)); /* never */
    const double ph[3] = {1000, 300, 100}, q[3] = {35, 33, 30}; /* decreasing levels */
    CHECK(lm_cond_crossing(ph, q, 3, 36.0, 3.0, &at) == 1);
    CHECK_CLOSE(at, 300.0, 1e-9, 0); /* exactly at the threshold counts */
    CHECK(lm_cond_crossing(ph, q, 3, 35.0, 3.0, &at) == 1);
    CHECK_CLOSE(at, 300.0 - 200.0 / 3.0, 1e-9, 0); /* 32 between 33 and 30 */
    const double r[3] = {35, NAN, 20};
    CHECK(lm_cond_crossing(ph, r, 3, 35.0, 3.0, &at) == 1 && at == 300.0);
    const double s[2] = {INFINITY, 34};
    CHECK(lm_cond_crossing(ph, s, 2, 35.0, 3.0, &at) == 0);
}

static void test_eval_and_errors(void)
{
    if (!g_ok) return;
    lm_ctx c;
    CHECK(lm_ctx_init(&c, 2) == 0);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_rng rng;
    lm_rng_seed(&rng, 4);
    lm_err e;
    lm_metrics m[4], u;
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_PHOTONS, 0, &to, &rng, &m[0], &u, NULL,
                       &e) == 0);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_SATURATION, 1, &to, &rng, &m[1], NULL, NULL,
                       &e) == LM_OK);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_DEAD_PIXELS, 0, &to, &rng, &m[2], NULL, NULL,
                       &e) == LM_OK);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_PHOTONS, 30, &to, &rng, &m[3], NULL, NULL,
                       &e) == LM_OK);
    CHECK(m[0].psnr == m[1].psnr && m[0].psnr == m[2].psnr && u.psnr == m[0].psnr);
    CHECK_MSG(m[3].psnr < m[0].psnr, "30 photons %g, clean %g", m[3].psnr, m[0].psnr);
    lm_metrics st;
    CHECK_MSG(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_MOTION, 0, &to, &rng, &m[0], &u, &st,
                           &e) == LM_OK, "%s", e.msg);
    CHECK(isfinite(m[0].psnr) && isfinite(u.psnr) && st.psnr == u.psnr);
    /* errors */
    float *f;
    size_t n;
    lm_err_clear(&e);
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_SATURATION, 0.5, &rng, &f, &n, &e) ==
          LM_ERR_ARG && !f && strstr(e.msg, "saturation"));
    lm_err_clear(&e);
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_DEAD_PIXELS, 120, &rng, &f, &n, &e) ==
          LM_ERR_ARG && strstr(e.msg, "dead_pixels"));
    lm_err_clear(&e);
    CHECK(lm_cond_simulate(&g_im, &g_truth, LM_COND_MOTION, 10, &rng, &f, &n, &e) == LM_ERR_ARG);
    lm_err_clear(&e);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_PHOTONS, -1, &to, &rng, m, NULL, NULL, &e) ==
          LM_ERR_ARG);
    g_im.model->caps |= LM_CAP_RGB_INPUT; /* as an RGB model: LED gains and motion do not apply */
    lm_err_clear(&e);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_LED_GAIN, 5, &to, &rng, m, NULL, NULL, &e) ==
          LM_ERR_ARG && strstr(e.msg, "RGB"));
    lm_err_clear(&e);
    CHECK(lm_cond_eval(&c, &g_im, &g_truth, LM_COND_MOTION, 5, &to, &rng, m, NULL, NULL, &e) ==
          LM_ERR_ARG && strstr(e.msg, "motion"));
    g_im.model->caps &= ~(unsigned)LM_CAP_RGB_INPUT;
    lm_ctx_free(&c);
}

/* An RGB model (MST++): the frame is the 3 x H x W camera image; saturation and dead pixels
 * act on it as on a coded frame; LED gains do not apply. */
static void test_rgb_model(void)
{
    if (!g_ok) return;
    lm_err e;
    lm_err_clear(&e);
    lm_infer_model im = g_im;
    im.model = lm_model_create("mst-tiny", NULL, 3, &e);
    CHECK_MSG(im.model && im.model->in_channels == 3, "%s", e.msg);
    if (!im.model) return;
    lm_rng rng;
    lm_rng_seed(&rng, 2);
    float *clean = NULL, *sat = NULL, *dead = NULL;
    size_t n = 0, n2 = 0, n3 = 0;
    CHECK(lm_cond_simulate(&im, &g_truth, LM_COND_PHOTONS, 0, &rng, &clean, &n, &e) == LM_OK);
    CHECK(lm_cond_simulate(&im, &g_truth, LM_COND_SATURATION, 1.6, &rng, &sat, &n2, &e) == LM_OK);
    CHECK(lm_cond_simulate(&im, &g_truth, LM_COND_DEAD_PIXELS, 2, &rng, &dead, &n3, &e) == LM_OK);
    CHECK(n == 3u * SH * SW && n2 == n && n3 == n);
    if (clean && sat && dead) {
        int ok = 1, clipped = 0, changed = 0, stuck = 1;
        for (size_t i = 0; i < n; i++) {
            double want = clean[i] * 1.6 > 1.0 ? 1.0 / 1.6 : clean[i];
            ok &= fabs(sat[i] - want) <= 1e-6;
            clipped += clean[i] * 1.6 > 1.0;
            if (dead[i] != clean[i]) changed++, stuck &= dead[i] == 0.0f || dead[i] == 1.0f;
        }
        CHECK(ok && clipped > 0);
        /* 2 % of 3 x 72 x 96 = 414.72 -> 415 values, minus any stuck at a value they had */
        CHECK_MSG(changed <= 415 && changed >= 405 && stuck, "%d changed", changed);
    }
    free(sat);
    lm_err_clear(&e);
    CHECK(lm_cond_simulate(&im, &g_truth, LM_COND_LED_GAIN, 5, &rng, &sat, &n, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "led_gain") && strstr(e.msg, "RGB"));
    free(clean), free(dead);
    lm_model_free(im.model);
}

static void test_names(void)
{
    for (int f = 0; f < LM_COND_NFAMILIES; f++) {
        CHECK(lm_cond_parse(lm_cond_name((lm_cond_family)f)) == f);
        double lv[LM_COND_MAX_LEVELS];
        int n = lm_cond_default_levels((lm_cond_family)f, lv);
        CHECK(n >= 4 && n <= LM_COND_MAX_LEVELS);
        for (int i = 0; i < n; i++) CHECK(lm_cond_level_ok((lm_cond_family)f, lv[i]));
    }
    CHECK(lm_cond_parse("bogus") == -1 && lm_cond_name(LM_COND_NFAMILIES) == NULL);
    CHECK(lm_cond_applies(LM_COND_LED_GAIN, 0) && !lm_cond_applies(LM_COND_LED_GAIN, 1));
    CHECK(lm_cond_applies(LM_COND_PHOTONS, 1) && !lm_cond_applies(LM_COND_MOTION, 1));
    CHECK(lm_cond_stream(LM_COND_PHOTONS, 100) != lm_cond_stream(LM_COND_PHOTONS, 30));
    CHECK(lm_cond_stream(LM_COND_PHOTONS, 5) != lm_cond_stream(LM_COND_DEAD_PIXELS, 5));
}

int main(void)
{
    lm_err e;
    lm_err_clear(&e);
    g_ok = lm_system_default(&g_sys, &e) == LM_OK;
    if (!g_ok) printf("default system: %s\n", e.msg);
    lm_mosaic mo;
    if (g_ok) g_ok = lm_mosaic_from_system(&g_sys, &mo, &e) == LM_OK;
    if (g_ok) g_ok = (g_im.model = lm_model_create("linear", &mo, 11, &e)) != NULL;
    CHECK_MSG(g_ok, "%s", e.msg);
    g_im.sys = g_sys;
    small_scene(&g_truth);
    RUN(test_saturate_hand);
    RUN(test_dead_pixels_hand);
    RUN(test_poisson_moments);
    RUN(test_saturation_frame);
    RUN(test_led_gain_linearity);
    RUN(test_crossing_hand);
    RUN(test_eval_and_errors);
    RUN(test_rgb_model);
    RUN(test_names);
    lm_cube_free(&g_truth);
    lm_model_free(g_im.model);
    lm_system_free(&g_sys);
    return check_summary();
}
