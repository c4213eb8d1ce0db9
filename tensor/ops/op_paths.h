/* op_paths.h — a context's switch between the fast CPU kernels of some ops and their simple
 * reference loops (for tests: each fast path is compared against its reference).
 * Ops with such a pair: depthwise conv2d forward (stride-1 stencil vs per-tap loops,
 * conv2d_depthwise.c), l2_normalize along a contiguous axis (l2_normalize.c), GELU
 * (activation.c), conv_transpose2d forward with kernel == stride (conv_transpose2d.c).
 * What it is not: the conv2d path selection (lm_conv2d_set_path in gemm_internal.h). */
#ifndef LM_OP_PATHS_H
#define LM_OP_PATHS_H
#include "tensor/tensor.h"

enum { LM_OP_PATH_FAST = 0, LM_OP_PATH_REFERENCE = 1 };
/* Select the path for later kernels run on c (c->op_path); returns the previous setting. */
int lm_op_set_path(lm_ctx *c, int path);
int lm_op_path(const lm_ctx *c);

#endif
