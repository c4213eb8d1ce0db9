/* cube_io.h — reading spectral cubes from the formats users bring, and writing spectral EXR.
 * What it is: format detection + dispatch (lm_cube_read) and the per-format readers:
 *   - CAVE: a folder of 31 band PNGs `<scene>_ms_01.png .. _31.png` (400-700 nm, 10 nm);
 *     the folder may also hold them one level down (CAVE zips unpack as scene/scene/).
 *     8-bit bands are scaled by 1/255, 16-bit by 1/65535. A band stored with several channels
 *     is accepted only when its colour channels are identical at every pixel (alpha, if any,
 *     is ignored); its first channel is used. Otherwise the band is rejected as not greyscale.
 *   - .mat: ARAD (NTIRE 2022, MATLAB v7.3) key `cube`, H x W x 31 single/double in MATLAB's
 *     order (HDF5 tools show it as 31 x W x H), optional key `bands` (31 wavelengths in nm,
 *     default 400..700); KAUST (MATLAB v5) key `hsi`, H x W x B counts with B >= 31
 *     (34 bands 400-730 nm in the dataset), divided by 4095, first 31 bands kept (400-700 nm).
 *     `cube` wins when a file holds both keys. The file version does not matter (matio).
 *   - .exr: spectral OpenEXR (Fichet, Pacanowski, Wilkie, JCGT 2021): channels
 *     `T.<wavelength>nm` (reflective, comma or dot decimal separator), sorted by wavelength;
 *     if a file has no `T.` channel, the emissive `S0.<wavelength>nm` channels are read
 *     instead. Other channels are ignored. HALF or FLOAT channels, scanline storage.
 *     A .mat file's structure is checked first (a truncated file, or a variable whose data
 *     do not cover its dimensions, is LM_ERR_FORMAT), and matio reads it in a child process
 *     with capped memory and CPU time: a fault or a runaway allocation of libmatio/libhdf5 on
 *     a corrupt file is an error naming the file.
 * Every reader checks the claimed size against data/limits.h before allocating the cube.
 * Every cube read is validated: each value must be finite and >= 0, else LM_ERR_NUMERIC
 * naming the file, the band and the pixel. Readers and the writer may run concurrently on
 * different files.
 * What it is not: normalisation (cubes are returned in the file's units), resampling to other
 * wavelengths, or a cache (see the dataset code). */
#ifndef LM_CUBE_IO_H
#define LM_CUBE_IO_H
#include "data/cube.h"

#define LM_CAVE_BANDS 31

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

/* The per-format readers behind lm_cube_read (same contract, no format detection). */
lm_status lm_cube_read_cave(const char *dir, lm_cube *cube, lm_err *e);
lm_status lm_cube_read_mat(const char *path, lm_cube *cube, lm_err *e);
lm_status lm_cube_read_exr(const char *path, lm_cube *cube, lm_err *e);

/* Write a spectral OpenEXR: attribute spectralLayoutVersion = "1.0", one FLOAT channel per band
 * named `T.<wavelength>nm` with a comma and 6 decimals (e.g. "T.550,000000nm"), ZIP-compressed
 * (zlib level 1, lossless) scanlines. Wavelengths must be distinct; values finite and >= 0 (clamp network outputs first)
 * else LM_ERR_NUMERIC and nothing is written. Atomic: `<path>.tmp.<pid>` then rename; on
 * failure the temporary file is removed. */
lm_status lm_cube_write_exr(const char *path, const lm_cube *cube, lm_err *e);

/* LM_OK if every value is finite and >= 0; else LM_ERR_NUMERIC "<what>: band b (w nm) has
 * NaN|inf|negative value v at (x=.., y=..)". what names the file in messages. */
lm_status lm_cube_check_values(const lm_cube *cube, const char *what, lm_err *e);

/* The spectral EXR channel name of a wavelength: "T.550,000000nm". Returns 0 or -1 if n is too
 * small. */
int lm_spectral_channel_name(char *buf, size_t n, float wavelength_nm);

/* Parse a spectral channel name "<prefix><number>nm" (number with ',' or '.' as the decimal
 * separator, optional exponent). Returns 1 and sets *nm on a match, 0 otherwise. */
int lm_spectral_channel_parse(const char *name, const char *prefix, double *nm);

#endif
