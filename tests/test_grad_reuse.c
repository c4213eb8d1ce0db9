/* test_grad_reuse.c — lm_backward's reuse of intermediate gradient buffers (autograd/tape.c)
 * against the reference behaviour (every gradient kept, lm_backward_set_grad_reuse(c, 0)):
 * identical gradients on a branchy graph and on whole models (han-tiny, srnet-tiny: the same
 * bits), what stays readable afterwards (leaves, the root, parameters), lower arena peak, and
 * a repeated backward call. */
#include "models/model.h"
#include "tests/check.h"
#include <stdlib.h>
#include "tests/model_fixture.h"

/* x -> a = 2x + 1 -> b = tanh(a), c = a * b, d = sigmoid(c) + a, e = d * x (x reused late) */
static lm_tensor *branchy(lm_ctx *c, lm_tensor *x, lm_tensor **mid)
{
    lm_tensor *a = lm_affine(c, x, 2.0f, 1.0f);
    lm_tensor *b = lm_tanh(c, a);
    lm_tensor *cc = lm_mul(c, a, b);
    lm_tensor *d = lm_add(c, lm_sigmoid(c, cc), a);
    *mid = b;
    return lm_mul(c, d, x);
}

static void test_branchy_graph(void)
{
    float *g[2] = {0};
    for (int reuse = 0; reuse < 2; reuse++) {
        lm_ctx c;
        lm_ctx_init(&c, 2);
        lm_backward_set_grad_reuse(&c, reuse);
        lm_rng r;
        lm_rng_seed(&r, 41);
        lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){3, 7, 50}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *mid, *y = branchy(&c, x, &mid);
        lm_tensor *seed = lm_tensor_uniform(&c, 3, (int[]){3, 7, 50}, &r, -1, 1);
        CHECK(y && lm_backward(&c, y, seed) == LM_OK);
        CHECK(x->grad && y->grad);                   /* leaf and root: kept */
        CHECK(reuse ? mid->grad == NULL : mid->grad != NULL);
        if (x->grad) {
            g[reuse] = malloc(sizeof(float) * 1050);
            memcpy(g[reuse], x->grad->data, sizeof(float) * 1050);
        }
        /* with reuse, a second backward from the same root starts from fresh intermediate
         * gradients: the root's gradient is now 2 seed, so the leaf gets 2 G more (kept
         * intermediates would count the first pass again) */
        if (reuse) {
            CHECK(lm_backward(&c, y, seed) == LM_OK);
            if (x->grad && g[reuse])
                for (int i = 0; i < 1050; i++)
                    CHECK_CLOSE(x->grad->data[i], 3.0 * g[reuse][i], 1e-6, 1e-5);
        }
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    if (g[0] && g[1]) CHECK_ARRAY_CLOSE(g[1], g[0], 1050, 0, 0);
    free(g[0]), free(g[1]);
}

/* A chain of 40 same-size ops: without reuse the backward allocates 40 gradients, with reuse
 * two or three are alive at once. */
static void test_chain_peak(void)
{
    size_t peak[2];
    for (int reuse = 0; reuse < 2; reuse++) {
        lm_ctx c;
        lm_ctx_init(&c, 1);
        lm_backward_set_grad_reuse(&c, reuse);
        lm_rng r;
        lm_rng_seed(&r, 42);
        lm_tensor *x = lm_tensor_uniform(&c, 2, (int[]){256, 256}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = x;
        for (int i = 0; i < 40; i++) y = i % 2 ? lm_tanh(&c, y) : lm_affine(&c, y, 0.9f, 0.1f);
        size_t fwd = c.arena.in_use;
        CHECK(lm_backward(&c, y, NULL) == LM_OK);
        peak[reuse] = c.arena.high_water - fwd;
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    const size_t one = 256 * 256 * sizeof(float);
    CHECK_MSG(peak[0] >= 40 * one && peak[1] <= 4 * one, "backward allocated %zu MB without "
              "reuse, %zu MB with", peak[0] >> 20, peak[1] >> 20);
}


/* Parameter and input gradients of a whole model: the same bits with and without reuse. */
static void model_grads_same(const char *preset, int H, int W)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 3, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    lm_param *g1 = lm_params_find(&m->params, "la.gamma");
    if (g1) g1->t.data[0] = 0.5f;
    size_t np = m->params.total;
    float *g[2];
    for (int reuse = 0; reuse < 2; reuse++) {
        lm_ctx c;
        lm_ctx_init(&c, 2);
        lm_backward_set_grad_reuse(&c, reuse);
        lm_rng r;
        lm_rng_seed(&r, 43);
        lm_params_zero_grad(&m->params);
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 1, H, W}, &r, 0, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = lm_tensor_uniform(&c, 4, (int[]){2, m->out_channels, H, W}, &r, 0, 1);
        lm_tensor *loss = lm_l1_loss(&c, lm_model_forward(&c, m, x), y);
        CHECK(loss && lm_backward(&c, loss, NULL) == LM_OK);
        long nx = 2L * H * W;
        g[reuse] = calloc(np + (size_t)nx, sizeof(float));
        memcpy(g[reuse], m->params.grad, sizeof(float) * np);
        if (x->grad) memcpy(g[reuse] + np, x->grad->data, sizeof(float) * (size_t)nx);
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    CHECK_ARRAY_CLOSE(g[1], g[0], (long)np + 2L * H * W, 0, 0);
    free(g[0]), free(g[1]);
    lm_model_free(m);
}

static void test_models_same_bits(void)
{
    model_grads_same("han-tiny", 12, 16);
    model_grads_same("srnet-tiny", 18, 16);
    model_grads_same("mcan-tiny", 12, 16);
}

int main(void)
{
    RUN(test_branchy_graph);
    RUN(test_chain_peak);
    RUN(test_models_same_bits);
    return check_summary();
}
