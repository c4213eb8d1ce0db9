/* fuzz_sidecar.c — the wavelength sidecar (data/wl_sidecar.c) and the resampling map built on
 * its list (data/resample.c): byte 0 picks the form (even: `.wavelengths.txt`, odd: `.json`),
 * the rest is the file. A failure must be one line naming the sidecar (or the cube, for the
 * map); a list must be finite, positive, increasing and at most LM_RESAMPLE_MAX_BANDS long; a
 * map onto 31 bands must have finite, non-negative weights summing to 1 per band. */
#include "tests/fuzz/fuzz_util.h"
#include "data/resample.h"
#include <math.h>

/* Every output band of the map: a copy, or weights >= 0 summing to 1 (within 1e-9). */
static void check_map(const lm_resample *r)
{
    for (int b = 0; b < r->nout; b++) {
        if (r->copy[b] >= 0) {
            if (r->copy[b] >= r->nsrc) abort();
            continue;
        }
        double sum = 0.0;
        for (int s = 0; s < r->nsrc; s++) {
            double w = r->w[(size_t)b * r->nsrc + s];
            if (!isfinite(w) || w < 0.0) abort();
            sum += w;
        }
        if (fabs(sum - 1.0) > 1e-9) abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1) return 0;
    char cube[512], side[512];
    fz_path(cube, "cube.exr");
    const char *name = data[0] % 2 ? "cube.exr.wavelengths.json" : "cube.exr.wavelengths.txt";
    fz_write(side, name, data + 1, size - 1);
    double wl[LM_RESAMPLE_MAX_BANDS];
    int n = -1;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_wavelengths_sidecar(cube, wl, &n, &e);
    fz_check(s, &e, "cube.exr.wavelengths");
    remove(side);
    if (s != LM_OK) return 0;
    if (n < 1 || n > LM_RESAMPLE_MAX_BANDS) abort();
    for (int i = 0; i < n; i++)
        if (!isfinite(wl[i]) || !(wl[i] > 0.0) || (i > 0 && !(wl[i] > wl[i - 1]))) abort();
    lm_resample r;
    lm_err_clear(&e);
    s = lm_resample_init(&r, wl, n, 0, (lm_grid){0, 0.0f, 0.0f}, cube, &e);
    fz_check(s, &e, "cube.exr");
    if (s == LM_OK) check_map(&r);
    lm_resample_free(&r);
    return 0;
}
