/* dataset_cache.c — the dataset's lazy LRU cube cache (dataset_internal.h): scenes are read on
 * first use, normalised by their maximum, pinned while a sample uses them and evicted least
 * recently used first; never more than cfg.cache_scenes held. What it is not: the scene list or
 * the split (dataset.c), or the worker pool (dataset_workers.c). */
#include "data/dataset_internal.h"
#include "data/cube_io.h"
#include "data/spectra.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

static int cache_find(const lm_dataset *d, int s)
{
    for (int e = 0; e < d->cache_cap; e++)
        if (d->cache[e].scene == s) return e;
    return -1;
}

/* An empty entry, else the least recently used unpinned one (evicted), else -1. */
static int cache_victim(lm_dataset *d)
{
    int best = -1;
    for (int e = 0; e < d->cache_cap; e++) {
        cache_entry *c = &d->cache[e];
        if (c->scene < 0) return e;
        if (c->pins == 0 && (best < 0 || c->last_use < d->cache[best].last_use)) best = e;
    }
    if (best >= 0) {
        lm_cube_free(&d->cache[best].cube);
        d->cache[best].scene = -1;
        d->cached--;
    }
    return best;
}

static lm_status load_checked(const lm_dataset *d, int s, lm_cube *c, lm_err *err)
{
    const scene *sc = &d->scenes[s];
    lm_cube_read_opts o;
    lm_dataset_read_opts(d, &o);
    lm_status st = lm_cube_read_with(sc->path, &o, c, err);
    if (st != LM_OK) return st;
    int grid = c->bands == LM_GRID31_COUNT && fabsf(c->wavelength[0] - 400.0f) < 0.5f &&
               fabsf(c->wavelength[30] - 700.0f) < 0.5f;
    if (!grid || c->height != sc->height || c->width != sc->width) {
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: read %d bands of %d x %d; the dataset expected "
                        "31 bands 400..700 nm of %d x %d (file changed?)", sc->path, c->bands,
                        c->height, c->width, sc->height, sc->width);
        lm_cube_free(c);
        return st;
    }
    /* system.md §10: every scene is divided by its own maximum, for training as for scoring. */
    float mx = lm_cube_max(c);
    if (!(mx > 0.0f) || !isfinite(mx)) {
        st = lm_err_set(err, LM_ERR_NUMERIC, "%s: the cube's maximum is %g; a scene needs a "
                        "positive, finite maximum to be normalised", sc->path, (double)mx);
        lm_cube_free(c);
        return st;
    }
    size_t n = (size_t)c->bands * (size_t)c->height * (size_t)c->width;
    for (size_t i = 0; i < n; i++) c->data[i] /= mx;
    return LM_OK;
}

/* Under the lock: pin entry r->entry for a sample. */
static void pin(lm_dataset *d, scene_ref *r)
{
    d->cache[r->entry].pins++;
    d->cache[r->entry].last_use = ++d->tick;
    r->cube = &d->cache[r->entry].cube;
}

lm_status lm_ds_scene_acquire(lm_dataset *d, int s, scene_ref *r, lm_err *err)
{
    memset(r, 0, sizeof *r);
    pthread_mutex_lock(&d->mu);
    r->entry = cache_find(d, s);
    if (r->entry >= 0) pin(d, r);
    pthread_mutex_unlock(&d->mu);
    if (r->entry >= 0) return LM_OK;
    lm_cube c;
    lm_status st = load_checked(d, s, &c, err); /* outside the lock: workers load in parallel */
    if (st != LM_OK) return st;
    pthread_mutex_lock(&d->mu);
    d->loads++;
    r->entry = cache_find(d, s); /* another thread may have loaded it meanwhile */
    if (r->entry >= 0) {
        lm_cube_free(&c);
    } else if ((r->entry = cache_victim(d)) >= 0) {
        d->cache[r->entry].scene = s;
        d->cache[r->entry].cube = c;
        d->cached++;
        d->max_cached = d->cached > d->max_cached ? d->cached : d->max_cached;
    }
    if (r->entry >= 0) {
        pin(d, r);
    } else {
        r->priv = c; /* every entry pinned: use it once, uncached */
        r->cube = &r->priv;
    }
    pthread_mutex_unlock(&d->mu);
    return LM_OK;
}

void lm_ds_scene_release(lm_dataset *d, scene_ref *r)
{
    pthread_mutex_lock(&d->mu);
    if (r->entry >= 0) d->cache[r->entry].pins--;
    pthread_mutex_unlock(&d->mu);
    if (r->entry < 0) lm_cube_free(&r->priv);
}

void lm_dataset_get_stats(lm_dataset *d, lm_dataset_stats *st)
{
    pthread_mutex_lock(&d->mu);
    *st = (lm_dataset_stats){d->loads, d->cached, d->max_cached};
    pthread_mutex_unlock(&d->mu);
}

lm_status lm_ds_cache_init(lm_dataset *d, lm_err *err)
{
    d->cache_cap = d->cfg.cache_scenes > 0 && d->cfg.cache_scenes < d->nscenes
                   ? d->cfg.cache_scenes : d->nscenes;
    d->cache = calloc((size_t)(d->cache_cap + 1), sizeof *d->cache);
    if (!d->cache) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    for (int e = 0; e < d->cache_cap; e++) d->cache[e].scene = -1;
    return LM_OK;
}

void lm_ds_cache_free(lm_dataset *d)
{
    for (int e = 0; e < d->cache_cap && d->cache; e++) lm_cube_free(&d->cache[e].cube);
    free(d->cache);
}
