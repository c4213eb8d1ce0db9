/* test_doe.c — the DOE optics of the QDO baseline (data/doe.h): Parseval in the Fresnel
 * transform, an ideal thin lens focusing to a diffraction-limited spot (FWHM vs 1.03 lambda f/D),
 * quantisation converging to the continuous PSF and costing the expected efficiency, the
 * chromatic focal shift of a diffractive lens, the bundled default, and bad fields.
 * Not here: the camera convolution (test_qdocam.c). */
#include "data/doe.h"
#include "data/image.h"
#include <unistd.h>
#include "tests/check.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A small lens for tests: D = 0.4 mm, dx = 2 um, N = 1024, f = z = 10 mm at 550 nm, 8 um
 * sensor pixels (so that 1024 samples satisfy the sampling rule). */
static const char *const base_keys[] = {
    "version", "aperture_mm", "doe_pitch_um", "grid", "levels", "material", "profile",
    "sensor_distance_mm", "sensor_pitch_um", "psf_size", NULL};
static const char *const base_vals[] = {
    "1", "0.4", "2", "1024", "0", "\"fused_silica\"",
    "{\"type\": \"fresnel_lens\", \"focal_mm\": 10, \"design_nm\": 550}", "10", "8", "15"};

/* The base description with `key` set to `val` (NULL val: key removed; a new key is added). */
static void make_json(char *out, size_t n, const char *key, const char *val)
{
    size_t len = (size_t)snprintf(out, n, "{");
    int found = 0;
    for (int i = 0; base_keys[i]; i++) {
        const char *v = base_vals[i];
        if (key && strcmp(key, base_keys[i]) == 0) {
            found = 1;
            if (!val) continue;
            v = val;
        }
        len += (size_t)snprintf(out + len, n - len, "%s\"%s\": %s", len > 1 ? ", " : "",
                                base_keys[i], v);
    }
    if (key && !found && val) len += (size_t)snprintf(out + len, n - len, ", \"%s\": %s", key, val);
    snprintf(out + len, n - len, "}");
}

static int load_lens(lm_doe *d, int levels)
{
    char js[2048], lv[16];
    snprintf(lv, sizeof lv, "%d", levels);
    make_json(js, sizeof js, "levels", lv);
    lm_err e = {0};
    lm_status st = lm_doe_parse(js, "test", d, &e);
    CHECK_MSG(st == LM_OK, "%s", e.msg);
    return st == LM_OK;
}

static void test_parseval(void)
{
    lm_doe d;
    if (!load_lens(&d, 8)) return;
    size_t N = (size_t)d.grid;
    float *I = malloc(N * N * sizeof(float));
    double du, energy, sum = 0;
    lm_err e = {0};
    CHECK(lm_doe_fresnel(&d, 480e-9, I, &du, &energy, &e) == LM_OK);
    for (size_t k = 0; k < N * N; k++) sum += I[k];
    long inside = 0;
    for (int k = 0; k < d.m * d.m; k++) inside += d.mask[k];
    CHECK_CLOSE(energy, (double)inside, 0, 1e-12);
    CHECK_CLOSE(sum, energy, 0, 1e-4);
    CHECK_CLOSE(du, 480e-9 * 10e-3 / (1024 * 2e-6), 0, 1e-12);
    printf("parseval: sum |U|^2 = %.6g, pupil energy = %.6g\n", sum, energy);
    free(I);
    lm_doe_free(&d);
}

/* Full width at half maximum of row y of an N x N image, in samples (linear interpolation of
 * the two half-maximum crossings around the peak at column c). */
static double fwhm_row(const float *I, int N, int y, int c, int stride)
{
    const float *r = I + (size_t)y * (stride == 1 ? N : 1);
#define AT(k) r[(size_t)(k) * stride]
    double half = 0.5 * AT(c);
    int a = c, b = c;
    while (a > 0 && AT(a - 1) > half) a--;
    while (b < N - 1 && AT(b + 1) > half) b++;
    double left = (a - 1) + (half - AT(a - 1)) / (AT(a) - AT(a - 1));
    double right = b + (AT(b) - half) / (AT(b) - AT(b + 1));
#undef AT
    return right - left;
}

static void test_focus_fwhm(void)
{
    lm_doe d;
    if (!load_lens(&d, 0)) return;
    int N = d.grid;
    float *I = malloc((size_t)N * N * sizeof(float));
    double du, lambda = 550e-9;
    lm_err e = {0};
    CHECK(lm_doe_fresnel(&d, lambda, I, &du, NULL, &e) == LM_OK);
    size_t best = 0;
    for (size_t k = 0; k < (size_t)N * N; k++) if (I[k] > I[best]) best = k;
    CHECK(best == (size_t)(N / 2) * N + N / 2); /* focused on axis */
    double fx = fwhm_row(I, N, N / 2, N / 2, 1) * du, fy = fwhm_row(I, N, N / 2, N / 2, N) * du;
    double theory = 1.029 * lambda * 10e-3 / 0.4e-3;
    printf("focus: FWHM x %.3f um, y %.3f um, theory 1.03 lambda f / D = %.3f um (du %.3f um)\n",
           fx * 1e6, fy * 1e6, theory * 1e6, du * 1e6);
    CHECK_CLOSE(fx, theory, 0, 0.10);
    CHECK_CLOSE(fy, theory, 0, 0.10);
    free(I);
    lm_doe_free(&d);
}

static void test_quantisation(void)
{
    lm_doe d;
    if (!load_lens(&d, 0)) return;
    int S2 = d.psf_size * d.psf_size, N = d.grid;
    float *ref = malloc((size_t)S2 * sizeof(float)), *q = malloc((size_t)S2 * sizeof(float));
    float *I = malloc((size_t)N * N * sizeof(float));
    lm_err e = {0};
    CHECK(lm_doe_psf(&d, 550e-9, ref, &e) == LM_OK);
    CHECK(lm_doe_fresnel(&d, 550e-9, I, NULL, NULL, &e) == LM_OK);
    double peak0 = I[(size_t)(N / 2) * N + N / 2], prev = 1e9;
    static const int levels[] = {2, 4, 8, 16, 64};
    for (int t = 0; t < 5; t++) {
        int L = levels[t];
        d.levels = L;
        CHECK(lm_doe_build_height(&d, &e) == LM_OK);
        CHECK(lm_doe_psf(&d, 550e-9, q, &e) == LM_OK);
        CHECK(lm_doe_fresnel(&d, 550e-9, I, NULL, NULL, &e) == LM_OK);
        double l1 = 0, s = sin(M_PI / L) / (M_PI / L);
        for (int k = 0; k < S2; k++) l1 += fabs(q[k] - ref[k]);
        double eff = I[(size_t)(N / 2) * N + N / 2] / peak0;
        printf("quantisation L = %2d: L1 to continuous PSF %.4f, peak / continuous %.3f "
               "(sinc^2(1/L) = %.3f)\n", L, l1, eff, s * s);
        CHECK(l1 < prev); /* converges as L grows */
        CHECK_CLOSE(eff, s * s, 0.03, 0);
        prev = l1;
    }
    CHECK(prev < 0.02);
    free(ref);
    free(q);
    free(I);
    lm_doe_free(&d);
}

/* z (metres) of the largest on-axis intensity density at a wavelength, scanning 5..18 mm. */
static double best_focus(lm_doe *d, double lambda)
{
    int N = d->grid;
    float *I = malloc((size_t)N * N * sizeof(float));
    double best = 0, zbest = 0, du;
    lm_err e = {0};
    for (double z = 5e-3; z <= 18e-3; z += 0.05e-3) {
        d->distance_m = z;
        CHECK(lm_doe_fresnel(d, lambda, I, &du, NULL, &e) == LM_OK);
        double v = I[(size_t)(N / 2) * N + N / 2] / (du * du);
        if (v > best) best = v, zbest = z;
    }
    free(I);
    return zbest;
}

static void test_chromatic_focus(void)
{
    lm_doe d;
    if (!load_lens(&d, 0)) return;
    d.grid = 256; /* on-axis values only: the aperture (201 samples) fits */
    double z[3], l[3] = {450e-9, 550e-9, 650e-9};
    for (int i = 0; i < 3; i++) {
        z[i] = best_focus(&d, l[i]);
        double expect = 10e-3 * 550e-9 / l[i];
        printf("chromatic: best focus at %.0f nm: %.2f mm (diffractive lens f0 l0 / l = %.2f mm)\n",
               l[i] * 1e9, z[i] * 1e3, expect * 1e3);
        CHECK_CLOSE(z[i], expect, 0, 0.04);
    }
    CHECK(z[0] > z[1] && z[1] > z[2]);
    lm_doe_free(&d);
}

static void test_default(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK_MSG(lm_doe_default(&d, &e) == LM_OK, "%s", e.msg);
    if (e.status) return;
    CHECK(d.levels == 8 && d.psf_size == 63 && d.grid == 1536);
    CHECK_CLOSE(lm_doe_index(&d, 587.6e-9), 1.4585, 2e-4, 0); /* fused silica n_d */
    int S = d.psf_size, S2 = S * S;
    float *psf = malloc((size_t)3 * S2 * sizeof(float));
    CHECK(lm_doe_psfs(&d, 400, 150, 3, psf, &e) == LM_OK); /* 400, 550, 700 nm */
    double pk[3];
    for (int b = 0; b < 3; b++) {
        double sum = 0;
        pk[b] = 0;
        for (int k = 0; k < S2; k++) {
            sum += psf[b * S2 + k];
            if (psf[b * S2 + k] > pk[b]) pk[b] = psf[b * S2 + k];
        }
        CHECK_CLOSE(sum, 1.0, 1e-5, 0);
        if (b == 1) CHECK(psf[b * S2 + S2 / 2] == pk[b]); /* in focus, on axis */
    }
    printf("default: PSF peak 400 / 550 / 700 nm: %.4f / %.4f / %.4f\n", pk[0], pk[1], pk[2]);
    CHECK(pk[1] > 20 * pk[0] && pk[1] > 20 * pk[2]); /* sharp at the design wavelength only */
    free(psf);
    lm_doe_free(&d);
}

static void test_bad_fields(void)
{
    static const struct { const char *key, *val, *want; } cases[] = {
        {"grid", NULL, "grid: missing"},
        {"levels", "1", "levels:"},
        {"psf_size", "4", "psf_size: must be odd"},
        {"material", "{\"model\": \"glass\"}", "material.model: unknown model"},
        {"material", "{\"model\": \"cauchy\", \"A\": 1.45}", "material.B_um2"},
        {"foo", "1", "foo: unknown field"},
        {"version", "2", "version: unsupported"},
        {"grid", "256", "grid: too small"},
        {"aperture_mm", "-1", "aperture_mm: must be a positive"},
        {"aperture_mm", "3", "aperture_mm: the aperture spans"},
        {"aperture_mm", "100000000", "aperture_mm: the aperture spans"}, /* no int overflow */
        {"profile", "{\"type\": \"cubic\", \"focal_mm\": 10, \"design_nm\": 550}", "profile.type"},
        {"psf_size", "255", "psf_size: the PSF window"},
        {"sensor_pitch_um", "\"8\"", "sensor_pitch_um: must be a positive"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char js[2048];
        make_json(js, sizeof js, cases[i].key, cases[i].val);
        lm_doe d;
        lm_err e = {0};
        lm_status st = lm_doe_parse(js, "bad.json", &d, &e);
        CHECK_MSG(st == LM_ERR_FORMAT, "case %zu accepted", i);
        CHECK_MSG(strstr(e.msg, cases[i].want) && strstr(e.msg, "doe file bad.json: ") &&
                  !strchr(e.msg, '\n'), "case %zu: '%s' lacks '%s'", i, e.msg, cases[i].want);
        CHECK(d.height == NULL);
    }
    lm_doe d;
    lm_err e = {0};
    CHECK(lm_doe_load("/nonexistent/qdo.json", &d, &e) == LM_ERR_IO);
    CHECK(strstr(e.msg, "/nonexistent/qdo.json") != NULL);
    CHECK(lm_doe_parse("{\"version\": 1,", "trunc.json", &d, &e) == LM_ERR_FORMAT);
}

/* A DOE written as a height map (lm_doe_save) reads back with the same heights and PSFs; a
 * map of the wrong size, a missing or non-PNG file, and bad profile fields fail with one line. */
static void test_height_map_round_trip(void)
{
    lm_doe d, r;
    if (!load_lens(&d, 8)) return;
    char dir[] = "/tmp/lm_doe_hm_XXXXXX", js[256], png[256];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(js, sizeof js, "%s/learned.json", dir);
    snprintf(png, sizeof png, "%s/learned_heights.png", dir);
    lm_err e = {0};
    CHECK_MSG(lm_doe_save(&d, js, "learned_heights.png", &e) == LM_OK, "%s", e.msg);
    CHECK_MSG(lm_doe_load(js, &r, &e) == LM_OK, "%s", e.msg);
    if (r.height) {
        CHECK(r.height_map == 1 && r.m == d.m && r.levels == 8);
        CHECK_CLOSE(r.max_height_m, d.max_height_m, 0, 1e-12);
        CHECK_ARRAY_CLOSE(r.height, d.height, (long)d.m * d.m, 1e-12, 1e-6);
        int S = d.psf_size;
        float *a = malloc((size_t)S * S * sizeof(float)), *b = malloc((size_t)S * S * sizeof(float));
        CHECK(lm_doe_psf(&d, 470e-9, a, &e) == LM_OK && lm_doe_psf(&r, 470e-9, b, &e) == LM_OK);
        CHECK_ARRAY_CLOSE(b, a, S * S, 1e-6, 1e-4);
        free(a), free(b);
        lm_doe_free(&r);
    }
    /* a map of the wrong size */
    float v[9] = {0, 0.5f, 0.25f, 0, 0, 0, 0, 0, 1};
    CHECK(lm_image_write_gray16(png, 3, 3, v, &e) == LM_OK);
    e = (lm_err){0};
    CHECK(lm_doe_load(js, &r, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "3 x 3 x 1; this DOE needs 203 x 203") != NULL, "%s", e.msg);
    CHECK(!strchr(e.msg, '\n'));
    remove(png);
    e = (lm_err){0};
    CHECK(lm_doe_load(js, &r, &e) != LM_OK && strstr(e.msg, "learned_heights.png"));
    /* profile fields */
    char txt[2048];
    make_json(txt, sizeof txt, "profile", "{\"type\": \"height_map\"}");
    e = (lm_err){0};
    CHECK(lm_doe_parse(txt, "t", &r, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "profile.file"), "%s", e.msg);
    make_json(txt, sizeof txt, "profile", "{\"type\": \"height_map\", \"file\": \"a.png\", "
              "\"focal_mm\": 3}");
    e = (lm_err){0};
    CHECK(lm_doe_parse(txt, "t", &r, &e) == LM_ERR_FORMAT && strstr(e.msg, "profile.focal_mm"));
    make_json(txt, sizeof txt, "profile", "{\"type\": \"zone_plate\"}");
    e = (lm_err){0};
    CHECK(lm_doe_parse(txt, "t", &r, &e) == LM_ERR_FORMAT && strstr(e.msg, "profile.type"));
    remove(js);
    rmdir(dir);
    lm_doe_free(&d);
}

/* The quantisation rule: wrap into [0, 1), nearest level, the top level wraps to 0. */
static void test_quantise(void)
{
    CHECK(lm_doe_quantise(0.06, 8) == 0.0);
    CHECK(lm_doe_quantise(0.07, 8) == 0.125);
    CHECK(lm_doe_quantise(0.5, 8) == 0.5);
    CHECK(lm_doe_quantise(0.95, 8) == 0.0);           /* nearest is 1 = a full period */
    CHECK(lm_doe_quantise(-0.1, 8) == 0.875);         /* wrapped first */
    CHECK(lm_doe_quantise(2.3, 4) == 0.25);
    CHECK_CLOSE(lm_doe_quantise(1.3, 0), 0.3, 1e-12, 0);
    CHECK(lm_doe_quantise(-1e-20, 0) == 0.0);         /* 1 - 1e-20 rounds to 1: wraps */
    CHECK(lm_doe_quantise(NAN, 8) == 0.0);
    for (int L = 2; L <= 16; L *= 2)
        for (double v = -2; v < 2; v += 0.013) {
            double q = lm_doe_quantise(v, L), k = q * L;
            CHECK(q >= 0 && q < 1 && fabs(k - round(k)) < 1e-12);
            double d = fabs(v - floor(v) - q); /* at most half a level away, modulo the period */
            CHECK(fmin(d, 1 - d) <= 0.5 / L + 1e-12);
        }
}

int main(void)
{
    RUN(test_parseval);
    RUN(test_focus_fwhm);
    RUN(test_quantisation);
    RUN(test_chromatic_focus);
    RUN(test_default);
    RUN(test_bad_fields);
    RUN(test_height_map_round_trip);
    RUN(test_quantise);
    return check_summary();
}
