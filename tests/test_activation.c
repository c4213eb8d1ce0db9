/* test_activation.c — relu, leaky_relu, sigmoid, tanh, gelu (activation.c): hand-computed
 * values, an independent double-precision reference, behaviour for large |x|, gradient checks
 * away from kinks, exact gradients at and around the kinks, errors, determinism. */
#include "tensor/ops/op_paths.h"
#include "tests/check.h"
#include <stdlib.h>

enum { A_RELU, A_LEAKY, A_SIGMOID, A_TANH, A_GELU, A_COUNT };
static const char *const A_NAMES[A_COUNT] = {"relu", "leaky_relu", "sigmoid", "tanh", "gelu"};
#define SLOPE 0.2f

static lm_tensor *act(lm_ctx *c, int k, lm_tensor *x)
{
    switch (k) {
    case A_RELU: return lm_relu(c, x);
    case A_LEAKY: return lm_leaky_relu(c, x, SLOPE);
    case A_SIGMOID: return lm_sigmoid(c, x);
    case A_TANH: return lm_tanh(c, x);
    default: return lm_gelu(c, x);
    }
}

/* Reference in double, written from the definitions. */
static double ref_f(int k, double x)
{
    switch (k) {
    case A_RELU: return x > 0 ? x : 0;
    case A_LEAKY: return x > 0 ? x : SLOPE * x;
    case A_SIGMOID: return 1.0 / (1.0 + exp(-x));
    case A_TANH: return (exp(x) - exp(-x)) / (exp(x) + exp(-x));
    default: return x * 0.5 * erfc(-x / sqrt(2.0));
    }
}

static double ref_df(int k, double x)
{
    double s;
    switch (k) {
    case A_RELU: return x > 0 ? 1 : 0;
    case A_LEAKY: return x > 0 ? 1 : SLOPE;
    case A_SIGMOID: s = 1.0 / (1.0 + exp(-x)); return s * (1 - s);
    case A_TANH: s = tanh(x); return 1 - s * s;
    default: return 0.5 * erfc(-x / sqrt(2.0)) + x * exp(-0.5 * x * x) / sqrt(2.0 * M_PI);
    }
}

static void test_activation_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 1, (int[]){5}, (float[]){-2, -0.5f, 0, 0.5f, 1});
    CHECK_ARRAY_CLOSE(lm_relu(&c, x)->data, ((float[]){0, 0, 0, 0.5f, 1}), 5, 0, 0);
    CHECK_ARRAY_CLOSE(lm_leaky_relu(&c, x, 0.1f)->data, ((float[]){-0.2f, -0.05f, 0, 0.5f, 1}),
                      5, 0, 1e-7);
    /* sigmoid(0) = 1/2, sigmoid(1) = 0.7310585786300049, sigmoid(-2) = 0.11920292202211755 */
    float sg[5] = {0.11920292202211755f, 0.3775406687981454f, 0.5f, 0.6224593312018546f,
                   0.7310585786300049f};
    CHECK_ARRAY_CLOSE(lm_sigmoid(&c, x)->data, sg, 5, 1e-7, 1e-6);
    float th[5] = {-0.9640275800758169f, -0.46211715726000974f, 0, 0.46211715726000974f,
                   0.7615941559557649f};
    CHECK_ARRAY_CLOSE(lm_tanh(&c, x)->data, th, 5, 1e-7, 1e-6);
    /* gelu(x) = x Phi(x): Phi(1) = 0.8413447460685429, Phi(0.5) = 0.6914624612740131 */
    float ge[5] = {-2 * 0.022750131948179195f, -0.5f * 0.3085375387259869f, 0,
                   0.5f * 0.6914624612740131f, 0.8413447460685429f};
    CHECK_ARRAY_CLOSE(lm_gelu(&c, x)->data, ge, 5, 1e-7, 1e-6);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_activation_matches_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){4, 5, 30}, &r, -6, 6);
    long n = lm_tensor_numel(x);
    for (int k = 0; k < A_COUNT; k++) {
        lm_tensor *y = act(&c, k, x);
        CHECK(y && lm_tensor_same_shape(x, y));
        if (!y) continue;
        int bad = 0;
        for (long i = 0; i < n; i++) {
            double e = ref_f(k, x->data[i]);
            bad += !(fabs(y->data[i] - e) <= 1e-6 + 2e-6 * fabs(e));
        }
        CHECK_MSG(bad == 0, "%s: %d of %ld elements off", A_NAMES[k], bad, n);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* No inf/NaN for large |x|; saturation values as expected. */
static void test_activation_extremes(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float v[6] = {-1e4f, -100, -30, 30, 100, 1e4f};
    lm_tensor *x = lm_tensor_from(&c, 1, (int[]){6}, v);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *s = lm_sigmoid(&c, x);
    for (int i = 0; i < 6; i++) CHECK(isfinite(s->data[i]) && s->data[i] >= 0 && s->data[i] <= 1);
    CHECK(s->data[0] == 0.0f && s->data[5] == 1.0f && s->data[4] == 1.0f);
    CHECK_CLOSE(s->data[2], 9.357622968840175e-14, 0, 1e-5); /* exp(-30) / (1 + exp(-30)) */
    CHECK(s->data[1] > 0.0f && s->data[1] < 1e-40f);          /* exp(-100): subnormal, not 0 */
    lm_tensor *t = lm_tanh(&c, x);
    CHECK(t->data[0] == -1.0f && t->data[5] == 1.0f);
    lm_tensor *g = lm_gelu(&c, x);
    CHECK(g->data[0] == 0.0f && g->data[5] == 1e4f && g->data[3] == 30.0f);
    lm_tensor *sum = lm_add(&c, lm_add(&c, s, t), g);
    CHECK(lm_backward(&c, sum, lm_tensor_full(&c, 1, (int[]){6}, 1.0f)) == LM_OK);
    for (int i = 0; i < 6; i++) CHECK(isfinite(x->grad->data[i]));
    /* d/dx at -1e4: 0 + 0 + 0; at 1e4: 0 + 0 + 1 */
    CHECK(x->grad->data[0] == 0.0f && x->grad->data[5] == 1.0f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_act(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    return act(c, *(int *)user, in[0]);
}

static void test_activation_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 8);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.atol = 1e-3;
    o.rtol = 1e-2;
    for (int k = 0; k < A_COUNT; k++) {
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -3, 3);
        for (long i = 0; i < lm_tensor_numel(x); i++) /* keep away from the kink at 0 */
            if (fabsf(x->data[i]) < 0.05f) x->data[i] = x->data[i] < 0 ? -0.05f : 0.05f;
        lm_tensor_set_requires_grad(x, 1);
        int before = check_failures_;
        CHECK_GRAD(&c, fn_act, &x, 1, &k, &o);
        if (check_failures_ != before) fprintf(stderr, "  activation %s\n", A_NAMES[k]);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

/* Backward against the derivative formulas, including x = 0 (relu' = 0, leaky' = slope). */
static void test_activation_grad_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float v[7] = {-3, -1, -1e-3f, 0, 1e-3f, 0.7f, 2.5f};
    for (int k = 0; k < A_COUNT; k++) {
        lm_tensor *x = lm_tensor_from(&c, 1, (int[]){7}, v);
        lm_tensor *w = lm_tensor_from(&c, 1, (int[]){7}, (float[]){1, -2, 3, 0.5f, -1, 2, 0.25f});
        lm_tensor_set_requires_grad(x, 1);
        CHECK(lm_backward(&c, act(&c, k, x), w) == LM_OK);
        for (int i = 0; i < 7; i++) {
            double e = w->data[i] * ref_df(k, v[i]);
            CHECK_MSG(fabs(x->grad->data[i] - e) <= 1e-6 + 1e-5 * fabs(e),
                      "%s'(%g): %g, expected %g", A_NAMES[k], v[i], x->grad->data[i], e);
        }
        lm_ctx_reset(&c);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_activation_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    for (int k = 0; k < A_COUNT; k++) {
        CHECK(act(&c, k, NULL) == NULL);
        CHECK_MSG(strstr(c.msg, A_NAMES[k]) != NULL, "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    }
    lm_tensor *x = lm_tensor_zeros(&c, 1, (int[]){3});
    CHECK(lm_leaky_relu(&c, x, NAN) == NULL);
    CHECK_MSG(strstr(c.msg, "leaky_relu") != NULL, "message: %s", c.msg);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    /* strided input is copied first */
    lm_tensor *m = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){-1, 2, -3, 4, -5, 6});
    lm_tensor *y = lm_relu(&c, lm_slice(&c, m, 1, 1, 2));
    CHECK(y && y->shape[0] == 2 && y->shape[1] == 2);
    if (y) CHECK_ARRAY_CLOSE(y->data, ((float[]){2, 0, 0, 6}), 4, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Every activation forward and backward on a parallel-sized tensor: bitwise repeatable. */
static void run_big(int nthreads, float *out)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 99);
    int shape[4] = {2, 16, 64, 64};
    long n = 2L * 16 * 64 * 64;
    lm_tensor *x = lm_tensor_uniform(&c, 4, shape, &r, -4, 4);
    lm_tensor *w = lm_tensor_uniform(&c, 4, shape, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = act(&c, 0, x);
    for (int k = 1; k < A_COUNT; k++) y = lm_add(&c, y, act(&c, k, x));
    CHECK(lm_backward(&c, y, w) == LM_OK);
    memcpy(out, y->data, (size_t)n * sizeof(float));
    memcpy(out + n, x->grad->data, (size_t)n * sizeof(float));
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_activation_determinism(void)
{
    size_t n = 2 * 2L * 16 * 64 * 64;
    float *a = malloc(n * sizeof(float)), *b = malloc(n * sizeof(float));
    float *one = malloc(n * sizeof(float));
    for (int nt = 1; nt <= 2; nt++) {
        run_big(nt, a);
        run_big(nt, b);
        CHECK_MSG(memcmp(a, b, n * sizeof(float)) == 0, "nthreads %d: runs differ", nt);
        if (nt == 1) memcpy(one, a, n * sizeof(float));
    }
    CHECK_MSG(memcmp(one, a, n * sizeof(float)) == 0, "1 and 2 threads differ");
    free(a);
    free(b);
    free(one);
}

/* The GELU test points: -12 .. 12 in steps of 1e-4, then zeros, tiny, the erf branch point,
 * the density's underflow region and huge values. Returns n points (malloc'ed). */
static float *gelu_points(long *n)
{
    enum { GRID = 240001 };
    static const float sp[] = {0.0f, -0.0f, 1e-30f, -1e-30f, 1e-40f, 0.927734375f, -0.927734375f,
                               0.9277344f, 14.3f, 88.0f, -88.0f, 1e30f, -1e30f};
    *n = GRID + (long)(sizeof sp / sizeof sp[0]);
    float *xv = malloc(sizeof(float) * (size_t)*n);
    for (long i = 0; i < GRID; i++) xv[i] = -12.0f + (float)i * 1e-4f;
    memcpy(xv + GRID, sp, sizeof sp);
    return xv;
}

/* The vectorised GELU forward (its own erf) against the erff loop it replaces (the reference
 * path) on a dense grid of [-12, 12], tiny and special values: within 1.1 ulp of erf, i.e.
 * |fast - ref| <= |x| * 1.2e-7 + 1 ulp of the result; same for any thread count. */
static void test_gelu_fast_matches_reference(void)
{
    long n;
    float *xv = gelu_points(&n);
    float *out[3];
    for (int v = 0; v < 3; v++) {
        lm_ctx c;
        lm_ctx_init(&c, v == 1 ? 2 : 1);
        int old = lm_op_set_path(&c, v == 2 ? LM_OP_PATH_REFERENCE : LM_OP_PATH_FAST);
        lm_tensor *x = lm_tensor_from(&c, 1, (int[]){(int)n}, xv);
        lm_tensor *y = lm_gelu(&c, x);
        lm_op_set_path(&c, old);
        out[v] = malloc(sizeof(float) * n);
        if (y) memcpy(out[v], y->data, sizeof(float) * n);
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    long bad = 0, first = -1;
    for (long i = 0; i < n; i++) {
        double e = fabs((double)out[0][i] - out[2][i]);
        double tol = fabs(xv[i]) * 1.2e-7 + fabs((double)out[2][i]) * 1.2e-7;
        if (!(e <= tol) || out[0][i] != out[1][i]) {
            if (first < 0) first = i;
            bad++;
        }
    }
    CHECK_MSG(bad == 0, "%ld of %ld off; first x = %.9g: fast %.9g, reference %.9g", bad, n,
              first >= 0 ? xv[first] : 0.0, first >= 0 ? out[0][first] : 0.0,
              first >= 0 ? out[2][first] : 0.0);
    for (int v = 0; v < 3; v++) free(out[v]);
    /* inf, -inf and NaN behave as the reference: inf, NaN (-inf * 0), NaN */
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 1, (int[]){3}, (float[]){INFINITY, -INFINITY, NAN});
    lm_tensor *y = lm_gelu(&c, x);
    CHECK(y && isinf(y->data[0]) && y->data[0] > 0 && isnan(y->data[1]) && isnan(y->data[2]));
    lm_ctx_free(&c);
    free(xv);
}

/* The GELU backward's fast path against its erff/expf reference, on the same grid and special
 * values, 1 and 2 threads (identical), and the non-finite inputs. */
static void test_gelu_grad_fast_matches_reference(void)
{
    long n;
    float *xv = gelu_points(&n);
    float *out[3];
    for (int v = 0; v < 3; v++) {
        lm_ctx c;
        lm_ctx_init(&c, v == 1 ? 2 : 1);
        int old = lm_op_set_path(&c, v == 2 ? LM_OP_PATH_REFERENCE : LM_OP_PATH_FAST);
        lm_tensor *x = lm_tensor_from(&c, 1, (int[]){(int)n}, xv);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = lm_gelu(&c, x);
        out[v] = calloc((size_t)n, sizeof(float));
        if (y && lm_backward(&c, y, NULL) == LM_OK && x->grad)
            memcpy(out[v], x->grad->data, sizeof(float) * n);
        lm_op_set_path(&c, old);
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    long bad = 0, first = -1;
    for (long i = 0; i < n; i++) {
        /* gelu' = Phi(x) + x phi(x): both terms' rounding, relative to their sizes */
        double e = fabs((double)out[0][i] - out[2][i]);
        double tol = 4e-7 * (1.0 + fabs(xv[i]) * 0.4);
        if (!(e <= tol) || out[0][i] != out[1][i]) {
            if (first < 0) first = i;
            bad++;
        }
    }
    CHECK_MSG(bad == 0, "%ld of %ld off; first x = %.9g: fast %.9g, reference %.9g", bad, n,
              first >= 0 ? xv[first] : 0.0, first >= 0 ? out[0][first] : 0.0,
              first >= 0 ? out[2][first] : 0.0);
    for (int v = 0; v < 3; v++) free(out[v]);
    free(xv);
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 1, (int[]){3}, (float[]){INFINITY, -INFINITY, NAN});
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = lm_gelu(&c, x);
    CHECK(y && lm_backward(&c, y, NULL) == LM_OK && x->grad);
    if (x->grad) CHECK(isnan(x->grad->data[0]) && isnan(x->grad->data[1]) && isnan(x->grad->data[2]));
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_activation_hand_values);
    RUN(test_activation_matches_reference);
    RUN(test_activation_extremes);
    RUN(test_activation_gradcheck);
    RUN(test_activation_grad_exact);
    RUN(test_activation_errors);
    RUN(test_activation_determinism);
    RUN(test_gelu_fast_matches_reference);
    RUN(test_gelu_grad_fast_matches_reference);
    return check_summary();
}
