/* synth.h — synthetic reflectance for training and testing (system.md section 7).
 * What it is:
 *   - narrowband spectra: a single Gaussian (centre 400-700 nm, FWHM 10/20/30/40/50 nm) or a
 *     pair (centre separation 10/20/30/40/60/80 nm, both peaks inside 400-700 nm, the same FWHM,
 *     equal heights), sampled at 1 nm, integrated into the 31 10-nm bins of 400..700 nm
 *     (lm_spectrum_bin) and normalised to max 1, used as uniform textureless patches;
 *   - the rainbow test scene: a Gaussian of FWHM 20 nm whose centre sweeps 400 nm (bottom row)
 *     to 700 nm (top row), the same pipeline per row;
 *   - a procedural scene generator (Voronoi regions with ellipses and triangles on top, sharp
 *     edges, smooth gradients, stripes and fine noise, multiplicative smooth shading), each
 *     region's reflectance either a ColorChecker patch (BabelColor average, bundled in
 *     data/spectra/) or a smooth random spectrum (a sum of broad Gaussians); values in [0, 1].
 * Every cube produced here is 31 bands at 400..700 nm (the dataset grid), deterministic given
 * the generator state or seed passed in.
 * What it is not: the forward model (forward.h) or the sampler that mixes these with real
 * scenes (dataset.h). */
#ifndef LM_SYNTH_H
#define LM_SYNTH_H
#include <stdint.h>
#include "data/cube.h"
#include "tensor/rng.h"
#include "tensor/status.h"

#define LM_SYNTH_BANDS 31           /* 400..700 nm, 10 nm */
#define LM_SYNTH_NFWHM 5
#define LM_SYNTH_NSEP 6
#define LM_SYNTH_CC_PATCHES 24
#define LM_SYNTH_CC_FILE "spectra/colorchecker_24_reflectance_babelcolor_avg_380-730_10nm.csv"

/* The widths and pair separations of the paper, nm. */
extern const int lm_synth_fwhm_nm[LM_SYNTH_NFWHM];     /* 10, 20, 30, 40, 50 */
extern const int lm_synth_sep_nm[LM_SYNTH_NSEP];       /* 10, 20, 30, 40, 60, 80 */

/* One narrowband spectrum: npeaks (1 or 2) Gaussians of height 1 and the same FWHM. */
typedef struct lm_synth_gauss {
    int npeaks;
    double centre[2];  /* nm */
    double fwhm;       /* nm */
} lm_synth_gauss;

/* Draw a spectrum: single or pair with probability 1/2 each; FWHM from lm_synth_fwhm_nm;
 * integer centres (the 1 nm sampling grid) uniform in [400, 700] (pairs: the first in
 * [400, 700 - sep], the second sep nm above). */
void lm_synth_gauss_draw(lm_rng *r, lm_synth_gauss *g);
/* The continuous spectrum at wl (nm): sum over peaks of exp(-4 ln2 (wl - c)^2 / fwhm^2). */
double lm_synth_gauss_eval(const lm_synth_gauss *g, double wl);
/* out[i] = lm_synth_gauss_eval at wl0 + i nm, i < n (the 1 nm sampling). */
void lm_synth_gauss_sample(const lm_synth_gauss *g, double wl0, int n, double *out);
/* The 31 bin values: the 1 nm samples over 380..720 nm binned into 10 nm bins centred at
 * 400..700 nm, divided by the largest bin. LM_ERR_ARG for npeaks not 1 or 2 or fwhm <= 0,
 * LM_ERR_NUMERIC if every bin is 0 (a peak far outside the range). */
lm_status lm_synth_gauss_bins(const lm_synth_gauss *g, float out31[LM_SYNTH_BANDS], lm_err *err);
/* Allocate *cube (31 x h x w) filled with one spectrum at every pixel. */
lm_status lm_synth_uniform_cube(const float spec31[LM_SYNTH_BANDS], int h, int w, lm_cube *cube,
                                lm_err *err);
/* Draw a spectrum with r (lm_synth_gauss_draw) and allocate the textureless h x w patch; *g
 * (may be NULL) receives the drawn parameters. */
lm_status lm_synth_gauss_patch(lm_rng *r, int h, int w, lm_cube *cube, lm_synth_gauss *g,
                               lm_err *err);

/* ---- the rainbow test scene ------------------------------------------------------------ */
/* True peak wavelength of row y of an h-row rainbow: 400 + 300 (h - 1 - y) / (h - 1) nm
 * (700 nm at the top row y = 0, 400 nm at the bottom; 0.587 nm per row for h = 512). */
double lm_synth_rainbow_peak(int y, int h);
/* Allocate the h x w rainbow (h >= 2): row y is the binned, normalised FWHM-20 Gaussian centred
 * at lm_synth_rainbow_peak(y, h). The paper's scene is 512 x 512. */
lm_status lm_synth_rainbow(int h, int w, lm_cube *cube, lm_err *err);

/* ---- procedural scenes ----------------------------------------------------------------- */
/* The reflectances regions draw from: the 24 ColorChecker patches at 400..700 nm. */
typedef struct lm_synth_palette {
    int count;
    float refl[LM_SYNTH_CC_PATCHES][LM_SYNTH_BANDS];
} lm_synth_palette;

/* Load <lm_data_dir()>/LM_SYNTH_CC_FILE (values at 400, 410, ..., 700 nm). Errors name the
 * file (LM_ERR_IO / LM_ERR_FORMAT, or LM_ERR_FORMAT when it has not 24 patches covering
 * 400..700 nm). */
lm_status lm_synth_palette_load(lm_synth_palette *p, lm_err *err);
/* Allocate a procedural h x w scene for `seed` (same seed and size, same cube). pal may be NULL:
 * every region then gets a smooth random spectrum. Values in [0, 1]. */
lm_status lm_synth_scene(uint64_t seed, int h, int w, const lm_synth_palette *pal,
                         lm_cube *cube, lm_err *err);

/* ---- fine narrowband detail ------------------------------------------------------------ */
/* The content where a mosaic aliases, which natural training scenes hold little of: the
 * procedural scene of `seed` (lm_synth_scene) with fine, saturated, narrowband detail on top:
 *   - 4..24 strokes (antialiased line segments 0.6..2.5 px wide, 4..64 px long: fibres,
 *     threads), each a narrowband spectrum (one Gaussian, FWHM 10..40 nm, height 0.4..1)
 *     whose peak drifts along the stroke by up to +-60 nm (FWHM in 5 nm steps);
 *   - with probability 1/2, an iridescent sheet over a half-plane (a diffraction grating's
 *     rainbow): a narrowband spectrum whose peak sweeps 400..700 nm and back with a period of
 *     4..32 px across it, over 50..100 % of the light below.
 * Deterministic given seed and size; values in [0, 1]. */
lm_status lm_synth_fine(uint64_t seed, int h, int w, const lm_synth_palette *pal,
                        lm_cube *cube, lm_err *err);

#endif
