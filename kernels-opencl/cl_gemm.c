/* cl_gemm.c — the device GEMM (gemm.cl) behind lm_cl_gemm, and the typed launchers of
 * tensor/ops/matmul.c: "matmul_fwd", "matmul_bwd_a", "matmul_bwd_b" (the same GEMM calls as
 * the CPU kernels, batch folding included) and "linear_fwd", "linear_bwd_x", "linear_bwd_w",
 * "linear_bwd_bias". Not here: convolutions (cl_ops_conv.c), which also use lm_cl_gemm. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

#define GEMM_TILE 64

static void arg_mat(lm_cl_args *a, const lm_cl_mat *m, int with_trans)
{
    lm_tensor v = *m->t;
    v.dev_off += (size_t)m->off;
    lm_cl_arg_tensor(a, &v);
    lm_cl_arg_int(a, m->ld);
    if (with_trans) lm_cl_arg_int(a, m->trans);
    lm_cl_arg_int(a, (int)m->s1);
    lm_cl_arg_int(a, (int)m->s2);
}

/* Kernel choice (gemm.cl): gemm_vn whenever B is not transposed, gemm_dot for A x B^T, the
 * tiled gemm for A^T x B^T. Our kernels rather than CLBlast (Debian 1.5.3): measured on PoCL 3.1
 * (AVX-512 EPYC, 2 cores) with the conv shapes of han-tiny / mcan at batch 4 of 66x64,
 * gemm_vn / gemm_dot ran at 45-70 GFLOP/s where CLBlast's SGEMM ran at 7-14 (its default,
 * untuned parameters for a CPU device and its extra pad/transpose kernels) and the old tiled
 * kernel at 1.5-9. Work-groups of 4 x 1 items for gemm_vn (larger ones are slower on PoCL:
 * its work-item loop around a vector body), 1 x 1 for gemm_dot. */
int lm_cl_gemm(lm_cl *b, lm_ctx *c, int n1, int n2, int sum1, int M, int N, int K, float alpha,
               lm_cl_mat A, lm_cl_mat B, float beta, lm_cl_mat C)
{
    if (c->status) return c->status;
    int tiled = A.trans && B.trans, vn = !B.trans;
    if (tiled && b->max_wg < 256)
        return lm_ctx_fail(c, LM_ERR_UNSUPPORTED, "opencl: gemm needs work-groups of 256 items; "
                           "%s allows %zu", b->device_name, b->max_wg);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, tiled ? "gemm" : vn ? "gemm_vn" : "gemm_dot")) return c->status;
    arg_mat(&a, &A, 1);
    arg_mat(&a, &B, 1);
    arg_mat(&a, &C, 0);
    lm_cl_arg_int(&a, M);
    lm_cl_arg_int(&a, N);
    lm_cl_arg_int(&a, K);
    lm_cl_arg_int(&a, n1);
    lm_cl_arg_int(&a, n2);
    lm_cl_arg_int(&a, sum1);
    lm_cl_arg_float(&a, alpha);
    lm_cl_arg_float(&a, beta);
    size_t nz = (size_t)(sum1 ? n2 : n1 * n2);
    if (tiled) {
        size_t global[3] = {(size_t)(N + GEMM_TILE - 1) / GEMM_TILE * 16,
                            (size_t)(M + GEMM_TILE - 1) / GEMM_TILE * 16, nz};
        size_t local[3] = {16, 16, 1};
        return lm_cl_run_nd(&a, 3, global, local);
    }
    size_t bn = vn ? 16 : 4, bm = vn ? 8 : 4;
    size_t global[3] = {(N + bn - 1) / bn, (M + bm - 1) / bm, nz};
    size_t local[3] = {vn && global[0] >= 4 ? 4 : 1, 1, 1};
    return lm_cl_run_nd(&a, 3, global, local);
}

/* A matrix operand of one tensor: no offset, batch stride s (along n1), none along n2. */
static lm_cl_mat mat(const lm_tensor *t, int ld, int trans, long s)
{
    lm_cl_mat m = {t, 0, ld, trans, s, 0};
    return m;
}

/* ---- matmul ----------------------------------------------------------------------------- */
/* Batched product with the CPU kernel's lm_gemm_batched semantics: sc == 0 sums the batch. */
static int batched(lm_cl *b, lm_ctx *c, int batch, int M, int N, int K, lm_cl_mat A,
                   lm_cl_mat B, float beta, lm_cl_mat C)
{
    return lm_cl_gemm(b, c, batch, 1, C.s1 == 0 && batch > 1, M, N, K, 1.0f, A, B, beta, C);
}

/* t = {a, b, y}: y_i = op(a_i) op(b_i) */
int lm_cl_launch_matmul_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(pp);
    return batched(b, c, p.batch, p.M, p.N, p.K, mat(t[0], lm_mm_lda(&p), p.ta, lm_mm_sa(&p)),
                   mat(t[1], lm_mm_ldb(&p), p.tb, lm_mm_sb(&p)), 0.0f,
                   mat(t[2], p.N, 0, (long)p.M * p.N));
}

/* t = {dy, b, da}: da_i += dy_i op(b_i)^T (transposed back if ta) */
int lm_cl_launch_matmul_bwd_a(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(pp);
    long sdy = (long)p.M * p.N, sda = lm_mm_sa(&p);
    if (!p.ta)
        return batched(b, c, p.batch, p.M, p.K, p.N, mat(t[0], p.N, 0, sdy),
                       mat(t[1], lm_mm_ldb(&p), !p.tb, lm_mm_sb(&p)), 1.0f, mat(t[2], p.K, 0, sda));
    return batched(b, c, p.batch, p.K, p.M, p.N, mat(t[1], lm_mm_ldb(&p), p.tb, lm_mm_sb(&p)),
                   mat(t[0], p.N, 1, sdy), 1.0f, mat(t[2], p.M, 0, sda));
}

/* t = {dy, a, db}: db_i += op(a_i)^T dy_i (transposed back if tb) */
int lm_cl_launch_matmul_bwd_b(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_mm_params p = lm_mm_folded(pp);
    long sdy = (long)p.M * p.N, sdb = lm_mm_sb(&p);
    if (!p.tb)
        return batched(b, c, p.batch, p.K, p.N, p.M, mat(t[1], lm_mm_lda(&p), !p.ta, lm_mm_sa(&p)),
                       mat(t[0], p.N, 0, sdy), 1.0f, mat(t[2], p.N, 0, sdb));
    return batched(b, c, p.batch, p.N, p.K, p.M, mat(t[0], p.N, 1, sdy),
                   mat(t[1], lm_mm_lda(&p), p.ta, lm_mm_sa(&p)), 1.0f, mat(t[2], p.K, 0, sdb));
}

/* ---- linear ------------------------------------------------------------------------------ */
/* t = {x (R x in), w (out x in), y (R x out)[, bias]}: y = x w^T + bias */
int lm_cl_launch_linear_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    const lm_linear_params *p = pp;
    if (nt > 3) { /* y = bias broadcast over rows, then the GEMM adds */
        lm_tensor bv = *t[3], yv = *t[2];
        bv.ndim = yv.ndim = 2;
        bv.shape[0] = yv.shape[0] = p->R;
        bv.shape[1] = yv.shape[1] = p->out;
        bv.stride[0] = 0, bv.stride[1] = 1;
        yv.stride[0] = p->out, yv.stride[1] = 1;
        if (lm_cl_view_copy(b, c, &bv, &yv, 0)) return c->status;
    }
    return lm_cl_gemm(b, c, 1, 1, 0, p->R, p->out, p->in, 1.0f, mat(t[0], p->in, 0, 0),
                      mat(t[1], p->in, 1, 0), nt > 3 ? 1.0f : 0.0f, mat(t[2], p->out, 0, 0));
}

/* t = {dy (R x out), w, dx (R x in)}: dx += dy w */
int lm_cl_launch_linear_bwd_x(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_linear_params *p = pp;
    return lm_cl_gemm(b, c, 1, 1, 0, p->R, p->in, p->out, 1.0f, mat(t[0], p->out, 0, 0),
                      mat(t[1], p->in, 0, 0), 1.0f, mat(t[2], p->in, 0, 0));
}

/* t = {dy (R x out), x (R x in), dw (out x in)}: dw += dy^T x */
int lm_cl_launch_linear_bwd_w(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_linear_params *p = pp;
    return lm_cl_gemm(b, c, 1, 1, 0, p->out, p->in, p->R, 1.0f, mat(t[0], p->out, 1, 0),
                      mat(t[1], p->in, 0, 0), 1.0f, mat(t[2], p->in, 0, 0));
}

/* t = {dy (R x out), db (out)}: db[o] += sum over rows */
int lm_cl_launch_linear_bwd_bias(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_linear_params *p = pp;
    lm_cl_reduction r;
    lm_cl_reduction_init(&r);
    r.kshp.s[4] = p->out, r.kst.s[4] = 1, r.ny = p->out;
    r.rshp.s[4] = p->R, r.rst.s[4] = p->out, r.nr = p->R;
    return lm_cl_reduce(b, c, t[0], &r, t[1], 1.0f, 1);
}
