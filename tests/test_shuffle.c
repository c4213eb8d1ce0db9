/* test_shuffle.c — pixel_unshuffle / pixel_shuffle: reference values from an independent
 * index loop, round trips, gradients, strided inputs and error cases; the per-phase mean and
 * scale (tensor/ops/phase.c) against their definitions through the shuffles, by hand and with
 * gradients. */
#include "tests/check.h"

/* Reference: out[b, ch*fy*fx + i*fx + j, y, x] = in[b, ch, fy*y + i, fx*x + j]. */
static void ref_unshuffle(const float *in, float *out, int B, int C, int H, int W, int fy, int fx)
{
    int hs = H / fy, ws = W / fx;
    for (int b = 0; b < B; b++)
        for (int ch = 0; ch < C; ch++)
            for (int i = 0; i < fy; i++)
                for (int j = 0; j < fx; j++)
                    for (int y = 0; y < hs; y++)
                        for (int x = 0; x < ws; x++) {
                            int oc = ch * fy * fx + i * fx + j;
                            out[((b * C * fy * fx + oc) * hs + y) * ws + x] =
                                in[((b * C + ch) * H + fy * y + i) * W + fx * x + j];
                        }
}

static void test_unshuffle_reference_3x4(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 11);
    int B = 2, C = 2, H = 66, W = 64;
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, C, H, W}, &r, -1, 1);
    lm_tensor *y = lm_pixel_unshuffle(&c, x, 3, 4);
    CHECK_CTX_OK(&c);
    CHECK(y && y->shape[0] == B && y->shape[1] == 24 && y->shape[2] == 22 && y->shape[3] == 16);
    lm_tensor *e = lm_tensor_new(&c, 4, (int[]){B, 24, 22, 16});
    ref_unshuffle(x->data, e->data, B, C, H, W, 3, 4);
    if (y) CHECK_ARRAY_CLOSE(y->data, e->data, lm_tensor_numel(e), 0, 0);
    lm_ctx_free(&c);
}

/* Hand-written: a 1 x 1 x 2 x 4 input, factors 2 x 2 -> 4 channels of 1 x 2. */
static void test_unshuffle_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float v[8] = {0, 1, 2, 3, 4, 5, 6, 7}; /* rows {0 1 2 3}, {4 5 6 7} */
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 4}, v);
    lm_tensor *y = lm_pixel_unshuffle(&c, x, 2, 2);
    /* channel (i, j): (0,0) = {0, 2}, (0,1) = {1, 3}, (1,0) = {4, 6}, (1,1) = {5, 7} */
    float expect[8] = {0, 2, 1, 3, 4, 6, 5, 7};
    CHECK(y && y->shape[1] == 4 && y->shape[2] == 1 && y->shape[3] == 2);
    if (y) CHECK_ARRAY_CLOSE(y->data, expect, 8, 0, 0);
    lm_tensor *z = lm_pixel_shuffle(&c, y, 2, 2);
    if (z) CHECK_ARRAY_CLOSE(z->data, v, 8, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_round_trips(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 12);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 12, 20}, &r, -1, 1);
    lm_tensor *back = lm_pixel_shuffle(&c, lm_pixel_unshuffle(&c, x, 3, 5), 3, 5);
    CHECK(back && lm_tensor_same_shape(back, x));
    if (back) CHECK_ARRAY_CLOSE(back->data, x->data, lm_tensor_numel(x), 0, 0);
    lm_tensor *z = lm_tensor_uniform(&c, 4, (int[]){1, 12, 4, 5}, &r, -1, 1);
    lm_tensor *zb = lm_pixel_unshuffle(&c, lm_pixel_shuffle(&c, z, 2, 3), 2, 3);
    CHECK(zb && lm_tensor_same_shape(zb, z));
    if (zb) CHECK_ARRAY_CLOSE(zb->data, z->data, lm_tensor_numel(z), 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* A strided (sliced) input gives the same result as its contiguous copy. */
static void test_strided_input(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 13);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, 2, 6, 12}, &r, -1, 1);
    lm_tensor *s = lm_slice(&c, x, 3, 2, 8); /* 1 x 2 x 6 x 8, strided */
    lm_tensor *y = lm_pixel_unshuffle(&c, s, 3, 4);
    lm_tensor *e = lm_tensor_new(&c, 4, (int[]){1, 24, 2, 2});
    lm_tensor *sc = lm_contiguous(&c, s);
    ref_unshuffle(sc->data, e->data, 1, 2, 6, 8, 3, 4);
    if (y) CHECK_ARRAY_CLOSE(y->data, e->data, 96, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_unshuffle(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    return check_with_input(c, lm_pixel_unshuffle(c, in[0], 3, 2), in[0]);
}
static lm_tensor *fn_shuffle(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    return check_with_input(c, lm_pixel_shuffle(c, in[0], 2, 3), in[0]);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 14);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 2, 6, 4}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_unshuffle, &x, 1, NULL, NULL);
    lm_tensor *z = lm_tensor_uniform(&c, 4, (int[]){2, 12, 2, 3}, &r, -1, 1);
    lm_tensor_set_requires_grad(z, 1);
    CHECK_GRAD(&c, fn_shuffle, &z, 1, NULL, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void expect_fail(lm_ctx *c, lm_tensor *y, lm_status s, const char *op)
{
    CHECK(y == NULL);
    CHECK_MSG(strstr(c->msg, op) != NULL, "message '%s' lacks '%s'", c->msg, op);
    CHECK_CTX_FAILED(c, s);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 2, 6, 8});
    expect_fail(&c, lm_pixel_unshuffle(&c, x, 4, 4), LM_ERR_SHAPE, "pixel_unshuffle"); /* H%4 */
    expect_fail(&c, lm_pixel_unshuffle(&c, x, 3, 3), LM_ERR_SHAPE, "pixel_unshuffle"); /* W%3 */
    expect_fail(&c, lm_pixel_unshuffle(&c, x, 0, 2), LM_ERR_ARG, "pixel_unshuffle");
    lm_tensor *x3 = lm_tensor_zeros(&c, 3, (int[]){2, 6, 8});
    expect_fail(&c, lm_pixel_unshuffle(&c, x3, 2, 2), LM_ERR_SHAPE, "pixel_unshuffle");
    expect_fail(&c, lm_pixel_shuffle(&c, x, 2, 2), LM_ERR_SHAPE, "pixel_shuffle"); /* C%4 */
    expect_fail(&c, lm_pixel_shuffle(&c, x3, 1, 1), LM_ERR_SHAPE, "pixel_shuffle");
    expect_fail(&c, lm_pixel_shuffle(&c, x, 1, -1), LM_ERR_ARG, "pixel_shuffle");
    /* a NULL input (earlier failure) gives NULL and an error naming the op */
    expect_fail(&c, lm_pixel_shuffle(&c, NULL, 1, 1), LM_ERR_ARG, "pixel_shuffle");
    lm_ctx_free(&c);
}

/* phase_mean = global_avg_pool(pixel_unshuffle), phase_scale = shuffle(unshuffle(x) * s). */
static void test_phase_ops_match_shuffles(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 15);
    const int fy[3] = {3, 2, 1}, fx[3] = {4, 1, 3}, H[3] = {66, 6, 5}, W[3] = {64, 5, 9};
    for (int k = 0; k < 3; k++) {
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 5, H[k], W[k]}, &r, -1, 1);
        int P = fy[k] * fx[k];
        lm_tensor *s = lm_tensor_uniform(&c, 4, (int[]){2, 5 * P, 1, 1}, &r, 0, 2);
        lm_tensor *u = lm_pixel_unshuffle(&c, x, fy[k], fx[k]);
        lm_tensor *m = lm_phase_mean(&c, x, fy[k], fx[k]), *me = lm_global_avg_pool(&c, u);
        lm_tensor *y = lm_phase_scale(&c, x, s, fy[k], fx[k]);
        lm_tensor *ye = lm_pixel_shuffle(&c, lm_mul(&c, u, s), fy[k], fx[k]);
        CHECK_CTX_OK(&c);
        CHECK(m && me && lm_tensor_same_shape(m, me) && y && lm_tensor_same_shape(y, x));
        if (m && me) CHECK_ARRAY_CLOSE(m->data, me->data, lm_tensor_numel(me), 1e-6, 1e-5);
        if (y && ye) CHECK_ARRAY_CLOSE(y->data, ye->data, lm_tensor_numel(ye), 0, 0);
    }
    /* by hand: 1 x 1 x 2 x 4, factors 1 x 2: phase 0 = columns 0, 2; phase 1 = columns 1, 3 */
    float v[8] = {0, 1, 2, 3, 4, 5, 6, 7}, sc[2] = {10, -1};
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 4}, v);
    lm_tensor *m = lm_phase_mean(&c, x, 1, 2);
    lm_tensor *y = lm_phase_scale(&c, x, lm_tensor_from(&c, 2, (int[]){1, 2}, sc), 1, 2);
    float me[2] = {3, 4}, ye[8] = {0, -1, 20, -3, 40, -5, 60, -7};
    if (m) CHECK_ARRAY_CLOSE(m->data, me, 2, 0, 0);
    if (y) CHECK_ARRAY_CLOSE(y->data, ye, 8, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_phase(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *m = lm_phase_mean(c, in[0], 3, 2);
    lm_tensor *y = lm_phase_scale(c, in[0], in[1], 3, 2);
    return lm_phase_scale(c, y, lm_mul(c, m, m), 3, 2); /* both ops, every input */
}

static void test_phase_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 16);
    lm_tensor *in[2] = {lm_tensor_uniform(&c, 4, (int[]){2, 2, 6, 4}, &r, -1, 1),
                        lm_tensor_uniform(&c, 2, (int[]){2, 12}, &r, -1, 1)};
    lm_tensor_set_requires_grad(in[0], 1);
    lm_tensor_set_requires_grad(in[1], 1);
    CHECK_GRAD(&c, fn_phase, in, 2, NULL, NULL);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 2, 6, 8});
    expect_fail(&c, lm_phase_mean(&c, x, 4, 4), LM_ERR_SHAPE, "phase_mean");
    expect_fail(&c, lm_phase_mean(&c, x, 0, 2), LM_ERR_ARG, "phase_mean");
    expect_fail(&c, lm_phase_scale(&c, x, lm_tensor_zeros(&c, 2, (int[]){1, 23}), 3, 4),
                LM_ERR_SHAPE, "phase_scale");
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_unshuffle_reference_3x4);
    RUN(test_unshuffle_hand_values);
    RUN(test_round_trips);
    RUN(test_strided_input);
    RUN(test_gradients);
    RUN(test_phase_ops_match_shuffles);
    RUN(test_phase_gradients);
    RUN(test_errors);
    return check_summary();
}
