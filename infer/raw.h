/* raw.h — what a camera's frame must become before a trained model reads it.
 * What it is: the gain remap — a model trained for one system description reading frames of
 * another system of the same LEDs, sensor and tile map whose LED gains differ (a calibrated
 * system, `lumosaic calibrate`). Each pixel integrates exactly one LED, so such a frame differs
 * from the frame the model's system would record by the factor a0_l / a_l (the ratio of the two
 * systems' responses of LED l, a constant over wavelength when only gains and allocations
 * differ) per tile phase: the frame is multiplied by it phase by phase, and the noise, whose sd
 * is scaled the same way per phase, is summarised by the root mean square of the factors over
 * the phases.
 * What it is not: model loading (infer/model_io.h: it decides when a remap is needed) or the
 * calibration itself (data/calib.h). */
#ifndef LM_RAW_H
#define LM_RAW_H
#include <stddef.h>
#include "data/system.h"
#include "tensor/status.h"

typedef struct lm_gain_remap {
    int active;                       /* 0: frames are read as they are */
    int ty, tx;                       /* the tile */
    float scale[LM_SYSTEM_MAX_TILE];  /* per tile phase t: a0 / a of the LED at t */
    float noise_scale;                /* root mean square of scale over the phases */
    float min, max;                   /* smallest and largest scale */
} lm_gain_remap;

/* The remap from frames of `camera` to the frames `model` (the system a model was trained for)
 * would record. Mappable: the same sensor size, grid, tile map (LED names at every position)
 * and LED names, and each LED's response on the grid a rescaled copy of the model's (same
 * emission and sensor QE; relative tolerance 1e-4); gains and sub-frame allocations may
 * differ. out->active is 1 when any factor differs from 1 by more than 1e-6. Errors
 * (LM_ERR_ARG, *out zeroed): what cannot be mapped, named ("another tile map: position (r, c)
 * holds X, the model's system Y"; "LED 'X' has another emission or sensor QE"; "LED 'X' has
 * no response (gain 0)"). */
lm_status lm_gain_remap_init(const lm_system *model, const lm_system *camera, lm_gain_remap *out,
                             lm_err *err);

/* In into out (may be the same buffer): each of `planes` planes of height x width (a multiple
 * of the tile) multiplied by its phase's factor. k: a noise level given for the raw frame
 * (sigma = k x the first plane's maximum, as lm_model.noise_given); returns the level that
 * describes the rescaled frame (sigma x noise_scale over its first plane's maximum), or k
 * itself when k < 0 (then a noise-reading model estimates it on the rescaled frame). With
 * g->active 0 the frame is copied unchanged. */
float lm_gain_remap_frame(const lm_gain_remap *g, const float *in, int planes, int height,
                          int width, float k, float *out);

/* One line (no newline) saying that frames of `camera` are rescaled to the gains of `model_sys`
 * (the files' names), with the range of the factors and the noise factor. */
void lm_gain_remap_describe(const lm_gain_remap *g, const char *camera, const char *model_sys,
                            char *buf, size_t n);

#endif
