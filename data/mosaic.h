/* mosaic.h — the network front (lm_mosaic) derived from a system description.
 * What it is: channel order, tile phases and each channel's 33-channel response (system.md §3,
 * §6): channels are the tile positions ordered by the peak wavelength of their LED (UV first;
 * ties between positions of one LED in raster order), so the default system gives one channel
 * per LED in peak order. A channel's response is its LED's 41-bin a_l reduced to the target
 * grid exactly as the target is: ch 0 = mean of the 380/390 bins, 1..31 = 400..700 nm,
 * ch 32 = mean of the 710..780 bins.
 * What it is not: the demosaic (models/layers.h) or the system loader (data/system.h). */
#ifndef LM_MOSAIC_SYSTEM_H
#define LM_MOSAIC_SYSTEM_H
#include "data/system.h"
#include "models/layers.h"

/* Errors: LM_ERR_ARG when the system is not on the 380/10/41 grid or its tile has more than
 * LM_MOSAIC_MAX_CH positions; the message starts with "mosaic:". */
lm_status lm_mosaic_from_system(const lm_system *sys, lm_mosaic *m, lm_err *err);
/* The 33-channel reduction of one 41-bin spectrum (the target's rule). */
void lm_reduce41_to33(const float *in41, float *out33);

#endif
