/* doe_psf.c — the differentiable PSF of a DOE (doe.h, lm_doe_psf_t): the same optics as doe.c's
 * lm_doe_psf, written with tensor ops so the tape carries gradients to the height map.
 * Chain per wavelength (batched over the nb wavelengths of a call):
 *   t (m x m, heights as fractions of max_height)          the trainable map
 *   phase_b = 2 pi (n_b - 1) hmax / l_b * t + pi |x|^2 / (l_b z)    lm_mul + lm_add (the
 *             Fresnel chirp is a constant tensor)
 *   zero-padded to N x N (lm_pad2d; the pupil's position only multiplies the field by a linear
 *             phase, so the intensity is that of doe.c, which wraps the pupil round index 0)
 *   field   = mask e^{i phase}       lm_polar (mask: the aperture, constant)
 *   U       = fft2(field)            lm_fft2 (FFT order: index 0 on the axis)
 *   I       = |U|^2                  lm_abs2
 *   cells   = area integral over the sensor pixels   lm_area_sample (K = LM_DOE_SUPERSAMPLE,
 *             ratio p / du_b, du_b = l_b z / (N dx)), as doe.c's resample
 *   psf     = cells / sum(cells)     lm_sum + lm_div (unit sum over the window)
 * What it is not: quantisation (the caller quantises t, e.g. train/doe_opt.c) or the camera. */
#include "data/doe.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

lm_tensor *lm_doe_psf_t(lm_ctx *c, const lm_doe *d, lm_tensor *t, const double *lambda_m, int nb)
{
    if (!lm_check_inputs(c, "doe_psf", 1, t)) return NULL;
    int m = d->m, N = d->grid, S = d->psf_size;
    char s[64];
    if (t->ndim != 2 || t->shape[0] != m || t->shape[1] != m || !d->mask) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "doe_psf: height map %s; this DOE has %d x %d samples",
                    lm_shape_str(t, s, sizeof s), m, m);
        return NULL;
    }
    if (nb < 1 || nb > LM_AREA_MAX_B || !lambda_m) {
        lm_ctx_fail(c, LM_ERR_ARG, "doe_psf: %d wavelengths (1..%d)", nb, LM_AREA_MAX_B);
        return NULL;
    }
    /* the constants, filled on the host and copied (a device ctx places them on its device) */
    size_t mm = (size_t)m * m, NN = (size_t)N * N;
    float *hs = malloc((size_t)nb * sizeof(float)), *hc = malloc((size_t)nb * mm * sizeof(float));
    float *hm = calloc((size_t)nb * NN, sizeof(float));
    double ratio[LM_AREA_MAX_B];
    lm_status bad = !hs || !hc || !hm ? lm_ctx_fail(c, LM_ERR_NOMEM, "doe_psf: out of memory")
                                      : LM_OK;
    for (int b = 0; b < nb && !bad; b++) {
        double l = lambda_m[b];
        if (!(l > 0)) {
            bad = lm_ctx_fail(c, LM_ERR_ARG, "doe_psf: wavelength %g m", l);
            break;
        }
        hs[b] = (float)(2 * M_PI * (lm_doe_index(d, l) - 1.0) * d->max_height_m / l);
        ratio[b] = d->sensor_pitch_m / (l * d->distance_m / (N * d->pitch_m));
        for (int i = 0; i < m; i++)
            for (int j = 0; j < m; j++) {
                double y = (i - m / 2) * d->pitch_m, x = (j - m / 2) * d->pitch_m;
                hc[b * mm + (size_t)i * m + j] = (float)(M_PI * (x * x + y * y) /
                                                         (l * d->distance_m));
                hm[b * NN + (size_t)i * N + j] = d->mask[(size_t)i * m + j];
            }
    }
    lm_tensor *scale = bad ? NULL : lm_tensor_from(c, 3, (int[]){nb, 1, 1}, hs);
    lm_tensor *chirp = bad ? NULL : lm_tensor_from(c, 3, (int[]){nb, m, m}, hc);
    lm_tensor *mask = bad ? NULL : lm_tensor_from(c, 4, (int[]){nb, 1, N, N}, hm);
    free(hs), free(hc), free(hm);
    if (!scale || !chirp || !mask) return NULL;
    lm_tensor *t3 = lm_reshape(c, t, 3, (int[]){1, m, m});
    lm_tensor *ph = lm_add(c, lm_mul(c, t3, scale), chirp);
    ph = lm_pad2d(c, lm_reshape(c, ph, 4, (int[]){nb, 1, m, m}), 0, N - m, 0, N - m,
                  LM_PAD_ZERO);
    lm_tensor *I = lm_abs2(c, lm_fft2(c, lm_polar(c, mask, ph), 0));
    lm_tensor *cells = lm_area_sample(c, lm_reshape(c, I, 3, (int[]){nb, N, N}), S,
                                      LM_DOE_SUPERSAMPLE, ratio);
    return lm_div(c, cells, lm_sum(c, cells, 0x6, 1));
}

lm_tensor *lm_doe_height_t(lm_ctx *c, const lm_doe *d)
{
    if (!d->height || !(d->max_height_m > 0)) {
        lm_ctx_fail(c, LM_ERR_ARG, "doe: no height map");
        return NULL;
    }
    size_t n = (size_t)d->m * d->m;
    float *h = malloc(n * sizeof(float));
    if (!h) {
        lm_ctx_fail(c, LM_ERR_NOMEM, "doe: out of memory");
        return NULL;
    }
    for (size_t k = 0; k < n; k++) h[k] = (float)(d->height[k] / d->max_height_m);
    lm_tensor *t = lm_tensor_from(c, 2, (int[]){d->m, d->m}, h);
    free(h);
    return t;
}
