/* cl_backend.h — the OpenCL backend: device tensors and kernels run by name on an OpenCL 1.2
 * device (PoCL on the CPU here; any conformant GPU driver elsewhere).
 *
 * What it is: lm_cl_backend_create() picks a device, builds the program made of every
 * embedded kernels-opencl .cl file once, and returns an lm_backend. A ctx switched to it
 * (lm_ctx_set_backend) allocates new tensors in device memory (a per-ctx device arena, reset
 * with the ctx) and every kernel run through lm_kernel_run() executes on the device through a
 * typed launcher registered under the lm_kernel's name. Kernels without an OpenCL port fail
 * with LM_ERR_UNSUPPORTED naming the kernel. The backend registers itself as "opencl" at
 * start-up, so code above tensor/ opens it by name (lm_backend_open) and places tensors on it
 * (lm_tensor_to_device / lm_tensor_to_host, parameter swaps) through tensor/device.h, never
 * through this header; this header is for the backend's own tests and benchmarks.
 * What it is not: a scheduler (one in-order queue; reads are blocking), nor thread-safe (one
 * backend per thread). Free every ctx using a backend before freeing the backend. */
#ifndef LM_CL_BACKEND_H
#define LM_CL_BACKEND_H
#include "tensor/device.h"
#include "tensor/tensor.h"

/* Create the backend. Device: env LM_OPENCL_DEVICE = index into the list of every device of
 * every platform (in platform order), else the first GPU, else the first device.
 * Env LM_OPENCL_CONV_SCRATCH: floats of im2col scratch per convolution chunk (default 4M).
 * Returns NULL and fills e on failure; a program build failure prints the build log to stderr
 * and puts its first lines in e. e->status is LM_ERR_UNSUPPORTED when no OpenCL platform
 * exists at all (lm_cl_platform_count() == 0), LM_ERR_BACKEND for every other failure. */
lm_backend *lm_cl_backend_create(lm_err *e);
void lm_cl_backend_free(lm_backend *b);
/* Number of OpenCL platforms (0 when none is installed or the ICD loader finds none). */
int lm_cl_platform_count(void);
/* "device name (platform name)" of an OpenCL backend. */
const char *lm_cl_backend_device_name(const lm_backend *b);

/* Wait until every command queued on the backend's device has finished (benchmarks). */
void lm_cl_backend_finish(lm_backend *b);

/* Compile an extra OpenCL C source on the backend's device and discard it (diagnostics and
 * tests): LM_OK, or LM_ERR_BACKEND with the build log printed to stderr and quoted in e. */
lm_status lm_cl_compile_check(lm_backend *b, const char *src, lm_err *e);

#endif
