/* cl_ops_phase.c — launchers of phase.cl for tensor/ops/phase.c ("phase_mean_fwd/bwd",
 * "phase_scale_fwd", "phase_scale_bwd_x", "phase_scale_bwd_s"): two kernels, a per-phase sum
 * (of x, or of gy x) and a per-phase broadcast (of a scale, times x or gy). */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

/* y[plane, q] (= or +=) inv * sum over phase q of a (times b if b). */
static int run_sum(lm_cl *b, lm_ctx *c, const lm_tensor *a, const lm_tensor *bb, lm_tensor *y,
                   const lm_shuffle_params *p, float inv, int add)
{
    int n = (int)lm_tensor_numel(y);
    lm_cl_args g;
    if (lm_cl_begin(&g, b, c, "phase_sum")) return c->status;
    lm_cl_arg_tensor(&g, a);
    lm_cl_arg_tensor(&g, bb ? bb : a);
    lm_cl_arg_int(&g, bb != NULL);
    lm_cl_arg_tensor(&g, y);
    lm_cl_arg_int(&g, p->fy);
    lm_cl_arg_int(&g, p->fx);
    lm_cl_arg_int(&g, a->shape[2]);
    lm_cl_arg_int(&g, a->shape[3]);
    lm_cl_arg_int(&g, n);
    lm_cl_arg_float(&g, inv);
    lm_cl_arg_int(&g, add);
    return lm_cl_run_chunks(&g, (size_t)n);
}

/* d (= or +=) k * (a or 1) * s at each element's phase; d has the image's shape. */
static int run_apply(lm_cl *b, lm_ctx *c, const lm_tensor *a, const lm_tensor *s, lm_tensor *d,
                     const lm_shuffle_params *p, float k, int add)
{
    int n = (int)lm_tensor_numel(d);
    lm_cl_args g;
    if (lm_cl_begin(&g, b, c, "phase_apply")) return c->status;
    lm_cl_arg_tensor(&g, a ? a : d);
    lm_cl_arg_int(&g, a != NULL);
    lm_cl_arg_tensor(&g, s);
    lm_cl_arg_tensor(&g, d);
    lm_cl_arg_int(&g, p->fy);
    lm_cl_arg_int(&g, p->fx);
    lm_cl_arg_int(&g, d->shape[2]);
    lm_cl_arg_int(&g, d->shape[3]);
    lm_cl_arg_int(&g, n);
    lm_cl_arg_float(&g, k);
    lm_cl_arg_int(&g, add);
    return lm_cl_run_chunks(&g, (size_t)n);
}

static float per_phase(const lm_tensor *img, const lm_shuffle_params *p)
{
    return (float)((double)(p->fy * p->fx) / ((double)img->shape[2] * img->shape[3]));
}

/* t = {x, y}: y = per-phase means. */
int lm_cl_launch_phase_mean_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_sum(b, c, t[0], NULL, t[1], pp, per_phase(t[0], pp), 0);
}

/* t = {gy, gx}: gx += gy / (H W / P). */
int lm_cl_launch_phase_mean_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_apply(b, c, NULL, t[0], t[1], pp, per_phase(t[1], pp), 1);
}

/* t = {x, s, y}: y = x s. */
int lm_cl_launch_phase_scale_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                 const void *pp)
{
    (void)nt;
    return run_apply(b, c, t[0], t[1], t[2], pp, 1.0f, 0);
}

/* t = {gy, s, gx}: gx += gy s. */
int lm_cl_launch_phase_scale_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                   const void *pp)
{
    (void)nt;
    return run_apply(b, c, t[0], t[1], t[2], pp, 1.0f, 1);
}

/* t = {gy, x, gs}: gs += per-phase sums of gy x. */
int lm_cl_launch_phase_scale_bwd_s(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                   const void *pp)
{
    (void)nt;
    return run_sum(b, c, t[0], t[1], t[2], pp, 1.0f, 1);
}
