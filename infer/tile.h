/* tile.h — patch-wise inference (system.md §8): a coded frame is cut into overlapping windows
 * (66 x 64, stride 30 x 32 by default) whose top-left corners lie on the mosaic tile grid, plus
 * windows flush with the bottom / right edges (still on the grid) where the regular grid does not
 * reach them. Windows run through a network in batches; each window's output is multiplied by a
 * fixed weighting kernel K, accumulated, and divided by the accumulated K.
 *
 * K is separable: K(i, j) = k_h(i) * k_w(j) with k_n(i) = f + (1 - f) * sin^2(pi (i + 0.5) / n),
 * f = LM_TILE_FLOOR (0.05). It is a raised cosine (Hann) that is highest in the centre and falls
 * to f (small but non-zero) at the edges, so every covered pixel has a positive weight sum and
 * pixels near a window's border — where the demosaic interpolates differently than in the whole
 * frame — count little where another window covers them better.
 *
 * Windows are folded in raster order of their positions whatever the batch size, so the result
 * does not depend on the batch size (given a network whose per-sample output does not depend on
 * the batch). The lm_ctx passed in is used as the per-batch arena: it is lm_ctx_reset after every
 * batch (peak memory is bounded by one batch of windows, not the frame), so the caller must hold
 * no tensors in it. Grad mode is switched off for the call and restored afterwards.
 * What it is not: model loading (infer/model_io.h) or temporal alignment (data/flow.h). */
#ifndef LM_TILE_H
#define LM_TILE_H
#include "data/cube.h"
#include "models/model.h"

#define LM_TILE_FLOOR 0.05f

typedef struct lm_tile_opts {
    int win_h, win_w;       /* window size (66 x 64); multiples of the tile */
    int stride_y, stride_x; /* window stride (30, 32); multiples of the tile */
    int batch;              /* windows per network call (>= 1) */
} lm_tile_opts;

/* 66 x 64, stride (30, 32), batch 8. */
void lm_tile_default_opts(lm_tile_opts *o);

/* The smallest frame patch-wise inference takes, in tiles each way (the noise estimate needs
 * 3 x 3 samples of each phase). */
#define LM_TILE_MIN_TILES 3

/* Validate the options and the frame size for a tile of ty x tx pixels: window and stride
 * multiples of the tile and > 0, frame size a multiple of the tile, at least
 * LM_TILE_MIN_TILES tiles each way and >= the window (lm_tile_fitted shrinks the window to a
 * smaller frame). Errors: LM_ERR_ARG (options) / LM_ERR_SHAPE (frame), message starting
 * "tile:". */
lm_status lm_tile_check(const lm_tile_opts *o, int height, int width, int ty, int tx,
                        lm_err *err);

/* o with the window cut to the frame along an axis where the frame is smaller (one window
 * covers it there; the stride no longer than the window). A frame that is a multiple of the
 * tile keeps the window a multiple of it. Every patch-wise path fits its options so. */
lm_tile_opts lm_tile_fitted(const lm_tile_opts *o, int height, int width);

/* Window start positions along one axis of length n: 0, stride, 2 stride, ... while the window
 * fits, then n - win if the last one does not end at n. Writes up to max positions into pos
 * (may be NULL) and returns the count (needs n >= win). */
int lm_tile_positions(int n, int win, int stride, int *pos, int max);

/* The weighting kernel for one axis of length n (see above): k[i], i < n. */
void lm_tile_kernel_1d(int n, float *k);

/* A network on a batch: raw B x 1 x h x w in, B x C x h x w out (C = out_ch of lm_tile_fold),
 * or NULL with the ctx error set. */
typedef lm_tensor *(*lm_tile_fn)(lm_ctx *c, lm_tensor *raw, void *user);

/* Fold: run fn over every window of frame (height x width, row-major) and write the K-weighted
 * average into out (out_ch x height x width). Errors: those of lm_tile_check, a wrong output
 * shape from fn (LM_ERR_SHAPE), the ctx error of fn (its status and message). */
lm_status lm_tile_fold(lm_ctx *c, const float *frame, int height, int width, int ty, int tx,
                       const lm_tile_opts *o, lm_tile_fn fn, void *user, int out_ch,
                       float *out, lm_err *err);

/* Seconds spent by lm_tile_fold_timed in each stage (added to, not reset). */
typedef struct lm_tile_timing {
    double gather;    /* window extraction into the batch buffer */
    double network;   /* fn on the batches, including the upload and the read-back */
    double fold;      /* K-weighted accumulation and the final division by the sum of K */
    int windows, batches;
} lm_tile_timing;

/* lm_tile_fold, adding the time of each stage into *t (NULL: no timing; same result). */
lm_status lm_tile_fold_timed(lm_ctx *c, const float *frame, int height, int width, int ty,
                             int tx, const lm_tile_opts *o, lm_tile_fn fn, void *user,
                             int out_ch, float *out, lm_tile_timing *t, lm_err *err);

/* lm_tile_fold_timed on a frame of `planes` planes (1 or 2; planes x height x width, plane
 * after plane): every window holds the same region of each plane, fn gets B x planes x h x w. */
lm_status lm_tile_fold_planes(lm_ctx *c, const float *frame, int planes, int height, int width,
                              int ty, int tx, const lm_tile_opts *o, lm_tile_fn fn, void *user,
                              int out_ch, float *out, lm_tile_timing *t, lm_err *err);

/* A model on a whole frame: lm_tile_fold with lm_model_forward, then channels 1..31 (400-700 nm)
 * of the 33-channel output as a 31-band cube (allocated here; lm_cube_free). A two-bucket model
 * (lm_model_buckets 2) takes frame = bucket 1 then bucket 0 / (LEDs - 1), 2 x height x width;
 * the noise level is read from bucket 1. */
lm_status lm_tile_infer(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                        const lm_tile_opts *o, lm_cube *cube, lm_err *err);

/* A model running on a compute device for a whole run (the CLI's --device): the backend is
 * opened once, the run's ctx switched to it, and the model's parameters are copied to the
 * device once (lm_tensors_swap_to_device into a ctx of their own that is never reset), so every
 * batch of lm_tile_fold / lm_tile_infer on that ctx runs there without re-uploading them.
 * For "cpu" nothing moves. The model and the ctx must outlive the device; close it before
 * freeing them (it puts the host parameters back and the ctx back on the CPU). */
typedef struct lm_tile_device {
    lm_backend *backend;     /* NULL when not open */
    lm_ctx pctx;             /* holds the device copies of the parameters */
    lm_ctx *ctx;             /* the run's ctx, switched to backend */
    lm_tensor **ps, *held;   /* the swapped parameters and their host structs */
    int np, have_pctx;
} lm_tile_device;

/* Open device `name` ("cpu", "opencl"; NULL or "" = env LM_DEVICE, else cpu) for model m and
 * ctx c (which must hold no tensors). Errors (d left closed): LM_ERR_ARG for an unknown name,
 * LM_ERR_UNSUPPORTED when no OpenCL platform exists, LM_ERR_BACKEND / LM_ERR_NOMEM otherwise;
 * messages start with "device". */
lm_status lm_tile_device_open(lm_tile_device *d, const char *name, lm_model *m, lm_ctx *c,
                              lm_err *err);
/* "cpu", or the OpenCL device's name. */
/* The same for several models run by one ctx (`infer --model auto`): every model's parameters
 * are on the device for the run. */
lm_status lm_tile_device_open_models(lm_tile_device *d, const char *name, lm_model *const *ms,
                                     int nm, lm_ctx *c, lm_err *err);
const char *lm_tile_device_name(const lm_tile_device *d);
/* Parameters back on the host, c back on the CPU backend, the backend closed. Idempotent. */
void lm_tile_device_close(lm_tile_device *d);

#endif
