/* resample.c — the map from a cube's own bands to the 31-band 400-700 nm grid (method:
 * resample.h), and its application one source band at a time.
 * What it is: wavelength-list checks, the weights (reflection at the edges, bin integration of
 * the piecewise-linear spectrum or interpolation at the band centre), copies where an output
 * band is a source band. What it is not: a reader, or the sidecar parser (wl_sidecar.c). */
#include "data/resample.h"
#include "data/spectra.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define GRID_STEP 10.0
#define ON_BAND_NM 1e-3 /* a source band this close to a centre is that band */

lm_status lm_wavelengths_check(const double *wl, int n, const char *what, lm_err *e)
{
    if (n < 1 || n > LM_RESAMPLE_MAX_BANDS)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: %d wavelengths, expected 1 to %d", what, n,
                          LM_RESAMPLE_MAX_BANDS);
    for (int i = 0; i < n; i++) {
        if (isnan(wl[i]) || !isfinite(wl[i]) || !(wl[i] > 0.0))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: wavelength %d is %s (%g); wavelengths are "
                              "positive numbers in nm", what, i + 1,
                              isnan(wl[i]) ? "NaN" : isfinite(wl[i]) ? "not positive"
                                                                      : "infinite", wl[i]);
        if (i > 0 && !(wl[i] > wl[i - 1]))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: wavelengths are not increasing (wavelength "
                              "%d is %g nm, after %g nm)", what, i + 1, wl[i], wl[i - 1]);
    }
    return LM_OK;
}

int lm_grid_matches(const double *wl, int n, lm_grid g)
{
    if (g.count <= 0 || n != g.count) return 0;
    for (int i = 0; i < n; i++)
        if (fabs(wl[i] - ((double)g.start + (double)g.step * i)) > 0.01 * fabs((double)g.step))
            return 0;
    return 1;
}

/* The source spectrum's argument after reflection about its first / last band. */
static double reflect(const double *wl, int n, double x)
{
    if (x < wl[0]) return 2.0 * wl[0] - x;
    if (x > wl[n - 1]) return 2.0 * wl[n - 1] - x;
    return x;
}

/* Interpolation at x (inside [wl[0], wl[n-1]]): the weights of the two bands around it into
 * row; returns the band x lies on (within ON_BAND_NM), else -1. */
static int interp_weights(const double *wl, int n, double x, double *row)
{
    int i = 0;
    while (i < n - 1 && wl[i + 1] < x) i++;
    if (fabs(x - wl[i]) <= ON_BAND_NM) return i;
    if (i + 1 < n && fabs(x - wl[i + 1]) <= ON_BAND_NM) return i + 1;
    double u = (x - wl[i]) / (wl[i + 1] - wl[i]);
    row[i] += 1.0 - u;
    row[i + 1] += u;
    return -1;
}

/* Adds the integral over [lo, hi] (inside [wl[0], wl[n-1]]) of the piecewise-linear spectrum,
 * as weights of its bands, into row. */
static void integral_weights(const double *wl, int n, double lo, double hi, double *row)
{
    for (int i = 0; i + 1 < n && wl[i] < hi; i++) {
        double p = fmax(lo, wl[i]), q = fmin(hi, wl[i + 1]);
        if (!(q > p)) continue;
        double h = wl[i + 1] - wl[i], tp = (p - wl[i]) / h, tq = (q - wl[i]) / h;
        row[i] += (q - p) * (1.0 - 0.5 * (tp + tq));
        row[i + 1] += (q - p) * 0.5 * (tp + tq);
    }
}

/* The bin [c - 5, c + 5] of the reflected spectrum: the parts beyond either end are the
 * mirror images of parts inside. Divided by the bin's width. */
static void bin_weights(const double *wl, int n, double c, double *row)
{
    double a = c - 0.5 * GRID_STEP, b = c + 0.5 * GRID_STEP, w0 = wl[0], w1 = wl[n - 1];
    if (a < w0) integral_weights(wl, n, 2.0 * w0 - fmin(b, w0), 2.0 * w0 - a, row);
    integral_weights(wl, n, fmax(a, w0), fmin(b, w1), row);
    if (b > w1) integral_weights(wl, n, 2.0 * w1 - b, 2.0 * w1 - fmax(a, w1), row);
    for (int i = 0; i < n; i++) row[i] /= GRID_STEP;
}

static lm_status init_copies(lm_resample *r, const double *wl, int n, const char *what,
                             lm_err *e)
{
    if (n > LM_CUBE_MAX_BANDS)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: %d bands, more than the %d a cube can keep "
                          "as read", what, n, LM_CUBE_MAX_BANDS);
    r->nout = n;
    for (int b = 0; b < n; b++) {
        r->copy[b] = b;
        r->wavelength[b] = (float)wl[b];
    }
    return LM_OK;
}

lm_status lm_resample_init(lm_resample *r, const double *wl, int n, int native, lm_grid keep,
                           const char *what, lm_err *e)
{
    memset(r, 0, sizeof *r);
    lm_status s = lm_wavelengths_check(wl, n, what, e);
    if (s != LM_OK) return s;
    r->nsrc = n;
    lm_grid g31 = {LM_GRID31_COUNT, LM_GRID31_START, (float)GRID_STEP};
    if (native || lm_grid_matches(wl, n, g31) || lm_grid_matches(wl, n, keep))
        return init_copies(r, wl, n, what, e);
    if (wl[0] > LM_RESAMPLE_MIN_NM + ON_BAND_NM || wl[n - 1] < LM_RESAMPLE_MAX_NM - ON_BAND_NM)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: covers %g-%g nm; resampling to 400-700 nm needs "
                          "at least %g-%g nm", what, wl[0], wl[n - 1], LM_RESAMPLE_MIN_NM,
                          LM_RESAMPLE_MAX_NM);
    r->nout = LM_GRID31_COUNT;
    r->dense = (wl[n - 1] - wl[0]) / (n - 1) < GRID_STEP - ON_BAND_NM;
    if (!(r->w = calloc((size_t)r->nout * n, sizeof *r->w)))
        return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", what);
    for (int b = 0; b < r->nout; b++) {
        double c = LM_GRID31_START + GRID_STEP * b, *row = r->w + (size_t)b * n;
        r->wavelength[b] = (float)c;
        r->copy[b] = -1;
        if (r->dense) bin_weights(wl, n, c, row);
        else r->copy[b] = interp_weights(wl, n, reflect(wl, n, c), row);
    }
    return LM_OK;
}

void lm_resample_free(lm_resample *r)
{
    free(r->w);
    r->w = NULL;
}

int lm_resample_uses(const lm_resample *r, int s)
{
    for (int b = 0; b < r->nout; b++)
        if (r->copy[b] == s || (r->copy[b] < 0 && r->w && r->w[(size_t)b * r->nsrc + s] != 0.0))
            return 1;
    return 0;
}

void lm_resample_band(const lm_resample *r, int s, const float *plane, lm_cube *out)
{
    size_t np = (size_t)out->height * out->width;
    for (int b = 0; b < r->nout; b++) {
        float *dst = lm_cube_band(out, b);
        if (r->copy[b] == s) {
            memcpy(dst, plane, np * sizeof *dst);
            continue;
        }
        float w = r->copy[b] < 0 && r->w ? (float)r->w[(size_t)b * r->nsrc + s] : 0.0f;
        if (w == 0.0f) continue;
        for (size_t i = 0; i < np; i++) dst[i] += w * plane[i];
    }
}

lm_status lm_resample_cube(const lm_resample *r, const lm_cube *in, lm_cube *out, lm_err *e)
{
    memset(out, 0, sizeof *out);
    if (in->bands != r->nsrc)
        return lm_err_set(e, LM_ERR_ARG, "resample: a %d-band cube for a map of %d bands",
                          in->bands, r->nsrc);
    lm_status s = lm_cube_alloc(out, r->nout, in->height, in->width, 0.0f, 0.0f);
    if (s != LM_OK)
        return lm_err_set(e, s, "cannot allocate a %d x %d x %d cube", r->nout, in->height,
                          in->width);
    memcpy(out->wavelength, r->wavelength, sizeof(float) * (size_t)r->nout);
    for (int sb = 0; sb < r->nsrc; sb++) lm_resample_band(r, sb, lm_cube_band(in, sb), out);
    return LM_OK;
}
