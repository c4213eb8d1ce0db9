/* calib.c — LED-gain calibration from ColorChecker frames (calib.h). */
#define _XOPEN_SOURCE 700 /* realpath */
#include <errno.h>
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "data/calib.h"
#include "data/nnls.h"
#include "data/spectra.h"

#define NP LM_CALIB_PATCHES

lm_status lm_calib_grid(const double corners[8], double frac, lm_calib_rect out[NP], lm_err *err)
{
    for (int i = 0; i < 8; i++)
        if (!isfinite(corners[i]) || fabs(corners[i]) > 1e7)
            return lm_err_set(err, LM_ERR_ARG, "chart corners: coordinate %d is not a finite "
                              "pixel position", i + 1);
    if (!(frac > 0.0 && frac <= 1.0))
        return lm_err_set(err, LM_ERR_ARG, "patch fraction: must be in (0, 1] (got %g)", frac);
    double cx[NP], cy[NP];
    for (int r = 0; r < LM_CALIB_ROWS; r++)
        for (int c = 0; c < LM_CALIB_COLS; c++) {
            double u = c / (double)(LM_CALIB_COLS - 1), v = r / (double)(LM_CALIB_ROWS - 1);
            double w[4] = {(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v};
            int p = r * LM_CALIB_COLS + c;
            cx[p] = cy[p] = 0.0;
            for (int k = 0; k < 4; k++) cx[p] += w[k] * corners[2 * k], cy[p] += w[k] * corners[2 * k + 1];
        }
    double pitch = INFINITY; /* smallest distance between neighbouring centres */
    for (int r = 0; r < LM_CALIB_ROWS; r++)
        for (int c = 0; c < LM_CALIB_COLS; c++) {
            int p = r * LM_CALIB_COLS + c;
            if (c + 1 < LM_CALIB_COLS) pitch = fmin(pitch, hypot(cx[p + 1] - cx[p], cy[p + 1] - cy[p]));
            if (r + 1 < LM_CALIB_ROWS)
                pitch = fmin(pitch, hypot(cx[p + LM_CALIB_COLS] - cx[p], cy[p + LM_CALIB_COLS] - cy[p]));
        }
    if (!(pitch >= 2.0))
        return lm_err_set(err, LM_ERR_ARG, "chart corners: patch centres %.2g pixels apart (the "
                          "corners are patches 1, 6, 24, 19: top-left, top-right, bottom-right, "
                          "bottom-left)", pitch);
    int side = (int)lround(frac * pitch);
    if (side < 1) side = 1;
    for (int p = 0; p < NP; p++)
        out[p] = (lm_calib_rect){(int)lround(cx[p] - 0.5 * side), (int)lround(cy[p] - 0.5 * side),
                                 side, side};
    return LM_OK;
}

lm_status lm_calib_rects_load(const char *path, lm_calib_rect out[NP], lm_err *err)
{
    lm_status fchk = lm_file_check(path, "a JSON file", err);
    if (fchk) return fchk;
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(err, json_error_code(&je) == json_error_cannot_open_file
                                   ? LM_ERR_IO : LM_ERR_FORMAT,
                          "patches file %s: %s", path, je.text);
    json_t *a = json_object_get(root, "patches");
    lm_status st = LM_OK;
    if (!json_is_array(a) || json_array_size(a) != NP)
        st = lm_err_set(err, LM_ERR_FORMAT, "patches file %s: 'patches' must be an array of %d "
                        "rectangles [x, y, w, h] (chart order)", path, NP);
    for (int p = 0; !st && p < NP; p++) {
        json_t *e = json_array_get(a, (size_t)p);
        long long v[4];
        int ok = json_is_array(e) && json_array_size(e) == 4;
        for (int k = 0; ok && k < 4; k++) {
            json_t *n = json_array_get(e, (size_t)k);
            ok = json_is_integer(n) && (v[k] = json_integer_value(n)) >= (k < 2 ? 0 : 1) &&
                 v[k] <= 1000000;
        }
        if (!ok)
            st = lm_err_set(err, LM_ERR_FORMAT, "patches file %s: patches[%d] must be [x, y, w, h] "
                            "with integers x, y >= 0 and w, h >= 1 (at most 1e6)", path, p);
        else out[p] = (lm_calib_rect){(int)v[0], (int)v[1], (int)v[2], (int)v[3]};
    }
    json_decref(root);
    return st;
}

lm_status lm_calib_rects_check(const lm_system *sys, const lm_calib_rect *r, int height,
                               int width, lm_err *err)
{
    for (int p = 0; p < NP; p++) {
        const lm_calib_rect *q = &r[p];
        if (q->x < 0 || q->y < 0 || q->w < 1 || q->h < 1 || q->x > width - q->w ||
            q->y > height - q->h)
            return lm_err_set(err, LM_ERR_ARG, "patch %d (x %d, y %d, %d x %d pixels) is not "
                              "inside the %d x %d frame", p + 1, q->x, q->y, q->w, q->h, width,
                              height);
        if (q->w < sys->tile_cols || q->h < sys->tile_rows)
            return lm_err_set(err, LM_ERR_ARG, "patch %d (%d x %d pixels) is smaller than the "
                              "%d x %d tile: some LED has no pixel in it", p + 1, q->w, q->h,
                              sys->tile_cols, sys->tile_rows);
    }
    return LM_OK;
}

lm_status lm_calib_reflectances(const lm_system *sys, const char *path, double *C, lm_err *err)
{
    char def[1024];
    if (!path) {
        if (lm_data_path("spectra/colorchecker_24_reflectance_babelcolor_avg_380-730_10nm.csv",
                         def, sizeof def, err))
            return err->status;
        path = def;
    }
    lm_csv_table t;
    if (lm_csv_table_load(path, &t, err)) return err->status;
    lm_status st = t.cols - 1 < NP
        ? lm_err_set(err, LM_ERR_FORMAT, "reflectance table %s: %d value columns, need the %d "
                     "ColorChecker patches", path, t.cols - 1, NP) : LM_OK;
    double *wl = malloc((size_t)(t.rows + 2) * sizeof *wl), *val = malloc((size_t)(t.rows + 2) * sizeof *val);
    double *bins = malloc((size_t)sys->nbins * sizeof *bins);
    if (!st && (!wl || !val || !bins)) st = lm_err_set(err, LM_ERR_NOMEM, "out of memory");
    double lo = sys->grid_start - sys->grid_step, hi = sys->grid_start + sys->grid_step * sys->nbins;
    for (int p = 0; !st && p < NP; p++) {
        int n = 0; /* the column, extended flat to the grid's edges */
        if (t.data[0] > lo) wl[n] = lo, val[n++] = t.data[p + 1];
        for (int i = 0; i < t.rows; i++) wl[n] = t.data[i * t.cols], val[n++] = t.data[i * t.cols + p + 1];
        if (wl[n - 1] < hi) wl[n] = hi, val[n] = val[n - 1], n++;
        lm_spectrum sp;
        st = lm_spectrum_from_arrays(wl, val, n, &sp, err);
        if (!st) {
            st = lm_spectrum_bin(&sp, sys->grid_start, sys->grid_step, sys->nbins, bins, err);
            lm_spectrum_free(&sp);
        }
        for (int b = 0; !st && b < sys->nbins; b++) {
            C[p * sys->nbins + b] = bins[b] / sys->grid_step;
            if (!(C[p * sys->nbins + b] >= 0.0 && C[p * sys->nbins + b] <= 10.0))
                st = lm_err_set(err, LM_ERR_FORMAT, "reflectance table %s: patch %d has a "
                                "reflectance of %g (must be in 0..10)", path, p + 1,
                                C[p * sys->nbins + b]);
        }
    }
    free(wl), free(val), free(bins);
    lm_csv_table_free(&t);
    return st;
}

lm_status lm_calib_measure(const lm_system *sys, const float *frame, int height, int width,
                           const lm_calib_rect *r, double *M, lm_err *err)
{
    if (lm_calib_rects_check(sys, r, height, width, err)) return err->status;
    int L = sys->nleds;
    for (int p = 0; p < NP; p++) {
        double sum[LM_SYSTEM_MAX_LEDS] = {0};
        long cnt[LM_SYSTEM_MAX_LEDS] = {0};
        for (int y = r[p].y; y < r[p].y + r[p].h; y++)
            for (int x = r[p].x; x < r[p].x + r[p].w; x++) {
                int l = lm_system_pixel_led(sys, y, x);
                sum[l] += frame[(size_t)y * width + x];
                cnt[l]++;
            }
        for (int l = 0; l < L; l++) {
            M[l * NP + p] = cnt[l] ? sum[l] / cnt[l] : 0.0;
            if (!isfinite(M[l * NP + p]))
                return lm_err_set(err, LM_ERR_NUMERIC, "calibrate: non-finite frame values in "
                                  "patch %d", p + 1);
        }
    }
    return LM_OK;
}

void lm_calib_simulate(const lm_system *sys, const double *C, double *A)
{
    for (int l = 0; l < sys->nleds; l++)
        for (int p = 0; p < NP; p++) {
            double s = 0.0;
            for (int b = 0; b < sys->nbins; b++) s += sys->leds[l].response[b] * C[p * sys->nbins + b];
            A[l * NP + p] = s;
        }
}

lm_status lm_calib_solve(const lm_system *sys, const double *A, const double *M, int fit_offset,
                         lm_calib_fit *out, lm_err *err)
{
    int L = sys->nleds, n = L + (fit_offset ? 1 : 0), m = L * NP;
    memset(out, 0, sizeof *out);
    double mnorm = 0.0, msum = 0.0;
    for (int i = 0; i < m; i++) mnorm += M[i] * M[i], msum += M[i];
    if (!(mnorm > 0.0) || !isfinite(mnorm))
        return lm_err_set(err, LM_ERR_NUMERIC, "calibrate: the measured patch means are all zero "
                          "or not finite (a dark frame?)");
    double *D = calloc((size_t)m * n, sizeof *D), x[LM_SYSTEM_MAX_LEDS + 1];
    if (!D) return lm_err_set(err, LM_ERR_NOMEM, "calibrate: out of memory");
    for (int l = 0; l < L; l++) /* row (l, p): alpha_l A_lp (+ offset) = M_lp */
        for (int p = 0; p < NP; p++) {
            D[(size_t)(l * NP + p) * n + l] = A[l * NP + p];
            if (fit_offset) D[(size_t)(l * NP + p) * n + L] = 1.0;
        }
    double resid = 0.0;
    lm_status st = lm_nnls(D, m, n, M, x, &resid, err);
    free(D);
    if (st) return st;
    double mean = msum / m;
    out->offset = fit_offset ? x[L] : 0.0;
    out->rel_error = resid / sqrt(mnorm);
    for (int l = 0; l < L; l++) {
        out->alpha[l] = x[l];
        out->gain[l] = x[l] * sys->leds[l].gain;
    }
    for (int l = 0; l < L; l++)
        for (int p = 0; p < NP; p++) {
            double d = x[l] * A[l * NP + p] + out->offset - M[l * NP + p];
            out->led_rms[l] += d * d / NP;
            out->patch_rms[p] += d * d / L;
        }
    for (int l = 0; l < L; l++) out->led_rms[l] = sqrt(out->led_rms[l]) / mean;
    for (int p = 0; p < NP; p++) out->patch_rms[p] = sqrt(out->patch_rms[p]) / mean;
    return LM_OK;
}

/* A {"csv": path} spectrum with a relative path: made absolute against dir. */
static void absolute_csv(json_t *spec, const char *dir)
{
    json_t *csv = json_is_object(spec) ? json_object_get(spec, "csv") : NULL;
    const char *p = json_string_value(csv);
    if (!p || p[0] == '/') return;
    char buf[PATH_MAX + 1024], real[PATH_MAX];
    snprintf(buf, sizeof buf, "%s/%s", dir, p);
    json_object_set_new(spec, "csv", json_string(realpath(buf, real) ? real : buf));
}

lm_status lm_calib_write_system(const lm_system *sys, const double *gains, const char *note,
                                const char *out_path, lm_err *err)
{
    char name[160];
    snprintf(name, sizeof name, "%s (calibrated)", sys->name[0] ? sys->name : "system");
    lm_system_edit ed = {.gains = gains, .name = name, .note = note};
    return lm_system_write_edit(sys, &ed, out_path, err);
}

lm_status lm_system_write_edit(const lm_system *sys, const lm_system_edit *ed,
                               const char *out_path, lm_err *err)
{
    json_error_t je;
    json_t *root = json_load_file(sys->path, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(err, LM_ERR_IO, "system: cannot re-read the system file %s: %s",
                          sys->path, je.text);
    char dir[PATH_MAX], real[PATH_MAX];
    snprintf(dir, sizeof dir, "%s", realpath(sys->path, real) ? real : sys->path);
    char *slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    else snprintf(dir, sizeof dir, ".");
    json_t *sensor = json_object_get(root, "sensor"), *leds = json_object_get(root, "leds");
    if (ed->gains) {
        json_t *g = json_array();
        for (int l = 0; l < sys->nleds; l++) json_array_append_new(g, json_real(ed->gains[l]));
        json_object_set_new(root, "gains", g);
    }
    if (ed->subframes) { /* leds[] is in file order, as sys->leds */
        long total = 0;
        for (size_t i = 0; i < json_array_size(leds) && (int)i < sys->nleds; i++) {
            json_object_set_new(json_array_get(leds, i), "subframes",
                                json_integer(ed->subframes[i]));
            total += ed->subframes[i];
        }
        json_object_set_new(root, "subframes_total", json_integer(total));
    }
    if (ed->tile_led) {
        json_t *rows = json_array();
        for (int y = 0; y < sys->tile_rows; y++) {
            json_t *row = json_array();
            for (int x = 0; x < sys->tile_cols; x++)
                json_array_append_new(
                    row, json_string(sys->leds[ed->tile_led[y * sys->tile_cols + x]].name));
            json_array_append_new(rows, row);
        }
        json_object_set_new(root, "tile_map", rows);
    }
    if (ed->name) json_object_set_new(root, "name", json_string(ed->name));
    if (ed->note) json_object_set_new(root, "description", json_string(ed->note));
    if (sensor) absolute_csv(json_object_get(sensor, "qe"), dir);
    for (size_t i = 0; i < json_array_size(leds); i++)
        absolute_csv(json_object_get(json_array_get(leds, i), "emission"), dir);
    char tmp[PATH_MAX + 32];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", out_path, (long)getpid());
    int rc = json_dump_file(root, tmp, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(10));
    json_decref(root);
    lm_system check;
    lm_err e2 = {0};
    lm_status st = rc ? lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", out_path,
                                   strerror(errno))
                      : LM_OK;
    if (!st && lm_system_load(tmp, &check, &e2))
        st = lm_err_set(err, LM_ERR_FORMAT, "system: the written system does not load: %s",
                        e2.msg);
    else if (!st) lm_system_free(&check);
    if (!st && rename(tmp, out_path) != 0)
        st = lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", out_path, strerror(errno));
    if (st) remove(tmp);
    return st;
}

lm_status lm_calib_chart_cube(const lm_system *sys, int height, int width,
                              const lm_calib_rect *r, const double *C, double background,
                              lm_cube *out, lm_err *err)
{
    if (lm_calib_rects_check(sys, r, height, width, err)) return err->status;
    if (lm_cube_alloc(out, sys->nbins, height, width, sys->grid_start, sys->grid_step))
        return lm_err_set(err, LM_ERR_NOMEM, "chart: cannot allocate a %d x %d x %d cube",
                          sys->nbins, height, width);
    for (int b = 0; b < sys->nbins; b++) {
        float *band = lm_cube_band(out, b);
        for (size_t i = 0; i < (size_t)height * width; i++) band[i] = (float)background;
        for (int p = 0; p < NP; p++)
            for (int y = r[p].y; y < r[p].y + r[p].h; y++)
                for (int x = r[p].x; x < r[p].x + r[p].w; x++)
                    band[(size_t)y * width + x] = (float)C[p * sys->nbins + b];
    }
    return LM_OK;
}
