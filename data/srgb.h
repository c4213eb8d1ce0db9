/* srgb.h — render a reflectance cube to sRGB for previews: illuminant D65, CIE 1931 2-degree
 * observer, IEC 61966-2-1 (sRGB) primaries and transfer function.
 * What it is: per band b, XYZ weights W_k[b] = integral over the band's bin of
 * D65(lambda) * cmf_k(lambda) (the 1 nm CMF table times D65 interpolated linearly, trapezoid
 * rule), scaled so that a perfect white reflector has Y = 1; then XYZ -> linear sRGB (the IEC
 * matrix), clip to [0, 1], sRGB gamma, 8-bit. A band's bin spans half-way to its neighbours
 * (the outer bands extend by half their neighbour spacing): 31 bands 400..700 nm integrate
 * 395..705 nm, 41 bins 380..780 nm integrate 375..785 nm.
 * What it is not: white balancing, tone mapping, or PNG writing (see data/image.h). */
#ifndef LM_SRGB_H
#define LM_SRGB_H
#include <stdint.h>
#include "data/cube.h"
#include "tensor/status.h"

typedef struct lm_srgb {
    int bands;
    float wavelength[LM_CUBE_MAX_BANDS];
    float w[3][LM_CUBE_MAX_BANDS]; /* X, Y, Z weight of each band; sum of w[1] = 1 */
} lm_srgb;

/* Weights for bands at the given centre wavelengths (strictly increasing, >= 2 bands, within
 * the CIE table's 360..830 nm), from the bundled tables data/spectra/cie1931_2deg_xyz_cmfs_
 * 360-830_1nm.csv and cie_d65_spd.csv (see lm_data_dir in spectra.h). Errors: LM_ERR_ARG
 * (bad wavelengths), LM_ERR_IO / LM_ERR_FORMAT (tables missing or malformed). */
lm_status lm_srgb_init(lm_srgb *s, const float *wavelength, int bands, lm_err *err);

/* XYZ of one spectrum (bands values, `stride` floats apart). */
void lm_srgb_xyz(const lm_srgb *s, const float *spectrum, long stride, float xyz[3]);
/* XYZ (Y = 1 white) -> gamma-encoded sRGB in [0, 1] (clipped in linear light). */
void lm_srgb_encode(const float xyz[3], float rgb[3]);

/* Render cube (its bands must match s) multiplied by `exposure` (1 = as is) into rgb8
 * (H * W * 3, interleaved RGB, 8-bit) and/or rgb (H * W * 3 floats in [0, 1], gamma-encoded,
 * for lm_image_write_rgb8); either may be NULL. LM_ERR_SHAPE if the cube's wavelengths differ
 * from s's; LM_ERR_ARG for a negative or non-finite exposure. */
lm_status lm_srgb_render(const lm_srgb *s, const lm_cube *cube, float exposure, uint8_t *rgb8,
                         float *rgb, lm_err *err);
/* lm_srgb_init for the cube's wavelengths, then lm_srgb_render. */
lm_status lm_srgb_render_cube(const lm_cube *cube, float exposure, uint8_t *rgb8, float *rgb,
                              lm_err *err);

#endif
