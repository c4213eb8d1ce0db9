/* cube_io.h — reading spectral cubes from the formats users bring, and writing spectral EXR.
 * What it is: format detection + dispatch (lm_cube_read: onto the program's 31-band 400-700 nm
 * grid) and the per-format readers (the file's own bands):
 *   - CAVE: a folder of 31 band PNGs `<scene>_ms_01.png .. _31.png` (400-700 nm, 10 nm);
 *     the folder may also hold them one level down (CAVE zips unpack as scene/scene/).
 *     8-bit bands are scaled by 1/255, 16-bit by 1/65535. A band stored with several channels
 *     is accepted only when its colour channels are identical at every pixel (alpha, if any,
 *     is ignored); its first channel is used. Otherwise the band is rejected as not greyscale.
 *   - .mat: the cube variable H x W x B in MATLAB's order (HDF5 tools show it as B x W x H),
 *     real numeric; the first of LM_MAT_CUBE_KEYS the file holds (`cube` ARAD, `hsi` KAUST,
 *     `rad` ICVL, `ref` Harvard, ...), or the one named by lm_cube_read_opts.mat_key. Its
 *     wavelengths: the first of LM_MAT_WL_KEYS the file holds (`bands`, `wavelengths`, `wl`,
 *     ...; one value in nm per band), else by key: `hsi` (KAUST, MATLAB v5: 34 bands 400-730
 *     nm, 12-bit counts) 400 + 10 i nm; `ref` with 31 bands (Harvard) 420-720 nm; any other
 *     31-band variable 400-700 nm; other band counts need a list. `hsi` values are divided by
 *     4095 (KAUST's counts). The file version does not matter (matio).
 *     A .mat file's structure is checked first (a truncated file, or a variable whose data
 *     do not cover its dimensions, is LM_ERR_FORMAT), and matio reads it in a child process
 *     with capped memory and CPU time: a fault or a runaway allocation of libmatio/libhdf5 on
 *     a corrupt file is an error naming the file.
 *   - .exr: spectral OpenEXR (Fichet, Pacanowski, Wilkie, JCGT 2021): channels
 *     `T.<wavelength>nm` (reflective, comma or dot decimal separator), sorted by wavelength;
 *     if a file has no `T.` channel, the emissive `S0.<wavelength>nm` channels are read
 *     instead. Other channels are ignored. HALF or FLOAT channels, scanline storage.
 *   - Any format: a sidecar `<cube path>.wavelengths.txt` or `.json` (resample.h), one
 *     wavelength per band in the file's order, replaces the file's own wavelengths (a count
 *     that does not match the bands is LM_ERR_FORMAT).
 * lm_cube_read then resamples the cube to 31 bands 400-700 nm (method: resample.h) unless it
 * is already on that grid or on the grid the options keep (default: the 41 bins 380-780 nm
 * of the forward model, which simulate takes as they are).
 * Every reader checks the claimed size against data/limits.h before allocating the cube.
 * Every cube read is validated: each value must be finite and >= 0, else LM_ERR_NUMERIC
 * naming the file, the band and the pixel (a .mat band the grid does not use, such as KAUST's
 * 710-730 nm, is neither kept nor checked). Readers and the writer may run concurrently on
 * different files.
 * What it is not: normalisation (cubes are returned in the file's units, KAUST's counts
 * aside), or a cache (see the dataset code). */
#ifndef LM_CUBE_IO_H
#define LM_CUBE_IO_H
#include "data/cube.h"
#include "data/resample.h"

#define LM_CAVE_BANDS 31
/* The .mat variables tried, in order, for the cube and for its wavelengths. */
#define LM_MAT_CUBE_KEYS "cube", "hsi", "rad", "ref", "radiance", "reflectance", "msi", \
                         "hyper", "data", "img", "image", "I", "X"
#define LM_MAT_WL_KEYS "bands", "wavelengths", "wavelength", "wl", "wls", "lambda", "wave", \
                       "nm"

/* What lm_cube_read_with reads and keeps. */
typedef struct lm_cube_read_opts {
    const char *mat_key; /* .mat: the cube variable; NULL or "" = the first of LM_MAT_CUBE_KEYS */
    lm_grid keep;        /* a grid returned as read besides 31 bands 400-700 (count 0: none) */
} lm_cube_read_opts;

/* Automatic .mat key; keep the 41 bins 380-780 nm. */
void lm_cube_read_opts_default(lm_cube_read_opts *o);

typedef enum lm_cube_format {
    LM_CUBE_FMT_UNKNOWN = 0,
    LM_CUBE_FMT_CAVE,  /* a directory */
    LM_CUBE_FMT_MAT,   /* .mat */
    LM_CUBE_FMT_EXR    /* .exr */
} lm_cube_format;

/* Format from the path alone: a directory is CAVE, otherwise by extension (case-insensitive).
 * Does not open the file; a missing non-directory path is classified by its extension. */
lm_cube_format lm_cube_detect(const char *path);

/* Read any supported cube into *cube (allocated; free with lm_cube_free). On failure *cube is
 * zeroed and e holds "<path>: <problem>": LM_ERR_IO (missing, unreadable, a directory where a
 * file is expected), LM_ERR_FORMAT (corrupt, truncated, wrong band count or sizes, missing
 * key), LM_ERR_NUMERIC (NaN, inf or negative value), LM_ERR_UNSUPPORTED (unknown extension). */
lm_status lm_cube_read(const char *path, lm_cube *cube, lm_err *e);
/* lm_cube_read with options (o NULL: lm_cube_read_opts_default). A cube that covers less
 * than 420-680 nm is LM_ERR_FORMAT; a .mat key the file lacks is LM_ERR_FORMAT listing the
 * variables it holds. */
lm_status lm_cube_read_with(const char *path, const lm_cube_read_opts *o, lm_cube *cube,
                            lm_err *e);

/* The per-format readers behind lm_cube_read (same contract, no format detection, no
 * resampling: the file's bands and wavelengths, at most LM_CUBE_MAX_BANDS bands). */
lm_status lm_cube_read_cave(const char *dir, lm_cube *cube, lm_err *e);
lm_status lm_cube_read_mat(const char *path, lm_cube *cube, lm_err *e);
lm_status lm_cube_read_exr(const char *path, lm_cube *cube, lm_err *e);
/* The .mat reader with options; resample: as lm_cube_read_with (a .mat cube is resampled as
 * it is received, one band at a time, so it may have up to LM_RESAMPLE_MAX_BANDS bands). */
lm_status lm_cube_read_mat_with(const char *path, const lm_cube_read_opts *o, int resample,
                                lm_cube *cube, lm_err *e);

/* The name under which the .mat reader's child process runs (data/isolate.h); its helper program
 * `lumosaic-reader` (cli/reader_main.c) calls this so that the reader is linked in. */
const char *lm_mat_reader_name(void);

/* Write a spectral OpenEXR: attribute spectralLayoutVersion = "1.0", one FLOAT channel per band
 * named `T.<wavelength>nm` with a comma and 6 decimals (e.g. "T.550,000000nm"), ZIP-compressed
 * (zlib level 1, lossless) scanlines. Wavelengths must be distinct; values finite and >= 0 (clamp network outputs first)
 * else LM_ERR_NUMERIC and nothing is written. Atomic: `<path>.tmp.<pid>` then rename; on
 * failure the temporary file is removed. */
lm_status lm_cube_write_exr(const char *path, const lm_cube *cube, lm_err *e);

/* The sidecar of path (resample.h), if any, replaces cube's wavelengths (its count must be
 * cube->bands, else LM_ERR_FORMAT naming path). Called by every reader. */
lm_status lm_cube_apply_sidecar(const char *path, lm_cube *cube, lm_err *e);

/* LM_OK if every value is finite and >= 0; else LM_ERR_NUMERIC "<what>: band b (w nm) has
 * NaN|inf|negative value v at (x=.., y=..)". what names the file in messages. */
lm_status lm_cube_check_values(const lm_cube *cube, const char *what, lm_err *e);
/* The same for one band's plane of width x height values (band: 1-based, for the message). */
lm_status lm_cube_check_plane(const float *p, int width, int height, int band, float nm,
                              const char *what, lm_err *e);

/* The spectral EXR channel name of a wavelength: "T.550,000000nm". Returns 0 or -1 if n is too
 * small. */
int lm_spectral_channel_name(char *buf, size_t n, float wavelength_nm);

/* Parse a spectral channel name "<prefix><number>nm" (number with ',' or '.' as the decimal
 * separator, optional exponent). Returns 1 and sets *nm on a match, 0 otherwise. */
int lm_spectral_channel_parse(const char *name, const char *prefix, double *nm);

#endif
