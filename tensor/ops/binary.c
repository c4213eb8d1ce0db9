/* binary.c — elementwise add, sub, mul, div with NumPy broadcasting (up to 5 dims).
 *
 * What it is: one forward kernel over a "coalesced" view of the broadcast: size-1 dims are
 * dropped and adjacent dims that can be walked as one are merged, so equal shapes become a
 * single flat loop and the per-channel case (B x C x H x W with 1 x C x 1 x 1 or B x C x 1 x 1,
 * as channel attention's x * s) becomes rows of H*W against one scalar each. Rows are cut into
 * fixed blocks run in parallel; every output element is written by exactly one thread, so the
 * result does not depend on the thread count.
 * Backward: the per-element contribution (g, -g, g*b, g*a, g/b, -g*a/b^2) is added straight into
 * the gradient of an operand that has the output's size; for a broadcast operand it goes to a
 * temporary that lm_sum() (double accumulation, fixed order) reduces over the broadcast dims.
 * What it is not: scalar operands (scalar.c), in-place ops, type promotion. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <assert.h>

static const char *const BIN_NAMES[4] = {"add", "sub", "mul", "div"};

#define BLK 4096L      /* elements of the innermost dim per parallel work unit */
#define PAR_MIN 32768L /* below this many output elements, one thread */

/* ---- broadcast layout -------------------------------------------------------------------- */
/* The output (contiguous) seen as n[0] x ... x n[4] after coalescing, with the element strides
 * of a and b along each dim (0 where the operand is broadcast). */
typedef struct bc_layout {
    long n[LM_MAX_DIMS];
    ptrdiff_t s[2][LM_MAX_DIMS];
} bc_layout;

/* Broadcast shape of a and b (right-aligned; a dim broadcasts if it is 1). -1 if incompatible. */
static int bc_shape(const lm_tensor *a, const lm_tensor *b, int *nd, int *shape)
{
    int n = a->ndim > b->ndim ? a->ndim : b->ndim;
    for (int i = 0; i < n; i++) {
        int ia = i - (n - a->ndim), ib = i - (n - b->ndim);
        int da = ia >= 0 ? a->shape[ia] : 1, db = ib >= 0 ? b->shape[ib] : 1;
        if (da != db && da != 1 && db != 1) return -1;
        shape[i] = da == 1 ? db : da;
    }
    *nd = n;
    return 0;
}

/* Strides of contiguous t along the nd dims of the output (0 where t has size 1). */
static void bc_strides(const lm_tensor *t, int nd, ptrdiff_t *st)
{
    ptrdiff_t s = 1;
    for (int i = nd - 1; i >= 0; i--) {
        int it = i - (nd - t->ndim);
        int d = it >= 0 ? t->shape[it] : 1;
        st[i] = d == 1 ? 0 : s;
        s *= d;
    }
}

static void bc_layout_build(bc_layout *L, int nd, const int *oshape, const lm_tensor *a,
                            const lm_tensor *b)
{
    ptrdiff_t st[2][LM_MAX_DIMS];
    bc_strides(a, nd, st[0]);
    bc_strides(b, nd, st[1]);
    long n[LM_MAX_DIMS];
    ptrdiff_t s[2][LM_MAX_DIMS];
    int m = 0;
    for (int i = 0; i < nd; i++) { /* outer to inner; merge into the previous kept dim */
        if (oshape[i] == 1) continue;
        if (m > 0 && s[0][m - 1] == st[0][i] * oshape[i] && s[1][m - 1] == st[1][i] * oshape[i]) {
            n[m - 1] *= oshape[i];
            s[0][m - 1] = st[0][i];
            s[1][m - 1] = st[1][i];
            continue;
        }
        n[m] = oshape[i];
        s[0][m] = st[0][i];
        s[1][m] = st[1][i];
        m++;
    }
    for (int i = 0; i < LM_MAX_DIMS; i++) { /* right-align into 5 dims */
        int k = i - (LM_MAX_DIMS - m);
        L->n[i] = k >= 0 ? n[k] : 1;
        L->s[0][i] = k >= 0 ? s[0][k] : 0;
        L->s[1][i] = k >= 0 ? s[1][k] : 0;
    }
    /* The innermost coalesced dim is contiguous or broadcast for both operands. */
    assert((L->s[0][4] == 0 || L->s[0][4] == 1) && (L->s[1][4] == 0 || L->s[1][4] == 1));
}

/* Offsets into a and b of the start of row r (rows = dims 0..3 in lexicographic order). */
static void bc_row_offsets(const bc_layout *L, long r, ptrdiff_t *oa, ptrdiff_t *ob)
{
    ptrdiff_t pa = 0, pb = 0;
    for (int d = 3; d >= 0; d--) {
        long i = r % L->n[d];
        r /= L->n[d];
        pa += i * L->s[0][d];
        pb += i * L->s[1][d];
    }
    *oa = pa;
    *ob = pb;
}

/* ---- row loops --------------------------------------------------------------------------- */
/* One row segment of n elements: a and b advance by sa, sb in {0, 1}. EXPR reads av, bv (and
 * gv = g[i] in backward); STORE is "=" (forward) or "+=" (backward). Four specialisations so
 * the common cases vectorise. */
#define ROW_LOOP(DST, STORE, EXPR)                                                            \
    do {                                                                                      \
        if (sa && sb) {                                                                       \
            _Pragma("omp simd") for (long i = 0; i < n; i++) {                               \
                const float av = a[i], bv = b[i];                                             \
                (void)av, (void)bv;                                                           \
                DST[i] STORE(EXPR);                                                           \
            }                                                                                 \
        } else if (sa) {                                                                      \
            const float bv = b[0];                                                            \
            _Pragma("omp simd") for (long i = 0; i < n; i++) {                               \
                const float av = a[i];                                                        \
                (void)av, (void)bv;                                                           \
                DST[i] STORE(EXPR);                                                           \
            }                                                                                 \
        } else if (sb) {                                                                      \
            const float av = a[0];                                                            \
            _Pragma("omp simd") for (long i = 0; i < n; i++) {                               \
                const float bv = b[i];                                                        \
                (void)av, (void)bv;                                                           \
                DST[i] STORE(EXPR);                                                           \
            }                                                                                 \
        } else {                                                                              \
            const float av = a[0], bv = b[0];                                                 \
            (void)av, (void)bv;                                                               \
            _Pragma("omp simd") for (long i = 0; i < n; i++) DST[i] STORE(EXPR);              \
        }                                                                                     \
    } while (0)

/* y[i] = a op b  (writes =) */
static void fwd_row(int op, float *restrict y, const float *a, ptrdiff_t sa, const float *b,
                    ptrdiff_t sb, long n)
{
    switch (op) {
    case LM_BIN_ADD: ROW_LOOP(y, =, av + bv); break;
    case LM_BIN_SUB: ROW_LOOP(y, =, av - bv); break;
    case LM_BIN_MUL: ROW_LOOP(y, =, av * bv); break;
    default: ROW_LOOP(y, =, av / bv); break;
    }
}

/* d[i] += d(a op b)/d(operand `which`) * g[i]  (writes +=) */
static void bwd_row(int op, int which, float *restrict d, const float *restrict g,
                    const float *a, ptrdiff_t sa, const float *b, ptrdiff_t sb, long n)
{
    switch (op * 2 + which) {
    case LM_BIN_ADD * 2 + 0:
    case LM_BIN_ADD * 2 + 1:
    case LM_BIN_SUB * 2 + 0: ROW_LOOP(d, +=, g[i]); break;
    case LM_BIN_SUB * 2 + 1: ROW_LOOP(d, +=, -g[i]); break;
    case LM_BIN_MUL * 2 + 0: ROW_LOOP(d, +=, g[i] * bv); break;
    case LM_BIN_MUL * 2 + 1: ROW_LOOP(d, +=, g[i] * av); break;
    case LM_BIN_DIV * 2 + 0: ROW_LOOP(d, +=, g[i] / bv); break;
    default: ROW_LOOP(d, +=, -g[i] * av / (bv * bv)); break;
    }
}

/* ---- kernels ----------------------------------------------------------------------------- */
/* t[0] = a, t[1] = b (contiguous, broadcastable), t[2] = y (contiguous, broadcast shape).
 * y = a op b (writes =). */
static int binary_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_binary_params *p = params;
    const lm_tensor *a = t[0], *b = t[1];
    lm_tensor *y = t[2];
    bc_layout L;
    bc_layout_build(&L, y->ndim, y->shape, a, b);
    long n4 = L.n[4], nblk = (n4 + BLK - 1) / BLK;
    long units = L.n[0] * L.n[1] * L.n[2] * L.n[3] * nblk;
    int par = lm_tensor_numel(y) >= PAR_MIN;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        long r = u / nblk, j0 = (u % nblk) * BLK, len = n4 - j0 < BLK ? n4 - j0 : BLK;
        ptrdiff_t oa, ob;
        bc_row_offsets(&L, r, &oa, &ob);
        fwd_row(p->op, y->data + r * n4 + j0, a->data + oa + j0 * L.s[0][4], L.s[0][4],
                b->data + ob + j0 * L.s[1][4], L.s[1][4], len);
    }
    return 0;
}

/* t[0] = g (output gradient, broadcast shape), t[1] = a, t[2] = b, t[3] = d (numel of g).
 * d += (or =, if !accumulate) the per-element gradient contribution for operand `which`. */
static int binary_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_binary_bwd_params *p = params;
    const lm_tensor *g = t[0], *a = t[1], *b = t[2];
    float *d = t[3]->data;
    bc_layout L;
    bc_layout_build(&L, g->ndim, g->shape, a, b);
    long n4 = L.n[4], nblk = (n4 + BLK - 1) / BLK;
    long units = L.n[0] * L.n[1] * L.n[2] * L.n[3] * nblk;
    int par = lm_tensor_numel(g) >= PAR_MIN;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        long r = u / nblk, j0 = (u % nblk) * BLK, len = n4 - j0 < BLK ? n4 - j0 : BLK;
        ptrdiff_t oa, ob;
        bc_row_offsets(&L, r, &oa, &ob);
        float *dr = d + r * n4 + j0;
        if (!p->accumulate)
            for (long i = 0; i < len; i++) dr[i] = 0.0f;
        bwd_row(p->op, p->which, dr, g->data + r * n4 + j0, a->data + oa + j0 * L.s[0][4],
                L.s[0][4], b->data + ob + j0 * L.s[1][4], L.s[1][4], len);
    }
    return 0;
}

/* t[0] = d, t[1] = s (same numel, contiguous): d += scale * s. */
static int grad_acc_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    float k = ((const lm_grad_acc_params *)params)->scale;
    float *d = t[0]->data;
    const float *s = t[1]->data;
    long n = lm_tensor_numel(t[0]);
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long i = 0; i < n; i++) d[i] += k * s[i];
    return 0;
}

LM_KERNEL(binary_fwd, binary_fwd_cpu);
LM_KERNEL(binary_bwd, binary_bwd_cpu);
LM_KERNEL(binary_grad_acc, grad_acc_cpu);

/* ---- backward ---------------------------------------------------------------------------- */
/* Dims of the output g along which operand x was broadcast (x right-aligned). */
static unsigned bc_reduce_mask(const lm_tensor *x, const lm_tensor *g)
{
    unsigned mask = 0;
    for (int i = 0; i < g->ndim; i++) {
        int ix = i - (g->ndim - x->ndim);
        int dx = ix >= 0 ? x->shape[ix] : 1;
        if (dx == 1 && g->shape[i] != 1) mask |= 1u << i;
    }
    return mask;
}

static void binary_grad_input(lm_ctx *c, lm_node *n, int op, int which)
{
    lm_tensor *x = n->in[which], *g = n->out->grad, *gx = lm_grad(c, x);
    if (!gx) return;
    lm_binary_bwd_params bp = {op, which, 1};
    if (lm_tensor_numel(x) == lm_tensor_numel(g)) { /* not broadcast: add in place */
        lm_tensor *t[4] = {g, n->in[0], n->in[1], gx};
        lm_kernel_run(c, &lm_kernel_binary_bwd, t, 4, &bp);
        return;
    }
    lm_tensor *src = g; /* add / sub: the contribution is +-g itself */
    lm_grad_acc_params ap = {op == LM_BIN_SUB && which ? -1.0f : 1.0f};
    if (op == LM_BIN_MUL || op == LM_BIN_DIV) {
        src = lm_tensor_new(c, g->ndim, g->shape);
        if (!src) return;
        bp.accumulate = 0;
        lm_tensor *t[4] = {g, n->in[0], n->in[1], src};
        if (lm_kernel_run(c, &lm_kernel_binary_bwd, t, 4, &bp)) return;
    }
    lm_tensor *s = lm_sum(c, src, bc_reduce_mask(x, g), 1);
    if (!s) return;
    lm_tensor *t2[2] = {gx, s};
    lm_kernel_run(c, &lm_kernel_binary_grad_acc, t2, 2, &ap);
}

static void binary_backward(lm_ctx *c, lm_node *n)
{
    const lm_binary_params *p = n->params;
    for (int which = 0; which < 2; which++)
        if (lm_requires_grad(n->in[which])) binary_grad_input(c, n, p->op, which);
}

/* ---- public ------------------------------------------------------------------------------ */
static lm_tensor *binary(lm_ctx *c, int op, lm_tensor *a, lm_tensor *b)
{
    const char *name = BIN_NAMES[op];
    if (!lm_check_inputs(c, name, 2, a, b)) return NULL;
    int nd, shape[LM_MAX_DIMS];
    if (bc_shape(a, b, &nd, shape)) {
        char sa[64], sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: shapes %s and %s do not broadcast", name,
                    lm_shape_str(a, sa, sizeof sa), lm_shape_str(b, sb, sizeof sb));
        return NULL;
    }
    a = lm_contiguous(c, a);
    b = lm_contiguous(c, b);
    lm_tensor *y = a && b ? lm_tensor_new(c, nd, shape) : NULL;
    if (!y) return NULL;
    lm_binary_params p = {op};
    lm_tensor *t[3] = {a, b, y};
    if (lm_kernel_run(c, &lm_kernel_binary_fwd, t, 3, &p)) return NULL;
    lm_tensor *in[2] = {a, b};
    lm_record(c, name, binary_backward, y, in, 2, &p, sizeof p);
    return y;
}

lm_tensor *lm_add(lm_ctx *c, lm_tensor *a, lm_tensor *b) { return binary(c, LM_BIN_ADD, a, b); }
lm_tensor *lm_sub(lm_ctx *c, lm_tensor *a, lm_tensor *b) { return binary(c, LM_BIN_SUB, a, b); }
lm_tensor *lm_mul(lm_ctx *c, lm_tensor *a, lm_tensor *b) { return binary(c, LM_BIN_MUL, a, b); }
lm_tensor *lm_div(lm_ctx *c, lm_tensor *a, lm_tensor *b) { return binary(c, LM_BIN_DIV, a, b); }
