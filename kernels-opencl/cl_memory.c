/* cl_memory.c — device memory of the OpenCL backend: a per-ctx bump arena of big cl_mem blocks
 * (tensors are (block, element offset) pairs), reset with the ctx, plus blocking host<->device
 * copies of contiguous tensors.
 * Like the host arena (tensor/arena.c), a reset after a step that needed several blocks
 * replaces them with one block of the high-water size, so repeated steps allocate nothing.
 * Not here: kernels, transfers recorded on the tape (tensor/transfer.c). */
#include "kernels-opencl/cl_impl.h"
#include <limits.h>
#include <stdlib.h>
#include <string.h>

#define DEV_ALIGN 256                /* bytes; >= CL_DEVICE_MEM_BASE_ADDR_ALIGN of usual GPUs */
#define DEV_MIN_BLOCK ((size_t)16 << 20)

typedef struct dev_block {
    cl_mem mem;
    size_t cap, used;                /* bytes */
} dev_block;

typedef struct dev_arena {
    dev_block *blocks;
    int n, max, cur;
    size_t in_use, high_water;       /* bytes since the last reset */
    size_t max_block;                /* min(CL_DEVICE_MAX_MEM_ALLOC_SIZE, int indexing) */
} dev_arena;

static size_t round_up(size_t n, size_t a) { return (n + a - 1) / a * a; }

static dev_arena *arena_of(lm_cl *b, lm_ctx *c)
{
    if (c->dev_arena) return c->dev_arena;
    dev_arena *a = calloc(1, sizeof *a);
    if (!a) return NULL;
    cl_ulong max_alloc = 0;
    clGetDeviceInfo(b->device, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof max_alloc, &max_alloc, NULL);
    size_t int_limit = (size_t)INT_MAX / DEV_ALIGN * DEV_ALIGN * sizeof(float);
    a->max_block = max_alloc && max_alloc < int_limit ? (size_t)max_alloc : int_limit;
    c->dev_arena = a;
    return a;
}

static int add_block(lm_cl *b, lm_ctx *c, dev_arena *a, size_t cap)
{
    if (a->n == a->max) {
        int nm = a->max ? 2 * a->max : 8;
        dev_block *nb = realloc(a->blocks, (size_t)nm * sizeof *nb);
        if (!nb) return lm_ctx_fail(c, LM_ERR_NOMEM, "opencl: out of memory");
        a->blocks = nb;
        a->max = nm;
    }
    cl_int err;
    cl_mem m = clCreateBuffer(b->context, CL_MEM_READ_WRITE, cap, NULL, &err);
    if (err != CL_SUCCESS) {
        lm_ctx_fail(c, err == CL_INVALID_BUFFER_SIZE || err == CL_MEM_OBJECT_ALLOCATION_FAILURE
                           ? LM_ERR_NOMEM : LM_ERR_BACKEND,
                    "opencl: device buffer of %zu bytes: %s", cap, lm_cl_error_str(err));
        return c->status;
    }
    a->blocks[a->n].mem = m;
    a->blocks[a->n].cap = cap;
    a->blocks[a->n].used = 0;
    a->n++;
    return 0;
}

static void *cl_alloc(lm_backend *bb, lm_ctx *c, size_t bytes, size_t *off)
{
    lm_cl *b = bb->impl;
    dev_arena *a = arena_of(b, c);
    if (!a) {
        lm_ctx_fail(c, LM_ERR_NOMEM, "opencl: out of memory");
        return NULL;
    }
    size_t need = round_up(bytes ? bytes : 1, DEV_ALIGN);
    if (need > a->max_block) {
        lm_ctx_fail(c, LM_ERR_NOMEM, "opencl: tensor of %zu bytes exceeds the device's largest "
                    "buffer (%zu bytes)", bytes, a->max_block);
        return NULL;
    }
    while (a->cur < a->n && a->blocks[a->cur].cap - a->blocks[a->cur].used < need) {
        if (a->cur + 1 >= a->n) break;
        a->blocks[++a->cur].used = 0;
    }
    if (a->cur >= a->n || a->blocks[a->cur].cap - a->blocks[a->cur].used < need) {
        size_t cap = need > DEV_MIN_BLOCK ? need : DEV_MIN_BLOCK;
        if (cap > a->max_block) cap = a->max_block;
        if (add_block(b, c, a, cap)) return NULL;
        a->cur = a->n - 1;
    }
    dev_block *k = &a->blocks[a->cur];
    *off = k->used / sizeof(float);
    k->used += need;
    a->in_use += need;
    if (a->in_use > a->high_water) a->high_water = a->in_use;
    return k->mem;
}

static void free_blocks(dev_arena *a)
{
    for (int i = 0; i < a->n; i++) clReleaseMemObject(a->blocks[i].mem);
    a->n = 0;
    a->cur = 0;
}

/* Empty the arena; several blocks become one of the high-water size (when it fits one buffer).
 * Kernels still queued keep their buffers alive: clReleaseMemObject defers the free. */
static void cl_reset(lm_backend *bb, lm_ctx *c)
{
    dev_arena *a = c->dev_arena;
    if (!a) return;
    if (a->n > 1) {
        size_t total = 0;
        for (int i = 0; i < a->n; i++) total += a->blocks[i].cap;
        if (a->high_water > total) total = a->high_water;
        if (total <= a->max_block) {
            free_blocks(a);
            lm_status keep = c->status;
            if (add_block(bb->impl, c, a, round_up(total, DEV_ALIGN)) && keep == LM_OK)
                lm_ctx_clear_error(c); /* the next allocation retries and reports */
        }
    }
    for (int i = 0; i < a->n; i++) a->blocks[i].used = 0;
    a->cur = 0;
    a->in_use = 0;
    a->high_water = 0;
}

static void cl_release(lm_backend *bb, lm_ctx *c)
{
    (void)bb;
    dev_arena *a = c->dev_arena;
    if (!a) return;
    free_blocks(a);
    free(a->blocks);
    free(a);
    c->dev_arena = NULL;
}

static int cl_write(lm_backend *bb, lm_ctx *c, lm_tensor *t, const float *src)
{
    lm_cl *b = bb->impl;
    size_t n = (size_t)lm_tensor_numel(t);
    cl_int err = clEnqueueWriteBuffer(b->queue, (cl_mem)t->dev, CL_TRUE,
                                      t->dev_off * sizeof(float), n * sizeof(float), src, 0,
                                      NULL, NULL);
    return err == CL_SUCCESS ? 0 : lm_cl_fail(c, err, "clEnqueueWriteBuffer", NULL);
}

static int cl_read(lm_backend *bb, lm_ctx *c, const lm_tensor *t, float *dst)
{
    lm_cl *b = bb->impl;
    size_t n = (size_t)lm_tensor_numel(t);
    cl_int err = clEnqueueReadBuffer(b->queue, (cl_mem)t->dev, CL_TRUE,
                                     t->dev_off * sizeof(float), n * sizeof(float), dst, 0,
                                     NULL, NULL);
    return err == CL_SUCCESS ? 0 : lm_cl_fail(c, err, "clEnqueueReadBuffer", NULL);
}

void lm_cl_memory_install(lm_backend *b)
{
    b->alloc = cl_alloc;
    b->reset = cl_reset;
    b->release = cl_release;
    b->write = cl_write;
    b->read = cl_read;
}
