/* mosaic.c — the mosaic description: the paper's default and lm_mosaic from an lm_system
 * (see mosaic.h). */
#include "data/mosaic.h"
#include "data/spectra.h"
#include "data/system.h"
#include <math.h>
#include <string.h>

void lm_mosaic_default(lm_mosaic *m)
{
    /* system.md §2 map; tile phase t = row*4 + col:
     * row 0: FarRed Green DeepRed RoyalBlue / row 1: Red Violet Lime UV /
     * row 2: Amber Blue RedOrange Cyan. Channels in LED wavelength order: */
    static const int phase[12][2] = {
        {1, 3}, /* UV */        {1, 1}, /* Violet */   {0, 3}, /* RoyalBlue */
        {2, 1}, /* Blue */      {2, 3}, /* Cyan */     {0, 1}, /* Green */
        {1, 2}, /* Lime */      {2, 0}, /* Amber */    {2, 2}, /* RedOrange */
        {1, 0}, /* Red */       {0, 2}, /* DeepRed */  {0, 0}, /* FarRed */
    };
    memset(m, 0, sizeof *m);
    m->ty = 3;
    m->tx = 4;
    m->nch = 12;
    for (int k = 0; k < 12; k++) {
        m->phase_y[k] = phase[k][0];
        m->phase_x[k] = phase[k][1];
    }
}

void lm_reduce41_to33(const float *in41, float *out33)
{
    out33[0] = 0.5f * (in41[0] + in41[1]);
    for (int k = 1; k <= 31; k++) out33[k] = in41[k + 1];
    double s = 0.0;
    for (int b = 33; b < 41; b++) s += in41[b];
    out33[32] = (float)(s / 8.0);
}

lm_status lm_mosaic_from_system(const lm_system *sys, lm_mosaic *m, lm_err *err)
{
    int npos = sys->tile_rows * sys->tile_cols;
    if (sys->nbins != LM_GRID41_COUNT || fabsf(sys->grid_start - LM_GRID41_START) > 1e-3f ||
        fabsf(sys->grid_step - LM_GRID41_STEP) > 1e-3f)
        return lm_err_set(err, LM_ERR_ARG, "mosaic: system %s is on a %d-bin grid from %g nm "
                          "step %g nm; the 33-channel target needs 380..780 nm in 10 nm bins",
                          sys->path, sys->nbins, sys->grid_start, sys->grid_step);
    if (npos > LM_MOSAIC_MAX_CH)
        return lm_err_set(err, LM_ERR_ARG, "mosaic: system %s has a %d x %d tile (%d positions, "
                          "at most %d supported)", sys->path, sys->tile_rows, sys->tile_cols,
                          npos, LM_MOSAIC_MAX_CH);
    memset(m, 0, sizeof *m);
    m->ty = sys->tile_rows;
    m->tx = sys->tile_cols;
    const int *order = lm_system_peak_order(sys);
    int k = 0;
    for (int i = 0; i < sys->nleds; i++) {
        int led = order[i];
        for (int t = 0; t < npos; t++) {
            if (sys->tile_led[t] != led) continue;
            m->phase_y[k] = t / sys->tile_cols;
            m->phase_x[k] = t % sys->tile_cols;
            lm_reduce41_to33(lm_system_response(sys, led), m->response[k]);
            k++;
        }
    }
    m->nch = k;
    m->has_response = 1;
    return LM_OK;
}
