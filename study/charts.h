/* charts.h — the charts of a study (study.h), drawn by gnuplot.
 * What it is: plain-text data files and one gnuplot script per chart, written to
 * <dir>/charts/, and running gnuplot on them; every script writes <name>.png (pngcairo, or the
 * png terminal when cairo is missing) and <name>.svg. Charts:
 *   accuracy_speed      PSNR at noise 0 % and 10 % against seconds per frame (log scale),
 *                       one point per model, the Pareto front of each level as a dashed line
 *   noise_psnr, noise_ssim, noise_sam   the metric against the noise level, a line per model
 *   train_loss          training loss against iteration, a line per model (log scale)
 *   train_val_psnr      validation PSNR against iteration (only when some run validated)
 * The scripts can be edited and re-run by hand: `cd <dir>/charts && gnuplot <name>.gp`.
 * What it is not: the study run or its table (study.h). */
#ifndef LM_STUDY_CHARTS_H
#define LM_STUDY_CHARTS_H
#include "study/study.h"

/* Pareto front of (seconds, accuracy) points, lower seconds and higher accuracy better:
 * on[i] = 1 when no other point is at least as fast and at least as accurate and better in one
 * of the two. Points with a non-finite value are never on the front (and dominate nothing). */
void lm_study_pareto(const double *seconds, const double *acc, int n, int *on);

/* Is there an executable "gnuplot" on $PATH? */
int lm_charts_gnuplot_available(void);

/* Write the data files and scripts into <dir>/charts/ (created if missing). */
lm_status lm_charts_write(const lm_study_cfg *cfg, const lm_study *s, const char *dir,
                          lm_err *err);

/* Run gnuplot on every chart script written there (its messages go to
 * <dir>/charts/gnuplot.log). LM_ERR_IO naming the script when gnuplot fails or is missing. */
lm_status lm_charts_render(const char *dir, lm_err *err);

#endif
