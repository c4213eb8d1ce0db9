/* complex.c — elementwise ops on complex tensors (a last dim of 2: real, imaginary; see
 * fft2.c): lm_polar (amplitude and phase -> complex), lm_abs2 (|z|^2) and lm_cmul (complex
 * product, the second operand repeated over the leading elements of the first).
 * Gradients use g = dL/dRe + i dL/dIm of a real loss L:
 *   polar: y = a e^{i p}: dL/da = Re(conj(e^{i p}) g) = gr cos p + gi sin p,
 *          dL/dp = a (gi cos p - gr sin p);
 *   abs2:  y = zr^2 + zi^2: gz = 2 z gy;
 *   cmul:  y = a b: ga = g conj(b), gb = sum over the repeats of g conj(a).
 * What it is not: a complex dtype (the tensor core holds floats only) or broadcasting beyond
 * repetition of b. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <math.h>
#include <string.h>

#define PAR_MIN 16384L /* below this many elements, one thread */

/* ---- polar ------------------------------------------------------------------------------ */
/* t = {amp, phase, y}: y[2i] = amp[i] cos phase[i], y[2i+1] = amp[i] sin phase[i]. */
static int polar_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const float *a = t[0]->data, *p = t[1]->data;
    float *y = t[2]->data;
    long n = lm_tensor_numel(t[0]);
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        float s, co;
        s = sinf(p[i]), co = cosf(p[i]);
        y[2 * i] = a[i] * co;
        y[2 * i + 1] = a[i] * s;
    }
    return 0;
}

/* t = {amp, phase, gy, gamp or NULL, gphase or NULL}: the gradients += (see the top). */
static int polar_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const float *a = t[0]->data, *p = t[1]->data, *g = t[2]->data;
    float *ga = t[3] ? t[3]->data : NULL, *gp = t[4] ? t[4]->data : NULL;
    long n = lm_tensor_numel(t[0]);
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        float s, co, gr = g[2 * i], gi = g[2 * i + 1];
        s = sinf(p[i]), co = cosf(p[i]);
        if (ga) ga[i] += gr * co + gi * s;
        if (gp) gp[i] += a[i] * (gi * co - gr * s);
    }
    return 0;
}

LM_KERNEL(polar_fwd, polar_fwd_cpu);
LM_KERNEL(polar_bwd, polar_bwd_cpu);

static void polar_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *a = n->in[0], *p = n->in[1];
    lm_tensor *ga = lm_requires_grad(a) ? lm_grad(c, a) : NULL;
    lm_tensor *gp = lm_requires_grad(p) ? lm_grad(c, p) : NULL;
    if (!ga && !gp) return;
    lm_tensor *t[5] = {a, p, n->out->grad, ga, gp};
    lm_kernel_run(c, &lm_kernel_polar_bwd, t, 5, NULL);
}

lm_tensor *lm_polar(lm_ctx *c, lm_tensor *amp, lm_tensor *phase)
{
    if (!lm_check_inputs(c, "polar", 2, amp, phase)) return NULL;
    char s1[64], s2[64];
    if (!lm_tensor_same_shape(amp, phase) || amp->ndim >= LM_MAX_DIMS) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "polar: amplitude %s and phase %s must have the same shape "
                    "of at most %d dims", lm_shape_str(amp, s1, sizeof s1),
                    lm_shape_str(phase, s2, sizeof s2), LM_MAX_DIMS - 1);
        return NULL;
    }
    amp = lm_contiguous(c, amp);
    phase = lm_contiguous(c, phase);
    if (!amp || !phase) return NULL;
    int shape[LM_MAX_DIMS];
    memcpy(shape, amp->shape, sizeof(int) * (size_t)amp->ndim);
    shape[amp->ndim] = 2;
    lm_tensor *y = lm_tensor_new(c, amp->ndim + 1, shape);
    if (!y) return NULL;
    lm_tensor *k[3] = {amp, phase, y}, *in[2] = {amp, phase};
    if (lm_kernel_run(c, &lm_kernel_polar_fwd, k, 3, NULL)) return NULL;
    lm_record(c, "polar", polar_backward, y, in, 2, NULL, 0);
    return y;
}

/* ---- abs2 ------------------------------------------------------------------------------- */
/* t = {z, y}: y[i] = z[2i]^2 + z[2i+1]^2. */
static int abs2_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const float *z = t[0]->data;
    float *y = t[1]->data;
    long n = lm_tensor_numel(t[1]);
#pragma omp parallel for simd num_threads(lm_nthreads(c)) schedule(static) if (parallel: n >= PAR_MIN)
    for (long i = 0; i < n; i++) y[i] = z[2 * i] * z[2 * i] + z[2 * i + 1] * z[2 * i + 1];
    return 0;
}

/* t = {z, gy, gz}: gz += 2 z gy. */
static int abs2_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const float *z = t[0]->data, *g = t[1]->data;
    float *gz = t[2]->data;
    long n = lm_tensor_numel(t[1]);
#pragma omp parallel for simd num_threads(lm_nthreads(c)) schedule(static) if (parallel: n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        gz[2 * i] += 2.0f * z[2 * i] * g[i];
        gz[2 * i + 1] += 2.0f * z[2 * i + 1] * g[i];
    }
    return 0;
}

LM_KERNEL(abs2_fwd, abs2_fwd_cpu);
LM_KERNEL(abs2_bwd, abs2_bwd_cpu);

static void abs2_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *z = n->in[0];
    if (!lm_requires_grad(z)) return;
    lm_tensor *t[3] = {z, n->out->grad, lm_grad(c, z)};
    if (t[2]) lm_kernel_run(c, &lm_kernel_abs2_bwd, t, 3, NULL);
}

lm_tensor *lm_abs2(lm_ctx *c, lm_tensor *z)
{
    if (!lm_check_inputs(c, "abs2", 1, z)) return NULL;
    char s[64];
    if (z->ndim < 2 || z->shape[z->ndim - 1] != 2) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "abs2: z is %s; expected [..., 2] (complex)",
                    lm_shape_str(z, s, sizeof s));
        return NULL;
    }
    z = lm_contiguous(c, z);
    lm_tensor *y = z ? lm_tensor_new(c, z->ndim - 1, z->shape) : NULL;
    if (!y) return NULL;
    lm_tensor *k[2] = {z, y};
    if (lm_kernel_run(c, &lm_kernel_abs2_fwd, k, 2, NULL)) return NULL;
    lm_record(c, "abs2", abs2_backward, y, &z, 1, NULL, 0);
    return y;
}

/* ---- cmul ------------------------------------------------------------------------------- */
/* t = {a, b, y}: y[r nb + j] = a[r nb + j] b[j] (complex; nb = p->nb complex elements of b). */
static int cmul_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_cmul_params *p = params;
    const float *a = t[0]->data, *b = t[1]->data;
    float *y = t[2]->data;
    long n = p->na, nb = p->nb;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) {
        long j = i % nb;
        float ar = a[2 * i], ai = a[2 * i + 1], br = b[2 * j], bi = b[2 * j + 1];
        y[2 * i] = ar * br - ai * bi;
        y[2 * i + 1] = ar * bi + ai * br;
    }
    return 0;
}

/* t = {a, b, gy, g}: which 0: ga += gy conj(b); which 1: gb[j] += sum_r gy conj(a). */
static int cmul_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_cmul_params *p = params;
    const float *a = t[0]->data, *b = t[1]->data, *g = t[2]->data;
    float *d = t[3]->data;
    long na = p->na, nb = p->nb;
    if (p->which == 0) {
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (na >= PAR_MIN)
        for (long i = 0; i < na; i++) {
            long j = i % nb;
            float gr = g[2 * i], gi = g[2 * i + 1], br = b[2 * j], bi = b[2 * j + 1];
            d[2 * i] += gr * br + gi * bi;
            d[2 * i + 1] += gi * br - gr * bi;
        }
        return 0;
    }
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (na >= PAR_MIN)
    for (long j = 0; j < nb; j++) {
        double sr = 0, si = 0;
        for (long i = j; i < na; i += nb) {
            float gr = g[2 * i], gi = g[2 * i + 1], ar = a[2 * i], ai = a[2 * i + 1];
            sr += (double)gr * ar + (double)gi * ai;
            si += (double)gi * ar - (double)gr * ai;
        }
        d[2 * j] += (float)sr;
        d[2 * j + 1] += (float)si;
    }
    return 0;
}

LM_KERNEL(cmul_fwd, cmul_fwd_cpu);
LM_KERNEL(cmul_bwd, cmul_bwd_cpu);

static void cmul_backward(lm_ctx *c, lm_node *n)
{
    lm_cmul_params p = *(const lm_cmul_params *)n->params;
    for (int w = 0; w < 2; w++) {
        lm_tensor *x = n->in[w];
        if (!lm_requires_grad(x)) continue;
        lm_tensor *t[4] = {n->in[0], n->in[1], n->out->grad, lm_grad(c, x)};
        p.which = w;
        if (t[3]) lm_kernel_run(c, &lm_kernel_cmul_bwd, t, 4, &p);
    }
}

lm_tensor *lm_cmul(lm_ctx *c, lm_tensor *a, lm_tensor *b)
{
    if (!lm_check_inputs(c, "cmul", 2, a, b)) return NULL;
    char s1[64], s2[64];
    int ok = a->ndim >= 1 && b->ndim >= 1 && b->ndim <= a->ndim && a->shape[a->ndim - 1] == 2;
    for (int i = 1; ok && i <= b->ndim; i++) ok = a->shape[a->ndim - i] == b->shape[b->ndim - i];
    if (!ok) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "cmul: a %s and b %s: both complex ([..., 2]) and b's "
                    "shape the trailing dims of a's", lm_shape_str(a, s1, sizeof s1),
                    lm_shape_str(b, s2, sizeof s2));
        return NULL;
    }
    a = lm_contiguous(c, a);
    b = lm_contiguous(c, b);
    lm_tensor *y = a && b ? lm_tensor_new(c, a->ndim, a->shape) : NULL;
    if (!y) return NULL;
    lm_cmul_params p = {lm_tensor_numel(a) / 2, lm_tensor_numel(b) / 2, 0};
    lm_tensor *k[3] = {a, b, y}, *in[2] = {a, b};
    if (lm_kernel_run(c, &lm_kernel_cmul_fwd, k, 3, &p)) return NULL;
    lm_record(c, "cmul", cmul_backward, y, in, 2, &p, sizeof p);
    return y;
}
