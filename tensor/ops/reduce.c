/* reduce.c — sum and mean over any set of axes (bitmask, keepdim), and global average pooling.
 *
 * What it is: x is seen with its size-1 dims dropped and adjacent dims of the same kind
 * (reduced / kept) merged, so the layout alternates kept and reduced dims. Three forward cases,
 * all accumulating in double, each output element summed in a fixed order by one thread, so
 * results do not depend on the thread count:
 *   - innermost dim reduced: per output element, sum contiguous runs;
 *   - innermost dim kept: blocks of CB neighbouring outputs accumulate whole rows together;
 *   - everything reduced: fixed-size chunks (independent of the thread count) summed in
 *     parallel, then the chunk sums added in order.
 * Backward mirrors the forward partition: gx += scale * gy broadcast back (each gx element
 * written by one thread). lm_global_avg_pool is a dedicated B x C x H x W -> B x C x 1 x 1 path.
 * What it is not: max/min/argmax reductions, variance. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

#define CB 64            /* outputs per block when the innermost dim is kept */
#define PAR_MIN 32768L   /* below this many input elements, one thread */
#define MAX_CHUNKS 256   /* "everything reduced": at most this many chunk sums */
#define MIN_CHUNK 8192L  /* ... of at least this many elements */

/* ---- layout ------------------------------------------------------------------------------ */
typedef struct red_layout {
    int nd;                    /* coalesced dims (outer to inner) */
    long n[LM_MAX_DIMS];
    ptrdiff_t s[LM_MAX_DIMS];  /* strides in contiguous x */
    int red[LM_MAX_DIMS];      /* 1 = reduced */
    long ny, nr;               /* output elements; input elements summed into each */
} red_layout;

static void red_layout_build(red_layout *L, const lm_tensor *x, unsigned mask)
{
    int m = 0;
    for (int i = 0; i < x->ndim; i++) {
        if (x->shape[i] == 1) continue;
        int r = (mask >> i) & 1u;
        if (m > 0 && L->red[m - 1] == r) {
            L->n[m - 1] *= x->shape[i];
            continue;
        }
        L->n[m] = x->shape[i];
        L->red[m] = r;
        m++;
    }
    L->nd = m;
    L->ny = L->nr = 1;
    ptrdiff_t s = 1;
    for (int d = m - 1; d >= 0; d--) {
        L->s[d] = s;
        s *= L->n[d];
        if (L->red[d]) L->nr *= L->n[d];
        else L->ny *= L->n[d];
    }
}

/* Offset of the idx-th combination (lexicographic) of the dims d < upto with red[d] == red. */
static ptrdiff_t red_unravel(const red_layout *L, long idx, int red, int upto)
{
    ptrdiff_t off = 0;
    for (int d = upto - 1; d >= 0; d--) {
        if (L->red[d] != red) continue;
        off += (idx % L->n[d]) * L->s[d];
        idx /= L->n[d];
    }
    return off;
}

/* ---- forward ----------------------------------------------------------------------------- */
/* Everything reduced: y[0] = scale * sum(x). Chunk boundaries depend only on n. */
static void sum_all(lm_ctx *c, const float *x, long n, float *y, float scale)
{
    long chunk = (n + MAX_CHUNKS - 1) / MAX_CHUNKS;
    if (chunk < MIN_CHUNK) chunk = MIN_CHUNK;
    long nch = (n + chunk - 1) / chunk;
    double part[MAX_CHUNKS];
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (n >= PAR_MIN)
    for (long k = 0; k < nch; k++) {
        long e = (k + 1) * chunk < n ? (k + 1) * chunk : n;
        double s = 0.0;
        for (long i = k * chunk; i < e; i++) s += x[i];
        part[k] = s;
    }
    double s = 0.0;
    for (long k = 0; k < nch; k++) s += part[k];
    y[0] = (float)(s * scale);
}

/* Innermost dim reduced: one output element per unit, contiguous runs of n_last. */
static void sum_inner_reduced(lm_ctx *c, const red_layout *L, const float *x, float *y,
                              float scale, int par)
{
    long run = L->n[L->nd - 1], nq = L->nr / run;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long j = 0; j < L->ny; j++) {
        const float *base = x + red_unravel(L, j, 0, L->nd);
        double s = 0.0;
        for (long q = 0; q < nq; q++) {
            const float *p = base + red_unravel(L, q, 1, L->nd - 1);
            for (long t = 0; t < run; t++) s += p[t];
        }
        y[j] = (float)(s * scale);
    }
}

/* Innermost dim kept (length cols): CB neighbouring outputs per unit, rows added together. */
static void sum_inner_kept(lm_ctx *c, const red_layout *L, const float *x, float *y,
                           float scale, int par)
{
    long cols = L->n[L->nd - 1], nb = (cols + CB - 1) / CB, units = L->ny / cols * nb;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        long o = u / nb, j0 = (u % nb) * CB;
        int w = (int)(cols - j0 < CB ? cols - j0 : CB);
        const float *base = x + red_unravel(L, o, 0, L->nd - 1) + j0;
        double acc[CB];
        for (int j = 0; j < w; j++) acc[j] = 0.0;
        for (long q = 0; q < L->nr; q++) {
            const float *p = base + red_unravel(L, q, 1, L->nd - 1);
            for (int j = 0; j < w; j++) acc[j] += p[j];
        }
        for (int j = 0; j < w; j++) y[o * cols + j0 + j] = (float)(acc[j] * scale);
    }
}

/* t[0] = x, t[1] = y (contiguous; y has the kept elements in order): y = scale * sum (=). */
static int sum_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_reduce_params *p = params;
    const float *x = t[0]->data;
    float *y = t[1]->data;
    red_layout L;
    red_layout_build(&L, t[0], p->mask);
    int par = L.ny * L.nr >= PAR_MIN;
    if (L.nr == 1) { /* nothing to add up (reduced dims all of size 1) */
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
        for (long i = 0; i < L.ny; i++) y[i] = x[i] * p->scale;
    } else if (L.ny == 1)
        sum_all(c, x, L.nr, y, p->scale);
    else if (L.red[L.nd - 1])
        sum_inner_reduced(c, &L, x, y, p->scale, par);
    else
        sum_inner_kept(c, &L, x, y, p->scale, par);
    return 0;
}

/* ---- backward ---------------------------------------------------------------------------- */
static void bcast_inner_reduced(lm_ctx *c, const red_layout *L, const float *gy, float *gx,
                                float scale, int par)
{
    long run = L->n[L->nd - 1], nq = L->nr / run;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long j = 0; j < L->ny; j++) {
        float *base = gx + red_unravel(L, j, 0, L->nd);
        const float v = gy[j] * scale;
        for (long q = 0; q < nq; q++) {
            float *p = base + red_unravel(L, q, 1, L->nd - 1);
            for (long t = 0; t < run; t++) p[t] += v;
        }
    }
}

static void bcast_inner_kept(lm_ctx *c, const red_layout *L, const float *gy, float *gx,
                             float scale, int par)
{
    long cols = L->n[L->nd - 1], nb = (cols + CB - 1) / CB, units = L->ny / cols * nb;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
    for (long u = 0; u < units; u++) {
        long o = u / nb, j0 = (u % nb) * CB;
        int w = (int)(cols - j0 < CB ? cols - j0 : CB);
        float *base = gx + red_unravel(L, o, 0, L->nd - 1) + j0;
        float v[CB];
        for (int j = 0; j < w; j++) v[j] = gy[o * cols + j0 + j] * scale;
        for (long q = 0; q < L->nr; q++) {
            float *p = base + red_unravel(L, q, 1, L->nd - 1);
            for (int j = 0; j < w; j++) p[j] += v[j];
        }
    }
}

/* t[0] = gy, t[1] = gx (gx has x's shape): gx += scale * gy broadcast over the reduced dims. */
static int sum_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_reduce_params *p = params;
    const float *gy = t[0]->data;
    float *gx = t[1]->data;
    red_layout L;
    red_layout_build(&L, t[1], p->mask);
    long n = L.ny * L.nr;
    int par = n >= PAR_MIN;
    if (L.nr == 1 || L.ny == 1) { /* flat: gy has n elements, or one */
        long sy = L.ny == 1 ? 0 : 1;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (par)
        for (long i = 0; i < n; i++) gx[i] += gy[i * sy] * p->scale;
    } else if (L.red[L.nd - 1])
        bcast_inner_reduced(c, &L, gy, gx, p->scale, par);
    else
        bcast_inner_kept(c, &L, gy, gx, p->scale, par);
    return 0;
}

LM_KERNEL(reduce_sum_fwd, sum_fwd_cpu);
LM_KERNEL(reduce_sum_bwd, sum_bwd_cpu);

static void sum_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_reduce_sum_bwd, t, 2, n->params);
}

static lm_tensor *reduce(lm_ctx *c, const char *name, lm_tensor *x, unsigned mask,
                         int keepdim, int mean)
{
    if (!lm_check_inputs(c, name, 1, x)) return NULL;
    if ((mask >> x->ndim) != 0) {
        char sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: axes mask 0x%x names dims beyond the %d of %s", name,
                    mask, x->ndim, lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    int shape[LM_MAX_DIMS], nd = 0;
    long count = 1;
    for (int i = 0; i < x->ndim; i++) {
        int r = (mask >> i) & 1u;
        if (r) count *= x->shape[i];
        if (!r || keepdim) shape[nd++] = r ? 1 : x->shape[i];
    }
    if (nd == 0) shape[nd++] = 1;
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new(c, nd, shape) : NULL;
    if (!y) return NULL;
    lm_reduce_params p = {mask, mean ? (float)(1.0 / (double)count) : 1.0f};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_reduce_sum_fwd, t, 2, &p)) return NULL;
    lm_record(c, name, sum_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_sum(lm_ctx *c, lm_tensor *x, unsigned axes_mask, int keepdim)
{
    return reduce(c, "sum", x, axes_mask, keepdim, 0);
}

lm_tensor *lm_mean(lm_ctx *c, lm_tensor *x, unsigned axes_mask, int keepdim)
{
    return reduce(c, "mean", x, axes_mask, keepdim, 1);
}

/* ---- global average pooling ------------------------------------------------------------- */
/* t[0] = x (B x C x H x W), t[1] = y (B x C x 1 x 1): y = mean over H, W (writes =). */
static int gap_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const lm_tensor *x = t[0];
    long bc = (long)x->shape[0] * x->shape[1], hw = (long)x->shape[2] * x->shape[3];
    float *y = t[1]->data;
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (bc * hw >= PAR_MIN)
    for (long k = 0; k < bc; k++) {
        const float *p = x->data + k * hw;
        double s = 0.0;
        for (long i = 0; i < hw; i++) s += p[i];
        y[k] = (float)(s / (double)hw);
    }
    return 0;
}

/* t[0] = gy (B x C x 1 x 1), t[1] = gx (B x C x H x W): gx += gy / (H W). */
static int gap_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt, (void)params;
    const lm_tensor *gx = t[1];
    long bc = (long)gx->shape[0] * gx->shape[1], hw = (long)gx->shape[2] * gx->shape[3];
    const float *gy = t[0]->data, inv = (float)(1.0 / (double)hw);
#pragma omp parallel for num_threads(lm_nthreads(c)) schedule(static) if (bc * hw >= PAR_MIN)
    for (long k = 0; k < bc; k++) {
        float *p = gx->data + k * hw;
        const float v = gy[k] * inv;
        for (long i = 0; i < hw; i++) p[i] += v;
    }
    return 0;
}

LM_KERNEL(global_avg_pool_fwd, gap_fwd_cpu);
LM_KERNEL(global_avg_pool_bwd, gap_bwd_cpu);

static void gap_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_global_avg_pool_bwd, t, 2, NULL);
}

lm_tensor *lm_global_avg_pool(lm_ctx *c, lm_tensor *x)
{
    if (!lm_check_inputs(c, "global_avg_pool", 1, x)) return NULL;
    if (x->ndim != 4) {
        char sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "global_avg_pool: expects B x C x H x W, got %s",
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new4(c, x->shape[0], x->shape[1], 1, 1) : NULL;
    if (!y) return NULL;
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_global_avg_pool_fwd, t, 2, NULL)) return NULL;
    lm_record(c, "global_avg_pool", gap_backward, y, &x, 1, NULL, 0);
    return y;
}
