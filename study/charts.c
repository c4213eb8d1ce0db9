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
                                          "noise_sam", "train_loss", "train_val_psnr", NULL};

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
    if (!f) lm_err_set(err, LM_ERR_IO, "%s: cannot write (%s)", path, strerror(errno));
    return f;
}

static lm_status close_file(FILE *f, const char *path, lm_err *err)
{
    if (ferror(f) | fclose(f)) return lm_err_set(err, LM_ERR_IO, "%s: cannot write", path);
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
        char *fld[7] = {0}, *p = line;
        int k = 0;
        for (; k < 7 && p; k++) {
            fld[k] = p;
            p = strchr(p, ',');
            if (p) *p++ = 0;
        }
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

lm_status lm_charts_write(const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                          lm_err *err)
{
    char cdir[CPATH];
    snprintf(cdir, sizeof cdir, "%s/charts", dir);
    if (mkdir(cdir, 0777) && errno != EEXIST)
        return lm_err_set(err, LM_ERR_IO, "%s: cannot create (%s)", cdir, strerror(errno));
    lm_status st = speed_chart(cfg, s->runs, cdir, err);
    if (!st) st = noise_charts(cfg, s->runs, cdir, err);
    if (!st) st = curve_charts(s->runs, cfg->train.iterations, dir, cdir, err);
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
