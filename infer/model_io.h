/* model_io.h — a trained model for inference: from a training run folder (its
 * model.safetensors) or a .safetensors file written by the trainer (train/train.h).
 * What it is: read the metadata "preset" (required) and "system" / "system_hash" (the system
 * description the model was trained for; "" = the bundled default), load that system (or an
 * override), derive the network front (lm_mosaic_from_system), create the model and load its
 * weights (shapes must match), trainable parameters switched to no-grad. A QDO-baseline model
 * (LM_CAP_QDO_OPTICS) also gets its camera (the bundled DOE's PSFs, computed once here) for
 * eval's simulations.
 * What it is not: checkpoint resume (train/checkpoint.c) or the inference loop (infer/tile.h). */
#ifndef LM_MODEL_IO_H
#define LM_MODEL_IO_H
#include "data/qdocam.h"
#include "data/system.h"
#include "infer/auto.h"
#include "infer/raw.h"
#include "models/model.h"

typedef struct lm_infer_model {
    lm_model *model;
    lm_system sys;        /* the system description the model runs with */
    char weights[1024];   /* the .safetensors file loaded */
    char system_path[1024];
    lm_gain_remap remap;  /* frames of sys's gains to the model's (remap.active 0: none) */
    char model_system[1024]; /* with a remap: the system file the model was trained with */
    char *train_scenes;   /* content hashes of its training scenes ("train_scenes" metadata,
                           * data/dataset.h); NULL when the file records none */
    double clipped;       /* the share of its noisy training samples that were clipped to
                           * [0, 1] ("clipped" metadata); -1 when the file records none */
    int noise_oracle;     /* eval only: give noise-reading models the simulated level */
    int sensor_clip, sensor_bits; /* eval only: simulated frames clipped to [0, 1] / quantised
                                   * after the noise, as a 16-bit PNG holds them */
    double photons;       /* eval only: shot noise (photo-electrons at full scale, 0 = off) */
    float read_noise;     /* eval only: read noise (electrons with photons; 0 = off) */
    lm_qdocam *qdo;       /* LM_CAP_QDO_OPTICS models: the camera (NULL: eval builds one) */
    /* eval only, with a calibration (`eval --model auto --auto FILE`): each frame reconstructed
     * by the calibrated choice (lm_auto_run) among auto_cal's models auto_models[0..n)
     * (auto_models[0] = model); auto_cal NULL: none */
    const lm_auto_calib *auto_cal;
    const int *auto_choice;
    lm_model *auto_models[LM_AUTO_MAX_MODELS];
} lm_infer_model;

/* The bundled models (models/demo/ of the source tree, or LM_MODELS_DIR when set): the best
 * single-bucket model (buckets 1) and the two-bucket one (buckets 2), the models `infer --model
 * auto` picks from when no calibration is given. Into out (n bytes); LM_ERR_IO naming the file
 * when it is missing. */
#define LM_BUNDLED_MODEL_1 "tn160nc-lmmse.safetensors"
#define LM_BUNDLED_MODEL_2 "tn96nc-b2-lmmseb2.safetensors"
lm_status lm_infer_bundled_model(int buckets, char *out, size_t n, lm_err *err);

/* Load path (a folder holding model.safetensors, or a .safetensors file). system_override
 * (NULL or "" = the one recorded in the file) replaces the recorded system; the recorded file's
 * FNV-1a hash must equal the recorded system_hash when one is recorded. An override of another
 * hash is the camera the frames come from: when it differs from the recorded system (found
 * here by its path or as the bundled default) only in LED gains or allocations, im->sys is the
 * override, the network keeps the recorded system's front and im->remap rescales each tile
 * phase of every frame to the recorded gains (lm_gain_remap_init; callers apply it with
 * lm_gain_remap_frame); otherwise it is refused.
 * Errors (*im zeroed, message names the file): LM_ERR_IO (missing model or system file),
 * LM_ERR_FORMAT (not a Lumosaic model: no preset, bad weights), LM_ERR_ARG ("model/system
 * mismatch": the system cannot be mapped onto the one the model was trained for, with the
 * reason, or its tile does not fit the model's weights), others from the model / parameter loaders. */
lm_status lm_infer_model_load(const char *path, const char *system_override, lm_infer_model *im,
                              lm_err *err);
void lm_infer_model_free(lm_infer_model *im);
/* A model written elsewhere keeps its system: `recorded` (a model's "system" metadata, relative
 * to the folder of its weights file `weights`) as a path relative to out_path's folder, into out
 * (n bytes). "" (the bundled default) stays ""; an absolute or unresolvable path is kept. */
void lm_infer_system_relative(const char *weights, const char *recorded, const char *out_path,
                              char *out, size_t n);
/* The QDO baseline's camera, D65: the DOE of the run whose weights file is `weights` (its
 * folder's doe.json, written by every QDO training run, e.g. a learned height map), else (no
 * such file, or weights NULL) the bundled DOE (data/systems/qdo_default.json); *out freed
 * with lm_qdocam_free + free. */
lm_status lm_infer_qdocam(const char *weights, lm_qdocam **out, lm_err *err);

/* A `lumosaic fit-auto` calibration and its models, as `infer --model auto --auto FILE` and
 * `eval --auto FILE` run them: the file (lm_auto_load) into *a, model 0 into *im0 and model m
 * >= 1 into more[m] (system_override as lm_infer_model_load), models[m] their networks. Every
 * model must be one-bucket, one-frame, of model 0's tile with 33 outputs, its frames not
 * rescaled (no gain remap). Errors name the file and the model. */
lm_status lm_infer_auto_load(const char *file, const char *system_override, lm_auto_calib *a,
                             lm_infer_model *im0, lm_infer_model *more, lm_model **models,
                             lm_err *err);

/* For a model that reads its input's noise level (m->noise_input): set m->noise_sigma for this
 * frame (height x width raw mosaic), from m->noise_given (k x the frame's maximum) when >= 0,
 * else estimated from the frame itself (data/noise_est.h). No-op for other models. Called by
 * every frame-level inference entry (tile, whole, auto). */
void lm_infer_set_noise(lm_model *m, const float *frame, int height, int width);

#endif
