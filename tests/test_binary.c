/* test_binary.c — add/sub/mul/div with broadcasting (binary.c) and affine (scalar.c):
 * hand-computed values, an independent index-by-index broadcasting reference, IEEE division,
 * gradient checks of both operands over broadcast cases, exact reduced gradients, views,
 * errors, and bitwise determinism for a fixed thread count. */
#include "tests/check.h"
#include <stdlib.h>

enum { OP_ADD, OP_SUB, OP_MUL, OP_DIV };
static const char *const OP_NAMES[4] = {"add", "sub", "mul", "div"};

static lm_tensor *apply(lm_ctx *c, int op, lm_tensor *a, lm_tensor *b)
{
    switch (op) {
    case OP_ADD: return lm_add(c, a, b);
    case OP_SUB: return lm_sub(c, a, b);
    case OP_MUL: return lm_mul(c, a, b);
    default: return lm_div(c, a, b);
    }
}

static float ref_op(int op, float a, float b)
{
    switch (op) {
    case OP_ADD: return a + b;
    case OP_SUB: return a - b;
    case OP_MUL: return a * b;
    default: return a / b;
    }
}

typedef struct bcase { int na, sa[5], nb, sb[5]; } bcase;
static const bcase CASES[] = {
    {4, {2, 3, 4, 5}, 4, {1, 3, 1, 1}},  /* per-channel */
    {4, {2, 3, 4, 5}, 4, {2, 3, 1, 1}},  /* per-sample, per-channel */
    {2, {4, 5}, 1, {5}},                 /* rank difference, last dim */
    {2, {3, 1}, 2, {1, 4}},              /* both broadcast */
    {1, {5}, 2, {4, 5}},                 /* a is the smaller one */
    {5, {2, 1, 3, 1, 2}, 3, {3, 4, 1}},  /* 5-D, interleaved */
    {1, {1}, 2, {2, 3}},                 /* scalar-like */
    {3, {2, 3, 4}, 3, {2, 3, 4}},        /* equal shapes */
    {4, {1, 3, 4, 1}, 4, {2, 1, 1, 5}},  /* outer product-like */
};
#define NCASES ((int)(sizeof CASES / sizeof CASES[0]))

/* Independent reference: for every output multi-index, locate each operand's element. */
static long ref_index(int nd, const int *shape, int ond, const int *oidx)
{
    long k = 0;
    for (int i = 0; i < nd; i++) {
        int o = oidx[i + ond - nd];
        k = k * shape[i] + (shape[i] == 1 ? 0 : o);
    }
    return k;
}

static void ref_broadcast(int op, const bcase *bc, const float *a, const float *b, float *y,
                          int *ond, int *oshape)
{
    int nd = bc->na > bc->nb ? bc->na : bc->nb;
    for (int i = 0; i < nd; i++) {
        int ia = i - (nd - bc->na), ib = i - (nd - bc->nb);
        int da = ia >= 0 ? bc->sa[ia] : 1, db = ib >= 0 ? bc->sb[ib] : 1;
        oshape[i] = da > db ? da : db;
    }
    *ond = nd;
    long n = 1;
    for (int i = 0; i < nd; i++) n *= oshape[i];
    for (long k = 0; k < n; k++) {
        int idx[5];
        long r = k;
        for (int i = nd - 1; i >= 0; i--) {
            idx[i] = (int)(r % oshape[i]);
            r /= oshape[i];
        }
        y[k] = ref_op(op, a[ref_index(bc->na, bc->sa, nd, idx)],
                      b[ref_index(bc->nb, bc->sb, nd, idx)]);
    }
}

static void test_binary_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 4, 5, 6});
    lm_tensor *b = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){6, 5, 4, 3, 2, 1});
    CHECK_ARRAY_CLOSE(lm_add(&c, a, b)->data, ((float[]){7, 7, 7, 7, 7, 7}), 6, 0, 0);
    CHECK_ARRAY_CLOSE(lm_sub(&c, a, b)->data, ((float[]){-5, -3, -1, 1, 3, 5}), 6, 0, 0);
    CHECK_ARRAY_CLOSE(lm_mul(&c, a, b)->data, ((float[]){6, 10, 12, 12, 10, 6}), 6, 0, 0);
    CHECK_ARRAY_CLOSE(lm_div(&c, a, b)->data,
                      ((float[]){1 / 6.f, 0.4f, 0.75f, 4 / 3.f, 2.5f, 6}), 6, 0, 1e-7);
    /* 3x1 (+) 1x4 -> 3x4 */
    lm_tensor *col = lm_tensor_from(&c, 2, (int[]){3, 1}, (float[]){1, 2, 3});
    lm_tensor *row = lm_tensor_from(&c, 2, (int[]){1, 4}, (float[]){10, 20, 30, 40});
    lm_tensor *s = lm_add(&c, col, row);
    CHECK(s && s->ndim == 2 && s->shape[0] == 3 && s->shape[1] == 4);
    CHECK_ARRAY_CLOSE(s->data, ((float[]){11, 21, 31, 41, 12, 22, 32, 42, 13, 23, 33, 43}), 12,
                      0, 0);
    lm_tensor *d = lm_sub(&c, row, col);
    CHECK_ARRAY_CLOSE(d->data, ((float[]){9, 19, 29, 39, 8, 18, 28, 38, 7, 17, 27, 37}), 12, 0,
                      0);
    /* per-channel: 1x2x2x2 * 1x2x1x1 */
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 2, 2, 2}, (float[]){1, 2, 3, 4, 5, 6, 7, 8});
    lm_tensor *sc = lm_tensor_from(&c, 4, (int[]){1, 2, 1, 1}, (float[]){10, -1});
    lm_tensor *m = lm_mul(&c, x, sc);
    CHECK(m && m->ndim == 4 && m->shape[1] == 2 && m->shape[3] == 2);
    CHECK_ARRAY_CLOSE(m->data, ((float[]){10, 20, 30, 40, -5, -6, -7, -8}), 8, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_binary_matches_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 11);
    for (int k = 0; k < NCASES; k++) {
        const bcase *bc = &CASES[k];
        lm_tensor *a = lm_tensor_uniform(&c, bc->na, bc->sa, &r, -2, 2);
        lm_tensor *b = lm_tensor_uniform(&c, bc->nb, bc->sb, &r, 0.5f, 2);
        for (int op = 0; op < 4; op++) {
            lm_tensor *y = apply(&c, op, a, b);
            float ref[256];
            int ond, oshape[5];
            ref_broadcast(op, bc, a->data, b->data, ref, &ond, oshape);
            CHECK_MSG(y && y->ndim == ond, "case %d op %s", k, OP_NAMES[op]);
            if (!y) continue;
            for (int i = 0; i < ond; i++) CHECK(y->shape[i] == oshape[i]);
            /* the same float operation per element: bitwise equal */
            CHECK_ARRAY_CLOSE(y->data, ref, lm_tensor_numel(y), 0, 0);
        }
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_div_follows_ieee(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_from(&c, 1, (int[]){3}, (float[]){1, -1, 0});
    lm_tensor *z = lm_tensor_zeros(&c, 1, (int[]){1});
    lm_tensor *y = lm_div(&c, a, z);
    CHECK(y && isinf(y->data[0]) && y->data[0] > 0);
    CHECK(y && isinf(y->data[1]) && y->data[1] < 0);
    CHECK(y && isnan(y->data[2]));
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* ---- gradients --------------------------------------------------------------------------- */
static lm_tensor *fn_binary(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    return apply(c, *(int *)user, in[0], in[1]);
}

static void test_binary_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 5);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.atol = 1e-3;
    o.rtol = 1e-2;
    for (int k = 0; k < NCASES; k++) {
        const bcase *bc = &CASES[k];
        for (int op = 0; op < 4; op++) {
            lm_tensor *in[2] = {lm_tensor_uniform(&c, bc->na, bc->sa, &r, -1, 1),
                                lm_tensor_uniform(&c, bc->nb, bc->sb, &r, 0.5f, 1.5f)};
            lm_tensor_set_requires_grad(in[0], 1);
            lm_tensor_set_requires_grad(in[1], 1);
            int before = check_failures_;
            CHECK_GRAD(&c, fn_binary, in, 2, &op, &o);
            if (check_failures_ != before) fprintf(stderr, "  case %d op %s\n", k, OP_NAMES[op]);
            lm_ctx_reset(&c);
        }
    }
    lm_ctx_free(&c);
}

/* Per-channel x * s and x + s with a seed w: gs[c] = sum w*x (mul) or sum w (add) over B, H, W,
 * gx = w * s (mul) or w (add); references accumulated in double here. */
static void test_binary_broadcast_grad_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 9);
    int B = 2, C = 3, HW = 20;
    for (int k = 0; k < 2; k++) {
        int op = k == 0 ? OP_ADD : OP_MUL;
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, C, 4, 5}, &r, -1, 1);
        lm_tensor *s = lm_tensor_uniform(&c, 4, (int[]){1, C, 1, 1}, &r, -1, 1);
        lm_tensor *w = lm_tensor_uniform(&c, 4, (int[]){B, C, 4, 5}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor_set_requires_grad(s, 1);
        CHECK(lm_backward(&c, apply(&c, op, x, s), w) == LM_OK);
        for (int ch = 0; ch < C; ch++) {
            double gs = 0.0;
            for (int b = 0; b < B; b++)
                for (int i = 0; i < HW; i++) {
                    long k = (b * C + ch) * HW + i;
                    gs += op == OP_MUL ? (double)w->data[k] * x->data[k] : w->data[k];
                    float gx = op == OP_MUL ? w->data[k] * s->data[ch] : w->data[k];
                    CHECK_CLOSE(x->grad->data[k], gx, 0, 0);
                }
            CHECK_CLOSE(s->grad->data[ch], gs, 1e-6, 1e-6);
        }
        lm_ctx_reset(&c);
    }
    /* sub: b's gradient is minus the reduced seed; 4x5 - 5 */
    lm_tensor *a = lm_tensor_uniform(&c, 2, (int[]){4, 5}, &r, -1, 1);
    lm_tensor *b = lm_tensor_uniform(&c, 1, (int[]){5}, &r, -1, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 2, (int[]){4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(b, 1);
    CHECK(lm_backward(&c, lm_sub(&c, a, b), w) == LM_OK);
    CHECK(a->grad == NULL);
    for (int j = 0; j < 5; j++) {
        double e = 0.0;
        for (int i = 0; i < 4; i++) e -= w->data[i * 5 + j];
        CHECK_CLOSE(b->grad->data[j], e, 1e-6, 1e-6);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* The same tensor on both sides: d(x*x)/dx = 2x, d(x/x)/dx = 0, gradients accumulate. */
static void test_binary_same_operand(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 1, (int[]){3}, (float[]){1.5f, -2, 0.25f});
    lm_tensor_set_requires_grad(x, 1);
    CHECK(lm_backward(&c, lm_mul(&c, x, x), NULL) == LM_OK);
    CHECK_ARRAY_CLOSE(x->grad->data, ((float[]){3, -4, 0.5f}), 3, 0, 0);
    lm_ctx_reset(&c);
    x = lm_tensor_from(&c, 1, (int[]){3}, (float[]){1.5f, -2, 0.25f});
    lm_tensor_set_requires_grad(x, 1);
    CHECK(lm_backward(&c, lm_div(&c, x, x), NULL) == LM_OK);
    CHECK_ARRAY_CLOSE(x->grad->data, ((float[]){0, 0, 0}), 3, 1e-6, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Strided (sliced) operands are copied first; values and gradients still right. */
static lm_tensor *fn_sliced(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *a = lm_slice(c, in[0], 1, 1, 3); /* 2x3x4 view of 2x5x4 */
    lm_tensor *b = lm_slice(c, in[1], 2, 2, 1); /* 3x1 view of 3x4 -> broadcast */
    return lm_mul(c, a, b);
}

static void test_binary_strided_inputs(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 21);
    lm_tensor *in[2] = {lm_tensor_uniform(&c, 3, (int[]){2, 5, 4}, &r, -1, 1),
                        lm_tensor_uniform(&c, 3, (int[]){1, 3, 4}, &r, -1, 1)};
    lm_tensor *y = fn_sliced(&c, in, 2, NULL);
    CHECK(y && y->shape[0] == 2 && y->shape[1] == 3 && y->shape[2] == 4);
    for (int i = 0; y && i < 2; i++)
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 4; k++)
                CHECK(y->data[(i * 3 + j) * 4 + k] ==
                      in[0]->data[(i * 5 + j + 1) * 4 + k] * in[1]->data[j * 4 + 2]);
    lm_tensor_set_requires_grad(in[0], 1);
    lm_tensor_set_requires_grad(in[1], 1);
    CHECK_GRAD(&c, fn_sliced, in, 2, NULL, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_binary_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_zeros(&c, 2, (int[]){2, 3});
    lm_tensor *b = lm_tensor_zeros(&c, 1, (int[]){4});
    lm_tensor *t = lm_tensor_zeros(&c, 2, (int[]){3, 2});
    for (int op = 0; op < 4; op++) {
        CHECK(apply(&c, op, a, b) == NULL);
        CHECK_MSG(strstr(c.msg, OP_NAMES[op]) && strstr(c.msg, "2x3") && strstr(c.msg, "4"),
                  "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        CHECK(apply(&c, op, t, a) == NULL);
        CHECK_MSG(strstr(c.msg, "3x2") && strstr(c.msg, "2x3"), "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        CHECK(apply(&c, op, a, NULL) == NULL);
        CHECK_MSG(strstr(c.msg, OP_NAMES[op]) != NULL, "message: %s", c.msg);
        CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    }
    /* sticky: after a failure, a valid op returns NULL and keeps the first message */
    CHECK(lm_mul(&c, a, b) == NULL);
    CHECK(lm_add(&c, a, a) == NULL);
    CHECK(strstr(c.msg, "mul") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_affine(&c, NULL, 1, 0) == NULL);
    CHECK(strstr(c.msg, "affine") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

/* ---- affine ------------------------------------------------------------------------------ */
static lm_tensor *fn_affine(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    return lm_add_scalar(c, lm_scale(c, lm_affine(c, in[0], -1.5f, 0.25f), 3.0f), -2.0f);
}

static void test_affine(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 2, (int[]){2, 2}, (float[]){0, 1, -2, 0.5f});
    CHECK_ARRAY_CLOSE(lm_affine(&c, x, 2, 1)->data, ((float[]){1, 3, -3, 2}), 4, 0, 0);
    CHECK_ARRAY_CLOSE(lm_neg(&c, x)->data, ((float[]){0, -1, 2, -0.5f}), 4, 0, 0);
    CHECK_ARRAY_CLOSE(lm_scale(&c, x, 4)->data, ((float[]){0, 4, -8, 2}), 4, 0, 0);
    CHECK_ARRAY_CLOSE(lm_add_scalar(&c, x, -1)->data, ((float[]){-1, 0, -3, -0.5f}), 4, 0, 0);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_affine, &x, 1, NULL, NULL);
    /* exact: d/dx of 3 * (-1.5 x + 0.25) - 2 = -4.5 */
    lm_ctx_reset(&c);
    x = lm_tensor_from(&c, 1, (int[]){2}, (float[]){3, -7});
    lm_tensor_set_requires_grad(x, 1);
    CHECK(lm_backward(&c, fn_affine(&c, &x, 1, NULL), NULL) == LM_OK);
    CHECK_ARRAY_CLOSE(x->grad->data, ((float[]){-4.5f, -4.5f}), 2, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* ---- determinism ------------------------------------------------------------------------- */
/* x * s + (x / t) on a size that runs in parallel; outputs and all gradients. */
static void run_big(int nthreads, float *out, float *gx, float *gs, float *gt)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 77);
    int shape[4] = {4, 32, 40, 48};
    lm_tensor *x = lm_tensor_uniform(&c, 4, shape, &r, -1, 1);
    lm_tensor *s = lm_tensor_uniform(&c, 4, (int[]){4, 32, 1, 1}, &r, -1, 1);
    lm_tensor *t = lm_tensor_uniform(&c, 2, (int[]){40, 48}, &r, 0.5f, 1.5f);
    lm_tensor *w = lm_tensor_uniform(&c, 4, shape, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor_set_requires_grad(s, 1);
    lm_tensor_set_requires_grad(t, 1);
    lm_tensor *y = lm_add(&c, lm_mul(&c, x, s), lm_div(&c, x, t));
    CHECK(lm_backward(&c, y, w) == LM_OK);
    long n = lm_tensor_numel(x);
    memcpy(out, y->data, (size_t)n * sizeof(float));
    memcpy(gx, x->grad->data, (size_t)n * sizeof(float));
    memcpy(gs, s->grad->data, 128 * sizeof(float));
    memcpy(gt, t->grad->data, 1920 * sizeof(float));
    /* spot-check values against the plain formula (tolerance: the compiler may fuse) */
    for (long i = 0; i < n; i += 997)
        CHECK_CLOSE(y->data[i], x->data[i] * s->data[i / 1920] + x->data[i] / t->data[i % 1920],
                    1e-6, 1e-6);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_binary_determinism(void)
{
    long n = 4L * 32 * 40 * 48;
    float *buf[2][4];
    for (int k = 0; k < 2; k++) {
        buf[k][0] = malloc((size_t)n * sizeof(float));
        buf[k][1] = malloc((size_t)n * sizeof(float));
        buf[k][2] = malloc(128 * sizeof(float));
        buf[k][3] = malloc(1920 * sizeof(float));
    }
    size_t sz[4] = {(size_t)n, (size_t)n, 128, 1920};
    float *first1[4];
    for (int nt = 1; nt <= 2; nt++) {
        run_big(nt, buf[0][0], buf[0][1], buf[0][2], buf[0][3]);
        run_big(nt, buf[1][0], buf[1][1], buf[1][2], buf[1][3]);
        for (int j = 0; j < 4; j++)
            CHECK_MSG(memcmp(buf[0][j], buf[1][j], sz[j] * sizeof(float)) == 0,
                      "nthreads %d, buffer %d differs between runs", nt, j);
        if (nt == 1)
            for (int j = 0; j < 4; j++) {
                first1[j] = malloc(sz[j] * sizeof(float));
                memcpy(first1[j], buf[0][j], sz[j] * sizeof(float));
            }
    }
    /* by construction (fixed partition, per-element order) also independent of the count */
    for (int j = 0; j < 4; j++) {
        CHECK_MSG(memcmp(first1[j], buf[0][j], sz[j] * sizeof(float)) == 0,
                  "buffer %d differs between 1 and 2 threads", j);
        free(first1[j]);
    }
    for (int k = 0; k < 2; k++)
        for (int j = 0; j < 4; j++) free(buf[k][j]);
}

int main(void)
{
    RUN(test_binary_hand_values);
    RUN(test_binary_matches_reference);
    RUN(test_div_follows_ieee);
    RUN(test_binary_gradcheck);
    RUN(test_binary_broadcast_grad_exact);
    RUN(test_binary_same_operand);
    RUN(test_binary_strided_inputs);
    RUN(test_binary_errors);
    RUN(test_affine);
    RUN(test_binary_determinism);
    return check_summary();
}
