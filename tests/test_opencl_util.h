/* test_opencl_util.h — shared by tests/test_opencl_*.c: backend set-up with the CTest skip
 * rule, and the CPU-vs-OpenCL agreement check of one op (forward and every input gradient).
 *
 * Skip rule: exit 77 only when clGetPlatformIDs reports no platform at all; a platform whose
 * backend cannot be created (no device, build failure, ...) is a test failure. */
#ifndef LM_TEST_OPENCL_UTIL_H
#define LM_TEST_OPENCL_UTIL_H
#include "tests/check.h"
#include "kernels-opencl/cl_backend.h"
#include <stdlib.h>

static lm_backend *clb_; /* the backend every test of the executable uses */

/* Call first in main(): returns 77 to skip, 1 on failure, 0 when the backend is ready. */
static inline int opencl_setup(void)
{
    if (lm_cl_platform_count() == 0) {
        printf("skipped: no OpenCL platform (clGetPlatformIDs found none)\n");
        return 77;
    }
    lm_err e = {0};
    clb_ = lm_cl_backend_create(&e);
    if (!clb_) {
        fprintf(stderr, "FAIL: OpenCL backend: %s\n", e.msg);
        return 1;
    }
    printf("OpenCL device: %s\n", lm_cl_backend_device_name(clb_));
    return 0;
}

static inline void opencl_ctx(lm_ctx *c)
{
    lm_ctx_init(c, 2);
    lm_ctx_set_backend(c, clb_);
}

/* Host copy of any contiguous tensor (malloc'd; NULL on error). */
static inline float *opencl_fetch(lm_ctx *c, const lm_tensor *t)
{
    if (!t) return NULL;
    float *h = malloc((size_t)lm_tensor_numel(t) * sizeof(float));
    if (h && lm_tensor_read(c, t, h)) {
        free(h);
        return NULL;
    }
    return h;
}

/* ---- agreement of one op on both backends --------------------------------------------- */
#define AGREE_MAX_IN 6
typedef lm_tensor *(*agree_fn)(lm_ctx *c, lm_tensor *const *in, int nin, void *user);

typedef struct agree_case {
    const char *name;
    agree_fn fn;
    void *user;
    int nin;
    int ndim[AGREE_MAX_IN];
    int shape[AGREE_MAX_IN][LM_MAX_DIMS];
    float lo[AGREE_MAX_IN], hi[AGREE_MAX_IN]; /* input values uniform in [lo, hi) (0,0: -1..1) */
    int no_grad[AGREE_MAX_IN];                /* 1: the input gets no gradient */
    double atol, rtol;                        /* |cl - cpu| <= atol + rtol |cpu| */
} agree_case;

/* Compare a and b (n floats); print the worst errors under `what` (relative error with
 * |cpu| floored at 1e-6); count a failure. */
static inline void agree_compare(const char *name, const char *what, const float *cl,
                                 const float *cpu, long n, double atol, double rtol)
{
    double wa = 0, wr = 0;
    long bad = 0, first = -1;
    for (long i = 0; i < n; i++) {
        double d = fabs((double)cl[i] - (double)cpu[i]);
        double r = d / (fabs((double)cpu[i]) > 1e-6 ? fabs((double)cpu[i]) : 1e-6);
        if (!(d <= atol + rtol * fabs((double)cpu[i]))) {
            if (first < 0) first = i;
            bad++;
        }
        if (d > wa || d != d) wa = d;
        if (r > wr) wr = r;
    }
    printf("  %-28s %-5s worst abs %.2e  worst rel %.2e  (n=%ld)\n", name, what, wa, wr, n);
    if (bad) {
        fprintf(stderr, "%s %s: %ld of %ld differ; first [%ld] opencl %.8g cpu %.8g\n", name,
                what, bad, n, first, cl[first], cpu[first]);
        check_failures_++;
    }
}

/* Same inputs on both sides: uniform in [lo, hi) on the CPU, copied to the device. */
static inline void agree_inputs(const agree_case *k, lm_ctx *cc, lm_ctx *gc, lm_rng *r,
                                lm_tensor **ci, lm_tensor **gi)
{
    for (int i = 0; i < k->nin; i++) {
        float lo = k->lo[i], hi = k->hi[i];
        if (lo == 0 && hi == 0) lo = -1, hi = 1;
        ci[i] = lm_tensor_uniform(cc, k->ndim[i], k->shape[i], r, lo, hi);
        gi[i] = ci[i] ? lm_tensor_from(gc, k->ndim[i], k->shape[i], ci[i]->data) : NULL;
        if (ci[i] && gi[i] && !k->no_grad[i]) {
            lm_tensor_set_requires_grad(ci[i], 1);
            lm_tensor_set_requires_grad(gi[i], 1);
        }
    }
}

/* Backward on both sides with weights w, input gradients starting from the same random
 * values (so a kernel that writes = where it must add += is caught), then compared. */
static inline void agree_backward(const agree_case *k, lm_ctx *cc, lm_ctx *gc, lm_rng *r,
                                  lm_tensor **ci, lm_tensor **gi, lm_tensor *cy, lm_tensor *gy,
                                  lm_tensor *w)
{
    for (int i = 0; i < k->nin; i++) {
        if (k->no_grad[i]) continue;
        lm_tensor *a = lm_grad(cc, ci[i]), *b = lm_grad(gc, gi[i]);
        if (!a || !b) continue;
        lm_rng_fill_uniform(r, a->data, lm_tensor_numel(a), -1, 1);
        lm_tensor_write(gc, b, a->data);
    }
    lm_backward(cc, cy, w);
    lm_backward(gc, lm_tensor_to_host(gc, gy), w); /* the tape crosses back to the device */
    CHECK_CTX_OK(cc);
    CHECK_CTX_OK(gc);
    for (int i = 0; i < k->nin && !gc->status && !cc->status; i++) {
        if (k->no_grad[i]) continue;
        char what[16];
        snprintf(what, sizeof what, "grad%d", i);
        CHECK(gi[i]->grad && gi[i]->grad->device == LM_DEVICE_OPENCL);
        float *gh = opencl_fetch(gc, gi[i]->grad);
        if (gh) agree_compare(k->name, what, gh, ci[i]->grad->data, lm_tensor_numel(ci[i]),
                              k->atol, k->rtol);
        free(gh);
    }
}

/* Runs fn on a CPU ctx and on an OpenCL ctx (inputs created on the device) with the same
 * inputs and the same random output weights; backward on both; compares the outputs and
 * the gradient of every input that gets one. */
static inline void check_agree(const agree_case *k, uint64_t seed)
{
    lm_ctx cc, gc;
    lm_ctx_init(&cc, 2);
    opencl_ctx(&gc);
    lm_tensor *ci[AGREE_MAX_IN], *gi[AGREE_MAX_IN];
    lm_rng r;
    lm_rng_seed(&r, seed);
    agree_inputs(k, &cc, &gc, &r, ci, gi);
    CHECK(gi[0] == NULL || gi[0]->device == LM_DEVICE_OPENCL);
    lm_tensor *cy = k->fn(&cc, ci, k->nin, k->user);
    lm_tensor *gy = k->fn(&gc, gi, k->nin, k->user);
    CHECK_CTX_OK(&cc);
    CHECK_CTX_OK(&gc);
    if (cy && gy) {
        CHECK(gy->device == LM_DEVICE_OPENCL);
        CHECK(lm_tensor_same_shape(cy, gy));
        lm_tensor *w = lm_tensor_uniform(&cc, cy->ndim, cy->shape, &r, -1, 1);
        cy = lm_contiguous(&cc, cy);
        float *gyh = opencl_fetch(&gc, lm_contiguous(&gc, gy));
        if (gyh) agree_compare(k->name, "fwd", gyh, cy->data, lm_tensor_numel(cy), k->atol,
                               k->rtol);
        free(gyh);
        agree_backward(k, &cc, &gc, &r, ci, gi, cy, gy, w);
    }
    CHECK_CTX_OK(&gc);
    lm_ctx_free(&cc);
    lm_ctx_free(&gc);
}

#endif
