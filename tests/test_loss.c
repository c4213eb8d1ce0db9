/* test_loss.c — L1 and MSE losses (loss.c): hand values, an independent double reference,
 * gradient checks for pred and target, exact gradients incl. sign(0) = 0, scaling by the
 * incoming gradient, shape errors and determinism across runs and thread counts. */
#include "tests/check.h"
#include <stdlib.h>

static lm_tensor *loss_of(lm_ctx *c, int mse, lm_tensor *p, lm_tensor *t)
{
    return mse ? lm_mse_loss(c, p, t) : lm_l1_loss(c, p, t);
}

static void test_loss_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *p = lm_tensor_from(&c, 2, (int[]){2, 2}, (float[]){1, 2, 3, 4});
    lm_tensor *t = lm_tensor_from(&c, 2, (int[]){2, 2}, (float[]){0, 2, 5, 3.5f});
    lm_tensor *l1 = lm_l1_loss(&c, p, t);
    CHECK(l1 && l1->ndim == 1 && l1->shape[0] == 1);
    CHECK_CLOSE(l1->data[0], (1 + 0 + 2 + 0.5) / 4, 0, 0); /* 0.875 */
    lm_tensor *l2 = lm_mse_loss(&c, p, t);
    CHECK(l2 && l2->ndim == 1 && l2->shape[0] == 1);
    CHECK_CLOSE(l2->data[0], (1 + 0 + 4 + 0.25) / 4, 0, 0); /* 1.3125 */
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_loss_matches_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 14);
    int sizes[3] = {7, 8191, 100003}; /* one chunk, exactly below a chunk, many chunks */
    for (int k = 0; k < 3; k++) {
        lm_tensor *p = lm_tensor_uniform(&c, 1, &sizes[k], &r, -3, 3);
        lm_tensor *t = lm_tensor_uniform(&c, 1, &sizes[k], &r, -3, 3);
        double s1 = 0, s2 = 0;
        for (int i = 0; i < sizes[k]; i++) {
            double d = (double)p->data[i] - t->data[i];
            s1 += fabs(d);
            s2 += d * d;
        }
        CHECK_CLOSE(lm_l1_loss(&c, p, t)->data[0], s1 / sizes[k], 0, 1e-6);
        CHECK_CLOSE(lm_mse_loss(&c, p, t)->data[0], s2 / sizes[k], 0, 1e-6);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_loss(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    return loss_of(c, *(int *)user, in[0], in[1]);
}

/* Both inputs require grad; |p - t| >= 0.1 keeps L1 away from its kink. */
static void test_loss_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 15);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.atol = 1e-4;
    o.rtol = 1e-2;
    for (int mse = 0; mse < 2; mse++) {
        lm_tensor *in[2] = {lm_tensor_uniform(&c, 3, (int[]){2, 3, 5}, &r, -1, 1),
                            lm_tensor_new(&c, 3, (int[]){2, 3, 5})};
        for (int i = 0; i < 30; i++) {
            float d = 0.1f + 0.4f * lm_rng_uniform(&r);
            in[1]->data[i] = in[0]->data[i] + (i % 3 ? d : -d);
        }
        lm_tensor_set_requires_grad(in[0], 1);
        lm_tensor_set_requires_grad(in[1], 1);
        int before = check_failures_;
        CHECK_GRAD(&c, fn_loss, in, 2, &mse, &o);
        if (check_failures_ != before) fprintf(stderr, "  %s\n", mse ? "mse" : "l1");
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

/* dp = sign(p - t) g / N (sign(0) = 0) or 2 (p - t) g / N; dt = -dp; g = 3 via a scale. */
static void test_loss_grad_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float pv[5] = {1, 2, 3, -1, 0.5f}, tv[5] = {0, 2, 4, -1, 0.25f};
    for (int mse = 0; mse < 2; mse++) {
        lm_tensor *p = lm_tensor_from(&c, 1, (int[]){5}, pv);
        lm_tensor *t = lm_tensor_from(&c, 1, (int[]){5}, tv);
        lm_tensor_set_requires_grad(p, 1);
        lm_tensor_set_requires_grad(t, 1);
        CHECK(lm_backward(&c, lm_scale(&c, loss_of(&c, mse, p, t), 3.0f), NULL) == LM_OK);
        float l1g[5] = {0.6f, 0, -0.6f, 0, 0.6f};         /* 3 * sign / 5 */
        float l2g[5] = {1.2f, 0, -1.2f, 0, 0.3f};         /* 3 * 2 d / 5 */
        CHECK_ARRAY_CLOSE(p->grad->data, mse ? l2g : l1g, 5, 1e-7, 1e-6);
        for (int i = 0; i < 5; i++) CHECK(t->grad->data[i] == -p->grad->data[i]);
        lm_ctx_reset(&c);
    }
    /* only the target requires grad: pred gets none */
    lm_tensor *p = lm_tensor_from(&c, 1, (int[]){5}, pv);
    lm_tensor *t = lm_tensor_from(&c, 1, (int[]){5}, tv);
    lm_tensor_set_requires_grad(t, 1);
    CHECK(lm_backward(&c, lm_l1_loss(&c, p, t), NULL) == LM_OK);
    CHECK(p->grad == NULL);
    CHECK_ARRAY_CLOSE(t->grad->data, ((float[]){-0.2f, 0, 0.2f, 0, -0.2f}), 5, 1e-7, 1e-6);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_loss_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_zeros(&c, 2, (int[]){2, 3});
    lm_tensor *b = lm_tensor_zeros(&c, 2, (int[]){3, 2});
    lm_tensor *d = lm_tensor_zeros(&c, 3, (int[]){1, 2, 3}); /* same numel, not the same shape */
    const char *names[2] = {"l1_loss", "mse_loss"};
    for (int mse = 0; mse < 2; mse++) {
        CHECK(loss_of(&c, mse, a, b) == NULL);
        CHECK_MSG(strstr(c.msg, names[mse]) && strstr(c.msg, "2x3") && strstr(c.msg, "3x2"),
                  "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        CHECK(loss_of(&c, mse, a, d) == NULL);
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        CHECK(loss_of(&c, mse, NULL, a) == NULL);
        CHECK_MSG(strstr(c.msg, names[mse]) != NULL, "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    }
    /* strided pred is copied first */
    lm_tensor *m = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 4, 5, 6});
    lm_tensor *z = lm_tensor_zeros(&c, 2, (int[]){2, 2});
    lm_tensor *l = lm_l1_loss(&c, lm_slice(&c, m, 1, 1, 2), z);
    if (l) CHECK_CLOSE(l->data[0], (2 + 3 + 5 + 6) / 4.0, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void run_big(int nthreads, float *out, long n)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 41);
    int shape[4] = {2, 33, 64, 66};
    lm_tensor *p = lm_tensor_uniform(&c, 4, shape, &r, 0, 1);
    lm_tensor *t = lm_tensor_uniform(&c, 4, shape, &r, 0, 1);
    lm_tensor_set_requires_grad(p, 1);
    lm_tensor_set_requires_grad(t, 1);
    lm_tensor *l = lm_add(&c, lm_l1_loss(&c, p, t), lm_mse_loss(&c, p, t));
    CHECK(lm_backward(&c, l, NULL) == LM_OK);
    out[0] = l->data[0];
    memcpy(out + 1, p->grad->data, (size_t)n * sizeof(float));
    memcpy(out + 1 + n, t->grad->data, (size_t)n * sizeof(float));
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_loss_determinism(void)
{
    long n = 2L * 33 * 64 * 66;
    size_t bytes = (size_t)(2 * n + 1) * sizeof(float);
    float *a = malloc(bytes), *b = malloc(bytes), *one = malloc(bytes);
    for (int nt = 1; nt <= 2; nt++) {
        run_big(nt, a, n);
        run_big(nt, b, n);
        CHECK_MSG(memcmp(a, b, bytes) == 0, "nthreads %d: runs differ", nt);
        if (nt == 1) memcpy(one, a, bytes);
    }
    CHECK_MSG(memcmp(one, a, bytes) == 0, "1 and 2 threads differ");
    free(a);
    free(b);
    free(one);
}

int main(void)
{
    RUN(test_loss_hand_values);
    RUN(test_loss_matches_reference);
    RUN(test_loss_gradcheck);
    RUN(test_loss_grad_exact);
    RUN(test_loss_errors);
    RUN(test_loss_determinism);
    return check_summary();
}
