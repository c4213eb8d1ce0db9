/* srnet.c — SRNet (Bian et al. 2024, HyperspecI) adapted to Lumosaic (models.md §4): input =
 * the 12-channel demosaiced LED stack plus a 33-channel per-pixel response map (each pixel's
 * LED response, from the system description); a U-shaped encoder/decoder of spectral
 * self-attention blocks (SAM); H and W padded (reflect) to multiples of 16 inside the model
 * and cropped back. Parameter names follow the official SRNet module. */
#include "models/model.h"
#include "tensor/device.h"
#include <stdio.h>
#include <stdlib.h>

typedef struct sam {
    int dim, heads;
    lm_tensor *n1w, *n1b, *n2w, *n2b, *rescale;
    lm_conv to_q, to_k, to_v, q_dw, k_dw, v_dw, proj;
    lm_conv net1_0, net1_2, net2_0, net2_2, out_conv;
} sam;

typedef struct srnet {
    int dim, stages;
    lm_conv emb1, emb2, emb, down, up, mapping;
    lm_conv enc_down[4], dec_up[4], dec_fuse[4];
    sam enc[4], dec[4], bottleneck;
} srnet;

static lm_tensor *spectral_attention(lm_ctx *c, const sam *s, lm_tensor *x)
{
    int B = x->shape[0], d = s->dim, H = x->shape[2], W = x->shape[3], h = s->heads;
    int shp[3] = {B * h, d / h, H * W};
    /* q, k, v = dwconv(to_*(x)): the three 1x1 convs as one, the three depthwise as one */
    const lm_conv *pw[3] = {&s->to_q, &s->to_k, &s->to_v}, *dw[3] = {&s->q_dw, &s->k_dw, &s->v_dw};
    lm_tensor *qkv = lm_conv_forward_concat(c, dw, 3, lm_conv_forward_concat(c, pw, 3, x, 0), 1);
    lm_tensor *q = lm_reshape(c, lm_slice(c, qkv, 1, 0, d), 3, shp);
    lm_tensor *k = lm_reshape(c, lm_slice(c, qkv, 1, d, d), 3, shp);
    lm_tensor *v = lm_reshape(c, lm_slice(c, qkv, 1, 2 * d, d), 3, shp);
    q = lm_l2_normalize(c, q, -1, 1e-12f);
    k = lm_l2_normalize(c, k, -1, 1e-12f);
    lm_tensor *a = lm_reshape(c, lm_matmul(c, q, k, 0, 1), 4, (int[]){B, h, d / h, d / h});
    a = lm_softmax(c, lm_mul(c, a, s->rescale), -1);
    a = lm_reshape(c, a, 3, (int[]){B * h, d / h, d / h});
    lm_tensor *o = lm_reshape(c, lm_matmul(c, a, v, 0, 0), 4, (int[]){B, d, H, W});
    return lm_conv_forward(c, &s->proj, o);
}

/* out_conv(gelu(cat(o1, o2))), o_i = net_i.2(gelu(net_i.0(x))): both branches at once (the
 * 1x1 convs as one, the depthwise convs as one), whose output is already cat(o1, o2). */
static lm_tensor *ffn(lm_ctx *c, const sam *s, lm_tensor *x)
{
    const lm_conv *pw[2] = {&s->net1_0, &s->net2_0}, *dw[2] = {&s->net1_2, &s->net2_2};
    lm_tensor *o = lm_conv_forward_concat(c, pw, 2, x, 0);
    o = lm_conv_forward_concat(c, dw, 2, lm_gelu(c, o), 1);
    return lm_conv_forward(c, &s->out_conv, lm_gelu(c, o));
}

static lm_tensor *sam_forward(lm_ctx *c, const sam *s, lm_tensor *x)
{
    lm_scope sc = lm_scope_begin(c);
    x = lm_add(c, spectral_attention(c, s, lm_layer_norm_channels(c, x, s->n1w, s->n1b, 1e-5f)), x);
    x = lm_add(c, ffn(c, s, lm_layer_norm_channels(c, x, s->n2w, s->n2b, 1e-5f)), x);
    return lm_scope_end(c, sc, x);
}

/* 1 x 33 x H x W map: every pixel gets its LED's response, normalised to max 1. Built on the
 * host, moved to the ctx's device when the backend is not the CPU. */
static lm_tensor *response_map(lm_ctx *c, const lm_mosaic *m, int H, int W)
{
    lm_tensor *t = lm_tensor_new_on(c, LM_DEVICE_CPU, 4, (int[]){1, LM_MOSAIC_RESP_CH, H, W});
    if (!t) return NULL;
    float mx = 0.0f;
    for (int k = 0; k < m->nch; k++)
        for (int j = 0; j < LM_MOSAIC_RESP_CH; j++)
            if (m->response[k][j] > mx) mx = m->response[k][j];
    float inv = mx > 0 ? 1.0f / mx : 1.0f;
    int chan_of[LM_MOSAIC_MAX_CH] = {0};
    for (int k = 0; k < m->nch; k++) chan_of[m->phase_y[k] * m->tx + m->phase_x[k]] = k;
    for (int j = 0; j < LM_MOSAIC_RESP_CH; j++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                int k = chan_of[(y % m->ty) * m->tx + x % m->tx];
                t->data[((size_t)j * H + y) * W + x] = m->response[k][j] * inv;
            }
    return c->backend->device == LM_DEVICE_CPU ? t : lm_tensor_to_device(c, t);
}

static lm_tensor *srnet_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    srnet *n = m->impl;
    int H = raw->shape[2], W = raw->shape[3];
    int ph = (16 - H % 16) % 16, pw = (16 - W % 16) % 16;
    lm_tensor *x = lm_mosaic_demosaic(c, &m->mosaic, raw);
    lm_tensor *mask = response_map(c, &m->mosaic, H, W);
    if (ph || pw) {
        x = lm_pad2d(c, x, 0, ph, 0, pw, LM_PAD_REFLECT);
        mask = lm_pad2d(c, mask, 0, ph, 0, pw, LM_PAD_REFLECT);
    }
    lm_tensor *e2 = lm_conv_forward(c, &n->emb2, mask); /* same for every batch item */
    lm_tensor *e1 = lm_conv_forward(c, &n->emb1, x);
    /* emb(cat(e1, e2 broadcast to the batch)), with the e2 half convolved once */
    lm_tensor *fea = lm_conv_forward_shared(c, &n->emb, e1, e2);
    lm_tensor *residual = fea, *skips[4];
    fea = lm_conv_forward(c, &n->down, fea);
    for (int i = 0; i < n->stages; i++) {
        skips[i] = fea = sam_forward(c, &n->enc[i], fea);
        fea = lm_conv_forward(c, &n->enc_down[i], fea);
    }
    fea = sam_forward(c, &n->bottleneck, fea);
    for (int i = 0; i < n->stages; i++) {
        fea = lm_conv_forward(c, &n->dec_up[i], fea);
        fea = lm_concat(c, (lm_tensor *[]){fea, skips[n->stages - 1 - i]}, 2, 1);
        fea = sam_forward(c, &n->dec[i], lm_conv_forward(c, &n->dec_fuse[i], fea));
    }
    fea = lm_add(c, lm_conv_forward(c, &n->up, fea), residual);
    if (ph || pw) { /* the mapping conv only where the crop keeps it: H x W plus its halo */
        int hh = H + n->mapping.kh / 2, hw = W + n->mapping.kw / 2;
        if (hh < H + ph) fea = lm_slice(c, fea, 2, 0, hh);
        if (hw < W + pw) fea = lm_slice(c, fea, 3, 0, hw);
    }
    lm_tensor *out = lm_conv_forward(c, &n->mapping, fea);
    if (ph || pw) out = lm_contiguous(c, lm_slice(c, lm_slice(c, out, 2, 0, H), 3, 0, W));
    return out;
}

static void sam_init(sam *s, lm_rng *r)
{
    lm_init_const(s->n1w, 1.0f), lm_init_const(s->n1b, 0.0f);
    lm_conv *convs1[] = {&s->to_q, &s->to_k, &s->to_v, &s->q_dw, &s->k_dw, &s->v_dw};
    for (int i = 0; i < 6; i++) lm_conv_init_default(convs1[i], r);
    lm_init_const(s->rescale, 1.0f);
    lm_conv_init_default(&s->proj, r);
    lm_init_const(s->n2w, 1.0f), lm_init_const(s->n2b, 0.0f);
    lm_conv *convs2[] = {&s->net1_0, &s->net1_2, &s->net2_0, &s->net2_2, &s->out_conv};
    for (int i = 0; i < 5; i++) lm_conv_init_default(convs2[i], r);
}

static void srnet_init(lm_model *m, lm_rng *r)
{
    srnet *n = m->impl;
    lm_conv_init_default(&n->emb1, r);
    lm_conv_init_default(&n->emb2, r);
    lm_conv_init_default(&n->emb, r);
    lm_conv_init_default(&n->down, r);
    lm_conv_init_default(&n->up, r);
    lm_conv_init_default(&n->mapping, r);
    for (int i = 0; i < n->stages; i++) {
        sam_init(&n->enc[i], r);
        lm_conv_init_default(&n->enc_down[i], r);
    }
    sam_init(&n->bottleneck, r);
    for (int i = 0; i < n->stages; i++) {
        lm_conv_init_default(&n->dec_up[i], r);
        lm_conv_init_default(&n->dec_fuse[i], r);
        sam_init(&n->dec[i], r);
    }
}

static lm_status conv_nb(lm_params *p, lm_conv *l, const char *pre, const char *nm, int ci,
                         int co, int k, int stride, int pad, int groups, lm_err *e)
{
    char full[2 * LM_PARAM_NAME_MAX];
    snprintf(full, sizeof full, "%s%s", pre, nm);
    lm_conv_spec s = {ci, co, k, k, stride, pad, pad, groups, 0};
    return lm_conv_declare(p, l, full, s, 1, e);
}

static lm_status declare_sam(lm_params *p, sam *s, const char *pre, int d, int h, lm_err *e)
{
    char nm[LM_PARAM_NAME_MAX];
    s->dim = d, s->heads = h;
#define P_(field, suffix, ...)                                                                  \
    (snprintf(nm, sizeof nm, "%s.blocks.0.%s", pre, suffix),                                  \
     (s->field = lm_params_add(p, nm, __VA_ARGS__, 1, e)) == NULL)
    if (P_(n1w, "0.body.weight", 1, (int[]){d}) || P_(n1b, "0.body.bias", 1, (int[]){d}) ||
        P_(rescale, "1.rescale", 3, (int[]){h, 1, 1}) || P_(n2w, "2.body.weight", 1, (int[]){d}) ||
        P_(n2b, "2.body.bias", 1, (int[]){d}))
        return e->status;
#undef P_
    char a[LM_PARAM_NAME_MAX], f[LM_PARAM_NAME_MAX];
    snprintf(a, sizeof a, "%s.blocks.0.1.", pre);
    snprintf(f, sizeof f, "%s.blocks.0.3.", pre);
    if (conv_nb(p, &s->to_q, a, "to_q", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->to_k, a, "to_k", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->to_v, a, "to_v", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->q_dw, a, "q_dwconv", d, d, 3, 1, 1, d, e) ||
        conv_nb(p, &s->k_dw, a, "k_dwconv", d, d, 3, 1, 1, d, e) ||
        conv_nb(p, &s->v_dw, a, "v_dwconv", d, d, 3, 1, 1, d, e) ||
        conv_nb(p, &s->proj, a, "proj", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->net1_0, f, "net1.0", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->net1_2, f, "net1.2", d, d, 3, 1, 1, d, e) ||
        conv_nb(p, &s->net2_0, f, "net2.0", d, d, 1, 1, 0, 1, e) ||
        conv_nb(p, &s->net2_2, f, "net2.2", d, d, 3, 1, 1, d, e) ||
        conv_nb(p, &s->out_conv, f, "out_conv", 2 * d, d, 1, 1, 0, 1, e))
        return e->status;
    return LM_OK;
}

static void srnet_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

static lm_status declare_stages(lm_params *p, srnet *n, const int *heads, lm_err *e)
{
    char nm[LM_PARAM_NAME_MAX];
    int d = n->dim;
    for (int i = 0; i < n->stages; i++, d *= 2) {
        snprintf(nm, sizeof nm, "encoder_layers.%d.0", i);
        if (declare_sam(p, &n->enc[i], nm, d, heads[i], e)) return e->status;
        snprintf(nm, sizeof nm, "encoder_layers.%d.1", i);
        lm_conv_spec dn = {d, 2 * d, 4, 4, 2, 1, 1, 1, 0};
        if (lm_conv_declare(p, &n->enc_down[i], nm, dn, 1, e)) return e->status;
    }
    if (declare_sam(p, &n->bottleneck, "bottleneck", d, heads[n->stages], e)) return e->status;
    for (int i = 0; i < n->stages; i++, d /= 2) {
        lm_conv_spec up = {d, d / 2, 2, 2, 2, 0, 0, 1, 1}, fuse = {d, d / 2, 1, 1, 1, 0, 0, 1, 0};
        snprintf(nm, sizeof nm, "decoder_layers.%d.0", i);
        if (lm_conv_transpose_declare(p, &n->dec_up[i], nm, up, e)) return e->status;
        snprintf(nm, sizeof nm, "decoder_layers.%d.1", i);
        if (lm_conv_declare(p, &n->dec_fuse[i], nm, fuse, 1, e)) return e->status;
        snprintf(nm, sizeof nm, "decoder_layers.%d.2", i);
        if (declare_sam(p, &n->dec[i], nm, d / 2, heads[n->stages - 1 - i], e)) return e->status;
    }
    return LM_OK;
}

lm_status lm_srnet_build(lm_model *m, int dim, lm_err *err)
{
    srnet *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = srnet_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "srnet: out of memory");
    if (!m->mosaic.has_response)
        return lm_err_set(err, LM_ERR_ARG, "srnet: needs the LED responses of the system "
                          "description (mosaic without response map)");
    n->dim = dim, n->stages = 3;
    static const int heads[4] = {1, 2, 4, 8};
    lm_params *p = &m->params;
    int O = m->out_channels, d = dim;
    if (conv_nb(p, &n->emb1, "", "embedding1", m->mosaic.nch, d, 3, 1, 1, 1, err) ||
        conv_nb(p, &n->emb2, "", "embedding2", LM_MOSAIC_RESP_CH, d, 3, 1, 1, 1, err) ||
        conv_nb(p, &n->emb, "", "embedding", 2 * d, d, 3, 1, 1, 1, err) ||
        conv_nb(p, &n->down, "", "down_sample", d, d, 4, 2, 1, 1, err))
        return err->status;
    lm_conv_spec up = {d, d, 2, 2, 2, 0, 0, 1, 1};
    if (lm_conv_transpose_declare(p, &n->up, "up_sample", up, err) ||
        conv_nb(p, &n->mapping, "", "mapping", d, O, 3, 1, 1, 1, err) ||
        declare_stages(p, n, heads, err))
        return err->status;
    m->forward = srnet_forward;
    m->out_layers[0] = &n->mapping;
    m->n_out_layers = 1;
    m->init = srnet_init;
    snprintf(m->family, sizeof m->family, "srnet");
    return LM_OK;
}
