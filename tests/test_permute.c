/* test_permute.c — permute / transpose: reference values from an independent multi-index
 * loop, inverse-permutation round trips, gradients, strided inputs and error cases. */
#include "tests/check.h"

/* Reference for up to 5 dims: walk every multi-index of x, place at the permuted index. */
static void ref_permute(const float *x, float *y, int nd, const int *shape, const int *perm)
{
    int ys[5], idx[5] = {0, 0, 0, 0, 0};
    long n = 1;
    for (int d = 0; d < nd; d++) {
        ys[d] = shape[perm[d]];
        n *= shape[d];
    }
    for (long k = 0; k < n; k++) { /* idx = multi-index of flat k in x */
        long o = 0;
        for (int d = 0; d < nd; d++) o = o * ys[d] + idx[perm[d]];
        y[o] = x[k];
        for (int d = nd - 1; d >= 0; d--) {
            if (++idx[d] < shape[d]) break;
            idx[d] = 0;
        }
    }
}

static void test_permute_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 21);
    const int shape5[5] = {2, 3, 4, 5, 3}, perms5[3][5] = {{4, 2, 0, 3, 1}, {0, 1, 2, 4, 3},
                                                          {1, 0, 4, 3, 2}};
    lm_tensor *x = lm_tensor_uniform(&c, 5, shape5, &r, -1, 1);
    lm_tensor *e = lm_tensor_new(&c, 1, (int[]){360});
    for (int k = 0; k < 3; k++) {
        lm_tensor *y = lm_permute(&c, x, perms5[k]);
        CHECK_CTX_OK(&c);
        if (!y) continue;
        for (int d = 0; d < 5; d++) CHECK(y->shape[d] == shape5[perms5[k][d]]);
        ref_permute(x->data, e->data, 5, shape5, perms5[k]);
        CHECK_ARRAY_CLOSE(y->data, e->data, 360, 0, 0);
    }
    /* 2-D: hand values */
    float m[6] = {1, 2, 3, 4, 5, 6}, mt[6] = {1, 4, 2, 5, 3, 6};
    lm_tensor *a = lm_tensor_from(&c, 2, (int[]){2, 3}, m);
    lm_tensor *at = lm_transpose(&c, a, 0, 1);
    CHECK(at && at->shape[0] == 3 && at->shape[1] == 2);
    if (at) CHECK_ARRAY_CLOSE(at->data, mt, 6, 0, 0);
    /* transpose with negative dims = permute with the swap */
    lm_tensor *x4 = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -1, 1);
    lm_tensor *t4 = lm_transpose(&c, x4, -1, 1);
    ref_permute(x4->data, e->data, 4, x4->shape, (int[]){0, 3, 2, 1});
    CHECK(t4 && t4->shape[1] == 5 && t4->shape[3] == 3);
    if (t4) CHECK_ARRAY_CLOSE(t4->data, e->data, 120, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_inverse_round_trip(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 22);
    int perm[4] = {2, 0, 3, 1}, inv[4];
    for (int d = 0; d < 4; d++) inv[perm[d]] = d;
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){3, 4, 5, 6}, &r, -1, 1);
    lm_tensor *back = lm_permute(&c, lm_permute(&c, x, perm), inv);
    CHECK(back && lm_tensor_same_shape(back, x));
    if (back) CHECK_ARRAY_CLOSE(back->data, x->data, 360, 0, 0);
    lm_tensor *tt = lm_transpose(&c, lm_transpose(&c, x, 0, 2), 2, 0);
    if (tt) CHECK_ARRAY_CLOSE(tt->data, x->data, 360, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_strided_input(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 23);
    lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){4, 5, 6}, &r, -1, 1);
    lm_tensor *s = lm_slice(&c, x, 1, 1, 3); /* 4 x 3 x 6, strided */
    lm_tensor *y = lm_permute(&c, s, (int[]){2, 0, 1});
    lm_tensor *sc = lm_contiguous(&c, s);
    float e[72];
    ref_permute(sc->data, e, 3, sc->shape, (int[]){2, 0, 1});
    if (y) CHECK_ARRAY_CLOSE(y->data, e, 72, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_permute(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    return lm_permute(c, in[0], u);
}
static lm_tensor *fn_transpose(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    return lm_transpose(c, in[0], 0, 2);
}
/* both branches use x: gradients from two permutes must add up */
static lm_tensor *fn_permute_twice(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *a = lm_permute(c, in[0], (int[]){1, 0, 2});
    lm_tensor *b = lm_transpose(c, lm_permute(c, in[0], (int[]){1, 2, 0}), 1, 2);
    lm_tensor *ab[2] = {a, b};
    return lm_concat(c, ab, 2, 0);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 24);
    int perm[4] = {3, 1, 0, 2};
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_permute, &x, 1, perm, NULL);
    lm_tensor *z = lm_tensor_uniform(&c, 3, (int[]){3, 4, 2}, &r, -1, 1);
    lm_tensor_set_requires_grad(z, 1);
    CHECK_GRAD(&c, fn_transpose, &z, 1, NULL, NULL);
    CHECK_GRAD(&c, fn_permute_twice, &z, 1, NULL, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_permute(&c, x, (int[]){0, 0, 1}) == NULL); /* repeated dim */
    CHECK(strstr(c.msg, "permute") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_permute(&c, x, (int[]){0, 3, 1}) == NULL); /* out of range */
    CHECK(strstr(c.msg, "permute") != NULL && strstr(c.msg, "2x3x4") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_permute(&c, x, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_transpose(&c, x, 0, 3) == NULL);
    CHECK(strstr(c.msg, "transpose") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_transpose(&c, x, -4, 1) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_transpose(&c, NULL, 0, 1) == NULL);
    CHECK(strstr(c.msg, "transpose") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_permute_reference);
    RUN(test_inverse_round_trip);
    RUN(test_strided_input);
    RUN(test_gradients);
    RUN(test_errors);
    return check_summary();
}
