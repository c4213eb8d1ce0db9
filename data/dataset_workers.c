/* dataset_workers.c — the dataset's worker pool (dataset_internal.h): threads that prepare the
 * next training batch while the current one trains; a batch nobody asked for is cancelled.
 * Samples are pure functions of (seed, split, index), so the pool never changes the numbers.
 * What it is not: the sample itself (dataset.c) or the cube cache (dataset_cache.c). */
#include "data/dataset_internal.h"
#include "data/spectra.h"
#include <stdlib.h>
#include <string.h>

static size_t px_items(const lm_dataset *d) { return (size_t)d->cfg.patch_h * d->cfg.patch_w; }
/* one sample's raw floats: a plane per bucket */
static size_t raw_items(const lm_dataset *d)
{
    return px_items(d) * (size_t)(d->cfg.buckets == 2 ? 2 : 1);
}

static batch_slot *find_job(lm_dataset *d)
{
    if (d->wanted && !d->wanted->cancel && d->wanted->next < d->wanted->batch) return d->wanted;
    for (int k = 0; k < 2; k++) {
        batch_slot *s = &d->slot[k];
        if (s->batch > 0 && !s->cancel && s->next < s->batch) return s;
    }
    return NULL;
}

static void *worker_main(void *arg)
{
    lm_dataset *d = arg;
    size_t n = raw_items(d);
    pthread_mutex_lock(&d->mu);
    for (;;) {
        batch_slot *s = NULL;
        while (!d->stop && !(s = find_job(d))) pthread_cond_wait(&d->work_cv, &d->mu);
        if (d->stop) break;
        int j = s->next++;
        long i = s->index * s->batch + j;
        s->inflight++;
        pthread_mutex_unlock(&d->mu);
        lm_err e = {LM_OK, ""};
        lm_status st = lm_ds_make_sample(d, LM_SPLIT_TRAIN, i, s->raw + (size_t)j * n,
                                   s->target + (size_t)j * LM_TARGET_CHANNELS * px_items(d), &e);
        pthread_mutex_lock(&d->mu);
        s->inflight--;
        s->done++;
        if (st != LM_OK && (s->status == LM_OK || j < s->err_item)) {
            s->status = st;
            s->err_item = j;
            s->err = e;
        }
        pthread_cond_broadcast(&d->done_cv);
    }
    pthread_mutex_unlock(&d->mu);
    return NULL;
}

/* Under the lock: a free slot set up for (index, B). */
static batch_slot *slot_start(lm_dataset *d, long index, int B, lm_err *err)
{
    /* batch_pooled frees every other slot first, so one is always free */
    batch_slot *s = d->slot[0].batch == 0 ? &d->slot[0] : &d->slot[1];
    if (s->cap < B) {
        size_t n = raw_items(d) * (size_t)B, np = px_items(d) * (size_t)B;
        float *raw = realloc(s->raw, n * sizeof(float));
        if (raw) s->raw = raw;
        float *tg = raw ? realloc(s->target, np * LM_TARGET_CHANNELS * sizeof(float)) : NULL;
        if (tg) s->target = tg;
        if (!raw || !tg) {
            lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory for a batch of %d", B);
            return NULL;
        }
        s->cap = B;
    }
    s->index = index;
    s->batch = B;
    s->next = s->done = s->inflight = s->cancel = 0;
    s->status = LM_OK;
    s->err_item = B;
    lm_err_clear(&s->err);
    pthread_cond_broadcast(&d->work_cv);
    return s;
}

static lm_status batch_pooled(lm_dataset *d, long index, int B, float *raw, float *target,
                              lm_err *err)
{
    pthread_mutex_lock(&d->mu);
    batch_slot *s = NULL, *stale = NULL;
    for (int k = 0; k < 2; k++) {
        batch_slot *c = &d->slot[k];
        if (c->batch == 0) continue;
        if (c->index == index && c->batch == B && !c->cancel) s = c;
        else stale = c;
    }
    if (stale) { /* a prefetch nobody asked for: stop it */
        stale->cancel = 1;
        while (stale->inflight > 0) pthread_cond_wait(&d->done_cv, &d->mu);
        stale->batch = 0;
    }
    if (!s) s = slot_start(d, index, B, err);
    lm_status st = s ? LM_OK : LM_ERR_NOMEM;
    if (s) {
        d->wanted = s;
        while (s->done < B) pthread_cond_wait(&d->done_cv, &d->mu);
        d->wanted = NULL;
        st = s->status;
        if (st != LM_OK) lm_err_set(err, st, "%s", s->err.msg);
        s->cancel = 1; /* completed: no worker touches it; keep it out of find_job */
    }
    pthread_mutex_unlock(&d->mu);
    if (st == LM_OK) {
        size_t n = raw_items(d) * (size_t)B, np = px_items(d) * (size_t)B;
        memcpy(raw, s->raw, n * sizeof(float));
        memcpy(target, s->target, np * LM_TARGET_CHANNELS * sizeof(float));
    }
    pthread_mutex_lock(&d->mu);
    if (s) s->batch = 0;
    lm_err ignore = {LM_OK, ""};
    if (st == LM_OK) /* prefetch the batch asked for next */
        slot_start(d, index + (d->cfg.batch_stride > 1 ? d->cfg.batch_stride : 1), B, &ignore);
    pthread_mutex_unlock(&d->mu);
    return st;
}

lm_status lm_dataset_batch(lm_dataset *d, long index, int batch, float *raw, float *target,
                           lm_err *err)
{
    if (index < 0 || batch < 1 || !raw || !target)
        return lm_err_set(err, LM_ERR_ARG, "dataset batch: need index >= 0, batch >= 1 and "
                          "buffers (got %ld, %d)", index, batch);
    if (d->nthreads > 0) return batch_pooled(d, index, batch, raw, target, err);
    size_t n = raw_items(d);
    for (int j = 0; j < batch; j++) {
        lm_status st = lm_ds_make_sample(d, LM_SPLIT_TRAIN, index * batch + j, raw + (size_t)j * n,
                                   target + (size_t)j * LM_TARGET_CHANNELS * px_items(d), err);
        if (st != LM_OK) return st;
    }
    return LM_OK;
}

lm_status lm_ds_workers_start(lm_dataset *d, lm_err *err)
{
    for (int t = 0; t < d->cfg.workers; t++) {
        if (pthread_create(&d->threads[t], NULL, worker_main, d) != 0)
            return lm_err_set(err, LM_ERR_NOMEM, "dataset: cannot start worker thread %d", t);
        d->nthreads++;
    }
    return LM_OK;
}

void lm_ds_workers_stop(lm_dataset *d)
{
    pthread_mutex_lock(&d->mu);
    d->stop = 1;
    pthread_cond_broadcast(&d->work_cv);
    pthread_mutex_unlock(&d->mu);
    for (int t = 0; t < d->nthreads; t++) pthread_join(d->threads[t], NULL);
    for (int k = 0; k < 2; k++) free(d->slot[k].raw), free(d->slot[k].target);
}
