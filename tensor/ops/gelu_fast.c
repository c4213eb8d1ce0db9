/* gelu_fast.c — the vectorised GELU forward and backward loops of activation.c, built once
 * per instruction set (cmake/isa.cmake) and called through lm_gelu_fwd_fast / _bwd_fast.
 * erf without a libm call, branch-free so the GELU loop vectorises (glibc's erff is scalar and
 * was most of the time of the attention networks' FFNs). erf(a) = a + a q(a^2) for
 * |a| <= 0.927734375, else sign(a) (1 - exp(r(|a|))) with r a polynomial (N. Juffa's
 * minimax fits); exp by Cody-Waite reduction and a degree-7 polynomial. Max error over all
 * floats in [-8, 8]: 1.04 ulp of erf (glibc's erff: 0.9 ulp), so GELU agrees with the
 * reference loop (erff) to float rounding; lm_op_set_path(c, LM_OP_PATH_REFERENCE) selects it.
 * Without FMA (the generic level) each fused multiply-add below is a multiply and an add:
 * a call to libm's fmaf per term would be 3x slower than the whole loop. */
#include "tensor/ops/gelu_fast.h"
#include "tensor/ops/float_bits.h"
#include <math.h>

/* a b + c: fused where the instruction set has FMA */
static inline float madd(float a, float b, float c)
{
#if defined(__FMA__)
    return fmaf(a, b, c);
#else
    return a * b + c;
#endif
}

#define PAR_MIN 32768L /* below this many elements, one thread */
#define INV_SQRT2 0.70710678118654752440f
#define INV_SQRT2PI 0.39894228040143267794f

/* exp(x) for x in [-103, 0]; rint is the 1.5 * 2^23 trick (rintf does not vectorise). */
__attribute__((always_inline)) static inline float exp_neg(float x)
{
    float k = (x * 1.44269504f + 12582912.0f) - 12582912.0f;
    float r = madd(k, -0.693145752f, x);
    r = madd(k, -1.42860677e-6f, r);
    float p = 1.98756912e-4f;
    p = madd(p, r, 1.39843059e-3f);
    p = madd(p, r, 8.33332725e-3f);
    p = madd(p, r, 4.16664854e-2f);
    p = madd(p, r, 1.66666716e-1f);
    p = madd(p, r, 5.00000000e-1f);
    p = madd(p, r * r, r) + 1.0f;
    int32_t ki = (int32_t)k;
    ki = ki < -126 ? -126 : ki;
    return p * i2f((ki + 127) << 23);
}

__attribute__((always_inline)) static inline float erf_fast(float a)
{
    float t = fabsf(a), s = a * a;
    float r = madd(-1.72853470e-5f, t, 3.83197126e-4f);
    float u = madd(-3.88396438e-3f, t, 2.42546219e-2f);
    r = madd(r, s, u);
    r = madd(r, t, -1.06777877e-1f);
    r = madd(r, t, -6.34846687e-1f);
    r = madd(r, t, -1.28717512e-1f);
    r = madd(r, t, -t);
    /* r <= 0 where used; |r| > 103 (also inf, NaN) -> -103: exp underflows to ~0 */
    r = blend((f2i(r) & 0x7fffffff) > f2i(103.0f), -103.0f, r);
    float big = copysignf(1.0f - exp_neg(r), a);
    float q = -5.96761703e-4f;
    q = madd(q, s, 4.99119423e-3f);
    q = madd(q, s, -2.67681349e-2f);
    q = madd(q, s, 1.12819925e-1f);
    q = madd(q, s, -3.76125336e-1f);
    q = madd(q, s, 1.28379166e-1f);
    float small = madd(q, a, a);
    return blend(f2i(t) > f2i(0.927734375f), big, small); /* t >= 0: int order = float order */
}

void lm_gelu_fwd_fast(const float *x, float *y, long n, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) y[i] = 0.5f * x[i] * (1.0f + erf_fast(x[i] * INV_SQRT2));
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

void lm_gelu_bwd_fast(const float *x, const float *gy, float *gx, long n, int nthr)
{
#pragma omp parallel for simd num_threads(nthr) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) gx[i] += gy[i] * gelu_grad_fast(x[i]);
}
