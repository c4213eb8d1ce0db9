/* tensor.h — the tensor type, the context that owns per-step memory and the tape, kernel
 * dispatch to a backend, and tape recording used by every op.
 *
 * What it is: float32 tensors of up to LM_MAX_DIMS dimensions (NCHW for images), contiguous
 * storage plus cheap views (reshape, slice), allocated from the context's arena. Errors are
 * sticky per context: the first failure is kept (status + one-line message), later ops see a
 * NULL input and return NULL, so model code can run a sequence of ops and check once.
 * What it is not: the backward engine (autograd/), nor the ops themselves (tensor/ops/). */
#ifndef LM_TENSOR_H
#define LM_TENSOR_H
#include <stddef.h>
#include <stdint.h>
#include "tensor/status.h"
#include "tensor/arena.h"
#include "tensor/rng.h"

#define LM_MAX_DIMS 5
#define LM_MAX_INPUTS 8

enum lm_tensor_flags {
    LM_REQUIRES_GRAD = 1u << 0, /* gradients flow to / through this tensor */
    LM_PARAM = 1u << 1,         /* persistent parameter; grad lives outside the arena */
    LM_VIEW = 1u << 2           /* shares memory with another tensor */
};

typedef enum lm_device { LM_DEVICE_CPU = 0, LM_DEVICE_OPENCL = 1 } lm_device;

typedef struct lm_tensor {
    float *data;                      /* host memory (CPU backend) */
    void *dev;                        /* device buffer handle (device backends), else NULL */
    size_t dev_off;                   /* element offset into dev */
    int ndim;
    int shape[LM_MAX_DIMS];
    ptrdiff_t stride[LM_MAX_DIMS];    /* in elements */
    struct lm_tensor *grad;           /* contiguous, same shape; NULL until needed */
    unsigned flags;
    lm_device device;
    const char *name;                 /* optional, for parameters and debugging */
} lm_tensor;

typedef struct lm_ctx lm_ctx;
typedef struct lm_node lm_node;

/* ---- kernels and backends ------------------------------------------------------------ */
/* A kernel works on tensors t[0..nt) with an op-specific parameter struct. The CPU function is
 * the reference; a device backend looks the kernel up by name. Returns 0 or sets the ctx
 * error and returns a negative lm_status. */
typedef int (*lm_kernel_fn)(lm_ctx *c, lm_tensor *const *t, int nt, const void *params);
typedef struct lm_kernel {
    const char *name;
    lm_kernel_fn cpu;
} lm_kernel;

typedef struct lm_backend {
    const char *name;
    lm_device device;
    /* Run kernel k on this backend; NULL for the CPU backend. */
    int (*run)(struct lm_backend *b, lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt,
               const void *params);
    void *impl;
    /* Device memory (all NULL for the CPU backend). Tensors created while a device backend is
     * the ctx's live in a per-ctx device arena (c->dev_arena) owned by that backend.
     * alloc: room for `bytes` bytes; returns the buffer handle and sets *off (in elements);
     *        NULL with the ctx error set on failure.
     * reset: empty the ctx's device arena (lm_ctx_reset); release: free it (lm_ctx_free).
     * write/read: copy a contiguous device tensor from/to host memory (blocking). */
    void *(*alloc)(struct lm_backend *b, lm_ctx *c, size_t bytes, size_t *off);
    void (*reset)(struct lm_backend *b, lm_ctx *c);
    void (*release)(struct lm_backend *b, lm_ctx *c);
    int (*write)(struct lm_backend *b, lm_ctx *c, lm_tensor *t, const float *src);
    int (*read)(struct lm_backend *b, lm_ctx *c, const lm_tensor *t, float *dst);
    /* Lifetime of a created backend (NULL for the static CPU backend): close frees it
     * (lm_backend_close); device_name names its device for messages. */
    void (*close)(struct lm_backend *b);
    const char *device_name;
} lm_backend;

/* The CPU backend (static; the default of every ctx). Device backends are opened by name and
 * tensors placed on them through tensor/device.h. */
lm_backend *lm_backend_cpu(void);

int lm_kernel_run(lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt, const void *params);

/* ---- tape ---------------------------------------------------------------------------- */
/* Backward of one recorded op: reads n->out->grad and ADDS into the grads of n->in[] that
 * require grad (obtained with lm_grad()). */
typedef void (*lm_backward_fn)(lm_ctx *c, lm_node *n);

struct lm_node {
    lm_backward_fn backward;
    const char *op;                   /* op name, for error messages and debugging */
    lm_tensor *out;
    lm_tensor *in[LM_MAX_INPUTS];
    int nin;
    void *params;                     /* copy of the op's parameters (arena) */
    lm_node *prev;                    /* tape is a singly linked list, newest first */
};

/* ---- context ------------------------------------------------------------------------- */
/* Host gradient buffers released during lm_backward (those of intermediate tensors whose
 * backward has run), reused by lm_grad for later gradients (autograd/tape.c). */
typedef struct lm_grad_pool {
    float **data;
    long *cap;                        /* floats in data[i] */
    int n, max;
} lm_grad_pool;

struct lm_ctx {
    lm_arena arena;                   /* per step: tensors, tape nodes, scratch */
    lm_node *tape;                    /* newest node first */
    long tape_len;
    int grad_enabled;                 /* 1: ops record onto the tape */
    int nthreads;                     /* threads for CPU kernels (>= 1) */
    lm_backend *backend;              /* where new tensors live and kernels run */
    lm_status status;                 /* first error since the last clear */
    char msg[512];
    void *dev_arena;                  /* device memory of a device backend (owned by it) */
    lm_grad_pool *grad_pool;          /* set during lm_backward only */
    /* Reference switches (tests and benchmarks compare the fast paths with them); 0 = the
     * fast default except grad_reuse (1). conv_path: LM_CONV_PATH_* of conv2d's CPU kernels
     * (lm_conv2d_set_path, tensor/ops/gemm_internal.h); op_path: LM_OP_PATH_* of the ops with a
     * fast / reference pair (lm_op_set_path, tensor/ops/op_paths.h); grad_reuse: lm_backward
     * releases and reuses intermediate gradients (lm_backward_set_grad_reuse, autograd.h). */
    int conv_path;
    int op_path;
    int grad_reuse;
    /* Operand precision of the CPU convolution products: LM_PRECISION_FP32 (0, the default)
     * or LM_PRECISION_BF16 (operands rounded to bf16, sums in fp32: the Winograd products of
     * 3x3 convolutions, forward and input gradient; the weight gradient stays fp32). */
    int precision;
    /* Data derived from weights (transformed, packed), kept across lm_ctx_reset while the
     * weights are unchanged (tensor/ops/wcache.h); freed by lm_ctx_free. */
    struct lm_wcache *wcache;
};
enum { LM_PRECISION_FP32 = 0, LM_PRECISION_BF16 = 1 };

/* The most threads a context takes (every command's --threads and the run config's "threads"
 * are checked against it: OpenMP fails on absurd team sizes). */
#define LM_MAX_THREADS 1024

/* Initialise a context: CPU backend, grad enabled, nthreads (0 = all cores; at most
 * LM_MAX_THREADS, else LM_ERR_ARG), fast kernel paths, gradient reuse on. */
int lm_ctx_init(lm_ctx *c, int nthreads);
void lm_ctx_free(lm_ctx *c);
/* End of a step: drop the tape and everything allocated in the arena. Keeps the error. */
void lm_ctx_reset(lm_ctx *c);
/* Record the first error (printf-style message, one line). Returns the status. */
lm_status lm_ctx_fail(lm_ctx *c, lm_status s, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static inline lm_status lm_ctx_status(const lm_ctx *c) { return c->status; }
static inline const char *lm_ctx_message(const lm_ctx *c) { return c->status ? c->msg : ""; }
void lm_ctx_clear_error(lm_ctx *c);
/* Switch the backend new tensors and kernels use (NULL = CPU). Releases the device memory of
 * the previous device backend, so call it before creating tensors. */
void lm_ctx_set_backend(lm_ctx *c, lm_backend *b);
/* Grad mode: returns the previous value. */
int lm_ctx_set_grad(lm_ctx *c, int enabled);
/* Arena scratch (aligned, uninitialised); sets the error and returns NULL on failure. */
void *lm_ctx_alloc(lm_ctx *c, size_t bytes);

/* Scopes release intermediates early in no-grad mode: everything allocated after
 * lm_scope_begin() is freed by lm_scope_end() except the returned copy of `keep`.
 * In grad mode (intermediates are needed by backward) lm_scope_end() returns `keep` as is. */
typedef struct lm_scope { lm_arena_mark mark; lm_node *tape; long tape_len; } lm_scope;
lm_scope lm_scope_begin(lm_ctx *c);
lm_tensor *lm_scope_end(lm_ctx *c, lm_scope s, lm_tensor *keep);

/* ---- tensors ------------------------------------------------------------------------- */
/* New contiguous tensor in the ctx arena on the ctx backend; contents uninitialised. */
lm_tensor *lm_tensor_new(lm_ctx *c, int ndim, const int *shape);
/* Same, on a given device: LM_DEVICE_CPU (host arena, whatever the backend) or the ctx
 * backend's device. */
lm_tensor *lm_tensor_new_on(lm_ctx *c, lm_device dev, int ndim, const int *shape);
lm_tensor *lm_tensor_zeros(lm_ctx *c, int ndim, const int *shape);
lm_tensor *lm_tensor_full(lm_ctx *c, int ndim, const int *shape, float v);
/* Copy of host data (len = numel). */
lm_tensor *lm_tensor_from(lm_ctx *c, int ndim, const int *shape, const float *src);
lm_tensor *lm_tensor_new_like(lm_ctx *c, const lm_tensor *t);
lm_tensor *lm_tensor_uniform(lm_ctx *c, int ndim, const int *shape, lm_rng *r, float lo, float hi);
lm_tensor *lm_tensor_normal(lm_ctx *c, int ndim, const int *shape, lm_rng *r, float mean, float std);
/* Convenience for up to 5 dims: lm_tensor_new4(c, B, C, H, W) etc. */
lm_tensor *lm_tensor_new1(lm_ctx *c, int d0);
lm_tensor *lm_tensor_new2(lm_ctx *c, int d0, int d1);
lm_tensor *lm_tensor_new3(lm_ctx *c, int d0, int d1, int d2);
lm_tensor *lm_tensor_new4(lm_ctx *c, int d0, int d1, int d2, int d3);

/* Wrap caller-owned memory (not freed by Lumosaic); contiguous. `t` is caller storage. */
void lm_tensor_wrap(lm_tensor *t, float *data, int ndim, const int *shape);

long lm_tensor_numel(const lm_tensor *t);
int lm_tensor_is_contiguous(const lm_tensor *t);
int lm_tensor_same_shape(const lm_tensor *a, const lm_tensor *b);
/* "2x3x4" into buf; returns buf. */
const char *lm_shape_str(const lm_tensor *t, char *buf, size_t n);
void lm_tensor_set_requires_grad(lm_tensor *t, int on);
static inline int lm_requires_grad(const lm_tensor *t) { return t && (t->flags & LM_REQUIRES_GRAD); }
/* Copy a contiguous tensor of any device to / from host memory (numel floats). Returns 0 or
 * sets the ctx error and returns a negative lm_status. */
int lm_tensor_read(lm_ctx *c, const lm_tensor *t, float *dst);
int lm_tensor_write(lm_ctx *c, lm_tensor *t, const float *src);
/* Fill a contiguous CPU tensor; for tests and initialisation. */
void lm_tensor_fill(lm_tensor *t, float v);
/* Element access for contiguous CPU tensors (bounds are the caller's responsibility). */
static inline float *lm_at4(const lm_tensor *t, int i0, int i1, int i2, int i3)
{
    return t->data + i0 * t->stride[0] + i1 * t->stride[1] + i2 * t->stride[2] + i3 * t->stride[3];
}

/* ---- op helpers (used inside ops) ---------------------------------------------------- */
/* Nonzero when every input is non-NULL and the ctx has no error; otherwise records an error
 * naming `op` if the ctx has none yet. */
int lm_check_inputs(lm_ctx *c, const char *op, int n, ...);
/* Gradient of t, allocated zero-filled on first use (arena for intermediates). */
lm_tensor *lm_grad(lm_ctx *c, lm_tensor *t);
/* Seed of a backward pass on any device: grad(out) += seed (same shape, contiguous, on the host
 * or on out's device), or += 1 when seed is NULL. Returns the ctx status. */
lm_status lm_grad_seed(lm_ctx *c, lm_tensor *out, const lm_tensor *seed);
/* If grad mode is on and any input requires grad: mark `out` as requiring grad and push a node
 * (params copied, `params_size` bytes). Returns the node or NULL if nothing was recorded. */
lm_node *lm_record(lm_ctx *c, const char *op, lm_backward_fn bw, lm_tensor *out,
                   lm_tensor *const *in, int nin, const void *params, size_t params_size);

/* Thread count of the ctx's CPU kernels. */
static inline int lm_nthreads(const lm_ctx *c) { return c->nthreads > 0 ? c->nthreads : 1; }

#endif
