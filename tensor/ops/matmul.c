/* matmul.c — matrix products: lm_matmul (2-D or batched 3-D, transpose flags, one 2-D side
 * broadcast over the batch) and lm_linear (y = x W^T + b over the last dim, PyTorch Linear).
 * What it is: shape checks, CBLAS-backed kernels (through lm_gemm_mt / lm_gemm_batched, which
 * split the work over the ctx threads), and backward for every input. A 2-D right-hand side
 * shared by a non-transposed batched left side is folded into one tall GEMM.
 * What it is not: convolution (conv2d*.c) or attention (composed in models/). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include "tensor/ops/gemm_internal.h"
#include <omp.h>

/* ---- matmul --------------------------------------------------------------------------- */
/* t = {a, b, y}: y_i = op(a_i) op(b_i) (writes =). */
static int matmul_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(params);
    lm_gemm_batched(c, p.batch, p.ta, p.tb, p.M, p.N, p.K, 1.0f, t[0]->data, lm_mm_sa(&p),
                    lm_mm_lda(&p), t[1]->data, lm_mm_sb(&p), lm_mm_ldb(&p), 0.0f, t[2]->data,
                    (long)p.M * p.N, p.N);
    return 0;
}

/* t = {dy, b, da}: da_i += dy_i op(b_i)^T (transposed back if ta); summed over the batch
 * when a is shared. */
static int matmul_bwd_a_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(params);
    const float *dy = t[0]->data, *b = t[1]->data;
    long sdy = (long)p.M * p.N, sda = lm_mm_sa(&p);
    if (!p.ta)
        lm_gemm_batched(c, p.batch, 0, !p.tb, p.M, p.K, p.N, 1.0f, dy, sdy, p.N, b, lm_mm_sb(&p),
                        lm_mm_ldb(&p), 1.0f, t[2]->data, sda, p.K);
    else
        lm_gemm_batched(c, p.batch, p.tb, 1, p.K, p.M, p.N, 1.0f, b, lm_mm_sb(&p), lm_mm_ldb(&p),
                        dy, sdy, p.N, 1.0f, t[2]->data, sda, p.M);
    return 0;
}

/* t = {dy, a, db}: db_i += op(a_i)^T dy_i (transposed back if tb); summed over the batch
 * when b is shared. */
static int matmul_bwd_b_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(params);
    const float *dy = t[0]->data, *a = t[1]->data;
    long sdy = (long)p.M * p.N, sdb = lm_mm_sb(&p);
    if (!p.tb)
        lm_gemm_batched(c, p.batch, !p.ta, 0, p.K, p.N, p.M, 1.0f, a, lm_mm_sa(&p), lm_mm_lda(&p),
                        dy, sdy, p.N, 1.0f, t[2]->data, sdb, p.N);
    else
        lm_gemm_batched(c, p.batch, 1, p.ta, p.N, p.K, p.M, 1.0f, dy, sdy, p.N, a, lm_mm_sa(&p),
                        lm_mm_lda(&p), 1.0f, t[2]->data, sdb, p.K);
    return 0;
}

LM_KERNEL(matmul_fwd, matmul_fwd_cpu);
LM_KERNEL(matmul_bwd_a, matmul_bwd_a_cpu);
LM_KERNEL(matmul_bwd_b, matmul_bwd_b_cpu);

static void matmul_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *a = n->in[0], *b = n->in[1], *dy = n->out->grad;
    if (lm_requires_grad(a)) {
        lm_tensor *t[3] = {dy, b, lm_grad(c, a)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_matmul_bwd_a, t, 3, n->params);
    }
    if (lm_requires_grad(b)) {
        lm_tensor *t[3] = {dy, a, lm_grad(c, b)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_matmul_bwd_b, t, 3, n->params);
    }
}

lm_tensor *lm_matmul(lm_ctx *c, lm_tensor *a, lm_tensor *b, int trans_a, int trans_b)
{
    if (!lm_check_inputs(c, "matmul", 2, a, b)) return NULL;
    char sa[64], sb[64];
    lm_shape_str(a, sa, sizeof sa);
    lm_shape_str(b, sb, sizeof sb);
    if (a->ndim < 2 || a->ndim > 3 || b->ndim < 2 || b->ndim > 3) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "matmul: a %s and b %s must be 2-D or 3-D", sa, sb);
        return NULL;
    }
    lm_mm_params p = {1, 0, 0, 0, trans_a != 0, trans_b != 0, a->ndim == 3, b->ndim == 3};
    int ra = a->ndim - 2, rb = b->ndim - 2; /* index of the row dim */
    p.M = p.ta ? a->shape[ra + 1] : a->shape[ra];
    int ka = p.ta ? a->shape[ra] : a->shape[ra + 1];
    p.K = p.tb ? b->shape[rb + 1] : b->shape[rb];
    p.N = p.tb ? b->shape[rb] : b->shape[rb + 1];
    if (ka != p.K) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "matmul: inner sizes differ: a %s%s (K=%d) and b %s%s "
                    "(K=%d)", sa, p.ta ? "^T" : "", ka, sb, p.tb ? "^T" : "", p.K);
        return NULL;
    }
    if (p.a_batched && p.b_batched && a->shape[0] != b->shape[0]) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "matmul: batch sizes differ: a %s and b %s", sa, sb);
        return NULL;
    }
    p.batch = p.a_batched ? a->shape[0] : p.b_batched ? b->shape[0] : 1;
    a = lm_contiguous(c, a);
    b = lm_contiguous(c, b);
    if (!a || !b) return NULL;
    int shape[3] = {p.batch, p.M, p.N};
    int nd = (p.a_batched || p.b_batched) ? 3 : 2;
    lm_tensor *y = lm_tensor_new(c, nd, nd == 3 ? shape : shape + 1);
    if (!y) return NULL;
    lm_tensor *t[3] = {a, b, y};
    if (lm_kernel_run(c, &lm_kernel_matmul_fwd, t, 3, &p)) return NULL;
    lm_tensor *in[2] = {a, b};
    lm_record(c, "matmul", matmul_backward, y, in, 2, &p, sizeof p);
    return y;
}

/* ---- linear --------------------------------------------------------------------------- */
/* t = {x (R x in), w (out x in), y (R x out)[, bias (out)]}: y = x w^T + bias (writes =). */
static int linear_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    const lm_linear_params *p = params;
    float *y = t[2]->data;
    if (nt > 3) {
        const float *bias = t[3]->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) if (p->R >= 256)
        for (long r = 0; r < p->R; r++)
            for (int o = 0; o < p->out; o++) y[r * p->out + o] = bias[o];
    }
    lm_gemm_mt(c, 0, 1, p->R, p->out, p->in, 1.0f, t[0]->data, p->in, t[1]->data, p->in,
               nt > 3 ? 1.0f : 0.0f, y, p->out);
    return 0;
}

/* t = {dy (R x out), w, dx (R x in)}: dx += dy w. */
static int linear_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_linear_params *p = params;
    lm_gemm_mt(c, 0, 0, p->R, p->in, p->out, 1.0f, t[0]->data, p->out, t[1]->data, p->in, 1.0f,
               t[2]->data, p->in);
    return 0;
}

/* t = {dy (R x out), x (R x in), dw (out x in)}: dw += dy^T x. */
static int linear_bwd_w_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_linear_params *p = params;
    lm_gemm_mt(c, 1, 0, p->out, p->in, p->R, 1.0f, t[0]->data, p->out, t[1]->data, p->in, 1.0f,
               t[2]->data, p->in);
    return 0;
}

/* t = {dy (R x out), db (out)}: db[o] += sum_r dy[r, o], in double, rows in order; columns
 * split over threads (the result does not depend on the thread count). */
static int linear_bwd_bias_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_linear_params *p = params;
    const float *dy = t[0]->data;
    float *db = t[1]->data;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    double *acc = lm_ctx_alloc(c, sizeof(double) * (size_t)p->out);
    if (!acc) return c->status;
    int nth = (long)p->R * p->out < 65536 ? 1 : lm_nthreads(c);
#pragma omp parallel num_threads(nth)
    {
        int T = omp_get_num_threads(), id = omp_get_thread_num();
        int o0 = (int)((long)p->out * id / T), o1 = (int)((long)p->out * (id + 1) / T);
        for (int o = o0; o < o1; o++) acc[o] = 0.0;
        for (long r = 0; r < p->R; r++)
            for (int o = o0; o < o1; o++) acc[o] += dy[r * p->out + o];
        for (int o = o0; o < o1; o++) db[o] += (float)acc[o];
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

LM_KERNEL(linear_fwd, linear_fwd_cpu);
LM_KERNEL(linear_bwd_x, linear_bwd_x_cpu);
LM_KERNEL(linear_bwd_w, linear_bwd_w_cpu);
LM_KERNEL(linear_bwd_bias, linear_bwd_bias_cpu);

static void linear_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0], *w = n->in[1], *bias = n->nin > 2 ? n->in[2] : NULL;
    lm_tensor *dy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {dy, w, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_linear_bwd_x, t, 3, n->params);
    }
    if (lm_requires_grad(w)) {
        lm_tensor *t[3] = {dy, x, lm_grad(c, w)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_linear_bwd_w, t, 3, n->params);
    }
    if (lm_requires_grad(bias)) {
        lm_tensor *t[2] = {dy, lm_grad(c, bias)};
        if (t[1]) lm_kernel_run(c, &lm_kernel_linear_bwd_bias, t, 2, n->params);
    }
}

lm_tensor *lm_linear(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *b)
{
    if (!lm_check_inputs(c, "linear", 2, x, w)) return NULL;
    char sx[64], sw[64], sb[64];
    lm_shape_str(x, sx, sizeof sx);
    lm_shape_str(w, sw, sizeof sw);
    if (w->ndim != 2 || x->ndim < 1 || x->shape[x->ndim - 1] != w->shape[1]) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "linear: x %s does not match weight %s (need out x in "
                    "with in = last dim of x)", sx, sw);
        return NULL;
    }
    if (b && (b->ndim != 1 || b->shape[0] != w->shape[0])) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "linear: bias %s must have %d elements (weight %s)",
                    lm_shape_str(b, sb, sizeof sb), w->shape[0], sw);
        return NULL;
    }
    lm_linear_params p = {(int)(lm_tensor_numel(x) / w->shape[1]), w->shape[1], w->shape[0]};
    x = lm_contiguous(c, x);
    w = lm_contiguous(c, w);
    if (b) b = lm_contiguous(c, b);
    if (!x || !w || c->status) return NULL;
    int shape[LM_MAX_DIMS];
    for (int i = 0; i < x->ndim; i++) shape[i] = x->shape[i];
    shape[x->ndim - 1] = p.out;
    lm_tensor *y = lm_tensor_new(c, x->ndim, shape);
    if (!y) return NULL;
    lm_tensor *t[4] = {x, w, y, b};
    if (lm_kernel_run(c, &lm_kernel_linear_fwd, t, b ? 4 : 3, &p)) return NULL;
    lm_tensor *in[3] = {x, w, b};
    lm_record(c, "linear", linear_backward, y, in, b ? 3 : 2, &p, sizeof p);
    return y;
}
