/* params.c — parameter declaration, the contiguous data/grad blocks, initialisers. */
#include "models/params.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

/* Gradient blocks of at least this many bytes are anonymous mappings (zero-filled by the
 * kernel, committed page by page when first written). */
#define GRAD_MAP_MIN ((size_t)1 << 20)

void lm_params_init(lm_params *p) { memset(p, 0, sizeof *p); }

void lm_params_free(lm_params *p)
{
    for (int i = 0; i < p->n; i++) free(p->items[i]);
    free(p->items);
    free(p->data);
    if (p->grad_mapped) munmap(p->grad, p->grad_mapped);
    else free(p->grad);
    memset(p, 0, sizeof *p);
}

lm_param *lm_params_find(const lm_params *p, const char *name)
{
    for (int i = 0; i < p->n; i++)
        if (!strcmp(p->items[i]->name, name)) return p->items[i];
    return NULL;
}

lm_tensor *lm_params_add(lm_params *p, const char *name_in, int ndim, const int *shape,
                         int trainable, lm_err *err)
{
    char name[2 * LM_PARAM_NAME_MAX];
    snprintf(name, sizeof name, "%s%s", p->prefix, name_in);
    if (p->frozen) trainable = 0;
    if (p->finalized) {
        lm_err_set(err, LM_ERR_ARG, "parameter %s declared after finalize", name);
        return NULL;
    }
    if (strlen(name) >= LM_PARAM_NAME_MAX || lm_params_find(p, name)) {
        lm_err_set(err, LM_ERR_ARG, "parameter name '%s' is too long or declared twice", name);
        return NULL;
    }
    if (ndim < 1 || ndim > LM_MAX_DIMS) {
        lm_err_set(err, LM_ERR_SHAPE, "parameter %s: %d dimensions", name, ndim);
        return NULL;
    }
    for (int i = 0; i < ndim; i++)
        if (shape[i] <= 0) {
            lm_err_set(err, LM_ERR_SHAPE, "parameter %s: dimension %d has size %d", name, i,
                       shape[i]);
            return NULL;
        }
    if (p->n == p->cap) {
        int nc = p->cap ? 2 * p->cap : 64;
        lm_param **ni = realloc(p->items, (size_t)nc * sizeof *ni);
        if (!ni) goto nomem;
        p->items = ni;
        p->cap = nc;
    }
    lm_param *e = calloc(1, sizeof *e);
    if (!e) goto nomem;
    strcpy(e->name, name);
    lm_tensor_wrap(&e->t, NULL, ndim, shape);
    lm_tensor_wrap(&e->g, NULL, ndim, shape);
    e->t.name = e->name;
    e->t.flags = LM_PARAM | (trainable ? LM_REQUIRES_GRAD : 0);
    e->g.flags = LM_PARAM;
    e->trainable = trainable;
    e->offset = p->total;
    /* keep every parameter 16-float aligned inside the block (64-byte SIMD loads) */
    p->total += ((size_t)lm_tensor_numel(&e->t) + 15) / 16 * 16;
    p->items[p->n++] = e;
    return &e->t;
nomem:
    lm_err_set(err, LM_ERR_NOMEM, "out of memory declaring parameter %s", name);
    return NULL;
}

lm_status lm_params_finalize(lm_params *p, lm_err *err)
{
    if (p->finalized) return LM_OK;
    size_t bytes = (p->total ? p->total : 16) * sizeof(float);
    void *d = NULL, *g = NULL;
    size_t mapped = 0;
    if (bytes >= GRAD_MAP_MIN) {
        g = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (g == MAP_FAILED) g = NULL;
        else mapped = bytes;
    } else if (!posix_memalign(&g, 64, bytes)) {
        memset(g, 0, bytes);
    } else {
        g = NULL;
    }
    if (!g || posix_memalign(&d, 64, bytes)) {
        if (mapped) munmap(g, mapped);
        else free(g);
        return lm_err_set(err, LM_ERR_NOMEM, "out of memory for %zu parameters", p->total);
    }
    memset(d, 0, bytes);
    p->grad_mapped = mapped;
    p->data = d;
    p->grad = g;
    for (int i = 0; i < p->n; i++) {
        lm_param *e = p->items[i];
        e->t.data = p->data + e->offset;
        e->g.data = p->grad + e->offset;
        e->t.grad = e->trainable ? &e->g : NULL;
    }
    p->finalized = 1;
    return LM_OK;
}

long lm_params_count(const lm_params *p, int trainable_only)
{
    long n = 0;
    for (int i = 0; i < p->n; i++)
        if (!trainable_only || p->items[i]->trainable) n += lm_tensor_numel(&p->items[i]->t);
    return n;
}

void lm_params_zero_grad(lm_params *p)
{
    if (p->grad) memset(p->grad, 0, p->total * sizeof(float));
}

void lm_params_set_requires_grad(lm_params *p, int on)
{
    for (int i = 0; i < p->n; i++)
        if (p->items[i]->trainable) lm_tensor_set_requires_grad(&p->items[i]->t, on);
}

void lm_init_uniform(lm_tensor *t, lm_rng *r, float bound)
{
    lm_rng_fill_uniform(r, t->data, lm_tensor_numel(t), -bound, bound);
}

void lm_init_normal(lm_tensor *t, lm_rng *r, float std)
{
    lm_rng_fill_normal(r, t->data, lm_tensor_numel(t), 0.0f, std);
}

void lm_init_const(lm_tensor *t, float v) { lm_tensor_fill(t, v); }
