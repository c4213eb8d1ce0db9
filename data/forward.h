/* forward.h — the static forward model: a coded frame simulated from a reflectance cube
 * (system.md sections 4-5).
 * What it is: per pixel p with LED l(p) (its tile phase's LED),
 *     bucket 1:  Y_p = a_{l(p)} . r_p
 *     bucket 0:  Y0_p = sum_{l != l(p)} a_l . r_p   (every sub-frame where the pixel's code is 0)
 * which equals the paper's sub-frame sum Y_p = sum_s C_{p,s} (S .* I_{p,s}) . r_p, followed by
 * optional sensor noise drawn from an explicit lm_rng. Works on plain float images (H x W,
 * row-major) and lm_cube; OpenMP over rows; results do not depend on the thread count (each
 * row draws from its own stream split from the caller's generator).
 * What it is not: motion (video simulation integrates several static frames per LED window
 * elsewhere), demosaicking, or anything differentiable. */
#ifndef LM_FORWARD_H
#define LM_FORWARD_H
#include "data/cube.h"
#include "data/system.h"
#include "tensor/rng.h"
#include "tensor/status.h"

/* Sensor noise, applied in this order (each step off when its field is 0):
 *  1. shot noise: v <- Poisson(v / full_scale * photons) * full_scale / photons, i.e. `photons`
 *     expected photo-electrons at full scale (negative v counts as 0 electrons);
 *  2. full well (clip != 0): v <- min(v, full_scale);
 *  3. read noise: v += N(0, sd), sd = read_noise electrons (read_noise * full_scale / photons)
 *     when photons > 0, else read_noise as a fraction of full scale (read_noise * full_scale);
 *  4. Gaussian (the paper's noise): v += N(0, sd), sd = gauss_k * (largest clean value of the
 *     image being simulated: the frame or patch, each bucket separately);
 *  5. clip != 0: v <- clamp(v, 0, full_scale);
 *  6. quantisation (bits > 0): v <- clamp(round(v / full_scale * L), 0, L) * full_scale / L,
 *     L = 2^bits - 1 (an ADC: always clamps to its range).
 * Without clipping or quantisation values may be negative or exceed full scale. */
typedef struct lm_noise_opts {
    float gauss_k;      /* >= 0; paper: uniform in [0, 0.15] per sample (training) */
    double photons;     /* >= 0; photo-electrons at full scale (Poisson shot noise) */
    float read_noise;   /* >= 0; electrons if photons > 0, else a fraction of full scale */
    int clip;           /* clip at full well (and at 0 at the end) */
    int bits;           /* 0 or 1..24 */
    float full_scale;   /* signal at full well / largest code; 0 means 1.0 (the white response
                         * of the brightest LED with the system's normalisation) */
} lm_noise_opts;

typedef struct lm_forward_opts {
    int y0, x0;          /* sensor position of the cube's top-left pixel (>= 0): sets the tile
                          * phases; patches on the tile grid use 0, 0 */
    lm_noise_opts noise; /* all zero = noise-free */
    int nthreads;        /* OpenMP threads; 0 = the OpenMP default */
} lm_forward_opts;

/* Noise-free buckets. cube: the system's grid (nbins bands at grid_start + i*grid_step).
 * bucket1 (required) and bucket0 (NULL to skip) are height x width. Errors: LM_ERR_SHAPE (band
 * count or wavelengths do not match the grid), LM_ERR_ARG (negative offsets), LM_ERR_NUMERIC
 * (non-finite values in the cube); messages start with "forward:". */
lm_status lm_forward_clean(const lm_system *sys, const lm_cube *cube, int y0, int x0,
                           float *bucket1, float *bucket0, int nthreads, lm_err *err);
/* Apply noise in place to an H x W image. rng may be NULL only when no random step is on.
 * Advances *rng once, so consecutive calls draw different noise. LM_ERR_ARG for negative or
 * non-finite options, bits outside 0..24, or a missing rng. */
lm_status lm_forward_noise(float *img, int height, int width, const lm_noise_opts *o,
                           lm_rng *rng, int nthreads, lm_err *err);
/* The noise options of bucket 0's raw values (the sum of the other LEDs' light, up to LEDs - 1
 * times bucket 1's white response), given bucket 1's: bucket 0's full scale is (LEDs - 1) x
 * bucket 1's (a well and ADC sized for the complement, which is what the stored bucket-0 files,
 * divided by LEDs - 1 with white = 1, presume); the same signal per photo-electron (photons x
 * (LEDs - 1) at its full scale) and the same read noise in signal units; the same relative
 * Gaussian level k (of that bucket's own maximum). Equal to o for a single LED. */
lm_noise_opts lm_forward_bucket0_noise(const lm_noise_opts *o, int nleds);
/* lm_forward_clean then lm_forward_noise on each produced bucket (bucket 1 first; bucket 0 with
 * lm_forward_bucket0_noise(&o->noise, sys->nleds)). */
lm_status lm_forward_simulate(const lm_system *sys, const lm_cube *cube,
                              const lm_forward_opts *o, lm_rng *rng, float *bucket1,
                              float *bucket0, lm_err *err);
/* The same from a 31-band 400..700 nm cube, mirrored to 41 bins first (lm_cube_mirror41); the
 * system must use the default 380/10/41 grid. */
lm_status lm_forward_simulate31(const lm_system *sys, const lm_cube *cube31,
                                const lm_forward_opts *o, lm_rng *rng, float *bucket1,
                                float *bucket0, lm_err *err);

/* One Poisson(lambda) draw (exact: multiplication method below 10, Hormann's PTRS above);
 * lambda <= 0 gives 0. Exposed for tests and synthetic data. */
double lm_forward_poisson(lm_rng *r, double lambda);

#endif
