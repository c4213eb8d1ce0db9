/* lumosaic.h — the Lumosaic C library: 31-band hyperspectral cubes (400-700 nm) from coded
 * camera frames, and coded frames from cubes.
 *
 * What it is: a small C API over the library behind the `lumosaic` program (the same code, so
 * a frame reconstructed here equals `lumosaic infer`'s cube). Build against it with
 *     cc app.c $(pkg-config --cflags --libs lumosaic)
 *
 * Conventions (every function):
 *   - Objects are opaque handles (lm_api_system, lm_api_model, lm_api_cube) created by a
 *     *_load / *_read / *_create function and released by the matching *_free (which accepts
 *     NULL). Nothing the library allocates must be freed with free().
 *   - Every fallible function returns an lm_api_status (LM_API_OK = 0, errors negative) and
 *     takes a last argument `lm_api_error *err` (may be NULL) that receives the status and a
 *     one-line message naming the file or argument and the problem. On failure, output handles
 *     are set to NULL and nothing is left half-written.
 *   - The library never exits the process and keeps no state the caller must manage: there is
 *     no init call. Different handles may be used from different threads at once; one handle
 *     is used by one thread at a time (a model holds its working memory).
 *   - Images are row-major, cubes band-major: value (b, y, x) of a bands x height x width cube
 *     is data[(b * height + y) * width + x].
 *
 * Data files: the library finds its bundled system descriptions and spectra in $LM_DATA_DIR if
 * set, else in the source tree it was built from.
 */
#ifndef LUMOSAIC_H
#define LUMOSAIC_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The version of this header. A library with the same major version and a minor version at
 * least this one runs programs built against it (lm_api_version gives the library's). */
#define LM_API_VERSION_MAJOR 0
#define LM_API_VERSION_MINOR 4
#define LM_API_VERSION_PATCH 0

#if defined(__GNUC__)
#define LM_API __attribute__((visibility("default")))
#else
#define LM_API
#endif

/* ---- status and errors ---------------------------------------------------------------- */
typedef enum lm_api_status {
    LM_API_OK = 0,
    LM_API_ERR_SHAPE = -1,       /* sizes that do not fit (frame size, band count, buffers) */
    LM_API_ERR_ARG = -2,         /* an invalid argument (NULL, out of range) */
    LM_API_ERR_NOMEM = -3,       /* out of memory */
    LM_API_ERR_IO = -4,          /* a file that cannot be read (missing, no permission) */
    LM_API_ERR_FORMAT = -5,      /* a file whose content is malformed or not what was expected */
    LM_API_ERR_BACKEND = -6,     /* a compute backend failure */
    LM_API_ERR_NUMERIC = -7,     /* NaN, inf or a negative value where one is not allowed */
    LM_API_ERR_UNSUPPORTED = -8, /* a valid request this library cannot serve */
    LM_API_ERR_WRITE = -9        /* an output that cannot be written (disk full, permissions) */
} lm_api_status;

/* What went wrong: the status and a one-line message ("" when status is LM_API_OK). */
typedef struct lm_api_error {
    lm_api_status status;
    char message[512];
} lm_api_error;

/* A short constant text for a status ("ok", "shape error", ...). Never NULL. */
LM_API const char *lm_api_status_str(lm_api_status s);

/* ---- version -------------------------------------------------------------------------- */
/* The library's API version (any pointer may be NULL); returns it as "MAJOR.MINOR.PATCH". */
LM_API const char *lm_api_version(int *major, int *minor, int *patch);

/* ---- system descriptions -------------------------------------------------------------- */
/* The imaging system: LEDs, sensor, mosaic tile (a JSON system description). */
typedef struct lm_api_system lm_api_system;

/* Load a system description file (path NULL or "": the bundled prototype's). */
LM_API lm_api_status lm_api_system_load(const char *path, lm_api_system **out,
                                        lm_api_error *err);
LM_API void lm_api_system_free(lm_api_system *sys);
/* The number of LEDs and the mosaic tile (rows x columns); any pointer may be NULL. Frames
 * to reconstruct have sizes that are multiples of the tile. */
LM_API lm_api_status lm_api_system_info(const lm_api_system *sys, int *leds, int *tile_rows,
                                        int *tile_cols, lm_api_error *err);

/* ---- cubes ---------------------------------------------------------------------------- */
/* A spectral cube: bands x height x width floats with one wavelength (nm) per band. */
typedef struct lm_api_cube lm_api_cube;

/* Read a cube: a CAVE folder (31 band PNGs), a MATLAB .mat file (v5 or v7.3: ARAD, KAUST,
 * ICVL, Harvard and other keys, see mat_key) or a spectral OpenEXR (channels T.<nm>nm). Cubes
 * on 31 bands 400-700 nm or on the forward model's 41 bins 380-780 nm are returned as read;
 * any other grid covering 420-680 nm is resampled to 31 bands 400-700 nm. A
 * "<path>.wavelengths.txt" or ".json" sidecar overrides the file's wavelengths.
 * mat_key: the .mat variable holding the cube (NULL or "": the first of the usual keys). */
LM_API lm_api_status lm_api_cube_read(const char *path, const char *mat_key,
                                      lm_api_cube **out, lm_api_error *err);
/* Write a cube as a spectral OpenEXR (one float channel T.<nm>nm per band, lossless ZIP),
 * atomically (a temporary file renamed into place). Values must be finite and >= 0. */
LM_API lm_api_status lm_api_cube_write(const char *path, const lm_api_cube *cube,
                                       lm_api_error *err);
/* A new zero-filled cube; wavelengths: `bands` values in nm (NULL: 400, 410, ... nm). */
LM_API lm_api_status lm_api_cube_create(int bands, int height, int width,
                                        const float *wavelengths, lm_api_cube **out,
                                        lm_api_error *err);
/* A new cube holding rows [y0, y0 + height) and columns [x0, x0 + width) of every band. */
LM_API lm_api_status lm_api_cube_crop(const lm_api_cube *cube, int y0, int x0, int height,
                                      int width, lm_api_cube **out, lm_api_error *err);
LM_API void lm_api_cube_free(lm_api_cube *cube);
/* The cube's size (any pointer may be NULL). */
LM_API lm_api_status lm_api_cube_shape(const lm_api_cube *cube, int *bands, int *height,
                                       int *width, lm_api_error *err);
/* The values (bands x height x width, writable; owned by the cube) and the wavelengths
 * (bands values in nm). NULL for a NULL cube. */
LM_API float *lm_api_cube_data(lm_api_cube *cube);
LM_API const float *lm_api_cube_wavelengths(const lm_api_cube *cube);

/* The sRGB preview of a reflectance cube, as `lumosaic infer` writes it (srgb_NNNN.png): each
 * pixel's spectrum times `exposure` (1 = as is) under D65 with the CIE 1931 2-degree observer,
 * to sRGB clipped to [0, 1] and gamma-encoded. rgb receives height x width x 3 floats
 * (interleaved R, G, B; n: its element count, checked). The cube's wavelengths must lie within
 * 360-830 nm. */
LM_API lm_api_status lm_api_cube_srgb(const lm_api_cube *cube, float exposure, float *rgb,
                                      size_t n, lm_api_error *err);

/* ---- simulation ----------------------------------------------------------------------- */
/* Sensor noise of a simulated frame, applied in this order (a zero field is off):
 * shot noise (photons: photo-electrons at full scale), full-well clipping (clip), read noise
 * (read_noise: electrons with shot noise, else a fraction of full scale), Gaussian noise with
 * sd = gauss_k x the frame's largest clean value (the paper's noise; 0.05 = 5 %), clipping to
 * [0, 1] (clip), quantisation to `bits` bits (1..24). Zero-initialise it for a clean frame. */
typedef struct lm_api_noise {
    double gauss_k;
    double photons;
    double read_noise;
    int clip;
    int bits;
} lm_api_noise;

/* The coded frame (bucket 1) of a cube through the system's forward model, as `lumosaic
 * simulate --seed seed` makes it (before writing it to a file), and optionally bucket 0 (the
 * light of every other LED), divided by LEDs - 1 as two-bucket models read it. cube: 31 bands
 * 400-700 nm (mirrored to the 41 bins 380-780 nm) or the system's own grid; its top-left
 * pixel is at tile phase (0, 0). bucket1 (required) and bucket0 (NULL to skip) hold
 * height x width floats each (n: the element count of each buffer, checked). noise: NULL for
 * none. threads: 0 = all cores. */
LM_API lm_api_status lm_api_simulate(const lm_api_system *sys, const lm_api_cube *cube,
                                     const lm_api_noise *noise, uint64_t seed, int threads,
                                     float *bucket1, float *bucket0, size_t n,
                                     lm_api_error *err);

/* ---- models and reconstruction -------------------------------------------------------- */
/* A trained model with its system and its working memory. */
typedef struct lm_api_model lm_api_model;

/* Load a model: a .safetensors file written by `lumosaic train` or a training run folder
 * (its model.safetensors). sys: NULL for the system the model was trained with (recorded in
 * the file); a system given must be that same description. */
LM_API lm_api_status lm_api_model_load(const char *path, const lm_api_system *sys,
                                       lm_api_model **out, lm_api_error *err);
/* Load the bundled model for frames of `buckets` buckets (1: bucket 1 only; 2: both, bucket 0
 * as lm_api_frame.bucket0 holds it), as `lumosaic infer --model auto` picks it: from the
 * models/demo/ folder of the source tree, or $LM_MODELS_DIR. sys: as lm_api_model_load. */
LM_API lm_api_status lm_api_model_load_bundled(int buckets, const lm_api_system *sys,
                                               lm_api_model **out, lm_api_error *err);
/* Load a calibrated per-window choice, as `lumosaic infer --model auto --auto FILE
 * --auto-tol tol_db`: calibration is a file written by `lumosaic fit-auto` naming one-frame
 * models of one system that read the same buckets (all one-bucket, or all two-bucket: frames
 * then carry bucket 0, and lm_api_model_info says 2 buckets); each 66 x 64 window of a frame
 * is reconstructed by the cheapest model whose expected PSNR is within tol_db dB (>= 0; 0.5 is
 * infer's default; 0 = always the best model) of the best model's, and the windows are
 * blended. Such a model's
 * preset (lm_api_model_info) is "auto"; it always runs patch-wise. sys: NULL for the system
 * the models were trained with; a system of other LED gains is refused. */
LM_API lm_api_status lm_api_model_load_auto(const char *calibration, double tol_db,
                                            const lm_api_system *sys, lm_api_model **out,
                                            lm_api_error *err);
LM_API void lm_api_model_free(lm_api_model *model);
/* Average the weights of n trained models of one preset (and base) into one model file, as
 * `lumosaic average --output out_path PATHS...` does: paths are n (2..64) run folders or
 * .safetensors files written by `lumosaic train`, all of one preset, base, system description,
 * buckets and frames (else LM_API_ERR_ARG naming two of them); every parameter the inputs'
 * mean (elements equal in all of them kept exactly); out_path (.safetensors) written
 * atomically. Load it with lm_api_model_load. Since API 0.3. */
LM_API lm_api_status lm_api_model_average(const char *const *paths, int n, const char *out_path,
                                          lm_api_error *err);
/* Rewrite a trained model (a run folder or .safetensors file) with its weights stored as IEEE
 * half precision (fp16 != 0: half the file; each weight rounded once, widened back exactly when
 * read, so computation stays fp32) or as fp32 (fp16 == 0), as `lumosaic convert --output
 * out_path [--dtype f16|f32] in_path` does; metadata kept. A weight fp16 cannot hold (beyond
 * 65504, not finite), or out_path naming in_path's own file: LM_API_ERR_ARG, nothing written.
 * Since API 0.4. */
LM_API lm_api_status lm_api_model_convert(const char *in_path, const char *out_path, int fp16,
                                          lm_api_error *err);
/* The model's preset name (e.g. "rt-16-nc+lmmse"; "auto" for a calibrated choice), the
 * buckets it reads (1 or 2) and its mosaic tile; any pointer may be NULL. */
LM_API lm_api_status lm_api_model_info(const lm_api_model *model, const char **preset,
                                       int *buckets, int *tile_rows, int *tile_cols,
                                       lm_api_error *err);
/* Threads of the reconstruction (0 = all cores, the default; at most 1024). */
LM_API lm_api_status lm_api_model_set_threads(lm_api_model *model, int threads,
                                              lm_api_error *err);
/* The frames' Gaussian noise level for models that read it (0..1: sd = level x the frame's
 * maximum, as lm_api_noise.gauss_k); a negative level (the default) estimates it from each
 * frame. Other models ignore it. */
LM_API lm_api_status lm_api_model_set_noise_level(lm_api_model *model, double level,
                                                  lm_api_error *err);
/* 1: reconstruct in overlapping 66 x 64 windows even when the model could run on the whole
 * frame at once (0, the default: whole frame where the model allows, as `lumosaic infer`). */
LM_API lm_api_status lm_api_model_set_patchwise(lm_api_model *model, int patchwise,
                                                lm_api_error *err);

/* Operand precision of the reconstruction's convolution products. */
typedef enum lm_api_precision {
    LM_API_PRECISION_FP32 = 0, /* the default */
    LM_API_PRECISION_BF16 = 1  /* operands rounded to bf16, sums in fp32 (AMX tile or
                                * AVX-512-BF16 products where the CPU has them), as
                                * `lumosaic infer --precision bf16` */
} lm_api_precision;

/* The precision of the model's reconstructions (the weights stay fp32). */
LM_API lm_api_status lm_api_model_set_precision(lm_api_model *model, lm_api_precision precision,
                                                lm_api_error *err);

/* 1 (the default): values below 0 in reconstructed cubes are set to 0, as `lumosaic infer`
 * writes them (reflectance is not negative; the cube writer refuses negative values);
 * 0: the values as the network returns them, as `lumosaic eval` scores them. */
LM_API lm_api_status lm_api_model_set_clamp(lm_api_model *model, int clamp, lm_api_error *err);

typedef enum lm_api_pixel {
    LM_API_PIXEL_U16 = 1, /* uint16_t, 65535 = full scale (a 16-bit PNG or TIFF's samples) */
    LM_API_PIXEL_F32 = 2  /* float, 1.0 = full scale */
} lm_api_pixel;

/* One coded frame in memory. */
typedef struct lm_api_frame {
    int height, width;     /* multiples of the mosaic tile, at least 3 x 3 tiles (9 x 12) */
    lm_api_pixel type;
    const void *bucket1;   /* height x width samples: the coded frame */
    const void *bucket0;   /* two-bucket models only (NULL otherwise): bucket 0 divided by
                            * LEDs - 1, as lm_api_simulate and `lumosaic simulate` give it */
} lm_api_frame;

/* Reconstruct one frame into a caller-owned buffer: cube receives 31 x height x width floats
 * (n: its element count, checked), the bands 400, 410, ..., 700 nm; wavelengths (NULL or 31
 * floats) receives them. Values below 0 are set to 0 unless lm_api_model_set_clamp(0). A float
 * frame holding NaN or infinity is refused (LM_API_ERR_NUMERIC). */
LM_API lm_api_status lm_api_reconstruct(lm_api_model *model, const lm_api_frame *frame,
                                        float *cube, size_t n, float *wavelengths,
                                        lm_api_error *err);
/* The same into a new library-owned cube (lm_api_cube_free). */
LM_API lm_api_status lm_api_reconstruct_cube(lm_api_model *model, const lm_api_frame *frame,
                                             lm_api_cube **out, lm_api_error *err);

/* Reconstruct a sequence of `count` frames (a video, in time order) as `lumosaic infer` does
 * with a folder of frames: cube receives count cubes of 31 x height x width floats one after
 * the other (n: its element count, checked), frame i's at cube + i * 31 * height * width;
 * wavelengths (NULL or 31 floats) receives the bands. Every frame has frame 0's size and
 * pixel type. align 1: for 2 or more frames, each LED sub-image of a frame is moved to the
 * frame's lime-LED time by optical flow to the neighbouring frames (sub-images of at least
 * 24 x 24 pixels; smaller frames are reconstructed unaligned); 0: as recorded. Multi-frame
 * models ("-mf3" presets) need 2 or more frames and read each frame with its neighbours (moved
 * onto it when align is 1). Two-bucket models read each frame's bucket0 and reconstruct the
 * frames unaligned (bucket 0 is not aligned in time). Values below 0 are set to 0 unless
 * lm_api_model_set_clamp(0). On failure the message names the frame ("frame 3: ..."). */
LM_API lm_api_status lm_api_reconstruct_sequence(lm_api_model *model,
                                                 const lm_api_frame *frames, int count,
                                                 int align, float *cube, size_t n,
                                                 float *wavelengths, lm_api_error *err);

/* ---- metrics -------------------------------------------------------------------------- */
/* PSNR (dB, peak 1, over every value), SSIM (11 x 11 Gaussian window, sigma 1.5, per band,
 * averaged), MAE and SAM (mean spectral angle in degrees over pixels with a non-zero true
 * spectrum), as `lumosaic eval` reports them. */
typedef struct lm_api_metrics {
    double psnr, ssim, mae, sam;
} lm_api_metrics;

/* The metrics of a reconstruction against the truth: two bands x height x width arrays
 * (height and width at least 11) of finite values (else LM_API_ERR_NUMERIC). */
LM_API lm_api_status lm_api_metrics_compute(const float *pred, const float *truth, int bands,
                                            int height, int width, lm_api_metrics *out,
                                            lm_api_error *err);

#ifdef __cplusplus
}
#endif

#endif
