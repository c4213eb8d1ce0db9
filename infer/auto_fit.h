/* auto_fit.h — calibrating `--model auto` (infer/auto.h) on held-out scenes, the library
 * half of `lumosaic fit-auto`.
 * What it is: the models loaded (2..LM_AUTO_MAX_MODELS, the same coded frames), the scenes
 * taken (DATA scenes of the dataset's val / test splits, as training splits them, then
 * `synth` procedural scenes whose seeds training does not draw), each scene's coded frame
 * simulated at each noise level q (noise stream seed x 7919 + scene index + q x 104729), per window the difficulty and every
 * model's error recorded (lm_auto_scene), the fit of expected PSNR per difficulty bin
 * (lm_auto_fit), each model's measured seconds per window and MACs; and the held-out test:
 * `test_synth` more procedural scenes (a seed stream disjoint from the calibration scenes')
 * reconstructed by every model alone and by the auto choice at each tolerance (lm_auto_bin /
 * lm_auto_choose per window, lm_auto_infer), scored by PSNR against the truth (31 bands, the
 * scene divided by its maximum, as eval), with the share of windows per model, the seconds per
 * 640 x 480 frame estimated from the calibrated costs and the measured wall time; saved as the
 * calibration file (with "test" when measured). Progress lines go to a caller's callback.
 * What it is not: the selection or the inference (infer/auto.h), printing (cli/cmd_fit_auto.c). */
#ifndef LM_AUTO_FIT_H
#define LM_AUTO_FIT_H
#include "infer/auto.h"
#include "infer/model_io.h"

#define LM_AUTO_FIT_MAX_TOL 16
#define LM_AUTO_FIT_MAX_NOISE 8

typedef enum lm_auto_fit_split {
    LM_AUTO_FIT_VAL = 0,
    LM_AUTO_FIT_TEST,
    LM_AUTO_FIT_VALTEST,
    LM_AUTO_FIT_ALL
} lm_auto_fit_split;

/* "val", "test", "valtest", "all"; parse: -1 for another name. */
const char *lm_auto_fit_split_name(int split);
int lm_auto_fit_split_parse(const char *name);

typedef struct lm_auto_fit_opts {
    const char *models;         /* "RUN,RUN[,...]": run folders or .safetensors */
    const char *const *data;    /* scene files or folders */
    int ndata;
    int split;                  /* lm_auto_fit_split: which DATA scenes */
    long long synth;            /* procedural calibration scenes */
    int sh, sw;                 /* procedural scene size */
    long long bins;             /* difficulty bins, at most */
    lm_auto_measure measure;
    double noise[LM_AUTO_FIT_MAX_NOISE]; /* Gaussian noise k of the frames, in %: every scene
                                          * simulated at each level (calibration and test) */
    int nnoise;                 /* levels (1..LM_AUTO_FIT_MAX_NOISE) */
    int clip;                   /* frames clipped to [0, 1] after the noise (as a sensor or a
                                 * 16-bit PNG file holds them); 0 = negatives kept */
    long long bits;             /* frames quantised to this many bits (0 = off; 16: a PNG) */
    long long seed;             /* noise and procedural scene seed */
    long long batch;            /* windows per network call */
    int nthreads;               /* 0 = default */
    long long test_synth;       /* procedural test scenes (0 = no test) */
    double tol[LM_AUTO_FIT_MAX_TOL]; /* the test's tolerances, dB */
    int ntol;
    /* One line of progress (no newline); NULL = none. */
    void (*log)(void *user, const char *line);
    void *user;
} lm_auto_fit_opts;

/* Defaults: split valtest, 198 x 256 procedural scenes, 8 bins, grad, noise 0, seed 1, batch 8,
 * tolerances 0, 0.25, 0.5, 1, 2 dB. */
void lm_auto_fit_opts_default(lm_auto_fit_opts *o);

typedef struct lm_auto_test_row {
    int model;                    /* fixed rows: the model; auto rows: -1 */
    double tol;                   /* auto rows */
    int choice[LM_AUTO_MAX_BINS]; /* model per bin (fixed rows: `model` everywhere) */
    int same;                     /* auto row with the choice of an earlier auto row, or -1 */
    double psnr;                  /* mean over the test scenes */
    long win[LM_AUTO_MAX_MODELS]; /* windows run per model */
    double wall;                  /* seconds: difficulty (auto) + reconstruction */
} lm_auto_test_row;

typedef struct lm_auto_test {
    lm_auto_test_row rows[LM_AUTO_MAX_MODELS + LM_AUTO_FIT_MAX_TOL];
    int nrows, best;              /* best: the fixed row of the highest mean PSNR */
    long windows;                 /* windows of the test scenes */
    int wpf;                      /* windows per 640 x 480 frame */
} lm_auto_test;

typedef struct lm_auto_fit_run {
    const lm_auto_fit_opts *o;
    lm_infer_model im[LM_AUTO_MAX_MODELS];
    lm_model *models[LM_AUTO_MAX_MODELS];
    lm_auto_calib cal;            /* the calibration (after lm_auto_fit_calibrate) */
    lm_ctx ctx;
    int have_ctx;
    lm_tile_opts to;
    char (*scenes)[1024];         /* the DATA scenes */
    int nscenes;
    double *d, *mse, secs[LM_AUTO_MAX_MODELS]; /* samples: n, nmodels x cap */
    long n, cap;
    lm_auto_test *test;           /* after lm_auto_fit_test, else NULL */
} lm_auto_fit_run;

/* Load the models, list the DATA scenes and open the compute context. *r is zeroed first; free
 * it with lm_auto_fit_free whatever the status. Errors: LM_ERR_ARG ("--models: ..." for a list
 * too long, an empty element, more than LM_AUTO_MAX_MODELS or fewer than 2 models, models of
 * other frames; "no DATA scene of split ..."), those of lm_infer_model_load and
 * lm_dataset_list_scenes, LM_ERR_NOMEM. */
lm_status lm_auto_fit_open(lm_auto_fit_run *r, const lm_auto_fit_opts *o, lm_err *err);

/* The samples of every scene (a line per scene through o->log: "scene i/n: S s"), the models'
 * costs and MACs, the fit into r->cal. Errors: "scene i (PATH|procedural): ..." with the
 * scene's status; lm_auto_fit's ("... (use fewer --bins or more scenes)"). */
lm_status lm_auto_fit_calibrate(lm_auto_fit_run *r, lm_err *err);

/* The held-out test into r->test (a line per scene: "test scene i/n: S s"); nothing when
 * o->test_synth is 0. Errors: "test scene i: ..." with the scene's status, LM_ERR_NOMEM. */
lm_status lm_auto_fit_test(lm_auto_fit_run *r, lm_err *err);

/* Windows run by a test row (all models). */
long lm_auto_test_row_windows(const lm_auto_test_row *w, int nmodels);
/* Seconds per 640 x 480 frame from the calibrated per-window costs and the row's shares. */
double lm_auto_test_row_est(const lm_auto_fit_run *r, const lm_auto_test_row *w);

/* The calibration file at path (lm_auto_save_ext), with "test" when r->test is set. Errors:
 * those of lm_auto_save_ext, LM_ERR_NOMEM. */
lm_status lm_auto_fit_save(const lm_auto_fit_run *r, const char *path, lm_err *err);

void lm_auto_fit_free(lm_auto_fit_run *r);

#endif
