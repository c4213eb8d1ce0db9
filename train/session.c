/* session.c — a training run from its configuration: system description, network front,
 * model, dataset, then the loop (train.c). Also the dataset adapter of lm_train_source.
 * What it is not: option parsing (cli/cmd_train.c) or the loop itself. */
#include "train/train.h"
#include "data/rgbcam.h"
#include "data/dataset.h"
#include "data/spectra.h"
#include "train/dist.h"
#include "train/fit_lmmse.h"
#include "data/mosaic.h"
#include "data/util.h"
#include <errno.h>
#include <math.h>
#include <jansson.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static lm_status ds_batch(void *u, long index, int B, float *raw, float *target, lm_err *err)
{
    return lm_dataset_batch(u, index, B, raw, target, err);
}
static int ds_count(void *u) { return lm_dataset_eval_count(u, LM_SPLIT_VAL); }
static lm_status ds_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    return lm_dataset_eval_sample(u, LM_SPLIT_VAL, i, raw, target, err);
}

lm_train_source lm_train_source_dataset(lm_dataset *d)
{
    return (lm_train_source){d, ds_batch, ds_count, ds_eval, NULL};
}

/* pad_y, pad_x: context around each patch (the QDO camera's PSF radius), 0 otherwise. */
static lm_dataset *open_data(const lm_train_cfg *cfg, const lm_system *sys, int clean, int dp,
                             int pad_y, int pad_x, lm_err *err)
{
    const char *paths[LM_TRAIN_MAX_PATHS];
    for (int i = 0; i < cfg->ndata; i++) paths[i] = cfg->data[i];
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths;
    dc.npaths = cfg->ndata;
    dc.sys = sys;
    dc.patch_h = cfg->patch_h + 2 * pad_y;
    dc.patch_w = cfg->patch_w + 2 * pad_x;
    dc.synth_fraction = cfg->synth_fraction;
    dc.procedural_fraction = lm_train_procedural_share(cfg);
    dc.noise_min = cfg->noise_min;
    dc.noise_max = cfg->noise_max;
    dc.seed = cfg->seed;
    dc.workers = cfg->workers;
    dc.val_patches = cfg->val_patches;
    dc.val_noise = cfg->val_noise;
    dc.sensor_clip = cfg->sensor_clip;
    dc.sensor_bits = cfg->sensor_bits;
    dc.batch_stride = dp ? lm_dist_size() : 1; /* rank r takes every N-th batch (train.c) */
    dc.mat_key = cfg->mat_key;
    dc.buckets = cfg->buckets;
    dc.photons = cfg->photons, dc.read_noise = cfg->read_noise;
    dc.photons_min = cfg->photons_min;
    dc.illum_jitter = cfg->illum_jitter, dc.gain_jitter = cfg->gain_jitter;
    dc.scale_jitter = cfg->scale_jitter, dc.transpose = cfg->transpose;
    dc.collage = cfg->collage, dc.fine_fraction = cfg->fine_fraction;
    dc.clip_fraction = cfg->clip_fraction;
    dc.clean_fraction = cfg->clean_fraction;
    if (clean) { /* the fit adds noise, clipping and quantisation itself */
        dc.noise_min = dc.noise_max = dc.val_noise = 0.0f;
        dc.sensor_clip = dc.sensor_bits = 0;
        dc.clip_fraction = 0.0f;
        dc.clean_fraction = 0.0f;
    }
    return lm_dataset_open(&dc, err);
}

lm_dataset *lm_train_open_data(const lm_train_cfg *cfg, const lm_system *sys, int clean,
                               lm_err *err)
{
    return open_data(cfg, sys, clean, 0, 0, 0, err);
}

/* ---- residual on a trained base ---------------------------------------------------------- */
/* The weights file of a run folder or a .safetensors path. */
static void weights_path(const char *run, char *out, size_t n)
{
    struct stat st;
    if (stat(run, &st) == 0 && S_ISDIR(st.st_mode)) snprintf(out, n, "%s/model.safetensors", run);
    else snprintf(out, n, "%s", run);
}

/* Load the "base.*" parameters of m from the base run's weights (names without the prefix). */
static lm_status load_base(lm_model *m, const char *file, lm_err *err)
{
    lm_params v;
    lm_params_init(&v);
    lm_status st = LM_OK;
    for (int i = 0; i < m->params.n && !st; i++) {
        const lm_param *e = m->params.items[i];
        if (strncmp(e->name, "base.", 5)) continue;
        lm_tensor *t = lm_params_add(&v, e->name + 5, e->t.ndim, e->t.shape, 0, err);
        if (!t) st = err->status;
        else t->data = e->t.data;
    }
    if (!st) st = lm_params_load(&v, file, 0, err);
    lm_params_free(&v);
    return st;
}

/* The model of the run: the preset, or the preset as a residual on cfg->base. */
static lm_model *create_model(const lm_train_cfg *cfg, const lm_mosaic *mo, uint64_t sys_hash,
                              lm_err *err)
{
    if (!cfg->base[0]) return lm_model_create(cfg->model, mo, cfg->seed, err);
    char file[LM_TRAIN_PATH_LEN + 32];
    weights_path(cfg->base, file, sizeof file);
    lm_err e2 = {0};
    char *bp = lm_safetensors_meta(file, "preset", &e2);
    char *bh = bp ? lm_safetensors_meta(file, "system_hash", &e2) : NULL;
    char *bb = bp ? lm_safetensors_meta(file, "base_preset", &e2) : NULL;
    char want[32];
    snprintf(want, sizeof want, "%016llx", (unsigned long long)sys_hash);
    lm_model *m = NULL;
    if (!bp) /* a bad base is bad input (exit 2), whatever the reader's status */
        lm_err_set(err, LM_ERR_ARG, "base %s: %s", file, e2.status ? e2.msg
                   : "not a Lumosaic model (no preset)");
    else if (bb && bb[0])
        lm_err_set(err, LM_ERR_ARG, "base %s: is itself a residual (%s on %s); give a plain "
                   "model as the base", file, bp, bb);
    else if (bp && bh && sys_hash && strcmp(bh, want))
        lm_err_set(err, LM_ERR_ARG, "base %s: trained for another system description", file);
    else if (bp && (m = lm_model_create_residual(cfg->model, bp, mo, cfg->seed,
                                                  cfg->base_trainable, cfg->res_init, err)) &&
             load_base(m, file, err)) {
        lm_model_free(m);
        m = NULL;
    }
    free(bp);
    free(bh);
    free(bb);
    return m;
}

/* ---- closed-form fit --------------------------------------------------------------------- */
static lm_status write_fit_report(const lm_train_cfg *cfg, const lm_lmmse_fit_report *r,
                                  int K, lm_err *err)
{
    json_t *lv = json_array();
    for (int l = 0; l < LM_LMMSE_LEVELS; l++)
        json_array_append_new(lv, json_pack("{s:f, s:o, s:o, s:o, s:b}", "sigma",
                              (double)lm_lmmse_sigmas[l], "ridge", isfinite(r->ridge[l])
                              ? json_real(r->ridge[l]) : json_null(), "synth_weight",
                              isfinite(r->synth_weight[l]) ? json_real(r->synth_weight[l])
                              : json_null(), "val_psnr",
                              isfinite(r->val_psnr[l]) ? json_real(r->val_psnr[l]) : json_null(),
                              "interpolated", !isfinite(r->ridge[l])));
    json_t *root = json_pack("{s:s, s:i, s:I, s:I, s:s, s:I, s:I, s:f, s:f, s:b, s:o}",
                             "model", cfg->model, "window", K, "patches", (json_int_t)r->patches,
                             "patches_asked", (json_int_t)r->patches_asked, "stopped",
                             r->interrupted ? "interrupted" : r->budget_spent ? "time budget"
                             : "no",
                             "val_patches", (json_int_t)r->val_patches, "rows", (json_int_t)r->rows,
                             "seconds", r->seconds, "seconds_solve", r->seconds_solve, "ridge_from_validation", r->val_patches > 0,
                             "levels", lv);
    char path[LM_TRAIN_PATH_LEN + 32], tmp[LM_TRAIN_PATH_LEN + 48];
    snprintf(path, sizeof path, "%s/fit.json", cfg->output);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    int rc = root ? json_dump_file(root, tmp, JSON_INDENT(2) | JSON_REAL_PRECISION(6)) : -1;
    json_decref(root);
    if (rc || rename(tmp, path)) {
        int e = errno;
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write the fit report: %s", path,
                          strerror(e));
    }
    snprintf(path, sizeof path, "%s/log.csv", cfg->output);
    FILE *f = fopen(path, "w");
    int ok = f && fprintf(f, "iteration,loss,lr,psnr,ssim,mae,sam\n0,,,") > 0;
    if (ok && isfinite(r->val_psnr[0])) ok = fprintf(f, "%.6f", r->val_psnr[0]) > 0;
    ok = ok && fprintf(f, ",,,\n") > 0;
    if (f && fclose(f)) ok = 0;
    return ok ? LM_OK : lm_err_set(err, LM_ERR_WRITE, "%s: cannot write the log", path);
}

static lm_status fit_closed(const lm_train_cfg *cfg, lm_model *m, lm_dataset *d,
                            const lm_train_opts *opts, lm_train_result *res, lm_err *err)
{
    FILE *out = opts->progress_out ? opts->progress_out : stderr;
    lm_lmmse_fit_report r;
    char path[LM_TRAIN_PATH_LEN + 16];
    snprintf(path, sizeof path, "%s/config.json", cfg->output);
    lm_noise_opts sensor = {0};
    sensor.clip = cfg->sensor_clip;
    sensor.bits = cfg->sensor_bits;
    char made[LM_TRAIN_PATH_LEN] = ""; /* the run folder is made once the fit has worked */
    lm_lmmse_fit_ctl ctl = {.progress = opts->progress ? out : NULL, .name = cfg->model,
                            .interrupt = opts->interrupt, .budget_s = cfg->minutes * 60.0,
                            .cpu_clock = !strcmp(cfg->clock, "cpu"),
                            .b0_noise_ratio = cfg->fit_b0_noise};
    lm_status st = lm_lmmse_fit_ctl_run(m, d, cfg->patch_h, cfg->patch_w, cfg->fit_patches,
                                        cfg->batch, cfg->fit_synth, &sensor, &ctl, &r, err);
    if (!st) st = lm_train_make_dir_top(cfg->output, made, sizeof made, err);
    if (opts->hold) opts->hold(1);
    if (!st) st = lm_train_cfg_save(cfg, path, err);
    if (!st) st = lm_train_save_checkpoint(cfg->output, m, NULL, 0, 0, opts, cfg, err);
    if (!st) st = write_fit_report(cfg, &r, lm_lmmse_window(m), err);
    if (opts->hold) opts->hold(0);
    if (st) {
        lm_train_discard_dir(cfg->output, made);
        return st;
    }
    if (opts->progress) {
        fprintf(out, "train: %s fitted in closed form in %.1f s (%ld patches, %ld pixels; %ld "
                "validation patches; solving %.1f s)\n", cfg->model, r.seconds, r.patches, r.rows,
                r.val_patches, r.seconds_solve);
        for (int l = 0; l < LM_LMMSE_LEVELS; l++) {
            if (isnan(r.ridge[l])) { /* a level between the sampled ones */
                fprintf(out, "  noise sd %-7g interpolated between the levels around it\n",
                        (double)lm_lmmse_sigmas[l]);
                continue;
            }
            fprintf(out, "  noise sd %-7g ridge %-6g synthetic share %.2g",
                    (double)lm_lmmse_sigmas[l], r.ridge[l], r.synth_weight[l]);
            if (isnan(r.val_psnr[l])) fprintf(out, "\n");
            else fprintf(out, "  validation PSNR %.2f dB\n", r.val_psnr[l]);
        }
        if (!r.val_patches)
            fprintf(out, "  (no validation split: ridge fixed, synthetic share as sampled)\n");
    }
    memset(res, 0, sizeof *res);
    res->seconds = r.seconds;
    res->validated = r.val_patches > 0;
    res->closed_form = 1;
    res->val.psnr = r.val_psnr[0];
    res->interrupted = r.interrupted;
    res->budget_spent = r.budget_spent;
    res->fit_patches = r.patches;
    res->fit_patches_asked = r.patches_asked;
    return LM_OK;
}


/* The run of a validated configuration with absolute paths. */
static lm_status session(const lm_train_cfg *cfg, lm_train_opts opts, lm_train_result *res,
                         lm_err *err)
{
    lm_system sys;
    char syspath[LM_TRAIN_PATH_LEN];
    if (cfg->system[0]) snprintf(syspath, sizeof syspath, "%s", cfg->system);
    else if (lm_data_path("systems/default.json", syspath, sizeof syspath, err)) return err->status;
    if (lm_system_load(syspath, &sys, err)) {
        lm_system_free(&sys);
        return err->status;
    }
    /* the checkpoint records the bundled default as "" (found on any machine), another
     * system by a path relative to the checkpoint's folder */
    char def[LM_TRAIN_PATH_LEN];
    lm_err e_def = {0};
    int bundled = !cfg->system[0] ||
                  (!lm_data_path("systems/default.json", def, sizeof def, &e_def) &&
                   lm_path_relative(def, syspath, def, sizeof def) == 0 && !strcmp(def, "."));
    opts.system_path = bundled ? "" : syspath;
    opts.system_hash = lm_file_hash(syspath);
    lm_mosaic mo;
    lm_model *m = NULL;
    lm_dataset *d = NULL;
    lm_status st = lm_mosaic_from_system(&sys, &mo, err);
    if (!st && !(m = create_model(cfg, &mo, opts.system_hash, err))) st = err->status;
    int closed = !st && lm_model_has(m, LM_CAP_CLOSED_FORM) && strcmp(cfg->fit, "sgd");
    if (!st && !closed && !strcmp(cfg->fit, "closed"))
        st = lm_err_set(err, LM_ERR_ARG, "config: field 'fit': model %s has no closed form (only "
                        "lmmse presets)", cfg->model);
    if (!st && closed && opts.data_parallel && lm_dist_size() > 1)
        st = lm_err_set(err, LM_ERR_ARG, "%s is fitted in closed form in one process (seconds): "
                        "run it without mpirun", cfg->model);
    if (!st && closed && (cfg->photons > 0.0f || cfg->read_noise > 0.0f))
        st = lm_err_set(err, LM_ERR_ARG, "config: 'photons' / 'read_noise': the closed-form fit of "
                        "%s models Gaussian noise only (use --fit sgd, or a network on it as a "
                        "base)", cfg->model);
    if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) &&
        (cfg->scale_jitter > 0.0f || cfg->transpose || cfg->collage > 0.0f))
        st = lm_err_set(err, LM_ERR_ARG, "config: 'scale_jitter' / 'transpose' / 'collage' with "
                        "'motion_fraction' or 'frames' 3: moving and multi-frame samples are "
                        "cut from one scene on the tile grid, without zoom, transposition or "
                        "collage");
    if (!st && closed && cfg->clip_fraction > 0.0f)
        st = lm_err_set(err, LM_ERR_ARG, "config: 'clip_fraction': the closed-form fit of %s "
                        "clips all of its noisy samples or none ('sensor_clip')", cfg->model);
    if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) && cfg->clip_fraction > 0.0f)
        st = lm_err_set(err, LM_ERR_ARG, "config: 'clip_fraction' with 'motion_fraction' or "
                        "'frames' 3: moving and multi-frame samples are clipped all or none "
                        "('sensor_clip')");
    if (!st && closed && cfg->clean_fraction > 0.0f)
        st = lm_err_set(err, LM_ERR_ARG, "config: 'clean_fraction': the closed-form fit of %s "
                        "draws its own noise", cfg->model);
    if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) && cfg->clean_fraction > 0.0f)
        st = lm_err_set(err, LM_ERR_ARG, "config: 'clean_fraction' with 'motion_fraction' or "
                        "'frames' 3: moving and multi-frame samples take the noise range only");
    if (!st && closed && (cfg->illum_jitter > 0.0f || cfg->gain_jitter > 0.0f))
        st = lm_err_set(err, LM_ERR_ARG, "config: 'illum_jitter' / 'gain_jitter': augmentation "
                        "of SGD training; the closed-form fit of %s reads the scenes as they are "
                        "(use --fit sgd, or a network on it as a base)", cfg->model);
    if (!st && closed && cfg->fit_b0_noise > 0.0f &&
        (lm_model_buckets(m) != 2 || lm_lmmse_features(m) > 0))
        st = lm_err_set(err, LM_ERR_ARG, "config: 'fit_b0_noise': a bucket-0 noise ratio is for "
                        "the analytic noise of a two-bucket floor without features (lmmse-b2, "
                        "lmmse-K-b2), not %s", cfg->model);
    if (!st && !closed && cfg->fit_b0_noise > 0.0f)
        st = lm_err_set(err, LM_ERR_ARG, "config: 'fit_b0_noise' is an option of the two-bucket "
                        "floor's closed-form fit, not of SGD training (%s)", cfg->model);
    if (!st && closed && opts.resume)
        st = lm_err_set(err, LM_ERR_ARG, "resume: %s is fitted in closed form, nothing to resume "
                        "(use --fit sgd to fine-tune)", cfg->model);
    int pad_y = 0, pad_x = 0, qdo = !st && lm_model_has(m, LM_CAP_QDO_OPTICS);
    if (!st && !qdo && (cfg->doe[0] || cfg->doe_optimise))
        st = lm_err_set(err, LM_ERR_ARG, "config: field 'doe': only for the QDO presets "
                        "(qdo-mst), not %s", cfg->model);
    if (!st && qdo && strcmp(cfg->device, "cpu"))
        st = lm_err_set(err, LM_ERR_ARG, "config: field 'device': the QDO camera runs on the "
                        "CPU (got '%s')", cfg->device);
    if (!st && qdo && opts.data_parallel && lm_dist_size() > 1)
        st = lm_err_set(err, LM_ERR_ARG, "%s: one process only (the DOE is not averaged over "
                        "ranks)", cfg->model);
    if (!st && qdo && lm_train_doe_pad(cfg->doe, mo.ty, mo.tx, &pad_y, &pad_x, err))
        st = err->status;
    if (!st && !(d = open_data(cfg, &sys, closed, opts.data_parallel, pad_y, pad_x, err)))
        st = err->status;
    char *hashes = st ? NULL : lm_dataset_split_hashes(d, LM_SPLIT_TRAIN);
    if (!st && !hashes) st = lm_err_set(err, LM_ERR_NOMEM, "out of memory");
    opts.train_scenes = hashes; /* eval warns when it scores one of them */
    if (!st && opts.progress && (!opts.data_parallel || lm_dist_rank() == 0))
        lm_dataset_describe(d, opts.progress_out ? opts.progress_out : stderr);
    if (!st && closed) {
        st = fit_closed(cfg, m, d, &opts, res, err);
    } else if (!st && lm_model_has(m, LM_CAP_RGB_INPUT)) {
        /* the passive RGB baseline (MST++): same samples, seen through an RGB camera */
        /* (qdo-* presets: the same camera behind the bundled DOE) */
        lm_train_source src;
        int qdo = lm_model_has(m, LM_CAP_QDO_OPTICS);
        if (qdo) { /* the camera on the tape, patches with real context (train/doe_opt.c) */
            lm_train_doe_opts o = {.optimise = cfg->doe_optimise ||
                                               lm_model_has(m, LM_CAP_DOE_LEARNED),
                                   .lr = cfg->doe_lr,
                                   .bands = cfg->doe_bands, .total = cfg->iterations};
            snprintf(o.file, sizeof o.file, "%s", cfg->doe);
            snprintf(o.quantise, sizeof o.quantise, "%s", cfg->doe_quantise);
            st = lm_train_source_doe_open(&src, d, &o, cfg->patch_h, cfg->patch_w, pad_y, pad_x,
                                          cfg->seed, err);
        } else {
            st = lm_train_source_rgb_open(&src, d, NULL, LM_RGBCAM_D65, NULL, cfg->patch_h,
                                          cfg->patch_w, cfg->seed, err);
        }
        if (!st) st = lm_train_run(cfg, m, &src, &opts, res, err);
        if (src.user && qdo) lm_train_source_doe_close(&src);
        else if (src.user) lm_train_source_rgb_close(&src);
    } else if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) && cfg->buckets == 2) {
        st = lm_err_set(err, LM_ERR_ARG, "config: 'motion_fraction' or 'frames' 3 with "
                        "'buckets' 2: moving and multi-frame samples are simulated for bucket 1 "
                        "only");
    } else if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) &&
               cfg->photons_min > 0.0f) {
        st = lm_err_set(err, LM_ERR_ARG, "config: 'photons_min' with 'motion_fraction' or "
                        "'frames' 3: moving and multi-frame samples take one photon count "
                        "('photons')");
    } else if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3) &&
               (cfg->illum_jitter > 0.0f || cfg->gain_jitter > 0.0f)) {
        st = lm_err_set(err, LM_ERR_ARG, "config: 'illum_jitter' / 'gain_jitter' with "
                        "'motion_fraction' or 'frames' 3: moving and multi-frame samples are "
                        "simulated without augmentation");
    } else if (!st && (cfg->motion_fraction > 0.0f || cfg->frames == 3)) {
        /* moving scenes, multi-frame samples */
        lm_train_source src;
        lm_train_motion_opts mo = {cfg->motion_fraction, cfg->motion_speed, cfg->motion_rotation,
                                   cfg->motion_samples, cfg->sensor_clip, cfg->sensor_bits,
                                   cfg->photons, cfg->read_noise, cfg->frames, 1};
        st = lm_train_source_motion_open(&src, d, &sys, &mo, cfg->patch_h, cfg->patch_w,
                                         cfg->seed, err);
        if (!st) st = lm_train_run(cfg, m, &src, &opts, res, err);
        if (src.user) lm_train_source_motion_close(&src);
    } else if (!st) {
        lm_train_source src = lm_train_source_dataset(d);
        st = lm_train_run(cfg, m, &src, &opts, res, err);
    }
    lm_dataset_close(d);
    free(hashes);
    lm_model_free(m);
    lm_system_free(&sys);
    return st;
}

/* Paths of the run (data, system, base) made absolute, so that config.json means the same
 * from any working directory: `train --resume RUN` reads them relative to RUN otherwise. A path
 * that does not resolve (missing) is kept; opening it reports it. */
static void absolute_paths(lm_train_cfg *c)
{
    char *paths[LM_TRAIN_MAX_PATHS + 3];
    const int n = lm_train_cfg_paths(c, paths);
    for (int i = 0; i < n; i++) {
        char *abs = paths[i][0] ? realpath(paths[i], NULL) : NULL;
        if (abs && strlen(abs) < LM_TRAIN_PATH_LEN) strcpy(paths[i], abs);
        free(abs);
    }
}

/* The model and the loader read the same buckets: a "-b2" preset sets buckets 2; buckets 2
 * with a one-bucket name picks the name's "-b2" preset (rt-8 -> rt-8-b2). */
static lm_status resolve_buckets(lm_train_cfg *c, lm_err *err)
{
    size_t n = strlen(c->model);
    int b2 = n > 3 && !strcmp(c->model + n - 3, "-b2");
    if (b2 && c->buckets != 2 && lm_train_cfg_given(c, "buckets"))
        return lm_err_set(err, LM_ERR_ARG, "config: 'buckets' %d conflicts with model %s, a "
                          "two-bucket preset (drop 'buckets', or use the model without -b2)",
                          c->buckets, c->model);
    if (b2) c->buckets = 2;
    if (b2 || c->buckets != 2) return LM_OK;
    char name[sizeof c->model + 4];
    snprintf(name, sizeof name, "%s-b2", c->model);
    if (strlen(name) >= sizeof c->model || !lm_model_preset_known(name))
        return lm_err_set(err, LM_ERR_ARG, "config: field 'buckets': model %s has no two-bucket "
                          "form (lmmse, lmmse-K, rt-8 and rt-16 have: their \"-b2\" presets)",
                          c->model);
    snprintf(c->model, sizeof c->model, "%s", name);
    return LM_OK;
}

/* The same for frames: a "-mf3" preset sets frames 3; frames 3 with a one-frame name picks its
 * "-mf3" preset (rt-8 -> rt-8-mf3). */
static lm_status resolve_frames(lm_train_cfg *c, lm_err *err)
{
    size_t n = strlen(c->model);
    int mf = n > 4 && !strcmp(c->model + n - 4, "-mf3");
    if (mf && c->frames != 3 && lm_train_cfg_given(c, "frames"))
        return lm_err_set(err, LM_ERR_ARG, "config: 'frames' %d conflicts with model %s, a "
                          "three-frame preset (drop 'frames', or use the model without -mf3)",
                          c->frames, c->model);
    if (mf) c->frames = 3;
    if (c->frames == 2)
        return lm_err_set(err, LM_ERR_ARG, "config: field 'frames': 1 or 3 (got 2)");
    if (mf || c->frames != 3) return LM_OK;
    char name[sizeof c->model + 5];
    snprintf(name, sizeof name, "%s-mf3", c->model);
    if (strlen(name) >= sizeof c->model || !lm_model_preset_known(name))
        return lm_err_set(err, LM_ERR_ARG, "config: field 'frames': model %s has no multi-frame "
                          "form (rt-8 and rt-16 have: their \"-mf3\" presets)", c->model);
    snprintf(c->model, sizeof c->model, "%s", name);
    return LM_OK;
}

lm_status lm_train_session(const lm_train_cfg *cfg_in, const lm_train_opts *opts_in,
                           lm_train_result *res, lm_err *err)
{
    lm_train_opts opts = opts_in ? *opts_in : (lm_train_opts){0};
    if (lm_train_cfg_validate(cfg_in, err)) return err->status;
    lm_train_cfg *cfg = malloc(sizeof *cfg);
    if (!cfg) return lm_err_set(err, LM_ERR_NOMEM, "train: out of memory");
    *cfg = *cfg_in;
    absolute_paths(cfg);
    lm_status st = resolve_buckets(cfg, err);
    if (!st) st = resolve_frames(cfg, err);
    if (!st) st = session(cfg, opts, res, err);
    free(cfg);
    return st;
}
