/* mosaic.h — the mosaic description (lm_mosaic): how the raw coded frame maps to the network's
 * input channels, and its derivation from a system description.
 * What it is: channel order, tile phases and each channel's 33-channel response (system.md §3,
 * §6): channels are the tile positions ordered by the peak wavelength of their LED (UV first;
 * ties between positions of one LED in raster order), so the default system gives one channel
 * per LED in peak order. A channel's response is its LED's 41-bin a_l reduced to the target
 * grid exactly as the target is: ch 0 = mean of the 380/390 bins, 1..31 = 400..700 nm,
 * ch 32 = mean of the 710..780 bins. Filled here; models only read it.
 * What it is not: the demosaic (lm_mosaic_demosaic, models/layers.h) or the system loader
 * (data/system.h). The one header of data/ that models/ may include. */
#ifndef LM_MOSAIC_H
#define LM_MOSAIC_H
#include "tensor/status.h"

struct lm_system; /* data/system.h */

#define LM_MOSAIC_MAX_CH 64
#define LM_MOSAIC_RESP_CH 33
typedef struct lm_mosaic {
    int ty, tx;                    /* tile rows, cols (3, 4) */
    int nch;                       /* channels = LEDs (12) */
    int phase_y[LM_MOSAIC_MAX_CH]; /* channel k (by LED wavelength) -> tile phase */
    int phase_x[LM_MOSAIC_MAX_CH];
    /* Optional: each channel's LED response on the 33-channel target grid (system.md §3),
     * as SRNet's per-pixel response map needs; filled from the system description. */
    int has_response;
    float response[LM_MOSAIC_MAX_CH][LM_MOSAIC_RESP_CH];
} lm_mosaic;

/* The paper's default: 3x4 tile, channels ordered by LED wavelength for the map of
 * system.md §2 (UV, Violet, RoyalBlue, Blue, Cyan, Green, Lime, Amber, RedOrange, Red, DeepRed,
 * FarRed). Used when no system description is given. */
void lm_mosaic_default(lm_mosaic *m);

/* Errors: LM_ERR_ARG when the system is not on the 380/10/41 grid or its tile has more than
 * LM_MOSAIC_MAX_CH positions; the message starts with "mosaic:". */
lm_status lm_mosaic_from_system(const struct lm_system *sys, lm_mosaic *m, lm_err *err);
/* The 33-channel reduction of one 41-bin spectrum (the target's rule). */
void lm_reduce41_to33(const float *in41, float *out33);

#endif
