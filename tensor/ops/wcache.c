/* wcache.c — transformed and packed weights kept across calls in a context (wcache.h). */
#include "tensor/ops/wcache.h"
#include <stdlib.h>
#include <string.h>

typedef struct wentry {
    const float *w;      /* the weights' address (part of the key) */
    long n;
    unsigned long tag;
    float *copy;         /* w's values when data was derived */
    void *data;
    size_t bytes;
} wentry;

typedef struct lm_wcache lm_wcache;
struct lm_wcache {
    wentry *e;
    int n, cap;
    size_t held;         /* bytes of copies and data */
};

static wentry *find_key(lm_wcache *wc, const float *w, long n, unsigned long tag)
{
    for (int i = 0; wc && i < wc->n; i++)
        if (wc->e[i].w == w && wc->e[i].n == n && wc->e[i].tag == tag) return &wc->e[i];
    return NULL;
}

/* LM_WEIGHT_CACHE=0 in the environment turns the store off (benchmarks compare with it). */
static int enabled(void)
{
    static int on = -1;
    if (on < 0) {
        const char *s = getenv("LM_WEIGHT_CACHE");
        on = !(s && !strcmp(s, "0"));
    }
    return on;
}

const void *lm_wcache_find(lm_ctx *c, const float *w, long n, unsigned long tag, size_t *bytes)
{
    if (!enabled()) return NULL;
    wentry *e = find_key(c->wcache, w, n, tag);
    if (!e || memcmp(e->copy, w, sizeof(float) * (size_t)n)) return NULL;
    if (bytes) *bytes = e->bytes;
    return e->data;
}

static void drop(lm_wcache *wc, wentry *e)
{
    wc->held -= sizeof(float) * (size_t)e->n + e->bytes;
    free(e->copy);
    free(e->data);
    *e = wc->e[--wc->n];
}

void lm_wcache_put(lm_ctx *c, const float *w, long n, unsigned long tag, const void *data,
                   size_t bytes)
{
    if (!enabled()) return;
    if (!c->wcache && !(c->wcache = calloc(1, sizeof *c->wcache))) return;
    lm_wcache *wc = c->wcache;
    wentry *old = find_key(wc, w, n, tag);
    if (old) drop(wc, old);
    size_t need = sizeof(float) * (size_t)n + bytes;
    if (wc->held + need > LM_WCACHE_BYTES) return;
    if (wc->n == wc->cap) {
        int cap = wc->cap ? 2 * wc->cap : 16;
        wentry *e = realloc(wc->e, sizeof *e * (size_t)cap);
        if (!e) return;
        wc->e = e, wc->cap = cap;
    }
    float *copy = malloc(sizeof(float) * (size_t)n);
    void *d = malloc(bytes ? bytes : 1);
    if (!copy || !d) {
        free(copy);
        free(d);
        return;
    }
    memcpy(copy, w, sizeof(float) * (size_t)n);
    memcpy(d, data, bytes);
    wc->e[wc->n++] = (wentry){w, n, tag, copy, d, bytes};
    wc->held += need;
}

void lm_wcache_free(lm_ctx *c)
{
    lm_wcache *wc = c->wcache;
    if (!wc) return;
    for (int i = 0; i < wc->n; i++) {
        free(wc->e[i].copy);
        free(wc->e[i].data);
    }
    free(wc->e);
    free(wc);
    c->wcache = NULL;
}

void lm_wcache_stats(const lm_ctx *c, int *entries, size_t *bytes)
{
    *entries = c->wcache ? c->wcache->n : 0;
    *bytes = c->wcache ? c->wcache->held : 0;
}
