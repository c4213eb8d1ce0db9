/* auto.h — `--model auto`: per window, the cheapest model whose expected error stays within a
 * tolerance of the best.
 * What it is:
 *   - a cheap difficulty measure of one window of the coded frame, computed on the raw mosaic
 *     with same-phase differences only (pixels one tile apart, so the mosaic pattern itself
 *     does not count): "grad" = mean |f(y, x + tx) - f(y, x)| + |f(y + ty, x) - f(y, x)| over
 *     the window, and "relgrad" = grad / (mean |f| + 1e-3) (contrast rather than amplitude);
 *     or "noise": the frame's estimated noise level k (data/noise_est.h, sigma over the robust
 *     peak), the same for every window of a frame, so the choice is per frame: e.g. a network
 *     trained for clean frames beside one trained for noisy ones, calibrated at several noise
 *     levels (lm_auto_difficulty alone estimates the window's own level);
 *   - calibration: per window the difficulty and each model's K-weighted (infer/tile.h kernel)
 *     MSE on bands 400..700 nm against the truth (lm_auto_scene), then a fit (lm_auto_fit):
 *     quantile bins of difficulty, per bin and model the expected PSNR = -10 log10(mean MSE),
 *     plus each model's cost (seconds per window, measured during calibration; MACs for
 *     information); saved as / loaded from a JSON file (lm_auto_save / lm_auto_load);
 *   - selection (lm_auto_choose): per bin, among models with expected PSNR >= the best model's
 *     expected PSNR in that bin - tol dB, the one with the lowest cost (tol 0: always the best;
 *     a huge tol: always the cheapest);
 *   - inference with a model per window (lm_auto_fold / lm_auto_infer): the usual fold of
 *     infer/tile.h, whose network callback splits every fold batch (batch x nmodels windows)
 *     by model and runs each model on its windows in batches of at most `batch`. Windows
 *     assigned to one model give exactly that model's lm_tile_infer result (same windows, same
 *     per-window outputs, same fold order).
 * What it is not: model loading (infer/model_io.h), calibration runs (infer/auto_fit.h), the CLI,
 * a device backend (CPU only: the callback reads the batch on the host). */
#ifndef LM_AUTO_H
#define LM_AUTO_H
#include "data/cube.h"
#include "infer/tile.h"
#include "models/model.h"

#define LM_AUTO_MAX_MODELS 8
#define LM_AUTO_MAX_BINS 32
#define LM_AUTO_VERSION 1

typedef enum lm_auto_measure {
    LM_AUTO_GRAD = 0,
    LM_AUTO_RELGRAD = 1,
    LM_AUTO_NOISE = 2
} lm_auto_measure;

/* "grad" / "relgrad" / "noise"; lm_auto_measure_parse returns -1 for an unknown name. */
const char *lm_auto_measure_name(lm_auto_measure m);
int lm_auto_measure_parse(const char *name);

/* Difficulty of the wh x ww window at (y0, x0) of a frame `width` pixels wide (row-major). */
double lm_auto_difficulty(lm_auto_measure m, const float *frame, int width, int y0, int x0,
                          int wh, int ww, int ty, int tx);

/* Windows of a height x width frame under o (lm_tile_positions on both axes), raster order. */
int lm_auto_window_count(int height, int width, const lm_tile_opts *o);
/* Difficulty of every window into d (lm_auto_window_count entries), raster order; OpenMP over
 * windows with nthreads (0 = default); "noise": the frame's level in every entry (0 for a frame
 * without positive signal). Errors: those of lm_tile_check; "noise" on a frame too small for
 * the estimate (LM_ERR_SHAPE) or with NaN / inf (LM_ERR_NUMERIC). */
lm_status lm_auto_frame_difficulty(lm_auto_measure m, const float *frame, int height, int width,
                                   int ty, int tx, const lm_tile_opts *o, int nthreads,
                                   double *d, lm_err *err);

typedef struct lm_auto_model {
    char path[1024];                 /* the model as given to calibration */
    char preset[64];
    char label[128];                 /* for tables: the preset, or where two models share
                                      * it, the run folder or file name (lm_auto_label) */
    double cost;                     /* seconds per window (lower = cheaper), > 0 */
    double macs;                     /* multiply-adds per window (information only) */
    double psnr[LM_AUTO_MAX_BINS];   /* expected PSNR (dB) per difficulty bin */
} lm_auto_model;

typedef struct lm_auto_calib {
    lm_auto_measure measure;
    int win_h, win_w, stride_y, stride_x;   /* the windows calibrated on */
    int nbins, nmodels;
    double edges[LM_AUTO_MAX_BINS];         /* nbins - 1 ascending inner bin edges */
    long windows[LM_AUTO_MAX_BINS];         /* calibration windows per bin */
    lm_auto_model models[LM_AUTO_MAX_MODELS];
} lm_auto_calib;

/* Every model's label: its preset when no other model of the calibration has it, else its
 * path's run folder (".../RUN/model.safetensors", ".../RUN") or file name without
 * ".safetensors". lm_auto_load and lm_auto_fit call it. */
void lm_auto_label(lm_auto_calib *a);

/* Bin of difficulty d: the number of edges <= d (0..nbins-1). */
int lm_auto_bin(const lm_auto_calib *a, double d);
/* choice[b] = index of the model chosen for bin b (see the header comment; ties in cost go to
 * the higher PSNR, then the lower index). tol_db >= 0. */
void lm_auto_choose(const lm_auto_calib *a, double tol_db, int *choice);
/* Expected PSNR over the calibration windows (bins weighted by their window counts) when bin b
 * uses model choice[b]; choice NULL = model `model` everywhere. */
double lm_auto_expected_psnr(const lm_auto_calib *a, const int *choice, int model);

/* Fit edges, windows and psnr from n samples: difficulty d[i] and mse[m * n + i] for the
 * a->nmodels models (their path / preset / cost / macs set by the caller, kept). nbins_max
 * (1..LM_AUTO_MAX_BINS) quantile bins; fewer when difficulties repeat (edges strictly
 * increase). Errors (LM_ERR_ARG, "auto:"): n < nbins_max, no models, bad nbins_max. */
lm_status lm_auto_fit(lm_auto_calib *a, const double *d, const double *mse, long n,
                      int nbins_max, lm_err *err);

/* Validate a calibration (what lm_auto_load checks): 1..LM_AUTO_MAX_MODELS models with
 * positive finite costs, 1..LM_AUTO_MAX_BINS bins, strictly increasing finite edges, finite
 * PSNRs, positive window / stride sizes. LM_ERR_FORMAT with a message starting "auto:". */
lm_status lm_auto_validate(const lm_auto_calib *a, lm_err *err);
/* JSON: {"version": 1, "measure", "window": [h, w], "stride": [y, x], "edges": [...],
 * "windows": [...], "models": [{"model", "preset", "cost_s_per_window", "macs_per_window",
 * "psnr": [...]}]}. save: LM_ERR_IO; load: LM_ERR_IO (missing / unreadable), LM_ERR_FORMAT
 * (not JSON, wrong version, missing or bad fields); messages name the file. */
lm_status lm_auto_save(const char *path, const lm_auto_calib *a, lm_err *err);
/* lm_auto_save plus the members of `extra` (a jansson object, not consumed; NULL = none) added
 * to the root, e.g. calibrate's "test" measurement. lm_auto_load ignores unknown members. */
struct json_t;
lm_status lm_auto_save_ext(const char *path, const lm_auto_calib *a, struct json_t *extra,
                           lm_err *err);
/* load: a relative model path is the calibration file's folder's when it names something there
 * (a calibration shipped beside its models), else the working folder's. */
lm_status lm_auto_load(const char *path, lm_auto_calib *a, lm_err *err);

/* Calibration samples of one scene: frame (the coded frame, as for lm_auto_fold), truth (31 x
 * height x width, 400..700 nm), the nmodels models (33 output channels, the same tile and
 * buckets). For window i (raster order under o): d[i] difficulty, mse[m * nwin + i] the
 * K-weighted MSE of model m's window output (channels 1..31) against the truth window;
 * secs[m] += model m's network seconds (may be NULL). c must hold no tensors. */
lm_status lm_auto_scene(lm_ctx *c, lm_model *const *models, int nmodels, lm_auto_measure meas,
                        const float *frame, const float *truth, int height, int width,
                        const lm_tile_opts *o, double *d, double *mse, double *secs,
                        lm_err *err);

/* Fold with model win_model[i] for window i (raster order under o; o->batch = the per-model
 * network batch), out_ch x height x width into out (every model must return out_ch channels).
 * The models read the same frames: one-bucket models a height x width frame, two-bucket ones
 * bucket 1 then bucket 0 / (LEDs - 1), 2 x height x width (lm_tile_infer's layout); the
 * difficulty and the noise level are read from bucket 1 (the first plane).
 * windows[m] (may be NULL) += windows run by model m. Errors: those of lm_tile_fold;
 * LM_ERR_ARG for a bad model index or models with different tiles or buckets. */
lm_status lm_auto_fold(lm_ctx *c, lm_model *const *models, int nmodels, const int *win_model,
                       const float *frame, int height, int width, const lm_tile_opts *o,
                       int out_ch, float *out, long *windows, lm_err *err);
/* The calibrated choice on one frame, as `infer --model auto` and `eval --auto` run it: the
 * calibration's windows and strides (fitted to the frame, lm_tile_fitted; o gives the batch),
 * every window's difficulty (a->measure), the model choice[its bin], lm_auto_infer. *nwin
 * (may be NULL) = the frame's windows; windows[m] (may be NULL) += those model m ran. */
lm_status lm_auto_run(lm_ctx *c, const lm_auto_calib *a, const int *choice,
                      lm_model *const *models, const float *frame, int height, int width,
                      const lm_tile_opts *o, lm_cube *cube, int *nwin, long *windows,
                      lm_err *err);
/* lm_auto_fold, then channels 1..31 as a 31-band cube (allocated here), as lm_tile_infer. */
lm_status lm_auto_infer(lm_ctx *c, lm_model *const *models, int nmodels, const int *win_model,
                        const float *frame, int height, int width, const lm_tile_opts *o,
                        lm_cube *cube, long *windows, lm_err *err);

#endif
