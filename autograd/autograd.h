/* autograd.h — reverse-mode backward over the ctx tape, and the finite-difference checker.
 * What it is: lm_backward() walks the tape newest-first (record order is a topological
 * order) and calls each node's backward, which adds into input gradients.
 * What it is not: op-specific: it knows nothing about any op. */
#ifndef LM_AUTOGRAD_H
#define LM_AUTOGRAD_H
#include "tensor/tensor.h"

/* Back-propagate from `out`. seed: gradient of the final objective w.r.t. out (same shape),
 * or NULL for ones (a scalar loss). Gradients accumulate into ->grad of every leaf tensor and
 * parameter that requires grad, and of `out`; the gradients of intermediate tensors (outputs
 * of recorded ops) are released as soon as their op's backward has run (their buffers are
 * reused for later gradients) and are NULL afterwards. Returns LM_OK or the ctx error. */
lm_status lm_backward(lm_ctx *c, lm_tensor *out, const lm_tensor *seed);
/* Per context (c->grad_reuse): 0 keeps every intermediate gradient until lm_ctx_reset (the
 * reference behaviour, for tests); 1 (default) releases and reuses them as above. Returns the
 * previous setting. */
int lm_backward_set_grad_reuse(lm_ctx *c, int on);

/* Forget grads of every tensor on the tape (not parameters); the tape itself remains. */
void lm_tape_clear(lm_ctx *c);

/* ---- finite-difference gradient check ------------------------------------------------ */
/* The function under test: builds its output from inputs in[0..nin) with ops. */
typedef lm_tensor *(*lm_gradcheck_fn)(lm_ctx *c, lm_tensor *const *in, int nin, void *user);

typedef struct lm_gradcheck_opts {
    double eps;         /* perturbation (default 1e-2) */
    double atol, rtol;  /* pass if |analytic - numeric| <= atol + rtol * |numeric| */
    long max_checks;    /* per input, elements checked (random subset if more); 0 = all */
    uint64_t seed;      /* for the loss weights and the element subset */
} lm_gradcheck_opts;

typedef struct lm_gradcheck_result {
    double max_abs_err, max_rel_err;
    long checked, failed;
    int worst_input;
    long worst_index;
    double worst_analytic, worst_numeric;
} lm_gradcheck_result;

void lm_gradcheck_default_opts(lm_gradcheck_opts *o);
/* Checks d(sum(w .* f(in)))/d(in_i) for each input that requires grad, with w a random
 * weighting (uniform in [-1,1]); the loss is accumulated in double; numeric derivatives by
 * central differences. Inputs must be contiguous CPU tensors; they are perturbed in place and
 * restored. Returns LM_OK if every checked element passes, LM_ERR_NUMERIC otherwise (with a
 * message naming the worst element), or the ctx error. */
lm_status lm_gradcheck(lm_ctx *c, lm_gradcheck_fn fn, lm_tensor *const *in, int nin, void *user,
                       const lm_gradcheck_opts *o, lm_gradcheck_result *res);

#endif
