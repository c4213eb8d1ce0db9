/* profile.c — dry-run backend and per-layer accounting (see profile.h). */
#include "models/profile.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int dry_run(lm_backend *b, lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt,
                   const void *params)
{
    (void)b, (void)c, (void)k, (void)t, (void)nt, (void)params;
    return 0;
}

static lm_backend dry_backend = {.name = "dry-run", .device = LM_DEVICE_CPU, .run = dry_run};

lm_backend *lm_backend_dry_run(void) { return &dry_backend; }

static void observe(void *user, const char *kind, const lm_tensor *w, const lm_tensor *b,
                    const lm_tensor *x, const lm_tensor *y)
{
    lm_profile *p = user;
    if (p->n == p->cap) {
        int nc = p->cap ? 2 * p->cap : 64;
        lm_layer_stat *nl = realloc(p->layers, (size_t)nc * sizeof *nl);
        if (!nl) return; /* the caller sees a shorter table; totals stay consistent */
        p->layers = nl;
        p->cap = nc;
    }
    lm_layer_stat *s = &p->layers[p->n++];
    memset(s, 0, sizeof *s);
    snprintf(s->name, sizeof s->name, "%s", w->name ? w->name : "?");
    char *dot = strrchr(s->name, '.');
    if (dot && !strcmp(dot, ".weight")) *dot = 0;
    snprintf(s->kind, sizeof s->kind, "%s", kind);
    s->ndim = y->ndim;
    memcpy(s->shape, y->shape, sizeof s->shape);
    s->params = lm_tensor_numel(w) + (b ? lm_tensor_numel(b) : 0);
    long per = 1; /* weight elements per output (conv/linear) or per input (convT) */
    for (int d = 1; d < w->ndim; d++) per *= w->shape[d];
    if (!strcmp(kind, "convT")) s->macs = (double)lm_tensor_numel(x) * (double)per;
    else s->macs = (double)lm_tensor_numel(y) * (double)per;
    p->total_macs += s->macs;
    p->layer_params += s->params;
}

lm_status lm_model_profile(lm_model *m, int B, int H, int W, lm_profile *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    if (B < 1 || H < 1 || W < 1)
        return lm_err_set(err, LM_ERR_ARG, "profile: batch %d, size %dx%d must be positive", B,
                          H, W);
    lm_ctx c;
    if (lm_ctx_init(&c, 1) != LM_OK) return lm_err_set(err, LM_ERR_NOMEM, "profile: no memory");
    lm_ctx_set_backend(&c, &dry_backend);
    lm_ctx_set_grad(&c, 0);
    lm_layer_observe(&c, observe, out);
    lm_tensor *raw = lm_tensor_zeros(&c, 4, (int[]){B, m->in_channels > 0 ? m->in_channels : 1, H, W});
    float sig = m->noise_sigma; /* the cost does not depend on the noise level */
    if (m->noise_input && !(sig >= 0.0f) && !m->noise_sigma_items) m->noise_sigma = 0.0f;
    lm_tensor *y = lm_model_forward(&c, m, raw);
    m->noise_sigma = sig;
    lm_layer_observe(NULL, NULL, NULL);
    lm_status st = LM_OK;
    if (!y) {
        st = lm_err_set(err, lm_ctx_status(&c) ? lm_ctx_status(&c) : LM_ERR_ARG, "%s",
                        lm_ctx_message(&c));
    } else {
        out->out_ndim = y->ndim;
        memcpy(out->out_shape, y->shape, sizeof out->out_shape);
    }
    out->model_params = lm_params_count(&m->params, 0);
    out->trainable_params = lm_params_count(&m->params, 1);
    lm_ctx_free(&c);
    return st;
}

void lm_profile_free(lm_profile *p)
{
    free(p->layers);
    memset(p, 0, sizeof *p);
}
