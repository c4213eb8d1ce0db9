/* han.c — HAN (Holistic Attention Network), Lumosaic variant (models.md §2): head conv,
 * G residual groups of B RCABs (channel attention), body-tail conv, layer attention (LAM) over
 * the stack of group outputs, channel-spatial attention (CSAM) on the body output, fusion, global
 * residual and a 33-channel tail. Parameter names follow the official PyTorch module names.
 * "han-tiny-nc" (cfg.noise_cond): the head's output also gets a per-channel bias proportional
 * to the input's noise sd ("head.0.noise", feats values starting at 0; lm_model_noise_bias),
 * the rt-N-nc conditioning, so one model can leave clean frames alone and denoise noisy ones. */
#include "models/model.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct rcab { lm_conv c1, c2, du1, du2; } rcab;
typedef struct rgroup { rcab *blocks; lm_conv tail; } rgroup;

typedef struct han {
    lm_han_cfg cfg;
    lm_conv head, body_tail, last_conv, last, tail;
    rgroup *groups;
    lm_tensor *lam_gamma, *csa_gamma;
    lm_tensor *csa_w, *csa_b;      /* Conv3d(1, 1, 3): 1x1x3x3x3 and 1 */
    lm_tensor *noise;              /* "head.0.noise" (feats) or NULL */
} han;

/* CALayer: x * sigmoid(conv(relu(conv(gap(x))))) */
static lm_tensor *channel_attention(lm_ctx *c, const rcab *r, lm_tensor *x)
{
    lm_tensor *s = lm_global_avg_pool(c, x);
    s = lm_relu(c, lm_conv_forward(c, &r->du1, s));
    s = lm_sigmoid(c, lm_conv_forward(c, &r->du2, s));
    return lm_mul(c, x, s);
}

static lm_tensor *rcab_forward(lm_ctx *c, const rcab *r, lm_tensor *x)
{
    lm_scope sc = lm_scope_begin(c);
    lm_tensor *t = lm_relu(c, lm_conv_forward(c, &r->c1, x));
    t = channel_attention(c, r, lm_conv_forward(c, &r->c2, t));
    return lm_scope_end(c, sc, lm_add(c, t, x));
}

static lm_tensor *group_forward(lm_ctx *c, const han *h, const rgroup *g, lm_tensor *x)
{
    lm_scope sc = lm_scope_begin(c); /* no-grad: frees the block outputs of this group */
    lm_tensor *r = x;
    for (int b = 0; b < h->cfg.blocks; b++) r = rcab_forward(c, &g->blocks[b], r);
    return lm_scope_end(c, sc, lm_add(c, lm_conv_forward(c, &g->tail, r), x));
}

/* LAM: F = stack (B x N x D); out = gamma * softmax(-F F^T) F + F, as B x (N C) x H x W. */
static lm_tensor *layer_attention(lm_ctx *c, const han *h, lm_tensor *stack, int n, int ch)
{
    int B = stack->shape[0], H = stack->shape[2], W = stack->shape[3];
    lm_tensor *f = lm_reshape(c, stack, 3, (int[]){B, n, ch * H * W});
    lm_tensor *e = lm_matmul(c, f, f, 0, 1);            /* B x N x N */
    lm_tensor *a = lm_softmax(c, lm_neg(c, e), -1);    /* = softmax(rowmax - E) */
    lm_tensor *o = lm_matmul(c, a, f, 0, 0);            /* B x N x D */
    lm_tensor *out = lm_add(c, lm_mul(c, o, h->lam_gamma), f);
    return lm_reshape(c, out, 4, (int[]){B, n * ch, H, W});
}

/* CSAM: x * (1 + gamma * sigmoid(conv3d(x as B x 1 x C x H x W))). */
static lm_tensor *channel_spatial_attention(lm_ctx *c, const han *h, lm_tensor *x)
{
    int B = x->shape[0], C = x->shape[1], H = x->shape[2], W = x->shape[3];
    lm_tensor *v = lm_reshape(c, x, 5, (int[]){B, 1, C, H, W});
    lm_tensor *z = lm_sigmoid(c, lm_conv3d(c, v, h->csa_w, h->csa_b, 1, 1, 1));
    z = lm_mul(c, lm_reshape(c, z, 4, (int[]){B, C, H, W}), h->csa_gamma);
    return lm_add(c, lm_mul(c, x, z), x);
}

static lm_tensor *han_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    han *h = m->impl;
    int G = h->cfg.groups, C = h->cfg.feats;
    lm_tensor *x0 = lm_conv_forward(c, &h->head, lm_mosaic_demosaic(c, &m->mosaic, raw));
    if (h->noise) x0 = lm_add(c, x0, lm_model_noise_bias(c, m, h->noise, raw->shape[0]));
    lm_tensor **outs = lm_ctx_alloc(c, (size_t)(G + 1) * sizeof *outs);
    if (!x0 || !outs) return NULL;
    lm_tensor *r = x0;
    for (int g = 0; g < G; g++) outs[g] = r = group_forward(c, h, &h->groups[g], r);
    outs[G] = r = lm_conv_forward(c, &h->body_tail, r);
    /* stack newest first: [body-tail, RG_G, ..., RG_1] */
    lm_tensor **rev = lm_ctx_alloc(c, (size_t)(G + 1) * sizeof *rev);
    if (!rev) return NULL;
    for (int i = 0; i <= G; i++) rev[i] = outs[G - i];
    lm_tensor *stack = lm_concat(c, rev, G + 1, 1);   /* B x (G+1)C x H x W, layer-major */
    lm_tensor *o2 = lm_conv_forward(c, &h->last_conv, layer_attention(c, h, stack, G + 1, C));
    lm_tensor *o1 = channel_spatial_attention(c, h, r);
    lm_tensor *fused = lm_conv_forward(c, &h->last, lm_concat(c, (lm_tensor *[]){o1, o2}, 2, 1));
    return lm_conv_forward(c, &h->tail, lm_add(c, fused, x0));
}

static void han_init(lm_model *m, lm_rng *r)
{
    han *h = m->impl;
    lm_conv_init_default(&h->head, r);
    for (int g = 0; g < h->cfg.groups; g++) {
        for (int b = 0; b < h->cfg.blocks; b++) {
            rcab *k = &h->groups[g].blocks[b];
            lm_conv_init_default(&k->c1, r);
            lm_conv_init_default(&k->c2, r);
            lm_conv_init_default(&k->du1, r);
            lm_conv_init_default(&k->du2, r);
        }
        lm_conv_init_default(&h->groups[g].tail, r);
    }
    lm_conv_init_default(&h->body_tail, r);
    lm_init_const(h->lam_gamma, 0.0f);
    lm_conv_init_default(&h->last_conv, r);
    float bound = 1.0f / sqrtf(27.0f); /* Conv3d(1, 1, 3): fan_in 27 */
    lm_init_uniform(h->csa_w, r, bound);
    lm_init_uniform(h->csa_b, r, bound);
    lm_init_const(h->csa_gamma, 0.0f);
    lm_conv_init_default(&h->last, r);
    lm_conv_init_default(&h->tail, r);
}

static void han_free(lm_model *m)
{
    han *h = m->impl;
    if (!h) return;
    for (int g = 0; h->groups && g < h->cfg.groups; g++) free(h->groups[g].blocks);
    free(h->groups);
    free(h);
    m->impl = NULL;
}

static lm_status declare_group(lm_params *p, rgroup *g, int gi, const lm_han_cfg *cfg, lm_err *e)
{
    int C = cfg->feats, Cr = cfg->feats / cfg->reduction;
    char nm[LM_PARAM_NAME_MAX];
    g->blocks = calloc((size_t)cfg->blocks, sizeof *g->blocks);
    if (!g->blocks) return lm_err_set(e, LM_ERR_NOMEM, "han: out of memory");
    for (int b = 0; b < cfg->blocks; b++) {
        rcab *k = &g->blocks[b];
        lm_conv_spec one_down = {C, Cr, 1, 1, 1, 0, 0, 1, 1}, one_up = {Cr, C, 1, 1, 1, 0, 0, 1, 1};
        snprintf(nm, sizeof nm, "body.%d.body.%d.body.0", gi, b);
        if (lm_conv3_declare(p, &k->c1, nm, C, C, e)) return e->status;
        snprintf(nm, sizeof nm, "body.%d.body.%d.body.2", gi, b);
        if (lm_conv3_declare(p, &k->c2, nm, C, C, e)) return e->status;
        snprintf(nm, sizeof nm, "body.%d.body.%d.body.3.conv_du.0", gi, b);
        if (lm_conv_declare(p, &k->du1, nm, one_down, 1, e)) return e->status;
        snprintf(nm, sizeof nm, "body.%d.body.%d.body.3.conv_du.2", gi, b);
        if (lm_conv_declare(p, &k->du2, nm, one_up, 1, e)) return e->status;
    }
    snprintf(nm, sizeof nm, "body.%d.body.%d", gi, cfg->blocks);
    return lm_conv3_declare(p, &g->tail, nm, C, C, e);
}

lm_status lm_han_build(lm_model *m, lm_han_cfg cfg, lm_err *err)
{
    if (cfg.groups < 1 || cfg.blocks < 1 || cfg.feats < 1 || cfg.reduction < 1 ||
        cfg.feats % cfg.reduction)
        return lm_err_set(err, LM_ERR_ARG, "han: need groups, blocks, feats >= 1 and feats "
                          "divisible by reduction (got G%d B%d C%d r%d)", cfg.groups, cfg.blocks,
                          cfg.feats, cfg.reduction);
    han *h = calloc(1, sizeof *h);
    if (h) h->groups = calloc((size_t)cfg.groups, sizeof *h->groups);
    m->impl = h;
    m->free_impl = han_free;
    if (!h || !h->groups) return lm_err_set(err, LM_ERR_NOMEM, "han: out of memory");
    h->cfg = cfg;
    lm_params *p = &m->params;
    int C = cfg.feats, N = cfg.groups + 1;
    if (lm_conv3_declare(p, &h->head, "head.0", m->mosaic.nch, C, err)) return err->status;
    if (cfg.noise_cond) {
        if (!(h->noise = lm_params_add(p, "head.0.noise", 1, &C, 1, err))) return err->status;
        m->noise_input = 1;
    }
    for (int g = 0; g < cfg.groups; g++)
        if (declare_group(p, &h->groups[g], g, &cfg, err)) return err->status;
    char nm[LM_PARAM_NAME_MAX];
    snprintf(nm, sizeof nm, "body.%d", cfg.groups);
    if (lm_conv3_declare(p, &h->body_tail, nm, C, C, err)) return err->status;
    if (!(h->csa_w = lm_params_add(p, "csa.conv.weight", 5, (int[]){1, 1, 3, 3, 3}, 1, err)) ||
        !(h->csa_b = lm_params_add(p, "csa.conv.bias", 1, (int[]){1}, 1, err)) ||
        !(h->csa_gamma = lm_params_add(p, "csa.gamma", 1, (int[]){1}, 1, err)) ||
        !(h->lam_gamma = lm_params_add(p, "la.gamma", 1, (int[]){1}, 1, err)))
        return err->status;
    if (lm_conv3_declare(p, &h->last_conv, "last_conv", N * C, C, err) ||
        lm_conv3_declare(p, &h->last, "last", 2 * C, C, err) ||
        lm_conv3_declare(p, &h->tail, "tail.1", C, m->out_channels, err))
        return err->status;
    m->forward = han_forward;
    m->out_layers[0] = &h->tail;
    m->n_out_layers = 1;
    m->init = han_init;
    snprintf(m->family, sizeof m->family, "han");
    return LM_OK;
}
