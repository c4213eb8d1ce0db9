/* mst.c — MST++ (Cai et al. 2022, caiyuanhao1998/MST-plus-plus), models.md §5: reflect pad to
 * multiples of 8, conv_in, `stages` MST U-nets of spectral-wise multi-head self-attention
 * blocks (MSAB), conv_out, global residual to conv_in's output, crop back. Parameter names
 * follow the official module (body.<i>.encoder_layers.<s>.0.blocks.0.0.to_q.weight, ...), so
 * weights move between the two. Presets: "mst" (RGB 3 -> 31), "mst-tiny" (one MST, for
 * tests) and "mst-coded" (the raw coded frame, demosaiced to the 12 LED channels -> 31).
 * Attention is global over the image (31 x 31 per head, no windows), so whole frames go
 * through at once; lm_mst_reconstruct runs one frame without gradients, block by block.
 * What it is not: the RGB camera model (data/rgbcam.h) or the training source
 * (train/source_rgb.c). */
#include "models/model.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MST_DIM 31      /* n_feat and the head dimension, hard-coded in the official code */
#define MST_MAX_STAGES 8

typedef struct msab {
    int c, heads;
    lm_linear_layer q, k, v, proj;  /* to_q/to_k/to_v no bias, proj with bias */
    lm_tensor *rescale;             /* heads x 1 x 1, init 1 */
    lm_conv pos0, pos2;             /* depthwise 3x3, no bias */
    lm_conv ff0, ff2, ff4;          /* 1x1 c->4c, dw3 4c, 1x1 4c->c; no bias */
    lm_tensor *nw, *nb;             /* LayerNorm over channels */
} msab;

typedef struct mst_unet {
    lm_conv embedding, down[2], up[2], fuse[2], mapping;
    msab enc[2], bottleneck, dec[2];
} mst_unet;

typedef struct mst {
    int stages, raw_input;          /* raw_input: demosaic the coded frame first */
    lm_conv conv_in, conv_out;
    mst_unet body[MST_MAX_STAGES];
} mst;

/* ---- forward -------------------------------------------------------------------------- */
/* Spectral-wise MSA on x (B x c x H x W): tokens are pixels, attention is c/31 heads of
 * 31 x 31 (A = softmax(K^ Q^T * rho), K^, Q^ L2-normalised over pixels), plus the
 * positional branch dw3(GELU(dw3(V))). */
static lm_tensor *ms_msa(lm_ctx *c, const msab *s, lm_tensor *x)
{
    int B = x->shape[0], C = s->c, H = x->shape[2], W = x->shape[3], h = s->heads;
    lm_tensor *x3 = lm_reshape(c, x, 3, (int[]){B, C, H * W});
    int hs[3] = {B * h, MST_DIM, H * W};
    lm_tensor *q = lm_reshape(c, lm_matmul(c, s->q.w, x3, 0, 0), 3, hs);
    lm_tensor *k = lm_reshape(c, lm_matmul(c, s->k.w, x3, 0, 0), 3, hs);
    lm_tensor *v_inp = lm_matmul(c, s->v.w, x3, 0, 0);            /* B x C x HW */
    q = lm_l2_normalize(c, q, -1, 1e-12f);
    k = lm_l2_normalize(c, k, -1, 1e-12f);
    lm_tensor *a = lm_reshape(c, lm_matmul(c, k, q, 0, 1), 4, (int[]){B, h, MST_DIM, MST_DIM});
    a = lm_softmax(c, lm_mul(c, a, s->rescale), -1);
    a = lm_reshape(c, a, 3, (int[]){B * h, MST_DIM, MST_DIM});
    lm_tensor *o = lm_matmul(c, a, lm_reshape(c, v_inp, 3, hs), 0, 0);
    o = lm_matmul(c, s->proj.w, lm_reshape(c, o, 3, (int[]){B, C, H * W}), 0, 0);
    o = lm_add(c, o, lm_reshape(c, s->proj.b, 2, (int[]){C, 1}));
    lm_tensor *v4 = lm_reshape(c, v_inp, 4, (int[]){B, C, H, W});
    lm_tensor *p = lm_conv_forward(c, &s->pos2, lm_gelu(c, lm_conv_forward(c, &s->pos0, v4)));
    return lm_add(c, lm_reshape(c, o, 4, (int[]){B, C, H, W}), p);
}

static lm_tensor *msab_forward(lm_ctx *c, const msab *s, lm_tensor *x)
{
    lm_scope sc = lm_scope_begin(c);
    x = lm_add(c, ms_msa(c, s, x), x);
    lm_tensor *n = lm_layer_norm_channels(c, x, s->nw, s->nb, 1e-5f);
    lm_tensor *f = lm_gelu(c, lm_conv_forward(c, &s->ff0, n));
    f = lm_conv_forward(c, &s->ff4, lm_gelu(c, lm_conv_forward(c, &s->ff2, f)));
    return lm_scope_end(c, sc, lm_add(c, f, x));
}

static lm_tensor *unet_forward(lm_ctx *c, const mst_unet *u, lm_tensor *x)
{
    lm_tensor *skips[2];
    lm_tensor *f = lm_conv_forward(c, &u->embedding, x);
    for (int i = 0; i < 2; i++) {
        skips[i] = f = msab_forward(c, &u->enc[i], f);
        f = lm_conv_forward(c, &u->down[i], f);
    }
    f = msab_forward(c, &u->bottleneck, f);
    for (int i = 0; i < 2; i++) {
        lm_scope sc = lm_scope_begin(c);
        f = lm_conv_forward(c, &u->up[i], f);
        f = lm_concat(c, (lm_tensor *[]){f, skips[1 - i]}, 2, 1);
        f = lm_scope_end(c, sc, lm_conv_forward(c, &u->fuse[i], f));
        f = msab_forward(c, &u->dec[i], f);
    }
    return lm_add(c, lm_conv_forward(c, &u->mapping, f), x);
}

static lm_tensor *mst_forward(lm_ctx *c, lm_model *m, lm_tensor *in)
{
    mst *n = m->impl;
    int H = in->shape[2], W = in->shape[3];
    int ph = (8 - H % 8) % 8, pw = (8 - W % 8) % 8;
    lm_tensor *x = n->raw_input ? lm_mosaic_demosaic(c, &m->mosaic, in) : in;
    if (x && (ph >= H || pw >= W)) {
        char sb[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s too small to reflect-pad to a multiple of 8",
                    m->preset, lm_shape_str(in, sb, sizeof sb));
        return NULL;
    }
    if (ph || pw) x = lm_pad2d(c, x, 0, ph, 0, pw, LM_PAD_REFLECT);
    lm_tensor *x0 = lm_conv_forward(c, &n->conv_in, x);
    lm_tensor *h = x0;
    for (int i = 0; i < n->stages; i++) {
        lm_scope sc = lm_scope_begin(c);
        h = lm_scope_end(c, sc, unet_forward(c, &n->body[i], h));
    }
    lm_tensor *out = lm_add(c, lm_conv_forward(c, &n->conv_out, h), x0);
    if (ph || pw) out = lm_contiguous(c, lm_slice(c, lm_slice(c, out, 2, 0, H), 3, 0, W));
    return out;
}

/* ---- initialisation (official: Linear trunc-normal std 0.02 (cut-offs +-2, i.e. never hit),
 * biases 0, LayerNorm 1/0, rescale 1, convs PyTorch default) --------------------------- */
static void msab_init(msab *s, lm_rng *r)
{
    lm_init_normal(s->q.w, r, 0.02f);
    lm_init_normal(s->k.w, r, 0.02f);
    lm_init_normal(s->v.w, r, 0.02f);
    lm_init_const(s->rescale, 1.0f);
    lm_init_normal(s->proj.w, r, 0.02f);
    lm_init_const(s->proj.b, 0.0f);
    lm_conv_init_default(&s->pos0, r);
    lm_conv_init_default(&s->pos2, r);
    lm_conv_init_default(&s->ff0, r);
    lm_conv_init_default(&s->ff2, r);
    lm_conv_init_default(&s->ff4, r);
    lm_init_const(s->nw, 1.0f);
    lm_init_const(s->nb, 0.0f);
}

static void unet_init(mst_unet *u, lm_rng *r)
{
    lm_conv_init_default(&u->embedding, r);
    for (int i = 0; i < 2; i++) {
        msab_init(&u->enc[i], r);
        lm_conv_init_default(&u->down[i], r);
    }
    msab_init(&u->bottleneck, r);
    for (int i = 0; i < 2; i++) {
        lm_conv_init_default(&u->up[i], r);
        lm_conv_init_default(&u->fuse[i], r);
        msab_init(&u->dec[i], r);
    }
    lm_conv_init_default(&u->mapping, r);
}

static void mst_init(lm_model *m, lm_rng *r)
{
    mst *n = m->impl;
    lm_conv_init_default(&n->conv_in, r);
    for (int i = 0; i < n->stages; i++) unet_init(&n->body[i], r);
    lm_conv_init_default(&n->conv_out, r);
}

/* ---- declaration, in the official module order ---------------------------------------- */
static lm_status conv_nb(lm_params *p, lm_conv *l, const char *pre, const char *nm, int ci,
                         int co, int k, int stride, int pad, int groups, lm_err *e)
{
    char full[2 * LM_PARAM_NAME_MAX];
    snprintf(full, sizeof full, "%s%s", pre, nm);
    lm_conv_spec s = {ci, co, k, k, stride, pad, pad, groups, 0};
    return lm_conv_declare(p, l, full, s, 1, e);
}

static lm_status lin(lm_params *p, lm_linear_layer *l, const char *pre, const char *nm, int c,
                     int bias, lm_err *e)
{
    char full[2 * LM_PARAM_NAME_MAX];
    snprintf(full, sizeof full, "%s%s", pre, nm);
    return lm_linear_declare(p, l, full, c, c, bias, e);
}

/* MSAB(c, c/31 heads) with one block under "<pre>.blocks.0." */
static lm_status declare_msab(lm_params *p, msab *s, const char *pre, int C, lm_err *e)
{
    char a[LM_PARAM_NAME_MAX], f[LM_PARAM_NAME_MAX], nm[LM_PARAM_NAME_MAX + 16];
    s->c = C, s->heads = C / MST_DIM;
    snprintf(a, sizeof a, "%s.blocks.0.0.", pre);
    snprintf(f, sizeof f, "%s.blocks.0.1.", pre);
    if (lin(p, &s->q, a, "to_q", C, 0, e) || lin(p, &s->k, a, "to_k", C, 0, e) ||
        lin(p, &s->v, a, "to_v", C, 0, e))
        return e->status;
    snprintf(nm, sizeof nm, "%srescale", a);
    if (!(s->rescale = lm_params_add(p, nm, 3, (int[]){s->heads, 1, 1}, 1, e))) return e->status;
    if (lin(p, &s->proj, a, "proj", C, 1, e) ||
        conv_nb(p, &s->pos0, a, "pos_emb.0", C, C, 3, 1, 1, C, e) ||
        conv_nb(p, &s->pos2, a, "pos_emb.2", C, C, 3, 1, 1, C, e) ||
        conv_nb(p, &s->ff0, f, "fn.net.0", C, 4 * C, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->ff2, f, "fn.net.2", 4 * C, 4 * C, 3, 1, 1, 4 * C, e) ||
        conv_nb(p, &s->ff4, f, "fn.net.4", 4 * C, C, 1, 1, 0, 1, e))
        return e->status;
    snprintf(nm, sizeof nm, "%snorm.weight", f);
    if (!(s->nw = lm_params_add(p, nm, 1, &C, 1, e))) return e->status;
    snprintf(nm, sizeof nm, "%snorm.bias", f);
    if (!(s->nb = lm_params_add(p, nm, 1, &C, 1, e))) return e->status;
    return LM_OK;
}

static lm_status declare_unet(lm_params *p, mst_unet *u, const char *pre, lm_err *e)
{
    char nm[LM_PARAM_NAME_MAX];
    int d = MST_DIM;
    if (conv_nb(p, &u->embedding, pre, ".embedding", d, d, 3, 1, 1, 1, e)) return e->status;
    for (int i = 0; i < 2; i++, d *= 2) {
        snprintf(nm, sizeof nm, "%s.encoder_layers.%d.0", pre, i);
        if (declare_msab(p, &u->enc[i], nm, d, e)) return e->status;
        snprintf(nm, sizeof nm, "%s.encoder_layers.%d.1", pre, i);
        if (conv_nb(p, &u->down[i], nm, "", d, 2 * d, 4, 2, 1, 1, e)) return e->status;
    }
    snprintf(nm, sizeof nm, "%s.bottleneck", pre);
    if (declare_msab(p, &u->bottleneck, nm, d, e)) return e->status;
    for (int i = 0; i < 2; i++, d /= 2) {
        lm_conv_spec up = {d, d / 2, 2, 2, 2, 0, 0, 1, 1};
        snprintf(nm, sizeof nm, "%s.decoder_layers.%d.0", pre, i);
        if (lm_conv_transpose_declare(p, &u->up[i], nm, up, e)) return e->status;
        snprintf(nm, sizeof nm, "%s.decoder_layers.%d.1", pre, i);
        if (conv_nb(p, &u->fuse[i], nm, "", d, d / 2, 1, 1, 0, 1, e)) return e->status;
        snprintf(nm, sizeof nm, "%s.decoder_layers.%d.2", pre, i);
        if (declare_msab(p, &u->dec[i], nm, d / 2, e)) return e->status;
    }
    return conv_nb(p, &u->mapping, pre, ".mapping", MST_DIM, MST_DIM, 3, 1, 1, 1, e);
}

static void mst_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

lm_status lm_mst_build(lm_model *m, int stages, int raw_input, lm_err *err)
{
    mst *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = mst_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "mst: out of memory");
    if (stages < 1 || stages > MST_MAX_STAGES)
        return lm_err_set(err, LM_ERR_ARG, "mst: %d stages; need 1..%d", stages, MST_MAX_STAGES);
    n->stages = stages, n->raw_input = raw_input;
    m->in_channels = raw_input ? 1 : 3;
    m->out_channels = MST_DIM; /* the global residual forces out_channels = n_feat = 31 */
    int cin = raw_input ? m->mosaic.nch : 3;
    lm_params *p = &m->params;
    if (conv_nb(p, &n->conv_in, "", "conv_in", cin, MST_DIM, 3, 1, 1, 1, err)) return err->status;
    for (int i = 0; i < stages; i++) {
        char nm[32];
        snprintf(nm, sizeof nm, "body.%d", i);
        if (declare_unet(p, &n->body[i], nm, err)) return err->status;
    }
    if (conv_nb(p, &n->conv_out, "", "conv_out", MST_DIM, m->out_channels, 3, 1, 1, 1, err))
        return err->status;
    m->forward = mst_forward;
    m->init = mst_init;
    snprintf(m->family, sizeof m->family, "mst");
    return LM_OK;
}

lm_status lm_mst_reconstruct(lm_model *m, const float *in, int H, int W, float *out,
                             int nthreads, lm_err *err)
{
    if (!m || m->forward != mst_forward)
        return lm_err_set(err, LM_ERR_ARG, "mst reconstruct: model %s is not MST++",
                          m ? m->preset : "(null)");
    lm_ctx c;
    if (lm_ctx_init(&c, nthreads) != LM_OK)
        return lm_err_set(err, LM_ERR_NOMEM, "mst reconstruct: cannot create a context");
    lm_ctx_set_grad(&c, 0);
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, m->in_channels, H, W}, in);
    lm_tensor *y = lm_model_forward(&c, m, x);
    if (y) lm_tensor_read(&c, y, out);
    lm_status st = lm_ctx_status(&c);
    if (st) lm_err_set(err, st, "mst reconstruct: %s", lm_ctx_message(&c));
    lm_ctx_free(&c);
    return st;
}
