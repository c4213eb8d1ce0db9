/* layers.c — conv / linear layers with PyTorch-default initialisation; the demosaic front. */
#include "models/layers.h"
#include <math.h>
#include <stdio.h>
#include <string.h>

static lm_status declare_wb(lm_params *p, lm_tensor **w, lm_tensor **b, const char *name,
                            int ndim, const int *wshape, int nbias, int trainable, lm_err *err)
{
    char buf[LM_PARAM_NAME_MAX + 16];
    snprintf(buf, sizeof buf, "%s.weight", name);
    *w = lm_params_add(p, buf, ndim, wshape, trainable, err);
    if (!*w) return err ? err->status : LM_ERR_ARG;
    *b = NULL;
    if (nbias > 0) {
        snprintf(buf, sizeof buf, "%s.bias", name);
        *b = lm_params_add(p, buf, 1, &nbias, trainable, err);
        if (!*b) return err ? err->status : LM_ERR_ARG;
    }
    return LM_OK;
}

lm_status lm_conv_declare(lm_params *p, lm_conv *l, const char *name, lm_conv_spec s,
                          int trainable, lm_err *err)
{
    int g = s.groups > 0 ? s.groups : 1;
    if (s.cin % g || s.cout % g)
        return lm_err_set(err, LM_ERR_ARG, "%s: channels %d -> %d not divisible by groups %d",
                          name, s.cin, s.cout, g);
    l->cin = s.cin, l->cout = s.cout, l->kh = s.kh, l->kw = s.kw, l->transposed = 0;
    l->o = (lm_conv2d_opts){s.stride, s.stride, s.pad_h, s.pad_w, 1, 1, g};
    int ws[4] = {s.cout, s.cin / g, s.kh, s.kw};
    return declare_wb(p, &l->w, &l->b, name, 4, ws, s.bias ? s.cout : 0, trainable, err);
}

lm_status lm_conv3_declare(lm_params *p, lm_conv *l, const char *name, int cin, int cout,
                           lm_err *err)
{
    lm_conv_spec s = {cin, cout, 3, 3, 1, 1, 1, 1, 1};
    return lm_conv_declare(p, l, name, s, 1, err);
}

lm_status lm_conv_transpose_declare(lm_params *p, lm_conv *l, const char *name, lm_conv_spec s,
                                    lm_err *err)
{
    int g = s.groups > 0 ? s.groups : 1;
    if (s.cin % g || s.cout % g)
        return lm_err_set(err, LM_ERR_ARG, "%s: channels %d -> %d not divisible by groups %d",
                          name, s.cin, s.cout, g);
    l->cin = s.cin, l->cout = s.cout, l->kh = s.kh, l->kw = s.kw, l->transposed = 1;
    l->o = (lm_conv2d_opts){s.stride, s.stride, s.pad_h, s.pad_w, 1, 1, g};
    int ws[4] = {s.cin, s.cout / g, s.kh, s.kw};
    return declare_wb(p, &l->w, &l->b, name, 4, ws, s.bias ? s.cout : 0, 1, err);
}

void lm_conv_init_default(lm_conv *l, lm_rng *r)
{
    int g = l->o.groups > 0 ? l->o.groups : 1;
    int fan_in = (l->transposed ? l->cout / g : l->cin / g) * l->kh * l->kw;
    float bound = 1.0f / sqrtf((float)fan_in);
    lm_init_uniform(l->w, r, bound);
    if (l->b) lm_init_uniform(l->b, r, bound);
}

static const lm_ctx *observed_ctx;
static lm_layer_observer observer;
static void *observer_user;

void lm_layer_observe(const lm_ctx *c, lm_layer_observer fn, void *user)
{
    observed_ctx = fn ? c : NULL;
    observer = fn;
    observer_user = user;
}

lm_tensor *lm_conv_forward(lm_ctx *c, const lm_conv *l, lm_tensor *x)
{
    lm_tensor *y = l->transposed ? lm_conv_transpose2d(c, x, l->w, l->b, &l->o, 0, 0)
                                 : lm_conv2d(c, x, l->w, l->b, &l->o);
    if (observer && observed_ctx == c && y)
        observer(observer_user, l->transposed ? "convT" : "conv", l->w, l->b, x, y);
    return y;
}

lm_tensor *lm_conv_forward_shared(lm_ctx *c, const lm_conv *l, lm_tensor *a, lm_tensor *s)
{
    if (!lm_check_inputs(c, "conv_forward_shared", 2, a, s)) return NULL;
    int g = l->o.groups > 0 ? l->o.groups : 1;
    if (l->transposed || g != 1 || a->ndim != 4 || s->ndim != 4 || s->shape[0] != 1 ||
        a->shape[1] + s->shape[1] != l->cin) {
        char sa[64], ss[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv_forward_shared: inputs %s and %s (shared, batch 1) "
                    "do not make the %d input channels of a plain conv", lm_shape_str(a, sa,
                    sizeof sa), lm_shape_str(s, ss, sizeof ss), l->cin);
        return NULL;
    }
    int ca = a->shape[1], cs = s->shape[1];
    lm_tensor *ya = lm_conv2d(c, a, lm_slice(c, l->w, 1, 0, ca), NULL, &l->o);
    lm_tensor *ys = lm_conv2d(c, s, lm_slice(c, l->w, 1, ca, cs), l->b, &l->o);
    lm_tensor *y = lm_add(c, ya, ys);
    if (observer && observed_ctx == c && y) observer(observer_user, "conv", l->w, l->b, a, y);
    return y;
}

lm_tensor *lm_conv_forward_concat(lm_ctx *c, const lm_conv *const *ls, int n, lm_tensor *x,
                                  int stacked)
{
    if (!lm_check_inputs(c, "conv_forward_concat", 1, x)) return NULL;
    enum { MAXN = 8 };
    const lm_conv *l0 = ls[0];
    int g = l0->o.groups > 0 ? l0->o.groups : 1, ok = n >= 1 && n <= MAXN && !l0->transposed;
    for (int i = 1; ok && i < n; i++) {
        const lm_conv *l = ls[i];
        ok = !l->transposed && l->cin == l0->cin && l->kh == l0->kh && l->kw == l0->kw &&
             !memcmp(&l->o, &l0->o, sizeof l->o) && !l->b == !l0->b;
    }
    int cin = stacked ? n * l0->cin : l0->cin;
    if (!ok || x->ndim != 4 || x->shape[1] != cin) {
        char sx[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv_forward_concat: %d layers that differ in input "
                    "channels, kernel, options or bias, or input %s (need %d channels)", n,
                    lm_shape_str(x, sx, sizeof sx), cin);
        return NULL;
    }
    lm_tensor *ws[MAXN], *bs[MAXN];
    for (int i = 0; i < n; i++) ws[i] = ls[i]->w, bs[i] = ls[i]->b;
    lm_conv2d_opts o = l0->o;
    if (stacked) o.groups = n * g;
    lm_tensor *w = n > 1 ? lm_concat(c, ws, n, 0) : ws[0];
    lm_tensor *b = l0->b && n > 1 ? lm_concat(c, bs, n, 0) : bs[0];
    lm_tensor *y = lm_conv2d(c, x, w, b, &o);
    if (observer && observed_ctx == c && y) {
        int c0 = 0;
        for (int i = 0; i < n; i++) {
            lm_tensor *xi = stacked ? lm_slice(c, x, 1, i * l0->cin, l0->cin) : x;
            lm_tensor *yi = lm_slice(c, y, 1, c0, ls[i]->cout);
            if (xi && yi) observer(observer_user, "conv", ls[i]->w, ls[i]->b, xi, yi);
            c0 += ls[i]->cout;
        }
    }
    return y;
}

lm_status lm_linear_declare(lm_params *p, lm_linear_layer *l, const char *name, int in, int out,
                            int bias, lm_err *err)
{
    l->in = in, l->out = out;
    int ws[2] = {out, in};
    return declare_wb(p, &l->w, &l->b, name, 2, ws, bias ? out : 0, 1, err);
}

void lm_linear_init_default(lm_linear_layer *l, lm_rng *r)
{
    float bound = 1.0f / sqrtf((float)l->in);
    lm_init_uniform(l->w, r, bound);
    if (l->b) lm_init_uniform(l->b, r, bound);
}

lm_tensor *lm_linear_forward(lm_ctx *c, const lm_linear_layer *l, lm_tensor *x)
{
    lm_tensor *y = lm_linear(c, x, l->w, l->b);
    if (observer && observed_ctx == c && y) observer(observer_user, "linear", l->w, l->b, x, y);
    return y;
}

lm_tensor *lm_mosaic_demosaic(lm_ctx *c, const lm_mosaic *m, lm_tensor *raw)
{
    return lm_mosaic_upsample(c, raw, m->ty, m->tx, m->nch, m->phase_y, m->phase_x);
}
