/* softmax.c — softmax along one axis (negative axis counts from the end), max-subtracted.
 *
 * What it is: x seen as outer x L x inner with the softmax over L. inner == 1 (the last axis,
 * attention rows) runs row by row; otherwise blocks of up to CB neighbouring columns are
 * processed together so memory is read along rows. Sums are accumulated in double. Each work
 * unit (a row, or a block of columns) is independent, so results do not depend on the thread
 * count.  Backward: gx += y * (gy - sum_L(gy * y)).
 * What it is not: log-softmax, masking, or a fused attention kernel. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <math.h>

#define CB 64          /* columns per block when inner > 1 */
#define PAR_MIN 32768L /* below this many elements, one thread */

typedef struct sm_dims { long outer, len, inner; } sm_dims;

static sm_dims sm_split(const lm_tensor *x, int axis)
{
    sm_dims d = {1, x->shape[axis], 1};
    for (int i = 0; i < axis; i++) d.outer *= x->shape[i];
    for (int i = axis + 1; i < x->ndim; i++) d.inner *= x->shape[i];
    return d;
}

/* One row of len contiguous elements: y = softmax(x) (writes =). */
static void sm_row_fwd(const float *x, float *y, long len)
{
    float m = x[0];
    for (long l = 1; l < len; l++) m = x[l] > m ? x[l] : m;
    double s = 0.0;
    for (long l = 0; l < len; l++) {
        y[l] = expf(x[l] - m);
        s += y[l];
    }
    float inv = (float)(1.0 / s);
    for (long l = 0; l < len; l++) y[l] *= inv;
}

/* w columns (stride inner between the len entries of a column): y = softmax (writes =). */
static void sm_block_fwd(const float *x, float *y, long len, long inner, int w)
{
    float m[CB];
    double s[CB];
    for (int j = 0; j < w; j++) m[j] = x[j], s[j] = 0.0;
    for (long l = 1; l < len; l++)
        for (int j = 0; j < w; j++) m[j] = x[l * inner + j] > m[j] ? x[l * inner + j] : m[j];
    for (long l = 0; l < len; l++)
        for (int j = 0; j < w; j++) {
            float e = expf(x[l * inner + j] - m[j]);
            y[l * inner + j] = e;
            s[j] += e;
        }
    for (int j = 0; j < w; j++) m[j] = (float)(1.0 / s[j]); /* m now holds 1 / sum */
    for (long l = 0; l < len; l++)
        for (int j = 0; j < w; j++) y[l * inner + j] *= m[j];
}

/* gx += y * (gy - sum(gy * y)) along one contiguous row. */
static void sm_row_bwd(const float *y, const float *gy, float *gx, long len)
{
    double s = 0.0;
    for (long l = 0; l < len; l++) s += (double)gy[l] * y[l];
    float dot = (float)s;
    for (long l = 0; l < len; l++) gx[l] += y[l] * (gy[l] - dot);
}

static void sm_block_bwd(const float *y, const float *gy, float *gx, long len, long inner, int w)
{
    double s[CB];
    float dot[CB];
    for (int j = 0; j < w; j++) s[j] = 0.0;
    for (long l = 0; l < len; l++)
        for (int j = 0; j < w; j++) s[j] += (double)gy[l * inner + j] * y[l * inner + j];
    for (int j = 0; j < w; j++) dot[j] = (float)s[j];
    for (long l = 0; l < len; l++)
        for (int j = 0; j < w; j++) {
            long k = l * inner + j;
            gx[k] += y[k] * (gy[k] - dot[j]);
        }
}

/* t[0] = x, t[1] = y (contiguous, same shape): y = softmax(x) along axis (writes =). */
static int softmax_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    sm_dims d = sm_split(t[0], ((const lm_softmax_params *)params)->axis);
    const float *x = t[0]->data;
    float *y = t[1]->data;
    long nb = (d.inner + CB - 1) / CB, units = d.inner == 1 ? d.outer : d.outer * nb;
    int par = lm_tensor_numel(t[0]) >= PAR_MIN;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        if (d.inner == 1) {
            sm_row_fwd(x + u * d.len, y + u * d.len, d.len);
            continue;
        }
        long o = u / nb, j0 = (u % nb) * CB, off = o * d.len * d.inner + j0;
        int w = (int)(d.inner - j0 < CB ? d.inner - j0 : CB);
        sm_block_fwd(x + off, y + off, d.len, d.inner, w);
    }
    return 0;
}

/* t[0] = y, t[1] = gy, t[2] = gx (contiguous, same shape): gx += y * (gy - sum(gy * y)). */
static int softmax_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    sm_dims d = sm_split(t[0], ((const lm_softmax_params *)params)->axis);
    const float *y = t[0]->data, *gy = t[1]->data;
    float *gx = t[2]->data;
    long nb = (d.inner + CB - 1) / CB, units = d.inner == 1 ? d.outer : d.outer * nb;
    int par = lm_tensor_numel(t[0]) >= PAR_MIN;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        if (d.inner == 1) {
            sm_row_bwd(y + u * d.len, gy + u * d.len, gx + u * d.len, d.len);
            continue;
        }
        long o = u / nb, j0 = (u % nb) * CB, off = o * d.len * d.inner + j0;
        int w = (int)(d.inner - j0 < CB ? d.inner - j0 : CB);
        sm_block_bwd(y + off, gy + off, gx + off, d.len, d.inner, w);
    }
    return 0;
}

LM_KERNEL(softmax_fwd, softmax_fwd_cpu);
LM_KERNEL(softmax_bwd, softmax_bwd_cpu);

static void softmax_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[3] = {n->out, n->out->grad, lm_grad(c, x)};
    if (t[2]) lm_kernel_run(c, &lm_kernel_softmax_bwd, t, 3, n->params);
}

lm_tensor *lm_softmax(lm_ctx *c, lm_tensor *x, int axis)
{
    if (!lm_check_inputs(c, "softmax", 1, x)) return NULL;
    int a = axis < 0 ? axis + x->ndim : axis;
    if (a < 0 || a >= x->ndim) {
        char sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "softmax: axis %d is outside the %d dims of %s", axis,
                    x->ndim, lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new(c, x->ndim, x->shape) : NULL;
    if (!y) return NULL;
    lm_softmax_params p = {a};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_softmax_fwd, t, 2, &p)) return NULL;
    lm_record(c, "softmax", softmax_backward, y, &x, 1, &p, sizeof p);
    return y;
}
