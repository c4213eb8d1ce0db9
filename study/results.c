/* results.c — the summary files of a study (lm_study_write): results.json (the configuration
 * summary, the held-out set and every per-preset record as written by study.c), results.csv
 * (a row per model and noise level) and results.md (the tables and the chart links).
 * Record fields used here: preset, params, macs_per_frame, seconds_per_frame, threads,
 * eval.levels[k].{noise_percent, psnr, ssim, mae, sam}, rainbow.peak_error_mean_nm, train.*.
 * What it is not: the run (study.c) or the charts (charts.c). */
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "study/charts.h"
#include "study/study.h"

#define RPATH 1400

static double num(const json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

static double level(const json_t *rec, int k, const char *key)
{
    return num(json_array_get(json_object_get(json_object_get(rec, "eval"), "levels"),
                              (size_t)k), key);
}

static const char *str(const json_t *o, const char *key)
{
    const char *s = json_string_value(json_object_get(o, key));
    return s ? s : "";
}

static json_t *summary_json(const lm_study_cfg *cfg, const lm_study *s)
{
    const lm_train_cfg *t = &cfg->train;
    json_t *noise = json_array();
    for (int k = 0; k < cfg->nnoise; k++)
        json_array_append_new(noise, json_real(nearbyint(1e6 * cfg->noise[k]) / 1e4));
    json_t *data = json_array();
    for (int i = 0; i < t->ndata; i++) json_array_append_new(data, json_string(t->data[i]));
    json_t *train = json_pack("{s:I, s:[i,i], s:i, s:i, s:f, s:f, s:s, s:[f,f], s:I, s:o}",
                              "iterations", (json_int_t)t->iterations, "patch", t->patch_h,
                              t->patch_w, "batch", t->batch, "accum_steps", t->accum_steps,
                              "lr", (double)t->lr, "synth_fraction", (double)t->synth_fraction,
                              "schedule", t->schedule, "noise", (double)t->noise_min,
                              (double)t->noise_max, "seed", (json_int_t)t->seed, "data", data);
    json_t *j = json_pack("{s:i, s:s, s:o, s:o, s:O, s:[i,i], s:i, s:O}", "version", 1,
                          "config", cfg->path, "training", train, "noise_percent", noise,
                          "held_out", s->held_out, "frame", cfg->frame_h, cfg->frame_w,
                          "timing_repeats", cfg->timing_repeats, "runs", s->runs);
    if (j && s->narrowband) json_object_set(j, "narrowband_sweep", s->narrowband);
    return j;
}

static FILE *open_tmp(const char *dir, const char *name, char *tmp, char *dst, lm_err *err)
{
    snprintf(dst, RPATH, "%s/%s", dir, name);
    snprintf(tmp, RPATH + 32, "%s.tmp.%d", dst, (int)getpid());
    FILE *f = fopen(tmp, "w");
    if (!f) lm_err_set(err, LM_ERR_WRITE, "%s: cannot write (%s)", tmp, strerror(errno));
    return f;
}

static lm_status commit(FILE *f, const char *tmp, const char *dst, lm_err *err)
{
    if ((ferror(f) | fclose(f)) || rename(tmp, dst)) {
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write", dst);
    }
    return LM_OK;
}

static void write_csv(FILE *f, const lm_study_cfg *cfg, const json_t *runs)
{
    fprintf(f, "preset,noise_percent,psnr,ssim,mae,sam,params,macs_per_frame,seconds_per_frame,"
               "rainbow_peak_error_mean_nm,iterations\n");
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i);
        for (int k = 0; k < cfg->nnoise; k++)
            fprintf(f, "%s,%g,%.6f,%.6f,%.8f,%.6f,%.0f,%.0f,%.6f,%.4f,%.0f\n", str(r, "preset"),
                    100.0 * cfg->noise[k], level(r, k, "psnr"), level(r, k, "ssim"),
                    level(r, k, "mae"), level(r, k, "sam"), num(r, "params"),
                    num(r, "macs_per_frame"), num(r, "seconds_per_frame"),
                    num(json_object_get(r, "rainbow"), "peak_error_mean_nm"),
                    num(json_object_get(r, "train"), "iterations"));
    }
}

/* v with `digits` decimals, or "n/a" when it was not measured (null in the record). */
static void fmt_or_na(FILE *f, int digits, double v)
{
    if (isfinite(v)) fprintf(f, "%.*f", digits, v);
    else fprintf(f, "n/a");
}

/* "yes" on the Pareto front of PSNR at level k against seconds. */
static void front(const json_t *runs, int k, int *on)
{
    int n = (int)json_array_size(runs);
    double *t = calloc((size_t)n + 1, sizeof *t), *a = calloc((size_t)n + 1, sizeof *a);
    for (int i = 0; t && a && i < n; i++) {
        t[i] = num(json_array_get(runs, (size_t)i), "seconds_per_frame");
        a[i] = level(json_array_get(runs, (size_t)i), k, "psnr");
    }
    if (t && a) lm_study_pareto(t, a, n, on);
    else memset(on, 0, (size_t)n * sizeof *on);
    free(t), free(a);
}

static void md_main_table(FILE *f, const lm_study_cfg *cfg, const json_t *runs)
{
    int n = (int)json_array_size(runs), k0 = lm_study_noise_index(cfg, 0);
    int k10 = lm_study_noise_index(cfg, 10);
    int *on0 = calloc((size_t)n + 1, sizeof *on0), *on10 = calloc((size_t)n + 1, sizeof *on10);
    if (on0 && on10) front(runs, k0, on0), front(runs, k10, on10);
    fprintf(f, "| model | parameters | GMAC / frame | s / frame |");
    for (int k = 0; k < cfg->nnoise; k++) fprintf(f, " PSNR %g %% |", 100.0 * cfg->noise[k]);
    fprintf(f, " SSIM %g %% | SAM %g %% (deg) | rainbow peak error (nm) | Pareto |\n|---|---:|"
               "---:|---:|", 100.0 * cfg->noise[k0], 100.0 * cfg->noise[k0]);
    for (int k = 0; k < cfg->nnoise; k++) fprintf(f, "---:|");
    fprintf(f, "---:|---:|---:|---|\n");
    for (int i = 0; i < n; i++) {
        const json_t *r = json_array_get(runs, (size_t)i);
        fprintf(f, "| %s | %.0f | ", str(r, "preset"), num(r, "params"));
        fmt_or_na(f, 2, num(r, "macs_per_frame") / 1e9); /* null for RGB models (MST++) */
        fprintf(f, " | %.3f |", num(r, "seconds_per_frame"));
        for (int k = 0; k < cfg->nnoise; k++) fprintf(f, " %.2f |", level(r, k, "psnr"));
        const char *p = on0 && on10 && on0[i] ? (on10[i] ? "both" : "0 %")
                      : on10 && on10[i] ? "10 %" : "";
        fprintf(f, " %.4f | %.2f | %.2f | %s |\n", level(r, k0, "ssim"), level(r, k0, "sam"),
                num(json_object_get(r, "rainbow"), "peak_error_mean_nm"), p);
    }
    free(on0), free(on10);
}

/* Accuracy against training time: each run's curve (snapshots), PSNR at 0 % and 10 %. */
static void md_curve_table(FILE *f, const lm_study_cfg *cfg, const json_t *runs)
{
    int k0 = lm_study_noise_index(cfg, 0), k10 = lm_study_noise_index(cfg, 10), any = 0;
    for (size_t i = 0; i < json_array_size(runs); i++)
        any |= json_array_size(json_object_get(json_array_get(runs, i), "curve")) > 0;
    if (!any) return;
    fprintf(f, "\n## Accuracy against training time\n\nHeld-out PSNR (dB) at %g %% / %g %% noise "
               "of the weights after the given minutes of training on this machine (%s; "
               "snapshots of one run whose schedule spans the %g-minute budget; a closed-form "
               "fit: its fit time; a residual: its own training, after its base's).\n\n| model "
               "| points (minutes: PSNR %g %% / %g %%) | note |\n|---|---|---|\n",
            100.0 * cfg->noise[k0], 100.0 * cfg->noise[k10],
            strcmp(cfg->train.clock, "cpu") ? "wall-clock minutes"
            : "CPU minutes of the training process, all its threads: a budget that runs sharing "
              "the machine do not shrink",
            (double)cfg->train.minutes,
            100.0 * cfg->noise[k0], 100.0 * cfg->noise[k10]);
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i), *cv = json_object_get(r, "curve");
        fprintf(f, "| %s |", str(r, "preset"));
        for (size_t j = 0; j < json_array_size(cv); j++) {
            const json_t *pt = json_array_get(cv, j), *l = json_object_get(pt, "levels");
            fprintf(f, "%s %.3g: %.2f / %.2f", j ? ";" : "", num(pt, "minutes"),
                    num(json_array_get(l, (size_t)k0), "psnr"),
                    num(json_array_get(l, (size_t)k10), "psnr"));
        }
        const json_t *d = json_object_get(r, "dropped");
        if (d) fprintf(f, " | dropped at %g min: more than %g dB behind the best |\n",
                       num(d, "after_minutes"), num(d, "behind_db"));
        else fprintf(f, " | |\n");
    }
}

static void md_detail_table(FILE *f, const lm_study_cfg *cfg, const json_t *runs)
{
    fprintf(f, "\n### Every noise level\n\n| model | noise %% | PSNR (dB) | SSIM | MAE | SAM (deg) |"
               "\n|---|---:|---:|---:|---:|---:|\n");
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i);
        for (int k = 0; k < cfg->nnoise; k++)
            fprintf(f, "| %s | %g | %.3f | %.4f | %.5f | %.3f |\n", str(r, "preset"),
                    100.0 * cfg->noise[k], level(r, k, "psnr"), level(r, k, "ssim"),
                    level(r, k, "mae"), level(r, k, "sam"));
    }
    fprintf(f, "\n### Training\n\n| model | iterations | seconds (last invocation) | first loss |"
               " final loss | validation PSNR |\n|---|---:|---:|---:|---:|---:|\n");
    for (size_t i = 0; i < json_array_size(runs); i++) {
        const json_t *r = json_array_get(runs, i), *t = json_object_get(r, "train");
        fprintf(f, "| %s | ", str(r, "preset")); /* n/a: not recorded (closed form: no loss) */
        fmt_or_na(f, 0, num(t, "iterations"));
        fprintf(f, " | ");
        fmt_or_na(f, 1, num(t, "seconds"));
        fprintf(f, " | ");
        fmt_or_na(f, 5, num(t, "first_loss"));
        fprintf(f, " | ");
        fmt_or_na(f, 5, num(t, "final_loss"));
        fprintf(f, " | ");
        fmt_or_na(f, 3, num(json_object_get(t, "val"), "psnr")); /* null: no val split */
        fprintf(f, " |\n");
    }
}

/* The family record of a run (NULL when not measured). */
static const json_t *fam_rec(const json_t *r, const char *fam)
{
    const json_t *fs = json_object_get(json_object_get(r, "conditions"), "families");
    for (size_t i = 0; i < json_array_size(fs); i++)
        if (!strcmp(str(json_array_get(fs, i), "family"), fam)) return json_array_get(fs, i);
    return NULL;
}

/* The 3-dB table: per model and configured family the level of the 3-dB loss. */
static void md_failure(FILE *f, const lm_study_cfg *cfg, const json_t *runs)
{
    if (cfg->ncond == 0) return;
    fprintf(f, "\n## Where methods fail\n\nEach model's mean PSNR over the first %d held-out "
               "scene(s) under each condition, against its own clean-input PSNR (noise-free "
               "frame): the level at which it first loses 3 dB, interpolated linearly between "
               "the levels of the sweep; \"> x\" = never up to the last level x; n/a = the "
               "condition does not apply (RGB input).\n\n| model | clean PSNR |",
            (int)num(json_object_get(json_array_get(runs, 0), "conditions"), "scenes"));
    for (int i = 0; i < cfg->ncond; i++)
        fprintf(f, " %s: %s |", lm_cond_name(cfg->cond[i].family),
                lm_cond_unit(cfg->cond[i].family));
    fprintf(f, "\n|---|---:|");
    for (int i = 0; i < cfg->ncond; i++) fprintf(f, "---:|");
    fprintf(f, "\n");
    for (size_t r = 0; r < json_array_size(runs); r++) {
        const json_t *rec = json_array_get(runs, r);
        fprintf(f, "| %s | %.2f |", str(rec, "preset"),
                num(json_object_get(rec, "conditions"), "clean_psnr"));
        for (int i = 0; i < cfg->ncond; i++) {
            const json_t *fr = fam_rec(rec, lm_cond_name(cfg->cond[i].family));
            const json_t *lv = json_object_get(fr, "levels");
            double at = num(fr, "drop_3db");
            if (!fr || !json_is_true(json_object_get(fr, "applies"))) fprintf(f, " n/a |");
            else if (isfinite(at)) fprintf(f, " %.3g |", at);
            else fprintf(f, " > %g |", num(json_array_get(lv, json_array_size(lv) - 1), "level"));
        }
        fprintf(f, "\n");
    }
    fprintf(f, "\n### PSNR per condition level\n\n| model | condition | level: PSNR (dB) |\n"
               "|---|---|---|\n");
    for (size_t r = 0; r < json_array_size(runs); r++)
        for (int i = 0; i < cfg->ncond; i++) {
            const json_t *rec = json_array_get(runs, r);
            const json_t *fr = fam_rec(rec, lm_cond_name(cfg->cond[i].family));
            const json_t *lv = json_object_get(fr, "levels");
            if (!json_array_size(lv)) continue;
            fprintf(f, "| %s | %s |", str(rec, "preset"), lm_cond_name(cfg->cond[i].family));
            for (size_t k = 0; k < json_array_size(lv); k++) {
                const json_t *l = json_array_get(lv, k);
                fprintf(f, " %g: %.2f", num(l, "level"), num(l, "psnr"));
                if (isfinite(num(l, "psnr_unaligned")))
                    fprintf(f, " (unaligned %.2f, static %.2f)", num(l, "psnr_unaligned"),
                            num(l, "psnr_static"));
                fprintf(f, "%s", k + 1 < json_array_size(lv) ? ";" : "");
            }
            fprintf(f, " |\n");
        }
}

static void md_narrowband(FILE *f, const lm_study_cfg *cfg, const json_t *nb)
{
    if (!json_array_size(nb)) return;
    fprintf(f, "\n## Synthetic share of training and the rainbow\n\n%s trained with the same "
               "budget at each share of the paper's synthetic samples (narrowband textureless "
               "patches, data/dataset.h synth_fraction; no procedural scenes in these runs), "
               "then run through the rainbow test.\n\n"
               "| synthetic share | rainbow peak error (nm) | rainbow max error (nm) | rainbow "
               "PSNR | held-out PSNR %g %% |\n|---:|---:|---:|---:|---:|\n", cfg->nb_preset,
            100.0 * cfg->noise[0]);
    for (size_t i = 0; i < json_array_size(nb); i++) {
        const json_t *r = json_array_get(nb, i), *rb = json_object_get(r, "rainbow");
        fprintf(f, "| %g %% | %.2f | %.2f | %.2f | %.2f |\n", 100.0 * num(r, "synth_fraction"),
                num(rb, "peak_error_mean_nm"), num(rb, "peak_error_max_nm"), num(rb, "psnr"),
                level(r, 0, "psnr"));
    }
}

static void md_held_out(FILE *f, const lm_study_cfg *cfg, const json_t *h)
{
    const json_t *sc = json_object_get(h, "scenes");
    if (!strcmp(str(h, "kind"), "procedural")) {
        fprintf(f, "**Held-out set: %zu procedural scenes** (%d x %d, data/synth.h). The test "
                   "split of the data is empty (a tenth of the scene groups, rounded: none "
                   "here; data/dataset.h), so the models are scored on procedural scenes "
                   "whose seeds come from a stream of the study seed that training never "
                   "draws from.\n\n",
                json_array_size(sc), cfg->eval_h, cfg->eval_w);
        return;
    }
    fprintf(f, "**Held-out set:** the %zu scene(s) of the test split:", json_array_size(sc));
    for (size_t i = 0; i < json_array_size(sc); i++)
        fprintf(f, "%s %s", i ? "," : "", json_string_value(json_array_get(sc, i)));
    fprintf(f, ".\n\n");
}

static void write_md(FILE *f, const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                     int charts)
{
    const lm_train_cfg *t = &cfg->train;
    const json_t *r0 = json_array_get(s->runs, 0);
    char budget[160], noise[64];
    if (t->minutes > 0) /* the iterations are only the schedule's cap: say what bounds the run */
        snprintf(budget, sizeof budget, "%g minutes of training time (%s clock; the iterations "
                 "each preset ran are in the Training table)", (double)t->minutes,
                 t->clock[0] ? t->clock : "wall");
    else snprintf(budget, sizeof budget, "%ld iterations", t->iterations);
    if (t->noise_max <= 0) snprintf(noise, sizeof noise, "no training noise");
    else snprintf(noise, sizeof noise, "training noise k ~ U[%g, %g]", (double)t->noise_min,
                  (double)t->noise_max);
    fprintf(f, "# Speed against accuracy\n\nGenerated by `lumosaic study --config %s`. Every model "
               "trained with the same budget: %s of %d x %d patches, batch %d x %d "
               "accumulated, lr %g (%s), narrowband synthetic share %g, procedural share %g, "
               "%s, seed %llu.\n\n", cfg->path, budget,
            t->patch_h, t->patch_w, t->batch, t->accum_steps, (double)t->lr, t->schedule,
            (double)t->synth_fraction, (double)lm_train_procedural_share(t), noise,
            (unsigned long long)t->seed);
    if (cfg->preset_train && json_object_size(cfg->preset_train)) {
        fprintf(f, "Per-preset training fields over these (`preset_train`):");
        const char *name;
        json_t *o;
        int first = 1;
        json_object_foreach(cfg->preset_train, name, o) {
            char *text = json_dumps(o, JSON_COMPACT | JSON_SORT_KEYS | JSON_REAL_PRECISION(6));
            fprintf(f, "%s %s `%s`", first ? "" : ";", name, text ? text : "?");
            free(text);
            first = 0;
        }
        fprintf(f, ".\n\n");
    }
    fprintf(f, "To regenerate: `lumosaic study --config %s --output %s` (it resumes: finished "
               "presets are skipped; see `lumosaic study --help`).\n\n", cfg->path, dir);
    md_held_out(f, cfg, s->held_out);
    fprintf(f, "Seconds per frame: as `lumosaic infer` runs it (whole frame in strips for models "
               "with a finite receptive field: linear, lmmse, rt-*; else patch-wise, 66 x 64 "
               "windows, stride 30 x 32) on a "
               "%d x %d coded frame, the fastest of %d runs on %.0f thread(s). GMAC: multiply-adds "
               "of the conv/linear layers of one window times the windows of a frame. Metrics: "
               "means over the held-out scenes, 31 bands, noise in %% of the largest clean value. "
               "Rainbow: mean error of the recovered peak wavelength (%d x %d scene, no noise).\n\n",
            cfg->frame_w, cfg->frame_h, cfg->timing_repeats, num(r0, "threads"), cfg->rainbow,
            cfg->rainbow);
    md_main_table(f, cfg, s->runs);
    md_curve_table(f, cfg, s->runs);
    md_detail_table(f, cfg, s->runs);
    md_failure(f, cfg, s->runs);
    md_narrowband(f, cfg, s->narrowband);
    if (!charts) return;
    fprintf(f, "\n## Charts\n\n");
    static const char *const ch[][2] = {
        {"accuracy_speed", "PSNR against seconds per frame, Pareto fronts"},
        {"accuracy_minutes", "PSNR against minutes of training"},
        {"noise_psnr", "PSNR against noise"}, {"noise_ssim", "SSIM against noise"},
        {"noise_sam", "SAM against noise"}, {"train_loss", "training loss"},
        {"train_val_psnr", "validation PSNR during training"},
        {"rainbow_peaks", "rainbow: recovered against true peak per row"},
        {"motion", "PSNR against motion (px/frame), aligned, unaligned and static"},
        {"narrowband", "rainbow accuracy against the synthetic share of training"},
        {"failure_3db", "level of the 3-dB loss per condition"},
        {"cond_photons", "PSNR against the photon budget"},
        {"cond_saturation", "PSNR against exposure (saturation)"},
        {"cond_led_gain", "PSNR against LED gain mis-calibration"},
        {"cond_dead_pixels", "PSNR against dead pixels"},
        {"cond_motion", "PSNR against motion speed (aligned)"}};
    char path[RPATH + 64];
    for (size_t i = 0; i < sizeof ch / sizeof ch[0]; i++) {
        snprintf(path, sizeof path, "%s/charts/%s.png", dir, ch[i][0]);
        if (access(path, F_OK) == 0)
            fprintf(f, "![%s](charts/%s.png) ([SVG](charts/%s.svg))\n\n", ch[i][1], ch[i][0],
                    ch[i][0]);
    }
}

lm_status lm_study_write(const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                         int charts, lm_err *err)
{
    char tmp[RPATH + 32], dst[RPATH];
    json_t *j = summary_json(cfg, s);
    FILE *f = j ? open_tmp(dir, "results.json", tmp, dst, err) : NULL;
    if (!j) return lm_err_set(err, LM_ERR_NOMEM, "study: out of memory");
    if (f && json_dumpf(j, f, JSON_INDENT(2) | JSON_REAL_PRECISION(9)) == 0) fputc('\n', f);
    json_decref(j);
    if (!f || commit(f, tmp, dst, err)) return err->status;
    if (!(f = open_tmp(dir, "results.csv", tmp, dst, err))) return err->status;
    write_csv(f, cfg, s->runs);
    if (commit(f, tmp, dst, err)) return err->status;
    if (!(f = open_tmp(dir, "results.md", tmp, dst, err))) return err->status;
    write_md(f, cfg, s, dir, charts);
    return commit(f, tmp, dst, err);
}
