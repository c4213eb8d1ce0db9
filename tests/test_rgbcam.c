/* test_rgbcam.c — the RGB camera model (data/rgbcam.h): white gives (1,1,1) under both
 * illuminants, linearity, a pixel computed by hand from the CSV values (read and integrated
 * here, independently of data/spectra.c), the noise options, and file errors. */
#include "data/rgbcam.h"
#include "data/spectra.h"
#include "tests/check.h"
#include <math.h>
#include <stdlib.h>

#define NB LM_RGBCAM_BANDS

static void test_white(void)
{
    for (int il = 0; il < 2; il++) {
        lm_rgbcam cam;
        lm_err e = {0};
        CHECK_MSG(lm_rgbcam_load(&cam, NULL, (lm_rgbcam_illum)il, &e) == LM_OK, "%s", e.msg);
        int H = 3, W = 5;
        float cube[NB * 15], rgb[3 * 15];
        for (int i = 0; i < NB * H * W; i++) cube[i] = 1.0f;
        lm_rgbcam_render(&cam, cube, H, W, rgb, 2);
        for (int i = 0; i < 3 * H * W; i++) CHECK_CLOSE(rgb[i], 1.0f, 1e-5, 0);
        /* grey 0.4 -> 0.4 */
        for (int i = 0; i < NB * H * W; i++) cube[i] = 0.4f;
        lm_rgbcam_render(&cam, cube, H, W, rgb, 1);
        for (int i = 0; i < 3 * H * W; i++) CHECK_CLOSE(rgb[i], 0.4f, 1e-5, 0);
    }
}

static void test_linear(void)
{
    lm_rgbcam cam;
    lm_err e = {0};
    CHECK(lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, &e) == LM_OK);
    enum { H = 7, W = 9, N = NB * H * W };
    static float x[N], y[N], z[N], rx[3 * H * W], ry[3 * H * W], rz[3 * H * W];
    lm_rng r;
    lm_rng_seed(&r, 5);
    lm_rng_fill_uniform(&r, x, N, 0, 1);
    lm_rng_fill_uniform(&r, y, N, 0, 1);
    for (int i = 0; i < N; i++) z[i] = 0.3f * x[i] - 2.0f * y[i];
    lm_rgbcam_render(&cam, x, H, W, rx, 2);
    lm_rgbcam_render(&cam, y, H, W, ry, 2);
    lm_rgbcam_render(&cam, z, H, W, rz, 2);
    for (int i = 0; i < 3 * H * W; i++) CHECK_CLOSE(rz[i], 0.3f * rx[i] - 2.0f * ry[i], 1e-5, 1e-5);
    /* channels differ: the camera is not monochrome */
    CHECK(fabsf(rx[0] - rx[H * W]) > 1e-4f || fabsf(rx[0] - rx[2 * H * W]) > 1e-4f);
}

/* Read a CSV with a header and numeric columns (5 nm grids here) into rows x cols. */
static int read_csv(const char *rel, double *v, int maxrows, int cols)
{
    char path[1024];
    lm_err e = {0};
    if (lm_data_path(rel, path, sizeof path, &e)) return -1;
    FILE *f = fopen(path, "r");
    if (!f) return -1;
    char line[512];
    int n = 0;
    if (!fgets(line, sizeof line, f)) n = -1;
    while (n >= 0 && n < maxrows && fgets(line, sizeof line, f)) {
        char *p = line;
        for (int c = 0; c < cols; c++) {
            v[n * cols + c] = strtod(p, &p);
            if (*p == ',') p++;
        }
        n++;
    }
    fclose(f);
    return n;
}

/* Integral of the 5 nm samples s(wl) over the 10 nm bin centred at `centre` (trapezoid over
 * the samples centre-5, centre, centre+5). */
static double bin5(const double *wl, const double *s, int n, int stride, double centre)
{
    double a = 0, b = 0, c = 0;
    for (int i = 0; i < n; i++) {
        double w = wl[i * stride];
        if (fabs(w - (centre - 5)) < 1e-6) a = s[i * stride];
        if (fabs(w - centre) < 1e-6) b = s[i * stride];
        if (fabs(w - (centre + 5)) < 1e-6) c = s[i * stride];
    }
    return 2.5 * (a + b) + 2.5 * (b + c);
}

static double d65_at(const double *d, int n, double wl)
{
    for (int i = 0; i < n; i++)
        if (fabs(d[2 * i] - wl) < 1e-6) return d[2 * i + 1];
    return NAN;
}

/* Pixel with r(550) = 0.5, r(600) = 0.25, 0 elsewhere, equal energy and D65. */
static void test_hand_pixel(void)
{
    static double cs[200 * 4], d65[200 * 2];
    int n = read_csv(LM_RGBCAM_DEFAULT_CSV, cs, 200, 4);
    int nd = read_csv("spectra/cie_d65_spd.csv", d65, 200, 2);
    CHECK(n == 81 && nd > 90);
    if (n != 81 || nd <= 90) return;
    static double prod[81 * 4];
    for (int i = 0; i < n; i++) {
        prod[i * 4] = cs[i * 4];
        for (int k = 1; k < 4; k++) prod[i * 4 + k] = cs[i * 4 + k] * d65_at(d65, nd, cs[i * 4]);
    }
    float cube[NB] = {0}, rgb[3];
    cube[15] = 0.5f;  /* 550 nm */
    cube[20] = 0.25f; /* 600 nm */
    for (int il = 0; il < 2; il++) {
        const double *tab = il == LM_RGBCAM_D65 ? prod : cs;
        lm_rgbcam cam;
        lm_err e = {0};
        CHECK(lm_rgbcam_load(&cam, NULL, (lm_rgbcam_illum)il, &e) == LM_OK);
        lm_rgbcam_render(&cam, cube, 1, 1, rgb, 1);
        for (int k = 0; k < 3; k++) {
            double tot = 0;
            for (int b = 0; b < NB; b++) tot += bin5(tab, tab + 1 + k, n, 4, 400 + 10 * b);
            double want = (0.5 * bin5(tab, tab + 1 + k, n, 4, 550) +
                           0.25 * bin5(tab, tab + 1 + k, n, 4, 600)) / tot;
            CHECK_MSG(fabs(rgb[k] - want) < 1e-6, "illum %d channel %d: %g, by hand %g", il, k,
                      rgb[k], want);
        }
        if (il == 1) printf("     equal energy, 0.5 @550 + 0.25 @600 nm -> RGB %.5f %.5f %.5f\n",
                            rgb[0], rgb[1], rgb[2]);
    }
}

static void test_noise(void)
{
    lm_rgbcam cam;
    lm_err e = {0};
    CHECK(lm_rgbcam_load(&cam, NULL, LM_RGBCAM_EQUAL_ENERGY, &e) == LM_OK);
    enum { H = 64, W = 64, P = H * W };
    static float cube[NB * P], clean[3 * P], noisy[3 * P];
    for (int b = 0; b < NB; b++)
        for (int i = 0; i < P; i++) cube[b * P + i] = 0.2f + 0.6f * (float)(i % W) / W;
    lm_rgbcam_render(&cam, cube, H, W, clean, 2);
    float mx = 0;
    for (int i = 0; i < 3 * P; i++) mx = fmaxf(mx, clean[i]);
    lm_rng r;
    lm_rng_seed(&r, 17);
    lm_noise_opts no = {.gauss_k = 0.1f};
    CHECK(lm_rgbcam_simulate(&cam, cube, H, W, &no, &r, noisy, 2, &e) == LM_OK);
    double s = 0, s2 = 0;
    for (int i = 0; i < 3 * P; i++) {
        double d = noisy[i] - clean[i];
        s += d, s2 += d * d;
    }
    double sd = sqrt(s2 / (3 * P) - (s / (3 * P)) * (s / (3 * P)));
    CHECK_MSG(fabs(sd - 0.1 * mx) < 0.004, "gaussian sd %g, expected %g", sd, 0.1 * mx);
    /* Poisson with 1000 photons at full scale, clipped: variance v / 1000, values in [0, 1] */
    lm_noise_opts po = {.photons = 1000, .clip = 1};
    CHECK(lm_rgbcam_simulate(&cam, cube, H, W, &po, &r, noisy, 2, &e) == LM_OK);
    double var = 0, mean = 0;
    int inrange = 1;
    for (int i = 0; i < 3 * P; i++) {
        double d = noisy[i] - clean[i];
        var += d * d / (clean[i] / 1000.0);
        mean += d;
        inrange &= noisy[i] >= 0 && noisy[i] <= 1;
    }
    CHECK_MSG(fabs(var / (3 * P) - 1) < 0.05, "normalised Poisson variance %g", var / (3 * P));
    CHECK(fabs(mean / (3 * P)) < 1e-3 && inrange);
    /* no noise = render; a random option without a generator is an error */
    CHECK(lm_rgbcam_simulate(&cam, cube, H, W, NULL, NULL, noisy, 1, &e) == LM_OK);
    CHECK(!memcmp(noisy, clean, sizeof clean));
    CHECK(lm_rgbcam_simulate(&cam, cube, H, W, &no, NULL, noisy, 1, &e) == LM_ERR_ARG);
}

static void test_errors(void)
{
    lm_rgbcam cam;
    lm_err e = {0};
    CHECK(lm_rgbcam_load(&cam, "/nonexistent/cam.csv", LM_RGBCAM_D65, &e) == LM_ERR_IO);
    CHECK(strstr(e.msg, "/nonexistent/cam.csv") != NULL);
    char path[] = "/tmp/lm_rgbcam_XXXXXX";
    int fd = mkstemp(path);
    CHECK(fd >= 0);
    if (fd < 0) return;
    FILE *f = fdopen(fd, "w");
    fprintf(f, "wavelength_nm,R,X,B\n400,1,1,1\n500,1,1,1\n600,1,1,1\n");
    fclose(f);
    lm_err_clear(&e);
    CHECK(lm_rgbcam_load(&cam, path, LM_RGBCAM_EQUAL_ENERGY, &e) == LM_ERR_FORMAT);
    CHECK(strstr(e.msg, "'G'") && strstr(e.msg, path));
    f = fopen(path, "w");
    fprintf(f, "wavelength_nm,R,G,B\n400,1,0,1\n500,1,0,1\n700,1,0,1\n");
    fclose(f);
    lm_err_clear(&e);
    CHECK(lm_rgbcam_load(&cam, path, LM_RGBCAM_EQUAL_ENERGY, &e) == LM_ERR_FORMAT);
    CHECK(strstr(e.msg, "no response") != NULL);
    remove(path);
}

int main(void)
{
    RUN(test_white);
    RUN(test_linear);
    RUN(test_hand_pixel);
    RUN(test_noise);
    RUN(test_errors);
    return check_summary();
}
