/* test_pad.c — pad2d zero and reflect: hand-computed values (PyTorch 'reflect' excludes the
 * edge), an independent periodic-mirror reference, gradients (finite differences and exact
 * counts of how often each input is read), strided inputs and error cases. */
#include "tests/check.h"

/* Source index of padded position i (already shifted by the pad) in 0..n-1, -1 for zero:
 * reflection written as a mirror with period 2 (n - 1). */
static int ref_index(int i, int n, int reflect)
{
    if (!reflect) return i >= 0 && i < n ? i : -1;
    if (n == 1) return 0;
    int m = 2 * (n - 1), j = ((i % m) + m) % m;
    return j < n ? j : m - j;
}

static void ref_pad(const lm_tensor *x, float *out, int t, int b, int l, int r, int reflect)
{
    int P = x->shape[0] * x->shape[1], H = x->shape[2], W = x->shape[3];
    int Ho = H + t + b, Wo = W + l + r;
    for (int p = 0; p < P; p++)
        for (int Y = 0; Y < Ho; Y++)
            for (int X = 0; X < Wo; X++) {
                int iy = ref_index(Y - t, H, reflect), ix = ref_index(X - l, W, reflect);
                out[(p * Ho + Y) * Wo + X] =
                    iy < 0 || ix < 0 ? 0.0f : x->data[(p * H + iy) * W + ix];
            }
}

static void test_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float v[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 3, 3}, v);
    lm_tensor *y = lm_pad2d(&c, x, 2, 1, 1, 2, LM_PAD_REFLECT);
    float e[36] = {8, 7, 8, 9, 8, 7, 5, 4, 5, 6, 5, 4, 2, 1, 2, 3, 2, 1,
                   5, 4, 5, 6, 5, 4, 8, 7, 8, 9, 8, 7, 5, 4, 5, 6, 5, 4};
    CHECK(y && y->shape[2] == 6 && y->shape[3] == 6);
    if (y) CHECK_ARRAY_CLOSE(y->data, e, 36, 0, 0);
    lm_tensor *x2 = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 2}, (float[]){1, 2, 3, 4});
    lm_tensor *z = lm_pad2d(&c, x2, 1, 0, 0, 1, LM_PAD_ZERO);
    float ez[9] = {0, 0, 0, 1, 2, 0, 3, 4, 0};
    CHECK(z && z->shape[2] == 3 && z->shape[3] == 3);
    if (z) CHECK_ARRAY_CLOSE(z->data, ez, 9, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_reference_random(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 41);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 5, 7}, &r, -1, 1);
    const int pads[4][4] = {{0, 0, 0, 0}, {4, 4, 6, 6}, {1, 3, 0, 5}, {0, 2, 3, 0}};
    float e[2 * 3 * 13 * 19];
    for (int k = 0; k < 4; k++)
        for (int mode = 0; mode < 2; mode++) {
            const int *p = pads[k];
            lm_tensor *y = lm_pad2d(&c, x, p[0], p[1], p[2], p[3], (lm_pad_mode)mode);
            CHECK_CTX_OK(&c);
            if (!y) continue;
            CHECK(y->shape[2] == 5 + p[0] + p[1] && y->shape[3] == 7 + p[2] + p[3]);
            ref_pad(x, e, p[0], p[1], p[2], p[3], mode);
            CHECK_ARRAY_CLOSE(y->data, e, lm_tensor_numel(y), 0, 0);
        }
    /* a strided input pads like its contiguous copy */
    lm_tensor *s = lm_slice(&c, x, 3, 1, 4);
    lm_tensor *ys = lm_pad2d(&c, s, 2, 2, 3, 3, LM_PAD_REFLECT);
    ref_pad(lm_contiguous(&c, s), e, 2, 2, 3, 3, 1);
    if (ys) CHECK_ARRAY_CLOSE(ys->data, e, lm_tensor_numel(ys), 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

typedef struct pad_case { int t, b, l, r; lm_pad_mode mode; } pad_case;
static lm_tensor *fn_pad(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const pad_case *p = u;
    return check_with_input(c, lm_pad2d(c, in[0], p->t, p->b, p->l, p->r, p->mode), in[0]);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 42);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 2, 4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    pad_case zero = {1, 2, 3, 0, LM_PAD_ZERO}, refl = {3, 2, 1, 4, LM_PAD_REFLECT};
    CHECK_GRAD(&c, fn_pad, &x, 1, &zero, NULL);
    CHECK_GRAD(&c, fn_pad, &x, 1, &refl, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* With an all-ones seed, each input's gradient counts the outputs that read it. */
static void test_gradient_counts(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    const int H = 4, W = 3, t = 3, b = 2, l = 2, r = 1;
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){3, 1, H, W});
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = lm_pad2d(&c, x, t, b, l, r, LM_PAD_REFLECT);
    CHECK(lm_backward(&c, y, NULL) == LM_OK);
    float cnt[4 * 3] = {0};
    for (int Y = 0; Y < H + t + b; Y++)
        for (int X = 0; X < W + l + r; X++)
            cnt[ref_index(Y - t, H, 1) * W + ref_index(X - l, W, 1)] += 1.0f;
    for (int p = 0; p < 3 && x->grad; p++) CHECK_ARRAY_CLOSE(x->grad->data + p * 12, cnt, 12, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 2, 3, 4});
    CHECK(lm_pad2d(&c, x, 3, 0, 0, 0, LM_PAD_REFLECT) == NULL); /* pad == H */
    CHECK(strstr(c.msg, "pad2d") != NULL && strstr(c.msg, "1x2x3x4") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_pad2d(&c, x, 0, 0, 0, 4, LM_PAD_REFLECT) == NULL); /* pad == W */
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_pad2d(&c, x, 5, 5, 5, 5, LM_PAD_ZERO) != NULL); /* zero pads may be large */
    CHECK_CTX_OK(&c);
    CHECK(lm_pad2d(&c, x, -1, 0, 0, 0, LM_PAD_ZERO) == NULL);
    CHECK(strstr(c.msg, "pad2d") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_pad2d(&c, x, 1, 1, 1, 1, (lm_pad_mode)7) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_tensor *x3 = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_pad2d(&c, x3, 1, 1, 1, 1, LM_PAD_ZERO) == NULL);
    CHECK(strstr(c.msg, "pad2d") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_pad2d(&c, NULL, 1, 1, 1, 1, LM_PAD_ZERO) == NULL);
    CHECK(strstr(c.msg, "pad2d") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_hand_values);
    RUN(test_reference_random);
    RUN(test_gradients);
    RUN(test_gradient_counts);
    RUN(test_errors);
    return check_summary();
}
