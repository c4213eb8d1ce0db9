/* study.c — the study run (study.h): per preset train, evaluate on the held-out scenes, the
 * rainbow test, time a frame and count parameters / multiply-adds; one JSON record per preset
 * in <dir>/runs/<preset>/result.json, which also marks the preset as done (resume).
 * What it is not: the config loader (config.c), the summary files (results.c), charts. */
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <dirent.h>
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/util.h"
#include "data/synth.h"
#include "models/profile.h"
#include "study/study.h"
#include "train/dist.h"

/* The stream of the study seed that procedural held-out scene seeds come from. The dataset
 * draws its samples from streams 0x5EED0000 + split of the same seed, so these seeds are
 * independent of every training sample's. */
#define STUDY_HELD_STREAM 0x57D9000000000001ull

#define PATH_MAX_LEN 1200

typedef struct held {
    int procedural, n;
    char (*name)[256];
    char (*path)[1024];
    uint64_t *seed;
    lm_synth_palette pal;
} held;

static void held_free(held *h)
{
    free(h->name);
    free(h->path);
    free(h->seed);
    memset(h, 0, sizeof *h);
}

static lm_status load_system(const lm_study_cfg *cfg, lm_system *sys, lm_err *err)
{
    lm_status st = cfg->train.system[0] ? lm_system_load(cfg->train.system, sys, err)
                                        : lm_system_default(sys, err);
    if (st) lm_system_free(sys);
    return st;
}

/* The data's test split: the dataset's test list, unless borrowed (fewer than 3 scenes: it
 * then holds training scenes, which are not held out). */
static lm_status list_test_scenes(const lm_study_cfg *cfg, held *h, lm_err *err)
{
    lm_system sys;
    if (load_system(cfg, &sys, err)) return err->status;
    const char *paths[LM_TRAIN_MAX_PATHS];
    for (int i = 0; i < cfg->train.ndata; i++) paths[i] = cfg->train.data[i];
    lm_dataset_scene *ls = NULL;
    int total = 0;
    lm_status st = lm_dataset_list_scenes(paths, cfg->train.ndata, &sys, cfg->train.mat_key,
                                          LM_SPLIT_TEST, &ls, &total, err);
    if (st == LM_ERR_NOMEM) lm_err_set(err, st, "study: out of memory");
    h->name = calloc((size_t)total + 1, sizeof *h->name);
    h->path = calloc((size_t)total + 1, sizeof *h->path);
    if (!st && (!h->name || !h->path)) st = lm_err_set(err, LM_ERR_NOMEM, "study: out of memory");
    for (int i = 0; !st && i < total; i++) {
        snprintf(h->name[h->n], sizeof h->name[0], "%s", ls[i].name);
        snprintf(h->path[h->n++], sizeof h->path[0], "%s", ls[i].path);
    }
    free(ls);
    lm_system_free(&sys);
    return st;
}

static lm_status held_open(const lm_study_cfg *cfg, held *h, json_t **desc, lm_err *err)
{
    memset(h, 0, sizeof *h);
    if (list_test_scenes(cfg, h, err)) return err->status;
    json_t *names = json_array();
    if (h->n > 0) {
        for (int i = 0; i < h->n; i++) json_array_append_new(names, json_string(h->name[i]));
        *desc = json_pack("{s:s, s:o}", "kind", "test_split", "scenes", names);
        return LM_OK;
    }
    h->procedural = 1;
    h->n = cfg->eval_scenes;
    h->seed = calloc((size_t)h->n, sizeof *h->seed);
    if (!h->seed) return json_decref(names), lm_err_set(err, LM_ERR_NOMEM, "study: out of memory");
    if (lm_synth_palette_load(&h->pal, err)) return json_decref(names), err->status;
    lm_rng base, r;
    lm_rng_seed(&base, cfg->train.seed);
    r = lm_rng_split(&base, STUDY_HELD_STREAM);
    char nm[64];
    for (int i = 0; i < h->n; i++) {
        h->seed[i] = lm_rng_u64(&r);
        snprintf(nm, sizeof nm, "procedural_%016llx", (unsigned long long)h->seed[i]);
        json_array_append_new(names, json_string(nm));
    }
    *desc = json_pack("{s:s, s:o, s:[i,i], s:s}", "kind", "procedural", "scenes", names, "size",
                      cfg->eval_h, cfg->eval_w, "note",
                      "the test split of the data is empty: procedural scenes (data/synth.h) "
                      "with seeds from a stream of the study seed that training never draws");
    return LM_OK;
}

static json_t *jnum(double v)
{
    return v == v && v - v == 0 ? json_real(v) : json_null();
}

static json_t *metrics_json(const lm_metrics *m, double noise_pct)
{
    json_t *o = json_object();
    if (noise_pct >= 0) /* k is a float: 0.1f is 10.0000001 % */
        json_object_set_new(o, "noise_percent", json_real(nearbyint(noise_pct * 1e4) / 1e4));
    json_object_set_new(o, "psnr", jnum(m->psnr));
    json_object_set_new(o, "ssim", jnum(m->ssim));
    json_object_set_new(o, "mae", jnum(m->mae));
    json_object_set_new(o, "sam", jnum(m->sam));
    return o;
}

/* Mean metrics over the held-out scenes at every noise level. */
static lm_status eval_held(lm_ctx *c, const lm_infer_model *im, const lm_study_cfg *cfg,
                           const held *h, json_t *levels, lm_study_cond_acc *ca, lm_err *err)
{
    int ncs = cfg->cond_scenes > 0 && cfg->cond_scenes < h->n ? cfg->cond_scenes : h->n;
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_rng base;
    lm_rng_seed(&base, cfg->train.seed);
    lm_metrics_acc acc[LM_EVAL_MAX_NOISE];
    memset(acc, 0, sizeof acc);
    lm_metrics m[LM_EVAL_MAX_NOISE];
    lm_cube_read_opts ro; /* onto 31 bands, the training data's .mat key */
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    ro.mat_key = cfg->train.mat_key;
    for (int i = 0; i < h->n; i++) {
        lm_cube cube;
        lm_status st = h->procedural
            ? lm_synth_scene(h->seed[i], cfg->eval_h, cfg->eval_w, &h->pal, &cube, err)
            : lm_cube_read_with(h->path[i], &ro, &cube, err);
        if (st) return st;
        st = lm_eval_prepare(&cube, im->model->mosaic.ty, im->model->mosaic.tx, err);
        lm_rng rs = lm_rng_split(&base, h->procedural ? h->seed[i] : lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, h->name[i]));
        if (!st) st = lm_eval_scene(c, im, &cube, cfg->noise, cfg->nnoise, &to, &rs, m, err);
        if (!st && ca && cfg->ncond > 0 && i < ncs)
            st = lm_study_cond_add(c, im, cfg, &cube, &rs, ca, err);
        lm_cube_free(&cube);
        if (st) return st;
        for (int k = 0; k < cfg->nnoise; k++) lm_metrics_acc_add(&acc[k], &m[k]);
    }
    for (int k = 0; k < cfg->nnoise; k++) {
        lm_metrics mean = lm_metrics_acc_mean(&acc[k]);
        json_array_append_new(levels, metrics_json(&mean, 100.0 * cfg->noise[k]));
    }
    return LM_OK;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Seconds of lm_eval_reconstruct on a frame_h x frame_w input frame (uniform random values: the cost
 * does not depend on the content), each of timing_repeats runs; rec gets min, median, all. */
static lm_status time_frame(lm_ctx *c, const lm_infer_model *im, const lm_study_cfg *cfg,
                           json_t *rec, lm_err *err)
{
    size_t n = (size_t)im->model->in_channels * cfg->frame_h * (size_t)cfg->frame_w;
    float *frame = malloc(n * sizeof *frame);
    double t[100];
    if (!frame) return lm_err_set(err, LM_ERR_NOMEM, "study: out of memory (frame)");
    lm_rng r;
    lm_rng_seed(&r, 1);
    lm_rng_fill_uniform(&r, frame, (long)n, 0.0f, 1.0f);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_status st = LM_OK;
    json_t *runs = json_array();
    for (int k = 0; !st && k < cfg->timing_repeats; k++) {
        lm_cube cube;
        double t0 = omp_get_wtime();
        /* as `lumosaic infer` runs it: whole frames for a finite receptive field */
        st = lm_eval_reconstruct(c, im, frame, cfg->frame_h, cfg->frame_w, &to,
                                 im->model->conv_rows >= 0, &cube, err);
        t[k] = omp_get_wtime() - t0;
        if (!st) lm_cube_free(&cube);
        json_array_append_new(runs, json_real(t[k]));
    }
    free(frame);
    if (st) return json_decref(runs), st;
    qsort(t, (size_t)cfg->timing_repeats, sizeof t[0], cmp_double);
    int R = cfg->timing_repeats;
    json_object_set_new(rec, "seconds_per_frame", json_real(t[0]));
    json_object_set_new(rec, "seconds_per_frame_median",
                        json_real(R % 2 ? t[R / 2] : 0.5 * (t[R / 2 - 1] + t[R / 2])));
    json_object_set_new(rec, "timing_runs", runs);
    return LM_OK;
}

/* Parameters, and multiply-adds of one inference window times the windows of a frame. */
static lm_status count_costs(lm_model *m, const lm_study_cfg *cfg, json_t *rec, lm_err *err)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    if (lm_tile_check(&to, cfg->frame_h, cfg->frame_w, m->mosaic.ty, m->mosaic.tx, err))
        return err->status;
    if (m->in_channels != 1) { /* lm_model_profile runs a 1-channel input: parameters only */
        json_object_set_new(rec, "params", json_integer(lm_params_count(&m->params, 0)));
        json_object_set_new(rec, "trainable_params", json_integer(lm_params_count(&m->params, 1)));
        json_object_set_new(rec, "macs_per_frame", json_null());
        json_object_set_new(rec, "frame", json_pack("[i,i]", cfg->frame_h, cfg->frame_w));
        return LM_OK;
    }
    lm_profile p;
    int whole = lm_model_has(m, LM_CAP_WHOLE_FRAME); /* as lm_eval_reconstruct runs it */
    lm_status st = whole ? lm_model_profile(m, 1, cfg->frame_h, cfg->frame_w, &p, err)
                         : lm_model_profile(m, 1, to.win_h, to.win_w, &p, err);
    if (!st) {
        long win = whole ? 1
                         : (long)lm_tile_positions(cfg->frame_h, to.win_h, to.stride_y, NULL, 0) *
                               lm_tile_positions(cfg->frame_w, to.win_w, to.stride_x, NULL, 0);
        json_object_set_new(rec, "params", json_integer(p.model_params));
        json_object_set_new(rec, "trainable_params", json_integer(p.trainable_params));
        json_int_t macs = (json_int_t)llround(p.total_macs); /* a count: exact in a double */
        json_object_set_new(rec, "macs_per_window", json_integer(macs));
        json_object_set_new(rec, "windows_per_frame", json_integer(win));
        json_object_set_new(rec, "macs_per_frame", json_integer(macs * win));
        json_object_set_new(rec, "frame", json_pack("[i,i]", cfg->frame_h, cfg->frame_w));
    }
    lm_profile_free(&p);
    return st;
}

static json_t *rainbow_json(const lm_eval_rainbow *rb)
{
    json_t *o = metrics_json(&rb->m, -1);
    json_object_set_new(o, "size", json_integer(rb->size));
    json_object_set_new(o, "peak_error_mean_nm", jnum(rb->mean_err_nm));
    json_object_set_new(o, "peak_error_max_nm", jnum(rb->max_err_nm));
    json_object_set_new(o, "worst_row", json_integer(rb->worst_row));
    return o;
}

/* Evaluation, rainbow, and (unless light: the narrowband sweep's runs) conditions, timing and
 * costs of the trained run into rec. */
/* The study's "train": {"precision": ...} holds for its evaluation and timing too. */
static int study_precision(const lm_study_cfg *cfg)
{
    return strcmp(cfg->train.precision, "bf16") ? LM_PRECISION_FP32 : LM_PRECISION_BF16;
}

static lm_status measure(const lm_study_cfg *cfg, const char *rundir, const held *h, int threads,
                         int light, json_t *rec, FILE *log, lm_err *err)
{
    lm_infer_model im;
    if (lm_infer_model_load(rundir, NULL, &im, err)) return err->status;
    lm_ctx c;
    if (lm_ctx_init(&c, threads) != 0) {
        lm_infer_model_free(&im);
        return lm_err_set(err, LM_ERR_NOMEM, "study: out of memory (compute context)");
    }
    c.precision = study_precision(cfg);
    json_t *levels = json_array();
    json_object_set_new(rec, "threads", json_integer(lm_nthreads(&c)));
    json_object_set_new(rec, "precision", json_string(cfg->train.precision));
    double t0 = omp_get_wtime();
    lm_study_cond_acc *ca = cfg->ncond > 0 && !light ? malloc(sizeof *ca) : NULL;
    if (ca) lm_study_cond_init(ca);
    lm_status st = cfg->ncond > 0 && !light && !ca
                 ? lm_err_set(err, LM_ERR_NOMEM, "study: out of memory") : LM_OK;
    if (!st) st = eval_held(&c, &im, cfg, h, levels, ca, err);
    if (!st && ca) json_object_set_new(rec, "conditions", lm_study_cond_json(cfg, &im, ca));
    free(ca);
    json_object_set_new(rec, "eval", json_pack("{s:s, s:i, s:o}", "kind",
                        h->procedural ? "procedural" : "test_split", "scenes", h->n,
                        "levels", levels));
    if (!st && cfg->rainbow > 0) {
        lm_tile_opts to;
        lm_tile_default_opts(&to);
        lm_eval_rainbow rb;
        st = lm_eval_rainbow_run(&c, &im, cfg->rainbow, &to, &rb, err);
        json_t *rj = st ? NULL : rainbow_json(&rb);
        if (!st) st = lm_study_rainbow_rows(&c, &im, cfg->rainbow, rj, err);
        if (!st) json_object_set_new(rec, "rainbow", rj);
        else json_decref(rj);
    }
    if (!st) fprintf(log, "study: %s evaluated (%.1f s)\n", im.model->preset, omp_get_wtime() - t0);
    if (!st && !light) st = time_frame(&c, &im, cfg, rec, err);
    if (!st && !light) st = count_costs(im.model, cfg, rec, err);
    lm_ctx_free(&c);
    lm_infer_model_free(&im);
    return st;
}

static lm_status write_json_atomic(json_t *j, const char *path, lm_err *err);

/* ---- accuracy against training time (snapshots, study.h) ------------------------------- */
/* Held-out levels of the model in dir (a run or snapshot folder), cached in dir/eval.json. */
static lm_status dir_levels(const lm_study_cfg *cfg, const char *dir, const held *h, int threads,
                            json_t **levels, lm_err *err)
{
    char path[PATH_MAX_LEN + 16];
    snprintf(path, sizeof path, "%s/eval.json", dir);
    json_error_t je;
    json_t *cached = json_load_file(path, 0, &je);
    *levels = json_incref(json_object_get(cached, "levels"));
    json_decref(cached);
    if (json_is_array(*levels)) return LM_OK;
    json_decref(*levels);
    lm_infer_model im;
    if (lm_infer_model_load(dir, NULL, &im, err)) return err->status;
    lm_ctx c;
    lm_status st = lm_ctx_init(&c, threads) ? lm_err_set(err, LM_ERR_NOMEM, "study: no memory")
                                            : LM_OK;
    c.precision = study_precision(cfg);
    *levels = json_array();
    if (!st) st = eval_held(&c, &im, cfg, h, *levels, NULL, err);
    json_t *doc = json_pack("{s:O}", "levels", *levels);
    if (!st) st = write_json_atomic(doc, path, err);
    json_decref(doc);
    if (!st) lm_ctx_free(&c);
    lm_infer_model_free(&im);
    if (st) json_decref(*levels), *levels = NULL;
    return st;
}

static int cmp_minutes(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Training time of a run folder in minutes: its checkpoint's, or a closed-form fit's. */
static double run_minutes(const char *rundir)
{
    char p[PATH_MAX_LEN + 16];
    snprintf(p, sizeof p, "%s/fit.json", rundir);
    json_error_t je;
    json_t *f = json_load_file(p, 0, &je);
    double s = f ? json_number_value(json_object_get(f, "seconds"))
                 : lm_train_checkpoint_seconds(rundir);
    json_decref(f);
    return s / 60.0;
}

/* rec["curve"] = [{"minutes", "iteration", "levels"}] from the run's snapshots (minutes of
 * training time), plus the final model; a closed-form fit is one point at its fit time. */
static lm_status eval_curve(const lm_study_cfg *cfg, const char *rundir, const held *h,
                            int threads, json_t *rec, lm_err *err)
{
    char sdir[PATH_MAX_LEN + 16], d[PATH_MAX_LEN + 64];
    snprintf(sdir, sizeof sdir, "%s/snapshots", rundir);
    double mins[64];
    int n = 0;
    DIR *dp = opendir(sdir);
    for (struct dirent *e; dp && (e = readdir(dp)) && n < 64;) {
        char *end;
        double v = strtod(e->d_name, &end);
        if (end != e->d_name && !strcmp(end, "min")) mins[n++] = v;
    }
    if (dp) closedir(dp);
    qsort(mins, (size_t)n, sizeof mins[0], cmp_minutes);
    json_t *curve = json_array();
    lm_status st = LM_OK;
    for (int i = 0; i <= n && !st; i++) {
        if (i < n) snprintf(d, sizeof d, "%s/%gmin", sdir, mins[i]);
        else snprintf(d, sizeof d, "%s", rundir);
        double m = i < n ? mins[i] : run_minutes(rundir); /* final: its training time */
        /* the last snapshot is final: a run stopped at its budget (or the drop check) writes
         * its checkpoint a few seconds of training after the snapshot of the same weights */
        if (i == n && n > 0 && m <= mins[n - 1] + 0.1) break;
        json_t *lv = NULL;
        if (!(st = dir_levels(cfg, d, h, threads, &lv, err)))
            json_array_append_new(curve, json_pack("{s:f, s:o}", "minutes", m, "levels", lv));
    }
    if (!st) json_object_set(rec, "curve", curve);
    json_decref(curve);
    return st;
}

/* One run: a preset and its name (the folder under runs/), and for the narrowband sweep the
 * training synth_fraction (synth < 0: the config's) and a light measurement. */
typedef struct run_spec {
    const char *preset, *name;
    float synth;
    const char *base;       /* residual: the base's run name (runs/<base>), else NULL */
} run_spec;

/* The preset's own training fields (preset_train) over the study's. */
static lm_status apply_preset_train(const lm_study_cfg *cfg, const char *name, lm_train_cfg *tc,
                                    lm_err *err)
{
    json_t *o = cfg->preset_train ? json_object_get(cfg->preset_train, name) : NULL;
    if (!o) return LM_OK;
    json_t *t = json_deep_copy(o);
    json_object_set_new(t, "version", json_integer(LM_TRAIN_CFG_VERSION));
    char *text = json_dumps(t, 0);
    json_decref(t);
    if (!text) return lm_err_set(err, LM_ERR_NOMEM, "study: out of memory");
    lm_status st = lm_train_cfg_parse(tc, text, "preset_train", err);
    free(text);
    return st;
}

/* A time-budgeted run whose checkpoint reached the end of its (resolved) schedule. */
static int schedule_done(const char *rundir)
{
    char p[PATH_MAX_LEN + 32];
    snprintf(p, sizeof p, "%s/config.json", rundir);
    json_error_t je;
    json_t *c = json_load_file(p, 0, &je);
    long total = (long)json_integer_value(json_object_get(c, "iterations"));
    json_decref(c);
    snprintf(p, sizeof p, "%s/model.safetensors", rundir);
    lm_err e = {0};
    char *it = lm_safetensors_meta(p, "iteration", &e);
    long done = it ? atol(it) : -1;
    free(it);
    return total > 0 && done >= total;
}

int lm_study_log_fields(char *line, char *fld[7])
{
    int k = 0;
    for (char *p = line; k < 7 && p; k++) {
        fld[k] = p;
        p = strchr(p, ',');
        if (p) *p++ = 0;
    }
    for (int i = k; i < 7; i++) fld[i] = NULL;
    return k;
}

/* The "train" record of a run trained before (by a --jobs worker, or an earlier invocation),
 * from its folder: iterations, first and final loss and the last validation metrics from
 * log.csv, the training seconds from the checkpoint; closed form when fit.json is there. NULL
 * when the log cannot be read (the table then shows n/a). */
static json_t *train_record_from_run(const char *rundir)
{
    char path[PATH_MAX_LEN + 32];
    snprintf(path, sizeof path, "%s/log.csv", rundir);
    FILE *f = fopen(path, "r");
    if (!f) return NULL;
    char line[512];
    long it = -1;
    double first = NAN, last = NAN;
    lm_metrics val = {NAN, NAN, NAN, NAN, 0};
    int have_val = 0;
    if (!fgets(line, sizeof line, f)) line[0] = 0; /* header */
    while (fgets(line, sizeof line, f)) {
        char *fld[7];
        if (lm_study_log_fields(line, fld) < 7) continue;
        char *end;
        long i = strtol(fld[0], &end, 10);
        if (end == fld[0]) continue;
        it = i;
        double l = strtod(fld[1], &end);
        if (end != fld[1] && isfinite(l)) {
            if (first != first) first = l;
            last = l;
        }
        double v = strtod(fld[3], &end);
        if (end != fld[3] && isfinite(v)) {
            val.psnr = v, have_val = 1;
            val.ssim = strtod(fld[4], NULL), val.mae = strtod(fld[5], NULL);
            val.sam = strtod(fld[6], NULL);
        }
    }
    fclose(f);
    if (it < 0) return NULL;
    snprintf(path, sizeof path, "%s/fit.json", rundir);
    int closed = access(path, F_OK) == 0;
    json_t *t = json_pack("{s:I, s:f, s:b, s:o, s:o, s:b, s:b}", "iterations", (json_int_t)it,
                          "seconds", closed ? 0.0 : lm_train_checkpoint_seconds(rundir),
                          "resumed", 1, "first_loss", jnum(first), "final_loss", jnum(last),
                          "closed_form", closed, "from_log", 1);
    json_object_set_new(t, "val", have_val ? metrics_json(&val, -1) : json_null());
    return t;
}

/* Train (or continue) one run; stop_s > 0 stops it at that much training time (the early-drop
 * phase). A closed-form fit, or a run whose checkpoint is past stop_s, is not trained again. */
static lm_status train_preset(const lm_study_cfg *cfg, const char *dir, const run_spec *rs,
                              const char *rundir, const lm_study_opts *o, double stop_s,
                              json_t *rec, lm_err *err)
{
    lm_train_cfg tc = cfg->train;
    const char *preset = rs->name;
    if (apply_preset_train(cfg, rs->name, &tc, err)) return err->status;
    if (cfg->drop_minutes > 0 && tc.minutes > 0) { /* the drop check scores this snapshot */
        size_t l = strlen(tc.snapshots);
        snprintf(tc.snapshots + l, sizeof tc.snapshots - l, "%s%g", l ? "," : "",
                 (double)cfg->drop_minutes);
    }
    snprintf(tc.model, sizeof tc.model, "%s", rs->preset);
    if (rs->synth >= 0.0f) /* the narrowband sweep: that share, no procedural scenes */
        tc.synth_fraction = rs->synth, tc.procedural_fraction = 0.0f;
    if (snprintf(tc.output, sizeof tc.output, "%s", rundir) >= (int)sizeof tc.output ||
        (rs->base && snprintf(tc.base, sizeof tc.base, "%s/runs/%s", dir, rs->base) >=
                         (int)sizeof tc.base))
        return lm_err_set(err, LM_ERR_ARG, "%s: path too long", rundir);
    lm_train_cfg_apply_recipe(&tc); /* what the config does not set: the preset's recipe */
    if (rs->synth >= 0.0f) tc.synth_fraction = rs->synth;
    tc.threads = o->threads;
    char ck[PATH_MAX_LEN + 32];
    snprintf(ck, sizeof ck, "%s/model.safetensors", rundir);
    int resume = access(ck, F_OK) == 0;
    char fitp[PATH_MAX_LEN + 32];
    snprintf(fitp, sizeof fitp, "%s/fit.json", rundir);
    double done_s = resume ? lm_train_checkpoint_seconds(rundir) : 0.0;
    if (resume && (access(fitp, F_OK) == 0 || (stop_s > 0 && done_s >= stop_s - 1.0) ||
                   (tc.minutes > 0 && (done_s >= tc.minutes * 60.0 - 1.0 ||
                                       schedule_done(rundir))))) {
        fprintf(o->log, "study: %s: trained before (%.1f min), not trained again\n", preset,
                run_minutes(rundir));
        json_t *t = train_record_from_run(rundir);
        if (t) json_object_set_new(rec, "train", t);
        return LM_OK;
    }
    lm_train_opts to = {.resume = resume ? rundir : NULL, .progress = o->progress,
                        .progress_out = o->log, .stop_seconds = stop_s,
                        .interrupt = o->interrupt, .hold = o->hold};
    lm_train_result res;
    if (tc.minutes > 0)
        fprintf(o->log, "study: %s: %s %g minutes of training%s into %s\n", preset,
                resume ? "continuing to" : "training for", stop_s > 0 ? stop_s / 60.0 : tc.minutes,
                stop_s > 0 ? " (early-drop check)" : "", rundir);
    else
        fprintf(o->log, "study: %s: %s %ld iterations into %s\n", preset,
                resume ? "continuing to" : "training for", tc.iterations, rundir);
    if (lm_train_session(&tc, &to, &res, err)) return err->status;
    if (res.interrupted)
        return lm_err_set(err, LM_ERR_INTERRUPTED, "%s stopped at iteration %ld, checkpoint "
                          "written to %s", preset, res.iterations_done, rundir);
    json_t *t = json_pack("{s:I, s:f, s:b, s:o, s:o, s:b}", "iterations",
                          (json_int_t)res.iterations_done, "seconds", res.seconds,
                          "resumed", resume, "first_loss", jnum(res.first_loss),
                          "final_loss", jnum(res.last_loss), "closed_form", res.closed_form);
    json_object_set_new(t, "val", res.validated ? metrics_json(&res.val, -1) : json_null());
    json_object_set_new(rec, "train", t);
    return LM_OK;
}

static lm_status write_json_atomic(json_t *j, const char *path, lm_err *err)
{
    char tmp[PATH_MAX_LEN + 32];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid());
    if (json_dump_file(j, tmp, JSON_INDENT(2) | JSON_REAL_PRECISION(9)) != 0 ||
        rename(tmp, path) != 0) {
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write", path);
    }
    return LM_OK;
}

/* The record of a finished run (result.json), or NULL. */
static lm_status load_done(const char *rundir, const run_spec *rs, json_t **out, lm_err *err)
{
    char respath[PATH_MAX_LEN + 16];
    snprintf(respath, sizeof respath, "%s/result.json", rundir);
    *out = NULL;
    if (access(respath, F_OK) != 0) return LM_OK;
    json_error_t je;
    *out = json_load_file(respath, 0, &je);
    if (!json_is_object(*out) || !json_is_string(json_object_get(*out, "preset")))
        return json_decref(*out), *out = NULL,
               lm_err_set(err, LM_ERR_FORMAT, "%s: not a study record (delete it to run %s "
                          "again)", respath, rs->name);
    return LM_OK;
}

/* Train (unless dropped), measure and record one run. drop_psnr: its clean PSNR at the early-
 * drop check (NaN: no check). */
static lm_status run_preset(const lm_study_cfg *cfg, const char *dir, const run_spec *rs,
                            const held *h, const lm_study_opts *o, int dropped, double drop_psnr,
                            json_t **out, lm_err *err)
{
    const char *preset = rs->name;
    char rundir[PATH_MAX_LEN], respath[PATH_MAX_LEN + 16];
    snprintf(rundir, sizeof rundir, "%s/runs/%s", dir, preset);
    snprintf(respath, sizeof respath, "%s/result.json", rundir);
    if (load_done(rundir, rs, out, err) || *out) {
        if (*out) fprintf(o->log, "study: %s: done before (%s), skipped\n", preset, respath);
        return err->status;
    }
    char rel[128];
    snprintf(rel, sizeof rel, "runs/%s", preset);
    /* "preset": what tables show (the residual's full name; a sweep run: its preset) */
    json_t *rec = json_pack("{s:s, s:s, s:s}", "preset", rs->base ? rs->name : rs->preset,
                            "model", rs->preset, "run", rel);
    if (rs->base) json_object_set_new(rec, "base", json_string(rs->base));
    if (rs->synth >= 0.0f)
        json_object_set_new(rec, "synth_fraction", json_real(nearbyint(rs->synth * 1e4) / 1e4));
    if (dropped)
        json_object_set_new(rec, "dropped", json_pack("{s:f, s:f}", "after_minutes",
                            (double)cfg->drop_minutes, "behind_db", (double)cfg->drop_db));
    if (drop_psnr == drop_psnr)
        json_object_set_new(rec, "drop_check", json_pack("{s:f, s:f}", "minutes",
                            (double)cfg->drop_minutes, "psnr", drop_psnr));
    lm_status st = dropped ? LM_OK : train_preset(cfg, dir, rs, rundir, o, 0.0, rec, err);
    json_object_set_new(rec, "train_minutes", json_real(run_minutes(rundir)));
    if (!st) st = measure(cfg, rundir, h, o->threads, rs->synth >= 0.0f, rec, o->log, err);
    if (!st && cfg->train.minutes > 0) st = eval_curve(cfg, rundir, h, o->threads, rec, err);
    if (!st) st = write_json_atomic(rec, respath, err);
    if (st) json_decref(rec);
    else *out = rec;
    return st;
}

/* The i-th preset of the config: "net" or "net+base" (a residual on runs/<base>). */
static run_spec preset_spec(const lm_study_cfg *cfg, int i, char net[64])
{
    const char *p = cfg->presets[i], *plus = strchr(p, '+');
    snprintf(net, 64, "%.*s", plus ? (int)(plus - p) : 63, p);
    return (run_spec){net, p, -1.0f, plus ? plus + 1 : NULL};
}

lm_status lm_study_train_one(const lm_study_cfg *cfg, const char *dir, const char *name,
                             double stop_s, const lm_study_opts *o, lm_err *err)
{
    int i = 0;
    while (i < cfg->npresets && strcmp(cfg->presets[i], name)) i++;
    if (i == cfg->npresets)
        return lm_err_set(err, LM_ERR_ARG, "study --worker: %s is not a preset of %s", name,
                          cfg->path);
    char net[64], rundir[PATH_MAX_LEN];
    run_spec rs = preset_spec(cfg, i, net);
    snprintf(rundir, sizeof rundir, "%s/runs/%s", dir, name);
    json_t *rec = json_object();
    lm_status st = train_preset(cfg, dir, &rs, rundir, o, stop_s, rec, err);
    json_decref(rec);
    return st;
}

/* --jobs: every preset not dropped and not done is trained (to stop_s seconds of training
 * time when stop_s > 0) before the serial phases score it. The bases of residual presets
 * (closed-form fits in practice) are trained first, here; the rest side by side in workers. */
static lm_status train_side_by_side(const lm_study_cfg *cfg, const char *dir, const run_spec *rs,
                                    int n, const int *dropped, const lm_study_opts *o,
                                    double stop_s, lm_err *err)
{
    const char *names[LM_STUDY_MAX_PRESETS];
    int k = 0;
    lm_status st = LM_OK;
    for (int i = 0; i < n && !st; i++) {
        char rundir[PATH_MAX_LEN];
        snprintf(rundir, sizeof rundir, "%s/runs/%s", dir, rs[i].name);
        json_t *done = NULL;
        if (dropped[i] || (st = load_done(rundir, &rs[i], &done, err)) || done) {
            json_decref(done);
            continue;
        }
        int base = 0;
        for (int j = 0; j < n; j++) base |= rs[j].base && !strcmp(rs[j].base, rs[i].name);
        if (base && lm_dist_rank() == 0) st = lm_study_train_one(cfg, dir, rs[i].name, stop_s, o, err);
        else if (!base) names[k++] = rs[i].name;
    }
    if (lm_dist_size() > 1) { /* the bases (rank 0's) are there before any rank goes on */
        long bad = st != LM_OK;
        lm_dist_max_long(&bad, 1);
        if (!st && bad) st = lm_err_set(err, LM_ERR_NUMERIC, "study: rank 0 failed on a base");
    }
    if (st || !k) return st;
    if (lm_dist_size() > 1) { /* MPI ranks: rank r trains names r, r + N, ...; then all wait */
        for (int i = lm_dist_rank(); i < k && !st; i += lm_dist_size())
            st = lm_study_train_one(cfg, dir, names[i], stop_s, o, err);
        long bad = st != LM_OK;
        lm_dist_max_long(&bad, 1); /* one rank's failure fails the study on every rank */
        if (!st && bad)
            st = lm_err_set(err, LM_ERR_NUMERIC, "study: another rank's training failed (its "
                            "message is above)");
        return st;
    }
    return lm_study_spawn(cfg, dir, names, k, stop_s, o, err);
}

/* Early-drop phase: every unfinished preset trained to drop_minutes, scored there (clean PSNR
 * of the snapshot, or of the fit); dropped[i] = more than drop_db behind the best. */
static lm_status drop_phase(const lm_study_cfg *cfg, const char *dir, const run_spec *rs, int n,
                            const held *h, const lm_study_opts *o, int *dropped, double *psnr,
                            lm_err *err)
{
    double best = -INFINITY, stop_s = cfg->drop_minutes * 60.0;
    lm_status st = LM_OK;
    for (int i = 0; i < n && !st; i++) {
        char rundir[PATH_MAX_LEN], snap[PATH_MAX_LEN + 64], fitp[PATH_MAX_LEN + 16];
        snprintf(rundir, sizeof rundir, "%s/runs/%s", dir, rs[i].name);
        json_t *done = NULL, *rec = json_object(), *lv = NULL;
        psnr[i] = NAN;
        st = load_done(rundir, &rs[i], &done, err);
        json_t *drop = done ? json_object_get(done, "dropped") : NULL;
        if (!st && done) psnr[i] = json_number_value(json_object_get(
                              json_object_get(done, "drop_check"), "psnr"));
        if (!st && done) dropped[i] = drop != NULL;
        if (!st && !done) st = train_preset(cfg, dir, &rs[i], rundir, o, stop_s, rec, err);
        snprintf(fitp, sizeof fitp, "%s/fit.json", rundir);
        snprintf(snap, sizeof snap, "%s/snapshots/%gmin", rundir, (double)cfg->drop_minutes);
        /* the fit; the snapshot; or a schedule that ended before the check: the final model */
        int fit = access(fitp, F_OK) == 0, has_snap = access(snap, F_OK) == 0;
        if (!st && !done && (fit || has_snap || schedule_done(rundir)))
            st = dir_levels(cfg, has_snap ? snap : rundir, h, o->threads, &lv, err);
        if (lv) psnr[i] = json_number_value(json_object_get(json_array_get(lv, 0), "psnr"));
        json_decref(lv);
        json_decref(rec);
        json_decref(done);
        if (isfinite(psnr[i]) && psnr[i] > best) best = psnr[i];
    }
    for (int i = 0; i < n && !st; i++) {
        if (isfinite(psnr[i])) dropped[i] = psnr[i] < best - cfg->drop_db;
        fprintf(o->log, "study: %s at %g min: %.2f dB (best %.2f)%s\n", rs[i].name,
                (double)cfg->drop_minutes, psnr[i], best, dropped[i] ? ": dropped" : "");
    }
    return st;
}

/* LM_ERR_INTERRUPTED once a signal has come (between the study's steps). */
static lm_status check_interrupt(const lm_study_opts *o, lm_err *err)
{
    if (!o->interrupt || !atomic_load(o->interrupt)) return LM_OK;
    return lm_err_set(err, LM_ERR_INTERRUPTED, "stopped between runs; the finished runs are kept");
}

lm_status lm_study_run(const lm_study_cfg *cfg, const char *dir, const lm_study_opts *opts,
                       lm_study *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    lm_study_opts o = *opts;
    if (!o.log) o.log = stderr;
    char runs[PATH_MAX_LEN];
    snprintf(runs, sizeof runs, "%s/runs", dir);
    held h;
    lm_status st = held_open(cfg, &h, &out->held_out, err); /* checks the data first */
    if (!st && lm_make_dirs(runs, NULL, 0, NULL, 0))
        st = lm_err_set(err, LM_ERR_WRITE, "%s: cannot create (%s)", runs, strerror(errno));
    if (!st && h.procedural)
        fprintf(o.log, "study: the test split of the data is empty; evaluating on %d procedural "
                "scenes (%d x %d) with seeds disjoint from training's\n", h.n, cfg->eval_h,
                cfg->eval_w);
    else if (!st)
        fprintf(o.log, "study: evaluating on the %d scene(s) of the test split\n", h.n);
    run_spec rs[LM_STUDY_MAX_PRESETS];
    char net[LM_STUDY_MAX_PRESETS][64];
    int dropped[LM_STUDY_MAX_PRESETS] = {0};
    double drop_psnr[LM_STUDY_MAX_PRESETS];
    for (int i = 0; i < LM_STUDY_MAX_PRESETS; i++) drop_psnr[i] = NAN;
    for (int i = 0; i < cfg->npresets; i++) rs[i] = preset_spec(cfg, i, net[i]);
    int drop = cfg->drop_minutes > 0 && cfg->train.minutes > cfg->drop_minutes;
    int ranks = lm_dist_size(), side = o.jobs > 1 || ranks > 1;
    if (!st && drop && side)
        st = train_side_by_side(cfg, dir, rs, cfg->npresets, dropped, &o,
                                cfg->drop_minutes * 60.0, err);
    if (!st && drop && lm_dist_rank() == 0) /* scored once, on rank 0 */
        st = drop_phase(cfg, dir, rs, cfg->npresets, &h, &o, dropped, drop_psnr, err);
    if (drop && ranks > 1) { /* every rank learns the drops (and whether rank 0 failed) */
        long v[LM_STUDY_MAX_PRESETS + 1];
        for (int i = 0; i < cfg->npresets; i++) v[i] = dropped[i];
        v[cfg->npresets] = st != LM_OK;
        lm_dist_bcast_long(v, (size_t)cfg->npresets + 1);
        for (int i = 0; i < cfg->npresets; i++) dropped[i] = (int)v[i];
        if (!st && v[cfg->npresets])
            st = lm_err_set(err, LM_ERR_NUMERIC, "study: rank 0 failed in the drop check");
    }
    if (!st && side)
        st = train_side_by_side(cfg, dir, rs, cfg->npresets, dropped, &o, 0.0, err);
    if (!st && lm_dist_rank() > 0) { /* the serial phases (scores, timing) are rank 0's */
        held_free(&h);
        out->runs = json_array();
        return LM_OK;
    }
    out->runs = json_array();
    for (int i = 0; !st && i < cfg->npresets; i++) {
        json_t *rec = NULL;
        if ((st = check_interrupt(&o, err))) break;
        st = run_preset(cfg, dir, &rs[i], &h, &o, dropped[i], drop_psnr[i], &rec, err);
        if (!st) json_array_append_new(out->runs, rec);
    }
    if (cfg->nnb > 0) out->narrowband = json_array();
    for (int i = 0; !st && i < cfg->nnb; i++) { /* the narrowband sweep: light records */
        json_t *rec = NULL;
        char name[96];
        snprintf(name, sizeof name, "%s@synth%03d", cfg->nb_preset,
                 (int)lrintf(100.0f * cfg->nb_fraction[i]));
        run_spec nb = {cfg->nb_preset, name, cfg->nb_fraction[i], NULL};
        if ((st = check_interrupt(&o, err))) break;
        st = run_preset(cfg, dir, &nb, &h, &o, 0, NAN, &rec, err);
        if (!st) json_array_append_new(out->narrowband, rec);
    }
    held_free(&h);
    if (st) lm_study_free(out);
    return st;
}

void lm_study_free(lm_study *s)
{
    json_decref(s->held_out);
    json_decref(s->runs);
    json_decref(s->narrowband);
    s->held_out = s->runs = s->narrowband = NULL;
}
