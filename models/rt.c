/* rt.c — the real-time family: the phase-aware demosaic front, then a small branch of
 * two 3x3 convolutions at `width` channels, and one 1x1 head over the demosaic and the branch:
 *     x = demosaic(raw);  f = relu(body2(relu(body0([x, raw]))));  y = head([x, f])
 * The branch also reads the raw mosaic itself, where each pixel's exact sample and its tile
 * phase show (+1.3 dB validation PSNR over the demosaic alone for rt-16, test_train_slow).
 * The head's first 12 input columns are the linear baseline's spectral map (12 -> 33, plus
 * the bias), the other `width` columns the residual the branch adds to it; one conv over the
 * concatenation costs less memory traffic than two 33-channel convs and an add (measured).
 * Purely convolutional with a finite receptive field (demosaic + two 3x3 convs), so whole frames
 * run in strips (infer/whole.h) instead of overlapping windows; sized so that a 640x480 frame
 * reconstructs at >= 30 frames per second on two cores (bench/bench_rt.c).
 * Both buckets (LM_CAP_TWO_BUCKETS, "rt-N-b2"): the branch's first conv reads the bucket-0
 * plane beside bucket 1 (P + 2 input channels); the demosaic and the head are unchanged.
 * Multi-frame (LM_CAP_MULTI_FRAME, "rt-N-mf3"): likewise the two neighbour frames moved onto
 * the current one (P + 3 input channels).
 * Noise-conditioned ("rt-N-nc"): the branch's first conv also gets a per-channel bias
 * proportional to the input's noise sd (body.0.noise, width values, starting at 0), the sd
 * estimated from each frame as for lmmse (noise_input; train and infer set it): the same as
 * a constant noise-level input plane away from the borders, so one model can learn to leave
 * clean frames alone and denoise noisy ones (a residual trained on noisy samples only loses
 * 0.1-0.3 dB on clean frames against its lmmse base).
 * What it is not: an attention network; nothing here depends on the frame size. */
#include "models/model.h"
#include "tensor/device.h"
#include <stdio.h>
#include <stdlib.h>

typedef struct rt_net {
    lm_conv body0, body2, head;
    lm_tensor *noise; /* "body.0.noise" (width) or NULL */
} rt_net;

static lm_tensor *rt_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    rt_net *n = m->impl;
    /* both buckets or three frames (in_channels 2, 3): the demosaic of plane 0 (bucket 1 of the
     * current frame); the branch reads every plane */
    lm_tensor *b1 = m->in_channels == 1 ? raw : lm_contiguous(c, lm_slice(c, raw, 1, 0, 1));
    lm_tensor *x = lm_mosaic_demosaic(c, &m->mosaic, b1);
    lm_tensor *xr[2] = {x, raw};
    lm_tensor *f = lm_conv_forward(c, &n->body0, lm_concat(c, xr, 2, 1));
    if (n->noise) f = lm_add(c, f, lm_model_noise_bias(c, m, n->noise, raw->shape[0]));
    f = lm_relu(c, f);
    lm_tensor *xf[2] = {x, lm_relu(c, lm_conv_forward(c, &n->body2, f))};
    return lm_conv_forward(c, &n->head, lm_concat(c, xf, 2, 1));
}

static void rt_init(lm_model *m, lm_rng *r)
{
    rt_net *n = m->impl;
    lm_conv_init_default(&n->body0, r);
    lm_conv_init_default(&n->body2, r);
    lm_conv_init_default(&n->head, r);
}

static void rt_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

lm_status lm_rt_build(lm_model *m, int width, int noise_cond, lm_err *err)
{
    rt_net *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = rt_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "rt: out of memory");
    if (width < 1) return lm_err_set(err, LM_ERR_ARG, "rt: width %d < 1", width);
    int P = m->mosaic.nch, O = m->out_channels;
    lm_conv_spec head = {P + width, O, 1, 1, 1, 0, 0, 1, 1};
    if (lm_conv3_declare(&m->params, &n->body0, "body.0", P + m->in_channels, width, err) ||
        lm_conv3_declare(&m->params, &n->body2, "body.2", width, width, err) ||
        lm_conv_declare(&m->params, &n->head, "head", head, 1, err))
        return err->status;
    if (noise_cond) {
        n->noise = lm_params_add(&m->params, "body.0.noise", 1, &width, 1, err);
        if (!n->noise) return err->status;
        m->noise_input = 1;
    }
    m->forward = rt_forward;
    m->init = rt_init;
    m->conv_rows = 2; /* two 3x3 (the 1x1 convs add nothing) */
    m->out_layers[0] = &n->head;
    m->n_out_layers = 1;
    snprintf(m->family, sizeof m->family, "rt");
    return LM_OK;
}
