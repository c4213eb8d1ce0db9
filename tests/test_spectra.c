/* test_spectra.c — CSV tables (values and every error kind), bin integration against exact
 * integrals, 31 -> 41 mirroring, the 33-channel target, the data directory. */
#include "tests/check.h"
#include "data/spectra.h"
#include "tensor/rng.h"
#include <stdlib.h>
#include <unistd.h>

static char tmpdir[64];

static const char *write_tmp(const char *name, const char *text)
{
    static char path[256];
    snprintf(path, sizeof path, "%s/%s", tmpdir, name);
    FILE *f = fopen(path, "wb");
    if (!f) return path;
    fputs(text, f);
    fclose(f);
    return path;
}

static void test_csv_load_values(void)
{
    const char *p = write_tmp("ok.csv", "# a comment\r\nwavelength_nm, A ,\"B c\"\r\n"
                                        "400,1.5,-2\r\n\r\n410, 2.5e1 ,0\r\n420,3,1e-300\r\n");
    lm_csv_table t;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_csv_table_load(p, &t, &e) == LM_OK);
    CHECK_MSG(e.status == LM_OK, "%s", e.msg);
    CHECK(t.rows == 3 && t.cols == 3);
    if (t.rows == 3 && t.cols == 3) {
        CHECK(strcmp(t.names[1], "A") == 0 && strcmp(t.names[2], "B c") == 0);
        CHECK(t.data[0] == 400.0 && t.data[1] == 1.5 && t.data[2] == -2.0);
        CHECK(t.data[3] == 410.0 && t.data[4] == 25.0 && t.data[8] == 1e-300);
        CHECK(lm_csv_table_find(&t, "B c") == 2 && lm_csv_table_find(&t, "wavelength_nm") == -1);
        CHECK(lm_csv_table_find(&t, "Z") == -1);
    }
    lm_csv_table_free(&t);
    lm_spectrum s;
    CHECK(lm_spectrum_load(p, "A", 0, &s, &e) == LM_OK && s.n == 3);
    if (s.n == 3) CHECK(s.wl[2] == 420.0 && s.val[1] == 25.0);
    lm_spectrum_free(&s);
    CHECK(lm_spectrum_load(p, NULL, 2, &s, &e) == LM_OK && s.n == 3);
    if (s.n == 3) CHECK(s.val[0] == -2.0);
    lm_spectrum_free(&s);
}

/* The load must fail with status st and a message naming the file and containing `what`. */
static void expect_csv_error(const char *name, const char *text, lm_status st, const char *what)
{
    const char *p = text ? write_tmp(name, text) : name;
    char path[256];
    snprintf(path, sizeof path, "%s", p);
    lm_csv_table t;
    lm_err e;
    lm_err_clear(&e);
    lm_status s = lm_csv_table_load(path, &t, &e);
    CHECK_MSG(s == st && e.status == st, "%s: got %d (%s)", name, (int)s, e.msg);
    CHECK_MSG(strstr(e.msg, path) != NULL, "message does not name the file: %s", e.msg);
    CHECK_MSG(strstr(e.msg, what) != NULL, "message lacks '%s': %s", what, e.msg);
    CHECK(t.rows == 0 && t.data == NULL && t.names == NULL);
}

static void test_csv_errors(void)
{
    char missing[256];
    snprintf(missing, sizeof missing, "%s/no_such.csv", tmpdir);
    expect_csv_error(missing, NULL, LM_ERR_IO, "cannot open");
    expect_csv_error("nonnum.csv", "wl,a\n400,1\n410,abc\n", LM_ERR_FORMAT, "line 3, column 2");
    expect_csv_error("nonnum2.csv", "wl,a\n400,1\n410,1.5x\n", LM_ERR_FORMAT, "'1.5x'");
    expect_csv_error("empty_cell.csv", "wl,a\n400,\n410,1\n", LM_ERR_FORMAT, "line 2");
    expect_csv_error("nan.csv", "wl,a\n400,nan\n410,1\n", LM_ERR_FORMAT, "not a finite number");
    expect_csv_error("ragged.csv", "wl,a,b\n400,1,2\n410,1\n", LM_ERR_FORMAT, "line 3: 2 cells");
    expect_csv_error("ragged2.csv", "wl,a\n400,1,2\n410,1\n", LM_ERR_FORMAT, "ragged");
    expect_csv_error("order.csv", "wl,a\n400,1\n410,1\n405,1\n", LM_ERR_FORMAT,
                     "line 4: wavelength 405");
    expect_csv_error("dup.csv", "wl,a\n400,1\n400,2\n", LM_ERR_FORMAT, "must increase");
    expect_csv_error("onecol.csv", "wl\n400\n410\n", LM_ERR_FORMAT, "header has 1 column");
    expect_csv_error("onerow.csv", "wl,a\n400,1\n", LM_ERR_FORMAT, "1 data row");
    expect_csv_error("blank.csv", "\n\n", LM_ERR_FORMAT, "empty");

    const char *p = write_tmp("cols.csv", "wl,alpha,beta\n400,1,2\n410,1,2\n");
    lm_spectrum s;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_spectrum_load(p, "gamma", 0, &s, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "no column 'gamma'") && strstr(e.msg, "'beta'"), "%s", e.msg);
    lm_err_clear(&e);
    CHECK(lm_spectrum_load(p, NULL, 3, &s, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "no value column 3"), "%s", e.msg);
    lm_err_clear(&e);
    CHECK(lm_spectrum_load(p, NULL, 0, &s, &e) == LM_ERR_FORMAT); /* 0 = wavelength column */
    CHECK(s.n == 0 && s.wl == NULL);
}

static void make_spectrum(lm_spectrum *s, const double *wl, const double *v, int n)
{
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_spectrum_from_arrays(wl, v, n, s, &e) == LM_OK);
}

static void test_bin_constant_and_edges(void)
{
    double wl[501], v[501], out[41];
    for (int i = 0; i < 501; i++) wl[i] = 340.0 + i, v[i] = 2.5; /* 340..840 */
    lm_spectrum s;
    make_spectrum(&s, wl, v, 501);
    CHECK(lm_spectrum_bin(&s, 380, 10, 41, out, NULL) == LM_OK);
    for (int b = 0; b < 41; b++) CHECK_CLOSE(out[b], 25.0, 1e-12, 1e-12);
    lm_spectrum_free(&s);
    /* a table covering exactly 380..780: the outer half-bins lie outside and count as 0 */
    make_spectrum(&s, wl + 40, v + 40, 401);
    CHECK(lm_spectrum_bin(&s, 380, 10, 41, out, NULL) == LM_OK);
    CHECK_CLOSE(out[0], 12.5, 1e-12, 0);
    CHECK_CLOSE(out[40], 12.5, 1e-12, 0);
    CHECK_CLOSE(out[20], 25.0, 1e-12, 0);
    lm_spectrum_free(&s);
    lm_err e;
    lm_err_clear(&e);
    make_spectrum(&s, wl, v, 501);
    CHECK(lm_spectrum_bin(&s, 380, 0, 41, out, &e) == LM_ERR_ARG);
    CHECK(lm_spectrum_bin(&s, 380, 10, 0, out, NULL) == LM_ERR_ARG);
    lm_spectrum_free(&s);
}

/* A linear function is reproduced exactly by the piecewise-linear interpolant on any grid, so
 * every bin must equal the exact integral 10 * f(c), whatever the sample positions. */
static void test_bin_linear_irregular_grid(void)
{
    lm_rng r;
    lm_rng_seed(&r, 11);
    double wl[400], v[400];
    int n = 0;
    for (double x = 361.3; x < 800.0 && n < 400; x += lm_rng_uniform_range(&r, 0.3f, 4.0f)) {
        wl[n] = x;
        v[n] = 0.3 + 0.01 * x;
        n++;
    }
    lm_spectrum s;
    make_spectrum(&s, wl, v, n);
    double out[41];
    CHECK(lm_spectrum_bin(&s, 380, 10, 41, out, NULL) == LM_OK);
    for (int b = 0; b < 41; b++) {
        double c = 380.0 + 10.0 * b;
        CHECK_CLOSE(out[b], 10.0 * (0.3 + 0.01 * c), 1e-10, 1e-12);
    }
    CHECK_CLOSE(lm_spectrum_eval(&s, 555.5), 0.3 + 5.555, 1e-12, 1e-12);
    CHECK(lm_spectrum_eval(&s, 300.0) == 0.0 && lm_spectrum_eval(&s, 900.0) == 0.0);
    /* a bin narrower than one table segment, and one fully outside */
    CHECK_CLOSE(lm_spectrum_integrate(&s, 500.1, 500.2), 0.1 * (0.3 + 5.0015), 1e-12, 1e-9);
    CHECK(lm_spectrum_integrate(&s, 900, 910) == 0.0);
    lm_spectrum_free(&s);
}

/* Trapezoid, not exact integration or point sampling: for f = x^2 on a 1 nm grid the trapezoid
 * rule over a 10 nm bin errs by exactly (b - a) h^2 f'' / 12 = 10 / 6. */
static void test_bin_quadratic_trapezoid(void)
{
    double wl[500], v[500];
    for (int i = 0; i < 500; i++) wl[i] = 350.0 + i, v[i] = wl[i] * wl[i];
    lm_spectrum s;
    make_spectrum(&s, wl, v, 500);
    double out[41];
    CHECK(lm_spectrum_bin(&s, 380, 10, 41, out, NULL) == LM_OK);
    for (int b = 0; b < 41; b += 8) {
        double lo = 375.0 + 10 * b, hi = lo + 10;
        double exact = (hi * hi * hi - lo * lo * lo) / 3.0;
        CHECK_CLOSE(out[b], exact + 10.0 / 6.0, 1e-6, 1e-12);
    }
    lm_spectrum_free(&s);
}

/* A triangle 400 -> 410 -> 420 (peak 1): bins centred at 400, 410, 420 get 1.25, 7.5, 1.25. */
static void test_bin_triangle_by_hand(void)
{
    double wl[] = {300, 400, 410, 420, 800}, v[] = {0, 0, 1, 0, 0}, out[41];
    lm_spectrum s;
    make_spectrum(&s, wl, v, 5);
    CHECK(lm_spectrum_bin(&s, 380, 10, 41, out, NULL) == LM_OK);
    for (int b = 0; b < 41; b++) {
        double want = b == 2 || b == 4 ? 1.25 : (b == 3 ? 7.5 : 0.0);
        CHECK_CLOSE(out[b], want, 1e-12, 0);
    }
    CHECK(lm_spectrum_peak(&s) == 410.0);
    lm_spectrum_free(&s);
}

static void test_mirror_index_mapping(void)
{
    /* system.md section 3, written out */
    CHECK(lm_mirror_source_band(0) == 2);  /* 380 <- 420 */
    CHECK(lm_mirror_source_band(1) == 1);  /* 390 <- 410 */
    CHECK(lm_mirror_source_band(2) == 0);  /* 400 */
    CHECK(lm_mirror_source_band(32) == 30); /* 700 */
    CHECK(lm_mirror_source_band(33) == 29); /* 710 <- 690 */
    CHECK(lm_mirror_source_band(34) == 28); /* 720 <- 680 */
    CHECK(lm_mirror_source_band(40) == 22); /* 780 <- 620 */
    CHECK(lm_mirror_source_band(-1) == -1 && lm_mirror_source_band(41) == -1);
    for (int b = 0; b < 41; b++) { /* reflection about 400 and 700 nm */
        double wl = 380 + 10 * b, src = wl < 400 ? 800 - wl : (wl > 700 ? 1400 - wl : wl);
        CHECK(lm_mirror_source_band(b) == (int)((src - 400) / 10));
    }
    float in[31], out[41];
    for (int i = 0; i < 31; i++) in[i] = 400.0f + 10.0f * i;
    lm_spectrum_mirror41(in, out);
    CHECK(out[0] == 420.0f && out[1] == 410.0f && out[2] == 400.0f && out[33] == 690.0f &&
          out[40] == 620.0f);
}

static void test_cube_mirror41(void)
{
    lm_cube in, out;
    CHECK(lm_cube_alloc(&in, 31, 3, 5, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int i = 0; i < 15; i++) lm_cube_band(&in, b)[i] = (float)(400 + 10 * b) + 1000.0f * i;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_mirror41(&in, &out, &e) == LM_OK);
    CHECK(out.bands == 41 && out.height == 3 && out.width == 5);
    for (int b = 0; b < 41 && out.data; b++) {
        float wl = 380.0f + 10.0f * b;
        CHECK(out.wavelength[b] == wl);
        float src = wl < 400 ? 800 - wl : (wl > 700 ? 1400 - wl : wl);
        for (int i = 0; i < 15; i++) CHECK(lm_cube_band(&out, b)[i] == src + 1000.0f * i);
    }
    lm_cube_free(&out);
    in.wavelength[0] = 410.0f; /* not the 400..700 grid */
    CHECK(lm_cube_mirror41(&in, &out, &e) == LM_ERR_SHAPE && strstr(e.msg, "mirror"));
    CHECK(out.data == NULL);
    lm_cube_free(&in);
    lm_err_clear(&e);
    CHECK(lm_cube_alloc(&in, 41, 2, 2, 380, 10) == LM_OK);
    CHECK(lm_cube_mirror41(&in, &out, &e) == LM_ERR_SHAPE && strstr(e.msg, "41 bands"));
    lm_cube_free(&in);
}

static void test_target33(void)
{
    lm_cube in, out;
    lm_rng r;
    lm_rng_seed(&r, 5);
    CHECK(lm_cube_alloc(&in, 41, 2, 3, 380, 10) == LM_OK);
    lm_rng_fill_uniform(&r, in.data, 41 * 6, 0, 1);
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_target33(&in, &out, &e) == LM_OK);
    CHECK(out.bands == 33 && out.height == 2 && out.width == 3);
    CHECK(out.wavelength[0] == 385.0f && out.wavelength[1] == 400.0f &&
          out.wavelength[31] == 700.0f && out.wavelength[32] == 745.0f);
    for (int i = 0; i < 6 && out.data; i++) {
        float v[41];
        for (int b = 0; b < 41; b++) v[b] = lm_cube_band(&in, b)[i];
        CHECK_CLOSE(lm_cube_band(&out, 0)[i], (v[0] + v[1]) / 2, 1e-6, 1e-6);
        double nir = 0;
        for (int b = 33; b <= 40; b++) nir += v[b]; /* 710 .. 780 nm: 8 bins */
        CHECK_CLOSE(lm_cube_band(&out, 32)[i], nir / 8, 1e-6, 1e-6);
        for (int c = 1; c <= 31; c++) CHECK(lm_cube_band(&out, c)[i] == v[c + 1]);
    }
    lm_cube_free(&out);
    lm_cube_free(&in);
    /* mirrored 31-band cube: channel 0 = mean(420, 410), channel 32 = mean(690 .. 620) */
    lm_cube c31, c41;
    CHECK(lm_cube_alloc(&c31, 31, 1, 1, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++) c31.data[b] = (float)b;
    CHECK(lm_cube_mirror41(&c31, &c41, &e) == LM_OK && lm_cube_target33(&c41, &out, &e) == 0);
    CHECK_CLOSE(out.data[0], 1.5, 1e-6, 0);
    CHECK_CLOSE(out.data[32], (29 + 28 + 27 + 26 + 25 + 24 + 23 + 22) / 8.0, 1e-6, 0);
    lm_cube_free(&out);
    CHECK(lm_cube_target33(&c31, &out, &e) == LM_ERR_SHAPE && strstr(e.msg, "target33"));
    lm_cube_free(&c31);
    lm_cube_free(&c41);
}

static void test_data_dir(void)
{
    const char *old = getenv("LM_DATA_DIR");
    char saved[512] = "";
    if (old) snprintf(saved, sizeof saved, "%s", old);
    setenv("LM_DATA_DIR", "/somewhere/else", 1);
    CHECK(strcmp(lm_data_dir(), "/somewhere/else") == 0);
    char p[64];
    CHECK(lm_data_path("systems/default.json", p, sizeof p, NULL) == LM_OK);
    CHECK(strcmp(p, "/somewhere/else/systems/default.json") == 0);
    CHECK(lm_data_path("systems/default.json", p, 10, NULL) == LM_ERR_ARG);
    unsetenv("LM_DATA_DIR");
    const char *d = lm_data_dir();
    size_t n = strlen(d);
    CHECK(n >= 4 && strcmp(d + n - 4, "data") == 0);
    char path[1024];
    snprintf(path, sizeof path, "%s/spectra/cie_d65_spd.csv", d);
    CHECK_MSG(access(path, R_OK) == 0, "bundled table not found at %s", path);
    if (old) setenv("LM_DATA_DIR", saved, 1);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_test_spectra_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_csv_load_values);
    RUN(test_csv_errors);
    RUN(test_bin_constant_and_edges);
    RUN(test_bin_linear_irregular_grid);
    RUN(test_bin_quadratic_trapezoid);
    RUN(test_bin_triangle_by_hand);
    RUN(test_mirror_index_mapping);
    RUN(test_cube_mirror41);
    RUN(test_target33);
    RUN(test_data_dir);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}
