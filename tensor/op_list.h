/* op_list.h — the one list of kernels: every name that lm_kernel_run dispatches, from which
 * the CPU kernel set (tensor/op_table.c) and the OpenCL launcher table (kernels-opencl/
 * cl_backend.c) are generated.
 *
 * What it is: LM_OP_LIST(X) with one X(name) per kernel. For each name, the CPU op file defines
 * the kernel with LM_KERNEL(name, fn) (a name missing from the list fails to compile there),
 * and the OpenCL backend defines the launcher lm_cl_launch_<name> (a missing one fails to link,
 * as does a missing CPU kernel). tests/test_op_table.c walks the list on both sides.
 * What it is not: the op API (tensor/ops.h) or the parameter structs (tensor/op_params.h).
 * Adding a kernel: one X(name) line here, LM_KERNEL in its op file, a launcher
 * (CONTRIBUTING.md). */
#ifndef LM_OP_LIST_H
#define LM_OP_LIST_H
#include "tensor/tensor.h"

#define LM_OP_LIST(X)                                                                         \
    /* tensor.c, ops/view.c */                                                                \
    X(fill) X(flat_add) X(strided_copy) X(strided_add)                                        \
    /* ops/binary.c, scalar.c, activation.c */                                                \
    X(binary_fwd) X(binary_bwd) X(binary_grad_acc) X(affine_fwd) X(affine_bwd)                 \
    X(activation_fwd) X(activation_bwd)                                                       \
    /* ops/reduce.c, loss.c */                                                                \
    X(reduce_sum_fwd) X(reduce_sum_bwd) X(global_avg_pool_fwd) X(global_avg_pool_bwd)          \
    X(l1_mse_loss_fwd) X(l1_mse_loss_bwd)                                                     \
    /* ops/softmax.c, layer_norm.c, l2_normalize.c */                                         \
    X(softmax_fwd) X(softmax_bwd) X(layer_norm_channels_fwd) X(layer_norm_channels_bwd_x)      \
    X(layer_norm_channels_bwd_wb) X(l2_normalize_fwd) X(l2_normalize_bwd)                     \
    /* ops/permute.c, shuffle.c, concat.c, pad.c, resize.c, mosaic_upsample.c */              \
    X(permute_fwd) X(permute_bwd) X(pixel_unshuffle_fwd) X(pixel_unshuffle_bwd)               \
    X(pixel_shuffle_fwd) X(pixel_shuffle_bwd) X(concat_fwd) X(concat_bwd) X(split_fwd)        \
    X(split_bwd) X(pad2d_fwd) X(pad2d_bwd) X(resize_bilinear_fwd) X(resize_bilinear_bwd)       \
    X(mosaic_upsample_fwd) X(mosaic_upsample_bwd)                                             \
    /* ops/phase.c */                                                                         \
    X(phase_mean_fwd) X(phase_mean_bwd) X(phase_scale_fwd) X(phase_scale_bwd_x)                \
    X(phase_scale_bwd_s)                                                                      \
    /* ops/matmul.c */                                                                        \
    X(matmul_fwd) X(matmul_bwd_a) X(matmul_bwd_b) X(linear_fwd) X(linear_bwd_x)               \
    X(linear_bwd_w) X(linear_bwd_bias)                                                        \
    /* ops/conv2d.c, conv_transpose2d.c, conv3d.c */                                          \
    X(conv2d_fwd) X(conv2d_bwd_x) X(conv2d_bwd_w) X(conv2d_bwd_bias)                          \
    X(conv_transpose2d_fwd) X(conv_transpose2d_bwd_x) X(conv_transpose2d_bwd_w)               \
    X(conv_transpose2d_bwd_b) X(conv3d_fwd) X(conv3d_bwd_x) X(conv3d_bwd_w) X(conv3d_bwd_b)    \
    /* ops/fft2.c, complex.c, area_sample.c */                                                \
    X(fft2_fwd) X(fft2_bwd) X(polar_fwd) X(polar_bwd) X(abs2_fwd) X(abs2_bwd) X(cmul_fwd)       \
    X(cmul_bwd) X(area_sample_fwd) X(area_sample_bwd)

/* LM_OP_ID_<name>: the kernel's index in the list; LM_OP_COUNT kernels. */
#define LM_OP_ID_ENTRY(name) LM_OP_ID_##name,
enum lm_op_id { LM_OP_LIST(LM_OP_ID_ENTRY) LM_OP_COUNT };
#undef LM_OP_ID_ENTRY

/* The CPU kernels, one object per name (defined in the op files with LM_KERNEL). */
#define LM_KERNEL_DECL(name) extern const lm_kernel lm_kernel_##name;
LM_OP_LIST(LM_KERNEL_DECL)
#undef LM_KERNEL_DECL

/* Define the CPU kernel `name` (an identifier of LM_OP_LIST) as lm_kernel_<name>, running fn. */
#define LM_KERNEL(name, fn)                                                                   \
    _Static_assert(LM_OP_ID_##name < LM_OP_COUNT, #name " is in LM_OP_LIST");                 \
    const lm_kernel lm_kernel_##name = {#name, fn}

/* The CPU kernel set (tensor/op_table.c): the kernel of list index id (0 <= id <
 * LM_OP_COUNT), and the kernel of a name (NULL when no kernel has it). */
const lm_kernel *lm_kernel_at(int id);
const lm_kernel *lm_kernel_find(const char *name);

#endif
