/* test_opencl_eltwise.c — CPU vs OpenCL agreement, forward and every input gradient, through the
 * public op API: binary ops with broadcasting, affine, activations, sum/mean/global average
 * pooling, L1/MSE losses, softmax, layer norm over channels, L2 normalisation; and a small
 * composite graph whose tape runs on the device. Prints the worst differences per op.
 * Tolerances: |cl - cpu| <= atol + rtol |cpu|, stated per case (float kernels with Kahan sums on
 * the device vs double accumulation on the CPU for the reductions). Exit 77 only when no
 * OpenCL platform exists. */
#include "tests/test_opencl_util.h"

/* ---- op wrappers ------------------------------------------------------------------------- */
static lm_tensor *f_add(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_add(c, in[0], in[1]);
}
static lm_tensor *f_sub(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_sub(c, in[0], in[1]);
}
static lm_tensor *f_mul(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_mul(c, in[0], in[1]);
}
static lm_tensor *f_div(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_div(c, in[0], in[1]);
}
static lm_tensor *f_affine(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_affine(c, in[0], -1.75f, 0.25f);
}

typedef struct act_sel { int kind; } act_sel;
static lm_tensor *f_act(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    switch (((act_sel *)u)->kind) {
    case 0: return lm_relu(c, in[0]);
    case 1: return lm_leaky_relu(c, in[0], 0.1f);
    case 2: return lm_sigmoid(c, in[0]);
    case 3: return lm_tanh(c, in[0]);
    default: return lm_gelu(c, in[0]);
    }
}

typedef struct red_sel { unsigned mask; int keep, mean; } red_sel;
static lm_tensor *f_reduce(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const red_sel *r = u;
    return r->mean ? lm_mean(c, in[0], r->mask, r->keep) : lm_sum(c, in[0], r->mask, r->keep);
}
static lm_tensor *f_gap(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_global_avg_pool(c, in[0]);
}
static lm_tensor *f_l1(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_l1_loss(c, in[0], in[1]);
}
static lm_tensor *f_mse(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    return lm_mse_loss(c, in[0], in[1]);
}
typedef struct axis_sel { int axis; float eps; } axis_sel;
static lm_tensor *f_softmax(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    return lm_softmax(c, in[0], ((axis_sel *)u)->axis);
}
static lm_tensor *f_l2(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const axis_sel *a = u;
    return lm_l2_normalize(c, in[0], a->axis, a->eps);
}
static lm_tensor *f_ln(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)u;
    return lm_layer_norm_channels(c, in[0], n > 1 ? in[1] : NULL, n > 2 ? in[2] : NULL, 1e-5f);
}

#define SHAPE(...) {__VA_ARGS__}

/* ---- tests ------------------------------------------------------------------------------- */
static void test_binary(void)
{
    agree_fn fns[4] = {f_add, f_sub, f_mul, f_div};
    const char *names[4] = {"add", "sub", "mul", "div"};
    for (int op = 0; op < 4; op++) {
        char nm[3][48];
        /* same shape; channel broadcast (attention x * s); two-sided broadcast */
        agree_case k0 = {nm[0], fns[op], NULL, 2, {4, 4}, {SHAPE(2, 3, 5, 7), SHAPE(2, 3, 5, 7)},
                         .atol = 1e-6, .rtol = 1e-5};
        agree_case k1 = {nm[1], fns[op], NULL, 2, {4, 4}, {SHAPE(2, 3, 5, 7), SHAPE(1, 3, 1, 1)},
                         .atol = 1e-5, .rtol = 1e-5};
        agree_case k2 = {nm[2], fns[op], NULL, 2, {3, 4}, {SHAPE(3, 1, 6), SHAPE(2, 1, 4, 1)},
                         .atol = 1e-5, .rtol = 1e-5};
        agree_case *ks[3] = {&k0, &k1, &k2};
        const char *what[3] = {"same", "channel bcast", "two-sided bcast"};
        for (int j = 0; j < 3; j++) {
            snprintf(nm[j], sizeof nm[j], "%s %s", names[op], what[j]);
            if (op == 3) ks[j]->lo[1] = 0.5f, ks[j]->hi[1] = 2.0f; /* divisor away from 0 */
            check_agree(ks[j], 100 + (uint64_t)(op * 3 + j));
        }
    }
}

static void test_affine_and_activations(void)
{
    agree_case k = {"affine", f_affine, NULL, 1, {3}, {SHAPE(4, 5, 6)}, .atol = 1e-6,
                    .rtol = 1e-6};
    check_agree(&k, 1);
    const char *names[5] = {"relu", "leaky_relu", "sigmoid", "tanh", "gelu"};
    for (int a = 0; a < 5; a++) {
        act_sel s = {a};
        agree_case ka = {names[a], f_act, &s, 1, {4}, {SHAPE(2, 3, 9, 11)}, {-4}, {4},
                         .atol = 1e-6, .rtol = 1e-5};
        check_agree(&ka, 10 + (uint64_t)a);
    }
}

static void test_reductions(void)
{
    red_sel sels[6] = {{0x8, 0, 0}, {0x5, 1, 0}, {0x2, 0, 1}, {0xf, 0, 1}, {0x3, 1, 1},
                       {0x9, 0, 0}};
    const char *names[6] = {"sum inner", "sum 0,2 keep", "mean dim1", "mean all",
                            "mean 0,1 keep", "sum 0,3"};
    for (int i = 0; i < 6; i++) {
        agree_case k = {names[i], f_reduce, &sels[i], 1, {4}, {SHAPE(3, 4, 5, 6)},
                        .atol = 1e-5, .rtol = 1e-5};
        check_agree(&k, 20 + (uint64_t)i);
    }
    /* long sums: the chunked path (one output, >= 65536 elements) and work-group rows */
    red_sel all = {0x3, 0, 0}, rows = {0x2, 0, 1};
    agree_case kl = {"sum all 300x300", f_reduce, &all, 1, {2}, {SHAPE(300, 300)}, .atol = 1e-5,
                     .rtol = 1e-5};
    check_agree(&kl, 30);
    agree_case kr = {"mean rows 5x5000", f_reduce, &rows, 1, {2}, {SHAPE(5, 5000)}, .atol = 1e-6,
                     .rtol = 1e-5};
    check_agree(&kr, 31);
    agree_case kg = {"global_avg_pool", f_gap, NULL, 1, {4}, {SHAPE(2, 5, 7, 9)}, .atol = 1e-6,
                     .rtol = 1e-5};
    check_agree(&kg, 32);
    agree_case kg2 = {"global_avg_pool 64x64", f_gap, NULL, 1, {4}, {SHAPE(1, 3, 64, 64)},
                      .atol = 1e-6, .rtol = 1e-5};
    check_agree(&kg2, 33);
}

static void test_losses(void)
{
    agree_case k1 = {"l1_loss", f_l1, NULL, 2, {4, 4}, {SHAPE(2, 3, 8, 8), SHAPE(2, 3, 8, 8)},
                     .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k1, 40);
    agree_case k2 = {"mse_loss", f_mse, NULL, 2, {4, 4}, {SHAPE(2, 3, 8, 8), SHAPE(2, 3, 8, 8)},
                     .no_grad = {0, 1}, .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k2, 41);
    agree_case k3 = {"mse_loss 1x3x200x200", f_mse, NULL, 2, {4, 4},
                     {SHAPE(1, 3, 200, 200), SHAPE(1, 3, 200, 200)}, .atol = 1e-7, .rtol = 1e-5};
    check_agree(&k3, 42);
}

static void test_softmax_and_norms(void)
{
    axis_sel last = {-1, 0}, ch = {1, 0};
    agree_case k1 = {"softmax last", f_softmax, &last, 1, {3}, {SHAPE(3, 7, 33)}, {-5}, {5},
                     .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k1, 50);
    agree_case k2 = {"softmax axis 1", f_softmax, &ch, 1, {4}, {SHAPE(2, 6, 5, 4)}, {-5}, {5},
                     .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k2, 51);
    axis_sel l2a = {1, 1e-12f}, l2b = {-1, 0.5f};
    agree_case k3 = {"l2_normalize axis 1", f_l2, &l2a, 1, {4}, {SHAPE(2, 8, 3, 5)},
                     .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k3, 52);
    agree_case k4 = {"l2_normalize clamp eps", f_l2, &l2b, 1, {2}, {SHAPE(6, 3)}, {-0.3f}, {0.3f},
                     .atol = 1e-6, .rtol = 1e-5};
    check_agree(&k4, 53);
    agree_case k5 = {"layer_norm w b", f_ln, NULL, 3, {4, 1, 1},
                     {SHAPE(2, 7, 5, 6), SHAPE(7), SHAPE(7)}, .atol = 1e-5, .rtol = 1e-4};
    check_agree(&k5, 54);
    agree_case k6 = {"layer_norm plain", f_ln, NULL, 1, {4}, {SHAPE(3, 4, 9, 9)}, {-3}, {5},
                     .atol = 1e-5, .rtol = 1e-4};
    check_agree(&k6, 55);
}

/* A small composite: the tape mixes several ops and re-uses a tensor (x feeds two branches). */
static lm_tensor *f_graph(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    lm_tensor *x = in[0], *w = in[1], *t = in[2];
    lm_tensor *h = lm_layer_norm_channels(c, x, w, NULL, 1e-5f);
    lm_tensor *a = lm_sigmoid(c, lm_global_avg_pool(c, h));   /* channel attention */
    lm_tensor *y = lm_add(c, lm_mul(c, lm_gelu(c, h), a), x); /* residual */
    lm_tensor *s = lm_softmax(c, lm_scale(c, y, 0.5f), 1);
    return lm_l1_loss(c, lm_mean(c, s, 0x1, 0), t);
}

static void test_composite_graph(void)
{
    agree_case k = {"graph", f_graph, NULL, 3, {4, 1, 3},
                    {SHAPE(2, 6, 5, 5), SHAPE(6), SHAPE(6, 5, 5)}, {-2, 0.5f, 0}, {2, 1.5f, 0.3f},
                    .no_grad = {0, 0, 1}, .atol = 1e-6, .rtol = 1e-4};
    check_agree(&k, 60);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_binary);
    RUN(test_affine_and_activations);
    RUN(test_reductions);
    RUN(test_losses);
    RUN(test_softmax_and_norms);
    RUN(test_composite_graph);
    lm_cl_backend_free(clb_);
    return check_summary();
}
