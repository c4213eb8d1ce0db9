/* activation.c — elementwise nonlinearities: relu, leaky_relu(slope), sigmoid, tanh, exact GELU.
 *
 * What it is: one flat forward kernel and one flat backward kernel, each switching on the
 * activation once outside its loop; parallel for large tensors, every element written by one
 * thread. Backward reads what it needs: x (relu, leaky_relu, gelu) or y (sigmoid, tanh).
 *   relu'      = x > 0 ? 1 : 0          (0 at x = 0, as PyTorch)
 *   leaky'     = x > 0 ? 1 : slope
 *   sigmoid'   = y (1 - y);  computed without overflow for any |x|
 *   tanh'      = 1 - y^2
 *   gelu'      = Phi(x) + x phi(x),  Phi = normal CDF, phi = normal density
 * GELU forward and backward have a vectorised erf and exp (below; the erff / expf loops stay
 * as their reference).
 * What it is not: parametric activations (PReLU with a learned slope), approximate GELU. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include "tensor/ops/op_paths.h"
#include <math.h>
#include <stdint.h>
#include <string.h>

#define PAR_MIN 32768L /* below this many elements, one thread */
#define INV_SQRT2 0.70710678118654752440f
#define INV_SQRT2PI 0.39894228040143267794f

static const char *const ACT_NAMES[5] = {"relu", "leaky_relu", "sigmoid", "tanh", "gelu"};

/* e = exp(-|x|) is in (0, 1]: no overflow; sigmoid(x) = 1 / (1 + e) for x >= 0, else e / (1 + e).
 * Written as a select, not a branch (the sign of activations is unpredictable). */
static inline float sigmoid_stable(float x)
{
    float e = expf(-fabsf(x)), r = 1.0f / (1.0f + e);
    return x >= 0.0f ? r : e * r;
}

/* cond ? a : b without a branch, and the fast GELU loops (built once per instruction set) */
#include "tensor/ops/float_bits.h"
#include "tensor/ops/gelu_fast.h"

/* Parallel flat loop over i in [0, n). */
#define FLAT_LOOP(STMT)                                                                       \
    do {                                                                                      \
        _Pragma("omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)") \
        for (long i = 0; i < n; i++) STMT;                                                    \
    } while (0)

/* Leaky ReLU as a product with a selected factor (1 or the slope, a bitwise blend): exact,
 * a NaN input still gives NaN, and the loops vectorise (a float select does not if-convert
 * under the default -ftrapping-math). */
static void leaky_fwd(const float *restrict x, float *restrict y, long n, float slope, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        float v = x[i];
        y[i] = v * blend(v > 0.0f, 1.0f, slope);
    }
}

static void leaky_bwd(const float *restrict x, const float *restrict gy, float *restrict gx,
                      long n, float slope, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        gx[i] += gy[i] * blend(x[i] > 0.0f, 1.0f, slope);
    }
}

/* t[0] = x, t[1] = y (contiguous, same shape): y = f(x) (writes =). */
static int act_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_act_params *p = params;
    const float *x = t[0]->data, slope = p->slope;
    float *y = t[1]->data;
    long n = lm_tensor_numel(t[0]);
    int nthr = lm_nthreads(c);
    switch (p->kind) {
    case LM_ACT_RELU: FLAT_LOOP(y[i] = x[i] > 0.0f ? x[i] : 0.0f); break;
    case LM_ACT_LEAKY: leaky_fwd(x, y, n, slope, nthr); break;
    case LM_ACT_SIGMOID: FLAT_LOOP(y[i] = sigmoid_stable(x[i])); break;
    case LM_ACT_TANH: FLAT_LOOP(y[i] = tanhf(x[i])); break;
    default:
        if (lm_op_path(c) == LM_OP_PATH_FAST) lm_gelu_fwd_fast(x, y, n, nthr);
        else FLAT_LOOP(y[i] = 0.5f * x[i] * (1.0f + erff(x[i] * INV_SQRT2)));
        break;
    }
    return 0;
}

static inline float gelu_grad(float x)
{
    float cdf = 0.5f * (1.0f + erff(x * INV_SQRT2));
    return cdf + x * INV_SQRT2PI * expf(-0.5f * x * x);
}

/* t[0] = x, t[1] = y, t[2] = gy, t[3] = gx (contiguous, same shape): gx += f'(x) * gy. */
static int act_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_act_params *p = params;
    const float *x = t[0]->data, *y = t[1]->data, *gy = t[2]->data, slope = p->slope;
    float *gx = t[3]->data;
    long n = lm_tensor_numel(t[0]);
    int nthr = lm_nthreads(c);
    switch (p->kind) {
    case LM_ACT_RELU: FLAT_LOOP(gx[i] += x[i] > 0.0f ? gy[i] : 0.0f); break;
    case LM_ACT_LEAKY: leaky_bwd(x, gy, gx, n, slope, nthr); break;
    case LM_ACT_SIGMOID: FLAT_LOOP(gx[i] += gy[i] * y[i] * (1.0f - y[i])); break;
    case LM_ACT_TANH: FLAT_LOOP(gx[i] += gy[i] * (1.0f - y[i] * y[i])); break;
    default:
        if (lm_op_path(c) == LM_OP_PATH_FAST) lm_gelu_bwd_fast(x, gy, gx, n, nthr);
        else FLAT_LOOP(gx[i] += gy[i] * gelu_grad(x[i]));
        break;
    }
    return 0;
}

LM_KERNEL(activation_fwd, act_fwd_cpu);
LM_KERNEL(activation_bwd, act_bwd_cpu);

static void act_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[4] = {x, n->out, n->out->grad, lm_grad(c, x)};
    if (t[3]) lm_kernel_run(c, &lm_kernel_activation_bwd, t, 4, n->params);
}

static lm_tensor *activation(lm_ctx *c, lm_tensor *x, int kind, float slope)
{
    const char *name = ACT_NAMES[kind];
    if (!lm_check_inputs(c, name, 1, x)) return NULL;
    if (!isfinite(slope)) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: slope %g is not finite", name, (double)slope);
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new(c, x->ndim, x->shape) : NULL;
    if (!y) return NULL;
    lm_act_params p = {kind, slope};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_activation_fwd, t, 2, &p)) return NULL;
    lm_record(c, name, act_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_relu(lm_ctx *c, lm_tensor *x) { return activation(c, x, LM_ACT_RELU, 0.0f); }
lm_tensor *lm_leaky_relu(lm_ctx *c, lm_tensor *x, float slope)
{
    return activation(c, x, LM_ACT_LEAKY, slope);
}
lm_tensor *lm_sigmoid(lm_ctx *c, lm_tensor *x) { return activation(c, x, LM_ACT_SIGMOID, 0.0f); }
lm_tensor *lm_tanh(lm_ctx *c, lm_tensor *x) { return activation(c, x, LM_ACT_TANH, 0.0f); }
lm_tensor *lm_gelu(lm_ctx *c, lm_tensor *x) { return activation(c, x, LM_ACT_GELU, 0.0f); }
