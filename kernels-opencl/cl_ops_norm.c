/* cl_ops_norm.c — typed launchers of norm.cl for tensor/ops/softmax.c ("softmax_fwd",
 * "softmax_bwd"), layer_norm.c ("layer_norm_channels_fwd", "_bwd_x", "_bwd_wb") and
 * l2_normalize.c ("l2_normalize_fwd", "l2_normalize_bwd"). */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

/* outer x len x inner of t around axis */
static void split_axis(const lm_tensor *t, int axis, int *outer, int *len, int *inner)
{
    int o = 1, in = 1;
    for (int d = 0; d < axis; d++) o *= t->shape[d];
    for (int d = axis + 1; d < t->ndim; d++) in *= t->shape[d];
    *outer = o;
    *len = t->shape[axis];
    *inner = in;
}

/* Column kernels: tensors in order, then len, inner, ncols (and eps when given). */
static int run_columns(lm_cl *b, lm_ctx *c, const char *kname, lm_tensor *const *ts, int nts,
                       int axis, const float *eps)
{
    int outer, len, inner;
    split_axis(ts[0], axis, &outer, &len, &inner);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, kname)) return c->status;
    for (int i = 0; i < nts; i++) lm_cl_arg_tensor(&a, ts[i]);
    lm_cl_arg_int(&a, len);
    lm_cl_arg_int(&a, inner);
    lm_cl_arg_int(&a, outer * inner);
    if (eps) lm_cl_arg_float(&a, *eps);
    return lm_cl_run_1d(&a, (size_t)outer * (size_t)inner);
}

/* t = {x, y} */
int lm_cl_launch_softmax_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_columns(b, c, "softmax_fwd", t, 2, ((const lm_softmax_params *)pp)->axis, NULL);
}

/* t = {y, gy, gx} */
int lm_cl_launch_softmax_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_columns(b, c, "softmax_bwd", t, 3, ((const lm_softmax_params *)pp)->axis, NULL);
}

/* t = {x, y} */
int lm_cl_launch_l2_normalize_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_l2_params *p = pp;
    return run_columns(b, c, "l2_fwd", t, 2, p->axis, &p->eps);
}

/* t = {gx, gy, x} */
int lm_cl_launch_l2_normalize_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_l2_params *p = pp;
    return run_columns(b, c, "l2_bwd", t, 3, p->axis, &p->eps);
}

/* t = {x, y, stats, w or NULL, b or NULL} */
int lm_cl_launch_layer_norm_channels_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                         const void *pp)
{
    (void)nt;
    const lm_ln_params *p = pp;
    int C = t[0]->shape[1], HW = t[0]->shape[2] * t[0]->shape[3], npix = t[0]->shape[0] * HW;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "ln_fwd")) return c->status;
    for (int i = 0; i < 3; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_tensor_opt(&a, p->has_w ? t[3] : NULL);
    lm_cl_arg_tensor_opt(&a, p->has_b ? t[4] : NULL);
    lm_cl_arg_int(&a, C);
    lm_cl_arg_int(&a, HW);
    lm_cl_arg_int(&a, npix);
    lm_cl_arg_float(&a, p->eps);
    lm_cl_arg_int(&a, p->has_w);
    lm_cl_arg_int(&a, p->has_b);
    return lm_cl_run_1d(&a, (size_t)npix);
}

/* t = {gx, gy, x, stats, w or NULL} */
int lm_cl_launch_layer_norm_channels_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                           const void *pp)
{
    (void)nt;
    const lm_ln_params *p = pp;
    int C = t[0]->shape[1], HW = t[0]->shape[2] * t[0]->shape[3], npix = t[0]->shape[0] * HW;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "ln_bwd_x")) return c->status;
    for (int i = 0; i < 4; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_tensor_opt(&a, p->has_w ? t[4] : NULL);
    lm_cl_arg_int(&a, C);
    lm_cl_arg_int(&a, HW);
    lm_cl_arg_int(&a, npix);
    lm_cl_arg_int(&a, p->has_w);
    return lm_cl_run_1d(&a, (size_t)npix);
}

/* t = {gw or NULL, gb or NULL, gy, x, stats} */
int lm_cl_launch_layer_norm_channels_bwd_wb(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                            const void *pp)
{
    (void)nt, (void)pp;
    const lm_tensor *gy = t[2];
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "ln_bwd_wb")) return c->status;
    for (int i = 0; i < 2; i++) lm_cl_arg_tensor_opt(&a, t[i]);
    for (int i = 2; i < 5; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, gy->shape[0]);
    lm_cl_arg_int(&a, gy->shape[1]);
    lm_cl_arg_int(&a, gy->shape[2] * gy->shape[3]);
    lm_cl_arg_int(&a, t[0] != NULL);
    lm_cl_arg_int(&a, t[1] != NULL);
    return lm_cl_run_groups(&a, (size_t)gy->shape[1]);
}
