/* eval.h — evaluation of a trained model (system.md §10), the library half of `lumosaic eval`.
 * What it is: preparing a ground-truth cube (crop to the mosaic tile, normalise by its own
 * maximum), simulating its coded frame at given Gaussian noise levels k (sigma = k x the largest
 * clean value, §4) from an explicit generator, reconstructing with lm_tile_infer and scoring
 * PSNR / SSIM / MAE / SAM on the 31 bands (data/metrics.h); and the rainbow test (§7): per row
 * the recovered peak wavelength (parabolic interpolation around the largest band of the
 * row-averaged reconstructed spectrum) against the row's true peak.
 * Motion: the prepared cube translating at a given speed in a fixed direction is simulated as
 * a short coded video (data/video.h, §5 timing, noise-free), and its middle frame is
 * reconstructed with and without temporal alignment (data/align.h), both scored against the
 * scene at that frame's lime instant, on the region that stays in view over the video, beside
 * the static reference (that scene as a still frame).
 * RGB models (in_channels 3: the passive MST++ baseline) see the same cube through an RGB
 * camera (data/rgbcam.h: Nikon D5100, D65, white balanced; noise k x the largest clean value of
 * the three channels) and reconstruct the whole frame (lm_mst_reconstruct). In the motion test
 * an RGB camera has no LED sub-images: its frame is the scene averaged over the middle frame's
 * exposure (LM_VIDEO_DEFAULT_SAMPLES instants per LED, at most LM_VIDEO_MAX_SAMPLES, equally
 * spaced over lm_system_exposure_us from the frame's start; noise-free), scored against the same
 * lime-instant truth; there is nothing to align, so aligned = unaligned.
 * Reconstructions are scored as the network returns them (no clamping).
 * What it is not: scene listing and the run over scenes (infer/eval_run.h), file output
 * (infer/eval_write.h) or printing (cli/cmd_eval.c). */
#ifndef LM_EVAL_H
#define LM_EVAL_H
#include "data/cube.h"
#include "data/forward.h"
#include "data/align.h"
#include "data/flow.h"
#include "infer/model_io.h"
#include "infer/tile.h"
#include "tensor/rng.h"
#include "data/metrics.h"

#define LM_EVAL_MAX_NOISE 16

/* In place: keep the top-left (H - H % ty) x (W - W % tx) pixels, divide by the cube's
 * maximum. The cube must have 31 bands at 400..700 nm. Errors: LM_ERR_SHAPE (bands, or smaller
 * than one tile), LM_ERR_NUMERIC (maximum 0 or not finite), LM_ERR_NOMEM; messages start with
 * "eval:". */
lm_status lm_eval_prepare(lm_cube *cube, int ty, int tx, lm_err *err);

/* The sensor frame a model takes, simulated from a prepared 31-band cube (lm_eval_prepare):
 * coded models (in_channels 1): the coded frame of im->sys (H x W, lm_forward_simulate31);
 * RGB models (in_channels 3): the RGB camera image (3 x H x W planar, data/rgbcam.h, bundled
 * Nikon D5100 under D65); multi-frame models (LM_CAP_MULTI_FRAME): the cube as a still video
 * of three frames, each with its own noise (drawn in frame order from rng), stacked by
 * lm_align_stack_frames (data/align.h: the medium flow, the frames as recorded when the
 * sub-images are below its minimum), 3 x H x W. noise: NULL = none; rng: the noise stream (copied, not advanced; NULL
 * only without noise). *frame is malloc'ed (NULL on error), *n its element count. OpenMP
 * default thread count. Errors: LM_ERR_SHAPE (not 31 bands), LM_ERR_ARG (other in_channels),
 * those of the forward / camera models, LM_ERR_NOMEM. */
lm_status lm_eval_simulate(const lm_infer_model *im, const lm_cube *truth,
                           const lm_noise_opts *noise, const lm_rng *rng, float **frame,
                           size_t *n, lm_err *err);

/* A 31-band cube (400..700 nm, allocated here; lm_cube_free) from a frame of lm_eval_simulate's
 * layout: coded models through lm_tile_infer (to: window options) — or lm_whole_infer when
 * `whole` is non-zero and the model declares a receptive field (lm_whole_halo > 0); models
 * with LM_CAP_WHOLE_FRAME (MST++: the RGB "mst", "mst-tiny", and the coded "mst-coded", whose
 * global attention has no windows) through lm_mst_reconstruct on the whole frame with lm_nthreads(c)
 * threads (in its own ctx; `to` and `whole` unused). A coded frame of a system whose gains
 * differ from the model's (im->remap active, infer/raw.h) is rescaled per tile phase first,
 * the model's given noise level converted with it. c must hold no tensors. Errors: those of
 * the inference paths; LM_ERR_ARG for a model that is neither coded nor MST++. */
lm_status lm_eval_reconstruct(lm_ctx *c, const lm_infer_model *im, const float *frame,
                              int height, int width, const lm_tile_opts *to, int whole,
                              lm_cube *out, lm_err *err);

/* Score the model on a prepared 31-band cube at each noise level k[i] (fractions, 0.1 = 10 %):
 * level k draws from lm_rng_split(rng, round(k * 1e6)), the same noise whatever the list.
 * out[i] receives the metrics. c must hold no tensors (lm_tile_infer resets it). Simulation
 * and reconstruction as lm_eval_simulate / lm_eval_reconstruct (whole 0), with lm_nthreads(c)
 * threads. Errors: those of the forward model, lm_eval_reconstruct and the metrics;
 * LM_ERR_ARG for nnoise outside 1..LM_EVAL_MAX_NOISE or a negative k. */
lm_status lm_eval_scene(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                        const float *k, int nnoise, const lm_tile_opts *to, const lm_rng *rng,
                        lm_metrics *out, lm_err *err);

/* One level k of lm_eval_scene, the same noise (lm_rng_split(rng, round(k * 1e6))) and
 * metrics (*out), keeping the reconstruction: *pred is allocated here (lm_cube_free), as the
 * network returned it (not clamped). Errors: as lm_eval_scene. */
lm_status lm_eval_scene_one(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth, float k,
                            const lm_tile_opts *to, const lm_rng *rng, lm_metrics *out,
                            lm_cube *pred, lm_err *err);

/* lm_eval_scene that also returns, per noise level, the seconds the reconstruction of the
 * frame took (seconds[i], NULL-able; simulation and scoring not counted). */
lm_status lm_eval_scene_timed(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                              const float *k, int nnoise, const lm_tile_opts *to,
                              const lm_rng *rng, lm_metrics *out, double *seconds, lm_err *err);

/* Was the scene at path (a file or a CAVE folder) among the model's training scenes, by
 * content (lm_scene_content_hash in im->train_scenes)? 1 yes, 0 no, -1 unknown (the model
 * records no training scenes). */
int lm_eval_trained_on(const lm_infer_model *im, const char *path);

/* Peak wavelength of a spectrum sampled at wl0 + i * step (i < n): the largest sample m (first
 * one on ties), refined by the vertex of the parabola through m - 1, m, m + 1 when both
 * neighbours exist and the parabola is concave; else wl0 + m * step. */
double lm_eval_peak_nm(const float *spec, int n, double wl0, double step);

/* Direction of the simulated translation (a unit vector: 3-4-5). */
#define LM_EVAL_MOTION_DIR_X 0.8
#define LM_EVAL_MOTION_DIR_Y 0.6
#define LM_EVAL_MAX_MOTION 16
#define LM_EVAL_MAX_MOTION_NOISE 4
/* Frames of the motion test's video; the middle one is scored. */
#define LM_EVAL_MOTION_FRAMES 3
/* Mosaic tiles added to the motion margin for the filters' support (one for the bilinear
 * demosaic, one for the flow's smoothing across the last in-view pixels). */
#define LM_EVAL_MOTION_SUPPORT_TILES 2

/* The region of an H x W scene scored in the motion test: what the camera sees in every frame
 * of the video. Content moving at `speed` px/s along the test's direction enters and leaves
 * the view over the video's span, frame_period_us x (LM_EVAL_MOTION_FRAMES - 1); there the
 * simulator can only repeat the border (nothing real to align or reconstruct). The margin on
 * each side is ceil(|v_x| x span) + LM_EVAL_MOTION_SUPPORT_TILES x tile_cols columns, and
 * ceil(|v_y| x span) + LM_EVAL_MOTION_SUPPORT_TILES x tile_rows rows; a still scene keeps the
 * support margin too, so every speed is scored the same way. *y0, *x0: the region's top-left;
 * *h, *w its size (0 when the margins leave nothing). */
void lm_eval_motion_region(const lm_system *sys, double speed, int height, int width, int *y0,
                           int *x0, int *h, int *w);

typedef struct lm_eval_motion {
    double speed;          /* px/s along (LM_EVAL_MOTION_DIR_X, LM_EVAL_MOTION_DIR_Y) */
    double noise;          /* noise level k of the frames (0 = none) */
    double px_per_frame;   /* speed x frame period: the displacement between frames */
    int y0, x0, height, width; /* the scored region (lm_eval_motion_region) */
    lm_metrics still;      /* the static reference: the still scene that frame 1's truth shows,
                            * simulated and reconstructed (what a still camera would score) */
    lm_metrics aligned;    /* frame 1 aligned with frames 0 and 2, then reconstructed */
    lm_metrics unaligned;  /* frame 1 reconstructed as recorded */
} lm_eval_motion;

/* Frames 0, 1, 2 of the prepared 31-band cube moving at `speed` px/s (mirrored to the
 * system's 41-bin grid, lm_video_frame with the default motion-blur samples, no noise); the
 * truth is frame 1's scene at its lime instant (bands 400..700 nm). All three scores are taken
 * over lm_eval_motion_region only. The static reference simulates the truth itself as a still
 * frame: at speed 0 it equals the unaligned score exactly; at other speeds it is the score the
 * moving frames would reach if motion cost nothing (the simulator's sub-pixel resampling
 * smooths the moving scene, so the speed-0 score is not that reference). fo: flow options
 * (NULL = medium preset with lm_nthreads(c) threads; unused for RGB models, see above); ao:
 * alignment options (NULL = lm_align_default_opts). c must hold no tensors. Errors:
 * LM_ERR_ARG for a negative or non-finite speed; LM_ERR_SHAPE when the scored region is
 * smaller than the SSIM window (the scene is too small for that speed); those of the video
 * model, the alignment (sub-images smaller than lm_flow_min_size: LM_ERR_SHAPE), lm_tile_infer
 * and the metrics. */
lm_status lm_eval_motion_run(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                             double speed, const lm_tile_opts *to, const lm_flow_opts *fo,
                             const lm_align_opts *ao, lm_eval_motion *out, lm_err *err);

/* The same with noise level k (a fraction, as lm_eval_scene's; k = 0 is lm_eval_motion_run):
 * each of frames 0, 1, 2 gets its own Gaussian draw, k x its own maximum (with the model's
 * sensor options, as eval_one), from lm_rng_split(rng, round(k * 1e6)) in frame order, then the
 * still reference (a still frame, or for a multi-frame model three still frames) from the same
 * generator. rng NULL = seed 0. Multi-frame models (LM_CAP_MULTI_FRAME): "aligned" reads
 * lm_align_stack's input (frame 1 aligned, frames 0 and 2 moved onto it), "unaligned" frames
 * 1, 0, 2 as recorded. RGB models: k must be 0. */
lm_status lm_eval_motion_run_noise(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                                   double speed, float k, const lm_rng *rng,
                                   const lm_tile_opts *to, const lm_flow_opts *fo,
                                   const lm_align_opts *ao, lm_eval_motion *out, lm_err *err);

#define LM_EVAL_RAINBOW_MAX_ROWS 4096

typedef struct lm_eval_rainbow {
    int size;                 /* the scene simulated: size x size */
    int height, width;        /* after cropping to the tile */
    double mean_err_nm;       /* mean over rows of |recovered peak - true peak| */
    double max_err_nm;
    int worst_row;
    lm_metrics m;             /* metrics of the reconstruction against the rainbow */
    /* per row y < min(height, LM_EVAL_RAINBOW_MAX_ROWS): the true and the recovered peak */
    float row_true_nm[LM_EVAL_RAINBOW_MAX_ROWS], row_peak_nm[LM_EVAL_RAINBOW_MAX_ROWS];
} lm_eval_rainbow;

/* The rainbow test without noise: lm_synth_rainbow(size, size) cropped to the tile (rows kept
 * from the top, each row's truth lm_synth_rainbow_peak(y, size)), simulated, reconstructed.
 * Errors: those of the parts; LM_ERR_ARG for size < 2. */
lm_status lm_eval_rainbow_run(lm_ctx *c, const lm_infer_model *im, int size,
                              const lm_tile_opts *to, lm_eval_rainbow *out, lm_err *err);

#endif
