/* lmmse_direct.h — the closed-form floor's direct-path loops (lmmse_direct.c), built once per
 * instruction set. Private to models/lmmse.c. */
#ifndef LM_MODELS_LMMSE_DIRECT_H
#define LM_MODELS_LMMSE_DIRECT_H
#include <stddef.h>

/* out (nch planes of H x W) = the filters of wt applied to the padded planes of pad: for row y
 * and phase column j, the packed filters of phase (y % ty) tx + j start at
 * wt + ((y % ty) tx + j) packed, `lanes` (32 or 40) channels wide; pad holds C planes of
 * PH x PW (the frame padded by K / 2). Rows split over nthreads threads (static). */
void lm_lmmse_direct_rows(const float *wt, size_t packed, const float *pad, int PW, int PH, int C,
                          int K, int ty, int tx, int H, int W, float *out, int nch, int lanes,
                          int nthreads);
#endif
