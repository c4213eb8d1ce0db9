/* test_concat.c — concat / split: reference values from independent index loops along every
 * dim, split-then-concat round trips, gradients (including more inputs than one tape node
 * holds, and inputs that do not require grad), strided inputs and error cases. */
#include "tests/check.h"

/* Reference concat of n 3-D tensors along dim (all other dims equal). */
static void ref_concat3(lm_tensor *const *xs, int n, int dim, float *out, const int *os)
{
    int off = 0;
    for (int i = 0; i < n; i++) {
        const lm_tensor *x = xs[i];
        for (int a = 0; a < x->shape[0]; a++)
            for (int b = 0; b < x->shape[1]; b++)
                for (int d = 0; d < x->shape[2]; d++) {
                    int ia = a + (dim == 0 ? off : 0), ib = b + (dim == 1 ? off : 0),
                        id = d + (dim == 2 ? off : 0);
                    out[(ia * os[1] + ib) * os[2] + id] =
                        x->data[(a * x->shape[1] + b) * x->shape[2] + d];
                }
        off += x->shape[dim];
    }
}

static void test_concat_reference_every_dim(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 31);
    int base[3] = {2, 3, 4}, extra[3] = {1, 4, 2};
    for (int dim = 0; dim < 3; dim++) {
        lm_tensor *xs[3];
        int os[3] = {base[0], base[1], base[2]};
        for (int i = 0; i < 3; i++) {
            int s[3] = {base[0], base[1], base[2]};
            s[dim] = extra[i];
            xs[i] = lm_tensor_uniform(&c, 3, s, &r, -1, 1);
        }
        os[dim] = extra[0] + extra[1] + extra[2];
        lm_tensor *y = lm_concat(&c, xs, 3, dim - 3); /* negative dim */
        CHECK_CTX_OK(&c);
        CHECK(y && y->shape[0] == os[0] && y->shape[1] == os[1] && y->shape[2] == os[2]);
        float e[7 * 7 * 7];
        ref_concat3(xs, 3, dim, e, os);
        if (y) CHECK_ARRAY_CLOSE(y->data, e, (long)os[0] * os[1] * os[2], 0, 0);
    }
    /* hand values: [[1 2]] ++ [[3 4] [5 6]] along dim 0; [[1] [2]] ++ [[3 4] [5 6]] dim 1 */
    lm_tensor *a = lm_tensor_from(&c, 2, (int[]){1, 2}, (float[]){1, 2});
    lm_tensor *b = lm_tensor_from(&c, 2, (int[]){2, 2}, (float[]){3, 4, 5, 6});
    lm_tensor *ab = lm_concat(&c, (lm_tensor *[]){a, b}, 2, 0);
    if (ab) CHECK_ARRAY_CLOSE(ab->data, ((float[]){1, 2, 3, 4, 5, 6}), 6, 0, 0);
    lm_tensor *a2 = lm_tensor_from(&c, 2, (int[]){2, 1}, (float[]){1, 2});
    lm_tensor *ab2 = lm_concat(&c, (lm_tensor *[]){a2, b}, 2, 1);
    if (ab2) CHECK_ARRAY_CLOSE(ab2->data, ((float[]){1, 3, 4, 2, 5, 6}), 6, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* A big concat along channels of B x C x H x W (several parallel chunks per row). */
static void test_concat_large(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 32);
    lm_tensor *a = lm_tensor_uniform(&c, 4, (int[]){2, 3, 40, 60}, &r, -1, 1);
    lm_tensor *b = lm_tensor_uniform(&c, 4, (int[]){2, 5, 40, 60}, &r, -1, 1);
    lm_tensor_set_requires_grad(a, 1);
    lm_tensor_set_requires_grad(b, 1);
    lm_tensor *y = lm_concat(&c, (lm_tensor *[]){a, b}, 2, 1);
    CHECK(y && y->shape[1] == 8);
    lm_tensor *seed = lm_tensor_uniform(&c, 4, (int[]){2, 8, 40, 60}, &r, -1, 1);
    CHECK(lm_backward(&c, y, seed) == LM_OK);
    int bad = 0, badg = 0;
    for (int n = 0; y && n < 2; n++)
        for (int ch = 0; ch < 8; ch++)
            for (int p = 0; p < 2400; p++) {
                const lm_tensor *src = ch < 3 ? a : b;
                long k = ch < 3 ? (n * 3 + ch) * 2400 + p : (n * 5 + ch - 3) * 2400 + p;
                bad += y->data[(n * 8 + ch) * 2400 + p] != src->data[k];
                badg += src->grad->data[k] != seed->data[(n * 8 + ch) * 2400 + p];
            }
    CHECK(bad == 0);
    CHECK(badg == 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_split_then_concat(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 33);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 7, 3, 5}, &r, -1, 1);
    for (int dim = 0; dim < 4; dim++) {
        int n = x->shape[dim] >= 3 ? 3 : 2, sizes[3];
        for (int i = 0; i < n - 1; i++) sizes[i] = 1;
        sizes[n - 1] = x->shape[dim] - (n - 1);
        lm_tensor *parts[3];
        CHECK(lm_split(&c, x, dim, n, sizes, parts) == LM_OK);
        for (int i = 0; i < n; i++) CHECK(parts[i] && parts[i]->shape[dim] == sizes[i]);
        lm_tensor *y = lm_concat(&c, parts, n, dim);
        CHECK(y && lm_tensor_same_shape(y, x));
        if (y) CHECK_ARRAY_CLOSE(y->data, x->data, lm_tensor_numel(x), 0, 0);
    }
    /* split values: the middle part of dim 1 is an independent slice copy */
    lm_tensor *parts[3];
    CHECK(lm_split(&c, x, -3, 3, (int[]){2, 4, 1}, parts) == LM_OK);
    lm_tensor *ref = lm_contiguous(&c, lm_slice(&c, x, 1, 2, 4));
    if (parts[1]) CHECK_ARRAY_CLOSE(parts[1]->data, ref->data, lm_tensor_numel(ref), 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_concat(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    return lm_concat(c, in, nin, *(int *)u);
}
/* split in three, return the middle part */
static lm_tensor *fn_split_mid(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *p[3];
    lm_split(c, in[0], 2, 3, (int[]){1, 2, 2}, p);
    return check_with_input(c, p[1], in[0]);
}
/* split in two and put the parts back swapped (every part reaches the output) */
static lm_tensor *fn_split_swap(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *p[2];
    lm_split(c, in[0], 1, 2, (int[]){1, 2}, p);
    lm_tensor *q[2] = {p[1], p[0]};
    return lm_concat(c, q, 2, 1);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 34);
    /* 11 inputs (> LM_MAX_INPUTS): several tape nodes share the output */
    lm_tensor *xs[11];
    for (int i = 0; i < 11; i++) {
        xs[i] = lm_tensor_uniform(&c, 3, (int[]){2, 1 + i % 3, 3}, &r, -1, 1);
        lm_tensor_set_requires_grad(xs[i], 1);
    }
    int dim = 1;
    CHECK_GRAD(&c, fn_concat, xs, 11, &dim, NULL);
    /* only some inputs require grad: the others get none, the rest are right */
    lm_tensor_set_requires_grad(xs[0], 0);
    lm_tensor_set_requires_grad(xs[9], 0);
    CHECK_GRAD(&c, fn_concat, xs, 11, &dim, NULL);
    CHECK(xs[0]->grad == NULL && xs[9]->grad == NULL && xs[10]->grad != NULL);
    lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){2, 3, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_split_mid, &x, 1, NULL, NULL);
    CHECK_GRAD(&c, fn_split_swap, &x, 1, NULL, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Exact gradient of split: ones on the middle band, zero elsewhere. */
static void test_split_gradient_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){2, 2, 5});
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *p[3];
    CHECK(lm_split(&c, x, 2, 3, (int[]){1, 2, 2}, p) == LM_OK);
    CHECK(lm_backward(&c, p[1], NULL) == LM_OK);
    for (int i = 0; i < 20; i++) {
        int d = i % 5;
        CHECK(x->grad->data[i] == (d >= 1 && d < 3 ? 1.0f : 0.0f));
    }
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    lm_tensor *b = lm_tensor_zeros(&c, 3, (int[]){2, 5, 4});
    lm_tensor *d2 = lm_tensor_zeros(&c, 2, (int[]){2, 3});
    CHECK(lm_concat(&c, (lm_tensor *[]){a, b}, 2, 0) == NULL); /* dim 1 differs */
    CHECK(strstr(c.msg, "concat") && strstr(c.msg, "2x5x4") && strstr(c.msg, "2x3x4"));
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_concat(&c, (lm_tensor *[]){a, d2}, 2, 1) == NULL); /* ndim differs */
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_concat(&c, (lm_tensor *[]){a, b}, 2, 3) == NULL);
    CHECK(strstr(c.msg, "concat") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_concat(&c, (lm_tensor *[]){a}, 0, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_concat(&c, (lm_tensor *[]){a, NULL}, 2, 1) == NULL);
    CHECK(strstr(c.msg, "concat") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_tensor *p[3] = {a, a, a};
    CHECK(lm_split(&c, a, 1, 2, (int[]){1, 1}, p) == LM_ERR_SHAPE); /* sum 2 != 3 */
    CHECK(p[0] == NULL && p[1] == NULL && strstr(c.msg, "split") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_split(&c, a, 1, 2, (int[]){3, 0}, p) == LM_ERR_ARG);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_split(&c, a, 3, 1, (int[]){4}, p) == LM_ERR_ARG);
    CHECK(strstr(c.msg, "split") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_split(&c, NULL, 0, 1, (int[]){2}, p) != LM_OK && p[0] == NULL);
    CHECK(strstr(c.msg, "split") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_concat_reference_every_dim);
    RUN(test_concat_large);
    RUN(test_split_then_concat);
    RUN(test_gradients);
    RUN(test_split_gradient_exact);
    RUN(test_errors);
    return check_summary();
}
