/* session.c — a training run from its configuration: system description, network front,
 * model, dataset, then the loop (train.c). Also the dataset adapter of lm_train_source.
 * What it is not: option parsing (cli/cmd_train.c) or the loop itself. */
#include "train/train.h"
#include "data/rgbcam.h"
#include "data/dataset.h"
#include "data/spectra.h"
#include "train/mosaic_system.h"
#include <string.h>

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
    return (lm_train_source){d, ds_batch, ds_count, ds_eval};
}

static lm_dataset *open_data(const lm_train_cfg *cfg, const lm_system *sys, lm_err *err)
{
    const char *paths[LM_TRAIN_MAX_PATHS];
    for (int i = 0; i < cfg->ndata; i++) paths[i] = cfg->data[i];
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths;
    dc.npaths = cfg->ndata;
    dc.sys = sys;
    dc.patch_h = cfg->patch_h;
    dc.patch_w = cfg->patch_w;
    dc.synth_fraction = cfg->synth_fraction;
    dc.noise_min = cfg->noise_min;
    dc.noise_max = cfg->noise_max;
    dc.seed = cfg->seed;
    dc.workers = cfg->workers;
    dc.val_patches = cfg->val_patches;
    dc.val_noise = cfg->val_noise;
    return lm_dataset_open(&dc, err);
}

lm_status lm_train_session(const lm_train_cfg *cfg, const lm_train_opts *opts_in,
                           lm_train_result *res, lm_err *err)
{
    lm_train_opts opts = opts_in ? *opts_in : (lm_train_opts){0};
    if (lm_train_cfg_validate(cfg, err)) return err->status;
    lm_system sys;
    char syspath[LM_TRAIN_PATH_LEN];
    if (cfg->system[0]) snprintf(syspath, sizeof syspath, "%s", cfg->system);
    else if (lm_data_path("systems/default.json", syspath, sizeof syspath, err)) return err->status;
    if (lm_system_load(syspath, &sys, err)) {
        lm_system_free(&sys);
        return err->status;
    }
    opts.system_path = syspath;
    opts.system_hash = lm_file_hash(syspath);
    lm_mosaic mo;
    lm_model *m = NULL;
    lm_dataset *d = NULL;
    lm_status st = lm_mosaic_from_system(&sys, &mo, err);
    if (!st && !(m = lm_model_create(cfg->model, &mo, cfg->seed, err))) st = err->status;
    if (!st && !(d = open_data(cfg, &sys, err))) st = err->status;
    if (!st && opts.progress) lm_dataset_describe(d, opts.progress_out ? opts.progress_out : stderr);
    if (!st && m->in_channels == 3) {
        /* the passive RGB baseline (MST++): same samples, seen through an RGB camera */
        lm_train_source src;
        st = lm_train_source_rgb_open(&src, d, NULL, LM_RGBCAM_D65, NULL, cfg->patch_h,
                                      cfg->patch_w, cfg->seed, err);
        if (!st) st = lm_train_run(cfg, m, &src, &opts, res, err);
        if (src.user) lm_train_source_rgb_close(&src);
    } else if (!st) {
        lm_train_source src = lm_train_source_dataset(d);
        st = lm_train_run(cfg, m, &src, &opts, res, err);
    }
    lm_dataset_close(d);
    lm_model_free(m);
    lm_system_free(&sys);
    return st;
}
