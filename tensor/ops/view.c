/* view.c — reshape, slice (views sharing memory) and contiguous (copy of a strided view).
 * A view shares its input's data but has its own gradient buffer; its backward adds that
 * gradient into the input's gradient (flat for reshape, strided for slice). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include <string.h>

/* ---- strided copy helpers (CPU) ---------------------------------------------------------- */
/* dst (contiguous, shape of src) = src (any strides), or dst_strided += src_contig when add. */
static void copy_strided(const lm_tensor *v, float *contig, int to_contig)
{
    int nd = v->ndim;
    int shape[LM_MAX_DIMS] = {1, 1, 1, 1, 1};
    ptrdiff_t st[LM_MAX_DIMS] = {0, 0, 0, 0, 0};
    for (int i = 0; i < nd; i++) { /* right-align into 5 dims */
        shape[LM_MAX_DIMS - nd + i] = v->shape[i];
        st[LM_MAX_DIMS - nd + i] = v->stride[i];
    }
    long k = 0;
    for (int a = 0; a < shape[0]; a++)
        for (int b = 0; b < shape[1]; b++)
            for (int d = 0; d < shape[2]; d++)
                for (int e = 0; e < shape[3]; e++) {
                    float *p = v->data + a * st[0] + b * st[1] + d * st[2] + e * st[3];
                    if (st[4] == 1) { /* contiguous rows: copy / vectorised add */
                        float *q = contig + k;
                        if (to_contig) memcpy(q, p, sizeof(float) * (size_t)shape[4]);
                        else {
#pragma omp simd
                            for (int f = 0; f < shape[4]; f++) p[f] += q[f];
                        }
                        k += shape[4];
                    } else if (to_contig)
                        for (int f = 0; f < shape[4]; f++) contig[k++] = p[f * st[4]];
                    else
                        for (int f = 0; f < shape[4]; f++) p[f * st[4]] += contig[k++];
                }
}

/* t[0] = strided source view, t[1] = contiguous destination */
static int contig_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *p)
{
    (void)c, (void)nt, (void)p;
    copy_strided(t[0], t[1]->data, 1);
    return 0;
}
/* t[0] = strided destination view (+=), t[1] = contiguous source */
static int strided_add_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *p)
{
    (void)c, (void)nt, (void)p;
    copy_strided(t[0], t[1]->data, 0);
    return 0;
}
/* t[0] += t[1], same numel, both contiguous */
static int flat_add_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *p)
{
    (void)c, (void)nt, (void)p;
    long n = lm_tensor_numel(t[0]);
    float *a = t[0]->data;
    const float *b = t[1]->data;
#pragma omp simd
    for (long i = 0; i < n; i++) a[i] += b[i];
    return 0;
}
LM_KERNEL(strided_copy, contig_fwd_cpu);
LM_KERNEL(strided_add, strided_add_cpu);
LM_KERNEL(flat_add, flat_add_cpu);

/* ---- reshape ----------------------------------------------------------------------------- */
static void reshape_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_flat_add, t, 2, NULL);
}

lm_tensor *lm_reshape(lm_ctx *c, lm_tensor *x, int ndim, const int *shape)
{
    if (!lm_check_inputs(c, "reshape", 1, x)) return NULL;
    char sb[64];
    if (ndim < 1 || ndim > LM_MAX_DIMS) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "reshape: %d dimensions requested", ndim);
        return NULL;
    }
    long n = lm_tensor_numel(x), known = 1;
    int infer = -1, s[LM_MAX_DIMS];
    for (int i = 0; i < ndim; i++) {
        s[i] = shape[i];
        if (shape[i] == -1 && infer < 0) infer = i;
        else if (shape[i] <= 0) {
            lm_ctx_fail(c, LM_ERR_SHAPE, "reshape: invalid size %d at dim %d", shape[i], i);
            return NULL;
        } else known *= shape[i];
    }
    if (infer >= 0) s[infer] = known > 0 && n % known == 0 ? (int)(n / known) : 0;
    if (infer >= 0 ? s[infer] * known != n : known != n) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "reshape: %s (%ld elements) cannot be viewed with the "
                    "requested shape", lm_shape_str(x, sb, sizeof sb), n);
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_ctx_alloc(c, sizeof *y) : NULL;
    if (!y) return NULL;
    *y = *x;
    y->ndim = ndim;
    for (int i = 0; i < ndim; i++) y->shape[i] = s[i];
    ptrdiff_t st = 1;
    for (int i = ndim - 1; i >= 0; i--) {
        y->stride[i] = st;
        st *= s[i];
    }
    y->grad = NULL;
    y->flags = (x->flags & ~(unsigned)(LM_PARAM | LM_REQUIRES_GRAD)) | LM_VIEW;
    y->name = NULL;
    lm_record(c, "reshape", reshape_backward, y, &x, 1, NULL, 0);
    return y;
}

/* ---- slice ------------------------------------------------------------------------------- */
typedef struct slice_params { int dim, start; } slice_params;

/* The input's gradient restricted to the slice, as a strided view of x->grad. */
static lm_tensor slice_of(const lm_tensor *full, const lm_tensor *out, const slice_params *p)
{
    lm_tensor v = *full;
    for (int i = 0; i < out->ndim; i++) v.shape[i] = out->shape[i];
    if (full->device == LM_DEVICE_CPU) v.data = full->data + p->start * full->stride[p->dim];
    else v.dev_off = full->dev_off + (size_t)p->start * (size_t)full->stride[p->dim];
    return v;
}

static void slice_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *gx = lm_grad(c, x);
    if (!gx) return;
    lm_tensor v = slice_of(gx, n->out, n->params);
    lm_tensor *t[2] = {&v, n->out->grad};
    lm_kernel_run(c, &lm_kernel_strided_add, t, 2, NULL);
}

lm_tensor *lm_slice(lm_ctx *c, lm_tensor *x, int dim, int start, int len)
{
    if (!lm_check_inputs(c, "slice", 1, x)) return NULL;
    char sb[64];
    if (dim < 0) dim += x->ndim;
    if (dim < 0 || dim >= x->ndim || start < 0 || len <= 0 || start + len > x->shape[dim]) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "slice: [%d, %d) along dim %d is outside %s", start,
                    start + len, dim, lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    lm_tensor *y = lm_ctx_alloc(c, sizeof *y);
    if (!y) return NULL;
    *y = *x;
    y->shape[dim] = len;
    if (x->device == LM_DEVICE_CPU) y->data = x->data + start * x->stride[dim];
    else y->dev_off = x->dev_off + (size_t)start * (size_t)x->stride[dim]; /* device view */
    y->grad = NULL;
    y->flags = (x->flags & ~(unsigned)(LM_PARAM | LM_REQUIRES_GRAD)) | LM_VIEW;
    y->name = NULL;
    slice_params p = {dim, start};
    lm_record(c, "slice", slice_backward, y, &x, 1, &p, sizeof p);
    return y;
}

/* ---- contiguous -------------------------------------------------------------------------- */
static void contig_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_flat_add, t, 2, NULL); /* x's grad is contiguous */
}

lm_tensor *lm_contiguous(lm_ctx *c, lm_tensor *x)
{
    if (!lm_check_inputs(c, "contiguous", 1, x)) return NULL;
    if (lm_tensor_is_contiguous(x)) return x;
    lm_tensor *y = lm_tensor_new(c, x->ndim, x->shape);
    if (!y) return NULL;
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_strided_copy, t, 2, NULL)) return NULL;
    lm_record(c, "contiguous", contig_backward, y, &x, 1, NULL, 0);
    return y;
}
