/* system.c — load, validate and resolve an imaging-system description (format in system.h).
 * What it is: JSON (jansson) -> lm_system, with one error per file naming the field at fault;
 * spectra are read through spectra.h and binned to the system's grid; gains, responses, LED
 * windows and the sub-frame schedule are derived here once.
 * What it is not: a writer of system files, or the simulator. */
#include "data/system.h"
#include "data/spectra.h"
#include "data/util.h"
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

typedef struct loader {
    const char *label;  /* file name used in messages */
    char dir[512];      /* base directory of relative CSV paths */
    lm_err *err;
    lm_system *sys;
} loader;

static lm_status fail(loader *ld, lm_status s, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static lm_status fail(loader *ld, lm_status s, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    lm_status r = lm_err_fieldv(ld->err, s, "system file", ld->label, field, fmt, ap);
    va_end(ap);
    return r;
}

/* ---- small JSON getters ------------------------------------------------------------------ */
static lm_status check_keys(loader *ld, json_t *obj, const char *prefix,
                            const char *const *allowed)
{
    const char *key;
    json_t *v;
    json_object_foreach(obj, key, v) {
        int ok = 0;
        for (int i = 0; allowed[i] && !ok; i++) ok = strcmp(key, allowed[i]) == 0;
        if (!ok) {
            char f[128];
            snprintf(f, sizeof f, "%s%s", prefix, key);
            return fail(ld, LM_ERR_FORMAT, f, "unknown field");
        }
    }
    return LM_OK;
}

/* Field prefix+key of obj: *v = its value (NULL if absent and optional), f = its full name. */
static lm_status lookup(loader *ld, json_t *obj, const char *prefix, const char *key,
                        int required, char f[128], json_t **v)
{
    snprintf(f, 128, "%s%s", prefix, key);
    *v = json_object_get(obj, key);
    if (!*v && required) return fail(ld, LM_ERR_FORMAT, f, "missing (required)");
    return LM_OK;
}

/* The largest value of any spectrum sample and of any gain: far above real data, small
 * enough that every product of the responses stays finite (in float too). */
#define MAX_SPECTRUM 1e12
#define MAX_GAIN 1e12

/* " (got <number>)" or "" for a value that is not a number, for messages. */
static const char *got(json_t *v, char *buf, size_t n)
{
    if (json_is_number(v)) snprintf(buf, n, " (got %g)", json_number_value(v));
    else buf[0] = 0;
    return buf;
}

/* Number field in [min, max] (min > 0: a positive number): absent -> def (or an error when
 * required). */
static lm_status get_number(loader *ld, json_t *obj, const char *prefix, const char *key,
                            int required, double def, double min, double max, double *out)
{
    char f[128], g[48];
    json_t *v;
    lm_status st = lookup(ld, obj, prefix, key, required, f, &v);
    *out = def;
    if (st || !v) return st;
    double x = json_number_value(v);
    if (!json_is_number(v) || !(x >= min && x <= max)) {
        if (min > 0) return fail(ld, LM_ERR_FORMAT, f, "must be a positive number of at most %g%s",
                                 max, got(v, g, sizeof g));
        return fail(ld, LM_ERR_FORMAT, f, "must be a number in %g..%g%s", min, max,
                    got(v, g, sizeof g));
    }
    *out = x;
    return LM_OK;
}

/* Integer field in min..max: absent -> def (or an error when required). */
static lm_status get_int(loader *ld, json_t *obj, const char *prefix, const char *key,
                         int required, int def, int min, int max, int *out)
{
    char f[128];
    json_t *v;
    lm_status st = lookup(ld, obj, prefix, key, required, f, &v);
    *out = def;
    if (st || !v) return st;
    if (!json_is_integer(v) || json_integer_value(v) < min || json_integer_value(v) > max) {
        if (min == 1) return fail(ld, LM_ERR_FORMAT, f, "must be a positive integer (<= %d)", max);
        return fail(ld, LM_ERR_FORMAT, f, "must be an integer in %d..%d", min, max);
    }
    *out = (int)json_integer_value(v);
    return LM_OK;
}

/* ---- spectra ----------------------------------------------------------------------------- */
static lm_status spectrum_inline(loader *ld, json_t *v, const char *field, float *out,
                                 double *peak)
{
    lm_system *s = ld->sys;
    if (json_array_size(v) != (size_t)s->nbins)
        return fail(ld, LM_ERR_FORMAT, field, "inline array has %zu values; the grid has %d bins",
                    json_array_size(v), s->nbins);
    int best = 0;
    for (int b = 0; b < s->nbins; b++) {
        json_t *e = json_array_get(v, (size_t)b);
        double x = json_number_value(e);
        char g[48];
        if (!json_is_number(e) || !(x >= 0 && x <= MAX_SPECTRUM))
            return fail(ld, LM_ERR_FORMAT, field, "value %d must be a non-negative number of at "
                        "most %g%s", b, MAX_SPECTRUM, got(e, g, sizeof g));
        out[b] = (float)json_number_value(e);
        if (out[b] > out[best]) best = b;
    }
    *peak = s->grid_start + s->grid_step * best;
    return LM_OK;
}

static lm_status spectrum_csv(loader *ld, json_t *v, const char *field, float *out,
                              double *peak)
{
    static const char *const keys[] = {"csv", "column", NULL};
    char pre[128], path[1024];
    snprintf(pre, sizeof pre, "%s.", field);
    lm_status st = check_keys(ld, v, pre, keys);
    if (st) return st;
    json_t *csv = json_object_get(v, "csv"), *col = json_object_get(v, "column");
    if (!json_is_string(csv) || !json_string_value(csv)[0])
        return fail(ld, LM_ERR_FORMAT, field, "'csv' must be a file path (string)");
    if (!json_is_string(col) &&
        !(json_is_integer(col) && json_integer_value(col) >= 1 && json_integer_value(col) <= 100000))
        return fail(ld, LM_ERR_FORMAT, field, "'column' must be a column name or number "
                    "(1..100000)");
    const char *rel = json_string_value(csv);
    snprintf(path, sizeof path, "%s%s%s", rel[0] == '/' ? "" : ld->dir, rel[0] == '/' ? "" : "/",
             rel);
    lm_err e;
    lm_err_clear(&e);
    lm_spectrum sp;
    int index = json_is_integer(col) ? (int)json_integer_value(col) : 0;
    st = lm_spectrum_load(path, json_is_string(col) ? json_string_value(col) : NULL,
                                    index, &sp, &e);
    if (st != LM_OK) return fail(ld, st, field, "%s", e.msg);
    lm_system *s = ld->sys;
    double *bins = malloc((size_t)s->nbins * sizeof(double));
    if (!bins) st = fail(ld, LM_ERR_NOMEM, field, "out of memory");
    else st = lm_spectrum_bin(&sp, s->grid_start, s->grid_step, s->nbins, bins, &e);
    for (int b = 0; st == LM_OK && b < s->nbins; b++) {
        double x = bins[b] / s->grid_step;
        out[b] = (float)x;
        if (!(x >= 0 && x <= MAX_SPECTRUM))
            st = fail(ld, LM_ERR_FORMAT, field, "%s value (%g) in the %g nm bin of '%s' (spectra "
                      "must be in 0..%g)", x < 0 ? "negative" : "out-of-range", x,
                      s->grid_start + s->grid_step * b, path, MAX_SPECTRUM);
    }
    *peak = lm_spectrum_peak(&sp);
    free(bins);
    lm_spectrum_free(&sp);
    return st;
}

/* A spectrum field: {"csv", "column"} or an inline array on the grid. */
static lm_status parse_spectrum(loader *ld, json_t *v, const char *field, float *out,
                                double *peak)
{
    if (!v) return fail(ld, LM_ERR_FORMAT, field, "missing (required)");
    if (json_is_array(v)) return spectrum_inline(ld, v, field, out, peak);
    if (json_is_object(v)) return spectrum_csv(ld, v, field, out, peak);
    return fail(ld, LM_ERR_FORMAT, field, "must be {\"csv\": path, \"column\": name} or an "
                "array of %d numbers", ld->sys->nbins);
}

/* ---- sections ---------------------------------------------------------------------------- */
static lm_status parse_grid(loader *ld, json_t *root)
{
    static const char *const keys[] = {"start_nm", "step_nm", "count", NULL};
    lm_system *s = ld->sys;
    json_t *g = json_object_get(root, "grid");
    double start = LM_GRID41_START, step = LM_GRID41_STEP;
    s->nbins = LM_GRID41_COUNT;
    if (g) {
        if (!json_is_object(g)) return fail(ld, LM_ERR_FORMAT, "grid", "must be an object");
        lm_status st = check_keys(ld, g, "grid.", keys);
        if (!st) st = get_number(ld, g, "grid.", "start_nm", 1, 0, 0, 1e5, &start);
        if (!st) st = get_number(ld, g, "grid.", "step_nm", 1, 0, 1e-3, 1e4, &step);
        if (!st) st = get_int(ld, g, "grid.", "count", 1, 0, 1, 128, &s->nbins);
        if (st) return st;
    }
    s->grid_start = (float)start;
    s->grid_step = (float)step;
    s->qe = calloc((size_t)s->nbins, sizeof(float));
    return s->qe ? LM_OK : fail(ld, LM_ERR_NOMEM, "grid", "out of memory");
}

static lm_status parse_sensor(loader *ld, json_t *root)
{
    static const char *const keys[] = {"width", "height", "qe", NULL};
    lm_system *s = ld->sys;
    json_t *o = json_object_get(root, "sensor");
    if (!o) return fail(ld, LM_ERR_FORMAT, "sensor", "missing (required; holds \"qe\")");
    if (!json_is_object(o)) return fail(ld, LM_ERR_FORMAT, "sensor", "must be an object");
    double peak;
    lm_status st = check_keys(ld, o, "sensor.", keys);
    if (!st) st = get_int(ld, o, "sensor.", "width", 0, 640, 1, 1 << 16, &s->width);
    if (!st) st = get_int(ld, o, "sensor.", "height", 0, 480, 1, 1 << 16, &s->height);
    if (!st) st = parse_spectrum(ld, json_object_get(o, "qe"), "sensor.qe", s->qe, &peak);
    return st;
}

static lm_status parse_timing(loader *ld, json_t *root)
{
    lm_system *s = ld->sys;
    /* a sub-frame of at most 1 s, a frame period of at most 1000 s */
    lm_status st = get_number(ld, root, "", "subframe_us", 1, 0, 1e-9, 1e6, &s->subframe_us);
    if (!st) st = get_number(ld, root, "", "readout_us", 0, 0, 0, 1e9, &s->readout_us);
    if (!st) st = get_number(ld, root, "", "frame_period_us", 0, 1e6 / 30, 1e-9, 1e9,
                             &s->frame_period_us);
    return st;
}

static lm_status parse_led(loader *ld, json_t *o, int i)
{
    static const char *const keys[] = {"name", "emission", "subframes", "peak_nm", NULL};
    lm_system *s = ld->sys;
    lm_led *led = &s->leds[i];
    char pre[48], f[64];
    snprintf(pre, sizeof pre, "leds[%d].", i);
    snprintf(f, sizeof f, "leds[%d]", i);
    if (!json_is_object(o)) return fail(ld, LM_ERR_FORMAT, f, "must be an object");
    lm_status st = check_keys(ld, o, pre, keys);
    if (st) return st;
    json_t *name = json_object_get(o, "name");
    snprintf(f, sizeof f, "leds[%d].name", i);
    if (!json_is_string(name) || !json_string_value(name)[0] ||
        strlen(json_string_value(name)) >= LM_LED_NAME_LEN)
        return fail(ld, LM_ERR_FORMAT, f, "must be a non-empty string of at most %d characters",
                    LM_LED_NAME_LEN - 1);
    strcpy(led->name, json_string_value(name));
    for (int j = 0; j < i; j++)
        if (strcmp(s->leds[j].name, led->name) == 0)
            return fail(ld, LM_ERR_FORMAT, f, "duplicate LED name '%s' (also leds[%d])",
                        led->name, j);
    st = get_int(ld, o, pre, "subframes", 1, 0, 1, 1 << 20, &led->subframes);
    snprintf(f, sizeof f, "leds[%d].emission", i);
    if (!st) st = parse_spectrum(ld, json_object_get(o, "emission"), f, led->emission,
                                 &led->peak_nm);
    if (!st) st = get_number(ld, o, pre, "peak_nm", 0, led->peak_nm, 0, 1e5, &led->peak_nm);
    return st;
}

static lm_status parse_leds(loader *ld, json_t *root)
{
    lm_system *s = ld->sys;
    json_t *a = json_object_get(root, "leds");
    if (!a) return fail(ld, LM_ERR_FORMAT, "leds", "missing (required)");
    if (!json_is_array(a) || json_array_size(a) < 1 || json_array_size(a) > LM_SYSTEM_MAX_LEDS)
        return fail(ld, LM_ERR_FORMAT, "leds", "must be an array of 1..%d LEDs",
                    LM_SYSTEM_MAX_LEDS);
    int n = (int)json_array_size(a);
    s->leds = calloc((size_t)n, sizeof *s->leds);
    if (!s->leds) return fail(ld, LM_ERR_NOMEM, "leds", "out of memory");
    s->nleds = n;
    for (int i = 0; i < n; i++) {
        s->leds[i].emission = calloc((size_t)s->nbins, sizeof(float));
        s->leds[i].response = calloc((size_t)s->nbins, sizeof(float));
        if (!s->leds[i].emission || !s->leds[i].response)
            return fail(ld, LM_ERR_NOMEM, "leds", "out of memory");
    }
    long total = 0;
    for (int i = 0; i < n; i++) {
        lm_status st = parse_led(ld, json_array_get(a, (size_t)i), i);
        if (st) return st;
        total += s->leds[i].subframes;
    }
    if (total > (1 << 24)) return fail(ld, LM_ERR_FORMAT, "leds", "%ld sub-frames in total; "
                                       "at most %d", total, 1 << 24);
    s->nsubframes = (int)total;
    int declared = 0;
    lm_status st = get_int(ld, root, "", "subframes_total", 0, s->nsubframes, 1, 1 << 24,
                           &declared);
    if (!st && declared != s->nsubframes)
        st = fail(ld, LM_ERR_FORMAT, "subframes_total", "%d, but leds[].subframes sum to %d",
                  declared, s->nsubframes);
    return st;
}

static lm_status parse_gains(loader *ld, json_t *root, double *gains)
{
    lm_system *s = ld->sys;
    json_t *g = json_object_get(root, "gains");
    s->equal_white = 1;
    if (!g || (json_is_string(g) && strcmp(json_string_value(g), "equal_white") == 0))
        return LM_OK;
    if (!json_is_array(g) || json_array_size(g) != (size_t)s->nleds)
        return fail(ld, LM_ERR_FORMAT, "gains", "must be \"equal_white\" or an array of %d "
                    "non-negative numbers (one per LED)", s->nleds);
    s->equal_white = 0;
    for (int i = 0; i < s->nleds; i++) {
        json_t *e = json_array_get(g, (size_t)i);
        double x = json_number_value(e);
        if (!json_is_number(e) || !(x >= 0 && x <= MAX_GAIN)) {
            char f[32], g[48];
            snprintf(f, sizeof f, "gains[%d]", i);
            return fail(ld, LM_ERR_FORMAT, f, "must be a non-negative number of at most %g%s",
                        MAX_GAIN, got(e, g, sizeof g));
        }
        gains[i] = json_number_value(e);
    }
    return LM_OK;
}

static lm_status tile_entry(loader *ld, json_t *row, int r, int c, int *used)
{
    lm_system *s = ld->sys;
    char f[48];
    snprintf(f, sizeof f, "tile_map[%d][%d]", r, c);
    json_t *e = json_array_get(row, (size_t)c);
    if (!json_is_string(e)) return fail(ld, LM_ERR_FORMAT, f, "must be an LED name (string)");
    int l = lm_system_led_index(s, json_string_value(e));
    if (l < 0) return fail(ld, LM_ERR_FORMAT, f, "unknown LED '%s'", json_string_value(e));
    s->tile_led[r * s->tile_cols + c] = l;
    used[l] = 1;
    return LM_OK;
}

static lm_status parse_tile_map(loader *ld, json_t *root)
{
    lm_system *s = ld->sys;
    json_t *m = json_object_get(root, "tile_map");
    if (!m) return fail(ld, LM_ERR_FORMAT, "tile_map", "missing (required)");
    json_t *row0 = json_array_get(m, 0);
    if (!json_is_array(m) || !json_is_array(row0) || json_array_size(row0) < 1)
        return fail(ld, LM_ERR_FORMAT, "tile_map", "must be an array of rows, each an array of "
                    "LED names");
    s->tile_rows = (int)json_array_size(m);
    s->tile_cols = (int)json_array_size(row0);
    if (s->tile_rows * (long)s->tile_cols > LM_SYSTEM_MAX_TILE)
        return fail(ld, LM_ERR_FORMAT, "tile_map", "%d x %d is more than %d positions",
                    s->tile_rows, s->tile_cols, LM_SYSTEM_MAX_TILE);
    s->tile_led = calloc((size_t)s->tile_rows * s->tile_cols, sizeof(int));
    if (!s->tile_led) return fail(ld, LM_ERR_NOMEM, "tile_map", "out of memory");
    int used[LM_SYSTEM_MAX_LEDS] = {0};
    for (int r = 0; r < s->tile_rows; r++) {
        json_t *row = json_array_get(m, (size_t)r);
        char f[32];
        snprintf(f, sizeof f, "tile_map[%d]", r);
        if (!json_is_array(row) || json_array_size(row) != (size_t)s->tile_cols)
            return fail(ld, LM_ERR_FORMAT, f, "must be an array of %d LED names like row 0",
                        s->tile_cols);
        for (int c = 0; c < s->tile_cols; c++) {
            lm_status st = tile_entry(ld, row, r, c, used);
            if (st) return st;
        }
    }
    for (int l = 0; l < s->nleds; l++)
        if (!used[l])
            return fail(ld, LM_ERR_FORMAT, "tile_map", "LED '%s' is in no tile position (a %d x "
                        "%d map has %d positions for %d LEDs; every LED needs one)",
                        s->leds[l].name, s->tile_rows, s->tile_cols, s->tile_rows * s->tile_cols,
                        s->nleds);
    return LM_OK;
}

static lm_status parse_firing(loader *ld, json_t *root)
{
    lm_system *s = ld->sys;
    json_t *o = json_object_get(root, "firing_order");
    int seen[LM_SYSTEM_MAX_LEDS] = {0}, n = 0;
    s->firing = malloc((size_t)s->nleds * sizeof(int));
    if (!s->firing) return fail(ld, LM_ERR_NOMEM, "firing_order", "out of memory");
    if (!o || (json_is_string(o) && strcmp(json_string_value(o), "raster") == 0)) {
        for (int t = 0; t < s->tile_rows * s->tile_cols; t++)
            if (!seen[s->tile_led[t]]++) s->firing[n++] = s->tile_led[t];
        return LM_OK;
    }
    if (!json_is_array(o) || json_array_size(o) != (size_t)s->nleds)
        return fail(ld, LM_ERR_FORMAT, "firing_order", "must be \"raster\" or an array of the %d "
                    "LED names, each once", s->nleds);
    for (int i = 0; i < s->nleds; i++) {
        json_t *e = json_array_get(o, (size_t)i);
        char f[40];
        snprintf(f, sizeof f, "firing_order[%d]", i);
        int l = json_is_string(e) ? lm_system_led_index(s, json_string_value(e)) : -1;
        if (l < 0) return fail(ld, LM_ERR_FORMAT, f, "unknown LED %s%s%s",
                               json_is_string(e) ? "'" : "(not a string)",
                               json_is_string(e) ? json_string_value(e) : "",
                               json_is_string(e) ? "'" : "");
        if (seen[l]++) return fail(ld, LM_ERR_FORMAT, f, "LED '%s' is listed twice",
                                   s->leds[l].name);
        s->firing[i] = l;
    }
    return LM_OK;
}

/* ---- derived quantities ------------------------------------------------------------------ */
static lm_status build_schedule(loader *ld)
{
    lm_system *s = ld->sys;
    s->subframe_led = malloc((size_t)s->nsubframes * sizeof(int));
    s->by_peak = malloc((size_t)s->nleds * sizeof(int));
    if (!s->subframe_led || !s->by_peak) return fail(ld, LM_ERR_NOMEM, "leds", "out of memory");
    int sub = 0;
    for (int i = 0; i < s->nleds; i++) {
        lm_led *led = &s->leds[s->firing[i]];
        led->first_subframe = sub;
        led->start_us = sub * s->subframe_us;
        for (int k = 0; k < led->subframes; k++) s->subframe_led[sub++] = s->firing[i];
        led->end_us = sub * s->subframe_us;
    }
    for (int i = 0; i < s->nleds; i++) { /* stable insertion sort by peak wavelength */
        int j = i;
        for (; j > 0 && s->leds[s->by_peak[j - 1]].peak_nm > s->leds[i].peak_nm; j--)
            s->by_peak[j] = s->by_peak[j - 1];
        s->by_peak[j] = i;
    }
    double need = lm_system_exposure_us(s) + s->readout_us;
    if (s->frame_period_us < need)
        return fail(ld, LM_ERR_FORMAT, "frame_period_us", "%g us is shorter than the exposure "
                    "(%g us) plus the readout (%g us)", s->frame_period_us,
                    lm_system_exposure_us(s), s->readout_us);
    return LM_OK;
}

static lm_status compute_responses(loader *ld, double *gains)
{
    lm_system *s = ld->sys;
    double best = 0.0;
    for (int l = 0; l < s->nleds; l++) {
        lm_led *led = &s->leds[l];
        double alloc = led->subframes * s->subframe_us, dot = 0.0;
        for (int b = 0; b < s->nbins; b++) dot += (double)s->qe[b] * led->emission[b];
        if (s->equal_white) {
            if (!(dot > 0.0)) {
                char f[48];
                snprintf(f, sizeof f, "leds[%d].emission", l);
                return fail(ld, LM_ERR_FORMAT, f, "LED '%s' gives no response on the grid (its "
                            "emission and the sensor QE do not overlap); cannot equalise gains",
                            led->name);
            }
            gains[l] = 1.0 / (alloc * dot);
        }
        led->gain = gains[l];
        double white = alloc * led->gain * dot;
        if (white > best) best = white;
    }
    if (!(best > 0.0))
        return fail(ld, LM_ERR_FORMAT, "gains", "every LED's response to white is zero");
    if (!isfinite(best)) /* not reachable within the ranges above; never a silent zero */
        return fail(ld, LM_ERR_FORMAT, "gains", "the responses overflow (gains, emission and "
                    "timing too large together)");
    s->scale = 1.0 / best;
    for (int l = 0; l < s->nleds; l++) {
        lm_led *led = &s->leds[l];
        double k = s->scale * led->subframes * s->subframe_us * led->gain;
        for (int b = 0; b < s->nbins; b++)
            led->response[b] = (float)(k * s->qe[b] * led->emission[b]);
    }
    return LM_OK;
}

static lm_status parse_root(loader *ld, json_t *root)
{
    static const char *const keys[] = {"version", "name", "description", "grid", "sensor",
                                       "subframe_us", "readout_us", "frame_period_us",
                                       "subframes_total", "leds", "gains", "tile_map",
                                       "firing_order", NULL};
    lm_system *s = ld->sys;
    if (!json_is_object(root)) return fail(ld, LM_ERR_FORMAT, "(top level)", "must be an object");
    json_t *v = json_object_get(root, "version");
    if (!v) return fail(ld, LM_ERR_FORMAT, "version", "missing (this build reads version %d)",
                        LM_SYSTEM_VERSION);
    if (!json_is_integer(v) || json_integer_value(v) != LM_SYSTEM_VERSION)
        return fail(ld, LM_ERR_FORMAT, "version", "unsupported (this build reads version %d)",
                    LM_SYSTEM_VERSION);
    s->version = LM_SYSTEM_VERSION;
    lm_status st = check_keys(ld, root, "", keys);
    if (st) return st;
    json_t *name = json_object_get(root, "name");
    if (name && !json_is_string(name)) return fail(ld, LM_ERR_FORMAT, "name", "must be a string");
    json_t *desc = json_object_get(root, "description");
    if (desc && !json_is_string(desc))
        return fail(ld, LM_ERR_FORMAT, "description", "must be a string");
    snprintf(s->name, sizeof s->name, "%s", name ? json_string_value(name) : "");
    double gains[LM_SYSTEM_MAX_LEDS] = {0};
    st = parse_grid(ld, root);
    if (!st) st = parse_sensor(ld, root);
    if (!st) st = parse_timing(ld, root);
    if (!st) st = parse_leds(ld, root);
    if (!st) st = parse_gains(ld, root, gains);
    if (!st) st = parse_tile_map(ld, root);
    if (!st) st = parse_firing(ld, root);
    if (!st) st = build_schedule(ld);
    if (!st) st = compute_responses(ld, gains);
    return st;
}

/* ---- public ------------------------------------------------------------------------------ */
static lm_status finish(loader *ld, json_t *root)
{
    lm_status st = parse_root(ld, root);
    json_decref(root);
    if (st != LM_OK) lm_system_free(ld->sys);
    return st;
}

lm_status lm_system_parse(const char *json_text, const char *base_dir, const char *label,
                          lm_system *sys, lm_err *err)
{
    memset(sys, 0, sizeof *sys);
    loader ld = {label ? label : "(string)", "", err, sys};
    snprintf(ld.dir, sizeof ld.dir, "%s", base_dir && base_dir[0] ? base_dir : ".");
    snprintf(sys->path, sizeof sys->path, "%s", ld.label);
    json_error_t je;
    json_t *root = json_loads(json_text, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(err, LM_ERR_FORMAT, "system file %s: line %d, column %d: %s", ld.label,
                          je.line, je.column, je.text);
    return finish(&ld, root);
}

lm_status lm_system_load(const char *path, lm_system *sys, lm_err *err)
{
    memset(sys, 0, sizeof *sys);
    loader ld = {path, "", err, sys};
    const char *slash = strrchr(path, '/');
    if (!slash) snprintf(ld.dir, sizeof ld.dir, ".");
    else if (slash == path) snprintf(ld.dir, sizeof ld.dir, "/");
    else snprintf(ld.dir, sizeof ld.dir, "%.*s", (int)(slash - path), path);
    snprintf(sys->path, sizeof sys->path, "%s", path);
    json_error_t je;
    lm_status fchk = lm_file_check(path, "a system file (.json)", err);
    if (fchk) return fchk;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        if (json_error_code(&je) == json_error_cannot_open_file)
            return lm_err_set(err, LM_ERR_IO, "system file %s: cannot open (%s)", path, je.text);
        return lm_err_set(err, LM_ERR_FORMAT, "system file %s: line %d, column %d: %s", path,
                          je.line, je.column, je.text);
    }
    return finish(&ld, root);
}

uint64_t lm_file_hash(const char *path)
{
    FILE *f = path && path[0] && !lm_file_check(path, NULL, NULL) ? fopen(path, "rb") : NULL;
    if (!f) return 0;
    uint64_t h = LM_FNV1A_BASIS_SHORT;
    unsigned char buf[4096];
    size_t got;
    while ((got = fread(buf, 1, sizeof buf, f)) > 0) h = lm_fnv1a(h, buf, got);
    fclose(f);
    return h;
}

lm_status lm_system_default(lm_system *sys, lm_err *err)
{
    char path[1024];
    memset(sys, 0, sizeof *sys);
    lm_status st = lm_data_path("systems/default.json", path, sizeof path, err);
    return st ? st : lm_system_load(path, sys, err);
}

void lm_system_free(lm_system *sys)
{
    if (sys->leds)
        for (int i = 0; i < sys->nleds; i++) {
            free(sys->leds[i].emission);
            free(sys->leds[i].response);
        }
    free(sys->leds);
    free(sys->qe);
    free(sys->tile_led);
    free(sys->firing);
    free(sys->by_peak);
    free(sys->subframe_led);
    memset(sys, 0, sizeof *sys);
}

int lm_system_led_index(const lm_system *s, const char *name)
{
    for (int i = 0; i < s->nleds; i++)
        if (strcmp(s->leds[i].name, name) == 0) return i;
    return -1;
}

int lm_system_reference_led(const lm_system *s)
{
    for (int i = 0; i < s->nleds; i++)
        if (strcasecmp(s->leds[i].name, "Lime") == 0) return i;
    int sub = (int)(0.5 * lm_system_exposure_us(s) / s->subframe_us);
    return lm_system_subframe_led(s, sub < s->nsubframes ? sub : s->nsubframes - 1);
}

void lm_system_describe(const lm_system *s, FILE *f)
{
    fprintf(f, "system %s (%s): %d LEDs, %d sub-frames of %g us = %g us exposure, readout %g us,"
            " frame period %g us, sensor %d x %d, grid %g + %g nm x %d\n", s->path, s->name,
            s->nleds, s->nsubframes, s->subframe_us, lm_system_exposure_us(s), s->readout_us,
            s->frame_period_us, s->width, s->height, s->grid_start, s->grid_step, s->nbins);
    fprintf(f, "  %-12s %8s %9s %10s %10s %9s %12s\n", "LED", "peak_nm", "subframes", "start_us",
            "end_us", "white", "gain");
    for (int i = 0; i < s->nleds; i++) {
        const lm_led *l = &s->leds[s->firing[i]];
        double white = 0.0;
        for (int b = 0; b < s->nbins; b++) white += l->response[b];
        fprintf(f, "  %-12s %8.1f %9d %10.1f %10.1f %9.4f %12.5g\n", l->name, l->peak_nm,
                l->subframes, l->start_us, l->end_us, white, l->gain);
    }
    fprintf(f, "  gains %s; white: the 'white' column is what a perfect white reflector reads "
            "under each LED, in units of full scale (1.0 = a frame's largest code: 65535 in a "
            "16-bit file, 2^B - 1 with infer --bits B)\n", s->equal_white ? "equal_white" :
            "from file");
    fprintf(f, "  tile (%d x %d, repeated over the sensor): pixel (y, x) sees the LED at row "
            "y mod %d, column x mod %d\n", s->tile_rows, s->tile_cols, s->tile_rows,
            s->tile_cols);
    fprintf(f, "           ");
    for (int c = 0; c < s->tile_cols; c++)
        fprintf(f, c + 1 < s->tile_cols ? "  column %-5d" : "  column %d", c);
    fputc('\n', f);
    for (int r = 0; r <= s->tile_rows; r++) {
        fprintf(f, "          +");
        for (int c = 0; c < s->tile_cols; c++) fprintf(f, "-------------+");
        fputc('\n', f);
        if (r == s->tile_rows) break;
        fprintf(f, "    row %-2d|", r);
        for (int c = 0; c < s->tile_cols; c++)
            fprintf(f, " %-12.12s|", s->leds[s->tile_led[r * s->tile_cols + c]].name);
        fputc('\n', f);
    }
}
