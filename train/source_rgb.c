/* source_rgb.c — training batches for the passive RGB baseline (MST++): the coded dataset's
 * own samples (same scenes, split, tile-aligned patch positions, flips, synthetic share and
 * per-sample noise level k, all drawn by data/dataset.c), with the input replaced by the RGB
 * camera image of the sample's 400..700 nm bands (channels 1..31 of its 33-channel target,
 * data/rgbcam.h). The coded frame the dataset also simulates is discarded.
 * Difference from the coded pipeline, by necessity: the noise *realisation* is drawn here (from
 * (seed, split, sample index)), on the RGB image, with the dataset's k for that sample (sigma
 * = k x the largest clean RGB value of the patch); the other noise options (Poisson, clipping,
 * quantisation) are this source's own. Deterministic: batch `index` is a pure function of
 * (seed, index), like the dataset's.
 * The QDO baseline (lm_train_source_qdo_open) is the same source with the RGB camera behind a
 * DOE (data/qdocam.h: each band convolved with its PSF before the RGB integration).
 * What it is not: the dataset (data/dataset.h) or the camera models (data/rgbcam.h,
 * data/qdocam.h). */
#include "train/train.h"
#include "data/dataset.h"
#include "data/qdocam.h"
#include "data/rgbcam.h"
#include "data/spectra.h"
#include <stdlib.h>
#include <string.h>

typedef struct rgb_src {
    lm_dataset *d;
    lm_rgbcam cam;
    lm_qdocam *qdo;        /* NULL: the plain RGB camera */
    lm_noise_opts noise;
    int ph, pw;
    uint64_t seed;
    float *coded;          /* discarded coded frames, B x ph x pw */
    int coded_cap;         /* batch items it holds */
} rgb_src;

/* RGB of one 33-channel target sample with the noise of sample `i` of `split`. */
static lm_status to_rgb(rgb_src *s, lm_data_split split, long i, const float *target,
                        float *rgb, lm_err *err)
{
    lm_dataset_sample_info info;
    if (lm_dataset_sample_info_get(s->d, split, i, &info, err)) return err->status;
    lm_noise_opts no = s->noise;
    no.gauss_k = info.noise_k;
    if (info.clean) no.photons = 0.0, no.read_noise = 0.0f;
    lm_rng base, r;
    lm_rng_seed(&base, s->seed ^ 0x5267622d63616dULL); /* "Rgb-cam" */
    r = lm_rng_split(&base, (uint64_t)split << 48 ^ (uint64_t)i);
    size_t plane = (size_t)s->ph * s->pw;
    if (s->qdo) return lm_qdocam_simulate(s->qdo, target + plane, s->ph, s->pw, &no, &r, rgb, 1,
                                          err);
    return lm_rgbcam_simulate(&s->cam, target + plane, s->ph, s->pw, &no, &r, rgb, 1, err);
}

static lm_status rgb_batch(void *u, long index, int B, float *raw, float *target, lm_err *err)
{
    rgb_src *s = u;
    if (B > s->coded_cap) {
        float *p = realloc(s->coded, (size_t)B * s->ph * s->pw * sizeof(float));
        if (!p) return lm_err_set(err, LM_ERR_NOMEM, "rgb source: out of memory");
        s->coded = p, s->coded_cap = B;
    }
    if (lm_dataset_batch(s->d, index, B, s->coded, target, err)) return err->status;
    size_t plane = (size_t)s->ph * s->pw;
    for (int j = 0; j < B; j++)
        if (to_rgb(s, LM_SPLIT_TRAIN, index * B + j, target + j * LM_TARGET_CHANNELS * plane,
                   raw + j * 3 * plane, err))
            return err->status;
    return LM_OK;
}

static int rgb_count(void *u) { return lm_dataset_eval_count(((rgb_src *)u)->d, LM_SPLIT_VAL); }

static lm_status rgb_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    rgb_src *s = u;
    if (s->coded_cap < 1) {
        s->coded = malloc((size_t)s->ph * s->pw * sizeof(float));
        if (!s->coded) return lm_err_set(err, LM_ERR_NOMEM, "rgb source: out of memory");
        s->coded_cap = 1;
    }
    if (lm_dataset_eval_sample(s->d, LM_SPLIT_VAL, i, s->coded, target, err)) return err->status;
    return to_rgb(s, LM_SPLIT_VAL, i, target, raw, err);
}

lm_status lm_train_source_rgb_open(lm_train_source *src, lm_dataset *d, const char *camera_csv,
                                   int illum, const lm_noise_opts *noise, int patch_h,
                                   int patch_w, uint64_t seed, lm_err *err)
{
    memset(src, 0, sizeof *src);
    if (!d || patch_h < 1 || patch_w < 1)
        return lm_err_set(err, LM_ERR_ARG, "rgb source: needs a dataset and a patch size");
    rgb_src *s = calloc(1, sizeof *s);
    if (!s) return lm_err_set(err, LM_ERR_NOMEM, "rgb source: out of memory");
    if (lm_rgbcam_load(&s->cam, camera_csv, (lm_rgbcam_illum)illum, err)) {
        free(s);
        return err->status;
    }
    s->d = d, s->ph = patch_h, s->pw = patch_w, s->seed = seed;
    if (noise) s->noise = *noise;
    *src = (lm_train_source){s, rgb_batch, rgb_count, rgb_eval, NULL};
    return LM_OK;
}

lm_status lm_train_source_qdo_open(lm_train_source *src, lm_dataset *d, const char *doe_path,
                                   const lm_noise_opts *noise, int patch_h, int patch_w,
                                   uint64_t seed, lm_err *err)
{
    lm_status st = lm_train_source_rgb_open(src, d, NULL, LM_RGBCAM_D65, noise, patch_h, patch_w,
                                            seed, err);
    if (st) return st;
    rgb_src *s = src->user;
    lm_doe doe;
    s->qdo = calloc(1, sizeof *s->qdo);
    if (!s->qdo) st = lm_err_set(err, LM_ERR_NOMEM, "qdo source: out of memory");
    if (!st) st = doe_path ? lm_doe_load(doe_path, &doe, err) : lm_doe_default(&doe, err);
    if (!st) {
        st = lm_qdocam_init(s->qdo, &doe, LM_RGBCAM_D65, err);
        lm_doe_free(&doe);
    }
    if (st) lm_train_source_rgb_close(src);
    return st;
}

void lm_train_source_rgb_close(lm_train_source *src)
{
    rgb_src *s = src ? src->user : NULL;
    if (s) {
        free(s->coded);
        if (s->qdo) lm_qdocam_free(s->qdo);
        free(s->qdo);
    }
    free(s);
    if (src) memset(src, 0, sizeof *src);
}
