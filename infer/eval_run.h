/* eval_run.h — an evaluation run over scenes: the library half of `lumosaic eval`.
 * What it is: the model loaded (with a --system of other LED gains rescaled to the model's,
 * infer/raw.h, unless no_remap), the scenes listed (data/dataset.h: the dataset's split
 * lists, as in training; `all` keeps every scene; or the scenes named), each scene read onto
 * 31 bands, prepared (lm_eval_prepare), scored at each noise level (lm_eval_scene_timed, the
 * noise seeded per scene name and level) and, with motion speeds, at each motion noise level
 * and speed (lm_eval_motion_run_noise); means over the scenes; the rainbow test; which scenes
 * the model was trained on (by content). Progress and information lines go to a caller's
 * callback, one line at a time; nothing is printed.
 * What it is not: the scoring of one scene (infer/eval.h), the result files (infer/eval_write.h)
 * or printing (cli/cmd_eval.c). */
#ifndef LM_EVAL_RUN_H
#define LM_EVAL_RUN_H
#include "data/dataset.h"
#include "infer/eval.h"

typedef enum lm_eval_split {
    LM_EVAL_SPLIT_TEST = 0,
    LM_EVAL_SPLIT_VAL,
    LM_EVAL_SPLIT_TRAIN,
    LM_EVAL_SPLIT_ALL
} lm_eval_split;

/* "test", "val", "train", "all" */
const char *lm_eval_split_name(int split);

typedef struct lm_eval_run_opts {
    const char *model;          /* a training run folder or a .safetensors (ignored with
                                 * auto_file) */
    const char *auto_file;      /* a `lumosaic fit-auto` calibration: every frame reconstructed
                                 * by its choice per window (one-bucket models, CPU), or NULL */
    double auto_tol;            /* dB of expected PSNR the choice may give up (0.5) */
    const char *system;         /* NULL = the model's */
    int no_remap;               /* a system of other gains: frames given to the model as is */
    const char *const *data;    /* scenes or folders of scenes */
    int ndata;
    const char *mat_key;        /* NULL = automatic */
    int split;                  /* lm_eval_split */
    const char *scenes;         /* comma-separated scene names, or NULL (then split) */
    float k[LM_EVAL_MAX_NOISE]; /* noise levels (fractions) */
    int nnoise;
    double speed[LM_EVAL_MAX_MOTION]; /* motion speeds, px/s (nmotion 0 = no motion rows) */
    int nmotion;
    float mk[LM_EVAL_MAX_MOTION_NOISE]; /* motion noise levels (fractions) */
    int nmk;
    int align_plain;            /* warp every pixel (else confident alignment) */
    long long rainbow;          /* rainbow size (0 = skip) */
    long long batch;            /* windows per network call */
    long long seed;
    int nthreads;               /* 0 = default */
    const char *device;         /* NULL = env LM_DEVICE, else cpu */
    int precision;              /* LM_PRECISION_* */
    int noise_oracle, clip;     /* sensor options of the model (infer/model_io.h) */
    long long bits;
    double photons, read_noise;
    double report_noise;        /* report sample level in %, -1 = the level nearest 10 % */
    /* One line of progress or information (no newline); NULL = none. */
    void (*log)(void *user, const char *line);
    void *user;
} lm_eval_run_opts;

/* Defaults: seed 1, rainbow 256, batch 8, levels 0, 5, 10, 15, 20 %, one motion noise level 0,
 * report_noise -1, split test, auto_tol 0.5. */
void lm_eval_run_opts_default(lm_eval_run_opts *o);

typedef struct lm_eval_scene_res {
    char name[256], path[1024];
    lm_data_split split;  /* the dataset's split of the scene (never a borrowed one) */
    int height, width;
    int trained;          /* among the model's training scenes (1), not (0), unknown (-1) */
    lm_metrics m[LM_EVAL_MAX_NOISE];
    double sec[LM_EVAL_MAX_NOISE]; /* reconstruction seconds of the frame at each level */
    lm_eval_motion mo[LM_EVAL_MAX_MOTION * LM_EVAL_MAX_MOTION_NOISE]; /* noise-major */
} lm_eval_scene_res;

typedef struct lm_eval_run {
    const lm_eval_run_opts *o;
    lm_infer_model im;    /* the model (a calibration's: model 0) */
    lm_infer_model more[LM_AUTO_MAX_MODELS]; /* a calibration's models 1.. */
    lm_auto_calib cal;    /* with auto_file */
    int choice[LM_AUTO_MAX_BINS];
    lm_ctx ctx;
    int have_ctx;
    lm_tile_device dev;
    lm_tile_opts to;
    lm_eval_scene_res *sc;
    int nsc;
    int given;            /* scenes among DATA before the split / names were applied */
    lm_metrics mean[LM_EVAL_MAX_NOISE];
    double mean_sec[LM_EVAL_MAX_NOISE];
    lm_eval_motion mo_mean[LM_EVAL_MAX_MOTION * LM_EVAL_MAX_MOTION_NOISE];
    lm_eval_rainbow rb;
    int overlap_unknown;  /* the model records no training scenes */
} lm_eval_run;

/* Motion rows: every motion noise level by every speed, noise-major. */
int lm_eval_motion_rows(const lm_eval_run_opts *o);
/* The noise level of the report's sample: report_noise's, else the one nearest 10 % (-1:
 * report_noise is not a level). */
int lm_eval_report_level(const lm_eval_run_opts *o);

/* Load the model (a gain remap is described through o->log; with no_remap it is switched off),
 * or a calibration's models (each one-bucket, one-frame, of model 0's tile, without a gain
 * remap; the choice per bin at auto_tol), and list the scenes. *r is zeroed first; free it with lm_eval_run_free whatever the status.
 * Errors: those of lm_infer_model_load and lm_dataset_list_scenes; LM_ERR_ARG ("--scenes: no
 * scene 'X' among the N given (...)", "no scene of split 'S' among the N given (try --split
 * all)"); LM_ERR_NOMEM. */
lm_status lm_eval_run_open(lm_eval_run *r, const lm_eval_run_opts *o, lm_err *err);

/* The compute context and device (described through o->log when not the defaults), every
 * scene (a line per scene through o->log: "scene i/n NAME (W x H): S s"), the means, the
 * rainbow test and the training-set overlap. Errors: LM_ERR_NOMEM ("out of memory (compute
 * context)"), those of the device; LM_ERR_UNSUPPORTED (an MST++ model on a device); those of
 * the reader (its own message), of the scoring ("<path>: ...") and of the rainbow ("rainbow:
 * ..."). */
lm_status lm_eval_run_score(lm_eval_run *r, lm_err *err);

void lm_eval_run_free(lm_eval_run *r);

#endif
