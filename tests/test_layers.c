/* test_layers.c — the fused conv layer helpers of models/layers.c against their plain form:
 * lm_conv_forward_concat (n convs as one: shared input, or stacked inputs for depthwise / grouped
 * convs) against n lm_conv_forward calls and a concatenation; lm_conv_forward_shared (a conv on
 * cat(a, s broadcast over the batch)) against the conv on the explicit concatenation. Outputs and
 * every parameter / input gradient, the layer observer's view (n layers, their MACs), errors. */
#include "models/layers.h"
#include "models/params.h"
#include "tests/check.h"
#include <stdlib.h>

typedef struct net {
    lm_params p;
    lm_conv pw[3], dw[3], big, grp[2];
} net;

static void net_init(net *n)
{
    lm_err e = {0};
    lm_params_init(&n->p);
    char nm[32];
    for (int i = 0; i < 3; i++) {
        snprintf(nm, sizeof nm, "pw%d", i);
        lm_conv_spec pw = {8, 5 + i, 1, 1, 1, 0, 0, 1, 1}; /* different Cout, with bias */
        CHECK(lm_conv_declare(&n->p, &n->pw[i], nm, pw, 1, &e) == LM_OK);
        snprintf(nm, sizeof nm, "dw%d", i);
        lm_conv_spec dw = {4, 4, 3, 3, 1, 1, 1, 4, 0}; /* depthwise, no bias */
        CHECK(lm_conv_declare(&n->p, &n->dw[i], nm, dw, 1, &e) == LM_OK);
    }
    lm_conv_spec big = {10, 6, 3, 3, 1, 1, 1, 1, 1};
    CHECK(lm_conv_declare(&n->p, &n->big, "big", big, 1, &e) == LM_OK);
    for (int i = 0; i < 2; i++) {
        snprintf(nm, sizeof nm, "grp%d", i);
        lm_conv_spec g = {6, 4, 3, 3, 2, 1, 1, 2, 1}; /* groups 2, stride 2 */
        CHECK(lm_conv_declare(&n->p, &n->grp[i], nm, g, 1, &e) == LM_OK);
    }
    CHECK(lm_params_finalize(&n->p, &e) == LM_OK);
    lm_rng r;
    lm_rng_seed(&r, 11);
    for (int i = 0; i < n->p.n; i++) lm_init_uniform(&n->p.items[i]->t, &r, 0.5f);
}

/* which: 0 pointwise concat, 1 depthwise stacked, 3 grouped stacked (2: shared, tested below).
 * fused: the helper, else the plain form. Output into y (numel ny), then grads (input first,
 * then every parameter) into g (numel ng). */
static void run(net *n, int which, int fused, float *y, long *ny, float *g, long *ng)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 12 + which);
    lm_params_zero_grad(&n->p);
    int cin = which == 0 ? 8 : 12;
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, cin, 6, 9}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    const lm_conv *pw[3] = {&n->pw[0], &n->pw[1], &n->pw[2]};
    const lm_conv *dw[3] = {&n->dw[0], &n->dw[1], &n->dw[2]};
    const lm_conv *gr[2] = {&n->grp[0], &n->grp[1]};
    lm_tensor *out = NULL;
    if (fused) {
        out = which == 0 ? lm_conv_forward_concat(&c, pw, 3, x, 0)
            : which == 1 ? lm_conv_forward_concat(&c, dw, 3, x, 1)
                         : lm_conv_forward_concat(&c, gr, 2, x, 1);
    } else {
        lm_tensor *parts[3];
        int k = which == 3 ? 2 : 3;
        for (int i = 0; i < k; i++) {
            const lm_conv *l = which == 0 ? pw[i] : which == 1 ? dw[i] : gr[i];
            lm_tensor *xi = which == 0 ? x : lm_slice(&c, x, 1, i * l->cin, l->cin);
            parts[i] = lm_conv_forward(&c, l, xi);
        }
        out = lm_concat(&c, parts, k, 1);
    }
    CHECK_CTX_OK(&c);
    *ny = *ng = 0;
    if (out) {
        out = lm_contiguous(&c, out);
        *ny = lm_tensor_numel(out);
        memcpy(y, out->data, sizeof(float) * (size_t)*ny);
        lm_tensor *seed = lm_tensor_uniform(&c, out->ndim, out->shape, &r, -1, 1);
        CHECK(lm_backward(&c, out, seed) == LM_OK);
        if (x->grad) {
            *ng = lm_tensor_numel(x);
            memcpy(g, x->grad->data, sizeof(float) * (size_t)*ng);
        }
        memcpy(g + *ng, n->p.grad, sizeof(float) * n->p.total);
        *ng += (long)n->p.total;
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_fused_match_plain(void)
{
    net n;
    net_init(&n);
    const char *what[4] = {"pointwise concat", "depthwise stacked", "shared", "grouped stacked"};
    enum { CAP = 1 << 16 };
    float *y[2], *g[2];
    for (int v = 0; v < 2; v++) y[v] = malloc(sizeof(float) * CAP), g[v] = malloc(sizeof(float) * CAP);
    for (int which = 0; which < 4; which++) {
        if (which == 2) continue; /* below, with an explicit broadcast */
        long ny[2], ng[2];
        for (int v = 0; v < 2; v++) run(&n, which, v, y[v], &ny[v], g[v], &ng[v]);
        CHECK_MSG(ny[0] > 0 && ny[0] == ny[1] && ng[0] == ng[1], "%s", what[which]);
        if (ny[0] > 0 && ny[0] == ny[1] && ng[0] == ng[1]) {
            CHECK_ARRAY_CLOSE(y[1], y[0], ny[0], 1e-5, 1e-5);
            CHECK_ARRAY_CLOSE(g[1], g[0], ng[0], 1e-5, 1e-5);
        }
    }
    for (int v = 0; v < 2; v++) free(y[v]), free(g[v]);
    lm_params_free(&n.p);
}

/* conv(cat(a, s broadcast)) computed plainly: s repeated over the batch with concat. */
static void test_shared_matches_concat(void)
{
    net n;
    net_init(&n);
    float *out[2], *grads[2];
    long no = 0, ng = 0;
    for (int fused = 0; fused < 2; fused++) {
        lm_ctx c;
        lm_ctx_init(&c, 1);
        lm_rng r;
        lm_rng_seed(&r, 21);
        lm_params_zero_grad(&n.p);
        lm_tensor *a = lm_tensor_uniform(&c, 4, (int[]){3, 7, 5, 8}, &r, -1, 1);
        lm_tensor *s = lm_tensor_uniform(&c, 4, (int[]){1, 3, 5, 8}, &r, -1, 1);
        lm_tensor_set_requires_grad(a, 1);
        lm_tensor_set_requires_grad(s, 1);
        lm_tensor *y;
        if (fused) {
            y = lm_conv_forward_shared(&c, &n.big, a, s);
        } else {
            lm_tensor *sb = lm_concat(&c, (lm_tensor *[]){s, s, s}, 3, 0);
            y = lm_conv_forward(&c, &n.big, lm_concat(&c, (lm_tensor *[]){a, sb}, 2, 1));
        }
        CHECK(y && y->shape[0] == 3 && y->shape[1] == 6);
        if (!y) { lm_ctx_free(&c); continue; }
        lm_tensor *seed = lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1);
        CHECK(lm_backward(&c, y, seed) == LM_OK);
        no = lm_tensor_numel(y);
        out[fused] = malloc(sizeof(float) * (size_t)no);
        memcpy(out[fused], y->data, sizeof(float) * (size_t)no);
        ng = 3 * 7 * 40 + 3 * 40 + (long)n.p.total;
        grads[fused] = malloc(sizeof(float) * (size_t)ng);
        memcpy(grads[fused], a->grad->data, sizeof(float) * 3 * 7 * 40);
        memcpy(grads[fused] + 3 * 7 * 40, s->grad->data, sizeof(float) * 3 * 40);
        memcpy(grads[fused] + 3 * 7 * 40 + 3 * 40, n.p.grad, sizeof(float) * n.p.total);
        CHECK_CTX_OK(&c);
        lm_ctx_free(&c);
    }
    CHECK_ARRAY_CLOSE(out[1], out[0], no, 1e-5, 1e-5);
    CHECK_ARRAY_CLOSE(grads[1], grads[0], ng, 1e-5, 1e-5);
    for (int v = 0; v < 2; v++) free(out[v]), free(grads[v]);
    lm_params_free(&n.p);
}

typedef struct seen { int n; double macs; char names[8][32]; } seen;
static void observe(void *user, const char *kind, const lm_tensor *w, const lm_tensor *b,
                    const lm_tensor *x, const lm_tensor *y)
{
    (void)b, (void)x;
    seen *s = user;
    if (strcmp(kind, "conv") || s->n >= 8) return;
    snprintf(s->names[s->n++], 32, "%s", w->name ? w->name : "?");
    long per = 1;
    for (int d = 1; d < w->ndim; d++) per *= w->shape[d];
    s->macs += (double)lm_tensor_numel(y) * per;
}

static void test_observer_and_errors(void)
{
    net n;
    net_init(&n);
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 5);
    seen s = {0};
    lm_layer_observe(&c, observe, &s);
    const lm_conv *pw[3] = {&n.pw[0], &n.pw[1], &n.pw[2]};
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 8, 4, 5}, &r, -1, 1);
    lm_tensor *y = lm_conv_forward_concat(&c, pw, 3, x, 0);
    CHECK(y && y->shape[1] == 5 + 6 + 7);
    CHECK(s.n == 3 && !strcmp(s.names[0], "pw0.weight") && !strcmp(s.names[2], "pw2.weight"));
    CHECK_CLOSE(s.macs, 2.0 * 20 * 8 * (5 + 6 + 7), 0, 0);
    lm_tensor *a = lm_tensor_uniform(&c, 4, (int[]){2, 7, 4, 5}, &r, -1, 1);
    lm_tensor *sh = lm_tensor_uniform(&c, 4, (int[]){1, 3, 4, 5}, &r, -1, 1);
    s = (seen){0};
    CHECK(lm_conv_forward_shared(&c, &n.big, a, sh) != NULL);
    CHECK(s.n == 1 && !strcmp(s.names[0], "big.weight"));
    CHECK_CLOSE(s.macs, 2.0 * 6 * 20 * 10 * 9, 0, 0);
    lm_layer_observe(NULL, NULL, NULL);
    CHECK_CTX_OK(&c);
    /* errors: mixed layers, wrong channel counts, shared input with batch > 1 */
    const lm_conv *mixed[2] = {&n.pw[0], &n.dw[0]};
    CHECK(lm_conv_forward_concat(&c, mixed, 2, x, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_conv_forward_concat(&c, pw, 3, a, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_conv_forward_shared(&c, &n.big, a, a) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
    lm_params_free(&n.p);
}

int main(void)
{
    RUN(test_fused_match_plain);
    RUN(test_shared_matches_concat);
    RUN(test_observer_and_errors);
    return check_summary();
}
