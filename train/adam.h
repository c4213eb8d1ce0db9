/* adam.h — Adam / AdamW over a parameter block, and learning-rate schedules.
 * What it is: the optimizer state (first and second moments, step count) for the trainable
 * parameters of an lm_params, updated in one flat loop per parameter. PyTorch semantics:
 * weight_decay adds wd * w to the gradient (Adam) or decays w directly (AdamW, decoupled).
 * What it is not: the training loop (train/train.c). */
#ifndef LM_ADAM_H
#define LM_ADAM_H
#include "models/params.h"

typedef enum lm_lr_schedule { LM_LR_CONSTANT = 0, LM_LR_COSINE = 1, LM_LR_STEP = 2 } lm_lr_schedule;

typedef struct lm_adam_cfg {
    float lr, beta1, beta2, eps, weight_decay;
    int decoupled;               /* 1 = AdamW */
    lm_lr_schedule schedule;
    long total_steps;            /* cosine: lr -> lr_min over total_steps */
    float lr_min;
    long step_every;             /* step schedule: lr *= step_gamma every step_every steps */
    float step_gamma;
    long warmup_steps;           /* linear warm-up from 0 (0 = none) */
    float ema;                   /* decay of an exponential moving average of the weights
                                  * (0 = none); update t uses min(ema, (1 + t) / (10 + t)) */
} lm_adam_cfg;

typedef struct lm_adam {
    lm_adam_cfg cfg;
    long step;                   /* number of updates done */
    size_t n;                    /* floats (= params total) */
    float *m, *v;                /* moments, same layout as the params block */
    float *ema;                  /* cfg.ema > 0: the other copy of the weights (the average
                                  * while training; lm_adam_ema_swap exchanges them) */
} lm_adam;

/* Paper defaults: lr 1e-4, betas (0.9, 0.999), eps 1e-8, no decay, constant lr. */
void lm_adam_default_cfg(lm_adam_cfg *cfg);
lm_status lm_adam_init(lm_adam *o, const lm_params *p, const lm_adam_cfg *cfg, lm_err *err);
void lm_adam_free(lm_adam *o);
/* Learning rate used by update number `step` (0-based). */
float lm_adam_lr(const lm_adam_cfg *cfg, long step);
/* One update of every trainable parameter from its gradient (grads are not cleared). */
void lm_adam_step(lm_adam *o, lm_params *p, int nthreads);
/* cfg.ema > 0: exchange the trainable weights with o->ema (exact; twice restores both). The
 * training loop swaps the average in to validate and save, and back to train. */
void lm_adam_ema_swap(lm_adam *o, lm_params *p);

#endif
