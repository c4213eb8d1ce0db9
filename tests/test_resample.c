/* test_resample.c — cubes on other wavelength grids read onto 31 bands 400-700 nm (resample.h).
 * Synthetic cubes of a known smooth spectrum s(lambda) x a per-pixel gain on each grid (KAUST
 * .mat v5 `hsi` 34 bands 400-730 nm in 12-bit counts; Harvard `ref` 420-720 nm; ICVL-like `rad`
 * 519 bands 400-1000 nm with `bands`; a 61-band 5 nm EXR; sidecar wavelength lists) must come
 * back within TOL of the analytic band means (the mean of s, mirrored about the source's first
 * and last band, over [c - 5, c + 5]); 31-band 400-700 and 41-bin 380-780 cubes unchanged bit for
 * bit; narrow cubes, bad wavelength lists and wrong keys refused with one-line errors.
 * What it is not: the format readers' own tests (test_cube_io.c). */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/fixture.h"
#include "data/cube_io.h"
#include "data/resample.h"
#include <math.h>
#include <matio.h>
#include <stdlib.h>
#include <string.h>

#define H 3
#define W 4
/* Worst errors measured (each case prints its own): 1.3e-5 (519 bands), 9.5e-4 (5 nm),
 * 1.6e-3 / 1.9e-3 (10 nm KAUST with 12-bit counts / Harvard: their bands are point samples of
 * s, not bin means: s'' x 100 / 24), 5.9e-3 (12.5 nm, coarser than the grid: linear
 * interpolation adds s'' x h^2 / 8). Values are around 0.5. */
#define TOL 3e-3
#define TOL_COARSE 8e-3

/* The source's first and last wavelengths: the spectrum of each case is symmetric about both,
 * so mirroring it there (as the reader does) extends it exactly and the analytic band means
 * are those of the spectrum itself. */
static double span_lo = 400.0, span_hi = 700.0;

static void span(double lo, double hi) { span_lo = lo, span_hi = hi; }

static double spectrum(double nm)
{
    double t = 2.0 * M_PI * (nm - span_lo) / (span_hi - span_lo);
    return 0.55 + 0.25 * cos(t) + 0.1 * cos(2.0 * t) + 0.05 * cos(3.0 * t);
}

static double gain(int y, int x) { return 0.6 + 0.1 * y + 0.05 * x; }

/* The mean over [c - 5, c + 5] of s mirrored about lo and hi (Simpson, 2000 intervals). */
static double band_mean(double c, double lo, double hi)
{
    const int n = 2000;
    double a = c - 5.0, h = 10.0 / n, sum = 0.0;
    for (int i = 0; i <= n; i++) {
        double x = a + h * i;
        x = x < lo ? 2.0 * lo - x : x > hi ? 2.0 * hi - x : x;
        sum += spectrum(x) * (i == 0 || i == n ? 1.0 : i % 2 ? 4.0 : 2.0);
    }
    return sum * h / 3.0 / 10.0;
}

/* Worst |read - expected| over the cube (expected: band means x gain, x scale). */
static double worst_error(const lm_cube *c, double scale)
{
    double lo = span_lo, hi = span_hi;
    double worst = 0.0;
    for (int b = 0; b < c->bands; b++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                double want = band_mean(400.0 + 10.0 * b, lo, hi) * gain(y, x) * scale;
                double d = fabs(lm_cube_band(c, b)[y * W + x] - want);
                if (d > worst || isnan(d)) worst = isnan(d) ? INFINITY : d;
            }
    return worst;
}

static int on_grid31(const lm_cube *c)
{
    if (c->bands != 31 || c->height != H || c->width != W) return 0;
    for (int b = 0; b < 31; b++)
        if (c->wavelength[b] != 400.0f + 10.0f * b) return 0;
    return 1;
}

/* Read path onto the grid (o NULL: the defaults) and compare it with the band means of the
 * current span x scale: prints the worst error, checks it against tol. 1 if the cube is on the
 * grid (*c then holds it, to free), else 0 (nothing to free). */
static int read_close(const char *path, const lm_cube_read_opts *o, double scale, double tol,
                      const char *label, lm_cube *c)
{
    lm_err e = {0};
    CHECK_MSG(lm_cube_read_with(path, o, c, &e) == LM_OK, "%s: %s", label, e.msg);
    if (!on_grid31(c)) {
        CHECK_MSG(0, "%s: not read onto 31 bands 400-700 nm", label);
        lm_cube_free(c);
        return 0;
    }
    double err = worst_error(c, scale);
    printf("  %s: worst error %.2e\n", label, err);
    CHECK_MSG(err < tol, "%s: worst error %.2e, over %.1e", label, err, tol);
    return 1;
}

/* values(y, x, b) = s(wl[b]) x gain x scale, column-major H x W x B, as double or uint16 counts */
static void *make_values(const double *wl, int B, double scale, int counts)
{
    size_t n = (size_t)H * W * B;
    void *d = malloc(n * (counts ? sizeof(uint16_t) : sizeof(double)));
    for (int b = 0; b < B && d; b++)
        for (int x = 0; x < W; x++)
            for (int y = 0; y < H; y++) {
                double v = spectrum(wl[b]) * gain(y, x) * scale;
                size_t i = (size_t)y + H * ((size_t)x + W * b);
                if (counts) ((uint16_t *)d)[i] = (uint16_t)lround(v);
                else ((double *)d)[i] = v;
            }
    return d;
}

/* A .mat (v5) with the cube variable `key` and, if wl_key, a wavelength variable. */
static void write_mat(const char *path, const char *key, const double *wl, int B, int counts,
                      const char *wl_key, const double *wl_var, int n_wl)
{
    void *d = make_values(wl, B, counts ? 4095.0 : 1.0, counts);
    mat_t *m = Mat_CreateVer(path, NULL, MAT_FT_MAT5);
    size_t dims[3] = {H, W, (size_t)B};
    matvar_t *v = Mat_VarCreate(key, counts ? MAT_C_UINT16 : MAT_C_DOUBLE,
                                counts ? MAT_T_UINT16 : MAT_T_DOUBLE, 3, dims, d, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_ZLIB);
    Mat_VarFree(v);
    if (wl_key) {
        size_t wd[2] = {1, (size_t)n_wl};
        v = Mat_VarCreate(wl_key, MAT_C_DOUBLE, MAT_T_DOUBLE, 2, wd, (void *)wl_var, 0);
        Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
        Mat_VarFree(v);
    }
    Mat_Close(m);
    free(d);
}

/* A regular grid, which also sets the span of the spectrum. */
static void grid(double *wl, int n, double start, double step)
{
    for (int i = 0; i < n; i++) wl[i] = start + step * i;
    span(wl[0], wl[n - 1]);
}

static void write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (f) {
        fputs(text, f);
        fclose(f);
    }
}

/* A spectral EXR of B bands at wl (values s x gain). */
static void write_exr(const char *path, const double *wl, int B)
{
    lm_cube c;
    lm_err e = {0};
    CHECK(lm_cube_alloc(&c, B, H, W, 0.0f, 0.0f) == LM_OK);
    for (int b = 0; b < B; b++) {
        c.wavelength[b] = (float)wl[b];
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                lm_cube_band(&c, b)[y * W + x] = (float)(spectrum(wl[b]) * gain(y, x));
    }
    CHECK_MSG(lm_cube_write_exr(path, &c, &e) == LM_OK, "%s", e.msg);
    lm_cube_free(&c);
}

/* A .mat of B bands start + i * step (`wl_key` holding them, if not NULL; counts: KAUST's
 * 12-bit) at tmpdir/file (into p), read back with read_close. */
static int mat_case(char *p, const char *file, const char *key, int B, double start,
                    double step, int counts, const char *wl_key, double tol, lm_cube *c)
{
    double wl[LM_RESAMPLE_MAX_BANDS];
    grid(wl, B, start, step);
    write_mat(tpath(p, file), key, wl, B, counts, wl_key, wl, B);
    char label[128];
    snprintf(label, sizeof label, "%s '%s' %d bands %g-%g nm%s", file, key, B, wl[0],
             wl[B - 1], counts ? ", 12-bit counts" : "");
    return read_close(p, NULL, 1.0, tol, label, c);
}

static void test_kaust(void)
{
    char p[1024];
    lm_cube c, n;
    lm_err e = {0};
    if (!mat_case(p, "kaust.mat", "hsi", 34, 400.0, 10.0, 1, NULL, TOL, &c)) return;
    /* the first 31 bands of the file, bit for bit */
    CHECK_MSG(lm_cube_read_mat(p, &n, &e) == LM_OK, "%s", e.msg);
    CHECK(n.bands == 34 && n.wavelength[33] == 730.0f);
    if (n.bands == 34) CHECK(memcmp(c.data, n.data, sizeof(float) * 31 * H * W) == 0);
    lm_cube_free(&n);
    lm_cube_free(&c);
}

static void test_harvard(void)
{
    char p[1024];
    lm_cube c;
    if (!mat_case(p, "harvard.mat", "ref", 31, 420.0, 10.0, 0, NULL, TOL, &c)) return;
    /* mirrored edge: 400 <- 440, 410 <- 430 (copies); 420..700 are the file's bands */
    size_t np = (size_t)H * W;
    CHECK(memcmp(lm_cube_band(&c, 0), lm_cube_band(&c, 4), np * sizeof(float)) == 0);
    CHECK(memcmp(lm_cube_band(&c, 1), lm_cube_band(&c, 3), np * sizeof(float)) == 0);
    lm_cube_free(&c);
}

static void test_icvl_519(void)
{
    char p[1024];
    lm_cube c;
    lm_err e = {0};
    if (mat_case(p, "icvl.mat", "rad", 519, 400.0, 600.0 / 518.0, 0, "bands", 1e-4, &c))
        lm_cube_free(&c);
    /* too many bands for a cube kept as read */
    CHECK(lm_cube_read_mat(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "icvl.mat", "519 bands");
}

/* An EXR of B bands start + i * step at tmpdir/file (its path into p). */
static const char *exr_grid(char *p, const char *file, int B, double start, double step)
{
    double wl[LM_CUBE_MAX_BANDS];
    grid(wl, B, start, step);
    write_exr(tpath(p, file), wl, B);
    return p;
}

static void test_exr_5nm(void)
{
    char p[1024];
    exr_grid(p, "five.exr", 61, 400.0, 5.0);
    lm_cube c;
    if (read_close(p, NULL, 1.0, TOL, "EXR 61 bands 400-700 nm at 5 nm", &c)) lm_cube_free(&c);
}

static void test_sidecars(void)
{
    char p[1024], q[1024];
    double wl[26];
    grid(wl, 26, 395.0, 12.5); /* 395 .. 707.5 nm */
    write_mat(tpath(p, "side.mat"), "data", wl, 26, 0, NULL, NULL, 0);
    lm_cube c;
    lm_err e = {0};
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT); /* 26 bands, no list */
    CHECK_ERR(e, LM_ERR_FORMAT, "side.mat", "26 bands and no wavelength list");
    lm_err_clear(&e);
    char text[2048] = "# 26 bands, 12.5 nm\n";
    for (int i = 0; i < 26; i++)
        snprintf(text + strlen(text), sizeof text - strlen(text), "%g%s", wl[i],
                 i % 5 == 4 ? "\n" : ", ");
    write_text(tpath(q, "side.mat.wavelengths.txt"), text);
    if (read_close(p, NULL, 1.0, TOL_COARSE, "sidecar .txt, 26 bands 395-707.5 nm", &c))
        lm_cube_free(&c);
    /* a JSON sidecar on an EXR replaces the channel wavelengths (here: the same list) */
    double w5[61];
    grid(w5, 61, 400.0, 5.0);
    write_exr(tpath(p, "side.exr"), w5, 61);
    char js[2048] = "{\"wavelengths\": [";
    for (int i = 0; i < 61; i++)
        snprintf(js + strlen(js), sizeof js - strlen(js), "%s%g", i ? ", " : "", w5[i]);
    strcat(js, "]}");
    write_text(tpath(q, "side.exr.wavelengths.json"), js);
    if (read_close(p, NULL, 1.0, TOL, "sidecar .json on a 5 nm EXR", &c)) lm_cube_free(&c);
}

/* 31 bands 400-700 nm (EXR, .mat without a list) and the 41 bins 380-780 nm: bit for bit. */
static void test_on_grid_unchanged(void)
{
    char p[1024];
    double wl[41];
    lm_cube a, b;
    lm_err e = {0};
    grid(wl, 41, 380.0, 10.0);
    for (int k = 0; k < 2; k++) {
        const double *w = k ? wl : wl + 2;
        int B = k ? 41 : 31;
        write_exr(tpath(p, k ? "grid41.exr" : "grid31.exr"), w, B);
        CHECK_MSG(lm_cube_read(p, &a, &e) == LM_OK, "%s", e.msg);
        CHECK(lm_cube_read_exr(p, &b, &e) == LM_OK);
        CHECK(a.bands == B && b.bands == B);
        if (a.bands == B && b.bands == B)
            CHECK(!memcmp(a.data, b.data, sizeof(float) * B * H * W) &&
                  !memcmp(a.wavelength, b.wavelength, sizeof(float) * B));
        lm_cube_free(&a);
        lm_cube_free(&b);
    }
    span(400.0, 700.0);
    write_mat(tpath(p, "c31.mat"), "cube", wl + 2, 31, 0, NULL, NULL, 0);
    CHECK_MSG(lm_cube_read(p, &a, &e) == LM_OK, "%s", e.msg);
    CHECK(lm_cube_read_mat(p, &b, &e) == LM_OK);
    CHECK(on_grid31(&a) && on_grid31(&b));
    if (on_grid31(&a) && on_grid31(&b))
        CHECK(!memcmp(a.data, b.data, sizeof(float) * 31 * H * W));
    double err = on_grid31(&a) ? worst_error(&a, 1.0) : INFINITY;
    printf("  31 bands 400-700 nm (point samples vs band means): worst error %.2e\n", err);
    lm_cube_free(&a);
    lm_cube_free(&b);
}

static void test_narrow_refused(void)
{
    char p[1024];
    exr_grid(p, "narrow.exr", 27, 430.0, 10.0);
    lm_cube c;
    lm_err e = {0};
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "narrow.exr", "covers 430-690 nm; resampling to 400-700 nm needs "
              "at least 420-680 nm");
}

static void test_mat_key(void)
{
    char p[1024];
    double wl[31];
    grid(wl, 31, 400.0, 10.0);
    void *d = make_values(wl, 31, 1.0, 0), *d2 = make_values(wl, 31, 0.5, 0);
    mat_t *m = Mat_CreateVer(tpath(p, "two.mat"), NULL, MAT_FT_MAT5);
    size_t dims[3] = {H, W, 31};
    matvar_t *v = Mat_VarCreate("cube", MAT_C_DOUBLE, MAT_T_DOUBLE, 3, dims, d, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
    Mat_VarFree(v);
    v = Mat_VarCreate("half", MAT_C_DOUBLE, MAT_T_DOUBLE, 3, dims, d2, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
    Mat_VarFree(v);
    Mat_Close(m);
    free(d), free(d2);
    lm_cube c;
    lm_err e = {0};
    lm_cube_read_opts o;
    lm_cube_read_opts_default(&o);
    if (read_close(p, &o, 1.0, TOL, "--mat-key automatic: 'cube'", &c)) lm_cube_free(&c);
    o.mat_key = "half";
    if (read_close(p, &o, 0.5, TOL, "--mat-key half", &c)) lm_cube_free(&c);
    o.mat_key = "nope";
    CHECK(lm_cube_read_with(p, &o, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "no variable 'nope'", "the file holds: cube, half");
    lm_err_clear(&e);
    write_mat(tpath(p, "other.mat"), "zzz", wl, 31, 0, NULL, NULL, 0);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "--mat-key", "the file holds: zzz");
}

/* Bad wavelength lists: one-line errors, nothing allocated. */
static void test_hostile_lists(void)
{
    char p[1024], q[1024];
    double wl[31];
    grid(wl, 31, 400.0, 10.0);
    write_mat(tpath(p, "h.mat"), "cube", wl, 31, 0, NULL, NULL, 0);
    const char *side[][2] = {
        {"400 410 405 430", "not increasing"},
        {"400 nan 420", "'nan' is not a number"},
        {"400 0x19a 420", "'0x19a' is not a number"},
        {"400 410 420", "lists 3 wavelengths but 'cube' has 31 bands"},
        {"400 410 abc", "'abc' is not a number"},
        {"# nothing\n", "no wavelengths"},
        {"-5 410", "not positive"},
    };
    lm_cube c;
    lm_err e = {0};
    for (size_t i = 0; i < sizeof side / sizeof side[0]; i++) {
        write_text(tpath(q, "h.mat.wavelengths.txt"), side[i][0]);
        CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
        CHECK_ERR(e, LM_ERR_FORMAT, "h.mat", side[i][1]);
        lm_err_clear(&e);
    }
    write_text(tpath(q, "h.mat.wavelengths.json"), "[400, 410]");
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "two wavelength sidecars", NULL);
    lm_err_clear(&e);
    remove(tpath(q, "h.mat.wavelengths.txt"));
    write_text(tpath(q, "h.mat.wavelengths.json"), "{\"wavelengths\": [400, \"x\"]}");
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "wavelengths.json", "wavelength 2 is not a number");
    lm_err_clear(&e);
    write_text(tpath(q, "h.mat.wavelengths.json"), "{\"wavelengths\": [400,");
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "wavelengths.json", NULL);
    lm_err_clear(&e);
    remove(tpath(q, "h.mat.wavelengths.json"));
    /* the file's own list: NaN, decreasing, a count that does not match */
    double bad[31];
    memcpy(bad, wl, sizeof bad);
    bad[7] = NAN;
    write_mat(tpath(p, "hn.mat"), "rad", wl, 31, 0, "wavelengths", bad, 31);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "hn.mat", "wavelength 8 is NaN");
    lm_err_clear(&e);
    bad[7] = 300.0;
    write_mat(tpath(p, "hd.mat"), "rad", wl, 31, 0, "wl", bad, 31);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "hd.mat", "not increasing (wavelength 8 is 300 nm");
    lm_err_clear(&e);
    write_mat(tpath(p, "hc.mat"), "rad", wl, 31, 0, "bands", wl, 30);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "hc.mat", "'bands' has 30 entries but 'rad' has 31 bands");
    lm_err_clear(&e);
    /* an EXR whose sidecar count does not match its channels */
    write_exr(tpath(p, "hx.exr"), wl, 31);
    write_text(tpath(q, "hx.exr.wavelengths.txt"), "400 500 600");
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "hx.exr", "lists 3 wavelengths but the cube has 31 bands");
}

/* The map itself: weights of every resampled band sum to 1 (a flat spectrum stays flat). */
static void test_weights(void)
{
    double wl[519];
    int sizes[3] = {519, 61, 34};
    double steps[3] = {600.0 / 518.0, 5.0, 10.0}, starts[3] = {400.0, 400.0, 395.0};
    for (int k = 0; k < 3; k++) {
        grid(wl, sizes[k], starts[k], steps[k]);
        lm_resample r;
        lm_err e = {0};
        lm_grid none = {0, 0.0f, 0.0f};
        CHECK_MSG(lm_resample_init(&r, wl, sizes[k], 0, none, "w", &e) == LM_OK, "%s", e.msg);
        CHECK(r.nout == 31 && r.dense == (k < 2));
        for (int b = 0; b < r.nout; b++) {
            double sum = 0.0;
            for (int s = 0; s < r.nsrc; s++) sum += r.w[(size_t)b * r.nsrc + s];
            CHECK_MSG(r.copy[b] >= 0 || fabs(sum - 1.0) < 1e-12, "grid %d band %d: %g", k, b, sum);
        }
        lm_resample_free(&r);
    }
    lm_resample r;
    lm_err e = {0};
    double one = 500.0;
    CHECK(lm_resample_init(&r, &one, 1, 0, (lm_grid){0, 0, 0}, "one", &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "one", "covers 500-500 nm");
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_resample_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 1;
    }
    RUN(test_kaust);
    RUN(test_harvard);
    RUN(test_icvl_519);
    RUN(test_exr_5nm);
    RUN(test_sidecars);
    RUN(test_on_grid_unchanged);
    RUN(test_narrow_refused);
    RUN(test_mat_key);
    RUN(test_hostile_lists);
    RUN(test_weights);
    fixture_cleanup();
    return check_summary();
}
