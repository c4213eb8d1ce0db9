/* train.h — training runs: the run configuration (JSON, versioned, validated; every field also
 * settable by a CLI flag) and the training loop (Adam + L1 on all 33 channels, gradient
 * accumulation, validation metrics, CSV log, progress, checkpoints and exact resume).
 *
 * Output folder of a run:
 *   config.json               the resolved configuration (written at the start)
 *   model.safetensors         weights; tensor names = the model's PyTorch-style names;
 *                             metadata: format, preset, system (path and FNV-1a hash of its
 *                             file), iteration
 *   optimizer.safetensors     Adam state: "exp_avg.<param>", "exp_avg_sq.<param>"; metadata:
 *                             step, iteration, next_batch (the sampler position: batches are
 *                             a pure function of (seed, index)), seed, threads
 *   log.csv                   iteration,loss,lr,psnr,ssim,mae,sam (metrics only at validation)
 * Both checkpoint files are written atomically (temp file + rename), optimizer first; resume
 * checks that they name the same iteration. Resuming with the same thread count reproduces an
 * uninterrupted run bit for bit (every kernel is deterministic for a given thread count and
 * batches are a pure function of (seed, batch index)).
 *
 * What it is not: the data pipeline (data/dataset.h), the optimizer (train/adam.h), or the
 * models (models/model.h). */
#ifndef LM_TRAIN_H
#define LM_TRAIN_H
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include "models/model.h"
#include "train/adam.h"
#include "data/metrics.h"
#include "data/dataset.h"
#include "data/forward.h"

#define LM_TRAIN_CFG_VERSION 1
#define LM_TRAIN_MAX_PATHS 64
#define LM_TRAIN_PATH_LEN 512

typedef struct lm_train_cfg {
    int version;
    char model[64];                 /* preset name */
    char system[LM_TRAIN_PATH_LEN]; /* system description file; "" = bundled default */
    char data[LM_TRAIN_MAX_PATHS][LM_TRAIN_PATH_LEN];
    int ndata;
    float synth_fraction;           /* share of the paper's synthetic samples: textureless
                                     * narrowband patches (paper 0.33) */
    float procedural_fraction;      /* share of procedural scenes (not in the paper); -1 (the
                                     * default): lm_train_procedural_share */
    float motion_fraction;          /* share of real-scene samples seen moving (0) */
    float motion_speed;             /* their translation speed: uniform in [0, this] px/s (240) */
    float motion_rotation;          /* their rotation: uniform in [-this, this] deg/s (0) */
    int motion_samples;             /* instants per LED window (2) */
    int patch_h, patch_w;           /* 66 x 64 */
    int batch, accum_steps;         /* 14, 2 */
    long iterations;                /* optimizer updates (paper 50,000) */
    float lr, lr_min, weight_decay; /* 1e-4, 0, 0 */
    float ema;                      /* moving average of the weights: decay (0 = none); the
                                     * average is validated, snapshotted and is the checkpoint's
                                     * model, the weights being trained ride in the optimizer
                                     * file */
    char schedule[16];              /* constant | cosine | step */
    long warmup, step_every;
    float step_gamma;
    float noise_min, noise_max;     /* Gaussian noise k ~ U[min, max] (0, 0.15) */
    float val_noise;
    uint64_t seed;
    int threads;                    /* 0 = all cores */
    char device[16];                /* cpu | opencl: where forward/backward run (Adam, data
                                     * and metrics stay on the host); default $LM_DEVICE, else
                                     * cpu. Resume is exact only on the same device. */
    int workers;                    /* data preparation threads */
    long val_interval;              /* iterations between validations (0 = only at the end) */
    int val_patches;                /* fixed validation samples */
    long checkpoint_interval;       /* iterations between checkpoints (0 = only at the end) */
    long log_interval;              /* progress lines when stderr is not a tty */
    char output[LM_TRAIN_PATH_LEN]; /* run folder */
    /* closed-form models (lmmse): "auto" = closed form for lmmse presets, SGD otherwise;
     * "closed"; "sgd" (Adam from the default initialisation) */
    char fit[16];
    long fit_patches;               /* closed form: training patches accumulated (4096) */
    float fit_synth;                /* closed form: synthetic share of the statistics (-1: chosen
                                     * on the validation split) */
    char base[LM_TRAIN_PATH_LEN];   /* residual on this trained run's model ("" = none) */
    int base_trainable;             /* 1: the base is fine-tuned with the net */
    float res_init;                 /* initial residual gates (1); the net's output layers start
                                     * at 0, so the model starts at the base */
    float minutes;                  /* time budget (0 = none): the schedule spans it, the run
                                     * stops with a checkpoint when it is spent (training time
                                     * over every invocation: resume continues the clock) */
    int sensor_clip;                /* 1: samples clipped to [0, 1] after the noise, as a 16-bit
                                     * PNG frame holds them (0) */
    int sensor_bits;                /* quantisation of the samples (0 = off; 16 = PNG) */
    float photons;                  /* shot noise: photo-electrons at full scale (0 = off) */
    float photons_min;              /* > 0: training samples' photons log-uniform in
                                     * [photons_min, photons] (0 = all at photons) */
    float read_noise;               /* read noise: electrons with photons, else a fraction of
                                     * full scale (0 = off) */
    float fit_b0_noise;             /* closed form, two buckets: bucket 0's noise sd over bucket
                                     * 1's in the fit (0 = the same) */
    float illum_jitter;             /* training samples' illumination tilt range (data/dataset.h;
                                     * 0 = off) */
    float gain_jitter;              /* training samples' LED gain error sd (0 = off) */
    float scale_jitter;             /* training scene samples' zoom range: (1 + this)^U[-1, 1]
                                     * (data/dataset.h; 0 = off) */
    int transpose;                  /* 1: training scene samples transposed half of the time */
    float fine_fraction;            /* share of procedural scenes with fine narrowband detail
                                     * (data/synth.h lm_synth_fine; 0 = none) */
    float clip_fraction;            /* share of noisy training samples clipped to [0, 1] (a
                                     * 16-bit PNG frame); the rest keep their negatives */
    float clean_fraction;           /* share of training samples without noise (the rest as
                                     * noise / photons say) */
    float collage;                  /* share of training scene samples with another scene's
                                     * patch pasted across an edge (data/dataset.h; 0 = off) */
    char snapshots[128];            /* "5,15,30": weights at these minutes of training time into
                                     * <output>/snapshots/<M>min/ ("" = none) */
    /* what "training time" (minutes, snapshots, the checkpoint's seconds) counts: "wall"
     * (elapsed time, the default) or "cpu" (CPU time of the process, every thread: a budget a
     * busy machine does not shrink; the study runs presets side by side on it) */
    char clock[8];
    char precision[8];              /* fp32 | bf16: operands of the 3x3 convolutions' products */
    int buckets;                    /* coded-frame buckets the model reads: 1 (bucket 1) or 2
                                     * (both; the preset's "-b2" form, which sets 2 itself) */
    int frames;                     /* coded frames per sample: 1, or 3 (the preset's "-mf3"
                                     * form, which sets 3 itself; the multi-frame source) */
    char mat_key[LM_DATASET_KEY_LEN]; /* .mat cube variable of the data ("" = automatic:
                                        * cube, hsi, rad, ref, ...; data/cube_io.h) */
    /* QDO presets (LM_CAP_QDO_OPTICS) only; JSON also as one object "doe": {"file",
     * "optimise", "lr", "quantise", "bands"} */
    char doe[LM_TRAIN_PATH_LEN];    /* DOE description ("" or "default": the bundled one) */
    int doe_optimise;               /* 1: train the height map with the network */
    float doe_lr;                   /* Adam learning rate of the height map (fractions of the
                                     * maximum height; 0.01) */
    char doe_quantise[16];          /* progressive | ste | none (train/doe_opt.c) */
    int doe_bands;                  /* wavelengths whose PSFs get a gradient per update (4) */
    char recipe[16];                /* "preset" (default): the fields a file or flag did not
                                     * give take the model preset's measured recipe
                                     * (lm_train_recipe_find; none: the defaults above);
                                     * "paper": the paper's protocol (the defaults above) */
    uint64_t given[2];              /* bit i: field i of the table was given by a file or a
                                     * flag (internal, not a JSON field) */
} lm_train_cfg;

/* A training recipe measured for a preset on this project's machines: the
 * learning rate, batch and schedule that reached the best validation PSNR in a short
 * CPU-time-budgeted sweep (docs/guide/training.md, "Training recipes"). residual: trained on a
 * base (--base). */
typedef struct lm_train_recipe {
    const char *preset;
    int residual;
    float lr;
    int batch, accum_steps;
    const char *schedule;
    float lr_min;
    long warmup;
    float synth_fraction;           /* < 0: the default */
} lm_train_recipe;
/* The recipe of a preset ("rt-8", or a variant "rt-8-b2", "rt-8-mf3": the first name the
 * preset starts with followed by "-"), trained on a base or not; NULL when none is measured
 * (the paper-size presets, the closed-form fits). */
const lm_train_recipe *lm_train_recipe_find(const char *preset, int residual);
/* With cfg->recipe "preset": every recipe field (lr, batch, accum_steps, schedule, lr_min,
 * warmup, synth_fraction) that was not given takes the recipe's value. Returns the recipe used
 * (NULL: none, or recipe "paper"). Call once the model and base are known, before
 * lm_train_cfg_validate; a resumed run's config gives every field, so nothing changes. */
const lm_train_recipe *lm_train_cfg_apply_recipe(lm_train_cfg *cfg);
/* Was field `key` (JSON or flag spelling) given by a file or a flag? */
int lm_train_cfg_given(const lm_train_cfg *cfg, const char *key);

/* The default share of procedural scenes, chosen on the real validation split
 * (docs/guide/training.md). */
#define LM_TRAIN_PROCEDURAL_DEFAULT 0.2f
/* The share of procedural scenes a run draws: procedural_fraction, or when it is -1 the
 * default share, at most 1 - synth_fraction. */
float lm_train_procedural_share(const lm_train_cfg *cfg);
/* The data set a run reads, opened as `lumosaic train` opens it (one process, no context
 * around the patches); clean: no noise, clipping or quantisation (what a closed-form fit reads:
 * it adds them itself). NULL with err set. */
struct lm_system;
typedef struct lm_dataset lm_dataset;
lm_dataset *lm_train_open_data(const lm_train_cfg *cfg, const struct lm_system *sys, int clean,
                               lm_err *err);
/* Paper defaults (system.md §7) with output "runs/train". */
void lm_train_cfg_default(lm_train_cfg *cfg);
/* Merge a JSON config file over cfg. Unknown fields and wrong types are errors naming the
 * field: "config run.json: field 'batch': must be an integer >= 1". */
lm_status lm_train_cfg_load(lm_train_cfg *cfg, const char *path, lm_err *err);
lm_status lm_train_cfg_parse(lm_train_cfg *cfg, const char *json_text, const char *label,
                             lm_err *err);
/* Set one field from text, by its JSON name or flag name ("batch", "accum-steps" or
 * "accum_steps"). Lists: "data" appends one path; "patch" takes "66x64"; "noise" "0,0.15". */
lm_status lm_train_cfg_set(lm_train_cfg *cfg, const char *key, const char *value, lm_err *err);
/* Is `key` a field name (JSON or flag spelling)? */
int lm_train_cfg_has(const char *key);
/* Cross-field checks (errors name the field). */
lm_status lm_train_cfg_validate(const lm_train_cfg *cfg, lm_err *err);
/* Write the resolved config as JSON (atomic). */
/* The config's paths in place (data..., system, base, and the DOE unless "default"): pointers
 * into c, at most LM_TRAIN_MAX_PATHS + 3. Returns how many. */
int lm_train_cfg_paths(lm_train_cfg *c, char **paths);
lm_status lm_train_cfg_save(const lm_train_cfg *cfg, const char *path, lm_err *err);
/* Help text of every field: "  --batch N   ..." lines. */
void lm_train_cfg_print_help(FILE *f);
/* The Adam configuration a run uses. */
void lm_train_cfg_adam(const lm_train_cfg *cfg, lm_adam_cfg *out);

/* ---- data for the loop ------------------------------------------------------------------ */
/* A differentiable camera in front of the model (the QDO DOE, train/doe_opt.c): its source's
 * batch() leaves raw alone and input() makes the model input of that batch on the tape. */
typedef struct lm_train_front {
    lm_tensor *(*input)(void *user, lm_ctx *c, int B); /* NULL with the ctx error set */
    void (*zero_grad)(void *user);
    lm_status (*step)(void *user, lm_err *err);        /* after the network's Adam update */
    lm_status (*refresh)(void *user, lm_err *err);     /* before a validation */
    lm_status (*save)(void *user, const char *dir, lm_err *err); /* with each checkpoint */
    lm_status (*load)(void *user, const char *dir, lm_err *err); /* on resume */
} lm_train_front;

/* Where batches come from: data/dataset.h through lm_train_source_dataset, or any other
 * deterministic generator (tests use fixed in-memory batches). Buffers: raw B x 1 x ph x pw
 * (B x in_channels x ph x pw for a model whose in_channels is not 1, e.g. RGB for MST++),
 * target B x 33 x ph x pw, owned by the caller. batch() must be a pure function of index. */
typedef struct lm_train_source {
    void *user;
    lm_status (*batch)(void *user, long index, int B, float *raw, float *target, lm_err *err);
    int (*eval_count)(void *user);
    lm_status (*eval_sample)(void *user, int i, float *raw, float *target, lm_err *err);
    const lm_train_front *front;  /* NULL: raw is the model's input */
} lm_train_source;

typedef struct lm_dataset lm_dataset;
/* Training batches and the validation split's fixed samples of a dataset (data/dataset.h). */
lm_train_source lm_train_source_dataset(lm_dataset *d);
/* The passive RGB baseline (train/source_rgb.c): the dataset's own samples (scenes, patches,
 * flips, synthetic share, noise level k per sample) with raw = the RGB camera image
 * B x 3 x ph x pw of each sample's 400..700 nm bands (data/rgbcam.h: camera_csv NULL = the
 * bundled Nikon D5100, illum an lm_rgbcam_illum); target unchanged (B x 33). noise: extra
 * sensor options (Poisson, clip, bits; its gauss_k is replaced by the sample's k), or NULL.
 * Close with lm_train_source_rgb_close. */
lm_status lm_train_source_rgb_open(lm_train_source *src, lm_dataset *d, const char *camera_csv,
                                   int illum, const lm_noise_opts *noise, int patch_h,
                                   int patch_w, uint64_t seed, lm_err *err);
void lm_train_source_rgb_close(lm_train_source *src);
/* The QDO baseline: the same source with the RGB camera behind a DOE (data/qdocam.h; doe_path
 * NULL = the bundled data/systems/qdo_default.json), D65. Computes the 31 PSFs once (seconds).
 * Close with lm_train_source_rgb_close. */
lm_status lm_train_source_qdo_open(lm_train_source *src, lm_dataset *d, const char *doe_path,
                                   const lm_noise_opts *noise, int patch_h, int patch_w,
                                   uint64_t seed, lm_err *err);

/* The QDO baseline with the camera on the tape (train/doe_opt.c): dataset patches of
 * (patch_h + 2 pad_y) x (patch_w + 2 pad_x) (pads >= the PSF radius: real context for the
 * convolution), targets cropped to the patch; optionally the DOE's height map optimised with
 * the network. Writes doe.json + doe_heights.png (+ doe_state.safetensors when optimising)
 * with every checkpoint. Close with lm_train_source_doe_close. */
typedef struct lm_train_doe_opts {
    char file[LM_TRAIN_PATH_LEN];  /* "" or "default": bundled */
    int optimise;
    float lr;
    char quantise[16];
    int bands;
    long total;                    /* updates of the run (the progressive schedule) */
} lm_train_doe_opts;
lm_status lm_train_source_doe_open(lm_train_source *src, lm_dataset *d,
                                   const lm_train_doe_opts *o, int patch_h, int patch_w,
                                   int pad_y, int pad_x, uint64_t seed, lm_err *err);
void lm_train_source_doe_close(lm_train_source *src);
/* The context pads of that DOE: the PSF radius, raised until 2 pad is a multiple of the tile. */
int lm_train_doe_pad(const char *doe_path, int ty, int tx, int *py, int *px, lm_err *err);
/* Moving scenes (train/source_motion.c): a share `fraction` of the real-scene samples seen
 * moving during the exposure (translation up to `speed` px/s in any direction, rotation up to
 * `rotation` deg/s about the patch centre), each LED's pixels averaging `samples` instants of
 * its window; the target is the scene at the ground-truth instant (data/video.h). clip / bits:
 * as the dataset's sensor options. Close with lm_train_source_motion_close. */
/* frames 3 (the "-mf3" models): every sample is frames i-1, i, i+1 of one patch, B x 3 x ph x
 * pw: real-scene samples moving (the share `fraction`, motion drawn as above) or still, each
 * frame rendered in a window of lm_train_mf_margins more rows / columns each side (the flow
 * needs sub-images of lm_flow_min_size; the border repeats outside the scene), its own
 * noise (lm_train_mf_noise_rng), then aligned by lm_align_stack (data/align.h: the medium flow,
 * 1 thread, as inference aligns by default; no knowledge of the true motion) when `align`, and
 * cropped to the patch: plane 0 frame i aligned, planes 1, 2 frames i-1, i+1 moved onto it.
 * Synthetic samples: the dataset's clean patch with three noise draws, not aligned (still).
 * Validation: the still validation sample as all three planes. Batch `index` is a pure
 * function of (seed, index), whatever the thread count. */
typedef struct lm_train_motion_opts {
    float fraction, speed, rotation;
    int samples;
    int clip, bits;
    float photons, read_noise; /* shot and read noise, as the dataset's */
    int frames;                /* 1 (or 0): one coded frame per sample; 3: multi-frame */
    int align;                 /* frames 3: 1 = align (training); 0 = raw frames (tests) */
} lm_train_motion_opts;
#define LM_TRAIN_MF_MARGIN_Y 15
#define LM_TRAIN_MF_MARGIN_X 16
/* The window margins of a multi-frame sample of a ph x pw patch: LM_TRAIN_MF_MARGIN_Y / _X
 * rows / columns each side (whole tiles of the default system), raised by whole tiles until
 * the window's sub-images reach the medium flow's minimum size (15 / 16 for 66 x 64 patches:
 * a 96 x 96 window, 32 x 24 sub-images). */
void lm_train_mf_margins(const lm_system *sys, int ph, int pw, int *my, int *mx);
/* The noise generator of frame f (0, 1, 2 = i-1, i, i+1) of multi-frame sample i. */
void lm_train_mf_noise_rng(uint64_t seed, long i, int f, lm_rng *out);
lm_status lm_train_source_motion_open(lm_train_source *src, lm_dataset *d, const lm_system *sys,
                                      const lm_train_motion_opts *o, int patch_h, int patch_w,
                                      uint64_t seed, lm_err *err);
void lm_train_source_motion_close(lm_train_source *src);
/* One moving patch as the source renders it: rows [py, py + ph) x columns [px, px + pw) of the
 * 31-band crop c31 (tile phases from the patch's top-left), moving by m (its coordinates are
 * the crop's), `samples` instants per LED window: raw (ph x pw, noise-free) and the 33-channel
 * target at the ground-truth instant. Equals lm_video_frame on the crop up to float rounding. */
typedef struct lm_motion lm_motion;
lm_status lm_train_motion_render(const lm_system *sys, const lm_cube *c31, const lm_motion *m,
                                 int samples, int py, int px, int ph, int pw, float *raw,
                                 float *target, lm_err *err);

/* ---- the loop --------------------------------------------------------------------------- */
typedef struct lm_train_opts {
    const char *resume;        /* run folder to continue from, or NULL */
    long stop_after;           /* stop (with a checkpoint) after this many iterations of this
                                * invocation; 0 = run to cfg.iterations (tests: interruption) */
    int progress;              /* 1: progress bar / lines on stderr */
    FILE *progress_out;        /* NULL = stderr */
    const char *system_path;   /* recorded in checkpoints ("" = bundled default) */
    uint64_t system_hash;      /* FNV-1a of the system file (0 = unknown) */
    const char *train_scenes;  /* content hashes of the training scenes, recorded in
                                * checkpoints ("train_scenes"; lm_dataset_split_hashes) */
    double stop_seconds;       /* stop (with a checkpoint) once training time over all
                                * invocations reaches this; 0 = no such stop. Unlike
                                * cfg.minutes it does not shape the schedule (the study stops
                                * runs early with it) */
    double elapsed;            /* set by the loop: training seconds so far, recorded in
                                * checkpoints ("seconds") */
    const atomic_int *interrupt; /* NULL, or a flag another thread or a signal handler sets
                                * (nonzero, e.g. the signal's number): the run finishes the
                                * current iteration, writes its checkpoint and returns LM_OK
                                * with res->interrupted = the flag's value */
    void (*hold)(int on);      /* NULL, or called with 1 before and 0 after the run folder's
                                * files that must agree are written (config.json and the
                                * checkpoint), so that a signal ending the program at once
                                * waits for them (cli: lm_cli_signals_hold) */
    int restart;               /* 1: cfg.output holds config.json (and maybe log.csv) but no
                                * checkpoint: the run starts from its beginning there, and a
                                * failure leaves the folder's config.json in place */
    int data_parallel;         /* 1: this process is one of lm_dist_size() data-parallel ranks
                                * of one run (`mpirun ... lumosaic train`); 0: it trains alone
                                * (also under mpirun, e.g. a study's rank training its preset) */
} lm_train_opts;

typedef struct lm_train_result {
    long iterations_done;      /* completed optimizer updates, over all invocations */
    double last_loss;          /* mean L1 of the last completed iteration */
    double first_loss;         /* mean L1 of the first iteration of this invocation */
    lm_metrics val;            /* last validation (zeros if none) */
    int validated;
    double seconds;
    int closed_form;           /* fitted in closed form (lmmse): no iterations, val.psnr only */
    int budget_spent;          /* stopped because cfg.minutes of training time were spent */
    int interrupted;           /* stopped by opts->interrupt (its value), 0 otherwise */
    long fit_patches, fit_patches_asked; /* closed form: training patches read / asked for
                                * (fewer when interrupted or out of time) */
} lm_train_result;

/* Train `model` (created by the caller from cfg->model with the run's mosaic) on `src`.
 * The device backend (cfg->device) is opened once per run: each step uploads the batch,
 * swaps the parameters onto the device (lm_tensors_swap_to_device), runs forward, loss and
 * backward there, adds the device gradients into the host gradient block and runs Adam on the
 * host; validation runs its forward passes the same way. A device that cannot be opened is
 * LM_ERR_ARG with a one-line message naming it.
 * LM_ERR_NUMERIC when a loss is NaN/inf: the run stops, the message names the iteration, and
 * the last checkpoint on disk is left untouched. LM_ERR_WRITE when log.csv (or a checkpoint)
 * cannot be written: the run stops the same way. A fresh run that fails before its first
 * iteration completes (a scene that cannot be read, a NaN at once) leaves no run folder: the
 * files it wrote and the folders it created are removed. */
lm_status lm_train_run(const lm_train_cfg *cfg, lm_model *model, const lm_train_source *src,
                       const lm_train_opts *opts, lm_train_result *res, lm_err *err);

/* A whole run from its configuration: loads the system description (cfg->system or the
 * bundled default), derives the network front (data/mosaic.h), creates the model from
 * cfg->model and cfg->seed, opens the dataset (cfg->data, synthetic share, patch, noise, seed,
 * workers, validation samples) and runs lm_train_run. opts->system_path / system_hash are
 * filled in here. */
lm_status lm_train_session(const lm_train_cfg *cfg, const lm_train_opts *opts,
                           lm_train_result *res, lm_err *err);

/* Checkpoint files of a run folder (used by resume and by `lumosaic infer`). */
/* next_batch: the sampler position (index of the next batch; batches are a pure function of
 * (seed, index), so this and the seed are the whole sampler state). opt may be NULL on load
 * (weights only). */
lm_status lm_train_save_checkpoint(const char *dir, const lm_model *m, const lm_adam *opt,
                                   long iteration, long next_batch, const lm_train_opts *opts,
                                   const lm_train_cfg *cfg, lm_err *err);
lm_status lm_train_load_checkpoint(const char *dir, lm_model *m, lm_adam *opt, long *iteration,
                                   long *next_batch, uint64_t *seed, lm_err *err);
/* Training seconds recorded in a run folder's optimizer checkpoint (0 if none). */
double lm_train_checkpoint_seconds(const char *dir);
/* 1 when that checkpoint counted training time on the CPU clock (cfg.clock "cpu"); 0: wall
 * (also checkpoints from before the field). */
int lm_train_checkpoint_cpu_clock(const char *dir);
/* Data-parallel processes that trained that checkpoint (metadata "ranks"; 1 if absent). */
int lm_train_checkpoint_ranks(const char *dir);
/* mkdir -p. */
lm_status lm_train_make_dir(const char *path, lm_err *err);
/* mkdir -p that also gives the outermost folder it created (top, n bytes; "" if path existed). */
lm_status lm_train_make_dir_top(const char *path, char *top, size_t n, lm_err *err);
/* Undo a run that failed to start: remove the files a run writes into `dir` (config.json,
 * log.csv, fit.json, the checkpoints) and the folders from dir up to `top` (as made by
 * lm_train_make_dir_top; "" = none were created). Other files are left alone. */
void lm_train_discard_dir(const char *dir, const char *top);
/* Remove the checkpoint files of `dir` (weights, optimizer state, a DOE's state). */
void lm_train_discard_checkpoint(const char *dir);

#endif
