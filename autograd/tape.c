/* tape.c — the backward walk. Small on purpose: seed, walk newest-first, call, done. */
#include "autograd/autograd.h"
#include <string.h>

/* Gradient buffer reuse. Once a node's backward has run, the gradient of its output is dead
 * (every consumer of that output is newer on the tape and has already run), so its buffer goes
 * to a pool that lm_grad draws from: the peak memory of a backward is the saved activations
 * plus the gradients alive at once, not plus every intermediate gradient. Kept: the root's
 * gradient, parameters' (they live outside the arena), leaves' (never a node output), device
 * tensors', and any tensor that is the output of two nodes (checked, never expected). After
 * lm_backward, intermediate tensors' grad is NULL. The pool lives for one lm_backward, so its
 * arena buffers cannot outlive a rewind or reset. */
#define VISITED (1u << 30) /* temporary flags of lm_tensor (tensor.h uses the low bits) */
#define SHARED (1u << 31)

int lm_backward_set_grad_reuse(lm_ctx *c, int on)
{
    int old = c->grad_reuse;
    c->grad_reuse = on;
    return old;
}

static void pool_begin(lm_ctx *c, lm_grad_pool *p)
{
    if (!c->grad_reuse) return;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    p->data = lm_arena_alloc(&c->arena, sizeof *p->data * (size_t)(c->tape_len + 1));
    p->cap = p->data ? lm_arena_alloc(&c->arena, sizeof *p->cap * (size_t)(c->tape_len + 1)) : NULL;
    if (!p->cap) { /* no reuse then: lm_grad allocates as before */
        lm_arena_rewind(&c->arena, m);
        return;
    }
    for (lm_node *nd = c->tape; nd; nd = nd->prev) {
        if (nd->out->flags & VISITED) nd->out->flags |= SHARED;
        nd->out->flags |= VISITED;
    }
    p->max = (int)c->tape_len + 1;
    c->grad_pool = p;
}

static void release_grad(lm_grad_pool *p, lm_node *nd, const lm_tensor *root)
{
    lm_tensor *t = nd->out, *g = t->grad;
    if (!p->max || t == root || (t->flags & (LM_PARAM | SHARED)) || !g ||
        g->device != LM_DEVICE_CPU || !g->data || p->n == p->max)
        return;
    p->data[p->n] = g->data;
    p->cap[p->n] = lm_tensor_numel(g);
    p->n++;
    t->grad = NULL;
}

static void pool_end(lm_ctx *c)
{
    if (!c->grad_pool) return;
    for (lm_node *nd = c->tape; nd; nd = nd->prev) nd->out->flags &= ~(unsigned)(VISITED | SHARED);
    c->grad_pool = NULL;
}

lm_status lm_backward(lm_ctx *c, lm_tensor *out, const lm_tensor *seed)
{
    if (c->status) return c->status;
    if (!out) return lm_ctx_fail(c, LM_ERR_ARG, "backward: output is NULL");
    if (!lm_requires_grad(out))
        return lm_ctx_fail(c, LM_ERR_ARG, "backward: output does not require grad "
                                          "(no input requires grad, or grad mode was off)");
    if (seed && !lm_tensor_same_shape(seed, out)) {
        char a[64], b[64];
        return lm_ctx_fail(c, LM_ERR_SHAPE, "backward: seed %s does not match output %s",
                           lm_shape_str(seed, a, sizeof a), lm_shape_str(out, b, sizeof b));
    }
    if (lm_grad_seed(c, out, seed) != LM_OK) return c->status;
    int was = lm_ctx_set_grad(c, 0); /* backward itself records nothing */
    lm_grad_pool pool = {0};
    pool_begin(c, &pool);
    for (lm_node *nd = c->tape; nd && !c->status; nd = nd->prev) {
        if (!nd->out->grad) continue;
        nd->backward(c, nd);
        release_grad(&pool, nd, out);
    }
    pool_end(c);
    lm_ctx_set_grad(c, was);
    return c->status;
}

void lm_tape_clear(lm_ctx *c)
{
    for (lm_node *nd = c->tape; nd; nd = nd->prev) {
        if (!(nd->out->flags & LM_PARAM)) nd->out->grad = NULL;
        for (int i = 0; i < nd->nin; i++)
            if (nd->in[i] && !(nd->in[i]->flags & LM_PARAM)) nd->in[i]->grad = NULL;
    }
}
