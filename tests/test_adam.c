/* test_adam.c — Adam against hand-computed updates; schedules; convergence on a quadratic. */
#include "train/adam.h"
#include "tests/check.h"
#include <math.h>
#include <string.h>

static void setup(lm_params *p, int n)
{
    lm_err e = {0};
    lm_params_init(p);
    lm_params_add(p, "w", 1, &n, 1, &e);
    lm_params_add(p, "frozen", 1, (int[]){3}, 0, &e);
    lm_params_finalize(p, &e);
}

static void test_first_steps_by_hand(void)
{
    lm_params p;
    setup(&p, 2);
    lm_param *w = lm_params_find(&p, "w"), *fz = lm_params_find(&p, "frozen");
    w->t.data[0] = 1.0f;
    w->t.data[1] = -2.0f;
    lm_tensor_fill(&fz->t, 7.0f);
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    cfg.lr = 0.1f;
    lm_adam o;
    lm_err e = {0};
    CHECK(lm_adam_init(&o, &p, &cfg, &e) == LM_OK);
    /* step 1: update = lr * g / (|g| + eps') = lr * sign(g) */
    w->g.data[0] = 0.5f;
    w->g.data[1] = -3.0f;
    lm_adam_step(&o, &p, 1);
    CHECK_CLOSE(w->t.data[0], 1.0 - 0.1, 1e-6, 0);
    CHECK_CLOSE(w->t.data[1], -2.0 + 0.1, 1e-6, 0);
    /* step 2 with g = 1.0 and 0: m = 0.9*0.05 + 0.1*1 = 0.145, v = 0.999*0.00025 + 0.001 */
    w->g.data[0] = 1.0f;
    w->g.data[1] = 0.0f;
    lm_adam_step(&o, &p, 1);
    double m = 0.9 * 0.05 + 0.1 * 1.0, v = 0.999 * 0.00025 + 0.001 * 1.0;
    double upd = 0.1 * (m / (1 - 0.81)) / (sqrt(v / (1 - 0.999 * 0.999)) + 1e-8);
    CHECK_CLOSE(w->t.data[0], 0.9 - upd, 1e-6, 0);
    CHECK(fz->t.data[0] == 7.0f && fz->t.data[2] == 7.0f);
    lm_adam_free(&o);
    lm_params_free(&p);
}

static void test_weight_decay_variants(void)
{
    lm_params p;
    setup(&p, 1);
    lm_param *w = lm_params_find(&p, "w");
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    cfg.lr = 0.01f;
    cfg.weight_decay = 0.5f;
    cfg.decoupled = 1;
    lm_adam o;
    lm_err e = {0};
    w->t.data[0] = 2.0f;
    w->g.data[0] = 0.0f;
    lm_adam_init(&o, &p, &cfg, &e);
    lm_adam_step(&o, &p, 1);
    CHECK_CLOSE(w->t.data[0], 2.0 - 0.01 * 0.5 * 2.0, 1e-6, 0); /* AdamW: pure decay when g = 0 */
    lm_adam_free(&o);
    cfg.decoupled = 0;
    w->t.data[0] = 2.0f;
    lm_adam_init(&o, &p, &cfg, &e);
    lm_adam_step(&o, &p, 1);
    CHECK_CLOSE(w->t.data[0], 2.0 - 0.01, 1e-6, 0); /* Adam: g' = wd*w > 0, first step = lr */
    lm_adam_free(&o);
    cfg.lr = -1;
    CHECK(lm_adam_init(&o, &p, &cfg, &e) == LM_ERR_ARG && strstr(e.msg, "lr"));
    lm_params_free(&p);
}

static void test_schedules(void)
{
    lm_adam_cfg c;
    lm_adam_default_cfg(&c);
    c.lr = 1.0f;
    CHECK_CLOSE(lm_adam_lr(&c, 1000), 1.0, 0, 0);
    c.schedule = LM_LR_COSINE;
    c.total_steps = 100;
    c.lr_min = 0.0f;
    CHECK_CLOSE(lm_adam_lr(&c, 0), 1.0, 1e-7, 0);
    CHECK_CLOSE(lm_adam_lr(&c, 50), 0.5, 1e-6, 0);
    CHECK_CLOSE(lm_adam_lr(&c, 100), 0.0, 1e-7, 0);
    CHECK_CLOSE(lm_adam_lr(&c, 200), 0.0, 1e-7, 0);
    c.schedule = LM_LR_STEP;
    c.step_every = 10;
    c.step_gamma = 0.5f;
    CHECK_CLOSE(lm_adam_lr(&c, 9), 1.0, 0, 0);
    CHECK_CLOSE(lm_adam_lr(&c, 25), 0.25, 0, 0);
    c.warmup_steps = 4;
    CHECK_CLOSE(lm_adam_lr(&c, 0), 0.25, 1e-7, 0);
    CHECK_CLOSE(lm_adam_lr(&c, 3), 1.0, 1e-7, 0);
}

static void test_converges_on_quadratic(void)
{
    lm_params p;
    setup(&p, 100);
    lm_param *w = lm_params_find(&p, "w");
    lm_rng r;
    lm_rng_seed(&r, 9);
    float target[100];
    for (int i = 0; i < 100; i++) target[i] = lm_rng_normal(&r);
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    cfg.lr = 0.05f;
    lm_adam o;
    lm_err e = {0};
    lm_adam_init(&o, &p, &cfg, &e);
    for (int it = 0; it < 2000; it++) {
        for (int i = 0; i < 100; i++) w->g.data[i] = 2.0f * (w->t.data[i] - target[i]);
        lm_adam_step(&o, &p, 2);
    }
    CHECK_ARRAY_CLOSE(w->t.data, target, 100, 1e-3, 0);
    lm_adam_free(&o);
    lm_params_free(&p);
}

/* The weight average: started at the initial weights, a = d a + (1 - d) w after each update
 * with d = min(ema, (1 + t) / (10 + t)) for update t (0-based); frozen parameters untouched;
 * the swap exchanges the two copies exactly; decays outside [0, 1) refused. */
static void test_ema(void)
{
    lm_params p;
    setup(&p, 3);
    lm_param *w = lm_params_find(&p, "w"), *fz = lm_params_find(&p, "frozen");
    for (int i = 0; i < 3; i++) w->t.data[i] = 0.5f * (float)i - 1.0f;
    lm_tensor_fill(&fz->t, 7.0f);
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    cfg.lr = 0.05f;
    cfg.ema = 0.5f;
    lm_adam o;
    lm_err e = {0};
    CHECK(lm_adam_init(&o, &p, &cfg, &e) == LM_OK && o.ema);
    if (!o.ema) return;
    double a[3];
    for (int i = 0; i < 3; i++) a[i] = w->t.data[i];
    for (int t = 0; t < 20; t++) { /* d = 0.1, 0.18, ..., then 0.5 from t = 8 */
        for (int i = 0; i < 3; i++) w->g.data[i] = (float)(i + 1) * (t % 3 ? 1.0f : -0.5f);
        lm_adam_step(&o, &p, 1);
        double d = (1.0 + t) / (10.0 + t);
        if (d > 0.5) d = 0.5;
        for (int i = 0; i < 3; i++) a[i] = d * a[i] + (1 - d) * w->t.data[i];
    }
    float wv[3], av[3];
    for (int i = 0; i < 3; i++) wv[i] = w->t.data[i], av[i] = o.ema[w->offset + i];
    float want[3] = {(float)a[0], (float)a[1], (float)a[2]};
    CHECK_ARRAY_CLOSE(av, want, 3, 1e-5, 0);
    CHECK(memcmp(av, wv, sizeof wv) != 0);
    lm_adam_ema_swap(&o, &p);
    CHECK(!memcmp(w->t.data, av, sizeof av) && !memcmp(o.ema + w->offset, wv, sizeof wv));
    lm_adam_ema_swap(&o, &p);
    CHECK(!memcmp(w->t.data, wv, sizeof wv) && !memcmp(o.ema + w->offset, av, sizeof av));
    CHECK(fz->t.data[0] == 7.0f && fz->t.data[2] == 7.0f);
    lm_adam_free(&o);
    const float bad[] = {1.0f, -0.1f, NAN};
    for (int k = 0; k < 3; k++) {
        cfg.ema = bad[k];
        lm_err e2 = {0};
        CHECK(lm_adam_init(&o, &p, &cfg, &e2) == LM_ERR_ARG && strstr(e2.msg, "ema"));
        lm_adam_free(&o);
    }
    cfg.ema = 0; /* none: no second copy, the swap is a no-op */
    CHECK(lm_adam_init(&o, &p, &cfg, &e) == LM_OK && !o.ema);
    lm_adam_ema_swap(&o, &p);
    CHECK(!memcmp(w->t.data, wv, sizeof wv));
    lm_adam_free(&o);
    lm_params_free(&p);
}

int main(void)
{
    RUN(test_first_steps_by_hand);
    RUN(test_weight_decay_variants);
    RUN(test_schedules);
    RUN(test_converges_on_quadratic);
    RUN(test_ema);
    return check_summary();
}
