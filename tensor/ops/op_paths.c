/* op_paths.c — the fast / reference switch of op_paths.h, a field of the context. */
#include "tensor/ops/op_paths.h"

int lm_op_set_path(lm_ctx *c, int path)
{
    int old = c->op_path;
    c->op_path = path;
    return old;
}

int lm_op_path(const lm_ctx *c) { return c->op_path; }
