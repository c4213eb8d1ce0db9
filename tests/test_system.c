/* test_system.c — the bundled default system against system.md sections 1-4, hand-computed
 * responses of a small inline system, relative CSV paths, and the validation errors. */
#include "tests/check.h"
#include "data/spectra.h"
#include "data/system.h"
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdir[64];

static void write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    if (!f) return;
    fputs(text, f);
    fclose(f);
}

/* ---- the default system ---------------------------------------------------------------- */
static const char *const WINDOW_NAMES[12] = {"FarRed", "Green", "DeepRed", "RoyalBlue", "Red",
                                             "Violet", "Lime", "UV", "Amber", "Blue",
                                             "RedOrange", "Cyan"};
/* system.md section 2, "Resulting windows (us from exposure start)" */
static const double WINDOWS[12][2] = {{0, 4500},      {4500, 6150},   {6150, 7800},
                                      {7800, 8550},   {8550, 10350},  {10350, 11100},
                                      {11100, 12300}, {12300, 13650}, {13650, 19650},
                                      {19650, 20400}, {20400, 22350}, {22350, 23700}};

static int load_default(lm_system *s, lm_err *e)
{
    lm_err_clear(e);
    lm_status st = lm_system_default(s, e);
    CHECK_MSG(st == LM_OK, "%s", e->msg);
    return st == LM_OK;
}

static void test_default_timing_and_windows(void)
{
    lm_system s;
    lm_err e;
    if (!load_default(&s, &e)) return;
    CHECK(lm_system_num_leds(&s) == 12);
    CHECK(s.nsubframes == 158);
    CHECK_CLOSE(lm_system_exposure_us(&s), 23700.0, 1e-9, 0);
    CHECK_CLOSE(s.readout_us, 6000.0, 0, 0);
    CHECK(s.nbins == 41 && s.grid_start == 380.0f && s.grid_step == 10.0f);
    CHECK(s.width == 640 && s.height == 480);
    for (int i = 0; i < 12; i++) {
        int l = lm_system_led_index(&s, WINDOW_NAMES[i]);
        CHECK_MSG(l >= 0, "no LED %s", WINDOW_NAMES[i]);
        if (l < 0) continue;
        double a, b;
        lm_system_led_window(&s, l, &a, &b);
        CHECK_CLOSE(a, WINDOWS[i][0], 1e-6, 0);
        CHECK_CLOSE(b, WINDOWS[i][1], 1e-6, 0);
        CHECK(s.firing[i] == l); /* raster order of the tile map */
    }
    double a, b, mid = lm_system_exposure_us(&s) / 2;
    lm_system_led_window(&s, lm_system_led_index(&s, "Lime"), &a, &b);
    CHECK(a <= mid && mid < b);
    /* sub-frames per LED: the paper's table */
    const char *names[12] = {"UV", "Violet", "RoyalBlue", "Blue", "Cyan", "Green", "Lime",
                             "Amber", "RedOrange", "Red", "DeepRed", "FarRed"};
    const int subs[12] = {9, 5, 5, 5, 9, 11, 8, 40, 13, 12, 11, 30};
    for (int i = 0; i < 12; i++) CHECK(s.leds[lm_system_led_index(&s, names[i])].subframes ==
                                       subs[i]);
    lm_system_free(&s);
}

static void test_default_tile_map_and_orders(void)
{
    lm_system s;
    lm_err e;
    if (!load_default(&s, &e)) return;
    CHECK(s.tile_rows == 3 && s.tile_cols == 4);
    /* pixel (y, x) -> t = (y mod 3) * 4 + (x mod 4) -> LED of system.md section 2 */
    for (int y = 0; y < 7; y++)
        for (int x = 0; x < 9; x++) {
            int t = (y % 3) * 4 + (x % 4);
            CHECK(lm_system_tile_phase(&s, y, x) == t);
            CHECK(strcmp(s.leds[lm_system_pixel_led(&s, y, x)].name, WINDOW_NAMES[t]) == 0);
        }
    CHECK(strcmp(s.leds[lm_system_pixel_led(&s, 4, 6)].name, "Lime") == 0);
    /* network channel order: by peak wavelength, UV first */
    const char *by_peak[12] = {"UV", "Violet", "RoyalBlue", "Blue", "Cyan", "Green", "Lime",
                               "Amber", "RedOrange", "Red", "DeepRed", "FarRed"};
    const int *ord = lm_system_peak_order(&s);
    for (int i = 0; i < 12; i++) CHECK(strcmp(s.leds[ord[i]].name, by_peak[i]) == 0);
    CHECK(s.leds[lm_system_led_index(&s, "Amber")].peak_nm == 591.0);
    /* the schedule: each sub-frame has one LED, runs are contiguous and of the right length,
     * and exactly one tile phase integrates during each sub-frame */
    int count[12] = {0};
    for (int sub = 0; sub < s.nsubframes; sub++) {
        int l = lm_system_subframe_led(&s, sub), on = 0;
        count[l]++;
        CHECK(sub >= s.leds[l].first_subframe &&
              sub < s.leds[l].first_subframe + s.leds[l].subframes);
        for (int t = 0; t < 12; t++)
            if (lm_system_subframe_code(&s, sub, t)) {
                on++;
                CHECK(strcmp(s.leds[l].name, WINDOW_NAMES[t]) == 0);
            }
        CHECK(on == 1);
    }
    for (int l = 0; l < 12; l++) CHECK(count[l] == s.leds[l].subframes);
    CHECK(s.leds[lm_system_led_index(&s, "Lime")].first_subframe == 74); /* 11100 / 150 */
    lm_system_free(&s);
}

/* QE bin mean of a 5 nm table over [c-5, c+5] by the trapezoid rule: (q[-5] + 2 q[0] + q[5])/4 */
static double qe_bin_by_hand(const lm_csv_table *t, int col, double c)
{
    double q[3] = {0, 0, 0};
    for (int r = 0; r < t->rows; r++)
        for (int k = 0; k < 3; k++)
            if (t->data[(size_t)r * t->cols] == c - 5 + 5 * k)
                q[k] = t->data[(size_t)r * t->cols + col];
    return (q[0] + 2 * q[1] + q[2]) / 4;
}

static void test_default_responses_equal_white(void)
{
    lm_system s;
    lm_err e;
    if (!load_default(&s, &e)) return;
    CHECK(s.equal_white == 1);
    for (int l = 0; l < 12; l++) {
        const float *a = lm_system_response(&s, l);
        double white = 0, dot = 0;
        for (int b = 0; b < 41; b++) white += a[b], dot += (double)s.qe[b] * s.leds[l].emission[b];
        CHECK_CLOSE(white, 1.0, 1e-5, 0);
        for (int b = 0; b < 41; b++) /* a_l = (S .* E_l) / (S . E_l) for equal-white gains */
            CHECK_CLOSE(a[b], s.qe[b] * s.leds[l].emission[b] / dot, 1e-7, 1e-5);
        CHECK_CLOSE(s.leds[l].gain * s.leds[l].subframes * s.subframe_us * dot, 1.0, 0, 1e-9);
    }
    /* QE binned from the CMV12000 table (5 nm): compare a few bins with the hand formula */
    char path[1024];
    snprintf(path, sizeof path, "%s/spectra/sensor_mono_qe_cmv12000.csv", lm_data_dir());
    lm_csv_table t;
    CHECK(lm_csv_table_load(path, &t, &e) == LM_OK);
    int col = lm_csv_table_find(&t, "qe_fraction_derived(=R*1239.84/lambda)");
    CHECK(col == 2);
    for (int b = 0; b < 41 && col > 0; b += 10)
        CHECK_CLOSE(s.qe[b], qe_bin_by_hand(&t, col, 380 + 10 * b), 1e-7, 1e-6);
    lm_csv_table_free(&t);
    /* LED emission bins: UV is large at 380-390 nm, FarRed is ~0 below 600 nm */
    const lm_led *uv = &s.leds[lm_system_led_index(&s, "UV")];
    const lm_led *fr = &s.leds[lm_system_led_index(&s, "FarRed")];
    CHECK(uv->emission[1] > 0.8f && fr->emission[10] < 1e-6f && fr->emission[35] > 0.8f);
    lm_system_free(&s);
}

/* ---- a small inline system computed by hand ------------------------------------------ */
static const char *SMALL =
    "{\"version\": 1, \"name\": \"small\", \"grid\": {\"start_nm\": 500, \"step_nm\": 20, "
    "\"count\": 5}, \"sensor\": {\"width\": 8, \"height\": 6, \"qe\": [1, 1, 1, 1, 0.5]},"
    "\"subframe_us\": 100, \"readout_us\": 50,"
    "\"leds\": [{\"name\": \"A\", \"subframes\": 2, \"emission\": [0, 1, 2, 1, 0]},"
    "           {\"name\": \"B\", \"subframes\": 1, \"emission\": [1, 0, 0, 0, 2]}],"
    "\"gains\": [1, 2], \"tile_map\": [[\"B\", \"A\", \"A\"]], \"firing_order\": [\"B\", \"A\"]}";

static void test_inline_system_by_hand(void)
{
    lm_system s;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_system_parse(SMALL, ".", "small.json", &s, &e) == LM_OK, "%s", e.msg);
    if (e.status) return;
    /* raw white responses: A = 200 us * 1 * 4 = 800, B = 100 us * 2 * (1 + 1) = 400;
     * scale = 1/800: a_A = [0, .25, .5, .25, 0], a_B = 200 * [1, 0, 0, 0, 1] / 800 */
    const float wa[5] = {0, 0.25f, 0.5f, 0.25f, 0}, wb[5] = {0.25f, 0, 0, 0, 0.25f};
    CHECK_ARRAY_CLOSE(lm_system_response(&s, 0), wa, 5, 1e-7, 1e-6);
    CHECK_ARRAY_CLOSE(lm_system_response(&s, 1), wb, 5, 1e-7, 1e-6);
    CHECK_CLOSE(s.scale, 1.0 / 800, 0, 1e-12);
    CHECK(s.nsubframes == 3 && s.equal_white == 0);
    double a, b;
    lm_system_led_window(&s, 1, &a, &b); /* B fires first */
    CHECK(a == 0 && b == 100);
    lm_system_led_window(&s, 0, &a, &b);
    CHECK(a == 100 && b == 300);
    CHECK(s.subframe_led[0] == 1 && s.subframe_led[1] == 0 && s.subframe_led[2] == 0);
    /* A fills tile phases 1 and 2: both integrate while A is on */
    CHECK(lm_system_subframe_code(&s, 1, 1) && lm_system_subframe_code(&s, 1, 2) &&
          !lm_system_subframe_code(&s, 1, 0) && lm_system_subframe_code(&s, 0, 0));
    CHECK(lm_system_pixel_led(&s, 5, 4) == 0 && lm_system_pixel_led(&s, 5, 3) == 1);
    /* peaks: A at the 540 nm bin, B's largest inline bin is 580 nm */
    CHECK(s.leds[0].peak_nm == 540.0 && s.leds[1].peak_nm == 580.0);
    CHECK(s.by_peak[0] == 0 && s.by_peak[1] == 1);
    CHECK_CLOSE(s.frame_period_us, 1e6 / 30, 1e-9, 0);
    FILE *f = tmpfile();
    if (f) {
        lm_system_describe(&s, f);
        char buf[4096] = {0};
        rewind(f);
        size_t n = fread(buf, 1, sizeof buf - 1, f);
        CHECK(n > 0 && strstr(buf, "small") && strstr(buf, "B "));
        CHECK_MSG(strstr(buf, "row 0 | B           | A           | A") && strstr(buf, "pixel (y, x) sees the LED at row") &&
                  strstr(buf, "white reflector"), "%s", buf);
        fclose(f);
    }
    lm_system_free(&s);
    CHECK(s.leds == NULL && s.nleds == 0);
}

static void test_relative_csv_path(void)
{
    char dir[128], path[256];
    snprintf(dir, sizeof dir, "%s/sub", tmpdir);
    mkdir(dir, 0755);
    snprintf(path, sizeof path, "%s/led.csv", dir);
    write_file(path, "wl,first,second\n380,0,1\n400,2,1\n420,0,1\n");
    snprintf(path, sizeof path, "%s/sys.json", tmpdir);
    write_file(path, "{\"version\": 1, \"grid\": {\"start_nm\": 390, \"step_nm\": 5, "
                     "\"count\": 3}, \"sensor\": {\"qe\": {\"csv\": \"sub/led.csv\", \"column\": "
                     "2}}, \"subframe_us\": 10, \"leds\": [{\"name\": \"X\", \"subframes\": 1,"
                     " \"emission\": {\"csv\": \"sub/led.csv\", \"column\": \"first\"}}],"
                     " \"tile_map\": [[\"X\"]]}");
    lm_system s;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_system_load(path, &s, &e) == LM_OK, "%s", e.msg);
    if (e.status) return;
    /* triangle 380 -> 400 (2) -> 420: bin means over [387.5, 392.5], [392.5, 397.5] and
     * [397.5, 402.5] (the last straddles the peak: 2 * 2.5 * (1.75 + 2) / 2 / 5) */
    const float em[3] = {1.0f, 1.5f, 1.875f}, qe[3] = {1, 1, 1};
    CHECK_ARRAY_CLOSE(s.leds[0].emission, em, 3, 1e-6, 1e-6);
    CHECK_ARRAY_CLOSE(s.qe, qe, 3, 1e-6, 1e-6);
    CHECK(s.leds[0].peak_nm == 400.0);
    CHECK(strcmp(s.path, path) == 0);
    lm_system_free(&s);
}

/* ---- validation errors ----------------------------------------------------------------- */
/* Build the SMALL system with one substitution (from -> to) and expect status st with a message
 * naming the label and containing `what`. */
static void expect_json_error(const char *json, lm_status st, const char *what)
{
    lm_system s;
    lm_err e;
    lm_err_clear(&e);
    lm_status got = lm_system_parse(json, tmpdir, "bad.json", &s, &e);
    CHECK_MSG(got == st && e.status == st, "[%s] got %d: %s", json, (int)got, e.msg);
    CHECK_MSG(strstr(e.msg, "system file bad.json: ") == e.msg, "%s", e.msg);
    CHECK_MSG(strstr(e.msg, what) != NULL, "message lacks '%s': %s", what, e.msg);
    CHECK(s.leds == NULL && s.qe == NULL && s.nleds == 0);
}

static void expect_error(const char *from, const char *to, lm_status st, const char *what)
{
    char json[4096];
    const char *at = strstr(SMALL, from);
    CHECK_MSG(at != NULL, "test bug: '%s' not in SMALL", from);
    if (!at) return;
    snprintf(json, sizeof json, "%.*s%s%s", (int)(at - SMALL), SMALL, to, at + strlen(from));
    expect_json_error(json, st, what);
}

static void test_validation_errors(void)
{
    const lm_status F = LM_ERR_FORMAT;
    expect_error("\"version\": 1, ", "", F, "version: missing");
    expect_error("\"version\": 1", "\"version\": 2", F, "version: unsupported");
    expect_error("\"name\": \"small\"", "\"tile_mpa\": 1", F, "tile_mpa: unknown field");
    expect_error("\"subframes\": 1,", "\"subframes\": 0,", F,
                 "leds[1].subframes: must be a positive integer");
    expect_error("\"subframes\": 2,", "\"subframes\": \"2\",", F,
                 "leds[0].subframes: must be a positive integer");
    expect_error("\"subframes\": 2,", "", F, "leds[0].subframes: missing");
    expect_error("\"subframe_us\": 100", "\"subframe_us\": -1", F, "subframe_us: must be a "
                 "positive number");
    expect_error("\"subframe_us\": 100,", "", F, "subframe_us: missing");
    expect_error("\"tile_map\": [[\"B\", \"A\", \"A\"]]", "\"tile_map\": [[\"B\", \"Q\", \"A\"]]",
                 F, "tile_map[0][1]: unknown LED 'Q'");
    expect_error("\"tile_map\": [[\"B\", \"A\", \"A\"]]", "\"tile_map\": [[\"A\"]]", F,
                 "tile_map: LED 'B' is in no tile position (a 1 x 1 map has 1 positions for 2");
    expect_error("\"tile_map\": [[\"B\", \"A\", \"A\"]]",
                 "\"tile_map\": [[\"B\", \"A\"], [\"A\"]]", F,
                 "tile_map[1]: must be an array of 2");
    expect_error("\"tile_map\": [[\"B\", \"A\", \"A\"]]", "\"tile_map\": \"BA\"", F,
                 "tile_map: must be an array of rows");
}

static void test_validation_errors_schedule_and_spectra(void)
{
    const lm_status F = LM_ERR_FORMAT;
    expect_error("\"readout_us\": 50,", "\"subframes_total\": 4,", F,
                 "subframes_total: 4, but leds[].subframes sum to 3");
    expect_error("\"gains\": [1, 2]", "\"gains\": [1]", F, "gains: must be \"equal_white\" or");
    expect_error("\"gains\": [1, 2]", "\"gains\": [1, -2]", F, "gains[1]: must be a non-negative");
    expect_error("\"gains\": [1, 2]", "\"gains\": [0, 0]", F, "gains: every LED's response");
    expect_error("\"firing_order\": [\"B\", \"A\"]", "\"firing_order\": [\"B\", \"B\"]", F,
                 "firing_order[1]: LED 'B' is listed twice");
    expect_error("\"firing_order\": [\"B\", \"A\"]", "\"firing_order\": [\"B\", \"C\"]", F,
                 "firing_order[1]: unknown LED 'C'");
    expect_error("\"name\": \"B\"", "\"name\": \"A\"", F, "leds[1].name: duplicate LED name 'A'");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": [0, 1, 2, 1]", F,
                 "leds[0].emission: inline array has 4 values; the grid has 5 bins");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": [0, 1, -2, 1, 0]", F,
                 "leds[0].emission: value 2 must be a non-negative number");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": 3", F,
                 "leds[0].emission: must be {\"csv\"");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": {\"csv\": \"none.csv\", "
                 "\"column\": \"A\"}", LM_ERR_IO, "leds[0].emission: spectra file");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": {\"csv\": \"none.csv\", "
                 "\"colour\": \"A\"}", F, "leds[0].emission.colour: unknown field");
    expect_error("\"qe\": [1, 1, 1, 1, 0.5]", "\"qe\": {\"csv\": \"none.csv\"}", F,
                 "sensor.qe: 'column' must be");
    expect_error("\"readout_us\": 50", "\"readout_us\": 50, \"frame_period_us\": 320", F,
                 "frame_period_us: 320 us is shorter than the exposure (300 us) plus the "
                 "readout (50 us)");
    expect_error("\"count\": 5", "\"count\": 0", F, "grid.count: must be a positive integer");
    expect_json_error("{\"version\": 1, \"sensor\": {\"qe\": [1]}, \"subframe_us\": 1, "
                      "\"grid\": {\"start_nm\": 500, \"step_nm\": 1, \"count\": 1}, "
                      "\"leds\": {}, \"tile_map\": [[\"L\"]]}", F, "leds: must be an array");
    expect_json_error("{\"version\": 1, \"sensor\": {\"qe\": [1]}, \"subframe_us\": 1, "
                      "\"grid\": {\"start_nm\": 500, \"step_nm\": 1, \"count\": 1}, "
                      "\"tile_map\": [[\"L\"]]}", F, "leds: missing");
    expect_json_error("{\"version\": 1, \"subframe_us\": 1}", F, "sensor: missing");
    expect_json_error("[1, 2]", F, "must be an object");
    expect_error("\"width\": 8, ", "\"width\": 8.5, ", F, "sensor.width: must be a positive");
    expect_error("\"version\": 1,", "\"version\": 1,,", F, "line 1, column");
    expect_error("\"name\": \"small\"", "\"name\": \"small\", \"name\": \"twice\"", F, "line 1");
}

/* Every number is range-checked: values that overflow or make no physical sense are errors
 * naming the field and the range, never an inf that turns every frame into zeros. */
static void test_numeric_ranges(void)
{
    const lm_status F = LM_ERR_FORMAT;
    expect_error("\"gains\": [1, 2]", "\"gains\": [1e308, 2]", F,
                 "gains[0]: must be a non-negative number of at most 1e+12 (got 1e+308)");
    expect_error("\"gains\": [1, 2]", "\"gains\": [1, 1e13]", F, "gains[1]: must be");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": [0, 1, 1e308, 1, 0]", F,
                 "leds[0].emission: value 2 must be a non-negative number of at most 1e+12");
    expect_error("\"qe\": [1, 1, 1, 1, 0.5]", "\"qe\": [1, 1, 1, 1, 1e300]", F,
                 "sensor.qe: value 4 must be");
    expect_error("\"subframe_us\": 100", "\"subframe_us\": 1e308", F,
                 "subframe_us: must be a positive number of at most 1e+06 (got 1e+308)");
    expect_error("\"readout_us\": 50", "\"readout_us\": 1e308", F,
                 "readout_us: must be a number in 0..1e+09");
    expect_error("\"readout_us\": 50", "\"readout_us\": 50, \"frame_period_us\": 1e300", F,
                 "frame_period_us: must be a positive number of at most 1e+09");
    expect_error("\"start_nm\": 500", "\"start_nm\": 1e300", F, "grid.start_nm: must be a number "
                 "in 0..100000");
    expect_error("\"step_nm\": 20", "\"step_nm\": 1e-300", F, "grid.step_nm: must be a positive");
    expect_error("\"subframes\": 2,", "\"subframes\": 2, \"peak_nm\": 1e308,", F,
                 "leds[0].peak_nm: must be a number in 0..100000");
    expect_error("\"subframes\": 2,", "\"subframes\": 4294967298,", F,
                 "leds[0].subframes: must be a positive integer");
    expect_error("\"width\": 8, ", "\"width\": 4294967304, ", F, "sensor.width: must be a positive");
    expect_error("\"emission\": [0, 1, 2, 1, 0]", "\"emission\": {\"csv\": \"x.csv\", "
                 "\"column\": 4294967297}", F, "leds[0].emission: 'column' must be a column name "
                 "or number (1..100000)");
}

static void test_csv_errors_through_system(void)
{
    char csv[256], json[2048];
    snprintf(csv, sizeof csv, "%s/e.csv", tmpdir);
    write_file(csv, "wl,A\n500,1\n520,x\n540,1\n");
    snprintf(json, sizeof json, "{\"version\": 1, \"sensor\": {\"qe\": {\"csv\": \"e.csv\", "
             "\"column\": \"A\"}}, \"subframe_us\": 1, \"leds\": [{\"name\": \"L\", "
             "\"subframes\": 1, \"emission\": {\"csv\": \"%s\", \"column\": \"B\"}}], "
             "\"tile_map\": [[\"L\"]]}", csv);
    lm_system s;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_system_parse(json, tmpdir, "c.json", &s, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "sensor.qe: spectra file") && strstr(e.msg, "line 3"), "%s", e.msg);
    write_file(csv, "wl,A\n500,1\n520,2\n540,1\n");
    lm_err_clear(&e);
    CHECK(lm_system_parse(json, tmpdir, "c.json", &s, &e) == LM_ERR_FORMAT);
    CHECK_MSG(strstr(e.msg, "leds[0].emission: spectra file") && strstr(e.msg, "no column 'B'"),
              "%s", e.msg);
    /* a missing system file, and a data directory without the default */
    lm_err_clear(&e);
    char missing[256];
    snprintf(missing, sizeof missing, "%s/none.json", tmpdir);
    CHECK(lm_system_load(missing, &s, &e) == LM_ERR_IO && strstr(e.msg, "none.json"));
    const char *old = getenv("LM_DATA_DIR");
    char saved[512] = "";
    if (old) snprintf(saved, sizeof saved, "%s", old);
    setenv("LM_DATA_DIR", tmpdir, 1);
    lm_err_clear(&e);
    CHECK(lm_system_default(&s, &e) == LM_ERR_IO && strstr(e.msg, "systems/default.json"));
    if (old) setenv("LM_DATA_DIR", saved, 1);
    else unsetenv("LM_DATA_DIR");
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_test_system_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_default_timing_and_windows);
    RUN(test_default_tile_map_and_orders);
    RUN(test_default_responses_equal_white);
    RUN(test_inline_system_by_hand);
    RUN(test_relative_csv_path);
    RUN(test_validation_errors);
    RUN(test_validation_errors_schedule_and_spectra);
    RUN(test_csv_errors_through_system);
    RUN(test_numeric_ranges);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}
