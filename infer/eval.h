/* eval.h — evaluation of a trained model (system.md §10), the library half of `lumosaic eval`.
 * What it is: preparing a ground-truth cube (crop to the mosaic tile, normalise by its own
 * maximum), simulating its coded frame at given Gaussian noise levels k (sigma = k x the largest
 * clean value, §4) from an explicit generator, reconstructing with lm_tile_infer and scoring
 * PSNR / SSIM / MAE / SAM on the 31 bands (train/metrics.h); and the rainbow test (§7): per row
 * the recovered peak wavelength (parabolic interpolation around the largest band of the
 * row-averaged reconstructed spectrum) against the row's true peak.
 * Motion: the prepared cube translating at a given speed in a fixed direction is simulated as
 * a short coded video (data/video.h, §5 timing, noise-free), and its middle frame is
 * reconstructed with and without temporal alignment (infer/align.h), both scored against the
 * scene at that frame's lime instant.
 * Reconstructions are scored as the network returns them (no clamping).
 * What it is not: scene listing, printing or file output (cli/cmd_eval.c). */
#ifndef LM_EVAL_H
#define LM_EVAL_H
#include "data/cube.h"
#include "infer/flow.h"
#include "infer/model_io.h"
#include "infer/tile.h"
#include "tensor/rng.h"
#include "train/metrics.h"

#define LM_EVAL_MAX_NOISE 16

/* In place: keep the top-left (H - H % ty) x (W - W % tx) pixels, divide by the cube's
 * maximum. The cube must have 31 bands at 400..700 nm. Errors: LM_ERR_SHAPE (bands, or smaller
 * than one tile), LM_ERR_NUMERIC (maximum 0 or not finite), LM_ERR_NOMEM; messages start with
 * "eval:". */
lm_status lm_eval_prepare(lm_cube *cube, int ty, int tx, lm_err *err);

/* Score the model on a prepared 31-band cube at each noise level k[i] (fractions, 0.1 = 10 %):
 * level k draws from lm_rng_split(rng, round(k * 1e6)), the same noise whatever the list.
 * out[i] receives the metrics. c must hold no tensors (lm_tile_infer resets it). Errors: those
 * of the forward model, lm_tile_infer and the metrics; LM_ERR_ARG for nnoise outside
 * 1..LM_EVAL_MAX_NOISE or a negative k. */
lm_status lm_eval_scene(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                        const float *k, int nnoise, const lm_tile_opts *to, const lm_rng *rng,
                        lm_metrics *out, lm_err *err);

/* Peak wavelength of a spectrum sampled at wl0 + i * step (i < n): the largest sample m (first
 * one on ties), refined by the vertex of the parabola through m - 1, m, m + 1 when both
 * neighbours exist and the parabola is concave; else wl0 + m * step. */
double lm_eval_peak_nm(const float *spec, int n, double wl0, double step);

/* Direction of the simulated translation (a unit vector: 3-4-5). */
#define LM_EVAL_MOTION_DIR_X 0.8
#define LM_EVAL_MOTION_DIR_Y 0.6
#define LM_EVAL_MAX_MOTION 16

typedef struct lm_eval_motion {
    double speed;          /* px/s along (LM_EVAL_MOTION_DIR_X, LM_EVAL_MOTION_DIR_Y) */
    lm_metrics aligned;    /* frame 1 aligned with frames 0 and 2, then reconstructed */
    lm_metrics unaligned;  /* frame 1 reconstructed as recorded */
} lm_eval_motion;

/* Frames 0, 1, 2 of the prepared 31-band cube moving at `speed` px/s (mirrored to the
 * system's 41-bin grid, lm_video_frame with the default motion-blur samples, no noise); the
 * truth is frame 1's scene at its lime instant (bands 400..700 nm). fo: flow options (NULL =
 * medium preset with lm_nthreads(c) threads). c must hold no tensors. Errors: LM_ERR_ARG for a
 * negative or non-finite speed; those of the video model, the alignment (sub-images smaller
 * than lm_flow_min_size: LM_ERR_SHAPE), lm_tile_infer and the metrics. */
lm_status lm_eval_motion_run(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                             double speed, const lm_tile_opts *to, const lm_flow_opts *fo,
                             lm_eval_motion *out, lm_err *err);

typedef struct lm_eval_rainbow {
    int size;                 /* the scene simulated: size x size */
    int height, width;        /* after cropping to the tile */
    double mean_err_nm;       /* mean over rows of |recovered peak - true peak| */
    double max_err_nm;
    int worst_row;
    lm_metrics m;             /* metrics of the reconstruction against the rainbow */
} lm_eval_rainbow;

/* The rainbow test without noise: lm_synth_rainbow(size, size) cropped to the tile (rows kept
 * from the top, each row's truth lm_synth_rainbow_peak(y, size)), simulated, reconstructed.
 * Errors: those of the parts; LM_ERR_ARG for size < 2. */
lm_status lm_eval_rainbow_run(lm_ctx *c, const lm_infer_model *im, int size,
                              const lm_tile_opts *to, lm_eval_rainbow *out, lm_err *err);

#endif
