/* cl_launch.c — what every typed launcher uses: kernel lookup, argument setting with the first
 * error kept, NDRange enqueue, OpenCL error text.
 * Not here: the launchers (cl_ops_*.c). */
#include "kernels-opencl/cl_impl.h"
#include <stdio.h>
#include <string.h>

const char *lm_cl_error_str(cl_int err)
{
    switch (err) {
    case CL_SUCCESS: return "CL_SUCCESS";
    case CL_DEVICE_NOT_FOUND: return "CL_DEVICE_NOT_FOUND";
    case CL_DEVICE_NOT_AVAILABLE: return "CL_DEVICE_NOT_AVAILABLE";
    case CL_COMPILER_NOT_AVAILABLE: return "CL_COMPILER_NOT_AVAILABLE";
    case CL_MEM_OBJECT_ALLOCATION_FAILURE: return "CL_MEM_OBJECT_ALLOCATION_FAILURE";
    case CL_OUT_OF_RESOURCES: return "CL_OUT_OF_RESOURCES";
    case CL_OUT_OF_HOST_MEMORY: return "CL_OUT_OF_HOST_MEMORY";
    case CL_BUILD_PROGRAM_FAILURE: return "CL_BUILD_PROGRAM_FAILURE";
    case CL_INVALID_VALUE: return "CL_INVALID_VALUE";
    case CL_INVALID_PLATFORM: return "CL_INVALID_PLATFORM";
    case CL_INVALID_DEVICE: return "CL_INVALID_DEVICE";
    case CL_INVALID_CONTEXT: return "CL_INVALID_CONTEXT";
    case CL_INVALID_COMMAND_QUEUE: return "CL_INVALID_COMMAND_QUEUE";
    case CL_INVALID_MEM_OBJECT: return "CL_INVALID_MEM_OBJECT";
    case CL_INVALID_BUILD_OPTIONS: return "CL_INVALID_BUILD_OPTIONS";
    case CL_INVALID_PROGRAM: return "CL_INVALID_PROGRAM";
    case CL_INVALID_PROGRAM_EXECUTABLE: return "CL_INVALID_PROGRAM_EXECUTABLE";
    case CL_INVALID_KERNEL_NAME: return "CL_INVALID_KERNEL_NAME";
    case CL_INVALID_KERNEL: return "CL_INVALID_KERNEL";
    case CL_INVALID_ARG_INDEX: return "CL_INVALID_ARG_INDEX";
    case CL_INVALID_ARG_VALUE: return "CL_INVALID_ARG_VALUE";
    case CL_INVALID_ARG_SIZE: return "CL_INVALID_ARG_SIZE";
    case CL_INVALID_KERNEL_ARGS: return "CL_INVALID_KERNEL_ARGS";
    case CL_INVALID_WORK_DIMENSION: return "CL_INVALID_WORK_DIMENSION";
    case CL_INVALID_WORK_GROUP_SIZE: return "CL_INVALID_WORK_GROUP_SIZE";
    case CL_INVALID_WORK_ITEM_SIZE: return "CL_INVALID_WORK_ITEM_SIZE";
    case CL_INVALID_GLOBAL_OFFSET: return "CL_INVALID_GLOBAL_OFFSET";
    case CL_INVALID_BUFFER_SIZE: return "CL_INVALID_BUFFER_SIZE";
    case CL_INVALID_GLOBAL_WORK_SIZE: return "CL_INVALID_GLOBAL_WORK_SIZE";
    case -1001: return "CL_PLATFORM_NOT_FOUND_KHR";
    default: return "unknown OpenCL error";
    }
}

lm_status lm_cl_fail(lm_ctx *c, cl_int err, const char *what, const char *kname)
{
    lm_status s = err == CL_MEM_OBJECT_ALLOCATION_FAILURE || err == CL_OUT_OF_HOST_MEMORY
                      ? LM_ERR_NOMEM : LM_ERR_BACKEND;
    if (kname)
        return lm_ctx_fail(c, s, "opencl: %s (kernel %s): %s (%d)", what, kname,
                           lm_cl_error_str(err), (int)err);
    return lm_ctx_fail(c, s, "opencl: %s: %s (%d)", what, lm_cl_error_str(err), (int)err);
}

/* ---- arguments ---------------------------------------------------------------------------- */
int lm_cl_begin(lm_cl_args *a, lm_cl *b, lm_ctx *c, const char *kernel)
{
    memset(a, 0, sizeof *a);
    a->b = b;
    a->c = c;
    a->kname = kernel;
    if (c->status) return c->status;
    a->kern = lm_cl_find_kernel(b, kernel);
    a->k = a->kern ? a->kern->k : NULL;
    if (!a->k)
        return lm_ctx_fail(c, LM_ERR_BACKEND, "opencl: kernel function '%s' is not in the "
                           "program (kernels-opencl/*.cl)", kernel);
    return 0;
}

static void set_arg(lm_cl_args *a, size_t size, const void *v, const char *what)
{
    if (a->err != CL_SUCCESS || !a->k) return;
    cl_int err = clSetKernelArg(a->k, a->i, size, v);
    if (err != CL_SUCCESS) {
        a->err = err;
        a->what = what;
    }
    a->i++;
}

void lm_cl_arg_tensor(lm_cl_args *a, const lm_tensor *t)
{
    if (!t || t->device != LM_DEVICE_OPENCL || !t->dev) {
        if (a->err == CL_SUCCESS) {
            a->err = CL_INVALID_MEM_OBJECT;
            a->what = "tensor argument not on the device";
        }
        return;
    }
    cl_mem m = (cl_mem)t->dev;
    cl_int off = (cl_int)t->dev_off;
    set_arg(a, sizeof m, &m, "clSetKernelArg(buffer)");
    set_arg(a, sizeof off, &off, "clSetKernelArg(offset)");
}

void lm_cl_arg_tensor_opt(lm_cl_args *a, const lm_tensor *t)
{
    if (t) {
        lm_cl_arg_tensor(a, t);
        return;
    }
    cl_mem m = NULL;
    cl_int off = 0;
    set_arg(a, sizeof m, &m, "clSetKernelArg(NULL buffer)");
    set_arg(a, sizeof off, &off, "clSetKernelArg(offset)");
}

void lm_cl_arg_int(lm_cl_args *a, int v)
{
    cl_int x = v;
    set_arg(a, sizeof x, &x, "clSetKernelArg(int)");
}

void lm_cl_arg_float(lm_cl_args *a, float v)
{
    cl_float x = v;
    set_arg(a, sizeof x, &x, "clSetKernelArg(float)");
}

void lm_cl_arg_raw(lm_cl_args *a, size_t size, const void *v)
{
    set_arg(a, size, v, "clSetKernelArg(value)");
}

void lm_cl_arg_local(lm_cl_args *a, size_t bytes)
{
    set_arg(a, bytes, NULL, "clSetKernelArg(__local)");
}

/* ---- enqueue ------------------------------------------------------------------------------ */
int lm_cl_run_nd(lm_cl_args *a, int dims, const size_t *global, const size_t *local)
{
    lm_ctx *c = a->c;
    if (c->status) return c->status;
    if (!a->k) return lm_ctx_fail(c, LM_ERR_BACKEND, "opencl: no kernel (lm_cl_begin failed)");
    if (a->err != CL_SUCCESS) return lm_cl_fail(c, a->err, a->what, a->kname);
    size_t g[3];
    for (int d = 0; d < dims; d++) {
        g[d] = global[d] ? global[d] : 1;
        if (local) g[d] = (g[d] + local[d] - 1) / local[d] * local[d];
    }
    cl_int err = clEnqueueNDRangeKernel(a->b->queue, a->k, (cl_uint)dims, NULL, g, local, 0,
                                        NULL, NULL);
    if (err != CL_SUCCESS) return lm_cl_fail(c, err, "clEnqueueNDRangeKernel", a->kname);
    return 0;
}

/* A fixed local size (not one fitted to n): drivers that compile per work-group size (PoCL)
 * then build each kernel once; the extra work-items of a short launch exit at the guard. */
int lm_cl_run_1d(lm_cl_args *a, size_t n)
{
    size_t wg = a->kern ? a->kern->wg : 0;
    if (a->kern && !wg && clGetKernelWorkGroupInfo(a->k, a->b->device, CL_KERNEL_WORK_GROUP_SIZE,
                                                   sizeof wg, &wg, NULL) == CL_SUCCESS)
        a->kern->wg = wg;
    size_t local = LM_CL_WG;
    if (wg && local > wg) local = wg;
    if (a->b->max_wg && local > a->b->max_wg) local = a->b->max_wg;
    return lm_cl_run_nd(a, 1, &n, &local);
}

/* Work-groups of 16 items (measured on PoCL 3.1: 1, 16 and 64 within noise of each other). */
int lm_cl_run_chunks(lm_cl_args *a, size_t n)
{
    size_t items = (n + LM_CL_CHUNK - 1) / LM_CL_CHUNK, local = 16;
    if (a->b->max_wg && local > a->b->max_wg) local = a->b->max_wg;
    return lm_cl_run_nd(a, 1, &items, &local);
}

int lm_cl_run_groups(lm_cl_args *a, size_t ngroups)
{
    size_t global = ngroups * LM_CL_WG, local = LM_CL_WG;
    return lm_cl_run_nd(a, 1, &global, &local);
}

void lm_cl_shape8(const lm_tensor *t, cl_int8 *shape, cl_int8 *stride)
{
    for (int i = 0; i < 8; i++) {
        shape->s[i] = 1;
        stride->s[i] = 0;
    }
    for (int i = 0; i < t->ndim; i++) {
        shape->s[LM_MAX_DIMS - t->ndim + i] = t->shape[i];
        stride->s[LM_MAX_DIMS - t->ndim + i] = (cl_int)t->stride[i];
    }
}
