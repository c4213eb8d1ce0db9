/* doe.h — a diffractive optical element (DOE) and its per-wavelength point-spread functions:
 * the optics of the QDO baseline (Li et al., CVPR 2022, "Quantization-aware deep optics for
 * diffractive snapshot hyperspectral imaging"), which the paper compares against.
 * What it is: a versioned JSON description (validated; every error names the field), the height
 * map it defines (quantised to a number of levels), and height map -> PSF on the sensor grid by
 * scalar Fresnel propagation (FFTW).
 * What it is not: the camera (data/qdocam.h convolves a cube with these PSFs and integrates RGB),
 * or a model of a lens other than the thin DOE itself. The differentiable twin of the PSF
 * (tensor ops, gradients to the height map) is lm_doe_psf_t (data/doe_psf.c).
 *
 * Bundled default (data/systems/qdo_default.json): a Fresnel lens of focal length 10 mm designed
 * for 550 nm, aperture 0.64 mm (f/15.6), fused silica, 8 height levels, DOE pitch 2 um, sensor at
 * the 550 nm focus, 4.8 um sensor pixels (Nikon D5100 class), 63 x 63 px PSFs. Why: a
 * diffractive lens is the classic diffractive spectral encoder and a natural starting point for
 * an optimised DOE: its focus moves with wavelength (f(lambda) = f0 lambda0 / lambda); the PSF
 * is nearly diffraction-limited at 550 nm (FWHM ~ 1.03 lambda f / D = 8.9 um ~ 1.9 px) and
 * widens into a defocus disc of D |1 - lambda / lambda0| / p ~ 36 px at 400 and 700 nm, so
 * the RGB image carries a spectral code in the blur. That blur does not depend on f, so the
 * aperture sets it. 8 levels (first-order efficiency sinc^2(1/8) = 95 %) is a level count QDO
 * studies and leaves ~8 DOE pixels per zone at the rim (local period 2 lambda0 f / D = 17 um).
 *
 * File format, version 1 (unknown fields are errors):
 *   "version": 1                                   required
 *   "name", "description": strings                 optional
 *   "aperture_mm": > 0                             circular aperture diameter D
 *   "doe_pitch_um": > 0                            DOE pixel pitch dx
 *   "grid": integer 16..4096                       FFT size N (the aperture is zero-padded); the
 *                                                  cost grows as N^2 log N: simulate on one
 *                                                  thread ~6 s at 1536, ~34 s and 330 MB at 4096;
 *                                                  training keeps ~12 x bands x N^2 floats
 *   "levels": 0 | 2..1024                          height levels (0 = continuous, no quantisation)
 *   "max_height_um": > 0                           optional; default lambda0 / (n(lambda0) - 1),
 *                                                  one 2 pi phase wrap at the design wavelength
 *   "material": {"model": "sellmeier", "B": [3], "C_um2": [3]}   n^2 = 1 + sum B l^2/(l^2 - C)
 *             | {"model": "cauchy", "A": a, "B_um2": b}         n = A + B / l^2 (l in um)
 *             | "fused_silica"  (Malitson 1965 Sellmeier)
 *   "profile": {"type": "fresnel_lens", "focal_mm": f, "design_nm": lambda0}   the height map
 *            | {"type": "height_map", "file": "heights.png"}   a given map: a single-channel
 *              16-bit PNG of m x m samples (m = 2 ceil(D / (2 dx)) + 1, the samples across the
 *              aperture; sample (m/2, m/2) on the axis), value v in [0, 1] = height v hmax,
 *              quantised to `levels` (nearest level, hmax wraps to 0) and zeroed outside the
 *              aperture; the path is relative to the JSON file's folder. An optimised DOE is
 *              written this way (lm_doe_save, `lumosaic train --optimise-doe`).
 *   "sensor_distance_mm": > 0                      DOE-to-sensor distance z
 *   "sensor_pitch_um": > 0                         sensor pixel pitch p
 *   "psf_size": odd integer 3..255                 PSF window in sensor pixels
 * Sampling checks at load (on 400..700 nm): the Fresnel-plane spacing lambda z / (N dx) must be
 * at most p / 2 at 700 nm (else "grid" is too small), its field lambda z / dx must cover the PSF
 * window at 400 nm, and the aperture must fit in the grid.
 *
 * Propagation: single-FFT Fresnel transform. U(u) ~ FFT[ A(x) exp(i 2 pi (n(l) - 1) h(x) / l)
 * exp(i pi |x|^2 / (l z)) ] sampled at u = m l z / (N dx): the sample spacing depends on the
 * wavelength, so each intensity is resampled to the sensor grid by integrating over each sensor
 * pixel (4 x 4 bilinear samples per pixel, an area integral, not a point sample: the sensor
 * integrates light over its pixel; bilinear is accurate because the spacing is <= p / 2). One
 * FFT per wavelength at any z, unlike the angular-spectrum method whose output spacing is dx
 * and would need dx <= p / 2 and a field of the PSF's size. Each PSF is normalised to unit sum
 * over its window (light falling outside the window is dropped). */
#ifndef LM_DOE_H
#define LM_DOE_H
#include <stdio.h>
#include "tensor/op_params.h"
#include "tensor/status.h"

#define LM_DOE_VERSION 1
#define LM_DOE_DEFAULT_FILE "systems/qdo_default.json"
#define LM_DOE_SUPERSAMPLE 4 /* bilinear samples per sensor pixel and axis */

typedef enum lm_doe_material {
    LM_DOE_SELLMEIER = 0,
    LM_DOE_CAUCHY = 1
} lm_doe_material;

/* The largest FFT size a description may ask for (what finishes in reasonable time). */
#define LM_DOE_MAX_GRID 4096

typedef struct lm_doe {
    int version;
    char name[64];
    double aperture_m, pitch_m;     /* D, dx */
    int grid;                       /* N (16..LM_DOE_MAX_GRID) */
    int levels;                     /* 0 = continuous */
    double max_height_m;            /* hmax: heights lie in [0, hmax) */
    lm_doe_material material;
    double coef[6];                 /* Sellmeier B1..B3, C1..C3 (um^2); Cauchy A, B (um^2) */
    int height_map;                 /* profile: 0 = Fresnel lens (focal_m, design_m), 1 = the
                                     * map of height_file */
    double focal_m, design_m;       /* the profile: Fresnel lens f at lambda0 */
    char height_file[1024];         /* height_map: the PNG's path (resolved) */
    double distance_m;              /* z */
    double sensor_pitch_m;          /* p */
    int psf_size;                   /* odd */
    int m;                          /* height map side: samples across the aperture */
    float *height;                  /* m x m heights (metres), 0 outside the aperture */
    unsigned char *mask;            /* m x m aperture (1 inside) */
} lm_doe;

/* Load and validate a description; builds the height map. Errors are one line:
 * "doe file <path>: <field>: <problem>". */
lm_status lm_doe_load(const char *path, lm_doe *doe, lm_err *err);
/* The same from JSON text; label names the source in messages. */
lm_status lm_doe_parse(const char *json_text, const char *label, lm_doe *doe, lm_err *err);
/* The bundled default (data/systems/qdo_default.json). */
lm_status lm_doe_default(lm_doe *doe, lm_err *err);
void lm_doe_free(lm_doe *doe);

/* Write doe (any profile) as a description with a height_map profile: json_path and the PNG
 * png_name (a file name, written into json_path's folder) from doe->height. Atomic writes. */
lm_status lm_doe_save(const lm_doe *doe, const char *json_path, const char *png_name,
                      lm_err *err);

/* A height as a fraction of max_height wrapped into [0, 1) (one 2 pi phase period at the
 * design wavelength) and rounded to the nearest of `levels` levels k / levels (the top one wraps
 * to 0); levels 0: wrapped only. The one rule of every profile and of training (doe_opt.c). */
double lm_doe_quantise(double frac, int levels);

/* Refractive index of the material at a wavelength in metres. */
double lm_doe_index(const lm_doe *doe, double lambda_m);
/* (Re)build the height map from the profile, aperture and levels (after changing any of them
 * in code: tests do; a later optimiser will write `height` itself). */
lm_status lm_doe_build_height(lm_doe *doe, lm_err *err);

/* Fresnel-plane intensity at one wavelength: out = N x N, centred (sample (N/2, N/2) is on
 * axis), spacing *du = lambda z / (N dx). Scaled so that its sum equals *pupil_energy = the sum
 * of |pupil|^2 over the DOE samples (Parseval). Either output pointer may be NULL. */
lm_status lm_doe_fresnel(const lm_doe *doe, double lambda_m, float *out, double *du,
                         double *pupil_energy, lm_err *err);
/* The sensor-plane PSF at one wavelength: psf_size^2 values, row-major, centre pixel on axis,
 * unit sum. */
lm_status lm_doe_psf(const lm_doe *doe, double lambda_m, float *psf, lm_err *err);
/* PSFs for nb wavelengths start_nm + i step_nm (e.g. 400, 10, 31): nb x psf_size^2. */
lm_status lm_doe_psfs(const lm_doe *doe, double start_nm, double step_nm, int nb, float *psfs,
                      lm_err *err);

/* ---- differentiable PSF (data/doe_psf.c) ---- */
/* The PSFs at nb wavelengths (metres; 1..64) as a tensor nb x psf_size x psf_size (each unit
 * sum), from the height map t (m x m, heights as fractions of max_height_m, 0 outside the
 * aperture: the mask applies anyway) by tensor ops, so gradients reach t. Same optics as
 * lm_doe_psf (which uses doe->height instead of t); sets the ctx error and returns NULL on a
 * bad shape. Memory: about 12 nb N^2 floats on the tape (N = grid). Runs on the ctx's
 * backend (on an OpenCL device the DFT is direct: small grids only). */
lm_tensor *lm_doe_psf_t(lm_ctx *c, const lm_doe *doe, lm_tensor *t, const double *lambda_m,
                        int nb);
/* doe->height as fractions of max_height_m: a new m x m tensor on the ctx's backend (no
 * gradient). */
lm_tensor *lm_doe_height_t(lm_ctx *c, const lm_doe *doe);

/* Print the description and, at 400..700 nm every 50 nm, the PSF's peak, its centroid offset
 * and the radius (px) holding half its energy (computes 7 PSFs). */
lm_status lm_doe_describe(const lm_doe *doe, FILE *f, lm_err *err);

/* lm_fftw_lock / lm_fftw_unlock (tensor/ops.h) guard every FFTW plan (the dataset's workers
 * simulate in parallel). */

#endif
