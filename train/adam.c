/* adam.c — Adam/AdamW update and learning-rate schedules. */
#include "train/adam.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

void lm_adam_default_cfg(lm_adam_cfg *c)
{
    memset(c, 0, sizeof *c);
    c->lr = 1e-4f;
    c->beta1 = 0.9f;
    c->beta2 = 0.999f;
    c->eps = 1e-8f;
    c->step_gamma = 0.5f;
}

lm_status lm_adam_init(lm_adam *o, const lm_params *p, const lm_adam_cfg *cfg, lm_err *err)
{
    memset(o, 0, sizeof *o);
    o->cfg = *cfg;
    if (!(cfg->lr > 0) || !(cfg->beta1 >= 0 && cfg->beta1 < 1) || !(cfg->beta2 >= 0 && cfg->beta2 < 1)
        || !(cfg->eps > 0) || cfg->weight_decay < 0 || !(cfg->ema >= 0 && cfg->ema < 1))
        return lm_err_set(err, LM_ERR_ARG, "adam: need lr > 0, 0 <= betas < 1, eps > 0, "
                          "weight_decay >= 0, 0 <= ema < 1");
    if (!p->finalized) return lm_err_set(err, LM_ERR_ARG, "adam: parameters not finalized");
    o->n = p->total;
    o->m = calloc(o->n ? o->n : 1, sizeof(float));
    o->v = calloc(o->n ? o->n : 1, sizeof(float));
    if (cfg->ema > 0 && (o->ema = calloc(o->n ? o->n : 1, sizeof(float))))
        for (int i = 0; i < p->n; i++) /* the average starts at the initial weights */
            memcpy(o->ema + p->items[i]->offset, p->items[i]->t.data,
                   (size_t)lm_tensor_numel(&p->items[i]->t) * sizeof(float));
    if (!o->m || !o->v || (cfg->ema > 0 && !o->ema)) {
        lm_adam_free(o);
        return lm_err_set(err, LM_ERR_NOMEM, "adam: out of memory for %zu moments", p->total);
    }
    return LM_OK;
}

void lm_adam_free(lm_adam *o)
{
    free(o->m);
    free(o->v);
    free(o->ema);
    o->m = o->v = o->ema = NULL;
}

float lm_adam_lr(const lm_adam_cfg *c, long step)
{
    double lr = c->lr;
    if (c->warmup_steps > 0 && step < c->warmup_steps)
        return (float)(lr * (double)(step + 1) / (double)c->warmup_steps);
    switch (c->schedule) {
    case LM_LR_COSINE: {
        long span = c->total_steps - c->warmup_steps;
        double t = span > 0 ? (double)(step - c->warmup_steps) / (double)span : 1.0;
        if (t > 1.0) t = 1.0;
        lr = c->lr_min + 0.5 * (c->lr - c->lr_min) * (1.0 + cos(M_PI * t));
        break;
    }
    case LM_LR_STEP:
        if (c->step_every > 0) lr *= pow(c->step_gamma, (double)(step / c->step_every));
        break;
    case LM_LR_CONSTANT: break;
    }
    return (float)lr;
}

void lm_adam_step(lm_adam *o, lm_params *p, int nthreads)
{
    const lm_adam_cfg *c = &o->cfg;
    float lr = lm_adam_lr(c, o->step);
    o->step++;
    double bc1 = 1.0 - pow(c->beta1, (double)o->step), bc2 = 1.0 - pow(c->beta2, (double)o->step);
    float step_size = (float)(lr / bc1), inv_sqrt_bc2 = (float)(1.0 / sqrt(bc2));
    float b1 = c->beta1, b2 = c->beta2, eps = c->eps, wd = c->weight_decay;
    int decoupled = c->decoupled;
    /* the average's decay, lower while it has seen few updates (its start is the init) */
    double ramp = (double)o->step / (double)(o->step + 9);
    float d = (float)(c->ema < ramp ? c->ema : ramp);
    for (int i = 0; i < p->n; i++) {
        const lm_param *e = p->items[i];
        if (!e->trainable) continue;
        long n = lm_tensor_numel(&e->t);
        float *w = e->t.data, *g = e->g.data, *m = o->m + e->offset, *v = o->v + e->offset;
        float *a = o->ema ? o->ema + e->offset : NULL;
#pragma omp parallel for num_threads(nthreads) schedule(static) if (n > 65536)
        for (long k = 0; k < n; k++) {
            float gk = g[k];
            if (wd > 0 && !decoupled) gk += wd * w[k];
            if (wd > 0 && decoupled) w[k] -= lr * wd * w[k];
            m[k] = b1 * m[k] + (1.0f - b1) * gk;
            v[k] = b2 * v[k] + (1.0f - b2) * gk * gk;
            w[k] -= step_size * m[k] / (sqrtf(v[k]) * inv_sqrt_bc2 + eps);
            if (a) a[k] = d * a[k] + (1.0f - d) * w[k];
        }
    }
}

void lm_adam_ema_swap(lm_adam *o, lm_params *p)
{
    if (!o->ema) return;
    for (int i = 0; i < p->n; i++) {
        const lm_param *e = p->items[i];
        if (!e->trainable) continue;
        float *w = e->t.data, *a = o->ema + e->offset;
        for (long k = 0, n = lm_tensor_numel(&e->t); k < n; k++) {
            float t = w[k];
            w[k] = a[k];
            a[k] = t;
        }
    }
}
