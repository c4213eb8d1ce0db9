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

/* ---- GELU forward fast path ----------------------------------------------------------------
 * erf without a libm call, branch-free so the GELU loop vectorises (glibc's erff is scalar and
 * was most of the time of the attention networks' FFNs). erf(a) = a + a q(a^2) for
 * |a| <= 0.927734375, else sign(a) (1 - exp(r(|a|))) with r a polynomial (N. Juffa's
 * minimax fits); exp by Cody-Waite reduction and a degree-7 polynomial. Max error over all
 * floats in [-8, 8]: 1.04 ulp of erf (glibc's erff: 0.9 ulp), so GELU agrees with the
 * reference loop (erff) to float rounding; lm_op_set_path(c, LM_OP_PATH_REFERENCE) selects it. */
static inline int32_t f2i(float f)
{
    int32_t i;
    memcpy(&i, &f, sizeof i);
    return i;
}

static inline float i2f(int32_t i)
{
    float f;
    memcpy(&f, &i, sizeof f);
    return f;
}

/* cond ? a : b as a bitwise blend: both sides are always computed, so the compiler cannot
 * sink them into branches (float operations in a branch block if-conversion, i.e.
 * vectorisation, under the default -ftrapping-math). */
static inline float blend(int cond, float a, float b)
{
    int32_t m = -(int32_t)(cond != 0);
    return i2f((f2i(a) & m) | (f2i(b) & ~m));
}

/* exp(x) for x in [-103, 0]; rint is the 1.5 * 2^23 trick (rintf does not vectorise). */
__attribute__((always_inline)) static inline float exp_neg(float x)
{
    float k = (x * 1.44269504f + 12582912.0f) - 12582912.0f;
    float r = fmaf(k, -0.693145752f, x);
    r = fmaf(k, -1.42860677e-6f, r);
    float p = 1.98756912e-4f;
    p = fmaf(p, r, 1.39843059e-3f);
    p = fmaf(p, r, 8.33332725e-3f);
    p = fmaf(p, r, 4.16664854e-2f);
    p = fmaf(p, r, 1.66666716e-1f);
    p = fmaf(p, r, 5.00000000e-1f);
    p = fmaf(p, r * r, r) + 1.0f;
    int32_t ki = (int32_t)k;
    ki = ki < -126 ? -126 : ki;
    return p * i2f((ki + 127) << 23);
}

__attribute__((always_inline)) static inline float erf_fast(float a)
{
    float t = fabsf(a), s = a * a;
    float r = fmaf(-1.72853470e-5f, t, 3.83197126e-4f);
    float u = fmaf(-3.88396438e-3f, t, 2.42546219e-2f);
    r = fmaf(r, s, u);
    r = fmaf(r, t, -1.06777877e-1f);
    r = fmaf(r, t, -6.34846687e-1f);
    r = fmaf(r, t, -1.28717512e-1f);
    r = fmaf(r, t, -t);
    /* r <= 0 where used; |r| > 103 (also inf, NaN) -> -103: exp underflows to ~0 */
    r = blend((f2i(r) & 0x7fffffff) > f2i(103.0f), -103.0f, r);
    float big = copysignf(1.0f - exp_neg(r), a);
    float q = -5.96761703e-4f;
    q = fmaf(q, s, 4.99119423e-3f);
    q = fmaf(q, s, -2.67681349e-2f);
    q = fmaf(q, s, 1.12819925e-1f);
    q = fmaf(q, s, -3.76125336e-1f);
    q = fmaf(q, s, 1.28379166e-1f);
    float small = fmaf(q, a, a);
    return blend(f2i(t) > f2i(0.927734375f), big, small); /* t >= 0: int order = float order */
}

static void gelu_fwd_fast(const float *x, float *y, long n, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) y[i] = 0.5f * x[i] * (1.0f + erf_fast(x[i] * INV_SQRT2));
}

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
        if (lm_op_path(c) == LM_OP_PATH_FAST) gelu_fwd_fast(x, y, n, nthr);
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

/* The same with erf_fast / exp_neg (vectorises). Below -103 the density is taken as exactly
 * 0, as expf's underflow gives the reference (so inf * 0 is NaN there too). */
static inline float gelu_grad_fast(float x)
{
    float e = -0.5f * x * x; /* <= 0 or NaN: compare magnitudes as integers (vectorises) */
    int under = (f2i(e) & 0x7fffffff) > f2i(103.0f);
    float d = blend(under, 0.0f, exp_neg(blend(under, -103.0f, e)));
    return 0.5f * (1.0f + erf_fast(x * INV_SQRT2)) + x * INV_SQRT2PI * d;
}

static void gelu_bwd_fast(const float *x, const float *gy, float *gx, long n, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) gx[i] += gy[i] * gelu_grad_fast(x[i]);
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
        if (lm_op_path(c) == LM_OP_PATH_FAST) gelu_bwd_fast(x, gy, gx, n, nthr);
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
