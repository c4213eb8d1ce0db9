/* layers.h — layers with parameters: 2-D/3-D convolution and linear, with PyTorch-default
 * initialisation (models.md §1), declared into an lm_params under PyTorch module names.
 * What it is not: networks (han.c, mcan.c, ...), which compose these with ops. */
#ifndef LM_LAYERS_H
#define LM_LAYERS_H
#include "data/mosaic.h"
#include "models/params.h"
#include "tensor/ops.h"

typedef struct lm_conv {
    lm_tensor *w, *b;              /* b NULL without bias */
    lm_conv2d_opts o;
    int cin, cout, kh, kw;
    int transposed;                /* ConvTranspose2d: w is Cin x Cout/g x kh x kw */
} lm_conv;

typedef struct lm_conv_spec {
    int cin, cout, kh, kw;
    int stride, pad_h, pad_w, groups;
    int bias;
} lm_conv_spec;

/* Declare "<name>.weight" (and "<name>.bias"). Returns LM_OK or the error. */
lm_status lm_conv_declare(lm_params *p, lm_conv *l, const char *name, lm_conv_spec s,
                          int trainable, lm_err *err);
/* 3x3, stride 1, pad 1, with bias (the default_conv of RCAN/HAN). */
lm_status lm_conv3_declare(lm_params *p, lm_conv *l, const char *name, int cin, int cout,
                           lm_err *err);
lm_status lm_conv_transpose_declare(lm_params *p, lm_conv *l, const char *name, lm_conv_spec s,
                                    lm_err *err);
/* PyTorch default: U(+-1/sqrt(fan_in)) for weight and bias; fan_in = (cin/g)*kh*kw for conv,
 * (cout/g)*kh*kw for transposed conv (PyTorch's quirk). */
void lm_conv_init_default(lm_conv *l, lm_rng *r);
lm_tensor *lm_conv_forward(lm_ctx *c, const lm_conv *l, lm_tensor *x);
/* The plain (ungrouped, not transposed) conv l on the channel concatenation of a
 * (B x Ca x H x W) and s (1 x Cs x H x W: the same for every batch item, broadcast), computed
 * as conv(a, W[:, :Ca]) + (conv(s, W[:, Ca:]) + bias) so the shared half is convolved once,
 * not B times. Equal to lm_conv_forward on the concatenation up to float rounding (the halves
 * are summed separately); differentiable; reported to the layer observer as one layer l. */
/* n (<= 8) convs with the same input channels, kernel, options and bias presence, as one
 * conv (weights and biases concatenated): the result is the channel concatenation of their
 * outputs. stacked = 0: every layer reads all of x; stacked = 1: x is the channel
 * concatenation of the layers' inputs (layer i reads its own block; for grouped layers the
 * groups line up, e.g. depthwise convs stay depthwise). One bigger conv instead of n small
 * ones; the same numbers up to float rounding (the conv path may differ); differentiable;
 * reported to the layer observer as the n layers. */
lm_tensor *lm_conv_forward_concat(lm_ctx *c, const lm_conv *const *ls, int n, lm_tensor *x,
                                  int stacked);
lm_tensor *lm_conv_forward_shared(lm_ctx *c, const lm_conv *l, lm_tensor *a, lm_tensor *s);

typedef struct lm_linear_layer {
    lm_tensor *w, *b;              /* w: out x in */
    int in, out;
} lm_linear_layer;

lm_status lm_linear_declare(lm_params *p, lm_linear_layer *l, const char *name, int in, int out,
                            int bias, lm_err *err);
void lm_linear_init_default(lm_linear_layer *l, lm_rng *r);
lm_tensor *lm_linear_forward(lm_ctx *c, const lm_linear_layer *l, lm_tensor *x);

/* Layer observer (profiling, models/profile.h): while installed for ctx c, every successful
 * lm_conv_forward ("conv" / "convT") and lm_linear_forward ("linear") on c reports its weight,
 * bias (or NULL), input and output. One observer per process; lm_layer_observe(NULL, NULL,
 * NULL) removes it. */
typedef void (*lm_layer_observer)(void *user, const char *kind, const lm_tensor *w,
                                  const lm_tensor *b, const lm_tensor *x, const lm_tensor *y);
void lm_layer_observe(const lm_ctx *c, lm_layer_observer fn, void *user);

/* The network input (the mosaic description, data/mosaic.h): raw B x 1 x H x W ->
 * B x nch x H x W (phase-aware bilinear, differentiable). */
lm_tensor *lm_mosaic_demosaic(lm_ctx *c, const lm_mosaic *m, lm_tensor *raw);

#endif
