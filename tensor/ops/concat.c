/* concat.c — concat (join tensors along one dim) and split (cut one tensor into parts).
 * What it is: both are block copies: viewing a tensor as outer x (size along dim * inner),
 * each part is a column band of that matrix. concat's backward and split's forward copy a
 * band out (=, +=); split's backward adds a part back into its band (+=).
 * Tape: a node holds at most LM_MAX_INPUTS inputs, so concat of more tensors records one node
 * per group of inputs, all with the same output; each adds only into its own group's grads.
 * What it is not: a view (outputs are contiguous copies). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <string.h>

/* Geometry of t around dim: outer = prod(shape[:dim]), inner = prod(shape[dim+1:]). */
static void band_geometry(const lm_tensor *t, int dim, long *outer, long *inner)
{
    long o = 1, i = 1;
    for (int d = 0; d < dim; d++) o *= t->shape[d];
    for (int d = dim + 1; d < t->ndim; d++) i *= t->shape[d];
    *outer = o;
    *inner = i;
}

/* part (contiguous, shape of whole except along dim) <-> band of whole starting at start.
 * to_part: part (= or += when add) band; else band += part (add must be set).
 * Jobs are (row, fixed chunk) pairs: disjoint destinations, no reductions. */
static void band_move(lm_ctx *c, const lm_tensor *whole, const lm_tensor *part, int dim,
                      int start, int to_part, int add)
{
    enum { CHUNK = 4096 };
    long outer, inner;
    band_geometry(whole, dim, &outer, &inner);
    const long len = part->shape[dim] * inner, ld = whole->shape[dim] * inner;
    const long nch = (len + CHUNK - 1) / CHUNK, jobs = outer * nch;
    float *wd = whole->data + start * inner, *pd = part->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) if (outer * len > 32768)
    for (long j = 0; j < jobs; j++) {
        const long r = j / nch, s = (j % nch) * CHUNK, e = s + CHUNK < len ? s + CHUNK : len;
        float *w = wd + r * ld + s, *p = pd + r * len + s;
        if (!to_part)
            for (long k = 0; k < e - s; k++) w[k] += p[k];
        else if (add)
            for (long k = 0; k < e - s; k++) p[k] += w[k];
        else
            memcpy(p, w, (size_t)(e - s) * sizeof *p);
    }
}

/* concat forward: t[0..nt-1) = inputs, t[nt-1] = output; out = */
static int concat_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    const lm_band_params *p = params;
    int start = p->start;
    for (int i = 0; i < nt - 1; i++) {
        long outer, inner;
        band_geometry(t[i], p->dim, &outer, &inner);
        const long len = t[i]->shape[p->dim] * inner, ld = t[nt - 1]->shape[p->dim] * inner;
        float *o = t[nt - 1]->data + start * inner;
        const float *s = t[i]->data;
        /* jobs are (row, chunk) pairs, as in band_move: a single large row (batch 1, the
         * whole-frame models) is split over the threads too */
        enum { CHUNK = 16384 };
        const long nch = (len + CHUNK - 1) / CHUNK, jobs = outer * nch;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) if (outer * len > 32768)
        for (long j = 0; j < jobs; j++) {
            const long r = j / nch, a = (j % nch) * CHUNK, e = a + CHUNK < len ? a + CHUNK : len;
            memcpy(o + r * ld + a, s + r * len + a, (size_t)(e - a) * sizeof *o);
        }
        start += t[i]->shape[p->dim];
    }
    return 0;
}
/* concat backward of one input: t[0] = gx_i (part), t[1] = gy (whole); gx_i += band */
static int concat_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_band_params *p = params;
    band_move(c, t[1], t[0], p->dim, p->start, 1, 1);
    return 0;
}
/* split forward of one part: t[0] = x (whole), t[1] = part; part = band */
static int split_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_band_params *p = params;
    band_move(c, t[0], t[1], p->dim, p->start, 1, 0);
    return 0;
}
/* split backward of one part: t[0] = gx (whole), t[1] = gpart; band += gpart */
static int split_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_band_params *p = params;
    band_move(c, t[0], t[1], p->dim, p->start, 0, 1);
    return 0;
}
LM_KERNEL(concat_fwd, concat_fwd_cpu);
LM_KERNEL(concat_bwd, concat_bwd_cpu);
LM_KERNEL(split_fwd, split_fwd_cpu);
LM_KERNEL(split_bwd, split_bwd_cpu);

/* One node = one group of inputs; params->start is the group's first band. */
static void concat_backward(lm_ctx *c, lm_node *n)
{
    const lm_band_params *p = n->params;
    lm_band_params q = *p;
    for (int i = 0; i < n->nin; i++) {
        lm_tensor *x = n->in[i];
        if (lm_requires_grad(x)) {
            lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
            if (!t[0]) return;
            lm_kernel_run(c, &lm_kernel_concat_bwd, t, 2, &q);
        }
        q.start += x->shape[p->dim];
    }
}

/* Checks xs[0..n) agree on every dim but `dim`; returns the concat size along dim or 0. */
static int concat_check(lm_ctx *c, lm_tensor *const *xs, int n, int dim)
{
    char sa[64], sb[64];
    int total = 0;
    for (int i = 0; i < n; i++) {
        int ok = xs[i]->ndim == xs[0]->ndim;
        for (int d = 0; ok && d < xs[0]->ndim; d++)
            ok = d == dim || xs[i]->shape[d] == xs[0]->shape[d];
        if (!ok) {
            lm_ctx_fail(c, LM_ERR_SHAPE, "concat: input %d (%s) does not match input 0 (%s) "
                        "outside dim %d", i, lm_shape_str(xs[i], sa, sizeof sa),
                        lm_shape_str(xs[0], sb, sizeof sb), dim);
            return 0;
        }
        total += xs[i]->shape[dim];
    }
    return total;
}

lm_tensor *lm_concat(lm_ctx *c, lm_tensor *const *xs, int n, int dim)
{
    if (c->status) return NULL;
    if (!xs || n < 1) {
        lm_ctx_fail(c, LM_ERR_ARG, "concat: %d inputs (need at least 1)", n);
        return NULL;
    }
    for (int i = 0; i < n; i++)
        if (!lm_check_inputs(c, "concat", 1, xs[i])) return NULL;
    int d = dim < 0 ? dim + xs[0]->ndim : dim;
    if (d < 0 || d >= xs[0]->ndim) {
        lm_ctx_fail(c, LM_ERR_ARG, "concat: dim %d out of range for %d dims", dim, xs[0]->ndim);
        return NULL;
    }
    int total = concat_check(c, xs, n, d);
    lm_tensor **in = total ? lm_ctx_alloc(c, (size_t)(n + 1) * sizeof *in) : NULL;
    if (!in) return NULL;
    for (int i = 0; i < n; i++)
        if (!(in[i] = lm_contiguous(c, xs[i]))) return NULL;
    int s[LM_MAX_DIMS];
    for (int k = 0; k < in[0]->ndim; k++) s[k] = k == d ? total : in[0]->shape[k];
    lm_tensor *y = lm_tensor_new(c, in[0]->ndim, s);
    if (!y) return NULL;
    in[n] = y;
    lm_band_params p = {d, 0};
    if (lm_kernel_run(c, &lm_kernel_concat_fwd, in, n + 1, &p)) return NULL;
    for (int g = 0; g < n; g += LM_MAX_INPUTS) {
        int m = n - g < LM_MAX_INPUTS ? n - g : LM_MAX_INPUTS;
        lm_record(c, "concat", concat_backward, y, in + g, m, &p, sizeof p);
        for (int i = g; i < g + m; i++) p.start += in[i]->shape[d];
    }
    return y;
}

static void split_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_split_bwd, t, 2, n->params);
}

/* Checks split arguments; returns nonzero when valid. */
static int split_check(lm_ctx *c, const lm_tensor *x, int dim, int n, const int *sizes)
{
    char sb[64];
    if (n < 1 || !sizes) {
        lm_ctx_fail(c, LM_ERR_ARG, "split: %d parts (need at least 1 and a sizes array)", n);
        return 0;
    }
    if (dim < 0 || dim >= x->ndim) {
        lm_ctx_fail(c, LM_ERR_ARG, "split: dim out of range for %s",
                    lm_shape_str(x, sb, sizeof sb));
        return 0;
    }
    long sum = 0;
    for (int i = 0; i < n; i++) {
        if (sizes[i] < 1) {
            lm_ctx_fail(c, LM_ERR_ARG, "split: part %d has size %d (must be >= 1)", i, sizes[i]);
            return 0;
        }
        sum += sizes[i];
    }
    if (sum != x->shape[dim]) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "split: sizes sum to %ld but %s has %d along dim %d", sum,
                    lm_shape_str(x, sb, sizeof sb), x->shape[dim], dim);
        return 0;
    }
    return 1;
}

int lm_split(lm_ctx *c, lm_tensor *x, int dim, int n, const int *sizes, lm_tensor **out)
{
    for (int i = 0; out && i < n; i++) out[i] = NULL;
    if (!lm_check_inputs(c, "split", 1, x)) return c->status;
    if (!out) return lm_ctx_fail(c, LM_ERR_ARG, "split: out is NULL");
    int d = dim < 0 ? dim + x->ndim : dim;
    if (!split_check(c, x, d, n, sizes)) return c->status;
    x = lm_contiguous(c, x);
    if (!x) return c->status;
    lm_band_params p = {d, 0};
    for (int i = 0; i < n; i++) {
        int s[LM_MAX_DIMS];
        for (int k = 0; k < x->ndim; k++) s[k] = k == d ? sizes[i] : x->shape[k];
        lm_tensor *y = lm_tensor_new(c, x->ndim, s);
        lm_tensor *t[2] = {x, y};
        if (!y || lm_kernel_run(c, &lm_kernel_split_fwd, t, 2, &p)) break;
        lm_record(c, "split", split_backward, y, &x, 1, &p, sizeof p);
        out[i] = y;
        p.start += sizes[i];
    }
    if (c->status)
        for (int i = 0; i < n; i++) out[i] = NULL;
    return c->status;
}
