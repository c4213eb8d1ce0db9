/* gradcheck.c — finite-difference check of analytic gradients for any op or composition.
 * The loss is L = sum_k w_k f_k(in) with random w (a plain sum hides bugs), accumulated in
 * double. Numeric derivative: (L(x + eps) - L(x - eps)) / (2 eps), evaluated in no-grad mode
 * with the arena rewound after each evaluation. */
#include "autograd/autograd.h"
#include "tensor/ops.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

void lm_gradcheck_default_opts(lm_gradcheck_opts *o)
{
    o->eps = 1e-2;
    o->atol = 2e-3;
    o->rtol = 2e-2;
    o->max_checks = 0;
    o->seed = 1234;
}

static double weighted_loss(const lm_tensor *y, const float *w)
{
    double s = 0.0;
    long n = lm_tensor_numel(y);
    for (long i = 0; i < n; i++) s += (double)w[i] * (double)y->data[i];
    return s;
}

/* L at the current input values, without recording. Returns NAN on failure. */
static double eval_loss(lm_ctx *c, lm_gradcheck_fn fn, lm_tensor *const *in, int nin, void *user,
                        const float *w, long nw)
{
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    int was = lm_ctx_set_grad(c, 0);
    lm_tensor *y = fn(c, in, nin, user);
    double L = NAN;
    if (y && !c->status) {
        if (lm_tensor_numel(y) != nw)
            lm_ctx_fail(c, LM_ERR_SHAPE, "gradcheck: output size changed between evaluations");
        else {
            y = lm_contiguous(c, y);
            if (y) L = weighted_loss(y, w);
        }
    }
    lm_ctx_set_grad(c, was);
    lm_arena_rewind(&c->arena, m);
    return L;
}

static void check_one(const lm_gradcheck_opts *o, lm_gradcheck_result *r, int input, long idx,
                      double ana, double num)
{
    double ae = fabs(ana - num);
    double re = ae / (fabs(num) > 1e-12 ? fabs(num) : 1e-12);
    r->checked++;
    int bad = !(ae <= o->atol + o->rtol * fabs(num));
    if (bad) r->failed++;
    if (ae > r->max_abs_err) r->max_abs_err = ae;
    if (re > r->max_rel_err && ae > o->atol) r->max_rel_err = re;
    if (bad && (r->failed == 1 || ae > fabs(r->worst_analytic - r->worst_numeric))) {
        r->worst_input = input;
        r->worst_index = idx;
        r->worst_analytic = ana;
        r->worst_numeric = num;
    }
}

lm_status lm_gradcheck(lm_ctx *c, lm_gradcheck_fn fn, lm_tensor *const *in, int nin, void *user,
                       const lm_gradcheck_opts *opts, lm_gradcheck_result *res)
{
    lm_gradcheck_opts o;
    if (opts) o = *opts;
    else lm_gradcheck_default_opts(&o);
    lm_gradcheck_result r;
    memset(&r, 0, sizeof r);
    r.worst_input = -1;
    for (int i = 0; i < nin; i++) {
        if (!in[i] || in[i]->device != LM_DEVICE_CPU || !lm_tensor_is_contiguous(in[i]))
            return lm_ctx_fail(c, LM_ERR_ARG, "gradcheck: input %d must be a contiguous CPU "
                                              "tensor", i);
        if ((in[i]->flags & LM_PARAM) && in[i]->grad) /* parameters keep their grad block */
            memset(in[i]->grad->data, 0, (size_t)lm_tensor_numel(in[i]) * sizeof(float));
        else
            in[i]->grad = NULL;
    }
    lm_rng rng;
    lm_rng_seed(&rng, o.seed);
    lm_node *tape0 = c->tape; /* the check's own nodes are dropped at the end */
    long len0 = c->tape_len;
    int was = lm_ctx_set_grad(c, 1);
    lm_tensor *y = fn(c, in, nin, user);
    if (!y || c->status) {
        lm_ctx_set_grad(c, was);
        return c->status ? c->status : lm_ctx_fail(c, LM_ERR_ARG, "gradcheck: fn returned NULL");
    }
    long ny = lm_tensor_numel(y);
    lm_tensor *w = lm_tensor_new_on(c, LM_DEVICE_CPU, y->ndim, y->shape); /* weights on the host */
    if (w) lm_rng_fill_uniform(&rng, w->data, ny, -1.0f, 1.0f);
    if (!w || lm_backward(c, y, w) != LM_OK) {
        lm_ctx_set_grad(c, was);
        return c->status;
    }
    lm_ctx_set_grad(c, was);
    for (int i = 0; i < nin && !c->status; i++) {
        if (!lm_requires_grad(in[i])) continue;
        long n = lm_tensor_numel(in[i]);
        long count = (o.max_checks > 0 && o.max_checks < n) ? o.max_checks : n;
        for (long k = 0; k < count && !c->status; k++) {
            long idx = count == n ? k : (long)lm_rng_below(&rng, (uint32_t)n);
            double ana = in[i]->grad ? in[i]->grad->data[idx] : 0.0;
            float x0 = in[i]->data[idx];
            in[i]->data[idx] = (float)(x0 + o.eps);
            double lp = eval_loss(c, fn, in, nin, user, w->data, ny);
            in[i]->data[idx] = (float)(x0 - o.eps);
            double lm = eval_loss(c, fn, in, nin, user, w->data, ny);
            in[i]->data[idx] = x0;
            /* use the actually representable step, not the nominal eps */
            double h = (double)(float)(x0 + o.eps) - (double)(float)(x0 - o.eps);
            check_one(&o, &r, i, idx, ana, (lp - lm) / h);
        }
    }
    if (res) *res = r;
    /* forget the check's nodes, so a later backward in this ctx does not run them again */
    for (lm_node *nd = c->tape; nd && nd != tape0; nd = nd->prev)
        if (!(nd->out->flags & LM_PARAM)) nd->out->grad = NULL;
    c->tape = tape0;
    c->tape_len = len0;
    if (c->status) return c->status;
    if (r.failed)
        return lm_ctx_fail(c, LM_ERR_NUMERIC,
                           "gradcheck: %ld of %ld elements off; worst input %d [%ld]: analytic "
                           "%.6g numeric %.6g (max abs err %.3g)",
                           r.failed, r.checked, r.worst_input, r.worst_index, r.worst_analytic,
                           r.worst_numeric, r.max_abs_err);
    return LM_OK;
}
