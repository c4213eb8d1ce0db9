/* recon.h — one coded frame to a 31-band cube with a loaded model: the path `lumosaic infer`
 * takes for a fixed model, shared with the public C API (include/lumosaic.h).
 * What it is: the choice between the whole frame in strips (infer/whole.h: models with a
 * finite receptive field, unless patch-wise is asked for) and overlapping windows
 * (infer/tile.h), the frame-size check, and the clamp of network outputs at 0 that every
 * written cube gets. The model's noise level (lm_model.noise_given) is read as the model
 * holds it.
 * What it is not: model loading (infer/model_io.h), temporal alignment (data/align.h), the
 * per-window model choice (infer/auto.h) or file output. */
#ifndef LM_RECON_H
#define LM_RECON_H
#include "data/cube.h"
#include "infer/model_io.h"
#include "models/model.h"

typedef struct lm_recon_opts {
    int batch; /* windows per network call of the patch-wise path (1..4096) */
    int tiles; /* 1: patch-wise even for models that can run on the whole frame */
} lm_recon_opts;

/* batch 8, tiles 0 (as `lumosaic infer`). */
void lm_recon_default_opts(lm_recon_opts *o);

/* Does the model run on the whole frame in strips with these options? */
int lm_recon_is_whole(const lm_model *m, const lm_recon_opts *o);

/* Frame size check against the default windows (66 x 64) and the model's tile: LM_ERR_SHAPE
 * "tile: ..." for a size that is not a multiple of the tile or smaller than a window. */
lm_status lm_recon_check(const lm_model *m, int height, int width, lm_err *err);

/* The model's input for one frame (in_channels planes of height x width: the coded frame; a
 * two-bucket model's bucket 1 then bucket 0 / (LEDs - 1); a multi-frame model's stack) to a
 * 31-band cube (400-700 nm, allocated here; lm_cube_free) by whole-frame strips or windows
 * (lm_recon_is_whole). Values as the network returns them (see lm_recon_clamp). c must hold
 * no tensors. Errors: those of lm_recon_check, lm_whole_infer and lm_tile_infer. */
lm_status lm_recon_frame(lm_ctx *c, lm_model *m, const float *in, int height, int width,
                         const lm_recon_opts *o, lm_cube *cube, lm_err *err);

/* lm_recon_frame for a frame of the camera im->sys describes: when its LED gains differ from
 * the model's (im->remap active, infer/raw.h) the frame is rescaled per tile phase (a copy) and
 * the model's given noise level converted with it for this call; otherwise lm_recon_frame as
 * it is. Errors: those of lm_recon_frame, LM_ERR_NOMEM. */
lm_status lm_recon_camera_frame(lm_ctx *c, const lm_infer_model *im, const float *in,
                                int height, int width, const lm_recon_opts *o, lm_cube *cube,
                                lm_err *err);

/* In place: every value below 0 set to 0 (reflectance is non-negative; the spectral EXR
 * writer refuses negative values). */
void lm_recon_clamp(lm_cube *cube);

#endif
