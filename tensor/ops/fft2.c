/* fft2.c — 2-D discrete Fourier transform over the last two complex dims (lm_fft2).
 * Layout: a complex tensor is a float tensor whose last dim is 2 (real, imaginary), so x is
 * [..., H, W, 2] and the transform runs over H and W for every leading index (B of them).
 * Convention: forward Y[k,l] = sum_{n,m} X[n,m] exp(-2 pi i (k n / H + l m / W)) (unnormalised,
 * as FFTW and numpy.fft.fft2); inverse = (1 / (H W)) sum X exp(+2 pi i (...)), so
 * inverse(forward(x)) = x.
 * Gradient: with complex gradients g = dL/dRe + i dL/dIm of a real loss L and y = A x linear
 * (A the DFT matrix, scale included), dL/dx = A^H g_y: the conjugate transpose of the DFT matrix
 * is the DFT of the opposite sign (the matrix is symmetric). So forward's backward is the
 * unnormalised +i transform of gy, and inverse's backward is (1 / (H W)) times the -i transform.
 * CPU kernel: FFTW (single precision), one plan of one H x W transform per call (FFTW_ESTIMATE,
 * FFTW_UNALIGNED: arena memory is not FFTW-aligned), executed for each of the B transforms
 * (OpenMP over B). Planning goes through lm_fftw_lock: FFTW's planner is not thread-safe.
 * What it is not: a real-to-complex transform, or any shift (fftshift is the caller's). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <fftw3.h>
#include <math.h>
#include <omp.h>
#include <pthread.h>
#include <string.h>

static pthread_mutex_t fftw_mu = PTHREAD_MUTEX_INITIALIZER;
void lm_fftw_lock(void) { pthread_mutex_lock(&fftw_mu); }
void lm_fftw_unlock(void) { pthread_mutex_unlock(&fftw_mu); }

/* out (= or += when acc) scale * DFT_sign(in) for B transforms of H x W; in is not modified. */
static int run_fft(lm_ctx *c, const float *in, float *out, const lm_fft2_params *p, int sign,
                   int acc)
{
    long hw = (long)p->H * p->W;
    fftwf_complex *tmp = NULL;
    int nt = lm_nthreads(c) < p->B ? lm_nthreads(c) : p->B;
    if (acc) { /* a scratch transform per thread */
        tmp = fftwf_malloc((size_t)(nt > 0 ? nt : 1) * (size_t)hw * sizeof(fftwf_complex));
        if (!tmp) return lm_ctx_fail(c, LM_ERR_NOMEM, "fft2: out of memory (%d x %d)", p->H,
                                     p->W);
    }
    lm_fftw_lock();
    /* FFTW_ESTIMATE does not touch the arrays while planning; the plan is executed on others
     * with fftwf_execute_dft (same sizes, FFTW_UNALIGNED). Out of place, the input is kept. */
    fftwf_plan plan = fftwf_plan_dft_2d(p->H, p->W, (fftwf_complex *)(void *)in,
                                        tmp ? tmp : (fftwf_complex *)(void *)out,
                                        sign < 0 ? FFTW_FORWARD : FFTW_BACKWARD,
                                        FFTW_ESTIMATE | FFTW_UNALIGNED | FFTW_PRESERVE_INPUT);
    lm_fftw_unlock();
    if (!plan) {
        fftwf_free(tmp);
        return lm_ctx_fail(c, LM_ERR_BACKEND, "fft2: FFTW could not plan %d x %d", p->H, p->W);
    }
    const float s = p->scale;
#pragma omp parallel for num_threads(nt > 0 ? nt : 1) schedule(static) if (nt > 1)
    for (int b = 0; b < p->B; b++) {
        fftwf_complex *src = (fftwf_complex *)(void *)(in + 2 * b * hw);
        float *dst = out + 2 * b * hw;
        if (!tmp) {
            fftwf_execute_dft(plan, src, (fftwf_complex *)(void *)dst);
            if (s != 1.0f)
                for (long i = 0; i < 2 * hw; i++) dst[i] *= s;
            continue;
        }
        float *w = (float *)(tmp + (size_t)omp_get_thread_num() * hw);
        fftwf_execute_dft(plan, src, (fftwf_complex *)w);
        for (long i = 0; i < 2 * hw; i++) dst[i] += s * w[i];
    }
    lm_fftw_lock();
    fftwf_destroy_plan(plan);
    lm_fftw_unlock();
    fftwf_free(tmp);
    return 0;
}

/* t[0] = x, t[1] = y ([B, H, W, 2] contiguous): y = scale DFT_sign(x) (writes =). */
static int fft2_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_fft2_params *p = params;
    return run_fft(c, t[0]->data, t[1]->data, p, p->sign, 0);
}

/* t[0] = gy, t[1] = gx: gx += scale DFT_{-sign}(gy) (the adjoint of fft2_fwd). */
static int fft2_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_fft2_params *p = params;
    return run_fft(c, t[0]->data, t[1]->data, p, -p->sign, 1);
}

LM_KERNEL(fft2_fwd, fft2_fwd_cpu);
LM_KERNEL(fft2_bwd, fft2_bwd_cpu);

static void fft2_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_fft2_bwd, t, 2, n->params);
}

lm_tensor *lm_fft2(lm_ctx *c, lm_tensor *x, int inverse)
{
    const char *name = inverse ? "ifft2" : "fft2";
    if (!lm_check_inputs(c, name, 1, x)) return NULL;
    char s[64];
    if (x->ndim < 3 || x->shape[x->ndim - 1] != 2) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: x is %s; expected [..., H, W, 2] (complex as a last "
                    "dim of 2)", name, lm_shape_str(x, s, sizeof s));
        return NULL;
    }
    lm_fft2_params p = {1, x->shape[x->ndim - 3], x->shape[x->ndim - 2], inverse ? 1 : -1, 1};
    for (int i = 0; i < x->ndim - 3; i++) p.B *= x->shape[i];
    if (inverse) p.scale = (float)(1.0 / ((double)p.H * p.W));
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new(c, x->ndim, x->shape) : NULL;
    if (!y) return NULL;
    lm_tensor *k[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_fft2_fwd, k, 2, &p)) return NULL;
    lm_record(c, name, fft2_backward, y, &x, 1, &p, sizeof p);
    return y;
}
