/* srgb.c — reflectance cube -> sRGB under D65 (CIE 1931 2-degree observer, IEC 61966-2-1).
 * What it is: band weights integrated from the bundled 1 nm CMF and 5 nm D65 tables, and a
 * per-pixel 3 x bands product followed by the sRGB matrix and transfer function (OpenMP over
 * rows). What it is not: colour management beyond sRGB output. */
#include "data/srgb.h"
#include "data/spectra.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define CMF_FILE "spectra/cie1931_2deg_xyz_cmfs_360-830_1nm.csv"
#define D65_FILE "spectra/cie_d65_spd.csv"

/* IEC 61966-2-1: XYZ (D65) -> linear sRGB */
static const float XYZ_TO_SRGB[3][3] = {{3.2406f, -1.5372f, -0.4986f},
                                        {-0.9689f, 1.8758f, 0.0415f},
                                        {0.0557f, -0.2040f, 1.0570f}};

static lm_status load_tables(lm_csv_table *cmf, lm_spectrum *d65, lm_err *err)
{
    char path[1024];
    memset(cmf, 0, sizeof *cmf);
    memset(d65, 0, sizeof *d65);
    lm_status st = lm_data_path(CMF_FILE, path, sizeof path, err);
    if (!st) st = lm_csv_table_load(path, cmf, err);
    if (!st && cmf->cols != 4)
        st = lm_err_set(err, LM_ERR_FORMAT, "srgb: '%s' has %d columns; expected wavelength, "
                        "xbar, ybar, zbar", path, cmf->cols);
    if (!st) st = lm_data_path(D65_FILE, path, sizeof path, err);
    if (!st) st = lm_spectrum_load(path, NULL, 1, d65, err);
    if (st) {
        lm_csv_table_free(cmf);
        lm_spectrum_free(d65);
    }
    return st;
}

/* Product D65(lambda) * cmf_k(lambda) sampled on the CMF table's wavelengths. */
static lm_status product_spectrum(const lm_csv_table *cmf, const lm_spectrum *d65, int k,
                                  lm_spectrum *out, lm_err *err)
{
    int n = cmf->rows;
    double *wl = malloc((size_t)n * sizeof(double)), *v = malloc((size_t)n * sizeof(double));
    lm_status st = LM_ERR_NOMEM;
    if (wl && v) {
        for (int i = 0; i < n; i++) {
            wl[i] = cmf->data[(size_t)i * cmf->cols];
            v[i] = lm_spectrum_eval(d65, wl[i]) * cmf->data[(size_t)i * cmf->cols + 1 + k];
        }
        st = lm_spectrum_from_arrays(wl, v, n, out, err);
    } else {
        lm_err_set(err, st, "srgb: out of memory");
    }
    free(wl);
    free(v);
    return st;
}

static lm_status check_wavelengths(const float *wl, int bands, lm_err *err)
{
    if (bands < 2 || bands > LM_CUBE_MAX_BANDS)
        return lm_err_set(err, LM_ERR_ARG, "srgb: %d bands; need 2..%d", bands,
                          LM_CUBE_MAX_BANDS);
    for (int b = 0; b < bands; b++) {
        if (!(wl[b] >= 360.0f && wl[b] <= 830.0f))
            return lm_err_set(err, LM_ERR_ARG, "srgb: band %d at %g nm is outside the CIE table "
                              "(360..830 nm)", b, wl[b]);
        if (b > 0 && !(wl[b] > wl[b - 1]))
            return lm_err_set(err, LM_ERR_ARG, "srgb: band wavelengths must increase (band %d: "
                              "%g nm after %g nm)", b, wl[b], wl[b - 1]);
    }
    return LM_OK;
}

lm_status lm_srgb_init(lm_srgb *s, const float *wavelength, int bands, lm_err *err)
{
    memset(s, 0, sizeof *s);
    lm_status st = check_wavelengths(wavelength, bands, err);
    if (st) return st;
    lm_csv_table cmf;
    lm_spectrum d65;
    st = load_tables(&cmf, &d65, err);
    if (st) return st;
    for (int k = 0; k < 3 && !st; k++) {
        lm_spectrum p;
        st = product_spectrum(&cmf, &d65, k, &p, err);
        for (int b = 0; !st && b < bands; b++) {
            double c = wavelength[b];
            double lo = b > 0 ? 0.5 * (c + wavelength[b - 1]) : c - 0.5 * (wavelength[1] - c);
            double hi = b < bands - 1 ? 0.5 * (c + wavelength[b + 1])
                                      : c + 0.5 * (c - wavelength[b - 1]);
            s->w[k][b] = (float)lm_spectrum_integrate(&p, lo, hi);
        }
        if (!st) lm_spectrum_free(&p);
    }
    lm_csv_table_free(&cmf);
    lm_spectrum_free(&d65);
    if (st) return st;
    double white = 0.0;
    for (int b = 0; b < bands; b++) white += s->w[1][b];
    if (!(white > 0.0))
        return lm_err_set(err, LM_ERR_ARG, "srgb: the bands have no luminance weight");
    for (int k = 0; k < 3; k++)
        for (int b = 0; b < bands; b++) s->w[k][b] = (float)(s->w[k][b] / white);
    memcpy(s->wavelength, wavelength, (size_t)bands * sizeof(float));
    s->bands = bands;
    return LM_OK;
}

void lm_srgb_xyz(const lm_srgb *s, const float *spectrum, long stride, float xyz[3])
{
    float acc[3] = {0.0f, 0.0f, 0.0f};
    for (int b = 0; b < s->bands; b++) {
        float r = spectrum[b * stride];
        for (int k = 0; k < 3; k++) acc[k] += s->w[k][b] * r;
    }
    memcpy(xyz, acc, sizeof acc);
}

static float srgb_gamma(float v)
{
    if (!(v > 0.0f)) v = 0.0f; /* also NaN */
    else if (v > 1.0f) v = 1.0f;
    return v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
}

void lm_srgb_encode(const float xyz[3], float rgb[3])
{
    for (int i = 0; i < 3; i++) {
        float lin = XYZ_TO_SRGB[i][0] * xyz[0] + XYZ_TO_SRGB[i][1] * xyz[1] +
                    XYZ_TO_SRGB[i][2] * xyz[2];
        rgb[i] = srgb_gamma(lin);
    }
}

lm_status lm_srgb_render(const lm_srgb *s, const lm_cube *cube, float exposure, uint8_t *rgb8,
                         float *rgb, lm_err *err)
{
    if (cube->bands != s->bands || !cube->data)
        return lm_err_set(err, LM_ERR_SHAPE, "srgb: cube has %d bands, the renderer was set up "
                          "for %d", cube->bands, s->bands);
    for (int b = 0; b < s->bands; b++)
        if (fabsf(cube->wavelength[b] - s->wavelength[b]) > 0.01f)
            return lm_err_set(err, LM_ERR_SHAPE, "srgb: cube band %d is at %g nm, the renderer "
                              "was set up for %g nm", b, cube->wavelength[b], s->wavelength[b]);
    if (!(exposure >= 0.0f) || !isfinite(exposure))
        return lm_err_set(err, LM_ERR_ARG, "srgb: exposure %g must be finite and >= 0", exposure);
    long n = (long)cube->height * cube->width;
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; i++) {
        float xyz[3], out[3];
        lm_srgb_xyz(s, cube->data + i, n, xyz);
        for (int k = 0; k < 3; k++) xyz[k] *= exposure;
        lm_srgb_encode(xyz, out);
        for (int k = 0; k < 3; k++) {
            if (rgb) rgb[i * 3 + k] = out[k];
            if (rgb8) rgb8[i * 3 + k] = (uint8_t)lrintf(out[k] * 255.0f);
        }
    }
    return LM_OK;
}

lm_status lm_srgb_render_cube(const lm_cube *cube, float exposure, uint8_t *rgb8, float *rgb,
                              lm_err *err)
{
    lm_srgb s;
    lm_status st = lm_srgb_init(&s, cube->wavelength, cube->bands, err);
    return st ? st : lm_srgb_render(&s, cube, exposure, rgb8, rgb, err);
}
