/* tile.c — the tile-resolution family ("tn-C[-dD]-nc"): a network on whole mosaic tiles.
 *     u = unshuffle(raw)                          the P phase planes of each tile (H/ty x W/tx)
 *     f = relu(conv3(u) [+ noise bias])           C channels
 *     f = f + conv3(relu(conv3(f)))   (x D)       D residual blocks (2 unless "-dD")
 *     y = shuffle(conv1(relu(f)))                 33 x P values per tile -> 33 x H x W
 * Every position of the network is one tile (12 pixels on the 3 x 4 map), so at the same
 * multiply-adds it has 12x fewer positions than a network at pixel resolution and can afford
 * ~3.5x the channels, and each 3x3 layer reaches a whole tile further (the five 3x3 layers:
 * 5 tiles each side). Each tile's 12 samples are read together, the way demosaicing needs
 * them; each further block reaches two tiles further. Meant as a residual on the closed-form
 * floor (train --base), whose smooth interpolation it corrects; the last layer starts at zero
 * there (out_layers).
 * "-nc": the first conv also gets the input's noise level as a bias (lm_model_noise_bias).
 * What it is not: patch-size agnostic: H and W must be multiples of the tile (66 x 64 is). */
#include "models/model.h"
#include <stdio.h>
#include <stdlib.h>

typedef struct tile_net {
    lm_conv head, blk[LM_TILE_MAX_BLOCKS][2], tail;
    int blocks;
    lm_tensor *noise; /* "head.noise" (C) or NULL */
} tile_net;

static lm_tensor *tile_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    tile_net *n = m->impl;
    const int ty = m->mosaic.ty, tx = m->mosaic.tx;
    lm_tensor *u = lm_pixel_unshuffle(c, raw, ty, tx);
    lm_tensor *f = lm_conv_forward(c, &n->head, u);
    if (n->noise) f = lm_add(c, f, lm_model_noise_bias(c, m, n->noise, raw->shape[0]));
    f = lm_relu(c, f);
    for (int b = 0; b < n->blocks; b++)
        f = lm_add(c, f, lm_conv_forward(c, &n->blk[b][1],
                                         lm_relu(c, lm_conv_forward(c, &n->blk[b][0], f))));
    lm_tensor *y = lm_conv_forward(c, &n->tail, lm_relu(c, f));
    return lm_pixel_shuffle(c, y, ty, tx);
}

static void tile_init(lm_model *m, lm_rng *r)
{
    tile_net *n = m->impl;
    lm_conv_init_default(&n->head, r); /* the order of the original two-block layout */
    for (int b = 0; b < n->blocks; b++)
        for (int j = 0; j < 2; j++) lm_conv_init_default(&n->blk[b][j], r);
    lm_conv_init_default(&n->tail, r);
}

static void tile_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

lm_status lm_tile_build(lm_model *m, int width, int blocks, int noise_cond, lm_err *err)
{
    tile_net *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = tile_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "tn: out of memory");
    if (width < 1) return lm_err_set(err, LM_ERR_ARG, "tn: width %d < 1", width);
    if (blocks < 1 || blocks > LM_TILE_MAX_BLOCKS)
        return lm_err_set(err, LM_ERR_ARG, "tn: %d residual blocks (1 to %d)", blocks,
                          LM_TILE_MAX_BLOCKS);
    n->blocks = blocks;
    const int P = m->mosaic.ty * m->mosaic.tx, O = m->out_channels, C = width;
    lm_conv_spec tail = {C, O * P, 1, 1, 1, 0, 0, 1, 1};
    if (lm_conv3_declare(&m->params, &n->head, "head", P * m->in_channels, C, err))
        return err->status;
    for (int b = 0; b < blocks; b++)
        for (int j = 0; j < 2; j++) {
            char name[32];
            snprintf(name, sizeof name, "body.%d.%d", b, 2 * j);
            if (lm_conv3_declare(&m->params, &n->blk[b][j], name, C, C, err)) return err->status;
        }
    if (lm_conv_declare(&m->params, &n->tail, "tail", tail, 1, err)) return err->status;
    if (noise_cond) {
        n->noise = lm_params_add(&m->params, "head.noise", 1, &C, 1, err);
        if (!n->noise) return err->status;
        m->noise_input = 1;
    }
    m->forward = tile_forward;
    m->init = tile_init;
    m->out_layers[0] = &n->tail;
    m->n_out_layers = 1;
    snprintf(m->family, sizeof m->family, "tn");
    return LM_OK;
}
