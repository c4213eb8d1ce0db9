/* test_models.c — presets build with the exact parameter counts of models.md, forward shapes,
 * finite-difference gradient checks of every tiny model, determinism of initialisation. */
#include "models/model.h"
#include "tests/check.h"
#include <stdlib.h>
#include "tests/model_fixture.h"


static void check_count(const char *preset, long total, long trainable)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 1, &e);
    CHECK_MSG(m != NULL, "%s: %s", preset, e.msg);
    if (!m) return;
    CHECK_MSG(lm_params_count(&m->params, 0) == total, "%s: %ld parameters, expected %ld", preset,
              lm_params_count(&m->params, 0), total);
    CHECK_MSG(lm_params_count(&m->params, 1) == trainable, "%s: %ld trainable, expected %ld",
              preset, lm_params_count(&m->params, 1), trainable);
    lm_model_free(m);
}

static void test_parameter_counts(void)
{
    check_count("han-tiny", 44223, 44223);
    check_count("han-g3b2c32", 218135, 218135);
    check_count("mcan", 887710, 887290);
    check_count("srnet", 1867670, 1867670);
    check_count("linear", 12 * 33 + 33, 12 * 33 + 33);
    /* rt-W: body.0 (12 + planes -> W, 3x3), body.2 (W -> W, 3x3), head (12 + W -> 33, 1x1);
     * the -b2 form reads one more plane (bucket 0) in body.0 */
    for (int w = 8; w <= 16; w += 8) {
        long one = (13L * w * 9 + w) + ((long)w * w * 9 + w) + ((12L + w) * 33 + 33);
        char nm[16];
        snprintf(nm, sizeof nm, "rt-%d", w);
        check_count(nm, one, one);
        snprintf(nm, sizeof nm, "rt-%d-b2", w);
        check_count(nm, one + 9L * w, one + 9L * w);
    }
    check_count("rt-8-b2", 2293, 2293); /* as lumosaic info prints it */
    /* the -mf3 form reads the two neighbour frames' planes in body.0 */
    for (int w = 8; w <= 16; w += 8) {
        long one = (13L * w * 9 + w) + ((long)w * w * 9 + w) + ((12L + w) * 33 + 33);
        char nm[16];
        snprintf(nm, sizeof nm, "rt-%d-mf3", w);
        check_count(nm, one + 18L * w, one + 18L * w);
    }
    check_count("rt-8-mf3", 2365, 2365);
    check_count("rt-16-mf3", 5453, 5453);
    /* the -nc form: one noise weight per branch channel */
    check_count("rt-8-nc", 2221 + 8, 2221 + 8);
    check_count("rt-16-nc", 5165 + 16, 5165 + 16);
    check_count("han-tiny-nc", 44223 + 16, 44223 + 16); /* one per head channel */
    check_count("han-g3b2c32-nc", 218135 + 32, 218135 + 32); /* one per head channel */
    /* tile resolution: head 3x3 12 -> C, four 3x3 C -> C, 1x1 C -> 33 x 12, C noise weights */
    static const int tn_width[3] = {64, 96, 160};
    for (int i = 0; i < 3; i++) {
        const int C = tn_width[i];
        long n = (9L * 12 * C + C) + 4 * (9L * C * C + C) + ((long)C * 396 + 396) + C;
        char nm[16];
        snprintf(nm, sizeof nm, "tn-%d-nc", C);
        check_count(nm, n, n);
    }
    /* "-d4": four residual blocks, eight 3x3 C -> C */
    for (int C = 64; C <= 96; C += 32) {
        long n = (9L * 12 * C + C) + 8 * (9L * C * C + C) + ((long)C * 396 + 396) + C;
        char nm[16];
        snprintf(nm, sizeof nm, "tn-%d-d4-nc", C);
        check_count(nm, n, n);
    }
}

/* The noise weights of a "-nc" model (rt-N-nc: body.0.noise, han-tiny-nc: head.0.noise). */
static lm_tensor *noise_weights(lm_model *m)
{
    lm_param *p = lm_params_find(&m->params, "body.0.noise");
    if (!p) p = lm_params_find(&m->params, "head.0.noise");
    return p ? &p->t : NULL;
}

/* A "-nc" preset: refused without a noise level; with zero noise weights (the start) it is its
 * plain twin (same seed) at any level; with non-zero ones each item's level reaches its own
 * output only. */
static void check_noise_conditioned(const char *nc, const char *plain)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(nc, &mo, 3, &e), *p = lm_model_create(plain, &mo, 3, &e);
    CHECK_MSG(m && p, "%s", e.msg);
    if (!m || !p) return;
    CHECK(m->noise_input && !p->noise_input);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 1);
    const int B = 2, H = 12, W = 16;
    long n = (long)B * 33 * H * W, half = n / B;
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, 1, H, W}, &r, 0, 1);
    CHECK(lm_model_forward(&c, m, x) == NULL && strstr(c.msg, "noise level"));
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_clear_error(&c);
    m->noise_sigma = 0.05f;
    lm_tensor *y0 = lm_model_forward(&c, m, x), *yp = lm_model_forward(&c, p, x);
    CHECK_CTX_OK(&c);
    CHECK_MSG(y0 && yp && !memcmp(y0->data, yp->data, sizeof(float) * (size_t)n), "%s", nc);
    lm_tensor *nw = noise_weights(m);
    CHECK(nw != NULL);
    for (int i = 0; nw && i < nw->shape[0]; i++) nw->data[i] = 0.5f * (float)(i % 3) - 0.4f;
    float sig[2] = {0.0f, 0.05f};
    m->noise_sigma_items = sig; /* item 0 clean, item 1 at the level above */
    lm_tensor *y1 = lm_model_forward(&c, m, x);
    m->noise_sigma_items = NULL;
    lm_tensor *y2 = lm_model_forward(&c, m, x); /* both at 0.05 */
    CHECK_CTX_OK(&c);
    double d0 = 0, d1 = 0, d2 = 0;
    for (long i = 0; y1 && y2 && i < half; i++) {
        d0 += fabs(y1->data[i] - yp->data[i]);               /* clean item: no bias */
        d1 += fabs(y1->data[half + i] - y2->data[half + i]); /* same level, same output */
        d2 += fabs(y2->data[i] - yp->data[i]);               /* level 0.05: the bias acts */
    }
    CHECK_MSG(d0 == 0 && d1 == 0 && d2 > 1e-3, "%s: %g %g %g", nc, d0, d1, d2);
    lm_ctx_free(&c);
    lm_model_free(m);
    lm_model_free(p);
}

/* Every preset says what it is for (info --list). */
static void test_purposes(void)
{
    for (const char *const *p = lm_model_presets(); *p; p++)
        CHECK_MSG(lm_model_preset_purpose(*p)[0], "preset %s has no purpose line", *p);
    CHECK(lm_model_preset_purpose("no-such")[0] == 0);
}

static void test_noise_conditioned(void)
{
    check_noise_conditioned("rt-8-nc", "rt-8");
    check_noise_conditioned("han-tiny-nc", "han-tiny");
    check_noise_conditioned("han-g3b2c32-nc", "han-g3b2c32");
}

static void test_paper_han_count(void)
{
    check_count("han-paper", 57115999, 57115999);
}

static void test_unknown_preset(void)
{
    lm_err e = {0};
    CHECK(lm_model_create("han-huge", NULL, 1, &e) == NULL);
    CHECK(e.status == LM_ERR_ARG && strstr(e.msg, "han-huge") && strstr(e.msg, "han-tiny"));
    lm_err_clear(&e);
    CHECK(lm_model_create("srnet", NULL, 1, &e) == NULL); /* no response map */
    CHECK(e.status == LM_ERR_ARG && strstr(e.msg, "response"));
}

static void test_init_deterministic(void)
{
    lm_err e = {0};
    lm_model *a = lm_model_create("han-tiny", NULL, 42, &e), *b = lm_model_create("han-tiny", NULL, 42, &e),
             *d = lm_model_create("han-tiny", NULL, 43, &e);
    CHECK(a && b && d);
    CHECK(!memcmp(a->params.data, b->params.data, a->params.total * sizeof(float)));
    CHECK(memcmp(a->params.data, d->params.data, a->params.total * sizeof(float)) != 0);
    /* gammas start at 0 as in the official code */
    CHECK(lm_params_find(&a->params, "la.gamma")->t.data[0] == 0.0f);
    CHECK(lm_params_find(&a->params, "csa.gamma")->t.data[0] == 0.0f);
    lm_model_free(a), lm_model_free(b), lm_model_free(d);
}

static void forward_shape(const char *preset, int B, int H, int W)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 3, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 1);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, m->in_channels, H, W}, &r, 0, 1);
    lm_tensor *y = lm_model_forward(&c, m, x);
    CHECK_CTX_OK(&c);
    CHECK_MSG(y && y->shape[0] == B && y->shape[1] == 33 && y->shape[2] == H && y->shape[3] == W,
              "%s output shape", preset);
    long n = y ? lm_tensor_numel(y) : 0;
    int finite = 1;
    for (long i = 0; i < n; i++) finite &= isfinite(y->data[i]);
    CHECK(finite);
    /* wrong input sizes give an error, not a crash */
    lm_tensor *bad = lm_tensor_zeros(&c, 4, (int[]){1, 1, 10, 16});
    CHECK(lm_model_forward(&c, m, bad) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    if (lm_model_buckets(m) == 2) {
        /* one bucket to a two-bucket model: refused; the bucket-0 plane changes the output */
        lm_ctx_clear_error(&c);
        lm_tensor *one = lm_tensor_zeros(&c, 4, (int[]){B, 1, H, W});
        CHECK(lm_model_forward(&c, m, one) == NULL && strstr(c.msg, "B x 2 x H x W"));
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        lm_ctx_clear_error(&c);
        lm_tensor *x2 = lm_tensor_uniform(&c, 4, (int[]){B, 2, H, W}, &r, 0, 1);
        memcpy(x2->data, x->data, sizeof(float) * (size_t)B * 2 * H * W);
        for (int b = 0; b < B; b++) /* bucket 0 of every item halved */
            for (long i = 0; i < (long)H * W; i++) x2->data[((size_t)b * 2 + 1) * H * W + i] *= 0.5f;
        lm_tensor *y2 = lm_model_forward(&c, m, x2);
        double diff = 0;
        for (long i = 0; y && y2 && i < n; i++) diff += fabs(y->data[i] - y2->data[i]);
        CHECK_MSG(diff > 1e-3, "%s: bucket 0 does not reach the output (%g)", preset, diff);
    }
    if (lm_model_frames(m) == 3) {
        /* one frame to a multi-frame model: refused; each neighbour plane changes the output */
        lm_ctx_clear_error(&c);
        CHECK(m->in_channels == 3 && lm_model_buckets(m) == 1);
        lm_tensor *one = lm_tensor_zeros(&c, 4, (int[]){B, 1, H, W});
        CHECK(lm_model_forward(&c, m, one) == NULL && strstr(c.msg, "B x 3 x H x W"));
        CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
        for (int q = 1; q < 3; q++) {
            lm_ctx_clear_error(&c);
            lm_tensor *x3 = lm_tensor_uniform(&c, 4, (int[]){B, 3, H, W}, &r, 0, 1);
            memcpy(x3->data, x->data, sizeof(float) * (size_t)B * 3 * H * W);
            for (int b = 0; b < B; b++)
                for (long i = 0; i < (long)H * W; i++) x3->data[((size_t)b * 3 + q) * H * W + i] *= 0.5f;
            lm_tensor *y3 = lm_model_forward(&c, m, x3);
            double diff = 0;
            for (long i = 0; y && y3 && i < n; i++) diff += fabs(y->data[i] - y3->data[i]);
            CHECK_MSG(diff > 1e-3, "%s: plane %d does not reach the output (%g)", preset, q, diff);
        }
    }
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_forward_shapes(void)
{
    forward_shape("linear", 2, 12, 16);
    forward_shape("han-tiny", 2, 66, 64);
    forward_shape("mcan-tiny", 2, 66, 64);
    forward_shape("srnet-tiny", 2, 66, 64);
    forward_shape("rt-8", 2, 12, 16);
    forward_shape("rt-8-b2", 2, 12, 16);
    forward_shape("rt-16-b2", 1, 66, 64);
    forward_shape("rt-8-mf3", 2, 12, 16);
    forward_shape("rt-16-mf3", 1, 66, 64);
}

typedef struct gc_user { lm_model *m; } gc_user;

static lm_tensor *model_fn(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    return lm_model_forward(c, ((gc_user *)u)->m, in[0]);
}

/* Gradient of the weighted output w.r.t. the raw input and a sample of every parameter. */
static void gradcheck_model(const char *preset, int H, int W)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 5, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    /* non-zero attention scales so that LAM/CSAM paths are exercised */
    lm_param *g1 = lm_params_find(&m->params, "la.gamma"), *g2 = lm_params_find(&m->params, "csa.gamma");
    if (g1) g1->t.data[0] = 0.3f;
    if (g2) g2->t.data[0] = 0.7f;
    lm_tensor *nz = noise_weights(m); /* "-nc": non-zero, and a level */
    for (int i = 0; nz && i < nz->shape[0]; i++) nz->data[i] = 0.3f - 0.1f * (float)(i % 7);
    if (m->noise_input) m->noise_sigma = 0.04f;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 2);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, m->in_channels, H, W}, &r, 0.1f, 1.0f);
    lm_tensor_set_requires_grad(x, 1);
    int np = m->params.n;
    lm_tensor **in = malloc((size_t)(np + 1) * sizeof *in);
    in[0] = x;
    for (int i = 0; i < np; i++) in[i + 1] = &m->params.items[i]->t;
    /* ReLU-family kinks make a few central differences straddle a kink (a unit whose
     * pre-activation lies within eps of 0 somewhere downstream); such elements show the
     * average of the two one-sided slopes. Every op is checked strictly on its own; here a
     * wiring error shows as many elements off (a wrong leaky-ReLU slope in backward: half of
     * MCAN's elements), so at most 10 % may miss (measured: han-tiny 1 %, mcan-tiny 6 %). */
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.max_checks = 6;
    o.atol = 5e-3;
    o.rtol = 5e-2;
    gc_user u = {m};
    lm_params_zero_grad(&m->params);
    lm_gradcheck_result res;
    lm_status st = lm_gradcheck(&c, model_fn, in, np + 1, &u, &o, &res);
    CHECK_MSG(st == LM_OK || st == LM_ERR_NUMERIC, "%s: %s", preset, c.msg);
    CHECK_MSG(res.checked > 6 * np / 2 && res.failed * 10 <= res.checked,
              "%s: %ld of %ld gradient elements off (%s)", preset, res.failed, res.checked, c.msg);
    printf("     %-11s gradient check: %ld of %ld elements within tolerance, worst abs err %.3g\n",
           preset, res.checked - res.failed, res.checked, res.max_abs_err);
    lm_ctx_clear_error(&c);
    free(in);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_gradcheck_models(void)
{
    gradcheck_model("linear", 6, 8);
    gradcheck_model("han-tiny", 6, 8);
    gradcheck_model("mcan-tiny", 6, 8);
    gradcheck_model("srnet-tiny", 12, 16);
    gradcheck_model("rt-8-b2", 6, 8);
    gradcheck_model("rt-8-mf3", 6, 8);
    gradcheck_model("rt-8-nc", 6, 8);
    gradcheck_model("han-tiny-nc", 6, 8);
    gradcheck_model("tn-64-nc", 6, 8);
}

/* A training step (forward, loss, backward) allocates nothing from the system after the
 * first steps: the arena coalesces into one block and is reused. */
static void steps_allocate_nothing(const char *preset)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, &mo, 3, &e);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 4);
    long allocs[4];
    for (int step = 0; step < 4; step++) {
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 1, 66, 64}, &r, 0, 1);
        lm_tensor *t = lm_tensor_uniform(&c, 4, (int[]){2, 33, 66, 64}, &r, 0, 1);
        lm_params_zero_grad(&m->params);
        lm_tensor *loss = lm_l1_loss(&c, lm_model_forward(&c, m, x), t);
        CHECK(lm_backward(&c, loss, NULL) == LM_OK);
        allocs[step] = c.arena.sys_allocs;
        lm_ctx_reset(&c);
    }
    CHECK_CTX_OK(&c);
    CHECK_MSG(allocs[3] == allocs[2] && allocs[2] <= allocs[1] + 1,
              "%s: system allocations per step %ld %ld %ld %ld", preset, allocs[0], allocs[1],
              allocs[2], allocs[3]);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_training_steps_reuse_arena(void)
{
    steps_allocate_nothing("han-tiny");
    steps_allocate_nothing("mcan-tiny");
    steps_allocate_nothing("srnet-tiny");
}

int main(int argc, char **argv)
{
    RUN(test_parameter_counts);
    RUN(test_unknown_preset);
    RUN(test_init_deterministic);
    RUN(test_forward_shapes);
    RUN(test_noise_conditioned);
    RUN(test_purposes);
    RUN(test_gradcheck_models);
    RUN(test_training_steps_reuse_arena);
    if (argc < 2 || strcmp(argv[1], "--quick")) RUN(test_paper_han_count);
    return check_summary();
}
