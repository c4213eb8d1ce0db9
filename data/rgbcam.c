/* rgbcam.c — RGB camera forward model (rgbcam.h): sensitivities x illuminant binned to the
 * 31 bands, white balanced; per-pixel 3 x 31 product; noise via lm_forward_noise. */
#include "data/rgbcam.h"
#include "data/spectra.h"
#include <stdlib.h>
#include <string.h>

#define D65_FILE "spectra/cie_d65_spd.csv"

/* S_c(lambda) * E(lambda) on the sensitivity table's wavelengths, binned to 400..700 nm. */
static lm_status bin_channel(const lm_csv_table *t, int col, const lm_spectrum *illum,
                             double *out, lm_err *err)
{
    int n = t->rows;
    double *wl = malloc((size_t)n * sizeof(double)), *v = malloc((size_t)n * sizeof(double));
    lm_spectrum s = {0};
    lm_status st = LM_OK;
    if (!wl || !v) st = lm_err_set(err, LM_ERR_NOMEM, "rgbcam: out of memory");
    for (int i = 0; !st && i < n; i++) {
        wl[i] = t->data[(size_t)i * t->cols];
        v[i] = t->data[(size_t)i * t->cols + col] * (illum ? lm_spectrum_eval(illum, wl[i]) : 1.0);
    }
    if (!st) st = lm_spectrum_from_arrays(wl, v, n, &s, err);
    if (!st) st = lm_spectrum_bin(&s, LM_GRID31_START, LM_GRID41_STEP, LM_RGBCAM_BANDS, out, err);
    lm_spectrum_free(&s);
    free(wl);
    free(v);
    return st;
}

static lm_status load_illum(lm_rgbcam_illum il, lm_spectrum *d65, lm_err *err)
{
    memset(d65, 0, sizeof *d65);
    if (il == LM_RGBCAM_EQUAL_ENERGY) return LM_OK;
    if (il != LM_RGBCAM_D65) return lm_err_set(err, LM_ERR_ARG, "rgbcam: unknown illuminant %d", il);
    char path[1024];
    lm_status st = lm_data_path(D65_FILE, path, sizeof path, err);
    return st ? st : lm_spectrum_load(path, NULL, 1, d65, err);
}

lm_status lm_rgbcam_load(lm_rgbcam *cam, const char *csv_path, lm_rgbcam_illum illum,
                         lm_err *err)
{
    memset(cam, 0, sizeof *cam);
    cam->illum = illum;
    char path[1024];
    if (!csv_path) {
        if (lm_data_path(LM_RGBCAM_DEFAULT_CSV, path, sizeof path, err)) return err->status;
        csv_path = path;
    }
    lm_spectrum d65;
    lm_status st = load_illum(illum, &d65, err);
    if (st) return st;
    lm_csv_table t = {0};
    st = lm_csv_table_load(csv_path, &t, err);
    static const char *names[3] = {"R", "G", "B"};
    for (int k = 0; k < 3 && !st; k++) {
        int col = lm_csv_table_find(&t, names[k]);
        if (col < 0) {
            st = lm_err_set(err, LM_ERR_FORMAT, "rgbcam: %s has no column '%s' (need R, G, B)",
                            csv_path, names[k]);
            break;
        }
        st = bin_channel(&t, col, illum == LM_RGBCAM_D65 ? &d65 : NULL, cam->bin[k], err);
        double sum = 0;
        for (int b = 0; b < LM_RGBCAM_BANDS; b++) sum += cam->bin[k][b];
        if (!st && !(sum > 0))
            st = lm_err_set(err, LM_ERR_FORMAT, "rgbcam: %s: channel %s has no response in "
                            "400..700 nm", csv_path, names[k]);
        for (int b = 0; b < LM_RGBCAM_BANDS && !st; b++) cam->w[k][b] = (float)(cam->bin[k][b] / sum);
    }
    lm_csv_table_free(&t); /* zeroed by a failed load */
    lm_spectrum_free(&d65);
    return st;
}

void lm_rgbcam_render(const lm_rgbcam *cam, const float *cube, int H, int W, float *rgb,
                      int nthreads)
{
    size_t plane = (size_t)H * W;
    if (nthreads <= 0) nthreads = 1;
#pragma omp parallel for schedule(static) num_threads(nthreads)
    for (int y = 0; y < H; y++) {
        for (int k = 0; k < 3; k++) {
            float *o = rgb + k * plane + (size_t)y * W;
            for (int x = 0; x < W; x++) o[x] = 0.0f;
            for (int b = 0; b < LM_RGBCAM_BANDS; b++) {
                const float *s = cube + b * plane + (size_t)y * W;
                float w = cam->w[k][b];
                for (int x = 0; x < W; x++) o[x] += w * s[x];
            }
        }
    }
}

lm_status lm_rgbcam_simulate(const lm_rgbcam *cam, const float *cube, int H, int W,
                             const lm_noise_opts *noise, lm_rng *rng, float *rgb, int nthreads,
                             lm_err *err)
{
    if (H < 1 || W < 1)
        return lm_err_set(err, LM_ERR_ARG, "rgbcam: image size %d x %d", H, W);
    lm_rgbcam_render(cam, cube, H, W, rgb, nthreads);
    if (!noise) return LM_OK;
    return lm_forward_noise(rgb, 3 * H, W, noise, rng, nthreads, err);
}
