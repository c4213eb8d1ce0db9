/* linear.c — the linear baseline: phase-aware demosaic, then a per-pixel 1x1 conv 12 -> 33
 * (a learned spectral matrix plus bias). The floor every network must beat. */
#include "models/model.h"
#include <stdio.h>
#include <stdlib.h>

typedef struct linear_net { lm_conv proj; } linear_net;

static lm_tensor *linear_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    linear_net *n = m->impl;
    return lm_conv_forward(c, &n->proj, lm_mosaic_demosaic(c, &m->mosaic, raw));
}

static void linear_init(lm_model *m, lm_rng *r)
{
    linear_net *n = m->impl;
    lm_conv_init_default(&n->proj, r);
}

static void linear_free(lm_model *m)
{
    free(m->impl);
    m->impl = NULL;
}

lm_status lm_linear_build(lm_model *m, lm_err *err)
{
    linear_net *n = calloc(1, sizeof *n);
    m->impl = n;
    m->free_impl = linear_free;
    if (!n) return lm_err_set(err, LM_ERR_NOMEM, "linear: out of memory");
    lm_conv_spec s = {m->mosaic.nch, m->out_channels, 1, 1, 1, 0, 0, 1, 1};
    if (lm_conv_declare(&m->params, &n->proj, "proj", s, 1, err)) return err->status;
    m->forward = linear_forward;
    m->init = linear_init;
    m->conv_rows = 0; /* 1x1 */
    m->out_layers[0] = &n->proj;
    m->n_out_layers = 1;
    snprintf(m->family, sizeof m->family, "linear");
    return LM_OK;
}
