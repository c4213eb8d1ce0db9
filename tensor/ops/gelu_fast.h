/* gelu_fast.h — GELU's vectorised loops (gelu_fast.c), built once per instruction set.
 * Private to activation.c. */
#ifndef LM_OPS_GELU_FAST_H
#define LM_OPS_GELU_FAST_H

/* y[i] = GELU(x[i]) for i < n (exact GELU, erf to ~1 ulp), on nthr threads from 32768. */
void lm_gelu_fwd_fast(const float *x, float *y, long n, int nthr);
/* gx[i] += gy[i] GELU'(x[i]). */
void lm_gelu_bwd_fast(const float *x, const float *gy, float *gx, long n, int nthr);
#endif
