/* test_metrics.c — PSNR, SSIM, MAE, SAM (system.md §10) against hand-computed values and an
 * independent direct-window SSIM reference; error handling. */
#include "tests/check.h"
#include "data/metrics.h"
#include <stdlib.h>

#define H 16
#define W 14
#define C 33

static float frand(unsigned *s)
{
    *s = *s * 1664525u + 1013904223u;
    return (float)((*s >> 8) & 0xffff) / 65536.0f;
}

/* pred = truth + d on bands 1..31 (half the pixels +d, half -d); bands 0 and 32 get a large
 * error that must not count. */
static void test_psnr_mae_known(void)
{
    static float t[C * H * W], p[C * H * W];
    unsigned s = 1;
    const float d = 0.05f;
    for (int b = 0; b < C; b++)
        for (int i = 0; i < H * W; i++) {
            t[b * H * W + i] = 0.2f + 0.6f * frand(&s);
            float e = (b == 0 || b == 32) ? 0.5f : (i % 2 ? d : -d);
            p[b * H * W + i] = t[b * H * W + i] + e;
        }
    lm_metrics m;
    lm_err e = {0};
    CHECK(lm_metrics_target33(p, t, H, W, &m, &e) == LM_OK);
    /* float rounding of t + d: error is d up to ~1e-7 */
    CHECK_CLOSE(m.psnr, -10.0 * log10((double)d * d), 1e-4, 0);
    CHECK_CLOSE(m.psnr, 26.0206, 1e-3, 0);
    CHECK_CLOSE(m.mae, d, 1e-6, 0);
    /* over all 33 channels the big edge errors dominate: MSE = (31 d^2 + 2 * 0.25) / 33 */
    double mse33 = (31.0 * d * d + 2 * 0.25) / 33.0;
    CHECK_CLOSE(lm_metric_psnr(p, t, C, H, W, 0, 33), -10.0 * log10(mse33), 1e-4, 0);
    CHECK_CLOSE(lm_metric_psnr(t, t, C, H, W, 1, 31), LM_PSNR_MAX_DB, 1e-9, 0);
}

/* Spectra with known angles in bands 1..31: 30 deg, 60 deg, 90 deg (zero prediction), 0 deg
 * (scaled copy), and one all-zero true spectrum that must be skipped. */
static void test_sam_known_angles(void)
{
    enum { h = 1, w = 5, n = C * h * w };
    float t[n], p[n];
    memset(t, 0, sizeof t);
    memset(p, 0, sizeof p);
    const double deg = M_PI / 180.0;
#define AT(a, b, x) a[(b) * w + (x)]
    double ang[2] = {30.0, 60.0};
    for (int x = 0; x < 2; x++) {
        AT(t, 3, x) = 0.5f;
        AT(p, 3, x) = (float)(0.8 * cos(ang[x] * deg));
        AT(p, 7, x) = (float)(0.8 * sin(ang[x] * deg));
    }
    AT(t, 10, 2) = 0.4f;                    /* prediction zero: 90 deg */
    for (int b = 1; b <= 31; b++) {         /* pixel 3: same direction, scaled */
        AT(t, b, 3) = 0.01f * b;
        AT(p, b, 3) = 0.02f * b;
    }
    AT(p, 5, 4) = 0.9f;                     /* pixel 4: true spectrum all zero: skipped */
    AT(t, 0, 4) = 1.0f;                     /* ... even if channel 0 (not evaluated) is not */
#undef AT
    long cnt = 0;
    double sam = lm_metric_sam(p, t, C, h, w, 1, 31, &cnt);
    CHECK(cnt == 4);
    CHECK_CLOSE(sam, (30.0 + 60.0 + 90.0 + 0.0) / 4.0, 1e-4, 0);
    CHECK_CLOSE(lm_metric_sam(t, t, C, h, w, 1, 31, NULL), 0.0, 1e-4, 0);
    /* nothing to measure */
    float z[n];
    memset(z, 0, sizeof z);
    CHECK(lm_metric_sam(p, z, C, h, w, 1, 31, &cnt) == 0.0 && cnt == 0);
}

/* Direct reference: explicit 11 x 11 Gaussian weights, every valid window position. */
static double ssim_direct(const float *x, const float *y, int h, int w)
{
    double g[11][11], s = 0;
    for (int i = 0; i < 11; i++)
        for (int j = 0; j < 11; j++) s += g[i][j] = exp(-((i - 5) * (i - 5) + (j - 5) * (j - 5)) / 4.5);
    const double C1 = 1e-4, C2 = 9e-4;
    double total = 0;
    int cnt = 0;
    for (int r = 0; r + 11 <= h; r++)
        for (int c = 0; c + 11 <= w; c++, cnt++) {
            double mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
            for (int i = 0; i < 11; i++)
                for (int j = 0; j < 11; j++) {
                    double wt = g[i][j] / s, a = x[(r + i) * w + c + j], b = y[(r + i) * w + c + j];
                    mx += wt * a, my += wt * b, xx += wt * a * a, yy += wt * b * b, xy += wt * a * b;
                }
            double vx = xx - mx * mx, vy = yy - my * my, cxy = xy - mx * my;
            total += (2 * mx * my + C1) * (2 * cxy + C2) / ((mx * mx + my * my + C1) * (vx + vy + C2));
        }
    return total / cnt;
}

static void test_ssim(void)
{
    static float x[H * W], y[H * W], k[H * W];
    unsigned s = 7;
    for (int i = 0; i < H * W; i++) x[i] = frand(&s);
    CHECK_CLOSE(lm_metric_ssim_band(x, x, H, W), 1.0, 1e-9, 0);
    /* constant images a and a + d: SSIM = (2a(a+d) + C1) / (a^2 + (a+d)^2 + C1) */
    const double a = 0.3, d = 0.2, C1 = 1e-4;
    for (int i = 0; i < H * W; i++) k[i] = (float)a, y[i] = (float)(a + d);
    double expect = (2 * a * (a + d) + C1) / (a * a + (a + d) * (a + d) + C1);
    CHECK_CLOSE(lm_metric_ssim_band(k, y, H, W), expect, 1e-6, 0);
    CHECK(expect < 0.95); /* the test can tell it from 1 */
    /* textured image with a constant offset, and a noisy copy: direct reference */
    for (int i = 0; i < H * W; i++) y[i] = x[i] + 0.1f;
    CHECK_CLOSE(lm_metric_ssim_band(x, y, H, W), ssim_direct(x, y, H, W), 1e-9, 1e-9);
    for (int i = 0; i < H * W; i++) y[i] = 0.7f * x[i] + 0.2f * frand(&s);
    double ref = ssim_direct(x, y, H, W);
    CHECK_CLOSE(lm_metric_ssim_band(x, y, H, W), ref, 1e-9, 1e-9);
    CHECK(ref > 0.1 && ref < 0.99);
    /* per-band mean over bands 1..31 of a cube */
    static float cp[C * H * W], ct[C * H * W];
    double want = 0;
    for (int b = 0; b < C; b++)
        for (int i = 0; i < H * W; i++) {
            ct[b * H * W + i] = x[i];
            cp[b * H * W + i] = x[i] + 0.01f * b;
        }
    for (int b = 1; b <= 31; b++) want += ssim_direct(ct + b * H * W, cp + b * H * W, H, W);
    CHECK_CLOSE(lm_metric_ssim(cp, ct, C, H, W, 1, 31), want / 31, 1e-9, 1e-9);
}

static void test_errors(void)
{
    static float a[C * 10 * 20];
    lm_metrics m;
    lm_err e = {0};
    CHECK(lm_metrics_compute(a, a, C, 10, 20, 1, 31, &m, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "metrics") && strstr(e.msg, "10 x 20"));
    lm_err_clear(&e);
    CHECK(lm_metrics_compute(a, a, C, 20, 10, 1, 33, &m, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "metrics") && strstr(e.msg, "bands"));
}

static void test_accumulator(void)
{
    lm_metrics_acc acc = {0};
    lm_metrics m1 = {30, 0.9, 0.02, 4, 10}, m2 = {40, 0.7, 0.04, 2, 6};
    lm_metrics_acc_add(&acc, &m1);
    lm_metrics_acc_add(&acc, &m2);
    lm_metrics r = lm_metrics_acc_mean(&acc);
    CHECK_CLOSE(r.psnr, 35, 1e-12, 0);
    CHECK_CLOSE(r.ssim, 0.8, 1e-12, 0);
    CHECK_CLOSE(r.mae, 0.03, 1e-12, 0);
    CHECK_CLOSE(r.sam, 3, 1e-12, 0);
}

int main(void)
{
    RUN(test_psnr_mae_known);
    RUN(test_sam_known_angles);
    RUN(test_ssim);
    RUN(test_errors);
    RUN(test_accumulator);
    return check_summary();
}
