/* tape.c — the backward walk. Small on purpose: seed, walk newest-first, call, done. */
#include "autograd/autograd.h"
#include <string.h>

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
    for (lm_node *nd = c->tape; nd && !c->status; nd = nd->prev) {
        if (nd->out->grad) nd->backward(c, nd);
    }
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
