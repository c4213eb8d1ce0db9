/* metrics.c — PSNR, SSIM, MAE and SAM (system.md §10; definitions in metrics.h). */
#include "data/metrics.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const float *band(const float *cube, int b, int H, int W)
{
    return cube + (size_t)b * H * W;
}

double lm_metric_psnr(const float *pred, const float *truth, int C, int H, int W, int b0, int nb)
{
    (void)C;
    long n = (long)nb * H * W;
    const float *p = band(pred, b0, H, W), *t = band(truth, b0, H, W);
    double s = 0.0;
    for (long i = 0; i < n; i++) {
        double d = (double)p[i] - (double)t[i];
        s += d * d;
    }
    double mse = s / (double)n;
    if (mse < 1e-10) mse = 1e-10;
    return -10.0 * log10(mse);
}

double lm_metric_mae(const float *pred, const float *truth, int C, int H, int W, int b0, int nb)
{
    (void)C;
    long n = (long)nb * H * W;
    const float *p = band(pred, b0, H, W), *t = band(truth, b0, H, W);
    double s = 0.0;
    for (long i = 0; i < n; i++) s += fabs((double)p[i] - (double)t[i]);
    return s / (double)n;
}

double lm_metric_sam(const float *pred, const float *truth, int C, int H, int W, int b0, int nb,
                     long *counted)
{
    (void)C;
    long hw = (long)H * W, cnt = 0;
    double sum = 0.0;
    for (long px = 0; px < hw; px++) {
        double pt = 0.0, pp = 0.0, tt = 0.0;
        for (int b = b0; b < b0 + nb; b++) {
            double p = pred[b * hw + px], t = truth[b * hw + px];
            pt += p * t;
            pp += p * p;
            tt += t * t;
        }
        if (tt == 0.0) continue;
        double cosv = pp > 0.0 ? pt / sqrt(pp * tt) : 0.0;
        if (cosv > 1.0) cosv = 1.0;
        if (cosv < -1.0) cosv = -1.0;
        sum += acos(cosv) * (180.0 / M_PI);
        cnt++;
    }
    if (counted) *counted = cnt;
    return cnt ? sum / (double)cnt : 0.0;
}

/* Normalised 1-D Gaussian of LM_SSIM_WIN taps, sigma 1.5 (the 2-D window is its outer
 * product). */
static void gauss_taps(double *g)
{
    double s = 0.0;
    for (int i = 0; i < LM_SSIM_WIN; i++) {
        double d = i - (LM_SSIM_WIN - 1) / 2.0;
        g[i] = exp(-d * d / (2.0 * 1.5 * 1.5));
        s += g[i];
    }
    for (int i = 0; i < LM_SSIM_WIN; i++) g[i] /= s;
}

/* Separable 'valid' filtering of the five moment images: out[k] is Ho x Wo. */
static void window_moments(const float *x, const float *y, int H, int W, double *const *out,
                           double *tmp)
{
    double g[LM_SSIM_WIN];
    gauss_taps(g);
    int Ho = H - LM_SSIM_WIN + 1, Wo = W - LM_SSIM_WIN + 1;
    for (int k = 0; k < 5; k++) {
        for (int r = 0; r < H; r++)
            for (int c = 0; c < Wo; c++) {
                double s = 0.0;
                for (int i = 0; i < LM_SSIM_WIN; i++) {
                    double a = x[r * W + c + i], b = y[r * W + c + i];
                    double v = k == 0 ? a : k == 1 ? b : k == 2 ? a * a : k == 3 ? b * b : a * b;
                    s += g[i] * v;
                }
                tmp[r * Wo + c] = s;
            }
        for (int r = 0; r < Ho; r++)
            for (int c = 0; c < Wo; c++) {
                double s = 0.0;
                for (int i = 0; i < LM_SSIM_WIN; i++) s += g[i] * tmp[(r + i) * Wo + c];
                out[k][r * Wo + c] = s;
            }
    }
}

double lm_metric_ssim_band(const float *x, const float *y, int H, int W)
{
    const double C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;
    int Ho = H - LM_SSIM_WIN + 1, Wo = W - LM_SSIM_WIN + 1;
    if (Ho < 1 || Wo < 1) return NAN;
    size_t n = (size_t)Ho * Wo;
    double *buf = malloc((5 * n + (size_t)H * Wo) * sizeof *buf);
    if (!buf) return NAN;
    double *m[5] = {buf, buf + n, buf + 2 * n, buf + 3 * n, buf + 4 * n};
    window_moments(x, y, H, W, m, buf + 5 * n);
    double s = 0.0;
    for (size_t i = 0; i < n; i++) {
        double mx = m[0][i], my = m[1][i];
        double vx = m[2][i] - mx * mx, vy = m[3][i] - my * my, cxy = m[4][i] - mx * my;
        s += ((2 * mx * my + C1) * (2 * cxy + C2)) / ((mx * mx + my * my + C1) * (vx + vy + C2));
    }
    free(buf);
    return s / (double)n;
}

double lm_metric_ssim(const float *pred, const float *truth, int C, int H, int W, int b0, int nb)
{
    (void)C;
    double s = 0.0;
    for (int b = b0; b < b0 + nb; b++)
        s += lm_metric_ssim_band(band(pred, b, H, W), band(truth, b, H, W), H, W);
    return s / nb;
}

lm_status lm_metrics_compute(const float *pred, const float *truth, int C, int H, int W, int b0,
                             int nb, lm_metrics *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    if (b0 < 0 || nb < 1 || b0 + nb > C)
        return lm_err_set(err, LM_ERR_SHAPE, "metrics: bands [%d, %d) outside the %d channels",
                          b0, b0 + nb, C);
    if (H < LM_SSIM_WIN || W < LM_SSIM_WIN)
        return lm_err_set(err, LM_ERR_SHAPE, "metrics: %d x %d image is smaller than the %d x %d "
                          "SSIM window", H, W, LM_SSIM_WIN, LM_SSIM_WIN);
    out->psnr = lm_metric_psnr(pred, truth, C, H, W, b0, nb);
    out->ssim = lm_metric_ssim(pred, truth, C, H, W, b0, nb);
    out->mae = lm_metric_mae(pred, truth, C, H, W, b0, nb);
    out->sam = lm_metric_sam(pred, truth, C, H, W, b0, nb, &out->sam_pixels);
    if (isnan(out->ssim))
        return lm_err_set(err, LM_ERR_NOMEM, "metrics: out of memory for SSIM of %d x %d", H, W);
    return LM_OK;
}

lm_status lm_metrics_target33(const float *pred, const float *truth, int H, int W,
                              lm_metrics *out, lm_err *err)
{
    return lm_metrics_compute(pred, truth, 33, H, W, 1, 31, out, err);
}

void lm_metrics_acc_add(lm_metrics_acc *a, const lm_metrics *m)
{
    a->sum.psnr += m->psnr;
    a->sum.ssim += m->ssim;
    a->sum.mae += m->mae;
    a->sum.sam += m->sam;
    a->sum.sam_pixels += m->sam_pixels;
    a->n++;
}

lm_metrics lm_metrics_acc_mean(const lm_metrics_acc *a)
{
    lm_metrics r = a->sum;
    if (a->n > 0) {
        r.psnr /= a->n;
        r.ssim /= a->n;
        r.mae /= a->n;
        r.sam /= a->n;
    }
    return r;
}
