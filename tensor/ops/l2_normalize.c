/* l2_normalize.c — y = x / max(||x||_2, eps) along one axis (PyTorch F.normalize, p = 2).
 * What it is: the tensor is viewed as outer x len x inner (len = size along axis); each job
 * takes one outer index and a block of inner positions, so the norms of a block are summed
 * (in double) over the axis with contiguous inner loops, by one thread, in a fixed order.
 * Backward, with n = ||x||: where n >= eps (the clamp passes the norm, as torch.clamp_min's
 * gradient does at equality) gx += g / n - x (x . g) / n^3; where n < eps the divisor is the
 * constant eps: gx += g / eps.
 * What it is not: other p-norms. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include "tensor/ops/op_paths.h"
#include <math.h>

enum { L2_BLOCK = 64 };

/* outer, len, inner of t around axis */
static void l2_geometry(const lm_tensor *t, int axis, long *outer, long *len, long *inner)
{
    long o = 1, i = 1;
    for (int d = 0; d < axis; d++) o *= t->shape[d];
    for (int d = axis + 1; d < t->ndim; d++) i *= t->shape[d];
    *outer = o;
    *len = t->shape[axis];
    *inner = i;
}

/* Fast path of the forward along the last axis (inner == 1, the rows of the spectral
 * attention): one row per job, the sum of squares in double over 4 interleaved partial sums
 * (vectorised), then y = x / den. The reference (the blocked loop below, with one position per
 * block) sums in row order: the double sums can differ in the last bits, which almost never
 * changes the float norm. */
static void l2_rows_fwd(lm_ctx *c, const float *x0, float *y0, long outer, long len, float eps)
{
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) if (outer * len >= 32768)
    for (long o = 0; o < outer; o++) {
        const float *x = x0 + o * len;
        float *y = y0 + o * len;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        long a = 0;
        for (; a + 4 <= len; a += 4) {
            s0 += (double)x[a] * x[a];
            s1 += (double)x[a + 1] * x[a + 1];
            s2 += (double)x[a + 2] * x[a + 2];
            s3 += (double)x[a + 3] * x[a + 3];
        }
        for (; a < len; a++) s0 += (double)x[a] * x[a];
        const float n = (float)sqrt((s0 + s1) + (s2 + s3));
        const float den = n > eps ? n : eps;
#pragma omp simd
        for (long i = 0; i < len; i++) y[i] = x[i] / den;
    }
}

/* forward: t[0] = x, t[1] = y (same shape); y = */
static int l2_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_l2_params *p = params;
    long outer, len, inner;
    l2_geometry(t[0], p->axis, &outer, &len, &inner);
    if (inner == 1 && lm_op_path(c) == LM_OP_PATH_FAST) {
        l2_rows_fwd(c, t[0]->data, t[1]->data, outer, len, p->eps);
        return 0;
    }
    const long nblk = (inner + L2_BLOCK - 1) / L2_BLOCK;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long j = 0; j < outer * nblk; j++) {
        const long o = j / nblk, i0 = (j % nblk) * L2_BLOCK;
        const int ni = (int)(inner - i0 < L2_BLOCK ? inner - i0 : L2_BLOCK);
        const float *x = t[0]->data + o * len * inner + i0;
        float *y = t[1]->data + o * len * inner + i0;
        double ss[L2_BLOCK] = {0};
        float den[L2_BLOCK];
        for (long a = 0; a < len; a++)
            for (int q = 0; q < ni; q++) ss[q] += (double)x[a * inner + q] * x[a * inner + q];
        for (int q = 0; q < ni; q++) {
            const float n = (float)sqrt(ss[q]);
            den[q] = n > p->eps ? n : p->eps;
        }
        for (long a = 0; a < len; a++)
            for (int q = 0; q < ni; q++) y[a * inner + q] = x[a * inner + q] / den[q];
    }
    return 0;
}

/* backward: t[0] = gx, t[1] = gy, t[2] = x; gx += (see the file comment) */
static int l2_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_l2_params *p = params;
    long outer, len, inner;
    l2_geometry(t[0], p->axis, &outer, &len, &inner);
    const long nblk = (inner + L2_BLOCK - 1) / L2_BLOCK;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long j = 0; j < outer * nblk; j++) {
        const long o = j / nblk, i0 = (j % nblk) * L2_BLOCK, off = o * len * inner + i0;
        const int ni = (int)(inner - i0 < L2_BLOCK ? inner - i0 : L2_BLOCK);
        const float *x = t[2]->data + off, *g = t[1]->data + off;
        float *gx = t[0]->data + off;
        double ss[L2_BLOCK] = {0}, dot[L2_BLOCK] = {0};
        float a1[L2_BLOCK], a3[L2_BLOCK]; /* gx += a1 g - a3 x */
        for (long a = 0; a < len; a++)
            for (int q = 0; q < ni; q++) {
                ss[q] += (double)x[a * inner + q] * x[a * inner + q];
                dot[q] += (double)x[a * inner + q] * g[a * inner + q];
            }
        for (int q = 0; q < ni; q++) {
            const double n = sqrt(ss[q]);
            const int pass = n >= (double)p->eps && n > 0.0;
            a1[q] = (float)(1.0 / (pass ? n : (double)p->eps));
            a3[q] = pass ? (float)(dot[q] / (n * n * n)) : 0.0f;
        }
        for (long a = 0; a < len; a++)
            for (int q = 0; q < ni; q++)
                gx[a * inner + q] += a1[q] * g[a * inner + q] - a3[q] * x[a * inner + q];
    }
    return 0;
}
LM_KERNEL(l2_normalize_fwd, l2_fwd_cpu);
LM_KERNEL(l2_normalize_bwd, l2_bwd_cpu);

static void l2_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[3] = {lm_grad(c, x), n->out->grad, x};
    if (t[0]) lm_kernel_run(c, &lm_kernel_l2_normalize_bwd, t, 3, n->params);
}

lm_tensor *lm_l2_normalize(lm_ctx *c, lm_tensor *x, int axis, float eps)
{
    if (!lm_check_inputs(c, "l2_normalize", 1, x)) return NULL;
    char sb[64];
    int a = axis < 0 ? axis + x->ndim : axis;
    if (a < 0 || a >= x->ndim) {
        lm_ctx_fail(c, LM_ERR_ARG, "l2_normalize: axis %d out of range for %s", axis,
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    if (!(eps >= 0.0f) || isinf(eps)) {
        lm_ctx_fail(c, LM_ERR_ARG, "l2_normalize: eps %g must be finite and >= 0", (double)eps);
        return NULL;
    }
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    lm_tensor *y = lm_tensor_new(c, x->ndim, x->shape);
    if (!y) return NULL;
    lm_l2_params p = {a, eps};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_l2_normalize_fwd, t, 2, &p)) return NULL;
    lm_record(c, "l2_normalize", l2_backward, y, &x, 1, &p, sizeof p);
    return y;
}
