/* area_sample.c — lm_area_sample: a centred window of S x S cells read from B images of N x N
 * samples on a finer, per-image grid, each cell the sum of K x K bilinear samples over its area.
 * It is the last step of the differentiable PSF (data/doe_grad.c): the Fresnel-plane intensity
 * (spacing du, depending on the wavelength) integrated over the sensor pixels (pitch p), the
 * same rule as data/doe.c's resample, as a fixed linear map with its transpose as gradient.
 * Coordinates: the input is in FFT order (index 0 on the axis, negative positions wrapped to
 * N - k, i.e. before any fftshift). Cell (i, j), sub-sample (a, b) reads position
 *   u = ratio_b (i - S/2 + (a + 0.5) / K - 0.5)   (and likewise v with j, b), ratio = p / du,
 * bilinearly between floor(u) and floor(u) + 1, which must both lie in -N/2 .. N - N/2 - 1
 * (otherwise the sample is 0, as doe.c's bilinear outside its shifted image).
 * What it is not: normalised (the caller divides by the sum) or general resampling. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <math.h>
#include <string.h>

/* One cell's K x K samples: calls visit(index into the N x N image, weight) for every tap. */
#define AREA_TAPS(p, b, i, j, VISIT)                                                          \
    do {                                                                                      \
        int N_ = (p)->N, K_ = (p)->K, S_ = (p)->S, lo_ = -(N_ / 2), hi_ = N_ - N_ / 2 - 1;    \
        double r_ = (p)->ratio[b];                                                            \
        for (int a_ = 0; a_ < K_; a_++) {                                                     \
            double u_ = r_ * ((i) - S_ / 2 + (a_ + 0.5) / K_ - 0.5);                          \
            int y0_ = (int)floor(u_);                                                         \
            if (y0_ < lo_ || y0_ + 1 > hi_) continue;                                         \
            double ty_ = u_ - y0_;                                                            \
            int ya_ = (y0_ + N_) % N_, yb_ = (y0_ + 1 + N_) % N_;                             \
            for (int b_ = 0; b_ < K_; b_++) {                                                 \
                double v_ = r_ * ((j) - S_ / 2 + (b_ + 0.5) / K_ - 0.5);                      \
                int x0_ = (int)floor(v_);                                                     \
                if (x0_ < lo_ || x0_ + 1 > hi_) continue;                                     \
                double tx_ = v_ - x0_;                                                        \
                int xa_ = (x0_ + N_) % N_, xb_ = (x0_ + 1 + N_) % N_;                         \
                VISIT((long)ya_ * N_ + xa_, (1 - ty_) * (1 - tx_));                           \
                VISIT((long)ya_ * N_ + xb_, (1 - ty_) * tx_);                                 \
                VISIT((long)yb_ * N_ + xa_, ty_ * (1 - tx_));                                 \
                VISIT((long)yb_ * N_ + xb_, ty_ * tx_);                                       \
            }                                                                                 \
        }                                                                                     \
    } while (0)

/* t = {x [B, N, N], y [B, S, S]}: y = the cell sums (writes =). */
static int area_sample_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_area_params *p = params;
    const long N2 = (long)p->N * p->N, S2 = (long)p->S * p->S;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) collapse(2)
    for (int b = 0; b < p->B; b++)
        for (int i = 0; i < p->S; i++) {
            const float *x = t[0]->data + b * N2;
            for (int j = 0; j < p->S; j++) {
                double acc = 0;
#define ACC(k, w) acc += (w) * x[k]
                AREA_TAPS(p, b, i, j, ACC);
#undef ACC
                t[1]->data[b * S2 + (long)i * p->S + j] = (float)acc;
            }
        }
    return 0;
}

/* t = {gy [B, S, S], gx [B, N, N]}: gx += the transpose of the map applied to gy (serial per
 * image: cells share taps). */
static int area_sample_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_area_params *p = params;
    const long N2 = (long)p->N * p->N, S2 = (long)p->S * p->S;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static)
    for (int b = 0; b < p->B; b++) {
        float *gx = t[1]->data + b * N2;
        for (int i = 0; i < p->S; i++)
            for (int j = 0; j < p->S; j++) {
                float g = t[0]->data[b * S2 + (long)i * p->S + j];
#define SCATTER(k, w) gx[k] += (float)(w) * g
                AREA_TAPS(p, b, i, j, SCATTER);
#undef SCATTER
            }
    }
    return 0;
}

LM_KERNEL(area_sample_fwd, area_sample_fwd_cpu);
LM_KERNEL(area_sample_bwd, area_sample_bwd_cpu);

static void area_sample_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_area_sample_bwd, t, 2, n->params);
}

lm_tensor *lm_area_sample(lm_ctx *c, lm_tensor *x, int S, int K, const double *ratio)
{
    if (!lm_check_inputs(c, "area_sample", 1, x)) return NULL;
    char s[64];
    if (x->ndim != 3 || x->shape[1] != x->shape[2] || x->shape[0] > LM_AREA_MAX_B) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "area_sample: x is %s; expected B x N x N, B <= %d",
                    lm_shape_str(x, s, sizeof s), LM_AREA_MAX_B);
        return NULL;
    }
    lm_area_params p = {x->shape[0], x->shape[1], S, K, {0}};
    int ok = S >= 1 && S <= 4096 && K >= 1 && K <= 64 && ratio;
    for (int b = 0; ok && b < p.B; b++) {
        ok = ratio[b] > 0 && ratio[b] * (S + 1) < 4.0 * p.N;
        p.ratio[b] = ratio[b];
    }
    if (!ok) {
        lm_ctx_fail(c, LM_ERR_ARG, "area_sample: S %d (1..4096), K %d (1..64) or a ratio "
                    "(> 0, window within the grid of %d) out of range", S, K, p.N);
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new3(c, p.B, S, S) : NULL;
    if (!y) return NULL;
    lm_tensor *k[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_area_sample_fwd, k, 2, &p)) return NULL;
    lm_record(c, "area_sample", area_sample_backward, y, &x, 1, &p, sizeof p);
    return y;
}
