/* checkpoint.c — checkpoints of a training run: weights (model.safetensors) and optimizer +
 * sampler state (optimizer.safetensors), each written atomically, optimizer first; see train.h.
 * What it is not: the loop (train.c) or the safetensors codec (models/safetensors.c). */
#include "train/train.h"
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include "train/dist.h"
#include "data/util.h"

#define CKPT_FORMAT "lumosaic-checkpoint-1"

/* An lm_params whose tensors view the optimizer moments (never finalized: data points into
 * opt->m / opt->v, so save and load need no copy) and, with a weight average (opt->ema), the
 * weights being trained ("train_weights.*": the checkpoint's model.safetensors holds the
 * average, the weights to use; the loop swaps them, lm_adam_ema_swap). */
static lm_status moment_views(const lm_model *m, const lm_adam *opt, lm_params *v, lm_err *err)
{
    static const char *const kind[3] = {"exp_avg", "exp_avg_sq", "train_weights"};
    lm_params_init(v);
    for (int pass = 0; pass < (opt->ema ? 3 : 2); pass++)
        for (int i = 0; i < m->params.n; i++) {
            const lm_param *e = m->params.items[i];
            if (!e->trainable) continue;
            char nm[LM_PARAM_NAME_MAX + 16];
            snprintf(nm, sizeof nm, "%s.%s", kind[pass], e->name);
            if (strlen(nm) >= LM_PARAM_NAME_MAX) /* keep the full name: fall back to a short one */
                snprintf(nm, sizeof nm, "%s.%d", kind[pass], i);
            lm_tensor *t = lm_params_add(v, nm, e->t.ndim, e->t.shape, 0, err);
            if (!t) {
                lm_params_free(v);
                return err->status;
            }
            t->data = (pass == 2 ? opt->ema : pass ? opt->v : opt->m) + e->offset;
        }
    return LM_OK;
}

static void dir_file(char *out, size_t n, const char *dir, const char *name)
{
    snprintf(out, n, "%s/%s", dir, name);
}

lm_status lm_train_save_checkpoint(const char *dir, const lm_model *m, const lm_adam *opt,
                                   long iteration, long next_batch, const lm_train_opts *opts,
                                   const lm_train_cfg *cfg, lm_err *err)
{
    char path[LM_TRAIN_PATH_LEN + 64], it[32], nb[32], step[32], seed[32], thr[16], hash[32];
    char secs[32], ranks[16];
    if (lm_lmmse_custom_levels(m) || (m->base && lm_lmmse_custom_levels(m->base)))
        return lm_err_set(err, LM_ERR_ARG, "checkpoint: model %s has noise levels other than "
                          "lm_lmmse_sigmas (a measurement's): checkpoints hold the default "
                          "levels only", m->preset);
    snprintf(ranks, sizeof ranks, "%d", opts && opts->data_parallel ? lm_dist_size() : 1);
    snprintf(secs, sizeof secs, "%.3f", opts ? opts->elapsed : 0.0);
    snprintf(it, sizeof it, "%ld", iteration);
    snprintf(nb, sizeof nb, "%ld", next_batch);
    snprintf(seed, sizeof seed, "%" PRIu64, cfg->seed);
    snprintf(thr, sizeof thr, "%d", cfg->threads);
    const char *sys = opts && opts->system_path ? opts->system_path : "";
    char sys_rel[LM_TRAIN_PATH_LEN]; /* relative to the checkpoint: the folder can move */
    if (sys[0] && !lm_path_relative(dir, sys, sys_rel, sizeof sys_rel)) sys = sys_rel;
    snprintf(hash, sizeof hash, "%016" PRIx64, opts ? opts->system_hash : 0);
    if (opt) {
        lm_params v;
        if (moment_views(m, opt, &v, err)) return err->status;
        snprintf(step, sizeof step, "%ld", opt->step);
        char ema[32];
        snprintf(ema, sizeof ema, "%.9g", (double)opt->cfg.ema);
        const char *meta[] = {"format", CKPT_FORMAT, "step", step, "iteration", it,
                              "next_batch", nb, "seed", seed, "threads", thr, "seconds", secs,
                              "clock", cfg->clock[0] ? cfg->clock : "wall", "ranks", ranks,
                              "ema", ema};
        dir_file(path, sizeof path, dir, "optimizer.safetensors");
        lm_status st = lm_params_save(&v, path, meta, 10, err);
        lm_params_free(&v);
        if (st) return st;
    }
    char bk[8]; /* the coded-frame buckets the model reads (1, 2; 0 = RGB input) */
    snprintf(bk, sizeof bk, "%d", lm_model_buckets(m));
    char fr[8]; /* coded frames per output frame (1; 3 = multi-frame) */
    snprintf(fr, sizeof fr, "%d", lm_model_frames(m));
    char clip[32]; /* the share of its noisy training samples clipped to [0, 1] */
    snprintf(clip, sizeof clip, "%.6g", cfg->sensor_clip ? 1.0 : (double)cfg->clip_fraction);
    const char *meta[] = {"format", CKPT_FORMAT, "preset", m->preset, "system", sys,
                          "system_hash", hash, "iteration", it, "seconds", secs, "buckets", bk,
                          "frames", fr, "train_scenes",
                          opts && opts->train_scenes ? opts->train_scenes : "",
                          "clipped", clip, "base_preset", m->base ? m->base->preset : ""};
    dir_file(path, sizeof path, dir, "model.safetensors");
    return lm_params_save(&m->params, path, meta, m->base ? 11 : 10, err);
}

int lm_train_checkpoint_cpu_clock(const char *dir)
{
    char path[LM_TRAIN_PATH_LEN + 64];
    dir_file(path, sizeof path, dir, "optimizer.safetensors");
    lm_err e = {0};
    char *s = lm_safetensors_meta(path, "clock", &e);
    int cpu = s && !strcmp(s, "cpu");
    free(s);
    return cpu;
}

int lm_train_checkpoint_ranks(const char *dir)
{
    char path[LM_TRAIN_PATH_LEN + 64];
    dir_file(path, sizeof path, dir, "optimizer.safetensors");
    lm_err e = {0};
    char *s = lm_safetensors_meta(path, "ranks", &e);
    long v = s ? strtol(s, NULL, 10) : 1;
    free(s);
    return v >= 1 && v <= 1000000 ? (int)v : 1;
}

double lm_train_checkpoint_seconds(const char *dir)
{
    char path[LM_TRAIN_PATH_LEN + 64];
    dir_file(path, sizeof path, dir, "optimizer.safetensors");
    lm_err e = {0};
    char *s = lm_safetensors_meta(path, "seconds", &e);
    double v = s ? strtod(s, NULL) : 0.0;
    free(s);
    return v >= 0 && v < 1e9 ? v : 0.0;
}

/* Integer metadata value, required. */
static lm_status meta_long(const char *path, const char *key, long long *out, lm_err *err)
{
    lm_err e2 = {0};
    char *s = lm_safetensors_meta(path, key, &e2);
    char *end = NULL;
    if (s) *out = strtoll(s, &end, 10);
    int ok = s && end != s && *end == 0;
    free(s);
    if (!ok)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: metadata '%s' missing or not an integer%s%s",
                          path, key, e2.status ? ": " : "", e2.msg);
    return LM_OK;
}

static lm_status load_optimizer(const char *path, lm_model *m, lm_adam *opt, long *next_batch,
                                uint64_t *seed, long iteration, lm_err *err)
{
    long long it = 0, step = 0, nb = 0, sd = 0;
    if (meta_long(path, "iteration", &it, err) || meta_long(path, "step", &step, err) ||
        meta_long(path, "next_batch", &nb, err) || meta_long(path, "seed", &sd, err))
        return err->status;
    if (it != iteration)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: iteration %lld but the weights are at "
                          "iteration %ld (interrupted while checkpointing?)", path, it, iteration);
    lm_err e2 = {0};
    char *ema = lm_safetensors_meta(path, "ema", &e2); /* absent before weight averages */
    double was = ema ? strtod(ema, NULL) : 0.0;
    free(ema);
    /* an average switched on at this checkpoint (a fork or resume with --ema) starts at the
     * checkpoint's weights; one that exists cannot change its decay or be dropped */
    int start_avg = was == 0.0 && opt->cfg.ema > 0 && opt->ema;
    if ((float)was != opt->cfg.ema && !start_avg)
        return lm_err_set(err, LM_ERR_ARG, "%s: the run averaged its weights with ema %g, this "
                          "run asks for %g (set --ema %g)", path, was, (double)opt->cfg.ema, was);
    float *avg = opt->ema;
    if (start_avg) opt->ema = NULL; /* no "train_weights" in this file */
    lm_params v;
    lm_status st = moment_views(m, opt, &v, err);
    if (start_avg) opt->ema = avg;
    if (st) return st;
    st = lm_params_load(&v, path, 0, err);
    lm_params_free(&v);
    if (st) return st;
    if (start_avg) /* the model holds the checkpoint's weights: the average starts there */
        for (int i = 0; i < m->params.n; i++) {
            const lm_param *e = m->params.items[i];
            if (e->trainable)
                memcpy(opt->ema + e->offset, e->t.data,
                       (size_t)lm_tensor_numel(&e->t) * sizeof(float));
        }
    opt->step = (long)step;
    if (next_batch) *next_batch = (long)nb;
    if (seed) *seed = (uint64_t)sd;
    return LM_OK;
}

lm_status lm_train_load_checkpoint(const char *dir, lm_model *m, lm_adam *opt, long *iteration,
                                   long *next_batch, uint64_t *seed, lm_err *err)
{
    char path[LM_TRAIN_PATH_LEN + 64];
    dir_file(path, sizeof path, dir, "model.safetensors");
    char *preset = lm_safetensors_meta(path, "preset", err);
    if (!preset) {
        if (err && !err->status)
            lm_err_set(err, LM_ERR_FORMAT, "%s: not a Lumosaic checkpoint (no preset)", path);
        return err ? err->status : LM_ERR_FORMAT;
    }
    int same = !strcmp(preset, m->preset);
    if (!same)
        lm_err_set(err, LM_ERR_ARG, "%s: checkpoint of model '%s', but the run uses '%s'", path,
                   preset, m->preset);
    free(preset);
    if (!same) return LM_ERR_ARG;
    long long it = 0;
    if (meta_long(path, "iteration", &it, err)) return err->status;
    lm_status st = lm_params_load(&m->params, path, 0, err);
    if (st) return st;
    if (iteration) *iteration = (long)it;
    if (!opt) return LM_OK;
    dir_file(path, sizeof path, dir, "optimizer.safetensors");
    return load_optimizer(path, m, opt, next_batch, seed, (long)it, err);
}
