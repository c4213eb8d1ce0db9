/* conditions.h — where methods fail: adverse capture conditions applied when
 * simulating the frame of a prepared cube (infer/eval.h), a level sweep per condition family,
 * and the level at which a model loses 3 dB against its own clean-input accuracy.
 * Families and their levels (the sweep goes from mild to severe):
 *   photons      Poisson shot noise with `level` expected photo-electrons at full scale
 *                (data/forward.h lm_noise_opts.photons; 0 = off, i.e. the clean frame);
 *                sweep e.g. 10000 .. 30 (decreasing)
 *   saturation   exposure x level (>= 1): every value multiplied by level, clipped at full well
 *                (full scale 1.0) and divided by level again (the exposure is known), so only
 *                the clipped pixels change; 1 = clean
 *   led_gain     each LED's gain off by +-level % in the SIMULATION only (sign drawn per LED
 *                and level from the generator; the model keeps the nominal system); coded
 *                models only (n/a for RGB input); 0 = clean
 *   dead_pixels  level % of the frame's values (round(level / 100 x n) distinct ones, seeded)
 *                stuck at 0 or at full scale (a fair coin each); 0 = clean
 *   motion       the scene translating at `level` px/s (lm_eval_motion_run: frame 1 of a short
 *                coded video, scored with and without temporal alignment); coded models only
 * Every random draw of a level comes from lm_rng_split(rng, lm_cond_stream(family, level)), so
 * a level draws the same corruption whatever the sweep it belongs to.
 * What it is not: the study loop, averaging over scenes or output (study/), nor the Gaussian
 * noise sweep (lm_eval_scene). */
#ifndef LM_CONDITIONS_H
#define LM_CONDITIONS_H
#include <stddef.h>
#include "infer/eval.h"

typedef enum lm_cond_family {
    LM_COND_PHOTONS,
    LM_COND_SATURATION,
    LM_COND_LED_GAIN,
    LM_COND_DEAD_PIXELS,
    LM_COND_MOTION,
    LM_COND_NFAMILIES
} lm_cond_family;

#define LM_COND_MAX_LEVELS 16

/* "photons", "saturation", "led_gain", "dead_pixels", "motion"; NULL outside the enum. */
const char *lm_cond_name(lm_cond_family f);
/* The family of a name, or -1. */
int lm_cond_parse(const char *name);
/* The level's unit for axis labels, e.g. "photo-electrons at full scale". */
const char *lm_cond_unit(lm_cond_family f);
/* The level at which the family changes nothing (photons 0, saturation 1, others 0). */
double lm_cond_clean_level(lm_cond_family f);
/* The valid levels of f: [*lo, *hi] (photons 0..1e12, saturation 1..1e6, led_gain 0..100,
 * dead_pixels 0..100, motion 0..1e4 px/s). 0, or -1 for an unknown family. */
int lm_cond_range(lm_cond_family f, double *lo, double *hi);
/* Is level valid for f (finite, in lm_cond_range)? */
int lm_cond_level_ok(lm_cond_family f, double level);
/* The default sweep (mild to severe) into levels (room for LM_COND_MAX_LEVELS); the count. */
int lm_cond_default_levels(lm_cond_family f, double *levels);
/* Does the family apply to a model whose input is the coded frame (rgb_input 0) or the RGB
 * camera image (rgb_input 1: lm_model_has(m, LM_CAP_RGB_INPUT))? */
int lm_cond_applies(lm_cond_family f, int rgb_input);
/* The generator stream of (family, level). */
uint64_t lm_cond_stream(lm_cond_family f, double level);

/* ---- the corruptions, on a simulated frame of n values (full scale fs) ------------------ */
/* v <- min(v x exposure, fs) / exposure. LM_ERR_ARG for exposure < 1 or not finite. */
lm_status lm_cond_saturate(float *frame, size_t n, double exposure, float fs, lm_err *err);
/* round(pct / 100 x n) distinct values (a partial Fisher-Yates shuffle of the indices) set to
 * 0 or fs (lm_rng_u32 & 1: 1 = fs). *ndead (may be NULL) receives the count. LM_ERR_ARG for
 * pct outside 0..100, LM_ERR_NOMEM. */
lm_status lm_cond_dead_pixels(float *frame, size_t n, double pct, float fs, lm_rng *rng,
                              size_t *ndead, lm_err *err);
/* A copy of sys whose LED l has gain and response multiplied by factor[l] = 1 + s_l pct / 100,
 * s_l = +1 or -1 (lm_rng_u32 & 1: 1 = +1, LEDs in file order). factor (may be NULL) receives
 * the factors (nleds). Free the copy with lm_cond_system_free only. LM_ERR_ARG for pct outside
 * 0..100, LM_ERR_NOMEM. */
lm_status lm_cond_led_gains(const lm_system *sys, double pct, lm_rng *rng, lm_system *out,
                            double *factor, lm_err *err);
void lm_cond_system_free(lm_system *s);

/* The frame of the prepared 31-band cube under family f (not motion) at level: the model's
 * input as lm_eval_simulate makes it (coded or RGB), corrupted; *frame (malloc'd, n values)
 * is the caller's to free. rng: the caller's generator (split per level inside). Errors:
 * LM_ERR_ARG (invalid level, motion, a family that does not apply to the model), those of
 * lm_eval_simulate. */
lm_status lm_cond_simulate(const lm_infer_model *im, const lm_cube *truth, lm_cond_family f,
                           double level, const lm_rng *rng, float **frame, size_t *n,
                           lm_err *err);

/* Score the model on the cube under (f, level): simulate, reconstruct (lm_eval_reconstruct
 * with the tiles of to), metrics into *m. For motion *m is the aligned frame's score, *unaligned
 * (may be NULL) the frame as recorded and *still (may be NULL) the static reference, all over
 * the in-view region (lm_eval_motion_run); for the other families *unaligned = *still = *m.
 * c must hold no tensors. */
lm_status lm_cond_eval(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                       lm_cond_family f, double level, const lm_tile_opts *to,
                       const lm_rng *rng, lm_metrics *m, lm_metrics *unaligned,
                       lm_metrics *still, lm_err *err);

/* The 3-dB point: with psnr[i] at levels[i] (sweep order, mild to severe), the first i with
 * psnr[i] <= clean - drop. Returns 1 and *at = the linear interpolation between levels[i - 1]
 * and levels[i] where the PSNR crosses clean - drop (levels[0] when i = 0); 0 when no level
 * gets there (*at = NAN: "beyond the last level"). A NaN PSNR counts as failed, +inf never;
 * the interpolation needs finite neighbours (else *at = levels[i]). */
int lm_cond_crossing(const double *levels, const double *psnr, int n, double clean,
                     double drop, double *at);

#endif
