/* test_forward.c — the closed form against the paper's per-sub-frame sum (both buckets), shape
 * and option errors, noise statistics (Gaussian, Poisson, read noise), determinism per seed and
 * thread count, quantisation levels and clipping. */
#include "tests/check.h"
#include "data/forward.h"
#include "data/spectra.h"
#include <stdlib.h>
#include <time.h>

static lm_system g_sys;
static int g_ok;
static lm_err g_err;

static void test_default_system_loads(void) { CHECK_MSG(g_ok, "default system: %s", g_err.msg); }

static void random_cube41(lm_cube *c, int h, int w, uint64_t seed)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    CHECK(lm_cube_alloc(c, 41, h, w, 380, 10) == LM_OK);
    lm_rng_fill_uniform(&r, c->data, 41L * h * w, 0, 1);
}

/* The paper's model, written from the schedule: Y_p = sum_s C_{p,s} (S .* I_{p,s}) . r_p, with
 * the per-sub-frame irradiance of the LED on at s being scale * subframe_us * gain_l * E_l. */
static void subframe_sum(const lm_system *s, const lm_cube *c, int y0, int x0, double *b1,
                         double *b0)
{
    int H = c->height, W = c->width;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int t = ((y + y0) % s->tile_rows) * s->tile_cols + (x + x0) % s->tile_cols;
            double acc1 = 0, acc0 = 0;
            for (int sub = 0; sub < s->nsubframes; sub++) {
                const lm_led *led = &s->leds[lm_system_subframe_led(s, sub)];
                double y_s = 0; /* a_{p,s} . r_p */
                for (int b = 0; b < s->nbins; b++)
                    y_s += s->scale * s->subframe_us * led->gain * s->qe[b] * led->emission[b] *
                           lm_cube_band(c, b)[y * W + x];
                if (lm_system_subframe_code(s, sub, t)) acc1 += y_s;
                else acc0 += y_s;
            }
            b1[y * W + x] = acc1;
            b0[y * W + x] = acc0;
        }
}

static void test_closed_form_equals_subframe_sum(void)
{
    if (!g_ok) return;
    const int H = 7, W = 9;
    lm_cube c;
    random_cube41(&c, H, W, 3);
    float b1[H * W], b0[H * W];
    double r1[H * W], r0[H * W];
    lm_err e;
    lm_err_clear(&e);
    for (int off = 0; off < 2; off++) { /* on the tile grid, and at an odd sensor position */
        int y0 = off ? 4 : 0, x0 = off ? 7 : 0;
        CHECK_MSG(lm_forward_clean(&g_sys, &c, y0, x0, b1, b0, 2, &e) == LM_OK, "%s", e.msg);
        subframe_sum(&g_sys, &c, y0, x0, r1, r0);
        for (int i = 0; i < H * W; i++) {
            CHECK_CLOSE(b1[i], r1[i], 1e-7, 2e-6);
            CHECK_CLOSE(b0[i], r0[i], 1e-6, 2e-6);
        }
    }
    lm_cube_free(&c);
}

static void test_white_and_mirrored(void)
{
    if (!g_ok) return;
    lm_cube c;
    CHECK(lm_cube_alloc(&c, 41, 3, 4, 380, 10) == LM_OK);
    for (long i = 0; i < 41 * 12; i++) c.data[i] = 1.0f;
    float b1[12], b0[12];
    CHECK(lm_forward_clean(&g_sys, &c, 0, 0, b1, b0, 1, NULL) == LM_OK);
    for (int i = 0; i < 12; i++) { /* equal-white: every LED gives 1, bucket 0 the other 11 */
        CHECK_CLOSE(b1[i], 1.0, 1e-5, 0);
        CHECK_CLOSE(b0[i], 11.0, 1e-4, 0);
    }
    lm_cube_free(&c);
    /* a 31-band cube goes through the mirror: Y = sum_b a[b] r31[src(b)] */
    lm_cube c31;
    CHECK(lm_cube_alloc(&c31, 31, 3, 4, 400, 10) == LM_OK);
    lm_rng r;
    lm_rng_seed(&r, 8);
    lm_rng_fill_uniform(&r, c31.data, 31 * 12, 0, 1);
    lm_forward_opts o = {0};
    CHECK(lm_forward_simulate31(&g_sys, &c31, &o, NULL, b1, NULL, NULL) == LM_OK);
    for (int i = 0; i < 12; i++) {
        const float *a = lm_system_response(&g_sys, g_sys.tile_led[i]); /* pixel (i/4, i%4) */
        double want = 0;
        for (int b = 0; b < 41; b++) {
            double wl = 380 + 10 * b, src = wl < 400 ? 800 - wl : (wl > 700 ? 1400 - wl : wl);
            want += a[b] * lm_cube_band(&c31, (int)((src - 400) / 10))[i];
        }
        CHECK_CLOSE(b1[i], want, 1e-6, 1e-5);
    }
    lm_cube_free(&c31);
}

static void test_shape_and_option_errors(void)
{
    if (!g_ok) return;
    lm_cube c;
    float out[16];
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_alloc(&c, 31, 2, 2, 400, 10) == LM_OK);
    CHECK(lm_forward_clean(&g_sys, &c, 0, 0, out, NULL, 1, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "forward: cube has 31 bands"), "%s", e.msg);
    lm_cube_free(&c);
    CHECK(lm_cube_alloc(&c, 41, 2, 2, 390, 10) == LM_OK);
    lm_err_clear(&e);
    CHECK(lm_forward_clean(&g_sys, &c, 0, 0, out, NULL, 1, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "forward: cube band 0 is at 390 nm"), "%s", e.msg);
    lm_cube_free(&c);
    CHECK(lm_cube_alloc(&c, 41, 2, 2, 380, 10) == LM_OK);
    lm_err_clear(&e);
    CHECK(lm_forward_clean(&g_sys, &c, -1, 0, out, NULL, 1, &e) == LM_ERR_ARG);
    c.data[5] = NAN;
    lm_err_clear(&e);
    CHECK(lm_forward_clean(&g_sys, &c, 0, 0, out, NULL, 1, &e) == LM_ERR_NUMERIC);
    CHECK_MSG(strstr(e.msg, "forward:") && strstr(e.msg, "NaN"), "%s", e.msg);
    lm_cube_free(&c);
    lm_cube c31;
    CHECK(lm_cube_alloc(&c31, 41, 2, 2, 380, 10) == LM_OK);
    lm_forward_opts o = {0};
    lm_err_clear(&e);
    CHECK(lm_forward_simulate31(&g_sys, &c31, &o, NULL, out, NULL, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "mirror"), "%s", e.msg);
    lm_cube_free(&c31);
    lm_rng r;
    lm_rng_seed(&r, 1);
    lm_noise_opts n = {.gauss_k = -0.1f};
    lm_err_clear(&e);
    CHECK(lm_forward_noise(out, 4, 4, &n, &r, 1, &e) == LM_ERR_ARG && strstr(e.msg, "forward"));
    n = (lm_noise_opts){.bits = 25};
    CHECK(lm_forward_noise(out, 4, 4, &n, &r, 1, NULL) == LM_ERR_ARG);
    n = (lm_noise_opts){.photons = 100};
    lm_err_clear(&e);
    CHECK(lm_forward_noise(out, 4, 4, &n, NULL, 1, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "random generator"), "%s", e.msg);
    n = (lm_noise_opts){.bits = 8}; /* quantisation alone needs no generator */
    CHECK(lm_forward_noise(out, 4, 4, &n, NULL, 1, NULL) == LM_OK);
}

static void moments(const float *v, long n, double offset, double scale, double *mean,
                    double *var)
{
    double s = 0, s2 = 0;
    for (long i = 0; i < n; i++) {
        double d = (v[i] - offset) * scale;
        s += d;
        s2 += d * d;
    }
    *mean = s / n;
    *var = s2 / n - *mean * *mean;
}

static void test_gaussian_noise_statistics(void)
{
    const int H = 300, W = 300;
    const long n = (long)H * W;
    float *img = malloc(n * sizeof(float));
    for (long i = 0; i < n; i++) img[i] = 0.4f;
    img[0] = 2.0f; /* the max clean value sets sigma = k * 2 */
    lm_rng r;
    lm_rng_seed(&r, 123);
    lm_noise_opts o = {.gauss_k = 0.05f};
    CHECK(lm_forward_noise(img, H, W, &o, &r, 2, NULL) == LM_OK);
    double mean, var;
    moments(img + 1, n - 1, 0.4, 1.0, &mean, &var);
    double sd = 0.1;                             /* 0.05 * 2.0 */
    CHECK_CLOSE(mean, 0.0, 4 * sd / sqrt(n), 0); /* 4 standard errors */
    CHECK_CLOSE(var, sd * sd, 4 * sd * sd * sqrt(2.0 / n), 0);
    /* about 68.3 % within one sigma */
    long inside = 0;
    for (long i = 1; i < n; i++) inside += fabs(img[i] - 0.4) < sd;
    CHECK_CLOSE((double)inside / (n - 1), 0.6827, 0.006, 0);
    free(img);
}

/* Poisson(lambda) counts: integer, mean lambda, variance lambda (4 standard errors). */
static void check_poisson(double lambda, double photons, long n)
{
    float *img = malloc(n * sizeof(float));
    for (long i = 0; i < n; i++) img[i] = (float)(lambda / photons);
    lm_rng r;
    lm_rng_seed(&r, (uint64_t)(lambda * 1000));
    lm_noise_opts o = {.photons = photons};
    CHECK(lm_forward_noise(img, (int)(n / 100), 100, &o, &r, 2, NULL) == LM_OK);
    long nonint = 0;
    for (long i = 0; i < n; i++) {
        double k = img[i] * photons;
        nonint += fabs(k - floor(k + 0.5)) > 1e-3 * (1 + k);
    }
    CHECK_MSG(nonint == 0, "lambda %g: %ld non-integer counts", lambda, nonint);
    double mean, var;
    moments(img, n, 0.0, photons, &mean, &var);
    CHECK_CLOSE(mean, lambda, 4 * sqrt(lambda / n), 0);
    /* var of the sample variance ~ (mu4 - sigma^4) / n = (lambda + 2 lambda^2) / n */
    CHECK_CLOSE(var, lambda, 4 * sqrt((lambda + 2 * lambda * lambda) / n), 0);
    free(img);
}

static void test_poisson_noise_statistics(void)
{
    check_poisson(3.0, 10.0, 200000);     /* multiplication method */
    check_poisson(300.0, 1000.0, 100000); /* transformed rejection */
    check_poisson(25000.0, 50000.0, 40000);
    lm_rng r;
    lm_rng_seed(&r, 2);
    CHECK(lm_forward_poisson(&r, 0.0) == 0.0 && lm_forward_poisson(&r, -3.0) == 0.0);
    /* P(0) for lambda = 0.5 is exp(-0.5) */
    long zeros = 0, n = 100000;
    for (long i = 0; i < n; i++) zeros += lm_forward_poisson(&r, 0.5) == 0.0;
    CHECK_CLOSE((double)zeros / n, exp(-0.5), 4 * sqrt(0.61 * 0.39 / n), 0);
}

/* Histogram of n draws against the Poisson pmf: chi-square below its 99.9 % quantile
 * (Wilson-Hilferty). Cells merge consecutive values until the expected count is >= 5; the last
 * cell takes the whole upper tail. */
static void check_poisson_pmf(double lambda, long n, uint64_t seed)
{
    enum { KMAX = 400 };
    static long hist[KMAX];
    memset(hist, 0, sizeof hist);
    lm_rng r;
    lm_rng_seed(&r, seed);
    for (long i = 0; i < n; i++) {
        double k = lm_forward_poisson(&r, lambda);
        hist[k < KMAX - 1 ? (int)k : KMAX - 1]++;
    }
    double chi2 = 0, o = 0, e = 0, seen_e = 0;
    long seen_o = 0;
    int cells = 0;
    for (int k = 0; k < KMAX; k++) {
        double ek = exp(k * log(lambda) - lambda - lgamma(k + 1.0)) * n;
        o += hist[k], e += ek;
        seen_o += hist[k], seen_e += ek;
        if (e >= 5 && n - seen_e >= 5) {
            chi2 += (o - e) * (o - e) / e;
            cells++;
            o = e = 0;
        } else if (n - seen_e < 5) { /* the tail: the rest of the draws against the rest */
            o += (double)(n - seen_o);
            e += n - seen_e;
            chi2 += (o - e) * (o - e) / e;
            cells++;
            break;
        }
    }
    double d = cells - 1, q = d * pow(1 - 2 / (9 * d) + 3.09 * sqrt(2 / (9 * d)), 3);
    CHECK_MSG(cells > 5 && chi2 < q, "lambda %g: chi-square %.1f with %d cells (99.9 %% "
              "quantile %.1f)", lambda, chi2, cells, q);
}

static void test_poisson_distribution(void)
{
    check_poisson_pmf(4.0, 200000, 1);  /* multiplication method */
    check_poisson_pmf(15.0, 200000, 2); /* transformed rejection */
    check_poisson_pmf(120.0, 200000, 3);
}

static void test_read_noise(void)
{
    const int H = 200, W = 200;
    const long n = (long)H * W;
    float *img = calloc(n, sizeof(float));
    lm_rng r;
    lm_rng_seed(&r, 77);
    /* electrons: 5 e- read noise with 1000 e- at full scale 2.0 -> sd = 5 * 2 / 1000 */
    lm_noise_opts o = {.photons = 1000, .read_noise = 5, .full_scale = 2.0f};
    CHECK(lm_forward_noise(img, H, W, &o, &r, 2, NULL) == LM_OK);
    double mean, var, sd = 0.01;
    moments(img, n, 0, 1, &mean, &var);
    CHECK_CLOSE(mean, 0.0, 4 * sd / sqrt(n), 0);
    CHECK_CLOSE(sqrt(var), sd, 4 * sd / sqrt(2.0 * n), 0);
    /* fraction of full scale without a photon budget */
    memset(img, 0, n * sizeof(float));
    o = (lm_noise_opts){.read_noise = 0.02f, .full_scale = 0.5f};
    CHECK(lm_forward_noise(img, H, W, &o, &r, 2, NULL) == LM_OK);
    moments(img, n, 0, 1, &mean, &var);
    CHECK_CLOSE(sqrt(var), 0.01, 4 * 0.01 / sqrt(2.0 * n), 0);
    free(img);
}

static void test_noise_determinism(void)
{
    const int H = 37, W = 53;
    const long n = (long)H * W;
    float *a = malloc(n * sizeof(float)), *b = malloc(n * sizeof(float));
    float *c = malloc(n * sizeof(float)), *d = malloc(n * sizeof(float));
    lm_noise_opts o = {.gauss_k = 0.1f, .photons = 500, .read_noise = 2, .clip = 1, .bits = 12};
    lm_rng r1, r2, r3;
    lm_rng_seed(&r1, 99);
    lm_rng_seed(&r2, 99);
    lm_rng_seed(&r3, 100);
    for (long i = 0; i < n; i++) a[i] = b[i] = c[i] = (float)(i % 17) / 17.0f;
    CHECK(lm_forward_noise(a, H, W, &o, &r1, 1, NULL) == LM_OK);
    CHECK(lm_forward_noise(b, H, W, &o, &r2, 2, NULL) == LM_OK); /* other thread count */
    CHECK(lm_forward_noise(c, H, W, &o, &r3, 2, NULL) == LM_OK);
    CHECK(memcmp(a, b, n * sizeof(float)) == 0);
    CHECK(memcmp(a, c, n * sizeof(float)) != 0);
    CHECK(memcmp(&r1, &r2, sizeof r1) == 0); /* the generators advanced alike */
    for (long i = 0; i < n; i++) d[i] = (float)(i % 17) / 17.0f;
    CHECK(lm_forward_noise(d, H, W, &o, &r1, 2, NULL) == LM_OK); /* next call: new noise */
    CHECK(memcmp(a, d, n * sizeof(float)) != 0);
    free(a), free(b), free(c), free(d);
}

static void test_quantisation_and_clipping(void)
{
    float v[8] = {0.0f, 0.03f, 0.5f, 0.97f, 1.2f, -0.1f, 0.2f, 1.0f};
    /* 4 bits: L = 15 levels; round(v * 15) clamped to 0..15, back to v */
    const float want[8] = {0, 0, 8 / 15.0f, 1, 1, 0, 3 / 15.0f, 1};
    lm_noise_opts o = {.bits = 4};
    CHECK(lm_forward_noise(v, 2, 4, &o, NULL, 1, NULL) == LM_OK);
    CHECK_ARRAY_CLOSE(v, want, 8, 1e-7, 0);
    /* full scale 2: codes of 2/15 */
    float u[4] = {0.5f, 1.9f, 2.5f, 0.07f}, wu[4] = {4 * 2 / 15.0f, 14 * 2 / 15.0f, 2, 2 / 15.0f};
    o.full_scale = 2.0f;
    CHECK(lm_forward_noise(u, 1, 4, &o, NULL, 1, NULL) == LM_OK);
    CHECK_ARRAY_CLOSE(u, wu, 4, 1e-6, 0);
    /* 16 bits: every output is k / 65535 and within half a level of the input */
    lm_rng r;
    lm_rng_seed(&r, 4);
    float in[1000], q[1000];
    lm_rng_fill_uniform(&r, in, 1000, 0, 1);
    memcpy(q, in, sizeof in);
    o = (lm_noise_opts){.bits = 16};
    CHECK(lm_forward_noise(q, 10, 100, &o, NULL, 2, NULL) == LM_OK);
    for (int i = 0; i < 1000; i++) {
        double k = q[i] * 65535.0;
        CHECK(fabs(k - floor(k + 0.5)) < 1e-2);
        CHECK(fabs(q[i] - in[i]) <= 0.5 / 65535 + 1e-7);
    }
    /* clipping with strong noise stays in [0, full scale]; without it, it does not */
    float w[400], w2[400];
    for (int i = 0; i < 400; i++) w[i] = w2[i] = 0.5f;
    o = (lm_noise_opts){.gauss_k = 1.0f, .clip = 1};
    CHECK(lm_forward_noise(w, 20, 20, &o, &r, 1, NULL) == LM_OK);
    o.clip = 0;
    CHECK(lm_forward_noise(w2, 20, 20, &o, &r, 1, NULL) == LM_OK);
    int in_range = 1, outside = 0;
    for (int i = 0; i < 400; i++) {
        in_range &= w[i] >= 0.0f && w[i] <= 1.0f;
        outside += w2[i] < 0.0f || w2[i] > 1.0f;
    }
    CHECK(in_range && outside > 0);
}

/* Full well: electrons beyond full scale saturate before read noise is added, so a pixel at
 * full scale ends exactly at full scale (after the final clip) with probability
 * sum_k P(k) P(min(k, 100) + 3 z > 100) for 100 e- at full scale and 3 e- read noise. */
static void test_full_well_before_read_noise(void)
{
    const long n = 40000;
    float *s = malloc(n * sizeof(float));
    for (long i = 0; i < n; i++) s[i] = 1.0f;
    lm_rng r;
    lm_rng_seed(&r, 31);
    lm_noise_opts o = {.photons = 100, .read_noise = 3, .clip = 1};
    CHECK(lm_forward_noise(s, 200, 200, &o, &r, 2, NULL) == LM_OK);
    long at_fs = 0;
    float lo = 1.0f;
    for (long i = 0; i < n; i++) {
        at_fs += s[i] == 1.0f;
        lo = s[i] < lo ? s[i] : lo;
    }
    double p = 0;
    for (int k = 0; k < 400; k++) {
        double pk = exp(k * log(100.0) - 100.0 - lgamma(k + 1.0));
        double kk = k < 100 ? k : 100;
        p += pk * 0.5 * erfc((100.0 - kk) / 3.0 / sqrt(2.0));
    }
    CHECK_CLOSE((double)at_fs / n, p, 4 * sqrt(p * (1 - p) / n), 0);
    CHECK(lo >= 0.0f && lo < 0.8f);
    free(s);
}

/* Bucket 0's noise (lm_forward_bucket0_noise): its full scale is (LEDs - 1) x bucket 1's, so a
 * white frame is neither clipped nor quantised away at bucket 1's full well; shot noise has the
 * same signal per photo-electron (variance = v x fs / photons) and read noise the same sd. */
static void test_bucket0_noise(void)
{
    if (!g_ok) return;
    const int H = 60, W = 80;
    const long n = (long)H * W;
    lm_cube c;
    CHECK(lm_cube_alloc(&c, 41, H, W, 380, 10) == LM_OK);
    for (long i = 0; i < 41 * n; i++) c.data[i] = 0.5f;
    float *b1 = malloc(sizeof(float) * n), *b0 = malloc(sizeof(float) * n);
    lm_noise_opts base = {.clip = 1, .bits = 16};
    lm_noise_opts z = lm_forward_bucket0_noise(&base, g_sys.nleds);
    CHECK(z.full_scale == 11.0f && z.clip && z.bits == 16 && z.photons == 0.0);
    lm_forward_opts o = {.noise = base, .nthreads = 2};
    lm_rng r;
    lm_rng_seed(&r, 3);
    CHECK(lm_forward_simulate(&g_sys, &c, &o, &r, b1, b0, NULL) == LM_OK);
    for (long i = 0; i < n; i += 97) {
        CHECK_CLOSE(b1[i], 0.5, 1e-4, 0);
        CHECK_CLOSE(b0[i], 5.5, 11.0 / 65535, 0); /* 16-bit steps of 11, not clipped at 1 */
    }
    /* shot + read noise: variance 5.5 / photons x 1 (per electron) + read^2, as bucket 1's */
    lm_noise_opts sn = {.photons = 2000, .read_noise = 3};
    o.noise = sn;
    CHECK(lm_forward_simulate(&g_sys, &c, &o, &r, b1, b0, NULL) == LM_OK);
    double m0, v0, m1, v1;
    moments(b0, n, 0.0, 1.0, &m0, &v0);
    moments(b1, n, 0.0, 1.0, &m1, &v1);
    const double e = 1.0 / 2000, want0 = 5.5 * e + 9 * e * e, want1 = 0.5 * e + 9 * e * e;
    CHECK_CLOSE(m0, 5.5, 5 * sqrt(want0 / n), 0);
    CHECK_CLOSE(v0, want0, 0.06 * want0, 0);
    CHECK_CLOSE(v1, want1, 0.06 * want1, 0);
    /* read noise as a fraction of the full scale (no photons): the same absolute sd */
    lm_noise_opts rf = {.read_noise = 0.01f};
    o.noise = rf;
    CHECK(lm_forward_simulate(&g_sys, &c, &o, &r, b1, b0, NULL) == LM_OK);
    moments(b0, n, 0.0, 1.0, &m0, &v0);
    CHECK_CLOSE(sqrt(v0), 0.01, 0.05 * 0.01, 0);
    free(b1), free(b0);
    lm_cube_free(&c);
}

static void test_full_frame_speed(void)
{
    if (!g_ok) return;
    lm_cube c;
    random_cube41(&c, 480, 640, 9);
    float *b1 = malloc(480 * 640 * sizeof(float)), *b0 = malloc(480 * 640 * sizeof(float));
    lm_forward_opts o = {.noise = {.gauss_k = 0.05f, .photons = 20000, .bits = 16, .clip = 1}};
    lm_rng r;
    lm_rng_seed(&r, 1);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    CHECK(lm_forward_simulate(&g_sys, &c, &o, &r, b1, b0, NULL) == LM_OK);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("     640 x 480 frame, both buckets, with noise: %.1f ms\n",
           (t1.tv_sec - t0.tv_sec) * 1e3 + (t1.tv_nsec - t0.tv_nsec) * 1e-6);
    free(b1), free(b0);
    lm_cube_free(&c);
}

int main(void)
{
    lm_err_clear(&g_err);
    g_ok = lm_system_default(&g_sys, &g_err) == LM_OK;
    RUN(test_default_system_loads);
    RUN(test_closed_form_equals_subframe_sum);
    RUN(test_white_and_mirrored);
    RUN(test_shape_and_option_errors);
    RUN(test_gaussian_noise_statistics);
    RUN(test_poisson_noise_statistics);
    RUN(test_poisson_distribution);
    RUN(test_read_noise);
    RUN(test_noise_determinism);
    RUN(test_quantisation_and_clipping);
    RUN(test_full_well_before_read_noise);
    RUN(test_bucket0_noise);
    RUN(test_full_frame_speed);
    lm_system_free(&g_sys);
    return check_summary();
}
