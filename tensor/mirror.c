/* mirror.c — model parameters on the device for one step (device.h), for any device backend:
 * persistent host tensors swapped in place for device copies, and their device gradients added
 * back into the host gradients (so the optimizer keeps running on the host's contiguous
 * parameter block).
 * The copies are views into one device block (one upload) and their gradients views into one
 * zero-filled device gradient block (one download), at the same 16-float-aligned offsets: a
 * model has a hundred small parameters and each transfer costs a queue round trip.
 * Not here: recorded transfers of activations (transfer.c). */
#include "tensor/device.h"
#include <string.h>

/* Offsets (floats) of each tensor in the blocks; returns the block size. */
static long layout(lm_tensor *const *ts, int n, long *off)
{
    long total = 0;
    for (int i = 0; i < n; i++) {
        if (off) off[i] = total;
        total += (lm_tensor_numel(ts[i]) + 15) / 16 * 16;
    }
    return total > 0 ? total : 16;
}

/* A contiguous view of `numel(like)` floats at element offset off of device tensor blk. */
static void view_of(lm_tensor *v, const lm_tensor *blk, const lm_tensor *like, long off)
{
    lm_tensor_wrap(v, NULL, like->ndim, like->shape);
    v->dev = blk->dev;
    v->dev_off = blk->dev_off + (size_t)off;
    v->device = blk->device;
}

static lm_status check_host(lm_ctx *c, lm_tensor *const *ts, int n)
{
    for (int i = 0; i < n; i++)
        if (ts[i]->device != LM_DEVICE_CPU || !lm_tensor_is_contiguous(ts[i]))
            return lm_ctx_fail(c, LM_ERR_ARG, "swap_to_device: tensor %d (%s) is not a "
                               "contiguous host tensor", i, ts[i]->name ? ts[i]->name : "unnamed");
    return LM_OK;
}

lm_status lm_tensors_swap_to_device(lm_ctx *c, lm_tensor *const *ts, int n, lm_tensor *saved)
{
    for (int i = 0; i < n; i++) saved[i] = *ts[i];
    if (c->status || c->backend->device == LM_DEVICE_CPU || n <= 0) return c->status;
    if (check_host(c, ts, n)) return c->status;
    long *off = lm_ctx_alloc(c, (size_t)n * sizeof *off);
    if (!off) return c->status;
    int total = (int)layout(ts, n, off);
    lm_tensor *blk = lm_tensor_new1(c, total), *gblk = lm_tensor_zeros(c, 1, &total);
    lm_tensor *views = lm_ctx_alloc(c, (size_t)n * sizeof *views);
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *h = blk && gblk && views ? lm_ctx_alloc(c, (size_t)total * sizeof(float)) : NULL;
    if (!h) return c->status;
    memset(h, 0, (size_t)total * sizeof(float));
    for (int i = 0; i < n; i++)
        memcpy(h + off[i], ts[i]->data, (size_t)lm_tensor_numel(ts[i]) * sizeof(float));
    int err = lm_tensor_write(c, blk, h);
    lm_arena_rewind(&c->arena, m);
    if (err) return c->status;
    for (int i = 0; i < n; i++) {
        lm_tensor *t = ts[i];
        unsigned rg = t->flags & LM_REQUIRES_GRAD;
        const char *name = t->name;
        view_of(&views[i], gblk, t, off[i]);
        view_of(t, blk, &saved[i], off[i]);
        t->flags = rg;
        t->name = name;
        t->grad = rg ? &views[i] : NULL;
    }
    return c->status;
}

/* The whole gradient block, found from the first swapped tensor with a gradient view. */
static int grad_block(lm_tensor *const *ts, int n, const long *off, long total, lm_tensor *blk)
{
    for (int i = 0; i < n; i++) {
        if (!ts[i]->grad) continue;
        int len = (int)total;
        lm_tensor_wrap(blk, NULL, 1, &len);
        blk->dev = ts[i]->grad->dev;
        blk->dev_off = ts[i]->grad->dev_off - (size_t)off[i];
        blk->device = ts[i]->grad->device;
        return 1;
    }
    return 0;
}

lm_status lm_tensors_swap_back(lm_ctx *c, lm_tensor *const *ts, int n, const lm_tensor *saved)
{
    int on_dev = n > 0 && ts[0]->device != LM_DEVICE_CPU;
    long total = layout(ts, n, NULL);
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    long *off = on_dev && !c->status ? lm_ctx_alloc(c, (size_t)n * sizeof *off) : NULL;
    float *h = off ? lm_ctx_alloc(c, (size_t)total * sizeof(float)) : NULL;
    lm_tensor blk;
    if (h) layout(ts, n, off);
    if (h && grad_block(ts, n, off, total, &blk) && lm_tensor_read(c, &blk, h) == 0)
        for (int i = 0; i < n; i++) {
            if (!ts[i]->grad || !saved[i].grad) continue;
            float *gd = saved[i].grad->data;
            long k = lm_tensor_numel(&saved[i]);
            for (long j = 0; j < k; j++) gd[j] += h[off[i] + j];
        }
    lm_arena_rewind(&c->arena, m);
    for (int i = 0; i < n; i++) *ts[i] = saved[i];
    return c->status;
}
