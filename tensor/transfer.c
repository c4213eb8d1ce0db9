/* transfer.c — the recorded host<->device copies lm_tensor_to_device / lm_tensor_to_host
 * (device.h), for any device backend: copies through its write / read, the device-side add of
 * the backward through lm_grad_seed (its "flat_add" kernel). Forward copies data across;
 * backward copies the gradient back and adds it (+=) on the input's side, so the tape runs
 * across the boundary.
 * Not here: plain copies without the tape (lm_tensor_read / lm_tensor_write in tensor.c). */
#include "tensor/device.h"
#include "tensor/ops.h"

/* Host tensor (any strides) packed row-major into dst. */
static void pack_host(const lm_tensor *x, float *dst)
{
    int shape[LM_MAX_DIMS] = {1, 1, 1, 1, 1};
    ptrdiff_t st[LM_MAX_DIMS] = {0, 0, 0, 0, 0};
    for (int i = 0; i < x->ndim; i++) {
        shape[LM_MAX_DIMS - x->ndim + i] = x->shape[i];
        st[LM_MAX_DIMS - x->ndim + i] = x->stride[i];
    }
    long k = 0;
    for (int a = 0; a < shape[0]; a++)
        for (int b = 0; b < shape[1]; b++)
            for (int d = 0; d < shape[2]; d++)
                for (int e = 0; e < shape[3]; e++) {
                    const float *p = x->data + a * st[0] + b * st[1] + d * st[2] + e * st[3];
                    for (int f = 0; f < shape[4]; f++) dst[k++] = p[f * st[4]];
                }
}

/* ---- to_device ---------------------------------------------------------------------------- */
/* in[0]: host x; out: device copy. grad(x) (host, contiguous) += download(grad(out)). */
static void to_device_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *gx = lm_grad(c, x);
    if (!gx) return;
    long k = lm_tensor_numel(gx);
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *h = lm_ctx_alloc(c, (size_t)k * sizeof(float));
    if (h && lm_tensor_read(c, n->out->grad, h) == 0)
        for (long i = 0; i < k; i++) gx->data[i] += h[i];
    lm_arena_rewind(&c->arena, m);
}

lm_tensor *lm_tensor_to_device(lm_ctx *c, lm_tensor *x)
{
    if (!lm_check_inputs(c, "to_device", 1, x)) return NULL;
    if (x->device != LM_DEVICE_CPU) return x;
    if (c->backend->device == LM_DEVICE_CPU || !c->backend->write) {
        lm_ctx_fail(c, LM_ERR_ARG, "to_device: the ctx backend (%s) has no device",
                    c->backend->name);
        return NULL;
    }
    lm_tensor *y = lm_tensor_new(c, x->ndim, x->shape);
    if (!y) return NULL;
    if (lm_tensor_is_contiguous(x)) {
        if (lm_tensor_write(c, y, x->data)) return NULL;
    } else {
        lm_arena_mark m = lm_arena_get_mark(&c->arena);
        float *h = lm_ctx_alloc(c, (size_t)lm_tensor_numel(x) * sizeof(float));
        if (!h) return NULL;
        pack_host(x, h);
        int err = lm_tensor_write(c, y, h);
        lm_arena_rewind(&c->arena, m);
        if (err) return NULL;
    }
    lm_record(c, "to_device", to_device_backward, y, &x, 1, NULL, 0);
    return y;
}

/* ---- to_host ------------------------------------------------------------------------------ */
/* in[0]: device x (contiguous); out: host copy. grad(x) (device) += upload(grad(out)): the
 * seed rule of lm_grad_seed (host values uploaded, added by the backend's "flat_add"). */
static void to_host_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_grad_seed(c, x, n->out->grad);
}

lm_tensor *lm_tensor_to_host(lm_ctx *c, lm_tensor *x)
{
    if (!lm_check_inputs(c, "to_host", 1, x)) return NULL;
    if (x->device == LM_DEVICE_CPU) return x;
    if (x->device != c->backend->device) {
        lm_ctx_fail(c, LM_ERR_ARG, "to_host: tensor is not on the ctx's device");
        return NULL;
    }
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new_on(c, LM_DEVICE_CPU, x->ndim, x->shape) : NULL;
    if (!y || lm_tensor_read(c, x, y->data)) return NULL;
    lm_record(c, "to_host", to_host_backward, y, &x, 1, NULL, 0);
    return y;
}
