/* noise_est.h — blind estimate of the additive white Gaussian noise in one raw coded frame, and
 * of the noise level k of system.md section 4 (sigma = k * max clean value of the frame).
 * What it is: a single-frame estimator for mosaic frames (H x W, row-major, one LED per pixel by
 * its tile phase (y mod tile_h, x mod tile_w)). Neighbouring pixels see different LEDs, so only
 * pixels of one phase are ever compared: each residual is the mask [1 -2 1; -2 4 -2; 1 -2 1] / 6
 * over a 3 x 3 window of same-phase pixels (rows +-tile_h, columns +-tile_w; std sigma for white
 * noise), pooled over all phases. Texture only adds to it and scales with the signal, so the
 * residuals are ranked by a texture predictor from the same window that is orthogonal to the
 * mask (window mean + 2 (|Sobel x| + |Sobel y|) / 8), hence independent of the residual's noise:
 * choosing by it biases nothing. sigma^2 is a trimmed second moment (smallest 90 % of |r|,
 * corrected to be exact for Gaussian noise) of the darkest, flattest 1/16 of the residuals (at
 * least 512), grown to 1/8, 1/4, 1/2 and all of them while each added shell agrees with the pool
 * (not above it by 2 standard errors): dark regions fix sigma at low noise, and at high noise the
 * whole frame is used.
 * peak, the robust maximum of the clean frame: the frame maximum minus 2 sigma when sigma <= 2 %
 * of it, or when the maximum stands more than 3 sigma above every 2 x 2 same-phase mean while
 * sigma < 6 % of it (a narrow highlight); otherwise the largest 2 x 2 same-phase mean minus sigma.
 * level = sigma / peak. Deterministic and independent of the thread count (OpenMP threads, the
 * default team; one thread inside a parallel region or with the caller's scratch); 2.1 ms per
 * 640 x 480 frame on one thread, 1.3 ms on two (this 2-core machine, quiet); ~230 KB of histograms per thread as scratch (no copy of the
 * frame).
 * Measured (tests/test_noise_est.c --report, 27 CAVE scenes, 10 noise draws each): sigma within
 * 17 % at k = 1 %, 11 % at 2.5 %, 8 % from 5 % on; clean frames read k < 0.005. The level is
 * within 20 % at k <= 2.5 %, and at every k where the frame's maximum lies on a bright area; a
 * maximum on a few specular pixels cannot be told from noise once k >= 5 to 10 %, and those
 * frames read k up to 2x too high. Texture finer than the mosaic looks like noise: small or
 * fully textured frames read high at low k.
 * Frames clipped at their minimum (a sensor's floor, a 16-bit PNG's 0: at least 1 pixel in 1000
 * exactly at the minimum) are estimated again without the windows that touch the floor or whose
 * mean is below 1.5 sigma of the previous estimate, until it settles: on CAVE frames clipped and
 * quantised to 16 bits, sigma within 23 % at k = 1 % and 16 % from 2.5 % (all 27 scenes, one
 * draw; without this pass 40-70 % low at k = 10-20 %).
 * What it is not: a model of shot (signal-dependent) noise. With shot noise it reads the noise
 * of the darkest flat regions. Nor a denoiser. */
#ifndef LM_NOISE_EST_H
#define LM_NOISE_EST_H
#include <stddef.h>
#include "tensor/status.h"

#define LM_NOISE_MAX_THREADS 64 /* threads one estimate uses at most */

typedef struct lm_noise_info {
    float sigma;    /* noise standard deviation, in the frame's units */
    float peak;     /* robust maximum of the clean frame (see above) */
    float level;    /* sigma / peak: the k of system.md */
    float fraction; /* share of the frame's residuals the estimate used (1/16 .. 1) */
} lm_noise_info;

/* Estimate sigma, peak and level of a raw frame. height and width must be multiples of the tile
 * and give each phase at least 3 x 3 pixels; values must be finite. Errors (message starts with
 * "noise:"): LM_ERR_ARG (NULL pointer, tile size < 1), LM_ERR_SHAPE (size not a positive
 * multiple of the tile, or too small), LM_ERR_NUMERIC (NaN/inf in the frame, or no positive
 * signal: peak <= 0, level undefined; sigma and peak are still filled), LM_ERR_NOMEM. */
lm_status lm_noise_analyze(const float *raw, int height, int width, int tile_h, int tile_w,
                           lm_noise_info *out, lm_err *err);

/* Standard deviation of the additive white Gaussian noise in the frame's units (>= 0), or, on
 * failure, the negative lm_status of lm_noise_analyze as a float (e.g. -1 = LM_ERR_SHAPE). */
float lm_noise_estimate(const float *raw, int height, int width, int tile_h, int tile_w);
/* The same with the caller's scratch of lm_noise_scratch_bytes(width) bytes (no allocation: a
 * training loop estimating every patch of every step). */
size_t lm_noise_scratch_bytes(int width);
float lm_noise_estimate_scratch(const float *raw, int height, int width, int tile_h, int tile_w,
                                void *scratch);
/* The level k = sigma / peak (>= 0), or the negative lm_status on failure (including
 * LM_ERR_NUMERIC for a frame with no positive signal). */
float lm_noise_level(const float *raw, int height, int width, int tile_h, int tile_w);

#endif
