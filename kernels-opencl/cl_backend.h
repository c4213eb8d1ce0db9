/* cl_backend.h — the OpenCL backend: device tensors and kernels run by name on an OpenCL 1.2
 * device (PoCL on the CPU here; any conformant GPU driver elsewhere).
 *
 * What it is: lm_cl_backend_create() picks a device, builds the program made of every
 * embedded kernels-opencl .cl file once, and returns an lm_backend. A ctx switched to it
 * (lm_ctx_set_backend) allocates new tensors in device memory (a per-ctx device arena, reset
 * with the ctx) and every kernel run through lm_kernel_run() executes on the device through a
 * typed launcher registered under the lm_kernel's name. Kernels without an OpenCL port fail
 * with LM_ERR_UNSUPPORTED naming the kernel. Host tensors enter and leave with the recorded
 * ops lm_tensor_to_device / lm_tensor_to_host, so gradients flow across.
 * What it is not: a scheduler (one in-order queue; reads are blocking), nor thread-safe (one
 * backend per thread). Free every ctx using a backend before freeing the backend. */
#ifndef LM_CL_BACKEND_H
#define LM_CL_BACKEND_H
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

/* Backend by name: "cpu" or "opencl"; NULL or "" reads env LM_DEVICE, default "cpu".
 * "opencl" creates an OpenCL backend (release with lm_backend_close); unknown names fail with
 * LM_ERR_ARG. Used by the CLI's --device option. */
lm_backend *lm_backend_open(const char *name, lm_err *e);
void lm_backend_close(lm_backend *b);

/* Recorded transfers. to_device: a host tensor -> a new device tensor on the ctx's device
 * backend (a device tensor is returned as is); backward downloads the gradient and adds it on
 * the host. to_host: a device tensor -> a new host tensor in the ctx arena (a host tensor is
 * returned as is); backward uploads the gradient and adds it on the device. Non-contiguous
 * inputs are made contiguous first. */
lm_tensor *lm_tensor_to_device(lm_ctx *c, lm_tensor *t);
lm_tensor *lm_tensor_to_host(lm_ctx *c, lm_tensor *t);

/* Persistent host tensors (model parameters: layers keep their addresses) used by device ops
 * for one step. swap_to_device replaces each *ts[i] in place by a device copy in the ctx's
 * device arena (requiring grad when the host tensor does; its gradient then lives on the
 * device), keeping the host structs in saved[0..n). swap_back adds each device gradient into
 * the host tensor's gradient (host grad, contiguous, when both exist) and puts the host structs
 * back; call it after lm_backward and before lm_ctx_reset. Both return the ctx status; on a
 * device-less backend they do nothing. */
lm_status lm_tensors_swap_to_device(lm_ctx *c, lm_tensor *const *ts, int n, lm_tensor *saved);
lm_status lm_tensors_swap_back(lm_ctx *c, lm_tensor *const *ts, int n, const lm_tensor *saved);

#endif
