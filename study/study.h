/* study.h — the speed-against-accuracy study behind `lumosaic study`.
 * What it is: a study configuration (JSON: presets, one shared training budget, evaluation
 * noise levels and scenes), and the run: for each preset train it (train/train.h) into
 * <dir>/runs/<preset>/, evaluate it on the held-out scenes at every noise level
 * (infer/eval.h), run the rainbow test, time a 640 x 480 frame (infer/tile.h, min of a few
 * repeats) and count parameters and multiply-adds (models/profile.h). Each preset's outcome is
 * one JSON object, written to <dir>/runs/<preset>/result.json; a preset whose result.json
 * exists is not run again (resume), and a preset with a checkpoint but no result.json
 * continues its training from the checkpoint.
 * Held-out scenes: the scenes of the configured data's test split (data/dataset.h: scene
 * groups ranked by hash, 10 % test); when there is none, `eval_scenes` procedural scenes (data/synth.h) whose
 * seeds come from a stream of the study seed that the training sampler never uses.
 * What it is not: the summary files and table (study/results.c, lm_study_write) or the charts
 * (study/charts.h). */
#ifndef LM_STUDY_H
#define LM_STUDY_H
#include <stdio.h>
#include "infer/conditions.h"
#include "infer/eval.h"
#include "train/train.h"

#define LM_STUDY_CFG_VERSION 1
#define LM_STUDY_MAX_PRESETS 32
#define LM_STUDY_MAX_FRACTIONS 8

/* One condition family of the failure study (infer/conditions.h) and its sweep. */
typedef struct lm_study_cond {
    lm_cond_family family;
    double levels[LM_COND_MAX_LEVELS];  /* mild to severe */
    int nlevels;
} lm_study_cond;

struct json_t;

typedef struct lm_study_cfg {
    int version;
    char presets[LM_STUDY_MAX_PRESETS][64];
    int npresets;
    lm_train_cfg train;              /* shared by every preset (model and output set per run) */
    float noise[LM_EVAL_MAX_NOISE];  /* evaluation noise levels k (fractions; JSON in %) */
    int nnoise;
    int eval_scenes;                 /* procedural held-out scenes when the test split is empty */
    int eval_h, eval_w;              /* their size */
    int rainbow;                     /* rainbow scene size (0 = skip) */
    int frame_h, frame_w;            /* timed frame (480 x 640) */
    int timing_repeats;              /* timed runs per model (min and median reported) */
    lm_study_cond cond[LM_COND_NFAMILIES]; /* failure conditions (config order) */
    int ncond;
    int cond_scenes;                 /* held-out scenes used for them (0 = all) */
    char nb_preset[64];              /* narrowband sweep preset ("" = no sweep) */
    /* Per-preset training fields over `train` (JSON objects, by preset name; NULL = none). */
    struct json_t *preset_train;
    /* Early drop (train.minutes > 0): every preset first trains to drop_minutes of training
     * time; those whose clean held-out PSNR there is more than drop_db below the best go no
     * further (recorded as dropped); the others continue to the budget. 0 = off. */
    float drop_minutes, drop_db;
    float nb_fraction[LM_STUDY_MAX_FRACTIONS]; /* its training synth_fraction values */
    int nnb;
    char output[LM_TRAIN_PATH_LEN];  /* default output folder ("" = none given) */
    char path[LM_TRAIN_PATH_LEN];    /* the config file */
} lm_study_cfg;

/* Defaults: no presets, lm_train_cfg_default with 2000 iterations, noise 0,5,10,15,20 %,
 * 8 procedural scenes of 132 x 128, rainbow 256, frame 480 x 640, 3 timing repeats, no
 * conditions, no narrowband sweep. */
void lm_study_cfg_default(lm_study_cfg *cfg);
/* Load a study config. Fields (all optional but "presets" and "data"):
 *   presets may name residuals "NET+BASE": NET trained on the study's own run of BASE (listed
 *   earlier), e.g. "lmmse", "han-tiny+lmmse"; preset_train {"name": {training fields}};
 *   drop {"after_minutes": M, "behind_db": D};
 *   version 1; presets [names]; data [paths, relative to the config's folder]; system;
 *   iterations; seed; patch "HxW"; synth_fraction; train {any other lm_train_cfg field;
 *   its "precision" also holds for the evaluation and timing
 *   except model, data, output}; noise [percent levels]; eval_scenes; eval_size "HxW";
 *   rainbow; frame "HxW"; timing_repeats; output;
 *   conditions [{"family": photons|saturation|led_gain|dead_pixels|motion, "levels": [...]
 *   (optional: the family's default sweep)}]; condition_scenes (first N held-out scenes);
 *   narrowband_sweep {"preset": name, "fractions": [synth shares 0..1]}.
 * Errors (LM_ERR_IO / LM_ERR_FORMAT / LM_ERR_ARG) are one line naming the file and the field. */
lm_status lm_study_cfg_load(lm_study_cfg *cfg, const char *path, lm_err *err);
void lm_study_cfg_free(lm_study_cfg *cfg);

typedef struct lm_study_opts {
    int threads;     /* compute threads for training, evaluation and timing (0 = all cores) */
    int progress;    /* training progress on `log` */
    FILE *log;       /* one line per step of the study (NULL = stderr) */
    int jobs;        /* presets trained side by side (<= 1: one at a time, in this process):
                      * each in a child `lumosaic study --worker` process with `threads`
                      * threads; evaluation and timing stay serial, after the training */
    const char *exe; /* jobs > 1: the lumosaic program the workers run (NULL: this one) */
    const atomic_int *interrupt; /* NULL, or a flag a signal handler sets (the signal's
                      * number): a training in this process finishes its iteration and
                      * checkpoints, workers are sent that signal (they do the same) and
                      * waited for, and the study returns LM_ERR_INTERRUPTED */
    void (*hold)(int on);         /* passed to training (lm_train_opts.hold) */
    void (*track)(long pid, int on); /* NULL, or told of each worker started (1) and waited
                      * for (0), e.g. so that a signal ending the program reaches them */
} lm_study_opts;

/* The outcome: a description of the held-out set and one record per preset (config order). */
typedef struct lm_study {
    struct json_t *held_out;  /* {"kind": "test_split" | "procedural", "scenes": [...], ...} */
    struct json_t *runs;      /* array of per-preset objects (see results.c for the fields) */
    struct json_t *narrowband;/* array of the narrowband sweep's records (NULL = no sweep):
                               * {"preset", "run", "synth_fraction", "train", "eval", "rainbow"} */
} lm_study;

/* Run (or resume) the study into dir (created if missing). On error the records of the
 * presets already finished stay on disk; *out is freed. */
lm_status lm_study_run(const lm_study_cfg *cfg, const char *dir, const lm_study_opts *o,
                       lm_study *out, lm_err *err);
void lm_study_free(lm_study *s);
/* One row of a run's log.csv (iteration,loss,lr,psnr,ssim,mae,sam) split in place at its commas
 * into fld[0..6] (empty fields stay empty strings, missing ones NULL); the number of fields. */
int lm_study_log_fields(char *line, char *fld[7]);
/* A --jobs worker: train (or continue) the one preset `name` of the config into
 * dir/runs/<name>, stopping at stop_s seconds of training time when stop_s > 0. */
lm_status lm_study_train_one(const lm_study_cfg *cfg, const char *dir, const char *name,
                             double stop_s, const lm_study_opts *o, lm_err *err);
/* (jobs.c) Train the presets names[0..n) side by side, o->jobs at a time, each in a worker
 * process (lm_study_train_one) with o->threads threads (0: the cores / jobs); waits for all.
 * A worker that fails fails the call (no new worker starts after it). */
lm_status lm_study_spawn(const lm_study_cfg *cfg, const char *dir, const char *const *names,
                         int n, double stop_s, const lm_study_opts *o, lm_err *err);

/* <dir>/results.json, results.csv and results.md (atomic: temp file + rename). charts: the
 * chart files exist in <dir>/charts/ (results.md links them). */
lm_status lm_study_write(const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                         int charts, lm_err *err);

/* ---- inside the study (study/conds.c) --------------------------------------------------- */
/* Means over scenes of the clean score and of each configured (family, level). */
typedef struct lm_study_cond_acc {
    lm_metrics_acc clean;
    lm_metrics_acc m[LM_COND_NFAMILIES][LM_COND_MAX_LEVELS]; /* aligned for motion */
    lm_metrics_acc u[LM_COND_NFAMILIES][LM_COND_MAX_LEVELS]; /* motion unaligned */
    lm_metrics_acc s[LM_COND_NFAMILIES][LM_COND_MAX_LEVELS]; /* motion static reference */
    int nscenes;
} lm_study_cond_acc;
void lm_study_cond_init(lm_study_cond_acc *a);
/* One prepared held-out scene through every configured condition (families that do not apply
 * to the model are skipped); rs: the scene's generator. */
lm_status lm_study_cond_add(lm_ctx *c, const lm_infer_model *im, const lm_study_cfg *cfg,
                            const lm_cube *truth, const lm_rng *rs, lm_study_cond_acc *a,
                            lm_err *err);
/* {"scenes", "clean_psnr", "drop_db": 3, "families": [{"family", "unit", "applies",
 * "levels": [{"level", "psnr", "ssim", "sam", and for motion "psnr_unaligned", "psnr_static"
 * (the static reference on the same in-view region) and "px_per_frame" (level x the system's
 * frame period)}], "drop_3db": level
 * or null, "beyond_last_level"}]} */
struct json_t *lm_study_cond_json(const lm_study_cfg *cfg, const lm_infer_model *im,
                                  const lm_study_cond_acc *a);
/* The rainbow (size x size, no noise) reconstructed; rb["rows_true_recovered_nm"] = per row
 * [true peak, recovered peak] (lm_eval_peak_nm of the row-averaged spectrum). */
lm_status lm_study_rainbow_rows(lm_ctx *c, const lm_infer_model *im, int size,
                                struct json_t *rb, lm_err *err);

/* Index of the noise level closest to pct percent. */
int lm_study_noise_index(const lm_study_cfg *cfg, double pct);

#endif
