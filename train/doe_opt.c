/* doe_opt.c — the QDO baseline's training source with the camera on the tape
 * (lm_train_source_doe_open): the dataset's samples cropped larger than the training patch,
 * each band convolved with the DOE's PSFs by tensor ops (data/qdocam_t.c), RGB, noise, and,
 * when optimising, the DOE's height map trained jointly with the network (QDO, Li et al.,
 * CVPR 2022: end-to-end optimisation of a quantised DOE).
 * Context: the dataset draws patches of (ph + 2 py) x (pw + 2 px) (py, px >= r, the PSF radius,
 * rounded up so the size stays on the mosaic's tile); the camera sees the (ph + 2r) x (pw + 2r)
 * window around the training patch, so every output pixel is blurred from real scene pixels
 * (no border padding inside training patches); targets are cropped to ph x pw.
 * Optimisation, per update:
 *  - t (m x m, heights as fractions of max_height, "doe.height") is wrapped into [0, 1) and
 *    quantised to the DOE's levels in the forward pass with a straight-through estimator: the
 *    quantised map is t + const(q(t) - t), so the gradient reaches t unchanged. "progressive"
 *    blends in the quantisation, t + a const(q(t) - t) with a rising linearly from 0 to 1 over
 *    the first half of the updates (continuous optics first, the fabricable DOE by the end;
 *    our simple form of QDO's progressive quantisation); "ste": a = 1 throughout; "none": no
 *    quantisation in training (the exported DOE is still quantised to the levels).
 *  - PSFs with gradient for `bands` wavelengths per update (a rotating subset: update u takes
 *    bands u k .. u k + k - 1 mod 31); the other bands use the PSFs of their last computation
 *    (a cache, refreshed in full before every validation). 31 PSFs with gradient at the
 *    default grid cost 3.4-7 s per update on one thread (bench_doe_psf, by machine load);
 *    4 cost 0.43 s.
 *  - Adam (own learning rate, constant) on t after the network's update.
 * Validation, the checkpoint's doe.json and eval use the fully quantised DOE. The noise: the
 * dataset's k of each sample, realised as source_rgb.c does (sigma = k x the largest clean RGB
 * value), added as a constant (no gradient through the noise's scale).
 * What it is not: the PSF (data/doe_psf.c) or the camera maths (data/qdocam_t.c). */
#include "train/train.h"
#include "autograd/autograd.h"
#include "data/doe.h"
#include "data/qdocam.h"
#include "data/spectra.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NB LM_RGBCAM_BANDS

typedef struct doe_src {
    lm_dataset *d;
    lm_train_doe_opts o;
    lm_doe doe;
    lm_rgbcam cam;
    lm_qdocam qdo;            /* the current quantised DOE's PSFs (validation) */
    int ph, pw, py, px, Hd, Wd, r, S;
    uint64_t seed;
    lm_params P;              /* "doe.height": m x m fractions of max_height */
    lm_tensor *t;
    lm_adam opt;
    long step;                /* DOE updates done */
    float *psf;               /* 31 x S x S: the PSF cache */
    float *dtgt, *dcoded, *cube, *clean;
    float *k;                 /* per item of the last batch: noise level */
    long first;               /* training sample index of the last batch's item 0 */
    int cap, lastB;
    lm_train_front front;
} doe_src;

/* The quantised fraction of one height (lm_doe_quantise). */
static float quant(float v, int levels) { return (float)lm_doe_quantise(v, levels); }

/* The height map the optics see on the tape: wrapped, and quantised with weight a. */
static lm_tensor *height_on_tape(doe_src *s, lm_ctx *c, float a)
{
    long n = lm_tensor_numel(s->t);
    lm_tensor *d = lm_tensor_new2(c, s->doe.m, s->doe.m);
    if (!d) return NULL;
    for (long i = 0; i < n; i++) {
        float v = s->t->data[i], w = v - floorf(v);
        d->data[i] = (w - v) + a * (quant(v, s->doe.levels) - w);
    }
    return lm_add(c, s->t, d);
}

static float quant_weight(const doe_src *s)
{
    if (!strcmp(s->o.quantise, "none")) return 0.0f;
    if (!strcmp(s->o.quantise, "ste") || s->o.total < 2) return 1.0f;
    float a = (float)s->step / (0.5f * (float)s->o.total);
    return a < 1.0f ? a : 1.0f;
}

/* doe.height <- the quantised t; all 31 PSFs into the cache and the validation camera. */
static lm_status refresh(void *u, lm_err *err)
{
    doe_src *s = u;
    long n = (long)s->doe.m * s->doe.m;
    for (long i = 0; i < n; i++)
        s->doe.height[i] = s->doe.mask[i] ? quant(s->t->data[i], s->doe.levels) *
                                                (float)s->doe.max_height_m : 0.0f;
    lm_qdocam_free(&s->qdo);
    lm_status st = lm_qdocam_init(&s->qdo, &s->doe, LM_RGBCAM_D65, err);
    if (!st) memcpy(s->psf, s->qdo.psf, (size_t)NB * s->S * s->S * sizeof(float));
    return st;
}

static lm_status grow(doe_src *s, int B, lm_err *err)
{
    if (B <= s->cap) return LM_OK;
    size_t dp = (size_t)s->Hd * s->Wd, cp = (size_t)(s->ph + 2 * s->r) * (s->pw + 2 * s->r);
    float *a = realloc(s->dtgt, (size_t)B * LM_TARGET_CHANNELS * dp * sizeof(float));
    if (a) s->dtgt = a;
    float *b = realloc(s->dcoded, (size_t)B * dp * sizeof(float));
    if (b) s->dcoded = b;
    float *c = realloc(s->cube, (size_t)B * NB * cp * sizeof(float));
    if (c) s->cube = c;
    float *k = realloc(s->k, (size_t)B * sizeof(float));
    if (k) s->k = k;
    float *cl = realloc(s->clean, (size_t)B * 3 * dp * sizeof(float));
    if (cl) s->clean = cl;
    if (!a || !b || !c || !k || !cl) return lm_err_set(err, LM_ERR_NOMEM, "doe source: out of memory");
    s->cap = B;
    return LM_OK;
}

/* Rows [y0, y0 + h) x [x0, x0 + w) of channels c0.. c0 + nc of one item (C x Hd x Wd) into dst. */
static void crop(const doe_src *s, const float *src, int c0, int nc, int y0, int x0, int h,
                 int w, float *dst)
{
    for (int ch = 0; ch < nc; ch++)
        for (int y = 0; y < h; y++)
            memcpy(dst + ((size_t)ch * h + y) * w,
                   src + ((size_t)(c0 + ch) * s->Hd + y0 + y) * s->Wd + x0,
                   (size_t)w * sizeof(float));
}

static lm_rng noise_rng(const doe_src *s, lm_data_split split, long i)
{
    lm_rng base;
    lm_rng_seed(&base, s->seed ^ 0x5267622d63616dULL); /* as source_rgb.c */
    return lm_rng_split(&base, (uint64_t)split << 48 ^ (uint64_t)i);
}

static lm_status doe_batch(void *u, long index, int B, float *raw, float *target, lm_err *err)
{
    (void)raw; /* the model's input is made on the tape (front.input) */
    doe_src *s = u;
    if (grow(s, B, err) || lm_dataset_batch(s->d, index, B, s->dcoded, s->dtgt, err))
        return err->status;
    size_t dp = (size_t)s->Hd * s->Wd, cp = (size_t)(s->ph + 2 * s->r) * (s->pw + 2 * s->r);
    for (int j = 0; j < B; j++) {
        const float *it = s->dtgt + (size_t)j * LM_TARGET_CHANNELS * dp;
        crop(s, it, 0, LM_TARGET_CHANNELS, s->py, s->px, s->ph, s->pw,
             target + (size_t)j * LM_TARGET_CHANNELS * s->ph * s->pw);
        crop(s, it, 1, NB, s->py - s->r, s->px - s->r, s->ph + 2 * s->r, s->pw + 2 * s->r,
             s->cube + (size_t)j * NB * cp);
        lm_dataset_sample_info info;
        if (lm_dataset_sample_info_get(s->d, LM_SPLIT_TRAIN, index * B + j, &info, err))
            return err->status;
        s->k[j] = info.noise_k;
    }
    s->first = index * B, s->lastB = B;
    return LM_OK;
}

static lm_tensor *doe_input(void *u, lm_ctx *c, int B)
{
    doe_src *s = u;
    if (B != s->lastB) {
        lm_ctx_fail(c, LM_ERR_ARG, "doe source: input of %d items after a batch of %d", B,
                    s->lastB);
        return NULL;
    }
    const int S = s->S;
    lm_tensor *psf = NULL;
    if (s->o.optimise) {
        int kb = s->o.bands, band[NB], pos[NB];
        double lam[NB];
        for (int b = 0; b < NB; b++) pos[b] = -1;
        for (int j = 0; j < kb; j++) {
            band[j] = (int)((s->step * kb + j) % NB);
            pos[band[j]] = j;
            lam[j] = (LM_GRID31_START + LM_GRID41_STEP * band[j]) * 1e-9;
        }
        lm_tensor *P = lm_doe_psf_t(c, &s->doe, height_on_tape(s, c, quant_weight(s)), lam, kb);
        if (!P) return NULL;
        for (int j = 0; j < kb; j++) /* the cache follows */
            memcpy(s->psf + (size_t)band[j] * S * S, P->data + (size_t)j * S * S,
                   (size_t)S * S * sizeof(float));
        lm_tensor *parts[NB];
        for (int b = 0; b < NB; b++)
            parts[b] = pos[b] >= 0 ? lm_slice(c, P, 0, pos[b], 1)
                                   : lm_tensor_from(c, 3, (int[]){1, S, S},
                                                    s->psf + (size_t)b * S * S);
        psf = lm_concat(c, parts, NB, 0);
    } else {
        psf = lm_tensor_from(c, 3, (int[]){NB, S, S}, s->psf);
    }
    lm_tensor *rgb = lm_qdocam_render_t(c, &s->cam, psf, s->cube, B, s->ph + 2 * s->r,
                                        s->pw + 2 * s->r);
    if (!rgb) return NULL;
    /* the noise, realised on the clean image as source_rgb.c does, added as a constant */
    size_t pl = (size_t)3 * s->ph * s->pw;
    lm_tensor *nz = lm_tensor_new4(c, B, 3, s->ph, s->pw);
    if (!nz) return NULL;
    memcpy(s->clean, rgb->data, (size_t)B * pl * sizeof(float));
    for (int j = 0; j < B; j++) {
        lm_noise_opts no = {0};
        no.gauss_k = s->k[j];
        lm_rng r = noise_rng(s, LM_SPLIT_TRAIN, s->first + j);
        lm_err e = {0};
        if (lm_forward_noise(s->clean + j * pl, 3 * s->ph, s->pw, &no, &r, 1, &e)) {
            lm_ctx_fail(c, e.status, "doe source: %s", e.msg);
            return NULL;
        }
        for (size_t i = 0; i < pl; i++) nz->data[j * pl + i] = s->clean[j * pl + i] -
                                                               rgb->data[j * pl + i];
    }
    return lm_add(c, rgb, nz);
}

static void doe_zero_grad(void *u) { lm_params_zero_grad(&((doe_src *)u)->P); }

static lm_status doe_step(void *u, lm_err *err)
{
    doe_src *s = u;
    if (!s->o.optimise) return LM_OK;
    const lm_param *e = s->P.items[0];
    long n = lm_tensor_numel(&e->t);
    for (long i = 0; i < n; i++)
        if (!isfinite(e->g.data[i]))
            return lm_err_set(err, LM_ERR_NUMERIC, "doe: the height map's gradient is not finite "
                              "at update %ld", s->step + 1);
    lm_adam_step(&s->opt, &s->P, 1);
    s->step++;
    return LM_OK;
}

static int doe_count(void *u) { return lm_dataset_eval_count(((doe_src *)u)->d, LM_SPLIT_VAL); }

/* A validation sample: the dataset's larger patch through the current DOE (edge padding at its
 * own border, as eval on whole images), noise of that sample, both cropped to the patch. */
static lm_status doe_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    doe_src *s = u;
    if (grow(s, 1, err)) return err->status;
    if (lm_dataset_eval_sample(s->d, LM_SPLIT_VAL, i, s->dcoded, s->dtgt, err)) return err->status;
    lm_dataset_sample_info info;
    if (lm_dataset_sample_info_get(s->d, LM_SPLIT_VAL, i, &info, err)) return err->status;
    size_t dp = (size_t)s->Hd * s->Wd;
    lm_noise_opts no = {0};
    no.gauss_k = info.noise_k;
    lm_rng r = noise_rng(s, LM_SPLIT_VAL, i);
    if (lm_qdocam_simulate(&s->qdo, s->dtgt + dp, s->Hd, s->Wd, &no, &r, s->clean, 1, err))
        return err->status;
    for (int ch = 0; ch < 3; ch++)
        for (int y = 0; y < s->ph; y++)
            memcpy(raw + ((size_t)ch * s->ph + y) * s->pw,
                   s->clean + ((size_t)ch * s->Hd + s->py + y) * s->Wd + s->px,
                   (size_t)s->pw * sizeof(float));
    crop(s, s->dtgt, 0, LM_TARGET_CHANNELS, s->py, s->px, s->ph, s->pw, target);
    return LM_OK;
}

/* The checkpoint's DOE: doe.json + doe_heights.png (the quantised map), and the optimiser's
 * state doe_state.safetensors (t and Adam's moments, step in the metadata). */
static lm_status doe_save(void *u, const char *dir, lm_err *err)
{
    doe_src *s = u;
    char path[LM_TRAIN_PATH_LEN + 32];
    lm_status st = refresh(s, err);
    snprintf(path, sizeof path, "%s/doe.json", dir);
    if (!st) st = lm_doe_save(&s->doe, path, "doe_heights.png", err);
    if (st || !s->o.optimise) return st;
    lm_params v;
    lm_params_init(&v);
    int m = s->doe.m;
    const char *names[3] = {"height", "exp_avg", "exp_avg_sq"};
    const float *src[3] = {s->t->data, s->opt.m, s->opt.v};
    lm_tensor *ts[3];
    for (int i = 0; i < 3 && !st; i++)
        if (!(ts[i] = lm_params_add(&v, names[i], 2, (int[]){m, m}, 0, err))) st = err->status;
    if (!st) st = lm_params_finalize(&v, err);
    for (int i = 0; i < 3 && !st; i++)
        memcpy(ts[i]->data, src[i], (size_t)m * m * sizeof(float));
    char stp[32];
    snprintf(stp, sizeof stp, "%ld", s->step);
    const char *meta[2] = {"doe_step", stp};
    snprintf(path, sizeof path, "%s/doe_state.safetensors", dir);
    if (!st) st = lm_params_save(&v, path, meta, 1, err);
    lm_params_free(&v);
    return st;
}

static lm_status doe_load(void *u, const char *dir, lm_err *err)
{
    doe_src *s = u;
    if (!s->o.optimise) return LM_OK;
    char path[LM_TRAIN_PATH_LEN + 32];
    snprintf(path, sizeof path, "%s/doe_state.safetensors", dir);
    lm_params v;
    lm_params_init(&v);
    int m = s->doe.m;
    const char *names[3] = {"height", "exp_avg", "exp_avg_sq"};
    float *dst[3] = {s->t->data, s->opt.m, s->opt.v};
    lm_tensor *ts[3];
    lm_status st = LM_OK;
    for (int i = 0; i < 3 && !st; i++)
        if (!(ts[i] = lm_params_add(&v, names[i], 2, (int[]){m, m}, 0, err))) st = err->status;
    if (!st) st = lm_params_finalize(&v, err);
    if (!st) st = lm_params_load(&v, path, 0, err);
    for (int i = 0; i < 3 && !st; i++)
        memcpy(dst[i], ts[i]->data, (size_t)m * m * sizeof(float));
    char *stp = st ? NULL : lm_safetensors_meta(path, "doe_step", err);
    if (!st && !stp) st = lm_err_set(err, LM_ERR_FORMAT, "%s: no doe_step", path);
    if (stp) s->step = s->opt.step = atol(stp);
    free(stp);
    lm_params_free(&v);
    return st ? st : refresh(s, err);
}

void lm_train_source_doe_close(lm_train_source *src)
{
    doe_src *s = src ? src->user : NULL;
    if (s) {
        lm_doe_free(&s->doe);
        lm_qdocam_free(&s->qdo);
        lm_params_free(&s->P);
        lm_adam_free(&s->opt);
        free(s->psf), free(s->dtgt), free(s->dcoded), free(s->cube), free(s->clean), free(s->k);
    }
    free(s);
    if (src) memset(src, 0, sizeof *src);
}

int lm_train_doe_pad(const char *doe_path, int ty, int tx, int *py, int *px, lm_err *err)
{
    lm_doe doe;
    if (doe_path && doe_path[0] && strcmp(doe_path, "default") ? lm_doe_load(doe_path, &doe, err)
                                                                : lm_doe_default(&doe, err))
        return err->status;
    int r = doe.psf_size / 2;
    lm_doe_free(&doe);
    /* 2 p a multiple of the tile: the dataset's patch stays on it */
    *py = r, *px = r;
    while ((2 * *py) % ty) (*py)++;
    while ((2 * *px) % tx) (*px)++;
    return LM_OK;
}

lm_status lm_train_source_doe_open(lm_train_source *src, lm_dataset *d,
                                   const lm_train_doe_opts *o, int patch_h, int patch_w,
                                   int pad_y, int pad_x, uint64_t seed, lm_err *err)
{
    memset(src, 0, sizeof *src);
    doe_src *s = calloc(1, sizeof *s);
    if (!s) return lm_err_set(err, LM_ERR_NOMEM, "doe source: out of memory");
    s->d = d, s->o = *o, s->ph = patch_h, s->pw = patch_w, s->py = pad_y, s->px = pad_x;
    s->Hd = patch_h + 2 * pad_y, s->Wd = patch_w + 2 * pad_x, s->seed = seed;
    lm_params_init(&s->P);
    src->user = s;
    lm_status st = o->file[0] && strcmp(o->file, "default") ? lm_doe_load(o->file, &s->doe, err)
                                                             : lm_doe_default(&s->doe, err);
    if (!st) st = lm_rgbcam_load(&s->cam, NULL, LM_RGBCAM_D65, err);
    if (!st) {
        s->S = s->doe.psf_size, s->r = s->S / 2;
        if (pad_y < s->r || pad_x < s->r)
            st = lm_err_set(err, LM_ERR_ARG, "doe source: context %d x %d below the PSF radius %d",
                            pad_y, pad_x, s->r);
    }
    if (!st && !(s->psf = malloc((size_t)NB * s->S * s->S * sizeof(float))))
        st = lm_err_set(err, LM_ERR_NOMEM, "doe source: out of memory");
    if (!st && !(s->t = lm_params_add(&s->P, "doe.height", 2, (int[]){s->doe.m, s->doe.m}, 1,
                                      err)))
        st = err->status;
    if (!st) st = lm_params_finalize(&s->P, err);
    if (!st) {
        for (long i = 0; i < (long)s->doe.m * s->doe.m; i++)
            s->t->data[i] = (float)(s->doe.height[i] / s->doe.max_height_m);
        lm_adam_cfg ac;
        lm_adam_default_cfg(&ac);
        ac.lr = o->lr;
        st = lm_adam_init(&s->opt, &s->P, &ac, err);
    }
    if (!st) st = refresh(s, err);
    if (st) {
        lm_train_source_doe_close(src);
        return st;
    }
    s->front = (lm_train_front){doe_input, doe_zero_grad, doe_step, refresh, doe_save, doe_load};
    src->batch = doe_batch;
    src->eval_count = doe_count;
    src->eval_sample = doe_eval;
    src->front = &s->front;
    return LM_OK;
}
