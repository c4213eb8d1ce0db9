/* test_calib.c — the calibration's pieces (data/calib.h) below the command (which
 * tests/cli/calibrate.sh runs end to end): the 6 x 4 grid from four corner centres (an affine
 * chart: centres on the lattice, squares of frac x spacing; a rotated chart too), bad corners and
 * fractions; region checks (outside the frame, smaller than a tile); the reflectances on the
 * grid (bin means of the table; flat past the table's 730 nm end); the measured means of a frame
 * built from known per-LED values; the fit on a measurement built from the simulated matrix with
 * known scales and offset (exact, with and without --offset) and an all-zero measurement. */
#include <stdlib.h>
#include "tests/check.h"
#include "data/calib.h"

static lm_system g_sys;

static void test_grid(void)
{
    double c[8] = {100, 50, 350, 50, 350, 200, 100, 200};
    lm_calib_rect r[LM_CALIB_PATCHES];
    lm_err e = {0};
    CHECK(lm_calib_grid(c, 0.5, r, &e) == LM_OK);
    for (int p = 0; p < LM_CALIB_PATCHES; p++) { /* spacing 50 px both ways: squares of 25 */
        CHECK(r[p].w == 25 && r[p].h == 25);
        CHECK_CLOSE(r[p].x + 12.5, 100 + 50 * (p % 6), 1.0, 0);
        CHECK_CLOSE(r[p].y + 12.5, 50 + 50 * (p / 6), 1.0, 0);
    }
    double rot[8] = {200, 0, 200, 250, 50, 250, 50, 0}; /* turned 90 degrees: still 50 px apart */
    CHECK(lm_calib_grid(rot, 1.0, r, &e) == LM_OK);
    CHECK(r[0].w == 50 && r[7].x + 25 == 150 && r[7].y + 25 == 50);
    double bad[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    CHECK(lm_calib_grid(bad, 0.5, r, &e) == LM_ERR_ARG);
    CHECK(lm_calib_grid(c, 0.0, r, &e) == LM_ERR_ARG);
    c[3] = NAN;
    CHECK(lm_calib_grid(c, 0.5, r, &e) == LM_ERR_ARG);
    lm_calib_rect in[LM_CALIB_PATCHES];
    for (int p = 0; p < LM_CALIB_PATCHES; p++) in[p] = (lm_calib_rect){10 * p, 0, 8, 6};
    CHECK(lm_calib_rects_check(&g_sys, in, 480, 640, &e) == LM_OK);
    in[5].x = 635;
    lm_err_clear(&e);
    CHECK(lm_calib_rects_check(&g_sys, in, 480, 640, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "patch 6") != NULL);
    in[5] = (lm_calib_rect){0, 0, 3, 3};
    CHECK(lm_calib_rects_check(&g_sys, in, 480, 640, &e) == LM_ERR_ARG);
}

static void test_reflectance_and_fit(void)
{
    int nb = g_sys.nbins, L = g_sys.nleds, P = LM_CALIB_PATCHES;
    double *C = malloc((size_t)P * nb * sizeof *C), A[LM_SYSTEM_MAX_LEDS * LM_CALIB_PATCHES];
    double M[LM_SYSTEM_MAX_LEDS * LM_CALIB_PATCHES];
    lm_err e = {0};
    CHECK(lm_calib_reflectances(&g_sys, NULL, C, &e) == LM_OK);
    for (int p = 0; p < P; p++) { /* 740..780 nm: the 730 sample; 400 nm: between 395 and 405 */
        for (int b = 37; b < nb; b++) CHECK_CLOSE(C[p * nb + b], C[p * nb + nb - 1], 1e-12, 0);
        CHECK(C[p * nb + 2] > 0 && C[p * nb + 2] < 1.5);
    }
    /* the white patch (19) reflects more than the black one (24) in every bin */
    for (int b = 0; b < nb; b++) CHECK(C[18 * nb + b] > 3 * C[23 * nb + b]);
    lm_calib_simulate(&g_sys, C, A);
    for (int l = 0; l < L; l++)
        for (int p = 0; p < P; p++)
            M[l * P + p] = (0.5 + 0.1 * l) * A[l * P + p] + 0.01;
    lm_calib_fit f;
    CHECK(lm_calib_solve(&g_sys, A, M, 1, &f, &e) == LM_OK);
    CHECK_CLOSE(f.offset, 0.01, 1e-9, 0);
    CHECK(f.rel_error < 1e-9);
    for (int l = 0; l < L; l++) {
        CHECK_CLOSE(f.alpha[l], 0.5 + 0.1 * l, 1e-8, 1e-8);
        CHECK_CLOSE(f.gain[l], f.alpha[l] * g_sys.leds[l].gain, 0, 1e-12);
    }
    CHECK(lm_calib_solve(&g_sys, A, M, 0, &f, &e) == LM_OK); /* the offset unexplained */
    CHECK(f.rel_error > 1e-3 && f.offset == 0.0);
    memset(M, 0, sizeof M);
    CHECK(lm_calib_solve(&g_sys, A, M, 0, &f, &e) == LM_ERR_NUMERIC);
    free(C);
}

static void test_measure(void)
{
    int H = 48, W = 64;
    float *frame = malloc((size_t)H * W * sizeof *frame);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) /* each LED's pixels: 1 + LED index, + 100 in patch 3 */
            frame[y * W + x] = 1.0f + lm_system_pixel_led(&g_sys, y, x) +
                               (x >= 20 && x < 28 && y >= 6 && y < 12 ? 100.0f : 0.0f);
    lm_calib_rect r[LM_CALIB_PATCHES];
    for (int p = 0; p < LM_CALIB_PATCHES; p++) r[p] = (lm_calib_rect){0, 30, 8, 6};
    r[2] = (lm_calib_rect){20, 6, 8, 6};
    double M[LM_SYSTEM_MAX_LEDS * LM_CALIB_PATCHES];
    lm_err e = {0};
    CHECK(lm_calib_measure(&g_sys, frame, H, W, r, M, &e) == LM_OK);
    for (int l = 0; l < g_sys.nleds; l++) {
        CHECK_CLOSE(M[l * LM_CALIB_PATCHES + 0], 1.0 + l, 1e-12, 0);
        CHECK_CLOSE(M[l * LM_CALIB_PATCHES + 2], 101.0 + l, 1e-12, 0);
    }
    r[1].y = 45;
    CHECK(lm_calib_measure(&g_sys, frame, H, W, r, M, &e) == LM_ERR_ARG);
    free(frame);
}

int main(void)
{
    lm_err e = {0};
    if (lm_system_default(&g_sys, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    RUN(test_grid);
    RUN(test_reflectance_and_fit);
    RUN(test_measure);
    lm_system_free(&g_sys);
    return check_summary();
}
