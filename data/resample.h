/* resample.h — putting a cube read with its own wavelengths onto the program's 31-band
 * 400-700 nm grid (10 nm), and the wavelength lists that say where a file's bands lie.
 * What it is:
 *   - lm_wavelengths_check: a list must be finite, positive and strictly increasing;
 *   - lm_wavelengths_sidecar: the optional sidecar `<cube path>.wavelengths.txt` (numbers in nm
 *     separated by white space or commas, `#` to the end of a line is a comment) or
 *     `<cube path>.wavelengths.json` (an array of numbers, or {"wavelengths": [...]}), one
 *     wavelength per band of the file, in the file's band order;
 *   - lm_resample: the linear map from the source bands to the output bands, applied one source
 *     band at a time (so a .mat cube of 519 bands never needs to be held whole).
 * The method, for each output band centre c in 400, 410, ..., 700 nm:
 *   - the source spectrum is the piecewise-linear function through its bands, extended beyond
 *     its first (last) band by reflecting it about that band, as system.md's spectral-edge
 *     mirroring does (Harvard starts at 420 nm: 410 <- 430, 400 <- 440);
 *   - a source denser than the grid (mean spacing under 10 nm: 5 nm EXR, ICVL's 519 bands)
 *     is integrated over the band's 10 nm bin [c - 5, c + 5] and divided by 10: the output is
 *     the bin's mean, as the LED and sensor tables are binned (system.md §3), not a point sample
 *     that would alias the fine structure and keep the noise of one narrow band;
 *   - otherwise (10 nm or coarser: KAUST, Harvard) it is the linear interpolation at c: bin
 *     integration would blur a source that has no detail finer than the grid, and a source
 *     band lying on c (within 0.001 nm) is copied exactly, so KAUST's first 31 bands are
 *     bit-identical to the file's.
 * A cube that does not cover 420-680 nm is refused (the mirrored edge would be more than 20 nm
 * of invented spectrum). A cube already on the 31-band grid, or on a grid the caller keeps
 * (simulate: the system's 41 bins 380-780 nm), is returned as read (every band copied).
 * What it is not: a reader (cube_io.h), or the 31 -> 41 mirroring of the forward model
 * (spectra.h). */
#ifndef LM_RESAMPLE_H
#define LM_RESAMPLE_H
#include "data/cube.h"

#define LM_RESAMPLE_MAX_BANDS 1024 /* source bands (ICVL's raw cubes have 519) */
#define LM_RESAMPLE_MIN_NM 420.0   /* the least coverage accepted */
#define LM_RESAMPLE_MAX_NM 680.0

/* LM_OK if wl[0..n) are finite, > 0 and strictly increasing and 1 <= n <=
 * LM_RESAMPLE_MAX_BANDS; else LM_ERR_FORMAT "<what>: wavelength 3 is NaN" / "... is not
 * increasing (430 nm after 440 nm)", one line. */
lm_status lm_wavelengths_check(const double *wl, int n, const char *what, lm_err *e);

/* The sidecar of cube_path, if any: *n = 0 when there is none; else its list (checked with
 * lm_wavelengths_check, at most LM_RESAMPLE_MAX_BANDS values) in wl and its count in *n.
 * Errors name the sidecar: unreadable, not numbers, bad JSON, both a .txt and a .json. */
lm_status lm_wavelengths_sidecar(const char *cube_path, double *wl, int *n, lm_err *e);

/* Where output band b comes from. */
typedef struct lm_resample {
    int nsrc, nout;
    int dense;                        /* 1: bin means; 0: interpolation (or copies) */
    float wavelength[LM_CUBE_MAX_BANDS]; /* of the output bands */
    int copy[LM_CUBE_MAX_BANDS];      /* output band b is source band copy[b] exactly, or -1 */
    double *w;                        /* nout x nsrc weights of the other output bands */
} lm_resample;

/* A grid kept as read (count 0: none). */
typedef struct lm_grid {
    int count;
    float start, step;
} lm_grid;

/* 1 if wl[0..n) is the grid (each within 1 % of a step of start + i * step). */
int lm_grid_matches(const double *wl, int n, lm_grid g);

/* The map for a source with wavelengths wl[0..n) (checked here). native: every band kept as
 * read (n <= LM_CUBE_MAX_BANDS); else the 31-band grid, with `keep` and the 31-band grid
 * itself kept as read. LM_ERR_FORMAT "<what>: covers 430-690 nm; ... needs at least 420-680
 * nm", LM_ERR_NOMEM. */
lm_status lm_resample_init(lm_resample *r, const double *wl, int n, int native, lm_grid keep,
                           const char *what, lm_err *e);
void lm_resample_free(lm_resample *r);
/* 1 if source band s contributes to the output. */
int lm_resample_uses(const lm_resample *r, int s);
/* Add source band s (plane: out->height x out->width values) into out (r->nout bands, zeroed
 * before the first band): copies are written (=), weighted bands added (+=). */
void lm_resample_band(const lm_resample *r, int s, const float *plane, lm_cube *out);
/* A whole cube held in memory (in->bands == r->nsrc) into a new cube *out. */
lm_status lm_resample_cube(const lm_resample *r, const lm_cube *in, lm_cube *out, lm_err *e);

#endif
