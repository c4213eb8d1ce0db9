/* op_table.c — the CPU kernel set, generated from LM_OP_LIST (tensor/op_list.h): every kernel
 * object by list index and by name. A name of the list without its LM_KERNEL definition fails
 * to link here.
 * Not here: the kernels (tensor.c, ops/), the OpenCL launcher table (kernels-opencl/). */
#include "tensor/op_list.h"
#include <string.h>

#define LM_KERNEL_REF(name) &lm_kernel_##name,
static const lm_kernel *const cpu_kernels[LM_OP_COUNT] = {LM_OP_LIST(LM_KERNEL_REF)};
#undef LM_KERNEL_REF

const lm_kernel *lm_kernel_at(int id)
{
    return id >= 0 && id < LM_OP_COUNT ? cpu_kernels[id] : NULL;
}

const lm_kernel *lm_kernel_find(const char *name)
{
    for (int i = 0; name && i < LM_OP_COUNT; i++)
        if (cpu_kernels[i] && !strcmp(cpu_kernels[i]->name, name)) return cpu_kernels[i];
    return NULL;
}
