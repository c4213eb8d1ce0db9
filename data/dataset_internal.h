/* dataset_internal.h — private to data/dataset.c, dataset_cache.c and dataset_workers.c: the
 * dataset's state (scenes, split lists, the cube cache, the worker pool) and the calls between
 * those three files. What it is not: an API (data/dataset.h is one); nothing else includes it. */
#ifndef LM_DATA_DATASET_INTERNAL_H
#define LM_DATA_DATASET_INTERNAL_H
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/synth.h"
#include <pthread.h>

#define DS_PATH_MAX 4096
#define DS_MAX_WORKERS LM_DATASET_MAX_WORKERS

typedef struct scene {
    char *path;          /* what lm_cube_read opens */
    char *name;          /* file name without extension, or the CAVE band folder's name */
    char *group;         /* group key (lm_dataset_group_key): hashed for the split */
    uint64_t hash;       /* split_hash(group) */
    int height, width;
    lm_data_split split; /* by the rule; the lists may also borrow (build_splits) */
} scene;

typedef struct cache_entry {
    int scene;           /* -1: empty */
    int pins;            /* samples using it now (not evictable) */
    unsigned long last_use;
    lm_cube cube;
} cache_entry;

typedef struct batch_slot {
    long index;
    int batch;           /* 0: free */
    int next, done, inflight, cancel;
    int cap;             /* items the buffers hold */
    float *raw, *target;
    lm_status status;
    int err_item;
    lm_err err;
} batch_slot;

struct lm_dataset {
    lm_dataset_cfg cfg;
    char mat_key[LM_DATASET_KEY_LEN]; /* cfg.mat_key, copied ("" = automatic) */
    scene *scenes;
    int nscenes;
    int *list[3], count[3], borrowed[3];
    int ngroups;         /* scene groups (assign_splits) */
    int too_small;       /* scenes smaller than the patch (in no list) */
    lm_synth_palette pal;
    lm_rng rng[3];
    pthread_mutex_t mu;  /* cache and worker pool */
    pthread_cond_t work_cv, done_cv;
    cache_entry *cache;
    int cache_cap, cached, max_cached;
    unsigned long tick;
    long loads;
    pthread_t threads[DS_MAX_WORKERS];
    int nthreads, stop;
    batch_slot slot[2];
    batch_slot *wanted;
};

/* How scenes are read (dataset.c): onto 31 bands 400-700 nm (no other grid kept), with the
 * dataset's .mat key. */
void lm_dataset_read_opts(const lm_dataset *d, lm_cube_read_opts *o);

/* ---- the cube cache (dataset_cache.c): lazy, LRU, pinned while a sample uses a scene ---- */
/* A scene in use by one sample. */
typedef struct scene_ref {
    int entry;          /* cache entry pinned, or -1: priv holds a private copy */
    lm_cube priv;
    const lm_cube *cube;
} scene_ref;
/* The empty cache (cfg.cache_scenes entries, 0 = every scene); LM_ERR_NOMEM. */
lm_status lm_ds_cache_init(lm_dataset *d, lm_err *err);
void lm_ds_cache_free(lm_dataset *d);
/* Scene s (an index in d->scenes), normalised by its maximum, pinned in the cache (or, when
 * every entry is pinned, a private copy) until lm_ds_scene_release. Thread-safe. */
lm_status lm_ds_scene_acquire(lm_dataset *d, int s, scene_ref *r, lm_err *err);
void lm_ds_scene_release(lm_dataset *d, scene_ref *r);

/* ---- samples (dataset.c) ---------------------------------------------------------------- */
/* Sample i of a split: raw (patch_h x patch_w) and target (33 x patch_h x patch_w). */
lm_status lm_ds_make_sample(lm_dataset *d, lm_data_split split, long i, float *raw,
                            float *target, lm_err *err);

/* ---- the worker pool (dataset_workers.c): the next training batch prepared ahead ------- */
/* Start cfg.workers threads (d->nthreads counts those started); LM_ERR_NOMEM. */
lm_status lm_ds_workers_start(lm_dataset *d, lm_err *err);
/* Stop and join the threads; free the batch buffers. */
void lm_ds_workers_stop(lm_dataset *d);

#endif
