/* op_paths.c — the process-wide fast / reference switch of op_paths.h. */
#include "tensor/ops/op_paths.h"

static int op_path = LM_OP_PATH_FAST;

int lm_op_set_path(int path)
{
    int old = op_path;
    op_path = path;
    return old;
}

int lm_op_path(void) { return op_path; }
