/* whole.h — whole-frame inference for purely convolutional models with a finite receptive
 * field (the linear baseline, the rt family): the frame runs through the model in horizontal
 * strips of full width, each read with a halo of rows above and below that covers the model's
 * receptive field, and only the strip's own rows are kept. The result equals one forward pass
 * over the whole frame (up to float summation order inside the convolutions), with the memory
 * of one strip instead of the frame, and without the ~4.4x pixel overlap of the §8 windows
 * (infer/tile.h), which real-time inference cannot pay.
 *
 * The receptive field is declared by the model (lm_model.conv_rows, lm_whole_halo): the demosaic reads
 * sample rows less than one tile row (ty) away, and each k x k convolution (stride 1) adds
 * (k - 1) / 2 rows. Strips and halos are multiples of ty, so every strip keeps the frame's
 * mosaic phase. Models with global context (attention, global pooling: han, mcan, srnet) have
 * no finite receptive field and are refused (use infer/tile.h).
 *
 * On a ctx with a device backend (the model's parameters on the device, lm_tile_device_open)
 * each strip runs on the device and is read back.
 * The lm_ctx passed in is the per-strip arena: it is lm_ctx_reset after every strip, so the
 * caller must hold no tensors in it. Grad mode is off during the call and restored afterwards.
 * What it is not: patch-wise inference with blending (infer/tile.h) or model loading. */
#ifndef LM_WHOLE_H
#define LM_WHOLE_H
#include "data/cube.h"
#include "models/model.h"

#define LM_WHOLE_STRIP_ROWS 96

typedef struct lm_whole_opts {
    int strip_rows; /* output rows per strip, rounded up to a multiple of ty; 0 = default */
    int halo;       /* context rows each side (multiple of ty); -1 = lm_whole_halo(model).
                     * Smaller than the receptive field breaks the equality (tests use this). */
} lm_whole_opts;

/* strip_rows LM_WHOLE_STRIP_ROWS, halo -1. */
void lm_whole_default_opts(lm_whole_opts *o);

/* Rows of context the model needs each side of a strip, a multiple of the tile height; or -1
 * when the model's receptive field is not finite or not declared (its family is not supported). */
int lm_whole_halo(const lm_model *m);

/* Run the model over frame (height x width, row-major; a two-bucket model's: bucket 1 then
 * bucket 0 / (LEDs - 1), 2 x height x width) in strips and write output channels
 * [ch0, ch0 + nch) into out (nch x height x width). Errors (message starting "whole:"):
 * LM_ERR_ARG for an unsupported model, bad options or channel range; LM_ERR_SHAPE for a frame
 * size that is not a positive multiple of the tile; the model's ctx error otherwise. */
lm_status lm_whole_forward(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                           const lm_whole_opts *o, int ch0, int nch, float *out, lm_err *err);

/* A model on a whole frame with the default options: channels 1..31 (400-700 nm) of the
 * 33-channel output as a 31-band cube (allocated here; lm_cube_free), as lm_tile_infer.
 * A video loop should rather call lm_whole_forward(..., 1, 31, buffer) into a buffer it
 * reuses: first-touching a fresh 31 x 480 x 640 cube costs ~7 ms of page faults per frame. */
lm_status lm_whole_infer(lm_ctx *c, lm_model *m, const float *frame, int height, int width,
                         lm_cube *cube, lm_err *err);

#endif
