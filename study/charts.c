/* charts.c — chart data files, gnuplot scripts and the gnuplot runs of a study (charts.h).
 * Data come from the per-preset records (study.h) and each run's log.csv (train/train.h:
 * iteration,loss,lr,psnr,ssim,mae,sam, metrics only on validation rows). One data file per
 * model and quantity, so a model without data simply has no line.
 * What it is not: the study's table (results.c). */
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>
#include "study/charts.h"

#define CPATH 1400

static const char *const chart_names[] = {"accuracy_speed", "noise_psnr", "noise_ssim",
    "noise_sam", "train_loss", "train_val_psnr", "rainbow_peaks", "motion", "narrowband",
    "failure_3db", "cond_photons", "cond_saturation", "cond_led_gain", "cond_dead_pixels",
    "cond_motion", "accuracy_minutes", NULL};

void lm_study_pareto(const double *t, const double *a, int n, int *on)
{
    for (int i = 0; i < n; i++) {
        on[i] = isfinite(t[i]) && isfinite(a[i]);
        for (int j = 0; j < n && on[i]; j++) {
            if (j == i || !isfinite(t[j]) || !isfinite(a[j])) continue;
            if (t[j] <= t[i] && a[j] >= a[i] && (t[j] < t[i] || a[j] > a[i])) on[i] = 0;
        }
    }
}

int lm_charts_gnuplot_available(void)
{
    const char *p = getenv("PATH");
    char buf[CPATH];
    while (p && *p) {
        size_t n = strcspn(p, ":");
        snprintf(buf, sizeof buf, "%.*s/gnuplot", (int)n, n ? p : ".");
        if (access(buf, X_OK) == 0) return 1;
        p += n + (p[n] == ':');
    }
    return 0;
}

static double num(const json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

/* Metric `key` of level k of a record's evaluation. */
static double level(const json_t *rec, int k, const char *key)
{
    return num(json_array_get(json_object_get(json_object_get(rec, "eval"), "levels"),
                              (size_t)k), key);
}

static const char *preset(const json_t *rec)
{
    const char *s = json_string_value(json_object_get(rec, "preset"));
    return s ? s : "?";
}

static FILE *open_in(const char *dir, const char *name, char *path, lm_err *err)
{
    snprintf(path, CPATH, "%s/%s", dir, name);
    FILE *f = fopen(path, "w");
    if (!f) lm_err_set(err, LM_ERR_WRITE, "%s: cannot write (%s)", path, strerror(errno));
    return f;
}

static lm_status close_file(FILE *f, const char *path, lm_err *err)
{
    if (ferror(f) | fclose(f)) return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write", path);
    return LM_OK;
}

/* Script head: the PNG terminal (cairo when there), the output, the common style. */
static void gp_head(FILE *f, const char *name, const char *title, const char *xl, const char *yl)
{
    fprintf(f, "# %s.gp — written by lumosaic study; run `gnuplot %s.gp` in this folder.\n"
               "if (strstrt(GPVAL_TERMINALS, \"pngcairo\") > 0) {\n"
               "    set terminal pngcairo size 960,640 noenhanced font \"sans,11\"\n"
               "} else {\n"
               "    set terminal png size 960,640 noenhanced\n"
               "}\n"
               "set output \"%s.png\"\n"
               "set title \"%s\"\nset xlabel \"%s\"\nset ylabel \"%s\"\n"
               "set grid\nset key outside right top\n",
            name, name, name, title, xl, yl);
}

/* Script tail: the same plot again as SVG. */
static void gp_tail(FILE *f, const char *name)
{
    fprintf(f, "set terminal svg size 960,640 dynamic noenhanced\n"
               "set output \"%s.svg\"\nreplot\nset output\n", name);
}

/* speed.dat (model, seconds, PSNR at each of the two levels) and pareto_<k>.dat (the front,
 * by seconds). */
static lm_status speed_data(const json_t *runs, const int lv[2], int nl, const char *dir,
                            lm_err *err)
{
    char path[CPATH];
    int n = (int)json_array_size(runs);
    double *t = calloc((size_t)n + 1, sizeof *t), *a = calloc((size_t)n + 1, sizeof *a);
    int *on = calloc((size_t)n + 1, sizeof *on), *ord = calloc((size_t)n + 1, sizeof *ord);
    lm_status st = t && a && on && ord ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "charts: no memory");
    FILE *f = st ? NULL : open_in(dir, "speed.dat", path, err);
    if (!st && !f) st = err->status;
    for (int i = 0; f && i < n; i++) {
        const json_t *r = json_array_get(runs, (size_t)i);
        fprintf(f, "\"%s\" %.9g", preset(r), num(r, "seconds_per_frame"));
        for (int k = 0; k < nl; k++) fprintf(f, " %.6f", level(r, lv[k], "psnr"));
        fputc('\n', f);
    }
    if (f) st = close_file(f, path, err);
    for (int k = 0; !st && k < nl; k++) {
        int m = 0;
        for (int i = 0; i < n; i++) {
            t[i] = num(json_array_get(runs, (size_t)i), "seconds_per_frame");
            a[i] = level(json_array_get(runs, (size_t)i), lv[k], "psnr");
        }
        lm_study_pareto(t, a, n, on);
        for (int i = 0; i < n; i++) /* insertion by seconds */
            if (on[i]) {
                int j = m++;
                for (; j > 0 && t[ord[j - 1]] > t[i]; j--) ord[j] = ord[j - 1];
                ord[j] = i;
            }
        char name[32];
        snprintf(name, sizeof name, "pareto_%d.dat", k);
        if (!(f = open_in(dir, name, path, err))) st = err->status;
        for (int j = 0; f && j < m; j++) fprintf(f, "%.9g %.6f\n", t[ord[j]], a[ord[j]]);
        if (f) st = close_file(f, path, err);
    }
    free(t), free(a), free(on), free(ord);
    return st;
}

static lm_status speed_chart(const lm_study_cfg *cfg, const json_t *runs, const char *dir,
                             lm_err *err)
{
    int lv[2] = {lm_study_noise_index(cfg, 0), lm_study_noise_index(cfg, 10)};
    int nl = lv[1] == lv[0] ? 1 : 2;
    if (speed_data(runs, lv, nl, dir, err)) return err->status;
    char path[CPATH];
    FILE *f = open_in(dir, "accuracy_speed.gp", path, err);
    if (!f) return err->status;
    char xl[64];
    snprintf(xl, sizeof xl, "seconds per %d x %d frame", cfg->frame_w, cfg->frame_h);
    gp_head(f, "accuracy_speed", "Accuracy against speed (dashed: Pareto front)", xl,
            "PSNR (dB)");
    fprintf(f, "set logscale x\nset offsets graph 0.05, graph 0.15, graph 0.08, graph 0.08\n"
               "plot ");
    for (int k = 0; k < nl; k++)
        fprintf(f, "%s\"speed.dat\" using 2:%d with points pt %d ps 1.5 lc %d "
                   "title \"noise %g %%\", \\\n     \"speed.dat\" using 2:%d:1 with labels "
                   "offset 1,0.7 left tc lt %d notitle, \\\n     \"pareto_%d.dat\" using 1:2 "
                   "with lines dt 2 lw 1.5 lc %d title \"Pareto front, noise %g %%\"",
                k ? ", \\\n     " : "", 3 + k, 7 + 2 * k, k + 1, 100.0 * cfg->noise[lv[k]], 3 + k,
                k + 1, k, k + 1, 100.0 * cfg->noise[lv[k]]);
    fprintf(f, "\n");
    gp_tail(f, "accuracy_speed");
    return close_file(f, path, err);
}

/* noise_<preset>.dat: noise_percent psnr ssim mae sam, and the three noise charts. */
static lm_status noise_charts(const lm_study_cfg *cfg, const json_t *runs, const char *dir,
                              lm_err *err)
{
    char path[CPATH], name[128];
    size_t n = json_array_size(runs);
    for (size_t i = 0; i < n; i++) {
        const json_t *r = json_array_get(runs, i);
        snprintf(name, sizeof name, "noise_%s.dat", preset(r));
        FILE *f = open_in(dir, name, path, err);
        if (!f) return err->status;
        fprintf(f, "# noise_percent psnr ssim mae sam\n");
        for (int k = 0; k < cfg->nnoise; k++)
            fprintf(f, "%g %.6f %.6f %.8f %.6f\n", 100.0 * cfg->noise[k], level(r, k, "psnr"),
                    level(r, k, "ssim"), level(r, k, "mae"), level(r, k, "sam"));
        if (close_file(f, path, err)) return err->status;
    }
    static const char *const what[3][3] = {{"noise_psnr", "PSNR (dB)", "2"},
                                           {"noise_ssim", "SSIM", "3"},
                                           {"noise_sam", "SAM (degrees)", "5"}};
    for (int q = 0; q < 3; q++) {
        snprintf(name, sizeof name, "%s.gp", what[q][0]);
        FILE *f = open_in(dir, name, path, err);
        if (!f) return err->status;
        char title[96];
        snprintf(title, sizeof title, "%s against noise, held-out scenes", what[q][1]);
        gp_head(f, what[q][0], title, "noise (% of the largest clean value)", what[q][1]);
        fprintf(f, "plot ");
        for (size_t i = 0; i < n; i++)
            fprintf(f, "%s\"noise_%s.dat\" using 1:%s with linespoints lw 1.5 title \"%s\"",
                    i ? ", \\\n     " : "", preset(json_array_get(runs, i)), what[q][2],
                    preset(json_array_get(runs, i)));
        fprintf(f, "\n");
        gp_tail(f, what[q][0]);
        if (close_file(f, path, err)) return err->status;
    }
    return LM_OK;
}

/* One log.csv into loss_<preset>.dat and val_<preset>.dat; *nval = validation rows. */
/* loss_<preset>.dat: iteration, loss, its exponential moving average over ~smooth iterations. */
static lm_status curve_data(const json_t *rec, const char *sdir, const char *dir, int smooth,
                            int *nval, lm_err *err)
{
    char path[CPATH + 16], lp[CPATH], vp[CPATH], name[128], line[512];
    snprintf(path, sizeof path, "%s/runs/%s/log.csv", sdir, preset(rec));
    FILE *in = fopen(path, "r");
    if (!in) return lm_err_set(err, LM_ERR_IO, "%s: cannot open (%s)", path, strerror(errno));
    snprintf(name, sizeof name, "loss_%s.dat", preset(rec));
    FILE *fl = open_in(dir, name, lp, err), *fv = NULL;
    snprintf(name, sizeof name, "val_%s.dat", preset(rec));
    if (fl) fv = open_in(dir, name, vp, err);
    *nval = 0;
    double ema = 0, alpha = 2.0 / (smooth + 1.0);
    int first = 1;
    while (fv && fgets(line, sizeof line, in)) {
        char *fld[7];
        int k = lm_study_log_fields(line, fld);
        char *end;
        long it = strtol(fld[0], &end, 10);
        if (end == fld[0] || k < 4) continue; /* the header */
        double loss = fld[1][0] ? strtod(fld[1], NULL) : NAN;
        if (isfinite(loss)) {
            ema = first ? loss : ema + alpha * (loss - ema);
            first = 0;
            fprintf(fl, "%ld %.8g %.8g\n", it, loss, ema);
        }
        if (fld[3][0]) fprintf(fv, "%ld %s\n", it, fld[3]), ++*nval;
    }
    fclose(in);
    lm_status st = fl ? close_file(fl, lp, err) : err->status;
    if (fv && close_file(fv, vp, err)) st = err->status;
    return fv ? st : err->status;
}

static lm_status curve_chart(const json_t *runs, const char *name, const char *prefix,
                             const char *title, const char *yl, const int *use, const char *dir,
                             lm_err *err)
{
    char path[CPATH], gp[128];
    snprintf(gp, sizeof gp, "%s.gp", name);
    FILE *f = open_in(dir, gp, path, err);
    if (!f) return err->status;
    gp_head(f, name, title, "iteration", yl);
    fprintf(f, "%splot ", strcmp(prefix, "loss") ? "" : "set logscale y\n");
    int first = 1;
    for (size_t i = 0; i < json_array_size(runs); i++) {
        if (use && !use[i]) continue;
        const char *p = preset(json_array_get(runs, i));
        fprintf(f, "%s\"%s_%s.dat\" using 1:%d with %s title \"%s\"", first ? "" : ", \\\n     ",
                prefix, p, use ? 2 : 3, use ? "linespoints lw 1.5" : "lines lw 1.5", p);
        first = 0;
    }
    fprintf(f, "\n");
    gp_tail(f, name);
    return close_file(f, path, err);
}

static lm_status curve_charts(const json_t *runs, long iterations, const char *sdir,
                              const char *dir, lm_err *err)
{
    int smooth = iterations >= 200 ? (int)(iterations / 100) : 1;
    size_t n = json_array_size(runs);
    int *nval = calloc(n + 1, sizeof *nval), any = 0;
    if (!nval) return lm_err_set(err, LM_ERR_NOMEM, "charts: no memory");
    lm_status st = LM_OK;
    for (size_t i = 0; !st && i < n; i++) {
        st = curve_data(json_array_get(runs, i), sdir, dir, smooth, &nval[i], err);
        any |= nval[i] > 0;
    }
    char title[96];
    snprintf(title, sizeof title, "Training loss (L1, 33 channels)%s", smooth > 1
             ? "; moving average over ~1 % of the run" : "");
    if (!st) st = curve_chart(runs, "train_loss", "loss", title, "loss", NULL, dir, err);
    char path[CPATH + 32];
    snprintf(path, sizeof path, "%s/train_val_psnr.gp", dir);
    remove(path); /* no validation in any run: no chart */
    if (!st && any)
        st = curve_chart(runs, "train_val_psnr", "val", "Validation PSNR during training",
                         "PSNR (dB)", nval, dir, err);
    free(nval);
    return st;
}

/* ---- the rainbow, motion, conditions, 3-dB failure and narrowband charts ---------------- */

/* Remove a chart's script (the chart does not apply to this study). */
static void drop_chart(const char *dir, const char *name)
{
    static const char *const ext[3] = {"gp", "png", "svg"};
    char path[CPATH + 64];
    for (int i = 0; i < 3; i++)
        if (snprintf(path, sizeof path, "%s/%s.%s", dir, name, ext[i]) < (int)sizeof path)
            remove(path);
}

/* The record of family `fam` in a run's conditions when it applies, else NULL. */
static const json_t *family_rec(const json_t *rec, const char *fam)
{
    const json_t *fs = json_object_get(json_object_get(rec, "conditions"), "families");
    for (size_t i = 0; i < json_array_size(fs); i++) {
        const json_t *f = json_array_get(fs, i);
        const char *n = json_string_value(json_object_get(f, "family"));
        if (n && !strcmp(n, fam) && json_is_true(json_object_get(f, "applies"))) return f;
    }
    return NULL;
}

/* rainbow_<preset>.dat: true and recovered peak per row; rainbow_peaks.gp. */
static lm_status rainbow_chart(const json_t *runs, const char *dir, lm_err *err)
{
    char path[CPATH], name[128];
    size_t n = json_array_size(runs);
    int any = 0;
    for (size_t i = 0; i < n; i++) {
        const json_t *r = json_array_get(runs, i);
        const json_t *rows = json_object_get(json_object_get(r, "rainbow"),
                                             "rows_true_recovered_nm");
        if (!json_array_size(rows)) continue;
        snprintf(name, sizeof name, "rainbow_%s.dat", preset(r));
        FILE *f = open_in(dir, name, path, err);
        if (!f) return err->status;
        fprintf(f, "# true_peak_nm recovered_peak_nm (one line per row of the rainbow)\n");
        for (size_t y = 0; y < json_array_size(rows); y++) {
            const json_t *p = json_array_get(rows, y);
            fprintf(f, "%.4f %.4f\n", json_number_value(json_array_get(p, 0)),
                    json_number_value(json_array_get(p, 1)));
        }
        if (close_file(f, path, err)) return err->status;
        any = 1;
    }
    if (!any) return drop_chart(dir, "rainbow_peaks"), LM_OK;
    FILE *f = open_in(dir, "rainbow_peaks.gp", path, err);
    if (!f) return err->status;
    gp_head(f, "rainbow_peaks", "Rainbow scene: recovered against true peak wavelength per row",
            "true peak (nm)", "recovered peak (nm)");
    fprintf(f, "set xrange [400:700]\nset yrange [380:720]\nplot x with lines dt 2 lc rgb "
               "\"gray40\" title \"ideal\"");
    for (size_t i = 0; i < n; i++) {
        const json_t *r = json_array_get(runs, i);
        if (json_array_size(json_object_get(json_object_get(r, "rainbow"),
                                            "rows_true_recovered_nm")))
            fprintf(f, ", \\\n     \"rainbow_%s.dat\" using 1:2 with lines lw 1.5 title \"%s\"",
                    preset(r), preset(r));
    }
    fprintf(f, "\n");
    gp_tail(f, "rainbow_peaks");
    return close_file(f, path, err);
}

/* cond_<family>_<preset>.dat: level psnr ssim sam psnr_unaligned psnr_static px_per_frame
 * (the last three: motion's, else psnr, psnr and the level); fail_<family>.dat: each
 * model's 3-dB point (level, clean - 3 dB). Returns the number of models with data. */
static int cond_data(const json_t *runs, const char *fam, const char *dir, int *ncross,
                     lm_err *err)
{
    *ncross = 0;
    char path[CPATH], name[192];
    int any = 0;
    FILE *ff = NULL;
    snprintf(name, sizeof name, "fail_%s.dat", fam);
    if (!(ff = open_in(dir, name, path, err))) return -1;
    char fpath[CPATH];
    memcpy(fpath, path, sizeof fpath);
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i), *fr = family_rec(r, fam);
        if (!fr) continue;
        snprintf(name, sizeof name, "cond_%s_%s.dat", fam, preset(r));
        FILE *f = open_in(dir, name, path, err);
        if (!f) return fclose(ff), -1;
        fprintf(f, "# level psnr ssim sam psnr_unaligned psnr_static px_per_frame\n");
        const json_t *lv = json_object_get(fr, "levels");
        for (size_t k = 0; k < json_array_size(lv); k++) {
            const json_t *l = json_array_get(lv, k);
            double u = num(l, "psnr_unaligned"), st = num(l, "psnr_static");
            double px = num(l, "px_per_frame");
            fprintf(f, "%.9g %.6f %.6f %.6f %.6f %.6f %.9g\n", num(l, "level"), num(l, "psnr"),
                    num(l, "ssim"), num(l, "sam"), isfinite(u) ? u : num(l, "psnr"),
                    isfinite(st) ? st : num(l, "psnr"), isfinite(px) ? px : num(l, "level"));
        }
        if (close_file(f, path, err)) return fclose(ff), -1;
        double at = num(fr, "drop_3db");
        double clean = num(json_object_get(r, "conditions"), "clean_psnr");
        if (isfinite(at)) fprintf(ff, "%.9g %.6f \"%s\"\n", at, clean - 3.0, preset(r)), ++*ncross;
        any++;
    }
    return close_file(ff, fpath, err) ? -1 : any;
}

/* cond_<family>.gp: PSNR against the level, a line per model, crosses at the 3-dB points. */
static lm_status cond_chart(const json_t *runs, lm_cond_family fam, const char *dir,
                            lm_err *err)
{
    const char *fn = lm_cond_name(fam);
    char path[CPATH], name[64], title[160];
    snprintf(name, sizeof name, "cond_%s", fn);
    int nc, k = cond_data(runs, fn, dir, &nc, err);
    if (k < 0) return err->status;
    if (k == 0) return drop_chart(dir, name), LM_OK;
    char gp[80];
    snprintf(gp, sizeof gp, "%s.gp", name);
    FILE *f = open_in(dir, gp, path, err);
    if (!f) return err->status;
    snprintf(title, sizeof title, "PSNR under %s (crosses: 3 dB below the model's clean PSNR)",
             fn);
    gp_head(f, name, title, lm_cond_unit(fam), "PSNR (dB)");
    if (fam == LM_COND_PHOTONS) fprintf(f, "set logscale x\nset xrange [*:*] reverse\n");
    fprintf(f, "set datafile missing \"NaN\"\nplot ");
    int first = 1;
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i);
        if (!family_rec(r, fn)) continue;
        fprintf(f, "%s\"cond_%s_%s.dat\" using 1:2 with linespoints lw 1.5 lc %zu title \"%s\"",
                first ? "" : ", \\\n     ", fn, preset(r), i + 1, preset(r));
        first = 0;
    }
    if (nc)
        fprintf(f, ", \\\n     \"fail_%s.dat\" using 1:2 with points pt 2 ps 2 lw 2 lc rgb "
                   "\"black\" title \"3-dB point\"", fn);
    fprintf(f, "\n");
    gp_tail(f, name);
    return close_file(f, path, err);
}

/* motion.gp: PSNR against the displacement per frame, aligned (solid), as recorded (dashed)
 * and the static reference (dotted: the same scene still), from cond_motion_*. */
static lm_status motion_chart(const json_t *runs, const char *dir, lm_err *err)
{
    char path[CPATH];
    int any = 0;
    for (size_t i = 0; i < json_array_size(runs); i++)
        any |= family_rec(json_array_get(runs, i), "motion") != NULL;
    if (!any) return drop_chart(dir, "motion"), LM_OK;
    FILE *f = open_in(dir, "motion.gp", path, err);
    if (!f) return err->status;
    gp_head(f, "motion", "PSNR against motion: aligned (solid), unaligned (dashed), static "
            "reference (dotted)", "motion (px/frame)", "PSNR (dB)");
    fprintf(f, "plot ");
    int first = 1;
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i);
        if (!family_rec(r, "motion")) continue;
        fprintf(f, "%s\"cond_motion_%s.dat\" using 7:2 with linespoints lw 1.5 lc %zu title "
                   "\"%s aligned\", \\\n     \"cond_motion_%s.dat\" using 7:5 with linespoints "
                   "dt 2 lw 1.5 lc %zu title \"%s unaligned\", \\\n     \"cond_motion_%s.dat\" "
                   "using 7:6 with lines dt 3 lw 1.5 lc %zu title \"%s static\"",
                first ? "" : ", \\\n     ", preset(r), i + 1, preset(r), preset(r), i + 1,
                preset(r), preset(r), i + 1, preset(r));
        first = 0;
    }
    fprintf(f, "\n");
    gp_tail(f, "motion");
    return close_file(f, path, err);
}

/* failure_<family>.dat: index, model, 3-dB level (the last level when never reached), label. */
static lm_status failure_data(const json_t *runs, const char *fam, const char *dir, int *any,
                              lm_err *err)
{
    char path[CPATH], name[96];
    snprintf(name, sizeof name, "failure_%s.dat", fam);
    FILE *f = open_in(dir, name, path, err);
    if (!f) return err->status;
    *any = 0;
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i), *fr = family_rec(r, fam);
        const json_t *lv = fr ? json_object_get(fr, "levels") : NULL;
        double at = num(fr, "drop_3db");
        double last = num(json_array_get(lv, json_array_size(lv) - 1), "level");
        char lab[64];
        if (!fr) snprintf(lab, sizeof lab, "n/a");
        else if (isfinite(at)) snprintf(lab, sizeof lab, "%.3g", at);
        else snprintf(lab, sizeof lab, "> %g", last);
        fprintf(f, "%zu \"%s\" %.9g \"%s\"\n", i, preset(r), fr ? (isfinite(at) ? at : last) : NAN,
                lab);
        *any |= fr != NULL;
    }
    return close_file(f, path, err);
}

static void failure_plots(FILE *f, const int *use, int nuse)
{
    fprintf(f, "set multiplot layout %d,%d title \"Level at which each model loses 3 dB against "
               "its own clean PSNR (label '> x': never, up to the last level x)\"\n",
            nuse > 3 ? 2 : 1, nuse > 3 ? (nuse + 1) / 2 : nuse);
    for (int q = 0; q < LM_COND_NFAMILIES; q++) {
        if (!use[q]) continue;
        const char *fn = lm_cond_name((lm_cond_family)q);
        fprintf(f, "set title \"%s\"\nset ylabel \"%s\"\n%s", fn, lm_cond_unit((lm_cond_family)q),
                q == LM_COND_PHOTONS ? "set logscale y\nset yrange [*:*]\n"
                                     : "unset logscale y\nset yrange [0:*]\n");
        fprintf(f, "plot \"failure_%s.dat\" using 1:3:xtic(2) with boxes fs solid 0.5 notitle, "
                   "\\\n     \"\" using 1:3:4 with labels rotate by 90 left offset 0,0.4 "
                   "font \",9\" notitle\n", fn);
    }
    fprintf(f, "unset multiplot\n");
}

/* failure_3db.gp: a panel per family (multiplot: PNG and SVG written separately). */
static lm_status failure_chart(const json_t *runs, const char *dir, lm_err *err)
{
    int use[LM_COND_NFAMILIES], nuse = 0;
    for (int q = 0; q < LM_COND_NFAMILIES; q++) {
        if (failure_data(runs, lm_cond_name((lm_cond_family)q), dir, &use[q], err))
            return err->status;
        nuse += use[q];
    }
    if (!nuse) return drop_chart(dir, "failure_3db"), LM_OK;
    char path[CPATH];
    FILE *f = open_in(dir, "failure_3db.gp", path, err);
    if (!f) return err->status;
    gp_head(f, "failure_3db", "", "", "");
    fprintf(f, "set datafile missing \"NaN\"\nset style fill solid 0.5\nset boxwidth 0.6\n"
               "set xtics rotate by -30\nset xlabel \"\"\nset offsets 0.5, 0.5, graph 0.35, 0\n"
               "unset key\n");
    failure_plots(f, use, nuse);
    fprintf(f, "set terminal svg size 960,640 dynamic noenhanced\nset output \"failure_3db.svg\"\n");
    failure_plots(f, use, nuse);
    fprintf(f, "set output\n");
    return close_file(f, path, err);
}

/* narrowband.dat (synthetic share %, rainbow peak error, rainbow PSNR, held-out PSNR at the
 * first noise level) and narrowband.gp. */
static lm_status narrowband_chart(const json_t *nb, const char *dir, lm_err *err)
{
    if (!json_array_size(nb)) return drop_chart(dir, "narrowband"), LM_OK;
    char path[CPATH];
    FILE *f = open_in(dir, "narrowband.dat", path, err);
    if (!f) return err->status;
    fprintf(f, "# synth_percent rainbow_peak_error_mean_nm rainbow_psnr heldout_psnr\n");
    for (size_t i = 0; i < json_array_size(nb); i++) {
        const json_t *r = json_array_get(nb, i), *rb = json_object_get(r, "rainbow");
        fprintf(f, "%g %.6f %.6f %.6f\n", 100.0 * num(r, "synth_fraction"),
                num(rb, "peak_error_mean_nm"), num(rb, "psnr"), level(r, 0, "psnr"));
    }
    if (close_file(f, path, err)) return err->status;
    if (!(f = open_in(dir, "narrowband.gp", path, err))) return err->status;
    char title[160];
    snprintf(title, sizeof title, "Rainbow accuracy of %s against the synthetic share of "
             "training", preset(json_array_get(nb, 0)));
    gp_head(f, "narrowband", title, "narrowband synthetic samples in training (%)",
            "rainbow mean peak error (nm)");
    fprintf(f, "set y2label \"PSNR (dB)\"\nset y2tics\nset ytics nomirror\nset xrange [-5:105]\n"
               "plot \"narrowband.dat\" using 1:2 with linespoints lw 2 pt 7 title \"rainbow "
               "peak error\", \\\n     \"\" using 1:3 axes x1y2 with linespoints dt 2 pt 5 "
               "title \"rainbow PSNR\", \\\n     \"\" using 1:4 axes x1y2 with linespoints dt 3 "
               "pt 9 title \"held-out PSNR\"\n");
    gp_tail(f, "narrowband");
    return close_file(f, path, err);
}

/* minutes_<preset>.dat (training minutes, PSNR at the two levels) from each record's "curve"
 * and accuracy_minutes.gp: accuracy against training time. No curve anywhere: no chart. */
static lm_status minutes_chart(const lm_study_cfg *cfg, const json_t *runs, const char *dir,
                               lm_err *err)
{
    int lv[2] = {lm_study_noise_index(cfg, 0), lm_study_noise_index(cfg, 10)};
    char path[CPATH], name[128];
    int n = (int)json_array_size(runs), any = 0;
    for (int i = 0; i < n; i++) {
        const json_t *rec = json_array_get(runs, i), *cv = json_object_get(rec, "curve");
        if (!json_array_size(cv)) continue;
        snprintf(name, sizeof name, "minutes_%s.dat", preset(rec));
        FILE *f = open_in(dir, name, path, err);
        if (!f) return err->status;
        for (size_t j = 0; j < json_array_size(cv); j++) {
            const json_t *pt = json_array_get(cv, j), *l = json_object_get(pt, "levels");
            fprintf(f, "%.6g %.6g %.6g\n", num(pt, "minutes"),
                    num(json_array_get(l, (size_t)lv[0]), "psnr"),
                    num(json_array_get(l, (size_t)lv[1]), "psnr"));
        }
        if (close_file(f, path, err)) return err->status;
        any = 1;
    }
    char gp[CPATH + 32];
    snprintf(gp, sizeof gp, "%s/accuracy_minutes.gp", dir);
    remove(gp);
    if (!any) return LM_OK;
    FILE *f = open_in(dir, "accuracy_minutes.gp", path, err);
    if (!f) return err->status;
    gp_head(f, "accuracy_minutes", "Held-out accuracy against training time (solid: noise "
            "0 %, dashed: 10 %)", strcmp(cfg->train.clock, "cpu") ? "minutes of training "
            "(this machine)" : "CPU minutes of training (this machine)", "PSNR (dB)");
    fprintf(f, "set logscale x\nplot ");
    int first = 1;
    for (int i = 0; i < n; i++) {
        const json_t *rec = json_array_get(runs, i);
        if (!json_array_size(json_object_get(rec, "curve"))) continue;
        fprintf(f, "%s\"minutes_%s.dat\" using 1:2 with linespoints lw 1.5 pt 7 lc %d title "
                "\"%s\", \\\n     \"minutes_%s.dat\" using 1:3 with linespoints dt 2 pt 6 lc %d "
                "notitle", first ? "" : ", \\\n     ", preset(rec), i + 1, preset(rec),
                preset(rec), i + 1);
        first = 0;
    }
    fprintf(f, "\n");
    gp_tail(f, "accuracy_minutes");
    return close_file(f, path, err);
}

static lm_status more_charts(const lm_study *s, const char *cdir, lm_err *err)
{
    lm_status st = rainbow_chart(s->runs, cdir, err);
    for (int q = 0; !st && q < LM_COND_NFAMILIES; q++)
        st = cond_chart(s->runs, (lm_cond_family)q, cdir, err);
    if (!st) st = motion_chart(s->runs, cdir, err);
    if (!st) st = failure_chart(s->runs, cdir, err);
    if (!st) st = narrowband_chart(s->narrowband, cdir, err);
    return st;
}

lm_status lm_charts_write(const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                          lm_err *err)
{
    char cdir[CPATH];
    snprintf(cdir, sizeof cdir, "%s/charts", dir);
    if (mkdir(cdir, 0777) && errno != EEXIST)
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot create (%s)", cdir, strerror(errno));
    lm_status st = speed_chart(cfg, s->runs, cdir, err);
    if (!st) st = noise_charts(cfg, s->runs, cdir, err);
    if (!st) st = curve_charts(s->runs, cfg->train.iterations, dir, cdir, err);
    if (!st) st = more_charts(s, cdir, err);
    if (!st) st = minutes_chart(cfg, s->runs, cdir, err);
    return st;
}

/* gnuplot <script> in folder cdir, output appended to gnuplot.log. Exit status, or -1. */
static int run_gnuplot(const char *cdir, const char *script)
{
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        if (chdir(cdir) != 0) _exit(127);
        int fd = open("gnuplot.log", O_WRONLY | O_CREAT | O_APPEND, 0666);
        if (fd >= 0) {
            dup2(fd, 1);
            dup2(fd, 2);
            close(fd);
        }
        execlp("gnuplot", "gnuplot", script, (char *)NULL);
        _exit(127);
    }
    int status;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

lm_status lm_charts_render(const char *dir, lm_err *err)
{
    char cdir[CPATH], path[CPATH + 64];
    snprintf(cdir, sizeof cdir, "%s/charts", dir);
    if (!lm_charts_gnuplot_available())
        return lm_err_set(err, LM_ERR_IO, "charts: gnuplot not found on PATH (install gnuplot, "
                          "or pass --no-charts)");
    snprintf(path, sizeof path, "%s/gnuplot.log", cdir);
    remove(path);
    for (int i = 0; chart_names[i]; i++) {
        char script[64];
        snprintf(script, sizeof script, "%s.gp", chart_names[i]);
        snprintf(path, sizeof path, "%s/%s", cdir, script);
        if (access(path, F_OK) != 0) continue;
        int rc = run_gnuplot(cdir, script);
        if (rc == 127) return lm_err_set(err, LM_ERR_IO, "charts: cannot run gnuplot");
        if (rc != 0)
            return lm_err_set(err, LM_ERR_IO, "charts: gnuplot failed on %s (see %s/gnuplot.log)",
                              path, cdir);
    }
    return LM_OK;
}
