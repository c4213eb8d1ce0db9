/* phase.c — pooling and scaling per mosaic phase, in place of the image: MCAN's mosaic attention
 * without moving the image to channels and back.
 *   lm_phase_mean(x, fy, fx)     y[b, c P + i fx + j] = mean of x[b, c, i::fy, j::fx]
 *                                (= global_avg_pool(pixel_unshuffle(x, fy, fx)))
 *   lm_phase_scale(x, s, fy, fx) y[b, c, y, x] = x[b, c, y, x] s[b, c P + (y % fy) fx + x % fx]
 *                                (= pixel_shuffle(pixel_unshuffle(x) * s))
 * with P = fy fx, x B x C x H x W (H, W multiples of fy, fx) and s B x C P (x 1 x 1).
 * What it is: each kernel runs over the B C planes of x, one plane per thread at a time (static
 * schedule), so every output element is computed by one thread in a fixed order whatever the
 * thread count. A plane's rows are added into W-wide float column sums per row phase
 * (vectorised), and those folded into the P phase sums in double. The scale is applied through a
 * row pattern (the phase scales of row phase i repeated along W), so the inner loops are plain
 * multiplies of contiguous rows.
 * What it is not: a general broadcast (binary.c), or a shuffle (shuffle.c). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <omp.h>
#include <stdlib.h>

#define PAR_MIN 32768L /* below this many elements, one thread */

/* Per-thread scratch of n floats each, or NULL (out of memory: the kernel fails). */
static float *scratch(int nthreads, size_t n) { return malloc(sizeof(float) * n * nthreads); }

/* The row patterns of one plane: pat[i W + x] = k s[(i fx + x % fx)], i < fy. */
static void patterns(const float *s, int fy, int fx, int W, float k, float *pat)
{
    for (int i = 0; i < fy; i++)
        for (int x = 0; x < W; x++) pat[i * W + x] = k * s[i * fx + x % fx];
}

/* t[0] = x, t[1] = y (B x C P x 1 x 1): y = per-phase means (writes =). */
static int phase_mean_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    const lm_tensor *x = t[0];
    const int fy = p->fy, fx = p->fx, P = fy * fx, H = x->shape[2], W = x->shape[3];
    const long planes = (long)x->shape[0] * x->shape[1], hw = (long)H * W;
    const int nth = planes * hw >= PAR_MIN ? lm_nthreads(c) : 1;
    float *col = scratch(nth, (size_t)fy * W);
    if (!col) return lm_ctx_fail(c, LM_ERR_NOMEM, "phase_mean: out of memory");
    const double inv = 1.0 / (double)(hw / P);
    float *y = t[1]->data;
#pragma omp parallel for num_threads(nth) schedule(static)
    for (long k = 0; k < planes; k++) {
        float *cs = col + (size_t)omp_get_thread_num() * fy * W;
        const float *xp = x->data + k * hw;
        for (int i = 0; i < fy; i++) {
            const float *r0 = xp + (long)i * W;
            for (int u = 0; u < W; u++) cs[i * W + u] = r0[u];
            for (int yy = i + fy; yy < H; yy += fy) {
                const float *r = xp + (long)yy * W;
                float *d = cs + i * W;
                for (int u = 0; u < W; u++) d[u] += r[u];
            }
        }
        for (int i = 0; i < fy; i++)
            for (int j = 0; j < fx; j++) {
                double s = 0.0;
                for (int u = j; u < W; u += fx) s += cs[i * W + u];
                y[k * P + i * fx + j] = (float)(s * inv);
            }
    }
    free(col);
    return 0;
}

/* t[0] = gy (B x C P), t[1] = gx: gx += gy / (H W / P) at each phase's pixels. */
static int phase_mean_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    const lm_tensor *gx = t[1];
    const int fy = p->fy, fx = p->fx, P = fy * fx, H = gx->shape[2], W = gx->shape[3];
    const long planes = (long)gx->shape[0] * gx->shape[1], hw = (long)H * W;
    const int nth = planes * hw >= PAR_MIN ? lm_nthreads(c) : 1;
    float *pats = scratch(nth, (size_t)fy * W);
    if (!pats) return lm_ctx_fail(c, LM_ERR_NOMEM, "phase_mean: out of memory");
    const float inv = (float)(1.0 / (double)(hw / P));
#pragma omp parallel for num_threads(nth) schedule(static)
    for (long k = 0; k < planes; k++) {
        float *pat = pats + (size_t)omp_get_thread_num() * fy * W;
        patterns(t[0]->data + k * P, fy, fx, W, inv, pat);
        float *gp = gx->data + k * hw;
        for (int yy = 0; yy < H; yy++) {
            float *r = gp + (long)yy * W;
            const float *q = pat + (yy % fy) * W;
            for (int u = 0; u < W; u++) r[u] += q[u];
        }
    }
    free(pats);
    return 0;
}

/* y = x s (mode 0, writes =) or gx += gy s (mode 1): t = {x or gy, s, y or gx}. */
static int scale_rows(lm_ctx *c, lm_tensor *const *t, const lm_shuffle_params *p, int add)
{
    const lm_tensor *x = t[0];
    const int fy = p->fy, fx = p->fx, P = fy * fx, H = x->shape[2], W = x->shape[3];
    const long planes = (long)x->shape[0] * x->shape[1], hw = (long)H * W;
    const int nth = planes * hw >= PAR_MIN ? lm_nthreads(c) : 1;
    float *pats = scratch(nth, (size_t)fy * W);
    if (!pats) return lm_ctx_fail(c, LM_ERR_NOMEM, "phase_scale: out of memory");
#pragma omp parallel for num_threads(nth) schedule(static)
    for (long k = 0; k < planes; k++) {
        float *pat = pats + (size_t)omp_get_thread_num() * fy * W;
        patterns(t[1]->data + k * P, fy, fx, W, 1.0f, pat);
        const float *xp = x->data + k * hw;
        float *yp = t[2]->data + k * hw;
        for (int yy = 0; yy < H; yy++) {
            const float *r = xp + (long)yy * W, *q = pat + (yy % fy) * W;
            float *d = yp + (long)yy * W;
            if (add)
                for (int u = 0; u < W; u++) d[u] += r[u] * q[u];
            else
                for (int u = 0; u < W; u++) d[u] = r[u] * q[u];
        }
    }
    free(pats);
    return 0;
}

static int phase_scale_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return scale_rows(c, t, params, 0);
}

/* t = {gy, s, gx}: gx += gy s. */
static int phase_scale_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return scale_rows(c, t, params, 1);
}

/* t = {gy, x, gs}: gs[b, c P + q] += sum over phase q's pixels of gy x. */
static int phase_scale_bwd_s_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    const lm_tensor *gy = t[0];
    const int fy = p->fy, fx = p->fx, P = fy * fx, H = gy->shape[2], W = gy->shape[3];
    const long planes = (long)gy->shape[0] * gy->shape[1], hw = (long)H * W;
    const int nth = planes * hw >= PAR_MIN ? lm_nthreads(c) : 1;
    float *col = scratch(nth, (size_t)fy * W);
    if (!col) return lm_ctx_fail(c, LM_ERR_NOMEM, "phase_scale: out of memory");
    float *gs = t[2]->data;
#pragma omp parallel for num_threads(nth) schedule(static)
    for (long k = 0; k < planes; k++) {
        float *cs = col + (size_t)omp_get_thread_num() * fy * W;
        const float *a = gy->data + k * hw, *b = t[1]->data + k * hw;
        for (int i = 0; i < fy; i++) {
            float *d = cs + i * W;
            for (int u = 0; u < W; u++) d[u] = a[(long)i * W + u] * b[(long)i * W + u];
            for (int yy = i + fy; yy < H; yy += fy)
                for (int u = 0; u < W; u++) d[u] += a[(long)yy * W + u] * b[(long)yy * W + u];
        }
        for (int i = 0; i < fy; i++)
            for (int j = 0; j < fx; j++) {
                double s = 0.0;
                for (int u = j; u < W; u += fx) s += cs[i * W + u];
                gs[k * P + i * fx + j] += (float)s;
            }
    }
    free(col);
    return 0;
}

LM_KERNEL(phase_mean_fwd, phase_mean_fwd_cpu);
LM_KERNEL(phase_mean_bwd, phase_mean_bwd_cpu);
LM_KERNEL(phase_scale_fwd, phase_scale_fwd_cpu);
LM_KERNEL(phase_scale_bwd_x, phase_scale_bwd_x_cpu);
LM_KERNEL(phase_scale_bwd_s, phase_scale_bwd_s_cpu);

static void phase_mean_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_phase_mean_bwd, t, 2, n->params);
}

static void phase_scale_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0], *s = n->in[1], *gy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {gy, s, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_phase_scale_bwd_x, t, 3, n->params);
    }
    if (lm_requires_grad(s)) {
        lm_tensor *t[3] = {gy, x, lm_grad(c, s)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_phase_scale_bwd_s, t, 3, n->params);
    }
}

/* x must be B x C x H x W with H, W multiples of fy, fx >= 1. */
static int phase_args_ok(lm_ctx *c, const char *op, const lm_tensor *x, int fy, int fx)
{
    char sb[64];
    if (fy < 1 || fx < 1 || fy > 64 || fx > 64) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: factors %d x %d must be in 1..64", op, fy, fx);
        return 0;
    }
    if (x->ndim != 4 || x->shape[2] % fy || x->shape[3] % fx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x C x H x W with H, W multiples of "
                    "%d x %d", op, lm_shape_str(x, sb, sizeof sb), fy, fx);
        return 0;
    }
    return 1;
}

lm_tensor *lm_phase_mean(lm_ctx *c, lm_tensor *x, int fy, int fx)
{
    if (!lm_check_inputs(c, "phase_mean", 1, x)) return NULL;
    if (!phase_args_ok(c, "phase_mean", x, fy, fx)) return NULL;
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new4(c, x->shape[0], x->shape[1] * fy * fx, 1, 1) : NULL;
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_phase_mean_fwd, t, 2, &p)) return NULL;
    lm_record(c, "phase_mean", phase_mean_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_phase_scale(lm_ctx *c, lm_tensor *x, lm_tensor *s, int fy, int fx)
{
    if (!lm_check_inputs(c, "phase_scale", 2, x, s)) return NULL;
    if (!phase_args_ok(c, "phase_scale", x, fy, fx)) return NULL;
    long want = (long)x->shape[0] * x->shape[1] * fy * fx;
    if (lm_tensor_numel(s) != want || s->shape[0] != x->shape[0]) {
        char sx[64], ss[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "phase_scale: scales %s do not match %s: want %d x %ld",
                    lm_shape_str(s, ss, sizeof ss), lm_shape_str(x, sx, sizeof sx),
                    x->shape[0], want / x->shape[0]);
        return NULL;
    }
    x = lm_contiguous(c, x);
    s = x ? lm_contiguous(c, s) : NULL;
    lm_tensor *y = s ? lm_tensor_new(c, 4, x->shape) : NULL;
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[3] = {x, s, y};
    if (lm_kernel_run(c, &lm_kernel_phase_scale_fwd, t, 3, &p)) return NULL;
    lm_tensor *in[2] = {x, s};
    lm_record(c, "phase_scale", phase_scale_backward, y, in, 2, &p, sizeof p);
    return y;
}
