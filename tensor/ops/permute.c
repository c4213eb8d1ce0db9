/* permute.c — permute (any reordering of up to 5 dims) and transpose (swap two dims).
 * What it is: a contiguous copy y with y.shape[i] = x.shape[perm[i]]; the backward moves the
 * gradient back with the same index map (+=). transpose builds a permutation and permutes.
 * What it is not: a view (PyTorch's permute is a view; ours always copies, so later ops see
 * contiguous memory). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

/* x: contiguous source (or gradient of the source), y: contiguous, y.shape[d] =
 * x.shape[perm[d]]. add == 0: y = x gathered; add: x += y scattered. The map is a bijection:
 * rows of y (all dims but the last) are independent jobs. */
static void permute_move(lm_ctx *c, const lm_tensor *x, const lm_tensor *y, const int *perm,
                         int add)
{
    const int nd = y->ndim, o = LM_MAX_DIMS - nd;
    int sh[LM_MAX_DIMS] = {1, 1, 1, 1, 1};
    ptrdiff_t st[LM_MAX_DIMS] = {0, 0, 0, 0, 0};
    for (int d = 0; d < nd; d++) { /* right-align into 5 dims */
        sh[o + d] = y->shape[d];
        st[o + d] = x->stride[perm[d]];
    }
    const long rows = (long)sh[0] * sh[1] * sh[2] * sh[3];
    const int n4 = sh[4];
    const ptrdiff_t s4 = st[4];
    float *xd = x->data, *yd = y->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long r = 0; r < rows; r++) {
        long q = r;
        const int i3 = (int)(q % sh[3]); q /= sh[3];
        const int i2 = (int)(q % sh[2]); q /= sh[2];
        const int i1 = (int)(q % sh[1]); q /= sh[1];
        const int i0 = (int)q;
        float *xp = xd + i0 * st[0] + i1 * st[1] + i2 * st[2] + i3 * st[3];
        float *yp = yd + r * n4;
        if (add)
            for (int f = 0; f < n4; f++) xp[f * s4] += yp[f];
        else
            for (int f = 0; f < n4; f++) yp[f] = xp[f * s4];
    }
}

/* forward: t[0] = x, t[1] = y; y = */
static int permute_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    permute_move(c, t[0], t[1], ((const lm_permute_params *)params)->perm, 0);
    return 0;
}
/* backward: t[0] = gx, t[1] = gy; gx += */
static int permute_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    permute_move(c, t[0], t[1], ((const lm_permute_params *)params)->perm, 1);
    return 0;
}
LM_KERNEL(permute_fwd, permute_fwd_cpu);
LM_KERNEL(permute_bwd, permute_bwd_cpu);

static void permute_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_permute_bwd, t, 2, n->params);
}

/* Shared by permute and transpose once `perm` is known to be valid. */
static lm_tensor *permute_run(lm_ctx *c, const char *op, lm_tensor *x, const int *perm)
{
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    lm_permute_params p = {x->ndim, {0, 0, 0, 0, 0}};
    int s[LM_MAX_DIMS];
    for (int d = 0; d < x->ndim; d++) {
        p.perm[d] = perm[d];
        s[d] = x->shape[perm[d]];
    }
    lm_tensor *y = lm_tensor_new(c, x->ndim, s);
    if (!y) return NULL;
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_permute_fwd, t, 2, &p)) return NULL;
    lm_record(c, op, permute_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_permute(lm_ctx *c, lm_tensor *x, const int *perm)
{
    if (!lm_check_inputs(c, "permute", 1, x)) return NULL;
    char sb[64];
    if (!perm) {
        lm_ctx_fail(c, LM_ERR_ARG, "permute: perm is NULL");
        return NULL;
    }
    unsigned seen = 0;
    for (int d = 0; d < x->ndim; d++) {
        if (perm[d] < 0 || perm[d] >= x->ndim || (seen & (1u << perm[d]))) {
            lm_ctx_fail(c, LM_ERR_ARG, "permute: entry %d (%d) makes no permutation of the %d "
                        "dims of %s", d, perm[d], x->ndim, lm_shape_str(x, sb, sizeof sb));
            return NULL;
        }
        seen |= 1u << perm[d];
    }
    return permute_run(c, "permute", x, perm);
}

lm_tensor *lm_transpose(lm_ctx *c, lm_tensor *x, int d0, int d1)
{
    if (!lm_check_inputs(c, "transpose", 1, x)) return NULL;
    char sb[64];
    int a = d0 < 0 ? d0 + x->ndim : d0, b = d1 < 0 ? d1 + x->ndim : d1;
    if (a < 0 || a >= x->ndim || b < 0 || b >= x->ndim) {
        lm_ctx_fail(c, LM_ERR_ARG, "transpose: dims %d, %d out of range for %s", d0, d1,
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    int perm[LM_MAX_DIMS];
    for (int d = 0; d < x->ndim; d++) perm[d] = d;
    perm[a] = b;
    perm[b] = a;
    return permute_run(c, "transpose", x, perm);
}
