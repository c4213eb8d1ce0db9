/* check.h — the tiny test harness every test executable uses.
 * A test file defines `static void test_xxx(void)` functions and a main() that calls
 * RUN(test_xxx) for each and returns check_summary(). Failures print file:line and continue.
 * Each executable prints "N passed, N failed" and exits non-zero on any failure. */
#ifndef LM_TESTS_CHECK_H
#define LM_TESTS_CHECK_H
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "autograd/autograd.h"
#include "tensor/ops.h"
#include "tensor/isa.h"

static int check_failures_ = 0, check_tests_ = 0, check_failed_tests_ = 0;

#define CHECK(cond)                                                                           \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);          \
            check_failures_++;                                                                \
        }                                                                                     \
    } while (0)

#define CHECK_MSG(cond, ...)                                                                  \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "%s:%d: CHECK failed: %s: ", __FILE__, __LINE__, #cond);          \
            fprintf(stderr, __VA_ARGS__);                                                     \
            fputc('\n', stderr);                                                              \
            check_failures_++;                                                                \
        }                                                                                     \
    } while (0)

/* |a - b| <= atol + rtol |b| */
#define CHECK_CLOSE(a, b, atol, rtol)                                                         \
    do {                                                                                      \
        double a_ = (a), b_ = (b);                                                            \
        if (!(fabs(a_ - b_) <= (atol) + (rtol) * fabs(b_))) {                                 \
            fprintf(stderr, "%s:%d: %s = %.8g, expected %s = %.8g\n", __FILE__, __LINE__, #a, \
                    a_, #b, b_);                                                              \
            check_failures_++;                                                                \
        }                                                                                     \
    } while (0)

/* Arrays: reports the first mismatch and the worst error. */
#define CHECK_ARRAY_CLOSE(a, b, n, atol, rtol)                                                \
    check_array_close_((a), (b), (long)(n), (atol), (rtol), __FILE__, __LINE__, #a)

static inline void check_array_close_(const float *a, const float *b, long n, double atol,
                                      double rtol, const char *file, int line, const char *what)
{
    long bad = 0, first = -1;
    double worst = 0.0;
    for (long i = 0; i < n; i++) {
        double e = fabs((double)a[i] - (double)b[i]);
        if (!(e <= atol + rtol * fabs((double)b[i]))) {
            if (first < 0) first = i;
            bad++;
        }
        if (e > worst || e != e) worst = e;
    }
    if (bad) {
        fprintf(stderr, "%s:%d: %s: %ld of %ld differ; first [%ld] %.8g vs %.8g; worst %.3g\n",
                file, line, what, bad, n, first, a[first], b[first], worst);
        check_failures_++;
    }
}

/* The ctx must be error-free; prints its message otherwise. */
#define CHECK_CTX_OK(c)                                                                       \
    do {                                                                                      \
        if ((c)->status) {                                                                    \
            fprintf(stderr, "%s:%d: ctx error: %s\n", __FILE__, __LINE__, (c)->msg);          \
            check_failures_++;                                                                \
        }                                                                                     \
    } while (0)

/* The ctx must hold an error of status s (message non-empty); then clears it. */
#define CHECK_CTX_FAILED(c, s)                                                                \
    do {                                                                                      \
        if ((c)->status != (s) || !(c)->msg[0]) {                                             \
            fprintf(stderr, "%s:%d: expected ctx error %d, got %d (%s)\n", __FILE__, __LINE__, \
                    (int)(s), (int)(c)->status, (c)->msg);                                    \
            check_failures_++;                                                                \
        }                                                                                     \
        lm_ctx_clear_error(c);                                                                \
    } while (0)

#define RUN(fn)                                                                               \
    do {                                                                                      \
        int before_ = check_failures_;                                                        \
        check_tests_++;                                                                       \
        fn();                                                                                 \
        if (check_failures_ != before_) {                                                     \
            check_failed_tests_++;                                                            \
            fprintf(stderr, "FAIL %s\n", #fn);                                                \
        } else                                                                                \
            printf("ok   %s\n", #fn);                                                         \
    } while (0)

static inline int check_summary(void)
{
    char isa_msg_[200]; /* a test run at an instruction-set level (LM_ISA) must really run it */
    if (lm_isa_init(isa_msg_, sizeof isa_msg_) != LM_OK) {
        fprintf(stderr, "%s\n", isa_msg_);
        check_failed_tests_++;
    }
    printf("%d passed, %d failed\n", check_tests_ - check_failed_tests_, check_failed_tests_);
    return check_failed_tests_ ? 1 : 0;
}

/* Run lm_gradcheck and report failures through CHECK. Uses its own rewind. */
static inline void check_grad_(lm_ctx *c, lm_gradcheck_fn fn, lm_tensor *const *in, int nin,
                               void *user, const lm_gradcheck_opts *o, const char *file, int line)
{
    lm_gradcheck_result r;
    lm_status s = lm_gradcheck(c, fn, in, nin, user, o, &r);
    if (s != LM_OK) {
        fprintf(stderr, "%s:%d: %s\n", file, line, c->msg);
        check_failures_++;
        lm_ctx_clear_error(c);
    } else if (r.checked == 0) {
        fprintf(stderr, "%s:%d: gradcheck checked no element (no input requires grad?)\n",
                file, line);
        check_failures_++;
    }
}
/* [y, x] flattened and joined: with x used twice, a backward that writes (=) instead of
 * adding (+=) into x's gradient loses the other use and fails a gradient check. */
static inline lm_tensor *check_with_input(lm_ctx *c, lm_tensor *y, lm_tensor *x)
{
    lm_tensor *p[2] = {lm_reshape(c, y, 1, (int[]){-1}), lm_reshape(c, x, 1, (int[]){-1})};
    return lm_concat(c, p, 2, 0);
}

#define CHECK_GRAD(c, fn, in, nin, user, opts) check_grad_((c), (fn), (in), (nin), (user), (opts), __FILE__, __LINE__)

#endif
