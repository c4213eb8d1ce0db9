/* ops.h — every differentiable op of Lumosaic (forward on call, backward recorded on the tape).
 *
 * Conventions (all ops):
 *  - Inputs may be NULL after an earlier failure: the op then returns NULL (sticky ctx error).
 *  - Invalid shapes/arguments set the ctx error (one line naming the op and the shapes) and
 *    return NULL; nothing crashes.
 *  - Outputs are new contiguous tensors in the ctx arena, except the views noted below.
 *  - Non-contiguous inputs are made contiguous first (recorded copy), so kernels see
 *    contiguous memory only.
 *  - Images are NCHW; volumes NCDHW. Weights follow PyTorch layouts so safetensors weights
 *    move between the two.
 * One op per file in tensor/ops/, forward and backward side by side. */
#ifndef LM_OPS_H
#define LM_OPS_H
#include "tensor/tensor.h"

/* ---- views and copies (tensor/ops/view.c) ------------------------------------------- */
/* Same data, new shape (one entry may be -1). Input must be contiguous or is copied. */
lm_tensor *lm_reshape(lm_ctx *c, lm_tensor *x, int ndim, const int *shape);
/* View of x restricted to [start, start+len) along dim (no copy; strided). */
lm_tensor *lm_slice(lm_ctx *c, lm_tensor *x, int dim, int start, int len);
/* x itself if contiguous, else a contiguous copy (recorded). */
lm_tensor *lm_contiguous(lm_ctx *c, lm_tensor *x);

/* ---- elementwise binary with NumPy broadcasting (tensor/ops/binary.c) --------------- */
lm_tensor *lm_add(lm_ctx *c, lm_tensor *a, lm_tensor *b);
lm_tensor *lm_sub(lm_ctx *c, lm_tensor *a, lm_tensor *b);
lm_tensor *lm_mul(lm_ctx *c, lm_tensor *a, lm_tensor *b);
lm_tensor *lm_div(lm_ctx *c, lm_tensor *a, lm_tensor *b);

/* ---- scalar ops (tensor/ops/scalar.c) ----------------------------------------------- */
/* y = s * x + t */
lm_tensor *lm_affine(lm_ctx *c, lm_tensor *x, float s, float t);
static inline lm_tensor *lm_scale(lm_ctx *c, lm_tensor *x, float s) { return lm_affine(c, x, s, 0.0f); }
static inline lm_tensor *lm_add_scalar(lm_ctx *c, lm_tensor *x, float t) { return lm_affine(c, x, 1.0f, t); }
static inline lm_tensor *lm_neg(lm_ctx *c, lm_tensor *x) { return lm_affine(c, x, -1.0f, 0.0f); }

/* ---- activations (tensor/ops/activation.c) ------------------------------------------ */
lm_tensor *lm_relu(lm_ctx *c, lm_tensor *x);
lm_tensor *lm_leaky_relu(lm_ctx *c, lm_tensor *x, float slope);
lm_tensor *lm_sigmoid(lm_ctx *c, lm_tensor *x);
lm_tensor *lm_tanh(lm_ctx *c, lm_tensor *x);
/* Exact GELU: x * Phi(x) = 0.5 x (1 + erf(x / sqrt 2)). */
lm_tensor *lm_gelu(lm_ctx *c, lm_tensor *x);

/* ---- softmax (tensor/ops/softmax.c) ------------------------------------------------- */
/* Along `axis` (negative counts from the end), max-subtracted. */
lm_tensor *lm_softmax(lm_ctx *c, lm_tensor *x, int axis);

/* ---- reductions (tensor/ops/reduce.c) ----------------------------------------------- */
/* Bit d of axes_mask set = reduce dimension d. keepdim keeps reduced dims with size 1;
 * otherwise they are removed (all removed = shape {1}). Accumulates in double. */
lm_tensor *lm_sum(lm_ctx *c, lm_tensor *x, unsigned axes_mask, int keepdim);
lm_tensor *lm_mean(lm_ctx *c, lm_tensor *x, unsigned axes_mask, int keepdim);
/* B x C x H x W -> B x C x 1 x 1 */
lm_tensor *lm_global_avg_pool(lm_ctx *c, lm_tensor *x);

/* ---- matrix products (tensor/ops/matmul.c) ------------------------------------------ */
/* a: [Ba x] M x K (or K x M if trans_a), b: [Bb x] K x N (or N x K if trans_b).
 * 2-D x 2-D -> M x N; 3-D batched with Ba == Bb, or one side 2-D (broadcast over batch). */
lm_tensor *lm_matmul(lm_ctx *c, lm_tensor *a, lm_tensor *b, int trans_a, int trans_b);
/* y = x W^T + b over the last dim (PyTorch Linear: W is out x in, b is out or NULL). */
lm_tensor *lm_linear(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *b);

/* ---- convolutions (tensor/ops/conv2d.c, conv_transpose2d.c, conv3d.c) ---------------- */
typedef struct lm_conv2d_opts {
    int stride_h, stride_w;   /* 0 is read as 1 */
    int pad_h, pad_w;         /* zero padding */
    int dil_h, dil_w;         /* 0 is read as 1 */
    int groups;               /* 0 is read as 1 */
} lm_conv2d_opts;
/* x: B x Cin x H x W, w: Cout x Cin/groups x kh x kw, bias: Cout or NULL; opts NULL = defaults.
 * Cross-correlation like PyTorch. Output B x Cout x Ho x Wo,
 * Ho = (H + 2 pad_h - dil_h (kh - 1) - 1) / stride_h + 1. */
lm_tensor *lm_conv2d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias,
                     const lm_conv2d_opts *o);
/* Transposed conv (gradient of conv2d w.r.t. its input), PyTorch ConvTranspose2d:
 * x: B x Cin x H x W, w: Cin x Cout/groups x kh x kw, bias: Cout or NULL.
 * Ho = (H - 1) stride_h - 2 pad_h + dil_h (kh - 1) + out_pad_h + 1. */
lm_tensor *lm_conv_transpose2d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias,
                               const lm_conv2d_opts *o, int out_pad_h, int out_pad_w);
/* 3-D conv, stride 1: x: B x Cin x D x H x W, w: Cout x Cin x kd x kh x kw, bias Cout or NULL;
 * zero padding (pad_d, pad_h, pad_w). Used by CSAM (1 -> 1 channel, 3x3x3, pad 1). */
lm_tensor *lm_conv3d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias, int pad_d,
                     int pad_h, int pad_w);

/* ---- rearrangement (tensor/ops/shuffle.c, permute.c, concat.c, pad.c) ---------------- */
/* B x C x H x W -> B x (C fy fx) x H/fy x W/fx, out channel c*fy*fx + i*fx + j holds
 * x[c, fy*y + i, fx*x + j] (PyTorch order, rectangular factors). */
lm_tensor *lm_pixel_unshuffle(lm_ctx *c, lm_tensor *x, int fy, int fx);
/* Inverse of lm_pixel_unshuffle. */
lm_tensor *lm_pixel_shuffle(lm_ctx *c, lm_tensor *x, int fy, int fx);
/* Per mosaic phase (tensor/ops/phase.c), x B x C x H x W with H, W multiples of fy, fx:
 * B x (C fy fx) x 1 x 1 means, channel c fy fx + i fx + j = mean of x[c, i::fy, j::fx]
 * (= global_avg_pool(pixel_unshuffle(x))), and x scaled by s (B x C fy fx, any shape of that
 * size) at each phase (= pixel_shuffle(pixel_unshuffle(x) * s)). */
lm_tensor *lm_phase_mean(lm_ctx *c, lm_tensor *x, int fy, int fx);
lm_tensor *lm_phase_scale(lm_ctx *c, lm_tensor *x, lm_tensor *s, int fy, int fx);
/* out.shape[i] = x.shape[perm[i]] (contiguous copy). */
lm_tensor *lm_permute(lm_ctx *c, lm_tensor *x, const int *perm);
lm_tensor *lm_transpose(lm_ctx *c, lm_tensor *x, int d0, int d1);
lm_tensor *lm_concat(lm_ctx *c, lm_tensor *const *xs, int n, int dim);
/* Split along dim into n parts of the given sizes (sum = x.shape[dim]); out[i] contiguous. */
int lm_split(lm_ctx *c, lm_tensor *x, int dim, int n, const int *sizes, lm_tensor **out);
typedef enum lm_pad_mode { LM_PAD_ZERO = 0, LM_PAD_REFLECT = 1 } lm_pad_mode;
/* Pad the last two dims (H, W) of a 4-D tensor. Reflect excludes the edge (PyTorch
 * 'reflect'): pad < size along that dim. */
lm_tensor *lm_pad2d(lm_ctx *c, lm_tensor *x, int top, int bottom, int left, int right,
                    lm_pad_mode mode);

/* ---- resampling (tensor/ops/resize.c, mosaic_upsample.c) ----------------------------- */
/* Bilinear resize of a 4-D tensor to oh x ow; align_corners as PyTorch interpolate. */
lm_tensor *lm_resize_bilinear(lm_ctx *c, lm_tensor *x, int oh, int ow, int align_corners);
/* Phase-aware demosaic upsampling (system.md section 6).
 * raw: B x 1 x H x W mosaic with a ty x tx tile (H % ty == 0, W % tx == 0).
 * Output channel k (0 <= k < nch) is the sub-image of tile phase (phase_y[k], phase_x[k]),
 * i.e. samples raw[ty*v + phase_y[k], tx*u + phase_x[k]], bilinearly interpolated at every
 * pixel of the H x W grid using each sample's true position; outside the first/last sample
 * row/column the nearest sample is used (never reads outside the frame).
 * Output B x nch x H x W. */
lm_tensor *lm_mosaic_upsample(lm_ctx *c, lm_tensor *raw, int ty, int tx, int nch,
                              const int *phase_y, const int *phase_x);

/* ---- normalisation (tensor/ops/layer_norm.c, l2_normalize.c) ------------------------- */
/* Per pixel over channels of B x C x H x W: (x - mean) / sqrt(var + eps) * w + b,
 * biased variance; w, b of shape C or NULL. */
lm_tensor *lm_layer_norm_channels(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *b, float eps);
/* x / max(||x||_2, eps) along axis (PyTorch F.normalize). */
lm_tensor *lm_l2_normalize(lm_ctx *c, lm_tensor *x, int axis, float eps);

/* ---- losses (tensor/ops/loss.c) ----------------------------------------------------- */
/* Mean over all elements; output shape {1}. The target gets a gradient too if it requires one. */
lm_tensor *lm_l1_loss(lm_ctx *c, lm_tensor *pred, lm_tensor *target);
lm_tensor *lm_mse_loss(lm_ctx *c, lm_tensor *pred, lm_tensor *target);

/* ---- complex tensors (tensor/ops/fft2.c, complex.c, area_sample.c) ------------------ */
/* A complex tensor is a float tensor whose last dim is 2 (real, imaginary). */
/* 2-D DFT over dims [-3, -2] of x [..., H, W, 2]: forward (inverse 0) is unnormalised with
 * exp(-2 pi i ...), inverse (1) carries 1 / (H W) and exp(+2 pi i ...) (numpy's fft2/ifft2).
 * CPU: FFTW; OpenCL: a direct DFT (exact, O((HW)^2): for small transforms). */
lm_tensor *lm_fft2(lm_ctx *c, lm_tensor *x, int inverse);
/* amp e^{i phase}: amp and phase of one shape [...] -> [..., 2]. */
lm_tensor *lm_polar(lm_ctx *c, lm_tensor *amp, lm_tensor *phase);
/* |z|^2: [..., 2] -> [...]. */
lm_tensor *lm_abs2(lm_ctx *c, lm_tensor *z);
/* Complex product a b; b's shape is the trailing dims of a's (b repeated over a's leading
 * dims), both ending in 2. */
lm_tensor *lm_cmul(lm_ctx *c, lm_tensor *a, lm_tensor *b);
/* x: B x N x N (B <= 64) in FFT order (index 0 on the axis) -> B x S x S: cell (i, j) sums K x K
 * bilinear samples at u = ratio[b] (i - S/2 + (k + 0.5) / K - 0.5) (and v likewise), samples
 * whose taps fall outside -N/2 .. N - N/2 - 1 count 0 (see area_sample.c). */
lm_tensor *lm_area_sample(lm_ctx *c, lm_tensor *x, int S, int K, const double *ratio);
/* FFTW's planner is not thread-safe: every FFTW plan made or destroyed in this project is
 * made between these (fft2.c; data/doe.c, data/qdocam.c). */
void lm_fftw_lock(void);
void lm_fftw_unlock(void);

#endif
