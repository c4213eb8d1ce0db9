/* cl_ops_complex.c — OpenCL launchers of tensor/ops/fft2.c ("fft2_fwd", "fft2_bwd"), complex.c
 * ("polar_*", "abs2_*", "cmul_*") and area_sample.c ("area_sample_*"); kernels in complex.cl.
 * Tensor order and params as the CPU kernels. The DFT is a direct sum (no device FFT library):
 * exact, O((H W)^2), meant for small transforms; large ones belong on the CPU. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

static int run_dft(lm_cl *b, lm_ctx *c, const lm_tensor *x, const lm_tensor *y,
                   const lm_fft2_params *p, int sign, int acc)
{
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "fft2_dft")) return c->status;
    lm_cl_arg_tensor(&a, x);
    lm_cl_arg_tensor(&a, y);
    lm_cl_arg_int(&a, p->B);
    lm_cl_arg_int(&a, p->H);
    lm_cl_arg_int(&a, p->W);
    lm_cl_arg_int(&a, sign);
    lm_cl_arg_float(&a, p->scale);
    lm_cl_arg_int(&a, acc);
    return lm_cl_run_1d(&a, (size_t)p->B * p->H * p->W);
}

/* t = {x, y}: y = scale DFT_sign(x). */
int lm_cl_launch_fft2_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_fft2_params *p = pp;
    return run_dft(b, c, t[0], t[1], p, p->sign, 0);
}

/* t = {gy, gx}: gx += scale DFT_{-sign}(gy). */
int lm_cl_launch_fft2_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_fft2_params *p = pp;
    return run_dft(b, c, t[0], t[1], p, -p->sign, 1);
}

/* t = {amp, phase, y}. */
int lm_cl_launch_polar_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt, (void)pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "polar_fwd")) return c->status;
    for (int i = 0; i < 3; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {amp, phase, gy, gamp or NULL, gphase or NULL}. */
int lm_cl_launch_polar_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt, (void)pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "polar_bwd")) return c->status;
    for (int i = 0; i < 3; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_tensor_opt(&a, t[3]);
    lm_cl_arg_tensor_opt(&a, t[4]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, t[3] != NULL);
    lm_cl_arg_int(&a, t[4] != NULL);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {z, y}. */
int lm_cl_launch_abs2_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt, (void)pp;
    int n = (int)lm_tensor_numel(t[1]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "abs2_fwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {z, gy, gz}. */
int lm_cl_launch_abs2_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt, (void)pp;
    int n = (int)lm_tensor_numel(t[1]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "abs2_bwd")) return c->status;
    for (int i = 0; i < 3; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t = {a, b, y}. */
int lm_cl_launch_cmul_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_cmul_params *p = pp;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "cmul_fwd")) return c->status;
    for (int i = 0; i < 3; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, (int)p->na);
    lm_cl_arg_int(&a, (int)p->nb);
    return lm_cl_run_chunks(&a, (size_t)p->na);
}

/* t = {a, b, gy, g}: which 0 -> ga, 1 -> gb. */
int lm_cl_launch_cmul_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_cmul_params *p = pp;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, p->which ? "cmul_bwd_b" : "cmul_bwd_a")) return c->status;
    lm_cl_arg_tensor(&a, p->which ? t[0] : t[1]);
    lm_cl_arg_tensor(&a, t[2]);
    lm_cl_arg_tensor(&a, t[3]);
    lm_cl_arg_int(&a, (int)p->na);
    lm_cl_arg_int(&a, (int)p->nb);
    return p->which ? lm_cl_run_1d(&a, (size_t)p->nb) : lm_cl_run_chunks(&a, (size_t)p->na);
}

/* fwd t = {x, y}, bwd t = {gy, gx}. The per-image ratios go to the device in one small
 * blocking write per launch. */
static int run_area(lm_cl *b, lm_ctx *c, lm_tensor *const *t, const lm_area_params *p, int bwd)
{
    float r[LM_AREA_MAX_B];
    for (int i = 0; i < p->B; i++) r[i] = (float)p->ratio[i];
    lm_tensor *dr = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1, (int[]){p->B});
    if (!dr || lm_tensor_write(c, dr, r)) return c->status;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, bwd ? "area_sample_bwd" : "area_sample_fwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_tensor(&a, dr);
    lm_cl_arg_int(&a, p->B);
    lm_cl_arg_int(&a, p->N);
    lm_cl_arg_int(&a, p->S);
    lm_cl_arg_int(&a, p->K);
    return lm_cl_run_1d(&a, bwd ? (size_t)p->B : (size_t)p->B * p->S * p->S);
}

int lm_cl_launch_area_sample_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                 const void *pp)
{
    (void)nt;
    return run_area(b, c, t, pp, 0);
}

int lm_cl_launch_area_sample_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                 const void *pp)
{
    (void)nt;
    return run_area(b, c, t, pp, 1);
}
