/* cl_params.h — private mirrors of the ops' parameter structs (each is defined privately in
 * its own file under tensor/ops/; the launchers read the same bytes). Each mirror names its source
 * and is pinned by a static assertion on its size; the CPU-vs-OpenCL tests catch a layout
 * change that keeps the size. To be replaced by shared headers when the lead moves them.
 * Enum values (op kinds) are mirrored too, with their source. */
#ifndef LM_CL_PARAMS_H
#define LM_CL_PARAMS_H

/* tensor/ops/binary.c: binary_params, binary_bwd_params, grad_acc_params;
 * op: BIN_ADD 0, BIN_SUB 1, BIN_MUL 2, BIN_DIV 3 */
typedef struct cl_binary_params { int op; } cl_binary_params;
typedef struct cl_binary_bwd_params { int op, which, accumulate; } cl_binary_bwd_params;
typedef struct cl_grad_acc_params { float scale; } cl_grad_acc_params;
_Static_assert(sizeof(cl_binary_params) == 4, "binary_params mirror");
_Static_assert(sizeof(cl_binary_bwd_params) == 12, "binary_bwd_params mirror");
_Static_assert(sizeof(cl_grad_acc_params) == 4, "grad_acc_params mirror");

/* tensor/ops/scalar.c: affine_params (y = s x + t) */
typedef struct cl_affine_params { float s, t; } cl_affine_params;
_Static_assert(sizeof(cl_affine_params) == 8, "affine_params mirror");

/* tensor/ops/activation.c: act_params;
 * kind: ACT_RELU 0, ACT_LEAKY 1, ACT_SIGMOID 2, ACT_TANH 3, ACT_GELU 4 */
typedef struct cl_act_params { int kind; float slope; } cl_act_params;
_Static_assert(sizeof(cl_act_params) == 8, "act_params mirror");

/* tensor/ops/reduce.c: reduce_params (bit d of mask = dim d reduced; y = scale * sum) */
typedef struct cl_reduce_params { unsigned mask; float scale; } cl_reduce_params;
_Static_assert(sizeof(cl_reduce_params) == 8, "reduce_params mirror");

/* tensor/ops/loss.c: loss_params, loss_bwd_params; kind: LOSS_L1 0, LOSS_MSE 1 */
typedef struct cl_loss_params { int kind; } cl_loss_params;
typedef struct cl_loss_bwd_params { int kind; float sign; } cl_loss_bwd_params;
_Static_assert(sizeof(cl_loss_params) == 4, "loss_params mirror");
_Static_assert(sizeof(cl_loss_bwd_params) == 8, "loss_bwd_params mirror");

/* tensor/ops/softmax.c: softmax_params (axis already made non-negative) */
typedef struct cl_softmax_params { int axis; } cl_softmax_params;
_Static_assert(sizeof(cl_softmax_params) == 4, "softmax_params mirror");

/* tensor/ops/layer_norm.c: ln_params */
typedef struct cl_ln_params { float eps; int has_w, has_b; } cl_ln_params;
_Static_assert(sizeof(cl_ln_params) == 12, "ln_params mirror");

/* tensor/ops/l2_normalize.c: l2_params (axis non-negative) */
typedef struct cl_l2_params { int axis; float eps; } cl_l2_params;
_Static_assert(sizeof(cl_l2_params) == 8, "l2_params mirror");

/* tensor/ops/permute.c: permute_params */
typedef struct cl_permute_params { int ndim; int perm[5]; } cl_permute_params;
_Static_assert(sizeof(cl_permute_params) == 24, "permute_params mirror");

/* tensor/ops/shuffle.c: shuffle_params */
typedef struct cl_shuffle_params { int fy, fx; } cl_shuffle_params;
_Static_assert(sizeof(cl_shuffle_params) == 8, "shuffle_params mirror");

/* tensor/ops/concat.c: band_params (band [start, ...) along dim) */
typedef struct cl_band_params { int dim, start; } cl_band_params;
_Static_assert(sizeof(cl_band_params) == 8, "band_params mirror");

/* tensor/ops/pad.c: pad_params; mode: LM_PAD_ZERO 0, LM_PAD_REFLECT 1 (tensor/ops.h) */
typedef struct cl_pad_params { int top, bottom, left, right, mode; } cl_pad_params;
_Static_assert(sizeof(cl_pad_params) == 20, "pad_params mirror");

/* tensor/ops/resize.c: resize_params */
typedef struct cl_resize_params { int align_corners; } cl_resize_params;
_Static_assert(sizeof(cl_resize_params) == 4, "resize_params mirror");

/* tensor/ops/mosaic_upsample.c: mosaic_params (MOSAIC_MAX_CH 64) */
#define CL_MOSAIC_MAX_CH 64
typedef struct cl_mosaic_params {
    int ty, tx, nch;
    int py[CL_MOSAIC_MAX_CH], px[CL_MOSAIC_MAX_CH];
} cl_mosaic_params;
_Static_assert(sizeof(cl_mosaic_params) == 524, "mosaic_params mirror");

#endif
