/* rgbcam.h — an RGB camera's forward model, for the passive RGB baseline (MST++): a 31-band
 * reflectance cube (400..700 nm, 10 nm) -> a linear RGB image, with the sensor noise options of
 * system.md §4 (data/forward.h).
 * Model: RGB_c(p) = g_c * sum_b S_c(b) E(b) r_p(b), with S_c the camera's spectral sensitivity
 * and E the illuminant, both integrated over each 10 nm bin (trapezoid, system.md §3), and g_c
 * the white balance that makes a perfect white reflector (r = 1) give (1, 1, 1) — the same
 * normalisation as the coded system, whose LED gains make white respond 1.0. Illuminant: D65
 * (default; a passive camera in daylight) or equal energy. Only the 400..700 nm bands enter: the
 * datasets have no data outside them (the coded system's mirrored 380/390, 710..780 bins are a
 * training-target device, not scene data).
 * What it is not: demosaicking (the image is a full 3-channel image, as MST++ expects),
 * colour rendering (data/srgb.h), or anything differentiable. */
#ifndef LM_RGBCAM_H
#define LM_RGBCAM_H
#include "data/forward.h"

#define LM_RGBCAM_BANDS 31   /* 400..700 nm */
#define LM_RGBCAM_DEFAULT_CSV "spectra/camera_rgb_sensitivity_Nikon_5100_NPL.csv"

typedef enum lm_rgbcam_illum {
    LM_RGBCAM_D65 = 0,
    LM_RGBCAM_EQUAL_ENERGY = 1
} lm_rgbcam_illum;

typedef struct lm_rgbcam {
    double bin[3][LM_RGBCAM_BANDS]; /* integral of S_c E over each bin (before white balance) */
    float w[3][LM_RGBCAM_BANDS];    /* weights g_c * bin: each row sums to 1 */
    lm_rgbcam_illum illum;
} lm_rgbcam;

/* Load sensitivities from a CSV (wavelength, R, G, B columns named R, G, B; NULL = the bundled
 * Nikon D5100 table) and bin them under the illuminant. Errors name the file (missing columns,
 * a channel with no response in 400..700 nm). */
lm_status lm_rgbcam_load(lm_rgbcam *cam, const char *csv_path, lm_rgbcam_illum illum,
                         lm_err *err);
/* Noise-free: cube = 31 planes of H x W (band-major, e.g. channels 1..31 of a 33-channel
 * target), rgb = 3 planes of H x W. OpenMP over rows (nthreads 0 = default). */
void lm_rgbcam_render(const lm_rgbcam *cam, const float *cube, int H, int W, float *rgb,
                      int nthreads);
/* Render, then apply lm_forward_noise to the image as a whole (the three planes as one
 * 3H x W image: the Gaussian sigma is k x the largest clean value over all channels; full
 * scale = white = 1). rng may be NULL when no noise is on. */
lm_status lm_rgbcam_simulate(const lm_rgbcam *cam, const float *cube, int H, int W,
                             const lm_noise_opts *noise, lm_rng *rng, float *rgb, int nthreads,
                             lm_err *err);

#endif
