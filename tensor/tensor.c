/* tensor.c — context, tensor creation, kernel dispatch and tape recording.
 * Not here: the backward walk (autograd/tape.c) and the ops (tensor/ops/). */
#include "tensor/tensor.h"
#include "tensor/op_list.h"
#include "tensor/ops/wcache.h"
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

extern void openblas_set_num_threads(int num_threads);

static lm_backend cpu_backend = {.name = "cpu", .device = LM_DEVICE_CPU};

lm_backend *lm_backend_cpu(void) { return &cpu_backend; }

int lm_ctx_init(lm_ctx *c, int nthreads)
{
    memset(c, 0, sizeof *c);
    if (nthreads > LM_MAX_THREADS) return LM_ERR_ARG;
    if (lm_arena_init(&c->arena, 0) != 0) return LM_ERR_NOMEM;
    c->grad_enabled = 1;
    c->grad_reuse = 1;
    c->nthreads = nthreads > 0 ? nthreads : omp_get_num_procs();
    c->backend = &cpu_backend;
    /* Our kernels parallelise with OpenMP and call BLAS from inside parallel regions or on
     * per-thread slices, so BLAS itself runs single-threaded (no oversubscription, and the
     * same numbers for the same thread count). */
    openblas_set_num_threads(1);
    return LM_OK;
}

void lm_ctx_free(lm_ctx *c)
{
    if (c->backend && c->backend->release) c->backend->release(c->backend, c);
    lm_wcache_free(c);
    lm_arena_free(&c->arena);
    memset(c, 0, sizeof *c);
}

void lm_ctx_reset(lm_ctx *c)
{
    c->tape = NULL;
    c->tape_len = 0;
    lm_arena_reset(&c->arena);
    if (c->backend->reset) c->backend->reset(c->backend, c);
}

void lm_ctx_set_backend(lm_ctx *c, lm_backend *b)
{
    if (!b) b = &cpu_backend;
    if (b == c->backend) return;
    if (c->backend->release) c->backend->release(c->backend, c);
    c->dev_arena = NULL;
    c->backend = b;
}

lm_status lm_ctx_fail(lm_ctx *c, lm_status s, const char *fmt, ...)
{
    if (c->status != LM_OK) return s; /* keep the first error */
    c->status = s;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->msg, sizeof c->msg, fmt, ap);
    va_end(ap);
    return s;
}

void lm_ctx_clear_error(lm_ctx *c)
{
    c->status = LM_OK;
    c->msg[0] = 0;
}

int lm_ctx_set_grad(lm_ctx *c, int enabled)
{
    int old = c->grad_enabled;
    c->grad_enabled = enabled;
    return old;
}

void *lm_ctx_alloc(lm_ctx *c, size_t bytes)
{
    void *p = lm_arena_alloc(&c->arena, bytes);
    if (!p) lm_ctx_fail(c, LM_ERR_NOMEM, "out of memory allocating %zu bytes", bytes);
    return p;
}

/* ---- scopes ---------------------------------------------------------------------------- */
lm_scope lm_scope_begin(lm_ctx *c)
{
    lm_scope s;
    s.mark = lm_arena_get_mark(&c->arena);
    s.tape = c->tape;
    s.tape_len = c->tape_len;
    return s;
}

/* Was ptr handed out after mark m? */
static int allocated_after(const lm_arena *a, lm_arena_mark m, const void *ptr)
{
    const unsigned char *p = ptr;
    for (int b = m.block; b <= a->cur && b < a->nblocks; b++) {
        const unsigned char *lo = a->blocks[b].mem + (b == m.block ? m.used : 0);
        if (p >= lo && p < a->blocks[b].mem + a->blocks[b].used) return 1;
    }
    return 0;
}

lm_tensor *lm_scope_end(lm_ctx *c, lm_scope s, lm_tensor *keep)
{
    if (c->grad_enabled || c->tape != s.tape || !keep || keep->device != LM_DEVICE_CPU)
        return keep;
    if (!allocated_after(&c->arena, s.mark, keep->data)) {
        lm_arena_rewind(&c->arena, s.mark); /* keep lives outside the scope: nothing to move */
        return keep;
    }
    if (!lm_tensor_is_contiguous(keep)) {
        lm_ctx_fail(c, LM_ERR_ARG, "lm_scope_end: kept tensor must be contiguous");
        return NULL;
    }
    lm_tensor k = *keep;
    size_t bytes = (size_t)lm_tensor_numel(keep) * sizeof(float);
    lm_arena_rewind(&c->arena, s.mark);
    /* The data is moved first (memmove handles the overlap), then the struct is placed after
     * it, so nothing is overwritten before it is copied. */
    float *d = lm_arena_alloc(&c->arena, bytes);
    if (d) memmove(d, k.data, bytes);
    lm_tensor *t = d ? lm_arena_alloc(&c->arena, sizeof *t) : NULL;
    if (!t) {
        lm_ctx_fail(c, LM_ERR_NOMEM, "out of memory in scope end");
        return NULL;
    }
    *t = k;
    t->data = d;
    t->grad = NULL;
    return t;
}

/* ---- tensors --------------------------------------------------------------------------- */
long lm_tensor_numel(const lm_tensor *t)
{
    long n = 1;
    for (int i = 0; i < t->ndim; i++) n *= t->shape[i];
    return n;
}

static void set_contiguous_strides(lm_tensor *t)
{
    ptrdiff_t s = 1;
    for (int i = t->ndim - 1; i >= 0; i--) {
        t->stride[i] = s;
        s *= t->shape[i];
    }
}

int lm_tensor_is_contiguous(const lm_tensor *t)
{
    ptrdiff_t s = 1;
    for (int i = t->ndim - 1; i >= 0; i--) {
        if (t->shape[i] != 1 && t->stride[i] != s) return 0;
        s *= t->shape[i];
    }
    return 1;
}

int lm_tensor_same_shape(const lm_tensor *a, const lm_tensor *b)
{
    if (a->ndim != b->ndim) return 0;
    for (int i = 0; i < a->ndim; i++)
        if (a->shape[i] != b->shape[i]) return 0;
    return 1;
}

const char *lm_shape_str(const lm_tensor *t, char *buf, size_t n)
{
    size_t o = 0;
    buf[0] = 0;
    if (!t) {
        snprintf(buf, n, "(null)");
        return buf;
    }
    for (int i = 0; i < t->ndim && o < n; i++)
        o += (size_t)snprintf(buf + o, n - o, i ? "x%d" : "%d", t->shape[i]);
    if (t->ndim == 0) snprintf(buf, n, "scalar");
    return buf;
}

void lm_tensor_set_requires_grad(lm_tensor *t, int on)
{
    if (on) t->flags |= LM_REQUIRES_GRAD;
    else t->flags &= ~(unsigned)LM_REQUIRES_GRAD;
}

void lm_tensor_wrap(lm_tensor *t, float *data, int ndim, const int *shape)
{
    memset(t, 0, sizeof *t);
    t->data = data;
    t->ndim = ndim;
    for (int i = 0; i < ndim; i++) t->shape[i] = shape[i];
    set_contiguous_strides(t);
}

/* A contiguous tensor in the ctx's device arena (no host memory: data is NULL). */
static lm_tensor *device_tensor_new(lm_ctx *c, lm_device dev, int ndim, const int *shape, long n)
{
    if (dev != c->backend->device || !c->backend->alloc) {
        lm_ctx_fail(c, LM_ERR_UNSUPPORTED, "backend %s cannot allocate tensors on device %d",
                    c->backend->name, (int)dev);
        return NULL;
    }
    lm_tensor *t = lm_ctx_alloc(c, sizeof *t);
    if (!t) return NULL;
    size_t off = 0;
    void *buf = c->backend->alloc(c->backend, c, (size_t)n * sizeof(float), &off);
    if (!buf) return NULL;
    lm_tensor_wrap(t, NULL, ndim, shape);
    t->dev = buf;
    t->dev_off = off;
    t->device = dev;
    return t;
}

lm_tensor *lm_tensor_new(lm_ctx *c, int ndim, const int *shape)
{
    return lm_tensor_new_on(c, c->backend->device, ndim, shape);
}

lm_tensor *lm_tensor_new_on(lm_ctx *c, lm_device dev, int ndim, const int *shape)
{
    if (c->status) return NULL;
    if (ndim < 0 || ndim > LM_MAX_DIMS) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "tensor of %d dimensions (at most %d)", ndim, LM_MAX_DIMS);
        return NULL;
    }
    long n = 1;
    for (int i = 0; i < ndim; i++) {
        if (shape[i] <= 0) {
            lm_ctx_fail(c, LM_ERR_SHAPE, "tensor dimension %d has size %d (must be > 0)", i,
                        shape[i]);
            return NULL;
        }
        n *= shape[i];
    }
    if (dev != LM_DEVICE_CPU) return device_tensor_new(c, dev, ndim, shape, n);
    lm_tensor *t = lm_ctx_alloc(c, sizeof *t);
    float *d = t ? lm_ctx_alloc(c, (size_t)n * sizeof(float)) : NULL;
    if (!d) return NULL;
    lm_tensor_wrap(t, d, ndim, shape);
    return t;
}

int lm_tensor_read(lm_ctx *c, const lm_tensor *t, float *dst)
{
    if (c->status) return c->status;
    if (!lm_tensor_is_contiguous(t))
        return lm_ctx_fail(c, LM_ERR_ARG, "lm_tensor_read: tensor must be contiguous");
    if (t->device == LM_DEVICE_CPU) {
        memcpy(dst, t->data, (size_t)lm_tensor_numel(t) * sizeof(float));
        return 0;
    }
    if (t->device != c->backend->device || !c->backend->read)
        return lm_ctx_fail(c, LM_ERR_ARG, "lm_tensor_read: tensor is not on the ctx's device");
    return c->backend->read(c->backend, c, t, dst);
}

int lm_tensor_write(lm_ctx *c, lm_tensor *t, const float *src)
{
    if (c->status) return c->status;
    if (!lm_tensor_is_contiguous(t))
        return lm_ctx_fail(c, LM_ERR_ARG, "lm_tensor_write: tensor must be contiguous");
    if (t->device == LM_DEVICE_CPU) {
        memcpy(t->data, src, (size_t)lm_tensor_numel(t) * sizeof(float));
        return 0;
    }
    if (t->device != c->backend->device || !c->backend->write)
        return lm_ctx_fail(c, LM_ERR_ARG, "lm_tensor_write: tensor is not on the ctx's device");
    return c->backend->write(c->backend, c, t, src);
}

lm_tensor *lm_tensor_new_like(lm_ctx *c, const lm_tensor *t)
{
    return t ? lm_tensor_new(c, t->ndim, t->shape) : NULL;
}

void lm_tensor_fill(lm_tensor *t, float v)
{
    long n = lm_tensor_numel(t);
    if (v == 0.0f) {
        memset(t->data, 0, (size_t)n * sizeof(float));
        return;
    }
    for (long i = 0; i < n; i++) t->data[i] = v;
}

lm_tensor *lm_tensor_zeros(lm_ctx *c, int ndim, const int *shape)
{
    return lm_tensor_full(c, ndim, shape, 0.0f);
}

/* Large fills (gradient buffers zeroed at the start of every backward) are split over the
 * threads: one core writing a 4 MB buffer alone left the other idle for ~5 % of a MCAN step. */
#define FILL_PARALLEL_MIN (1L << 18)
static int fill_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    long n = lm_tensor_numel(t[0]);
    int nth = lm_nthreads(c);
    if (n < FILL_PARALLEL_MIN || nth < 2) {
        lm_tensor_fill(t[0], *(const float *)params);
        return 0;
    }
    float v = *(const float *)params, *d = t[0]->data;
#pragma omp parallel num_threads(nth)
    {
        int me = omp_get_thread_num(), k = omp_get_num_threads();
        long a = n * me / k, b = n * (me + 1) / k;
        if (v == 0.0f) memset(d + a, 0, (size_t)(b - a) * sizeof(float));
        else
            for (long i = a; i < b; i++) d[i] = v;
    }
    return 0;
}
LM_KERNEL(fill, fill_cpu);

lm_tensor *lm_tensor_full(lm_ctx *c, int ndim, const int *shape, float v)
{
    lm_tensor *t = lm_tensor_new(c, ndim, shape);
    if (t && t->device == LM_DEVICE_CPU) lm_tensor_fill(t, v);
    else if (t && lm_kernel_run(c, &lm_kernel_fill, &t, 1, &v)) return NULL;
    return t;
}

lm_tensor *lm_tensor_from(lm_ctx *c, int ndim, const int *shape, const float *src)
{
    lm_tensor *t = lm_tensor_new(c, ndim, shape);
    if (t && lm_tensor_write(c, t, src)) return NULL;
    return t;
}

/* Random tensor: drawn on the host (device tensors through an arena scratch copy). */
static lm_tensor *random_tensor(lm_ctx *c, int ndim, const int *shape, lm_rng *r, int normal,
                                float a, float b)
{
    lm_tensor *t = lm_tensor_new(c, ndim, shape);
    if (!t) return NULL;
    long n = lm_tensor_numel(t);
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *h = t->device == LM_DEVICE_CPU ? t->data : lm_ctx_alloc(c, (size_t)n * sizeof(float));
    if (!h) return NULL;
    if (normal) lm_rng_fill_normal(r, h, n, a, b);
    else lm_rng_fill_uniform(r, h, n, a, b);
    int err = h != t->data ? lm_tensor_write(c, t, h) : 0;
    if (h != t->data) lm_arena_rewind(&c->arena, m);
    return err ? NULL : t;
}

lm_tensor *lm_tensor_uniform(lm_ctx *c, int ndim, const int *shape, lm_rng *r, float lo, float hi)
{
    return random_tensor(c, ndim, shape, r, 0, lo, hi);
}

lm_tensor *lm_tensor_normal(lm_ctx *c, int ndim, const int *shape, lm_rng *r, float mean, float std)
{
    return random_tensor(c, ndim, shape, r, 1, mean, std);
}

lm_tensor *lm_tensor_new1(lm_ctx *c, int d0) { return lm_tensor_new(c, 1, &d0); }
lm_tensor *lm_tensor_new2(lm_ctx *c, int d0, int d1)
{
    int s[2] = {d0, d1};
    return lm_tensor_new(c, 2, s);
}
lm_tensor *lm_tensor_new3(lm_ctx *c, int d0, int d1, int d2)
{
    int s[3] = {d0, d1, d2};
    return lm_tensor_new(c, 3, s);
}
lm_tensor *lm_tensor_new4(lm_ctx *c, int d0, int d1, int d2, int d3)
{
    int s[4] = {d0, d1, d2, d3};
    return lm_tensor_new(c, 4, s);
}

/* ---- kernels --------------------------------------------------------------------------- */
int lm_kernel_run(lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt, const void *params)
{
    if (c->status) return c->status;
    if (c->backend->run) return c->backend->run(c->backend, c, k, t, nt, params);
    return k->cpu(c, t, nt, params);
}

/* ---- op helpers ------------------------------------------------------------------------ */
int lm_check_inputs(lm_ctx *c, const char *op, int n, ...)
{
    if (c->status) return 0;
    va_list ap;
    va_start(ap, n);
    int ok = 1;
    for (int i = 0; i < n; i++) {
        if (va_arg(ap, const lm_tensor *) == NULL) {
            lm_ctx_fail(c, LM_ERR_ARG, "%s: input %d is NULL", op, i);
            ok = 0;
            break;
        }
    }
    va_end(ap);
    return ok;
}

/* A host gradient for t from the buffers released so far in this backward (the smallest one
 * that fits), or NULL. */
static lm_tensor *grad_from_pool(lm_ctx *c, const lm_tensor *t)
{
    lm_grad_pool *p = c->grad_pool;
    long n = lm_tensor_numel(t);
    int best = -1;
    for (int i = 0; i < p->n; i++)
        if (p->cap[i] >= n && (best < 0 || p->cap[i] < p->cap[best])) best = i;
    if (best < 0) return NULL;
    lm_tensor *g = lm_ctx_alloc(c, sizeof *g);
    if (!g) return NULL;
    lm_tensor_wrap(g, p->data[best], t->ndim, t->shape);
    p->n--;
    p->data[best] = p->data[p->n];
    p->cap[best] = p->cap[p->n];
    return g;
}

lm_tensor *lm_grad(lm_ctx *c, lm_tensor *t)
{
    if (t->grad) return t->grad;
    lm_tensor *g = NULL;
    if (c->grad_pool && t->device == LM_DEVICE_CPU) g = grad_from_pool(c, t);
    if (!g) g = lm_tensor_new_on(c, t->device, t->ndim, t->shape);
    if (!g) return NULL;
    float zero = 0.0f;
    lm_tensor *a[1] = {g};
    lm_kernel_run(c, &lm_kernel_fill, a, 1, &zero);
    t->grad = g;
    return g;
}

lm_status lm_grad_seed(lm_ctx *c, lm_tensor *out, const lm_tensor *seed)
{
    lm_tensor *g = lm_grad(c, out);
    if (!g) return c->status;
    long n = lm_tensor_numel(g);
    if (g->device == LM_DEVICE_CPU && seed && seed->device != LM_DEVICE_CPU)
        return lm_ctx_fail(c, LM_ERR_ARG, "backward: seed on the device, output on the host");
    if (g->device == LM_DEVICE_CPU) {
        for (long i = 0; i < n; i++) g->data[i] += seed ? seed->data[i] : 1.0f;
        return LM_OK;
    }
    lm_tensor *s = (lm_tensor *)seed;
    if (!seed || seed->device == LM_DEVICE_CPU) { /* host values -> device copy */
        s = lm_tensor_new_on(c, g->device, g->ndim, g->shape);
        if (!s) return c->status;
        if (seed) lm_tensor_write(c, s, seed->data);
        else {
            float one = 1.0f;
            lm_kernel_run(c, &lm_kernel_fill, &s, 1, &one);
        }
    }
    lm_tensor *t[2] = {g, s};
    lm_kernel_run(c, &lm_kernel_flat_add, t, 2, NULL); /* g += s (tensor/ops/view.c) */
    return c->status;
}

lm_node *lm_record(lm_ctx *c, const char *op, lm_backward_fn bw, lm_tensor *out,
                   lm_tensor *const *in, int nin, const void *params, size_t params_size)
{
    if (!c->grad_enabled || !out || c->status) return NULL;
    int any = 0;
    for (int i = 0; i < nin; i++) any |= lm_requires_grad(in[i]);
    if (!any) return NULL;
    if (nin > LM_MAX_INPUTS) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: %d inputs recorded (at most %d)", op, nin, LM_MAX_INPUTS);
        return NULL;
    }
    lm_node *n = lm_ctx_alloc(c, sizeof *n);
    if (!n) return NULL;
    memset(n, 0, sizeof *n);
    if (params_size) {
        n->params = lm_ctx_alloc(c, params_size);
        if (!n->params) return NULL;
        memcpy(n->params, params, params_size);
    }
    n->backward = bw;
    n->op = op;
    n->out = out;
    n->nin = nin;
    for (int i = 0; i < nin; i++) n->in[i] = in[i];
    out->flags |= LM_REQUIRES_GRAD;
    n->prev = c->tape;
    c->tape = n;
    c->tape_len++;
    return n;
}
