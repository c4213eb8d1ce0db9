/* profile.h — per-layer accounting of a model (for `lumosaic info`): output shape, parameters
 * and multiply-accumulates of every conv / transposed conv / linear layer, found by running the
 * model's forward as a dry run — on a backend that allocates tensors but executes no kernel —
 * so even the paper-size HAN at batch 14 is profiled in well under a second.
 * MAC counts (models.md: conv/linear layers only, like forward hooks on the PyTorch classes):
 * conv numel(out) * (Cin/groups) * kh * kw; transposed conv numel(in) * (Cout/groups) * kh * kw;
 * linear numel(out) * in. Ops outside lm_conv_forward / lm_linear_forward (attention matmuls,
 * HAN's CSAM Conv3d, MCAN's frozen bilinear and mosaic convolutions) are not counted.
 * What it is not: a timer (bench/) or a FLOP model of the backward pass. */
#ifndef LM_PROFILE_H
#define LM_PROFILE_H
#include "models/model.h"

typedef struct lm_layer_stat {
    char name[LM_PARAM_NAME_MAX];  /* module name: the weight's name without ".weight" */
    char kind[8];                  /* "conv", "convT", "linear" */
    int ndim, shape[LM_MAX_DIMS];  /* output shape */
    long params;                   /* weight + bias elements */
    double macs;
} lm_layer_stat;

typedef struct lm_profile {
    lm_layer_stat *layers;         /* in call order */
    int n, cap;
    double total_macs;             /* sum over layers */
    long layer_params;             /* sum over layers */
    long model_params;             /* every parameter of the model (incl. non-layer ones) */
    long trainable_params;
    int out_ndim, out_shape[LM_MAX_DIMS];
} lm_profile;

/* A backend that allocates host tensors like the CPU backend but runs no kernel (contents are
 * left uninitialised). For shape/size accounting only. */
lm_backend *lm_backend_dry_run(void);
/* Dry-run forward of `m` on a B x 1 x H x W input (no-grad). Errors (bad sizes, ...) carry the
 * model's message. */
lm_status lm_model_profile(lm_model *m, int B, int H, int W, lm_profile *out, lm_err *err);
void lm_profile_free(lm_profile *p);

#endif
