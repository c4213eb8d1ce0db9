/* fit_lmmse.h — the closed-form fit of the lmmse floor (models/lmmse.c): normal equations of
 * every tile phase's K x K raw window -> 33 channels, accumulated in double over clean training
 * patches of the loader, solved by Cholesky for every noise level of the family with the noise
 * added analytically (s^2 on the window diagonal) and a ridge chosen on the validation split.
 * With random ReLU features (lmmse-rf) the readout is fitted the same way, on features of
 * noisy samples at six levels. What it is not: SGD (train.c) or the model itself. */
#ifndef LM_FIT_LMMSE_H
#define LM_FIT_LMMSE_H
#include "models/model.h"
#include "data/forward.h"
#include <stdatomic.h>
#include <stdio.h>

typedef struct lm_lmmse_fit_report {
    long patches, val_patches;   /* training / validation patches read */
    long rows;                   /* training pixels (rows of the normal equations), all phases */
    double ridge[LM_LMMSE_LEVELS];    /* chosen ridge per level, relative to the mean window
                                       * second moment (the default when no validation) */
    double synth_weight[LM_LMMSE_LEVELS]; /* chosen share of synthetic patches in the
                                           * statistics (NaN: an interpolated level) */
    double val_psnr[LM_LMMSE_LEVELS]; /* validation PSNR (31 bands, interior pixels, noise at
                                       * the level's sd); NaN without a validation split */
    double seconds;              /* the whole fit */
    double seconds_solve;        /* of which solving (ridge and share search, every level) */
    long patches_asked;          /* the training patches asked for (patches: those read) */
    int budget_spent;            /* 1: accumulation stopped at ctl->budget_s (fitted from
                                  * the patches read by then) */
    int interrupted;             /* the value of ctl->interrupt when it stopped the
                                  * accumulation (0: not interrupted) */
} lm_lmmse_fit_report;

/* Control of a long fit (all optional: zeros = none). */
typedef struct lm_lmmse_fit_ctl {
    FILE *progress;              /* progress lines (patches read, elapsed, ETA), or NULL */
    const char *name;            /* the model's name in them */
    const atomic_int *interrupt; /* once nonzero, no more training patches are read: the
                                  * filters are solved from those read so far (with random
                                  * features or a sensor model, whose levels need passes of
                                  * their own: LM_ERR_INTERRUPTED unless the last pass was
                                  * under way) */
    double budget_s;             /* > 0: stop reading training patches once this many
                                  * seconds have passed, and solve from those read */
    int cpu_clock;               /* the budget counts the process's CPU time, not the wall */
    double b0_noise_ratio;       /* > 0: two buckets, the analytic noise of bucket 0's window
                                  * is this times bucket 1's sd (shot noise: about
                                  * 1 / sqrt(LEDs - 1), bucket 0 collecting the other LEDs'
                                  * light); 0 = the same sd on both (the relative-Gaussian
                                  * convention's conservative filter) */
} lm_lmmse_fit_ctl;

typedef struct lm_dataset lm_dataset;
/* Fit m (an lmmse model) from `patches` training patches of d (batches 0.. of `batch`; d must
 * be opened without noise: the fit adds it analytically) of size ph x pw, and d's validation
 * samples. Writes every level's filters into m. */
/* sensor: clip (to [0, 1]) and bits applied after the noise (NULL or zeros = none); with
 * either, or with random features, the noise is sampled at six levels (the others
 * interpolated), since the analytic term no longer holds. */
/* synth: the synthetic patches' share of the statistics (< 0: chosen on the validation split,
 * or as sampled without one). */
lm_status lm_lmmse_fit(lm_model *m, lm_dataset *d, int ph, int pw, long patches, int batch,
                       double synth, const lm_noise_opts *sensor, lm_lmmse_fit_report *rep, lm_err *err);
/* The same under control (ctl NULL: as lm_lmmse_fit). */
lm_status lm_lmmse_fit_ctl_run(lm_model *m, lm_dataset *d, int ph, int pw, long patches,
                               int batch, double synth, const lm_noise_opts *sensor,
                               const lm_lmmse_fit_ctl *ctl, lm_lmmse_fit_report *rep,
                               lm_err *err);

#endif
