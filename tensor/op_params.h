/* op_params.h — the parameter structs and enums of the op kernels, shared by the CPU kernels
 * (the files of tensor/ops/) and the OpenCL launchers (kernels-opencl/cl_ops_*.c, cl_gemm.c).
 *
 * What it is: one definition of what each kernel's `params` pointer points to (plain data, no
 * pointers, so a device backend reads the same bytes), the enum values the kernels switch on
 * (listed in LM_OP_ENUMS, which the OpenCL backend passes to its .cl sources as -D build
 * options), and the small index helpers both sides of matmul and resize need.
 * What it is not: the public op API (tensor/ops.h), nor parameters that only the tape keeps
 * for a backward (those stay private to their op file). */
#ifndef LM_OP_PARAMS_H
#define LM_OP_PARAMS_H
#include "tensor/ops.h"

/* ---- enums the kernels switch on ------------------------------------------------------- */
/* binary.c: the operation of binary_fwd / binary_bwd. */
typedef enum lm_binary_op {
    LM_BIN_ADD = 0, LM_BIN_SUB = 1, LM_BIN_MUL = 2, LM_BIN_DIV = 3
} lm_binary_op;
/* activation.c: the function of activation_fwd / activation_bwd. */
typedef enum lm_act_kind {
    LM_ACT_RELU = 0, LM_ACT_LEAKY = 1, LM_ACT_SIGMOID = 2, LM_ACT_TANH = 3, LM_ACT_GELU = 4
} lm_act_kind;
/* loss.c: the loss of l1_mse_loss_fwd / l1_mse_loss_bwd. */
typedef enum lm_loss_kind { LM_LOSS_L1 = 0, LM_LOSS_MSE = 1 } lm_loss_kind;
/* (pad.c's mode is lm_pad_mode of tensor/ops.h: LM_PAD_ZERO, LM_PAD_REFLECT.) */

/* Every enum value a kernel source may name: X(NAME) per value. The OpenCL backend defines
 * each as -D NAME=value when it builds its program, so .cl files use the names, not numbers. */
#define LM_OP_ENUMS(X)                                                                        \
    X(LM_BIN_ADD) X(LM_BIN_SUB) X(LM_BIN_MUL) X(LM_BIN_DIV)                                   \
    X(LM_ACT_RELU) X(LM_ACT_LEAKY) X(LM_ACT_SIGMOID) X(LM_ACT_TANH) X(LM_ACT_GELU)             \
    X(LM_LOSS_L1) X(LM_LOSS_MSE)                                                              \
    X(LM_PAD_ZERO) X(LM_PAD_REFLECT)

/* ---- elementwise (binary.c, scalar.c, activation.c) ------------------------------------ */
typedef struct lm_binary_params { int op; } lm_binary_params;                 /* lm_binary_op */
/* d (+)= the gradient of operand `which` (0 = a, 1 = b); accumulate 0 writes = */
typedef struct lm_binary_bwd_params { int op, which, accumulate; } lm_binary_bwd_params;
typedef struct lm_grad_acc_params { float scale; } lm_grad_acc_params;         /* d += scale s */
typedef struct lm_affine_params { float s, t; } lm_affine_params;              /* y = s x + t */
typedef struct lm_act_params { int kind; float slope; } lm_act_params;         /* lm_act_kind */

/* ---- reductions and losses (reduce.c, loss.c) ------------------------------------------ */
/* bit d of mask = dim d reduced; y = scale * sum */
typedef struct lm_reduce_params { unsigned mask; float scale; } lm_reduce_params;
typedef struct lm_loss_params { int kind; } lm_loss_params;                    /* lm_loss_kind */
/* gradient of pred (sign 1) or of target (sign -1) */
typedef struct lm_loss_bwd_params { int kind; float sign; } lm_loss_bwd_params;

/* ---- normalisation (softmax.c, layer_norm.c, l2_normalize.c) --------------------------- */
typedef struct lm_softmax_params { int axis; } lm_softmax_params;             /* axis >= 0 */
typedef struct lm_ln_params { float eps; int has_w, has_b; } lm_ln_params;
typedef struct lm_l2_params { int axis; float eps; } lm_l2_params;             /* axis >= 0 */

/* ---- rearrangement and resampling (permute.c, shuffle.c, concat.c, pad.c, resize.c,
 * mosaic_upsample.c) ---------------------------------------------------------------------- */
typedef struct lm_permute_params { int ndim; int perm[LM_MAX_DIMS]; } lm_permute_params;
typedef struct lm_shuffle_params { int fy, fx; } lm_shuffle_params;
typedef struct lm_band_params { int dim, start; } lm_band_params; /* band [start, ...) along dim */
/* mode: lm_pad_mode */
typedef struct lm_pad_params { int top, bottom, left, right, mode; } lm_pad_params;
typedef struct lm_resize_params { int align_corners; } lm_resize_params;
#define LM_MOSAIC_UPSAMPLE_MAX_CH 64
typedef struct lm_mosaic_params {
    int ty, tx, nch;
    int py[LM_MOSAIC_UPSAMPLE_MAX_CH], px[LM_MOSAIC_UPSAMPLE_MAX_CH];
} lm_mosaic_params;

/* Source-coordinate scale of one resize axis of `in` positions onto `out` (PyTorch's
 * align_corners rule). */
static inline float lm_resize_scale(int in, int out, int align_corners)
{
    return align_corners ? (out > 1 ? (float)(in - 1) / (float)(out - 1) : 0.0f)
                         : (float)in / (float)out;
}

/* ---- matrix products (matmul.c) -------------------------------------------------------- */
typedef struct lm_mm_params {
    int batch, M, N, K;   /* op(a): M x K, op(b): K x N, per batch item */
    int ta, tb;           /* transpose flags as given */
    int a_batched, b_batched;
} lm_mm_params;
typedef struct lm_linear_params { int R, in, out; } lm_linear_params;  /* R rows of x */

/* The batch folded into M when b is shared and a is not transposed (one tall GEMM). */
static inline lm_mm_params lm_mm_folded(const lm_mm_params *p)
{
    lm_mm_params q = *p;
    if (!p->ta && p->a_batched && !p->b_batched) {
        q.M = p->M * p->batch;
        q.batch = 1;
    }
    return q;
}
/* Leading dimensions of a and b, and their strides between batch items (0 when shared). */
static inline int lm_mm_lda(const lm_mm_params *p) { return p->ta ? p->M : p->K; }
static inline int lm_mm_ldb(const lm_mm_params *p) { return p->tb ? p->K : p->N; }
static inline long lm_mm_sa(const lm_mm_params *p) { return p->a_batched ? (long)p->M * p->K : 0; }
static inline long lm_mm_sb(const lm_mm_params *p) { return p->b_batched ? (long)p->K * p->N : 0; }

/* ---- convolutions (conv2d*.c, conv_transpose2d.c, conv3d.c) ----------------------------- */
/* conv2d: x: B x Cin x H x W, w: Cout x Cin/groups x kh x kw, y: B x Cout x Ho x Wo. */
typedef struct lm_conv_geom {
    int B, Cin, H, W, Cout, Ho, Wo;
    int kh, kw, sh, sw, ph, pw, dh, dw, groups;
} lm_conv_geom;
/* conv_transpose2d: x: B x Cin x H x W, y: B x Cout x Ho x Wo. */
typedef struct lm_convt_params {
    int B, Cin, H, W;       /* input x */
    int Cout, Ho, Wo;       /* output y */
    int kh, kw, sh, sw, ph, pw, dh, dw, groups;
    int has_bias;
} lm_convt_params;
/* conv3d (stride 1): x: B x Cin x D x H x W, y: B x Cout x Do x Ho x Wo. */
typedef struct lm_conv3d_params {
    int B, Cin, D, H, W;    /* input x */
    int Cout, Do, Ho, Wo;   /* output y */
    int kd, kh, kw, pd, ph, pw;
    int has_bias;
} lm_conv3d_params;

/* ---- complex tensors (fft2.c, complex.c, area_sample.c): a last dim of 2 (re, im) ------- */
/* B transforms of H x W: y = scale sum x exp(sign 2 pi i (k n / H + l m / W)); sign -1 is the
 * forward transform (scale 1), +1 the inverse (scale 1 / (H W)). The backward applies the
 * opposite sign with the same scale (the adjoint) and adds. */
typedef struct lm_fft2_params { int B, H, W, sign; float scale; } lm_fft2_params;
/* na, nb: complex elements of a and b (b repeated na / nb times); which: the gradient (0 a, 1 b) */
typedef struct lm_cmul_params { long na, nb; int which; } lm_cmul_params;
#define LM_AREA_MAX_B 64
/* B images N x N -> B x S x S cells of K x K samples; ratio[b]: input samples per cell */
typedef struct lm_area_params { int B, N, S, K; double ratio[LM_AREA_MAX_B]; } lm_area_params;

#endif
