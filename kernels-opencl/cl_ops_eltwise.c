/* cl_ops_eltwise.c — typed launchers of eltwise.cl for tensor/ops/binary.c ("binary_fwd",
 * "binary_bwd", "binary_grad_acc"), scalar.c ("affine_fwd", "affine_bwd") and activation.c
 * ("activation_fwd", "activation_bwd"). Tensor order and params as the CPU kernels. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

/* Strides of contiguous operand t broadcast to output y (right-aligned, 0 along broadcast
 * dims); *flat = 1 when t has y's size (then its offset is the output index). */
static void bcast8(const lm_tensor *t, const lm_tensor *y, cl_int8 *st, int *flat)
{
    for (int i = 0; i < 8; i++) st->s[i] = 0;
    cl_int s = 1;
    for (int i = t->ndim - 1; i >= 0; i--) {
        st->s[LM_MAX_DIMS - t->ndim + i] = t->shape[i] == 1 ? 0 : s;
        s *= t->shape[i];
    }
    *flat = lm_tensor_numel(t) == lm_tensor_numel(y);
}

/* One broadcast operand: buffer, offset, strides, flat flag. */
static void arg_operand(lm_cl_args *a, const lm_tensor *t, const lm_tensor *y)
{
    cl_int8 st;
    int flat;
    bcast8(t, y, &st, &flat);
    lm_cl_arg_tensor(a, t);
    lm_cl_arg_raw(a, sizeof st, &st);
    lm_cl_arg_int(a, flat);
}

/* t = {a, b, y}: y = a op b. */
int lm_cl_launch_binary_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_binary_params *p = pp;
    cl_int8 shp, unused;
    lm_cl_shape8(t[2], &shp, &unused);
    int n = (int)lm_tensor_numel(t[2]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "binary_fwd")) return c->status;
    arg_operand(&a, t[0], t[2]);
    arg_operand(&a, t[1], t[2]);
    lm_cl_arg_tensor(&a, t[2]);
    lm_cl_arg_raw(&a, sizeof shp, &shp);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, p->op);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {g, a, b, d}: d (+)= contribution of operand `which`. */
int lm_cl_launch_binary_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_binary_bwd_params *p = pp;
    cl_int8 shp, unused;
    lm_cl_shape8(t[0], &shp, &unused);
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "binary_bwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    arg_operand(&a, t[1], t[0]);
    arg_operand(&a, t[2], t[0]);
    lm_cl_arg_tensor(&a, t[3]);
    lm_cl_arg_raw(&a, sizeof shp, &shp);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, p->op);
    lm_cl_arg_int(&a, p->which);
    lm_cl_arg_int(&a, p->accumulate);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* d += k s (contiguous, same numel). */
static int run_scaled_add(lm_cl *b, lm_ctx *c, lm_tensor *d, const lm_tensor *s, float k)
{
    int n = (int)lm_tensor_numel(d);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "scaled_add")) return c->status;
    lm_cl_arg_tensor(&a, d);
    lm_cl_arg_tensor(&a, s);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_float(&a, k);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {d, s}: d += scale s. */
int lm_cl_launch_binary_grad_acc(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_scaled_add(b, c, t[0], t[1], ((const lm_grad_acc_params *)pp)->scale);
}

/* t = {x, y}: y = s x + t. */
int lm_cl_launch_affine_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_affine_params *p = pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "affine_fwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_float(&a, p->s);
    lm_cl_arg_float(&a, p->t);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {gy, gx}: gx += s gy. */
int lm_cl_launch_affine_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_scaled_add(b, c, t[1], t[0], ((const lm_affine_params *)pp)->s);
}

/* t = {x, y}: y = f(x). */
int lm_cl_launch_activation_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_act_params *p = pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "activation_fwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, p->kind);
    lm_cl_arg_float(&a, p->slope);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {x, y, gy, gx}: gx += f'(x) gy. */
int lm_cl_launch_activation_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_act_params *p = pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "activation_bwd")) return c->status;
    for (int i = 0; i < 4; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, p->kind);
    lm_cl_arg_float(&a, p->slope);
    return lm_cl_run_chunks(&a, (size_t)n);
}
