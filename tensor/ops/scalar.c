/* scalar.c — y = s * x + t with float constants s and t (lm_scale, lm_add_scalar and lm_neg are
 * inline wrappers in ops.h).
 * What it is: one flat elementwise kernel, parallel for large tensors; backward gx += s * gy.
 * What it is not: tensor-tensor arithmetic (binary.c); s and t get no gradient. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

#define PAR_MIN 32768L /* below this many elements, one thread */

/* t[0] = x, t[1] = y (contiguous, same shape): y = s * x + t (writes =). */
static int affine_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_affine_params *p = params;
    const float s = p->s, b = p->t, *x = t[0]->data;
    float *y = t[1]->data;
    long n = lm_tensor_numel(t[0]);
#pragma omp parallel for simd num_threads(lm_nthreads(c)) schedule(static) if (parallel: n >= PAR_MIN)
    for (long i = 0; i < n; i++) y[i] = s * x[i] + b;
    return 0;
}

/* t[0] = gy, t[1] = gx (contiguous, same shape): gx += s * gy. */
static int affine_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const float s = ((const lm_affine_params *)params)->s, *gy = t[0]->data;
    float *gx = t[1]->data;
    long n = lm_tensor_numel(t[0]);
#pragma omp parallel for simd num_threads(lm_nthreads(c)) schedule(static) if (parallel: n >= PAR_MIN)
    for (long i = 0; i < n; i++) gx[i] += s * gy[i];
    return 0;
}

LM_KERNEL(affine_fwd, affine_fwd_cpu);
LM_KERNEL(affine_bwd, affine_bwd_cpu);

static void affine_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_affine_bwd, t, 2, n->params);
}

lm_tensor *lm_affine(lm_ctx *c, lm_tensor *x, float s, float t)
{
    if (!lm_check_inputs(c, "affine", 1, x)) return NULL;
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new(c, x->ndim, x->shape) : NULL;
    if (!y) return NULL;
    lm_affine_params p = {s, t};
    lm_tensor *k[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_affine_fwd, k, 2, &p)) return NULL;
    lm_record(c, "affine", affine_backward, y, &x, 1, &p, sizeof p);
    return y;
}
