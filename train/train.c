/* train.c — the training loop: batches from an lm_train_source, forward, L1 on all 33
 * channels (models with 31 outputs, e.g. MST++: on target channels 1..31, 400..700 nm; models
 * with in_channels != 1 take B x in_channels x H x W batches) scaled by 1/accum_steps,
 * backward, gradient accumulation, Adam, NaN/inf guard, validation metrics, CSV log,
 * progress on stderr, checkpoints and exact resume (train.h).
 * What it is not: the config (config.c), checkpoint files (checkpoint.c), or the data
 * pipeline (data/dataset.h). */
#include "train/train.h"
#include "tensor/isa.h"
#include "autograd/autograd.h"
#include "data/noise_est.h"
#include "data/util.h"
#include "tensor/device.h"
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "train/dist.h"
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

typedef struct loop {
    const lm_train_cfg *cfg;
    const lm_train_opts *opts;
    const lm_train_source *src;
    lm_model *model;
    lm_adam opt;
    lm_ctx ctx;
    lm_backend *backend;          /* cfg->device (NULL until opened) */
    lm_tensor **ps, *held;        /* device runs: the parameters swapped in for each step */
    int np;                       /* 0 on the CPU: no swapping, the path is unchanged */
    float *raw, *target, *pred;   /* one batch, host */
    float *sigma;                 /* per item: the input's estimated noise sd (noise_input) */
    void *noise_scratch;          /* the estimator's scratch (noise_input), allocated once */
    FILE *log;
    char made[LM_TRAIN_PATH_LEN]; /* outermost folder this run created ("" = none) */
    long it0;                     /* iteration this invocation started at */
    long saved;                   /* iteration of the checkpoint on disk (-1: none yet) */
    double t0, last_print;        /* wall clock: progress lines */
    double t_train0;              /* training clock (train_s) when this invocation started */
    int tty;
    long total;                   /* iterations of the schedule (cfg->iterations, or resolved
                                   * from the time budget) */
    double seconds0;              /* training seconds before this invocation (resume) */
    double t_first;               /* when this invocation's first iteration ended (0: not yet) */
    double snap_done;             /* last snapshot mark written or found (minutes) */
    long next_it;                 /* time budget: re-resolve at this iteration too (0: none) */
    long it_res;                  /* time budget: iteration and time of the first resolution */
    double t_res;
    int cpu_clock;                /* cfg->clock "cpu": training time is the process's CPU time */
    int rank, nranks;             /* data-parallel ranks (train/dist.h); rank 0 writes files */
} loop;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* The clock of training time (budget, snapshots, checkpoint seconds): wall, or the process's
 * CPU time over all its threads (cfg->clock). Progress lines and ETAs stay on the wall clock. */
static double train_s(const loop *L)
{
    struct timespec ts;
    if (!L->cpu_clock || clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return now_s();
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

lm_status lm_train_make_dir_top(const char *path, char *top, size_t n, lm_err *err)
{
    char failed[LM_TRAIN_PATH_LEN];
    if (lm_make_dirs(path, top, n, failed, sizeof failed))
        return lm_err_set(err, LM_ERR_WRITE, "output %s: cannot create folder %s: %s", path,
                          failed, strerror(errno));
    return LM_OK;
}

lm_status lm_train_make_dir(const char *path, lm_err *err)
{
    return lm_train_make_dir_top(path, NULL, 0, err);
}

void lm_train_discard_dir(const char *dir, const char *top)
{
    static const char *const files[] = {"config.json", "log.csv", "fit.json",
                                        "model.safetensors", "optimizer.safetensors",
                                        "doe.json", "doe_heights.png", "doe_state.safetensors"};
    char p[LM_TRAIN_PATH_LEN + 32];
    for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
        snprintf(p, sizeof p, "%s/%s", dir, files[i]);
        remove(p);
    }
    if (!top || !top[0]) return;
    size_t lt = strlen(top);
    snprintf(p, sizeof p, "%s", dir); /* dir, then its parents, down to top */
    while (strlen(p) >= lt && rmdir(p) == 0 && strlen(p) > lt) {
        char *s = strrchr(p, '/');
        if (!s) break;
        *s = 0;
    }
}

void lm_train_discard_checkpoint(const char *dir)
{
    static const char *const files[] = {"model.safetensors", "optimizer.safetensors", "doe.json",
                                        "doe_heights.png", "doe_state.safetensors"};
    char p[LM_TRAIN_PATH_LEN + 32];
    for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
        snprintf(p, sizeof p, "%s/%s", dir, files[i]);
        remove(p);
    }
}

/* ---- parameters on the device for one step (no-ops on the CPU) ------------------------ */
/* Call right after lm_ctx_reset; params_back after backward and before the next reset (it
 * adds the device gradients into the host gradient block and restores the host tensors). */
static void params_in(loop *L)
{
    if (L->np) lm_tensors_swap_to_device(&L->ctx, L->ps, L->np, L->held);
}

static void params_back(loop *L)
{
    if (L->np) lm_tensors_swap_back(&L->ctx, L->ps, L->np, L->held);
}

/* Models that read the input's noise level get it estimated from each item, as infer does
 * from each frame (data/noise_est.h). */
static void set_noise(loop *L, int B)
{
    lm_model *m = L->model;
    if (!m->noise_input) return;
    const int H = L->cfg->patch_h, W = L->cfg->patch_w;
    for (int b = 0; b < B; b++) {
        /* bucket 1: plane 0 of the item (of in_channels planes) */
        float s = lm_noise_estimate_scratch(L->raw + (size_t)b * m->in_channels * H * W, H, W,
                                            m->mosaic.ty,
                                            m->mosaic.tx, L->noise_scratch);
        L->sigma[b] = s > 0.0f ? s : 0.0f;
    }
    m->noise_sigma_items = L->sigma;
}

/* ---- one iteration -------------------------------------------------------------------- */
/* "the last good checkpoint (iteration N) in DIR is kept" or "no checkpoint ..." */
static void kept_text(const loop *L, char *buf, size_t n)
{
    if (L->saved > 0 || (L->saved == 0 && L->opts->resume))
        snprintf(buf, n, "the last good checkpoint (iteration %ld) in %.400s is kept", L->saved,
                 L->cfg->output);
    else
        snprintf(buf, n, "no checkpoint had been written yet");
}

/* Forward + L1 + backward of batch `index`; adds the unscaled loss to *loss_sum. */
static lm_status micro_step(loop *L, long index, double *loss_sum, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    int B = cfg->batch, H = cfg->patch_h, W = cfg->patch_w;
    /* rank r of N takes global batch index * N + r: the N ranks' batches together are the
     * samples one process would draw with batch N x B */
    long gi = index * L->nranks + L->rank;
    if (L->src->batch(L->src->user, gi, B, L->raw, L->target, err)) return err->status;
    lm_ctx *c = &L->ctx;
    lm_ctx_reset(c);
    params_in(L);
    set_noise(L, B);
    const lm_train_front *fr = L->src->front;
    lm_tensor *raw = fr ? fr->input(L->src->user, c, B)
                        : lm_tensor_from(c, 4, (int[]){B, L->model->in_channels, H, W}, L->raw);
    lm_tensor *tgt = lm_tensor_from(c, 4, (int[]){B, LM_MODEL_OUT_CHANNELS, H, W}, L->target);
    if (L->model->out_channels == 31) tgt = lm_slice(c, tgt, 1, 1, 31); /* 400..700 nm */
    lm_tensor *loss = lm_l1_loss(c, lm_model_forward(c, L->model, raw), tgt);
    float lv = NAN;
    if (loss) lm_tensor_read(c, loss, &lv);
    if (loss && isfinite(lv))
        lm_backward(c, lm_scale(c, loss, 1.0f / (float)cfg->accum_steps), NULL);
    params_back(L);
    if (lm_ctx_status(c)) {
        lm_err_set(err, lm_ctx_status(c), "training step: %s", lm_ctx_message(c));
        lm_ctx_clear_error(c);
        return err->status;
    }
    *loss_sum += lv;
    return LM_OK;
}

static int grads_finite(const lm_params *p)
{
    int ok = 1;
    for (int i = 0; i < p->n && ok; i++) {
        const lm_param *e = p->items[i];
        if (!e->trainable) continue;
        long n = lm_tensor_numel(&e->t);
        for (long k = 0; k < n && ok; k++) ok = isfinite(e->g.data[k]);
    }
    return ok;
}

/* One optimizer update (iteration `it`, 0-based). *loss = mean L1 over the accumulated
 * batches. LM_ERR_NUMERIC (nothing updated) when the loss or a gradient is not finite. */
static lm_status iteration(loop *L, long it, double *loss, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    lm_params_zero_grad(&L->model->params);
    if (L->src->front) L->src->front->zero_grad(L->src->user);
    double sum = 0.0;
    for (int k = 0; k < cfg->accum_steps; k++) {
        lm_status st = micro_step(L, it * cfg->accum_steps + k, &sum, err);
        if (st) return st;
        if (!isfinite(sum)) break;
    }
    *loss = sum / cfg->accum_steps;
    if (L->nranks > 1) { /* the gradient and the loss averaged over the ranks */
        lm_params *p = &L->model->params;
        lm_dist_sum_float(p->grad, p->total);
        float inv = 1.0f / (float)L->nranks;
        for (size_t i = 0; i < p->total; i++) p->grad[i] *= inv;
        lm_dist_sum_double(loss, 1);
        *loss /= L->nranks;
    }
    if (isfinite(*loss) && grads_finite(&L->model->params)) {
        lm_adam_step(&L->opt, &L->model->params, lm_nthreads(&L->ctx));
        return L->src->front ? L->src->front->step(L->src->user, err) : LM_OK;
    }
    char kept[LM_TRAIN_PATH_LEN + 64];
    kept_text(L, kept, sizeof kept);
    return lm_err_set(err, LM_ERR_NUMERIC, "iteration %ld: %s is %s; training stopped (%s)",
                      it + 1, isfinite(*loss) ? "a gradient" : "the loss",
                      isnan(*loss) ? "NaN" : "not finite", kept);
}

/* ---- validation ----------------------------------------------------------------------- */
/* In place: b items of 31 planes (400..700 nm) -> the 33-channel layout (channels 1..31; the
 * edge channels 0 and 32, which the metrics do not read, are set to 0). Back to front, so no
 * plane is overwritten before it is moved. */
static void widen31(float *p, int b, int plane)
{
    for (int j = b - 1; j >= 0; j--) {
        for (int k = 30; k >= 0; k--)
            memmove(p + ((size_t)j * 33 + 1 + k) * plane, p + ((size_t)j * 31 + k) * plane,
                    (size_t)plane * sizeof(float));
        memset(p + (size_t)j * 33 * plane, 0, (size_t)plane * sizeof(float));
        memset(p + ((size_t)j * 33 + 32) * plane, 0, (size_t)plane * sizeof(float));
    }
}

static lm_status validate(loop *L, lm_metrics *out, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    int n = L->src->eval_count ? L->src->eval_count(L->src->user) : 0;
    int H = cfg->patch_h, W = cfg->patch_w;
    if (n > 0 && L->src->front && L->src->front->refresh(L->src->user, err)) return err->status;
    size_t rn = (size_t)L->model->in_channels * H * W, tn = (size_t)LM_MODEL_OUT_CHANNELS * H * W;
    lm_metrics_acc acc = {0};
    lm_ctx *c = &L->ctx;
    int old = lm_ctx_set_grad(c, 0);
    lm_status st = LM_OK;
    for (int i0 = 0, k = 0; i0 < n && !st; i0 += cfg->batch, k++) {
        int b = n - i0 < cfg->batch ? n - i0 : cfg->batch;
        if (k % L->nranks != L->rank) continue; /* ranks share the batches; summed below */
        for (int j = 0; j < b && !st; j++)
            st = L->src->eval_sample(L->src->user, i0 + j, L->raw + j * rn, L->target + j * tn, err);
        if (st) break;
        lm_ctx_reset(c);
        params_in(L);
        set_noise(L, b);
        lm_tensor *raw = lm_tensor_from(c, 4, (int[]){b, L->model->in_channels, H, W}, L->raw);
        lm_tensor *pred = lm_model_forward(c, L->model, raw);
        int bad = !pred || lm_tensor_read(c, pred, L->pred);
        params_back(L);
        if (!bad && L->model->out_channels == 31) widen31(L->pred, b, H * W);
        if (bad) {
            st = lm_err_set(err, lm_ctx_status(c), "validation: %s", lm_ctx_message(c));
            lm_ctx_clear_error(c);
            break;
        }
        for (int j = 0; j < b && !st; j++) {
            lm_metrics m;
            st = lm_metrics_target33(L->pred + j * tn, L->target + j * tn, H, W, &m, err);
            if (!st) lm_metrics_acc_add(&acc, &m);
        }
    }
    lm_ctx_set_grad(c, old);
    lm_ctx_reset(c);
    if (!st && L->nranks > 1) { /* every rank's share of the batches, summed */
        double v[6] = {acc.sum.psnr, acc.sum.ssim, acc.sum.mae, acc.sum.sam,
                       (double)acc.sum.sam_pixels, (double)acc.n};
        lm_dist_sum_double(v, 6);
        acc.sum.psnr = v[0], acc.sum.ssim = v[1], acc.sum.mae = v[2], acc.sum.sam = v[3];
        acc.sum.sam_pixels = (long)v[4], acc.n = (long)v[5];
    }
    *out = lm_metrics_acc_mean(&acc);
    return st;
}

/* ---- progress and log ------------------------------------------------------------------ */
static void fmt_time(char *buf, size_t n, double s)
{
    if (!(s >= 0) || s > 1e7) snprintf(buf, n, "?");
    else if (s >= 3600) snprintf(buf, n, "%dh%02dm", (int)(s / 3600), (int)fmod(s / 60, 60));
    else snprintf(buf, n, "%dm%02ds", (int)(s / 60), (int)fmod(s, 60));
}

static void progress(loop *L, long done, double loss, float lr, int final)
{
    if (!L->opts->progress || L->rank) return;
    FILE *f = L->opts->progress_out ? L->opts->progress_out : stderr;
    double t = now_s(), el = t - L->t0;
    long total = L->total, here = done - L->it0;
    if (L->tty && !final && t - L->last_print < 0.2) return;
    if (!L->tty && !final && done % L->cfg->log_interval) return;
    L->last_print = t;
    double ips = el > 0 ? here / el : 0;
    char eta[32], els[32];
    fmt_time(eta, sizeof eta, ips > 0 ? (total - done) / ips : -1);
    fmt_time(els, sizeof els, el);
    if (L->tty) {
        char bar[31];
        int fill = (int)(30.0 * done / total);
        for (int i = 0; i < 30; i++) bar[i] = i < fill ? '#' : '.';
        bar[30] = 0;
        fprintf(f, "\r[%s] %ld/%ld  %.2f it/s  loss %.5f  lr %.2e  ETA %s ", bar, done, total,
                ips, loss, lr, eta);
        if (final) fputc('\n', f);
    } else {
        fprintf(f, "train: iteration %ld/%ld  loss %.6f  lr %.3e  %.2f it/s  elapsed %s  ETA %s\n",
                done, total, loss, lr, ips, els, eta);
    }
    fflush(f);
}

/* One row of log.csv, flushed; a row that cannot be written (disk full) stops the run. */
static lm_status log_row(loop *L, long it, double loss, float lr, const lm_metrics *m,
                         lm_err *err)
{
    if (!L->log) return LM_OK;
    int ok = (loss == loss ? fprintf(L->log, "%ld,%.8g,%.6g", it, loss, lr)
                           : fprintf(L->log, "%ld,,%.6g", it, lr)) > 0;
    if (m) ok &= fprintf(L->log, ",%.6f,%.6f,%.8f,%.6f\n", m->psnr, m->ssim, m->mae, m->sam) > 0;
    else ok &= fprintf(L->log, ",,,,\n") > 0;
    if (fflush(L->log) == 0 && ok && !ferror(L->log)) return LM_OK;
    int e = errno;
    char kept[LM_TRAIN_PATH_LEN + 64];
    kept_text(L, kept, sizeof kept);
    return lm_err_set(err, LM_ERR_WRITE, "%.400s/log.csv: cannot write: %s; training stopped (%s)",
                      L->cfg->output, e ? strerror(e) : "write error", kept);
}

/* Open log.csv: fresh (header) or, on resume, keeping only rows up to `upto`. */
static lm_status open_log(loop *L, int resume, long upto, lm_err *err)
{
    char path[LM_TRAIN_PATH_LEN + 16], tmp[LM_TRAIN_PATH_LEN + 32];
    snprintf(path, sizeof path, "%s/log.csv", L->cfg->output);
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    FILE *in = resume ? fopen(path, "r") : NULL, *out = fopen(tmp, "w");
    if (!out) {
        if (in) fclose(in);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write: %s", tmp, strerror(errno));
    }
    fprintf(out, "iteration,loss,lr,psnr,ssim,mae,sam\n");
    char line[512];
    while (in && fgets(line, sizeof line, in)) {
        char *end;
        long it = strtol(line, &end, 10);
        if (end != line && *end == ',' && it <= upto) fputs(line, out);
    }
    if (in) fclose(in);
    if (fclose(out) != 0 || rename(tmp, path) != 0) {
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write the log", path);
    }
    L->log = fopen(path, "a");
    if (!L->log)
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot append: %s", path, strerror(errno));
    return LM_OK;
}

/* ---- the run --------------------------------------------------------------------------- */
/* Open cfg->device once for the run and switch the ctx to it (nothing to do for the CPU). */
static lm_status open_device(loop *L, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    if (!strcmp(cfg->device, "cpu")) return LM_OK;
    lm_err be = {0};
    L->backend = lm_backend_open(cfg->device, &be);
    if (!L->backend)
        return lm_err_set(err, LM_ERR_ARG, "device '%s' is not available: %s", cfg->device,
                          be.msg);
    lm_ctx_set_backend(&L->ctx, L->backend);
    if (L->backend->device == LM_DEVICE_CPU) return LM_OK;
    lm_params *p = &L->model->params;
    L->ps = malloc((size_t)p->n * sizeof *L->ps);
    L->held = malloc((size_t)p->n * sizeof *L->held);
    if (!L->ps || !L->held) return lm_err_set(err, LM_ERR_NOMEM, "train: out of memory");
    for (int i = 0; i < p->n; i++) L->ps[i] = &p->items[i]->t;
    L->np = p->n;
    if (L->opts->progress)
        fprintf(L->opts->progress_out ? L->opts->progress_out : stderr, "train: device %s: %s\n",
                cfg->device, lm_backend_device_name(L->backend));
    return LM_OK;
}

static lm_status setup(loop *L, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    if (lm_ctx_init(&L->ctx, cfg->threads) != LM_OK)
        return lm_err_set(err, LM_ERR_NOMEM, "train: cannot create the compute context");
    L->ctx.precision = strcmp(cfg->precision, "bf16") ? LM_PRECISION_FP32 : LM_PRECISION_BF16;
    if (L->ctx.precision != LM_PRECISION_FP32 && L->opts->progress)
        fprintf(L->opts->progress_out ? L->opts->progress_out : stderr, "train: precision %s\n",
                lm_precision_describe(L->ctx.precision));
    if (open_device(L, err)) return err->status;
    size_t bn = (size_t)cfg->batch * cfg->patch_h * cfg->patch_w;
    L->raw = malloc(bn * L->model->in_channels * sizeof(float));
    L->target = malloc(bn * LM_MODEL_OUT_CHANNELS * sizeof(float));
    L->pred = malloc(bn * LM_MODEL_OUT_CHANNELS * sizeof(float));
    L->sigma = malloc((size_t)cfg->batch * sizeof(float));
    L->noise_scratch = malloc(lm_noise_scratch_bytes(cfg->patch_w));
    if (!L->raw || !L->target || !L->pred || !L->sigma || !L->noise_scratch)
        return lm_err_set(err, LM_ERR_NOMEM, "train: out of memory for batch %d of %dx%d",
                          cfg->batch, cfg->patch_h, cfg->patch_w);
    lm_adam_cfg ac;
    lm_train_cfg_adam(cfg, &ac);
    if (lm_adam_init(&L->opt, &L->model->params, &ac, err)) return err->status;
    return L->rank ? LM_OK : lm_train_make_dir_top(cfg->output, L->made, sizeof L->made, err);
}

static void teardown(loop *L)
{
    if (L->log) fclose(L->log);
    free(L->raw);
    free(L->target);
    free(L->pred);
    free(L->sigma);
    free(L->noise_scratch);
    L->model->noise_sigma_items = NULL;
    lm_adam_free(&L->opt);
    lm_ctx_free(&L->ctx); /* before its backend */
    lm_backend_close(L->backend);
    free(L->ps);
    free(L->held);
}

/* Seconds of training so far, over every invocation (resume restores the checkpoint's). */
static double elapsed(const loop *L) { return L->seconds0 + (train_s(L) - L->t_train0); }

static void hold(const loop *L, int on)
{
    if (L->opts->hold) L->opts->hold(on);
}

/* The checkpoint of iteration `it` (rank 0): the front's state, the weights (the average when
 * there is one) and the optimizer's, written under a hold. */
static lm_status checkpoint(loop *L, long it, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    lm_train_opts o2 = *L->opts;
    o2.elapsed = elapsed(L);
    hold(L, 1);
    lm_status st = L->src->front ? L->src->front->save(L->src->user, cfg->output, err) : LM_OK;
    lm_adam_ema_swap(&L->opt, &L->model->params); /* the file holds the average */
    if (!st) st = lm_train_save_checkpoint(cfg->output, L->model, &L->opt, it,
                                           it * cfg->accum_steps, &o2, cfg, err);
    lm_adam_ema_swap(&L->opt, &L->model->params);
    hold(L, 0);
    if (!st) L->saved = it;
    return st;
}

/* Fresh run: config.json and the checkpoint of iteration 0, so that the folder resumes however
 * early the run is stopped; resume: checkpoint state. Sets *start (iterations done). */
static lm_status begin(loop *L, long *start, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    *start = 0;
    if (!L->opts->resume) {
        char path[LM_TRAIN_PATH_LEN + 16];
        snprintf(path, sizeof path, "%s/config.json", cfg->output);
        if (L->rank) return LM_OK; /* rank 0 writes the run folder */
        hold(L, 1);
        lm_status st = lm_train_cfg_save(cfg, path, err);
        if (!st) st = checkpoint(L, 0, err);
        if (!st) st = open_log(L, 0, 0, err);
        hold(L, 0);
        return st;
    }
    long nb = 0;
    uint64_t seed = 0;
    if (lm_train_load_checkpoint(L->opts->resume, L->model, &L->opt, start, &nb, &seed, err))
        return err->status;
    lm_adam_ema_swap(&L->opt, &L->model->params); /* the average was in the model file */
    if (L->src->front && L->src->front->load(L->src->user, L->opts->resume, err))
        return err->status;
    int was_cpu = lm_train_checkpoint_cpu_clock(L->opts->resume);
    if (was_cpu != !strcmp(cfg->clock, "cpu"))
        return lm_err_set(err, LM_ERR_ARG, "resume %s: its training time was counted on the %s "
                          "clock, this run counts the %s clock (set --clock %s)",
                          L->opts->resume, was_cpu ? "cpu" : "wall", cfg->clock,
                          was_cpu ? "cpu" : "wall");
    if (seed != cfg->seed || nb != *start * cfg->accum_steps)
        return lm_err_set(err, LM_ERR_ARG, "resume %s: checkpoint has seed %llu and sampler "
                          "position %ld, the run expects seed %llu and position %ld",
                          L->opts->resume, (unsigned long long)seed, nb,
                          (unsigned long long)cfg->seed, *start * cfg->accum_steps);
    int ranks = lm_train_checkpoint_ranks(L->opts->resume);
    if (ranks != L->nranks)
        return lm_err_set(err, LM_ERR_ARG, "resume %s: the run was trained by %d process(es), "
                          "this run has %d; another count changes the global batch (processes x "
                          "batch) and the sample stream, so resume with %d (mpirun -np %d, or "
                          "no mpirun for 1)", L->opts->resume, ranks, L->nranks, ranks, ranks);
    if (L->rank) return LM_OK;
    /* the config this invocation runs with (its flags over the folder's) becomes the run's, so
     * that a later --resume without them goes on the same way */
    char path[LM_TRAIN_PATH_LEN + 16];
    snprintf(path, sizeof path, "%s/config.json", cfg->output);
    hold(L, 1);
    lm_status st = lm_train_cfg_save(cfg, path, err);
    hold(L, 0);
    return st ? st : open_log(L, 1, *start, err);
}


/* Time budget: at 3 % and 50 % of it (training time over all invocations), and half-way
 * through each resolved schedule while more than a tenth of the budget is left, the schedule's
 * length becomes the iterations that fit in the rest of the budget at the speed measured since
 * the previous resolution (at most cfg->iterations); config.json records it, so a rerun with
 * --iterations repeats the schedule. The iteration marks follow a machine whose speed changes
 * (a busy start, another process leaving): one early estimate would end the schedule long
 * before the budget, or cut it short. The first speed is measured from the end of this
 * invocation's first iteration (start-up, first batches and a resume's loading excluded) over
 * at least 20 iterations and 5 seconds (a tenth of the budget when that is shorter): a
 * resumed run passes the marks at once, and its first few iterations say little. */
static void resolve_budget(loop *L, long done, double *next_mark, long *end)
{
    const lm_train_cfg *cfg = L->cfg;
    double el = elapsed(L), budget = cfg->minutes * 60.0, t = train_s(L);
    if (budget <= 0) return;
    if (L->t_first == 0.0) L->t_first = t;
    double own = t - L->t_first;
    long n = done - L->it0 - 1;
    int by_it = L->next_it > 0 && done >= L->next_it;
    if ((el < *next_mark && !by_it) || n < 20 || own < fmin(5.0, 0.1 * budget)) return;
    double per_it = own / (double)n;
    if (L->it_res > 0 && done - L->it_res >= 20 && t > L->t_res)
        per_it = (t - L->t_res) / (double)(done - L->it_res);
    long fit = done + (long)((budget - el) / per_it);
    if (fit > cfg->iterations) fit = cfg->iterations;
    if (fit <= done) fit = done + (done < cfg->iterations); /* at the cap: the run ends here */
    if (el >= *next_mark) *next_mark = el < 0.5 * budget ? 0.5 * budget : INFINITY;
    L->next_it = budget - el > 0.1 * budget ? done + (fit - done) / 2 : 0;
    L->it_res = done;
    L->t_res = t;
    L->total = fit;
    L->opt.cfg.total_steps = fit;
    if (*end > fit || L->opts->stop_after <= 0) *end = fit;
    lm_train_cfg rc = *cfg;
    rc.iterations = fit;
    char path[LM_TRAIN_PATH_LEN + 16];
    snprintf(path, sizeof path, "%s/config.json", cfg->output);
    lm_err e2;
    lm_err_clear(&e2);
    hold(L, 1);
    if (!L->rank) lm_train_cfg_save(&rc, path, &e2); /* best effort: resume needs the checkpoint */
    hold(L, 0);
}

/* Snapshots: the weights at each mark of cfg->snapshots (minutes of training time), into
 * <output>/snapshots/<M>min/ (written once; a resumed run skips those on disk, and marks its
 * checkpoint had already passed: a fork, or a folder whose snapshots were removed, must not
 * get the weights of now labelled as an earlier minute). */
static lm_status snapshots(loop *L, long it, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    if (L->rank) return LM_OK; /* rank 0 writes */
    char list[sizeof cfg->snapshots], *save = NULL;
    snprintf(list, sizeof list, "%s", cfg->snapshots);
    double el = elapsed(L);
    for (char *t = strtok_r(list, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
        double mark = strtod(t, NULL);
        if (!(el >= mark * 60.0) || mark <= L->snap_done) continue;
        if (mark * 60.0 < L->seconds0) { /* passed before this invocation's checkpoint */
            L->snap_done = mark;
            continue;
        }
        char dir[LM_TRAIN_PATH_LEN + 64];
        snprintf(dir, sizeof dir, "%s/snapshots/%gmin", cfg->output, mark);
        struct stat sb;
        if (stat(dir, &sb) != 0) {
            lm_train_opts o2 = *L->opts;
            o2.elapsed = el;
            if (lm_train_make_dir(dir, err)) return err->status;
            lm_adam_ema_swap(&L->opt, &L->model->params);
            hold(L, 1);
            lm_status st = lm_train_save_checkpoint(dir, L->model, NULL, it, 0, &o2, cfg, err);
            hold(L, 0);
            lm_adam_ema_swap(&L->opt, &L->model->params);
            if (st) return st;
        }
        L->snap_done = mark;
    }
    return LM_OK;
}

/* Data-parallel ranks take every decision of rank 0's clock (the schedule's length, the end)
 * and stop together when any rank is signalled: one rank leaving the loop alone would leave
 * the others waiting in the next gradient sum. */
static void sync_control(loop *L, long *end, int *out_of_time, int *stop_now, int *signalled)
{
    long v[4] = {L->total, *end, *out_of_time, *stop_now};
    lm_dist_bcast_long(v, 4);
    L->total = v[0];
    L->opt.cfg.total_steps = v[0];
    *end = v[1], *out_of_time = (int)v[2], *stop_now = (int)v[3];
    long sig = *signalled;
    lm_dist_max_long(&sig, 1);
    *signalled = (int)sig;
}

static lm_status run_loop(loop *L, long start, lm_train_result *res, lm_err *err)
{
    const lm_train_cfg *cfg = L->cfg;
    long end = L->total;
    if (L->opts->stop_after > 0 && start + L->opts->stop_after < end)
        end = start + L->opts->stop_after;
    double budget = cfg->minutes * 60.0, mark = 0.03 * budget;
    for (long it = start; it < end; it++) {
        float lr = lm_adam_lr(&L->opt.cfg, L->opt.step);
        double loss = 0;
        lm_status st = iteration(L, it, &loss, err);
        if (st) {
            log_row(L, it + 1, loss, lr, NULL, err); /* err keeps the step's message */
            return st;
        }
        if (it == start) res->first_loss = loss;
        res->last_loss = loss;
        res->iterations_done = it + 1;
        resolve_budget(L, it + 1, &mark, &end);
        double el = elapsed(L);
        int out_of_time = budget > 0 && el >= budget;
        int stop_now = L->opts->stop_seconds > 0 && el >= L->opts->stop_seconds;
        int signalled = L->opts->interrupt ? atomic_load(L->opts->interrupt) : 0;
        if (L->nranks > 1) sync_control(L, &end, &out_of_time, &stop_now, &signalled);
        if (out_of_time || stop_now || signalled) end = it + 1;
        res->interrupted = signalled;
        int last = it + 1 == end;
        int val = (cfg->val_interval > 0 && (it + 1) % cfg->val_interval == 0) ||
                  it + 1 == L->total || out_of_time;
        if (val && L->src->eval_count && L->src->eval_count(L->src->user) > 0) {
            lm_adam_ema_swap(&L->opt, &L->model->params); /* the average is what is scored */
            st = validate(L, &res->val, err);
            lm_adam_ema_swap(&L->opt, &L->model->params);
            if (st) return st;
            res->validated = 1;
        } else {
            val = 0;
        }
        if (log_row(L, it + 1, loss, lr, val ? &res->val : NULL, err)) return err->status;
        progress(L, it + 1, loss, lr, last);
        if (snapshots(L, it + 1, err)) return err->status;
        if (((cfg->checkpoint_interval > 0 && (it + 1) % cfg->checkpoint_interval == 0) || last) &&
            !L->rank && checkpoint(L, it + 1, err))
            return err->status;
        res->budget_spent = out_of_time;
    }
    return LM_OK;
}

lm_status lm_train_run(const lm_train_cfg *cfg, lm_model *model, const lm_train_source *src,
                       const lm_train_opts *opts, lm_train_result *res, lm_err *err)
{
    lm_train_opts dflt = {0};
    lm_train_result dummy;
    if (!opts) opts = &dflt;
    if (!res) res = &dummy;
    memset(res, 0, sizeof *res);
    if (lm_train_cfg_validate(cfg, err)) return err->status;
    if (!lm_model_has(model, LM_CAP_RGB_INPUT) && /* the coded frame: whole tiles */
        (cfg->patch_h % model->mosaic.ty || cfg->patch_w % model->mosaic.tx))
        return lm_err_set(err, LM_ERR_ARG, "config: field 'patch': %dx%d is not a multiple of the "
                          "%d x %d tile", cfg->patch_h, cfg->patch_w, model->mosaic.ty,
                          model->mosaic.tx);
    loop L = {.cfg = cfg, .opts = opts, .src = src, .model = model, .total = cfg->iterations,
              .rank = opts->data_parallel ? lm_dist_rank() : 0,
              .nranks = opts->data_parallel ? lm_dist_size() : 1};
    L.tty = isatty(fileno(opts->progress_out ? opts->progress_out : stderr));
    long start = 0;
    lm_status st = setup(&L, err);
    /* the clock first: begin() writes a fresh run's iteration-0 checkpoint, with its seconds */
    L.seconds0 = opts->resume ? lm_train_checkpoint_seconds(opts->resume) : 0.0;
    L.cpu_clock = !strcmp(cfg->clock, "cpu");
    L.t0 = L.last_print = now_s();
    L.t_train0 = train_s(&L);
    if (!st) st = begin(&L, &start, err);
    res->iterations_done = start;
    L.it0 = start;
    L.saved = opts->resume ? start : -1;
    if (!st) st = run_loop(&L, start, res, err);
    res->seconds = train_s(&L) - L.t_train0;
    if (L.opt.ema && !st) /* the caller's model: the average, as model.safetensors holds it */
        lm_adam_ema_swap(&L.opt, &L.model->params);
    teardown(&L);
    /* a fresh run that failed before its first iteration completed leaves no run folder (a
     * restarted one its config) */
    if (st && !L.rank && !opts->resume && L.saved <= 0 && res->iterations_done == 0) {
        if (opts->restart) lm_train_discard_checkpoint(cfg->output);
        else lm_train_discard_dir(cfg->output, L.made);
    }
    return st;
}
