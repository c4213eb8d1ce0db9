/* cl_ops_view.c — typed launchers of view.cl: fill (tensor/tensor.c) and the copies of
 * tensor/ops/view.c (strided_copy, strided_add, flat_add). Same tensor order as the CPU
 * kernels; no params struct except fill's float value. */
#include "kernels-opencl/cl_impl.h"

/* t[0] = value (contiguous); params: const float *. */
int lm_cl_launch_fill(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "fill")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_float(&a, *(const float *)params);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t[0] += t[1], same numel, contiguous. */
int lm_cl_launch_flat_add(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "flat_add")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* strided_copy: t[1] (contiguous) = t[0] (strided view);
 * strided_add: t[0] (strided view) += t[1] (contiguous). */
static int launch_strided(lm_cl *b, lm_ctx *c, lm_tensor *const *t, const char *kname)
{
    int n = (int)lm_tensor_numel(t[0]);
    cl_int8 shp, st;
    lm_cl_shape8(t[0], &shp, &st);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, kname)) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_raw(&a, sizeof shp, &shp);
    lm_cl_arg_raw(&a, sizeof st, &st);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_chunks(&a, (size_t)n);
}

int lm_cl_launch_strided_copy(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    return launch_strided(b, c, t, "strided_copy");
}

int lm_cl_launch_strided_add(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    return launch_strided(b, c, t, "strided_add");
}
