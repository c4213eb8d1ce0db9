/* device.h — device placement, for any backend: backends chosen by name, tensors moved between
 * the host and a device backend with the tape running across, and persistent parameters
 * mirrored on the device for a step. Everything here goes through the backend interface of
 * tensor.h (alloc, write, read, run); no backend is named.
 *
 * What it is: the backend registry (a device backend registers the function that creates it
 * under the name --device takes; "cpu" is built in; kernels-opencl/ registers "opencl" when the
 * program starts), the recorded transfers lm_tensor_to_device / lm_tensor_to_host
 * (tensor/transfer.c) and the parameter swaps lm_tensors_swap_to_device / _swap_back
 * (tensor/mirror.c). Networks and loops call these and never a backend's own header.
 * What it is not: a backend (kernels-opencl/), nor the choice of a device inside a backend
 * (that backend's own environment variables). */
#ifndef LM_DEVICE_H
#define LM_DEVICE_H
#include "tensor/tensor.h"

/* ---- backends by name ---------------------------------------------------------------- */
/* Creates a device backend; NULL with e filled on failure. */
typedef lm_backend *(*lm_backend_open_fn)(lm_err *e);
/* Register a device backend under name (a string with static lifetime, e.g. "opencl").
 * Registering a name again does nothing. Meant for start-up (not thread-safe); at most 8. */
void lm_backend_register(const char *name, lm_backend_open_fn open);
/* Backend by name: "cpu" or a registered name; NULL or "" reads env LM_DEVICE, default "cpu".
 * A device backend is created (release with lm_backend_close); unknown names fail with
 * LM_ERR_ARG ("unknown device 'x' (expected cpu or opencl)"). Used by the --device options. */
lm_backend *lm_backend_open(const char *name, lm_err *e);
/* Release a backend from lm_backend_open (the CPU backend and NULL: nothing to do). */
void lm_backend_close(lm_backend *b);
/* The device a backend runs on, for messages ("" for the CPU backend). */
const char *lm_backend_device_name(const lm_backend *b);

/* ---- recorded transfers (tensor/transfer.c) ------------------------------------------ */
/* to_device: a host tensor -> a new device tensor on the ctx's device backend (a device tensor
 * is returned as is; LM_ERR_ARG on a ctx without a device); backward downloads the gradient
 * and adds it on the host. to_host: a device tensor -> a new host tensor in the ctx arena (a
 * host tensor is returned as is); backward uploads the gradient and adds it on the device.
 * Non-contiguous inputs are made contiguous first. */
lm_tensor *lm_tensor_to_device(lm_ctx *c, lm_tensor *t);
lm_tensor *lm_tensor_to_host(lm_ctx *c, lm_tensor *t);

/* ---- parameters on the device for a step (tensor/mirror.c) --------------------------- */
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
