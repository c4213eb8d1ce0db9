/* calib.h — LED-gain calibration from ColorChecker frames (system.md section 11; the paper's
 * supplement, "Calibration"): the measured 12 x 24 matrix M (the mean of each LED's pixels in
 * each patch region of the averaged coded frames), the simulated matrix A (each LED's response
 * a_l of the current system against each patch's reflectance, summed over the grid's bins), and
 * gains alpha >= 0 by non-negative least squares (data/nnls.h) so that alpha_l A_lp (+ an
 * optional common dark offset >= 0) matches M_lp; the calibrated gains are alpha_l times the
 * system's, written as a new system file.
 * What it is not: the command (cli/cmd_calibrate.c), the per-window model choice of
 * `infer --model auto` (infer/auto.h, `lumosaic fit-auto`), or spectra or QE calibration.
 *
 * Averaging the LED's own pixels over a patch region is the mean of the demosaiced LED
 * sub-image over the region without the interpolation's blur across patch borders. Without the
 * offset each LED's gain depends only on its own row of M, so the NNLS solution is the clipped
 * per-LED ratio; with the offset (an unknown shared by every row) it is coupled. Gains are
 * relative: a system file's responses are normalised (brightest white response 1.0), so one
 * factor common to all LEDs (exposure, camera gain) drops out. */
#ifndef LM_CALIB_H
#define LM_CALIB_H
#include "data/cube.h"
#include "data/system.h"

#define LM_CALIB_PATCHES 24 /* the ColorChecker Classic: 4 rows x 6 columns, row-major */
#define LM_CALIB_ROWS 4
#define LM_CALIB_COLS 6

typedef struct lm_calib_rect {
    int x, y, w, h; /* pixels: columns x .. x+w-1, rows y .. y+h-1 */
} lm_calib_rect;

/* Patch regions of a 6 x 4 chart from the centres of its four corner patches, as (x, y)
 * pixel pairs: corners[0..1] patch 1 (top-left, dark skin), [2..3] patch 6 (top-right,
 * bluish green), [4..5] patch 24 (bottom-right, black), [6..7] patch 19 (bottom-left, white).
 * Each centre is the bilinear blend of the corners; each region is a square of side
 * frac x the smaller centre spacing (0 < frac <= 1), rounded. LM_ERR_ARG for non-finite
 * corners, frac outside (0, 1] or a degenerate chart (spacing under 2 pixels). */
lm_status lm_calib_grid(const double corners[8], double frac, lm_calib_rect out[LM_CALIB_PATCHES],
                        lm_err *err);
/* Patch regions from a JSON file {"patches": [[x, y, w, h], ...]} of exactly 24 rectangles
 * (integers, w, h >= 1). Errors name the file and the entry. */
lm_status lm_calib_rects_load(const char *path, lm_calib_rect out[LM_CALIB_PATCHES],
                              lm_err *err);
/* Every region inside a height x width frame and covering at least one pixel of every LED
 * (a whole tile): else LM_ERR_ARG naming the patch (1-based) and its rectangle. */
lm_status lm_calib_rects_check(const lm_system *sys, const lm_calib_rect *r, int height,
                               int width, lm_err *err);

/* The 24 reflectances on the system's grid (bin means), C[p * nbins + b], from a CSV whose
 * first 24 value columns are the patches in chart order (the bundled BabelColor table when
 * path is NULL). Bins beyond the table take its nearest sample (flat extension; the bundled
 * table ends at 730 nm). */
lm_status lm_calib_reflectances(const lm_system *sys, const char *path, double *C, lm_err *err);

/* M[l * 24 + p]: mean of the frame's LED-l pixels in region p (frame: height x width). */
lm_status lm_calib_measure(const lm_system *sys, const float *frame, int height, int width,
                           const lm_calib_rect *r, double *M, lm_err *err);
/* A[l * 24 + p] = sum_b a_l[b] C[p * nbins + b] with the system's responses a_l. */
void lm_calib_simulate(const lm_system *sys, const double *C, double *A);

typedef struct lm_calib_fit {
    double alpha[LM_SYSTEM_MAX_LEDS]; /* the NNLS scales of the system's responses */
    double gain[LM_SYSTEM_MAX_LEDS];  /* calibrated gains: alpha_l x the system's gain_l */
    double offset;                    /* the fitted common dark offset (0 when not fitted) */
    double rel_error;                 /* ||fit - M|| / ||M|| over all 24 x L entries */
    double patch_rms[LM_CALIB_PATCHES]; /* per patch: RMS of (fit - M) over LEDs / mean M */
    double led_rms[LM_SYSTEM_MAX_LEDS]; /* per LED: RMS of (fit - M) over patches / mean M */
} lm_calib_fit;

/* Solve for alpha (and the offset when fit_offset) by NNLS. LM_ERR_NUMERIC when M is all zero
 * or not finite. */
lm_status lm_calib_solve(const lm_system *sys, const double *A, const double *M, int fit_offset,
                         lm_calib_fit *out, lm_err *err);

/* Write a copy of the system file sys->path with "gains" replaced by gains[] (a name and a
 * description saying so; relative CSV paths made absolute so that the copy can live anywhere)
 * to out_path, atomically, and check that it loads. */
lm_status lm_calib_write_system(const lm_system *sys, const double *gains, const char *note,
                                const char *out_path, lm_err *err);
/* The general form: a copy of sys->path with the fields given replaced (NULL = keep): gains
 * (nleds), subframes per LED (file order; "subframes_total" updated), the tile map (LED index
 * per phase, the system's tile size), name, description. Atomic, checked by loading it back. */
typedef struct lm_system_edit {
    const double *gains;
    const int *subframes;
    const int *tile_led;
    const char *name, *note;
} lm_system_edit;
lm_status lm_system_write_edit(const lm_system *sys, const lm_system_edit *ed,
                               const char *out_path, lm_err *err);

/* A cube on the system's grid (height x width): a grey background of reflectance `background`
 * and each patch region filled with its reflectance (C). For trying calibration on simulated
 * frames (`lumosaic simulate` of it). */
lm_status lm_calib_chart_cube(const lm_system *sys, int height, int width,
                              const lm_calib_rect *r, const double *C, double background,
                              lm_cube *out, lm_err *err);

#endif
