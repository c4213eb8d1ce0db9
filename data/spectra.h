/* spectra.h — tabulated spectra: CSV tables, integration into wavelength bins, spectral-edge
 * mirroring (31 -> 41 bins) and the 33-channel training target (system.md section 3).
 * What it is: host-side double-precision helpers used when a system description, a colour
 * rendering or a training sample is prepared. CSV tables have one header row; the first column
 * is the wavelength in nm (strictly increasing), the others are values; cells are separated by
 * commas (no quoting), blank lines and lines starting with '#' are skipped.
 * What it is not: a general CSV reader, or anything differentiable (no tensors here). */
#ifndef LM_SPECTRA_H
#define LM_SPECTRA_H
#include <stddef.h>
#include "data/cube.h"
#include "tensor/status.h"

/* The forward-modelling grid and the dataset grid (system.md section 3). */
#define LM_GRID41_START 380.0f
#define LM_GRID41_STEP 10.0f
#define LM_GRID41_COUNT 41
#define LM_GRID31_START 400.0f
#define LM_GRID31_COUNT 31
#define LM_TARGET_CHANNELS 33

typedef struct lm_csv_table {
    int rows;      /* data rows */
    int cols;      /* columns, including the wavelength column 0 */
    char **names;  /* cols header cells (trimmed) */
    double *data;  /* rows * cols, row-major: data[r * cols + c]; column 0 = wavelength (nm) */
    char path[256];
} lm_csv_table;

/* Load a whole table. Errors (message names the file and, where it applies, the line and
 * column): LM_ERR_IO missing/unreadable file; LM_ERR_FORMAT empty file, header with fewer than
 * two columns, ragged row, empty or non-numeric or non-finite cell, wavelengths not strictly
 * increasing, fewer than two data rows. t is zeroed on failure. */
lm_status lm_csv_table_load(const char *path, lm_csv_table *t, lm_err *err);
void lm_csv_table_free(lm_csv_table *t);
/* Index (>= 1) of the value column named `name` (exact match after trimming), or -1. */
int lm_csv_table_find(const lm_csv_table *t, const char *name);

/* One tabulated spectrum: n samples at strictly increasing wavelengths, linear in between and
 * zero outside [wl[0], wl[n-1]]. */
typedef struct lm_spectrum {
    int n;
    double *wl;   /* nm */
    double *val;
} lm_spectrum;

/* Copy column `col` (1 .. cols-1) of a loaded table. LM_ERR_ARG for a bad index. */
lm_status lm_spectrum_from_table(const lm_csv_table *t, int col, lm_spectrum *s, lm_err *err);
/* Load one column of a CSV file, chosen by `column` (header name), or when column is NULL by
 * `index` (CSV column number, 1 = first value column). An unknown name or index is
 * LM_ERR_FORMAT and the message lists the file and the available columns. */
lm_status lm_spectrum_load(const char *path, const char *column, int index, lm_spectrum *s,
                           lm_err *err);
/* Build a spectrum from arrays (copied). n >= 2, wl strictly increasing, else LM_ERR_ARG. */
lm_status lm_spectrum_from_arrays(const double *wl, const double *val, int n, lm_spectrum *s,
                                  lm_err *err);
void lm_spectrum_free(lm_spectrum *s);

/* Linear interpolation at wl (0 outside the tabulated range). */
double lm_spectrum_eval(const lm_spectrum *s, double wl);
/* Exact integral of the piecewise-linear spectrum over [lo, hi] (trapezoid rule on the samples,
 * linear interpolation at lo and hi); the part of [lo, hi] outside the table contributes 0. */
double lm_spectrum_integrate(const lm_spectrum *s, double lo, double hi);
/* Wavelength of the largest sample (the first one on ties). */
double lm_spectrum_peak(const lm_spectrum *s);

/* Bin into `count` bins centred at start + i*step: out[i] = integral over
 * [c - step/2, c + step/2] (units: value x nm; divide by step for the bin mean). Bins that reach
 * beyond the table integrate only the covered part (the spectrum is taken as 0 outside).
 * LM_ERR_ARG for count < 1 or step <= 0. */
lm_status lm_spectrum_bin(const lm_spectrum *s, double start, double step, int count,
                          double *out, lm_err *err);

/* ---- spectral-edge mirroring and the training target ---------------------------------- */
/* The 31-band index (0 = 400 nm .. 30 = 700 nm) that bin `bin41` (0 = 380 nm .. 40 = 780 nm) of
 * the mirrored spectrum copies: 380 <- 420, 390 <- 410, 400..700 unchanged, 710 <- 690, ...,
 * 780 <- 620. Returns -1 for bin41 outside 0..40. */
int lm_mirror_source_band(int bin41);
/* out41[41] from in31[31] (bands 400..700 nm). */
void lm_spectrum_mirror41(const float *in31, float *out41);
/* Allocate *out as a 41-band cube (380..780 nm) mirrored from a 31-band 400..700 nm cube.
 * LM_ERR_SHAPE (message "mirror: ...") if `in` does not have 31 bands at 400..700 nm (10 nm). */
lm_status lm_cube_mirror41(const lm_cube *in, lm_cube *out, lm_err *err);
/* Allocate *out as the 33-channel training target of a 41-band 380..780 nm cube: channel 0 =
 * mean of the 380 and 390 bins (wavelength 385), 1..31 = the 400..700 bins, 32 = mean of the
 * 710..780 bins (wavelength 745). LM_ERR_SHAPE if `in` is not on the 41-bin grid. */
lm_status lm_cube_target33(const lm_cube *in, lm_cube *out, lm_err *err);

/* ---- bundled data files --------------------------------------------------------------- */
/* The directory of the project's data files (systems/, spectra/): $LM_DATA_DIR if set, else the
 * source tree's data/ folder baked in at build time, else "data". Never NULL. */
const char *lm_data_dir(void);
/* out = lm_data_dir() + "/" + rel. LM_ERR_ARG if it does not fit in n bytes. */
lm_status lm_data_path(const char *rel, char *out, size_t n, lm_err *err);

#endif
