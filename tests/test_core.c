/* test_core.c — arena, RNG, context errors, views, tape mechanics. */
#include "tests/check.h"
#include <stdlib.h>

static void test_arena_reuse_after_warmup(void)
{
    lm_arena a;
    CHECK(lm_arena_init(&a, 0) == 0);
    a.min_block = 4096; /* force several blocks on the first step */
    for (int step = 0; step < 4; step++) {
        long before = a.sys_allocs;
        for (int i = 0; i < 50; i++) {
            float *p = lm_arena_alloc(&a, 1000 + 37 * (size_t)i);
            CHECK(p != NULL);
            CHECK(((uintptr_t)p % LM_ARENA_ALIGN) == 0);
            p[0] = 1.0f;
        }
        if (step >= 1) CHECK_MSG(a.sys_allocs == before, "step %d allocated %ld blocks", step,
                                 a.sys_allocs - before);
        lm_arena_reset(&a);
    }
    CHECK(a.nblocks == 1);
    lm_arena_free(&a);
}

static void test_arena_mark_rewind(void)
{
    lm_arena a;
    lm_arena_init(&a, 1 << 16);
    void *p0 = lm_arena_alloc(&a, 100);
    lm_arena_mark m = lm_arena_get_mark(&a);
    void *p1 = lm_arena_alloc(&a, 5000);
    lm_arena_rewind(&a, m);
    void *p2 = lm_arena_alloc(&a, 5000);
    CHECK(p1 == p2);
    CHECK(p0 != p2);
    lm_arena_free(&a);
}

static void test_ctx_steps_allocate_nothing_after_warmup(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 7);
    long allocs_after_first = 0;
    for (int step = 0; step < 3; step++) {
        int s[4] = {2, 3, 8, 8};
        lm_tensor *x = lm_tensor_uniform(&c, 4, s, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = lm_reshape(&c, x, 2, (int[]){6, 64});
        lm_tensor *z = lm_contiguous(&c, lm_slice(&c, y, 1, 3, 20));
        CHECK(lm_backward(&c, z, NULL) == LM_OK);
        CHECK_CTX_OK(&c);
        if (step == 0) allocs_after_first = c.arena.sys_allocs;
        else CHECK(c.arena.sys_allocs == allocs_after_first + (step == 1 ? 1 : 0) ||
                   c.arena.sys_allocs == allocs_after_first);
        lm_ctx_reset(&c);
    }
    long settled = c.arena.sys_allocs;
    for (int step = 0; step < 3; step++) {
        lm_tensor *x = lm_tensor_zeros(&c, 2, (int[]){64, 64});
        lm_tensor_set_requires_grad(x, 1);
        lm_backward(&c, lm_reshape(&c, x, 1, (int[]){-1}), NULL);
        lm_ctx_reset(&c);
    }
    CHECK(c.arena.sys_allocs == settled);
    lm_ctx_free(&c);
}

static void test_rng_determinism(void)
{
    lm_rng a, b;
    lm_rng_seed(&a, 42);
    lm_rng_seed(&b, 42);
    for (int i = 0; i < 1000; i++) CHECK(lm_rng_u64(&a) == lm_rng_u64(&b));
    for (int i = 0; i < 101; i++) CHECK(lm_rng_normal(&a) == lm_rng_normal(&b));
    lm_rng s1 = lm_rng_split(&a, 1), s2 = lm_rng_split(&a, 2), s1b = lm_rng_split(&a, 1);
    CHECK(lm_rng_u64(&s1) != lm_rng_u64(&s2));
    lm_rng_u64(&s1b);
    CHECK(lm_rng_u64(&s1) == lm_rng_u64(&s1b));
    lm_rng c;
    lm_rng_seed(&c, 43);
    CHECK(lm_rng_u64(&c) != lm_rng_u64(&a));
}

static void test_rng_distributions(void)
{
    lm_rng r;
    lm_rng_seed(&r, 1);
    double s = 0, s2 = 0, u = 0;
    int n = 200000, below = 0;
    for (int i = 0; i < n; i++) {
        double v = lm_rng_normal(&r);
        s += v;
        s2 += v * v;
        float x = lm_rng_uniform(&r);
        CHECK(x >= 0.0f && x < 1.0f);
        u += x;
        below += lm_rng_below(&r, 10) < 3;
    }
    CHECK_CLOSE(s / n, 0.0, 0.01, 0);
    CHECK_CLOSE(s2 / n, 1.0, 0.015, 0);
    CHECK_CLOSE(u / n, 0.5, 0.005, 0);
    CHECK_CLOSE((double)below / n, 0.3, 0.005, 0);
}

static void test_errors_are_sticky(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 2, (int[]){3, 4});
    lm_tensor *y = lm_reshape(&c, x, 2, (int[]){5, 3});
    CHECK(y == NULL);
    CHECK(c.status == LM_ERR_SHAPE);
    CHECK(strstr(c.msg, "reshape") != NULL && strstr(c.msg, "3x4") != NULL);
    /* later ops see NULL and keep the first message */
    CHECK(lm_slice(&c, y, 0, 0, 1) == NULL);
    CHECK(strstr(c.msg, "reshape") != NULL);
    lm_ctx_clear_error(&c);
    CHECK(lm_slice(&c, x, 1, 2, 3) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_tensor_new(&c, 6, (int[]){1, 1, 1, 1, 1, 1}) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_tensor_new(&c, 2, (int[]){0, 1}) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
}

/* lm_err keeps the first error, on one line whatever the arguments hold. */
static void test_err_one_line(void)
{
    lm_err e = {LM_OK, ""};
    CHECK(lm_err_set(&e, LM_ERR_FORMAT, "%s: channel '%s'", "in.exr", "S0.6\n\n\tnm\r") ==
          LM_ERR_FORMAT);
    CHECK(strcmp(e.msg, "in.exr: channel 'S0.6???nm?'") == 0);
    CHECK(lm_err_set(&e, LM_ERR_IO, "second") == LM_ERR_IO && e.status == LM_ERR_FORMAT);
    lm_err_clear(&e);
    CHECK(e.status == LM_OK && e.msg[0] == 0);
}

static void test_views_share_memory(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float v[24];
    for (int i = 0; i < 24; i++) v[i] = (float)i;
    lm_tensor *x = lm_tensor_from(&c, 3, (int[]){2, 3, 4}, v);
    lm_tensor *r = lm_reshape(&c, x, 2, (int[]){-1, 4});
    CHECK(r && r->shape[0] == 6 && r->data == x->data);
    lm_tensor *s = lm_slice(&c, x, 2, 1, 2); /* 2x3x2, strided */
    CHECK(s && !lm_tensor_is_contiguous(s) && s->data == x->data + 1);
    lm_tensor *sc = lm_contiguous(&c, s);
    float expect[12] = {1, 2, 5, 6, 9, 10, 13, 14, 17, 18, 21, 22};
    CHECK_ARRAY_CLOSE(sc->data, expect, 12, 0, 0);
    lm_tensor *s0 = lm_slice(&c, x, 0, 1, 1); /* contiguous slice */
    CHECK(lm_tensor_is_contiguous(s0) && lm_contiguous(&c, s0) == s0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Gradients of views: slice then reshape, weighted sum -> scattered back. */
static lm_tensor *fn_views(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *s = lm_slice(c, in[0], 2, 1, 3);
    lm_tensor *s2 = lm_slice(c, s, 1, 1, 2);
    return lm_reshape(c, s2, 2, (int[]){-1, 3});
}

static void test_view_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){2, 3, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_views, &x, 1, NULL, NULL);
    /* exact: elements outside the slice get zero gradient */
    lm_ctx_reset(&c);
    x = lm_tensor_uniform(&c, 3, (int[]){2, 3, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = fn_views(&c, &x, 1, NULL);
    lm_backward(&c, y, NULL);
    for (int a = 0; a < 2; a++)
        for (int b = 0; b < 3; b++)
            for (int d = 0; d < 5; d++) {
                float expect = (b >= 1 && b < 3 && d >= 1 && d < 4) ? 1.0f : 0.0f;
                CHECK(x->grad->data[(a * 3 + b) * 5 + d] == expect);
            }
    lm_ctx_free(&c);
}

static void test_scope_releases_in_no_grad(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_ctx_set_grad(&c, 0);
    lm_tensor *x = lm_tensor_full(&c, 1, (int[]){1000}, 2.0f);
    size_t before = c.arena.in_use;
    lm_scope s = lm_scope_begin(&c);
    lm_tensor *junk = lm_tensor_full(&c, 1, (int[]){100000}, 1.0f);
    lm_tensor *keep = lm_tensor_full(&c, 1, (int[]){10}, 3.0f);
    (void)junk;
    keep = lm_scope_end(&c, s, keep);
    CHECK(keep && keep->data[9] == 3.0f && keep->data[0] == 3.0f);
    CHECK(c.arena.in_use < before + 1024);
    CHECK(x->data[999] == 2.0f);
    /* keeping a tensor from outside the scope leaves it untouched */
    s = lm_scope_begin(&c);
    lm_tensor_full(&c, 1, (int[]){1000}, 1.0f);
    CHECK(lm_scope_end(&c, s, x) == x);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_backward_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 1, (int[]){3});
    CHECK(lm_backward(&c, x, NULL) == LM_ERR_ARG); /* nothing requires grad */
    lm_ctx_clear_error(&c);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = lm_reshape(&c, x, 2, (int[]){1, 3});
    lm_tensor *bad = lm_tensor_zeros(&c, 1, (int[]){4});
    CHECK(lm_backward(&c, y, bad) == LM_ERR_SHAPE);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_arena_reuse_after_warmup);
    RUN(test_arena_mark_rewind);
    RUN(test_ctx_steps_allocate_nothing_after_warmup);
    RUN(test_rng_determinism);
    RUN(test_rng_distributions);
    RUN(test_errors_are_sticky);
    RUN(test_views_share_memory);
    RUN(test_view_gradients);
    RUN(test_scope_releases_in_no_grad);
    RUN(test_backward_errors);
    RUN(test_err_one_line);
    return check_summary();
}
