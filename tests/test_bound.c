/* test_bound.c — the spectral bound (infer/bound.h): the LEDs' responses of a cube equal a_l .
 * mirror41(r) computed directly, and at each pixel's own LED the forward model's noise-free
 * coded frame; their noise has sd k x the coded frame's largest clean value; scenes whose
 * spectra span 3 dimensions are recovered exactly by the linear map fitted on another such
 * scene (12 LEDs see 3 dimensions), spectra of 31 independent bands are not; the quadratic
 * map fits at least as well as the linear one on its own training pixels; bad arguments. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "tests/check.h"
#include "data/forward.h"
#include "data/metrics.h"
#include "data/spectra.h"
#include "infer/bound.h"
#include "tensor/rng.h"

static lm_system g_sys;

/* A 31-band cube whose spectra mix `dims` smooth basis spectra with random positive weights
 * (dims 0: every band drawn independently). */
static void make_cube(lm_cube *c, int h, int w, int dims, uint64_t seed)
{
    CHECK(lm_cube_alloc(c, 31, h, w, 400, 10) == LM_OK);
    lm_rng r;
    lm_rng_seed(&r, seed);
    const size_t np = (size_t)h * w;
    for (size_t i = 0; i < np; i++) {
        if (dims == 0) {
            for (int b = 0; b < 31; b++) lm_cube_band(c, b)[i] = lm_rng_uniform(&r);
            continue;
        }
        double wt[8];
        for (int d = 0; d < dims; d++) wt[d] = 0.1 + lm_rng_uniform(&r);
        for (int b = 0; b < 31; b++) {
            double v = 0.0;
            for (int d = 0; d < dims; d++)
                v += wt[d] * (1.0 + cos(0.2 * (d + 1) * b + d)) / 2.0;
            lm_cube_band(c, b)[i] = (float)(v / dims);
        }
    }
}

static void test_features(void)
{
    CHECK(lm_bound_features(12, LM_BOUND_LINEAR) == 13);
    CHECK(lm_bound_features(12, LM_BOUND_QUADRATIC) == 13 + 78);
    CHECK(!strcmp(lm_bound_map_name(LM_BOUND_QUADRATIC), "quadratic"));
}

static void test_responses(void)
{
    lm_cube c;
    make_cube(&c, 12, 16, 4, 1);
    float *resp = NULL;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_bound_responses(&g_sys, &c, 0.0f, NULL, &resp, &e) == LM_OK, "%s", e.msg);
    const int L = g_sys.nleds, H = c.height, W = c.width;
    const size_t np = (size_t)H * W;
    double worst = 0.0;
    for (int l = 0; l < L; l++)
        for (size_t i = 0; i < np; i += 7) {
            float in[31], s41[41];
            for (int b = 0; b < 31; b++) in[b] = lm_cube_band(&c, b)[i];
            lm_spectrum_mirror41(in, s41);
            double ref = 0.0;
            for (int b = 0; b < 41; b++) ref += (double)lm_system_response(&g_sys, l)[b] * s41[b];
            worst = fmax(worst, fabs(ref - resp[(size_t)l * np + i]));
        }
    CHECK_MSG(worst < 1e-5, "responses differ from a_l . r by %g", worst);
    /* at each pixel's own LED: the coded frame */
    float *frame = malloc(sizeof(float) * np);
    CHECK(frame != NULL);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    CHECK(lm_forward_simulate31(&g_sys, &c, &fo, NULL, frame, NULL, &e) == LM_OK);
    worst = 0.0;
    float mx = 0.0f;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const size_t i = (size_t)y * W + x;
            const float v = resp[(size_t)lm_system_pixel_led(&g_sys, y, x) * np + i];
            worst = fmax(worst, fabs((double)v - frame[i]));
            if (frame[i] > mx) mx = frame[i];
        }
    CHECK_MSG(worst < 1e-5, "own-LED responses differ from the coded frame by %g", worst);
    /* noise: sd k x the coded frame's largest clean value */
    lm_rng r;
    lm_rng_seed(&r, 5);
    float *noisy = NULL;
    CHECK(lm_bound_responses(&g_sys, &c, 0.1f, &r, &noisy, &e) == LM_OK);
    double ss = 0.0;
    for (size_t i = 0; noisy && i < (size_t)L * np; i++) {
        const double d = noisy[i] - resp[i];
        ss += d * d;
    }
    const double sd = sqrt(ss / ((double)L * np));
    CHECK_MSG(fabs(sd / (0.1 * mx) - 1.0) < 0.05, "noise sd %g, want %g", sd, 0.1 * mx);
    /* bad arguments */
    float *none = NULL;
    CHECK(lm_bound_responses(&g_sys, &c, 0.1f, NULL, &none, &e) == LM_ERR_ARG && !none);
    lm_cube bad;
    CHECK(lm_cube_alloc(&bad, 30, 12, 16, 400, 10) == LM_OK);
    lm_err_clear(&e);
    CHECK(lm_bound_responses(&g_sys, &bad, 0.0f, NULL, &none, &e) != LM_OK && !none);
    lm_cube_free(&bad);
    free(noisy);
    free(frame);
    free(resp);
    lm_cube_free(&c);
}

/* PSNR of a map fitted on one cube and applied to another of the same kind. */
static double fit_and_score(int map, int dims, double ridge, int self)
{
    lm_cube tr, te;
    make_cube(&tr, 24, 32, dims, 11);
    make_cube(&te, 24, 32, dims, self ? 11 : 12);
    lm_err e;
    lm_err_clear(&e);
    float *rt = NULL, *rs = NULL;
    CHECK(lm_bound_responses(&g_sys, &tr, 0.0f, NULL, &rt, &e) == LM_OK);
    CHECK(lm_bound_responses(&g_sys, &te, 0.0f, NULL, &rs, &e) == LM_OK);
    lm_bound_fit f;
    CHECK(lm_bound_fit_init(&f, g_sys.nleds, map, &e) == LM_OK);
    lm_bound_add(&f, rt, &tr);
    CHECK(f.pixels == 24 * 32);
    CHECK_MSG(lm_bound_solve(&f, ridge, &e) == LM_OK, "%s", e.msg);
    float *pred = malloc(sizeof(float) * 31 * 24 * 32);
    CHECK(pred != NULL);
    lm_bound_predict(&f, rs, 24, 32, pred);
    const double p = lm_metric_psnr(pred, te.data, 31, 24, 32, 0, 31);
    free(pred);
    free(rt);
    free(rs);
    lm_bound_fit_free(&f);
    lm_cube_free(&tr);
    lm_cube_free(&te);
    return p;
}

static void test_recovery(void)
{
    const double low = fit_and_score(LM_BOUND_LINEAR, 3, 1e-12, 0);
    CHECK_MSG(low > 60.0, "3-dimensional spectra: linear PSNR %.2f dB (want > 60)", low);
    const double full = fit_and_score(LM_BOUND_LINEAR, 0, 1e-9, 0);
    CHECK_MSG(full < 25.0, "independent bands: linear PSNR %.2f dB (want < 25)", full);
    /* on its own training pixels a superset of features cannot fit worse */
    const double lin = fit_and_score(LM_BOUND_LINEAR, 6, 1e-12, 1);
    const double quad = fit_and_score(LM_BOUND_QUADRATIC, 6, 1e-12, 1);
    CHECK_MSG(quad >= lin - 0.01, "training fit: quadratic %.2f dB < linear %.2f dB", quad, lin);
}

static void test_bad(void)
{
    lm_bound_fit f;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_bound_fit_init(&f, g_sys.nleds, LM_BOUND_LINEAR, &e) == LM_OK);
    CHECK(lm_bound_solve(&f, 1e-6, &e) == LM_ERR_ARG); /* nothing accumulated */
    lm_bound_fit_free(&f);
    lm_err_clear(&e);
    CHECK(lm_bound_fit_init(&f, 100, LM_BOUND_QUADRATIC, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "too many"), "%s", e.msg);
    lm_bound_run_opts o;
    lm_bound_run_opts_default(&o);
    o.nnoise = 0;
    lm_bound_result res;
    CHECK(lm_bound_run(&o, &res, &e) == LM_ERR_ARG);
}

int main(void)
{
    lm_err e;
    lm_err_clear(&e);
    int ok = lm_system_default(&g_sys, &e) == LM_OK;
    CHECK_MSG(ok, "%s", e.msg);
    if (!ok) return check_summary();
    RUN(test_features);
    RUN(test_responses);
    RUN(test_recovery);
    RUN(test_bad);
    lm_system_free(&g_sys);
    return check_summary();
}
