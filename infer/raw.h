/* raw.h — what a camera's frame must become before a trained model reads it.
 * What it is: the gain remap — a model trained for one system description reading frames of
 * another system of the same LEDs, sensor and tile map whose LED gains differ (a calibrated
 * system, `lumosaic calibrate`). Each pixel integrates exactly one LED, so such a frame differs
 * from the frame the model's system would record by the factor a0_l / a_l (the ratio of the two
 * systems' responses of LED l, a constant over wavelength when only gains and allocations
 * differ) per tile phase: the frame is multiplied by it phase by phase, and the noise, whose sd
 * is scaled the same way per phase, is summarised by the root mean square of the factors over
 * the phases.
 *
 * And the raw-frame conventions: what a camera's file holds and how it becomes the frame the
 * system describes, where 1.0 is full scale (the brightest LED's response to a perfect white
 * reflector with the bundled equal-white gains; system.h). Integer files are read as codes
 * (data/frames.h reads them as code / (2^file_bits - 1)); with `bits` B < the file's bits the
 * data is B-bit, either LSB-aligned (codes 0 .. 2^B - 1, the usual 12-bit-in-16-bit layout) or
 * MSB-aligned (codes shifted up by file_bits - B, low bits zero); either way code 2^B - 1 is
 * full scale. Then, in this order:
 *   black level V (in B-bit codes): x = (code - V) / (2^B - 1 - V);
 *   dark frames (averaged, read the same way): x = (x - D_p) / (1 - mean D), per pixel p;
 *   flat frame (a white target, averaged, read and darkened the same way): x / (F_p / mean of
 *   F over p's tile phase) — per-pixel gain and illumination fall-off, each LED's own level
 *   (its phase's mean) kept. Pixels of the flat under 5 % of their phase's mean (dead, or not
 *   lit) are left uncorrected.
 * Saturated pixels: those at the largest code (2^B - 1 in B bits; float files: >= 1.0), counted
 * on the file before any correction.
 * What it is not: model loading (infer/model_io.h: it decides when a remap is needed) or the
 * calibration itself (data/calib.h). */
#ifndef LM_RAW_H
#define LM_RAW_H
#include <stddef.h>
#include <stdint.h>
#include "data/frames.h"
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

typedef struct lm_raw_opts {
    int bits;            /* significant bits of integer files (0: the file's own) */
    int msb;             /* 1: MSB-aligned in the file, 0: LSB-aligned (with bits) */
    double black;        /* black level in `bits` codes (0: none) */
    const char *dark;    /* dark frame(s): a file, pattern or folder (NULL: none) */
    const char *flat;    /* white-target frame(s), the same (NULL: none) */
} lm_raw_opts;

typedef struct lm_raw {
    lm_raw_opts o;
    int height, width, ty, tx;
    float *dark;         /* averaged dark frame (converted), NULL: none */
    float dark_mean;
    float *gain;         /* per-pixel gain from the flat, NULL: none */
    long flat_skipped;   /* flat pixels left uncorrected (under 5 % of their phase's mean) */
} lm_raw;

/* Does o change anything (any option set)? */
int lm_raw_opts_any(const lm_raw_opts *o);

/* Prepare the conversion for frames of height x width on a ty x tx tile: read and average the
 * dark and flat frames (each converted as above). Errors (message names the file): those of
 * the frame reader, LM_ERR_SHAPE (a dark or flat frame of another size), LM_ERR_ARG (bits
 * outside 1..16, a black level at or above full scale, a flat whose phase mean is not
 * positive, a flat with saturated pixels over 1 %), LM_ERR_NOMEM. *r is zeroed on failure. */
lm_status lm_raw_init(lm_raw *r, const lm_raw_opts *o, int height, int width, int ty, int tx,
                      lm_err *err);
void lm_raw_free(lm_raw *r);

/* In place: f (as lm_frame_read returns it) converted to the system's scale. Errors
 * (LM_ERR_FORMAT, "<path>: ..."): bits with a float file or a file of fewer bits, LSB-aligned
 * codes above 2^B - 1 (MSB-aligned data?), MSB-aligned codes with non-zero low bits
 * (LSB-aligned data?). */
lm_status lm_raw_apply(const lm_raw *r, lm_frame *f, const char *path, lm_err *err);

/* The share of f's pixels at full scale (f as read, before lm_raw_apply); mask (NULL-able,
 * height x width) gets 1 for each saturated pixel, else 0. */
double lm_raw_saturated(const lm_raw_opts *o, const lm_frame *f, uint8_t *mask);

/* One line (no newline) saying that frames of `camera` are rescaled to the gains of `model_sys`
 * (the files' names), with the range of the factors and the noise factor. */
void lm_gain_remap_describe(const lm_gain_remap *g, const char *camera, const char *model_sys,
                            char *buf, size_t n);

#endif
