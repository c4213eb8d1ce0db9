/* loss.c — L1 loss mean|p - t| and MSE loss mean (p - t)^2; output shape {1}.
 *
 * What it is: pred and target of exactly the same shape. The forward adds up fixed-size
 * chunks (boundaries depend only on the element count) in double, in parallel, then the chunk
 * sums in order, so the loss does not depend on the thread count. Backward, with g the
 * incoming gradient of the loss and N the element count:
 *   L1:  dp += sign(p - t) g / N   (sign(0) = 0)        MSE: dp += 2 (p - t) g / N
 * and the target, if it requires grad, gets the negative of that (dt -= ...).
 * What it is not: reductions other than the mean, Charbonnier or relative losses. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <math.h>

#define PAR_MIN 32768L  /* below this many elements, one thread */
#define MAX_CHUNKS 256  /* at most this many chunk sums ... */
#define MIN_CHUNK 8192L /* ... of at least this many elements */

static const char *const LOSS_NAMES[2] = {"l1_loss", "mse_loss"};

/* t[0] = pred, t[1] = target (same shape), t[2] = y {1}: y = mean of |d| or d^2 (writes =). */
static int loss_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    int kind = ((const lm_loss_params *)params)->kind;
    const float *p = t[0]->data, *q = t[1]->data;
    long n = lm_tensor_numel(t[0]);
    long chunk = (n + MAX_CHUNKS - 1) / MAX_CHUNKS;
    if (chunk < MIN_CHUNK) chunk = MIN_CHUNK;
    long nch = (n + chunk - 1) / chunk;
    double part[MAX_CHUNKS];
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long k = 0; k < nch; k++) {
        long e = (k + 1) * chunk < n ? (k + 1) * chunk : n;
        double s = 0.0;
        if (kind == LM_LOSS_L1)
            for (long i = k * chunk; i < e; i++) s += fabsf(p[i] - q[i]);
        else
            for (long i = k * chunk; i < e; i++) {
                double d = (double)p[i] - (double)q[i];
                s += d * d;
            }
        part[k] = s;
    }
    double s = 0.0;
    for (long k = 0; k < nch; k++) s += part[k];
    t[2]->data[0] = (float)(s / (double)n);
    return 0;
}

/* t[0] = pred, t[1] = target, t[2] = gy {1}, t[3] = gd (pred's or target's gradient):
 * gd += sign * dloss/dpred (writes +=). */
static int loss_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_loss_bwd_params *bp = params;
    const float *p = t[0]->data, *q = t[1]->data;
    float *gd = t[3]->data;
    long n = lm_tensor_numel(t[0]);
    const float k = (float)((double)bp->sign * t[2]->data[0] / (double)n);
    if (bp->kind == LM_LOSS_L1) {
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
        for (long i = 0; i < n; i++) {
            float d = p[i] - q[i];
            gd[i] += k * (float)((d > 0.0f) - (d < 0.0f));
        }
    } else {
        const float k2 = 2.0f * k;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
        for (long i = 0; i < n; i++) gd[i] += k2 * (p[i] - q[i]);
    }
    return 0;
}

LM_KERNEL(l1_mse_loss_fwd, loss_fwd_cpu);
LM_KERNEL(l1_mse_loss_bwd, loss_bwd_cpu);

static void loss_backward(lm_ctx *c, lm_node *n)
{
    int kind = ((const lm_loss_params *)n->params)->kind;
    for (int i = 0; i < 2; i++) {
        if (!lm_requires_grad(n->in[i])) continue;
        lm_loss_bwd_params bp = {kind, i == 0 ? 1.0f : -1.0f};
        lm_tensor *t[4] = {n->in[0], n->in[1], n->out->grad, lm_grad(c, n->in[i])};
        if (t[3]) lm_kernel_run(c, &lm_kernel_l1_mse_loss_bwd, t, 4, &bp);
    }
}

static lm_tensor *loss(lm_ctx *c, int kind, lm_tensor *pred, lm_tensor *target)
{
    const char *name = LOSS_NAMES[kind];
    if (!lm_check_inputs(c, name, 2, pred, target)) return NULL;
    if (!lm_tensor_same_shape(pred, target)) {
        char sa[64], sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: pred %s and target %s differ in shape", name,
                    lm_shape_str(pred, sa, sizeof sa), lm_shape_str(target, sb, sizeof sb));
        return NULL;
    }
    pred = lm_contiguous(c, pred);
    target = lm_contiguous(c, target);
    lm_tensor *y = pred && target ? lm_tensor_new1(c, 1) : NULL;
    if (!y) return NULL;
    lm_loss_params p = {kind};
    lm_tensor *t[3] = {pred, target, y};
    if (lm_kernel_run(c, &lm_kernel_l1_mse_loss_fwd, t, 3, &p)) return NULL;
    lm_tensor *in[2] = {pred, target};
    lm_record(c, name, loss_backward, y, in, 2, &p, sizeof p);
    return y;
}

lm_tensor *lm_l1_loss(lm_ctx *c, lm_tensor *pred, lm_tensor *target)
{
    return loss(c, LM_LOSS_L1, pred, target);
}

lm_tensor *lm_mse_loss(lm_ctx *c, lm_tensor *pred, lm_tensor *target)
{
    return loss(c, LM_LOSS_MSE, pred, target);
}
