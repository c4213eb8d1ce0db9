/* metrics.h — the reconstruction metrics of system.md §10, defined once and used everywhere.
 * What it is: PSNR (peak 1, MSE over all bands and pixels), SSIM (per band, Gaussian window
 * 11 x 11 with sigma 1.5, K1 0.01, K2 0.03, data range 1, computed where the window fits inside
 * the image — the 'valid' region of Wang et al.'s reference code — and averaged over the region
 * and then over bands), MAE (mean absolute error), SAM (mean over pixels of the angle between
 * predicted and true spectra in degrees; pixels whose true spectrum is all zero are skipped; a
 * zero predicted spectrum against a non-zero true one counts as 90 degrees). Everything is
 * accumulated in double. Inputs are planar cubes C x H x W (band-major) in [0, 1].
 * The project evaluates the 31 bands 400..700 nm: channels 1..31 of the 33-channel target
 * (lm_metrics_target33). What it is not: differentiable (no tensors), or a loss. */
#ifndef LM_METRICS_H
#define LM_METRICS_H
#include "tensor/status.h"

#define LM_SSIM_WIN 11
#define LM_PSNR_MAX_DB 100.0 /* PSNR of identical cubes (MSE floored at 1e-10) */

typedef struct lm_metrics {
    double psnr, ssim, mae, sam;
    long sam_pixels;             /* pixels that entered SAM */
} lm_metrics;

/* Bands [b0, b0 + nb) of C x H x W cubes pred and truth (same layout). */
double lm_metric_psnr(const float *pred, const float *truth, int C, int H, int W, int b0, int nb);
double lm_metric_mae(const float *pred, const float *truth, int C, int H, int W, int b0, int nb);
/* Returns the mean angle in degrees (0 when no pixel has a non-zero true spectrum); *counted
 * (may be NULL) receives the number of pixels used. */
double lm_metric_sam(const float *pred, const float *truth, int C, int H, int W, int b0, int nb,
                     long *counted);
/* Mean SSIM of one H x W band (H, W >= LM_SSIM_WIN). */
double lm_metric_ssim_band(const float *x, const float *y, int H, int W);
double lm_metric_ssim(const float *pred, const float *truth, int C, int H, int W, int b0, int nb);

/* All four on bands [b0, b0 + nb). LM_ERR_SHAPE if the band range is outside 0..C-1 or
 * H, W < LM_SSIM_WIN (message starts with "metrics:"). */
lm_status lm_metrics_compute(const float *pred, const float *truth, int C, int H, int W, int b0,
                             int nb, lm_metrics *out, lm_err *err);
/* The project's evaluation: the 31 bands 400..700 nm of 33-channel cubes (channels 1..31). */
lm_status lm_metrics_target33(const float *pred, const float *truth, int H, int W,
                              lm_metrics *out, lm_err *err);

/* Running mean over samples (validation sets): add per-sample metrics, read the mean. */
typedef struct lm_metrics_acc { lm_metrics sum; long n; } lm_metrics_acc;
void lm_metrics_acc_add(lm_metrics_acc *a, const lm_metrics *m);
lm_metrics lm_metrics_acc_mean(const lm_metrics_acc *a);

#endif
