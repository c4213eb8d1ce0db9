/* wcache.h — transformed and packed weights kept across calls in a context (wcache.c).
 * Private to the ops.
 *
 * What it is: a small store, owned by an lm_ctx and kept across lm_ctx_reset, of data derived
 * from a weight tensor (e.g. the Winograd-transformed, panel-packed weights of a 3x3
 * convolution, or their bf16 pairs). An entry holds a copy of the weights it was derived
 * from and is returned only while the weights are bit for bit the same: after an optimizer
 * update (or any change of the values) it misses, so the derived data is rebuilt once per
 * weight update rather than once per call, and a stale entry can never be used. Entries are
 * added until LM_WCACHE_BYTES are held; past that the data is derived per call as without a
 * cache (no eviction: a cycle of more layers than fit keeps a fixed subset cached).
 * LM_WEIGHT_CACHE=0 in the environment turns it off (benchmarks compare with it).
 * What it is not: thread-safe (a context is used by one thread at a time). */
#ifndef LM_OPS_WCACHE_H
#define LM_OPS_WCACHE_H
#include "tensor/tensor.h"
#include <stddef.h>

#define LM_WCACHE_BYTES ((size_t)128 << 20) /* weights + derived data held per context */

/* The data stored for (w[0..n), tag), or NULL when there is none or w's values changed since.
 * *bytes (may be NULL) receives its size. */
const void *lm_wcache_find(lm_ctx *c, const float *w, long n, unsigned long tag, size_t *bytes);
/* Store a copy of data (bytes) for (w[0..n), tag), replacing an older entry of the same key;
 * does nothing when the store is full or memory is short (the caller keeps its own data). */
void lm_wcache_put(lm_ctx *c, const float *w, long n, unsigned long tag, const void *data,
                   size_t bytes);
/* Release everything (lm_ctx_free). */
void lm_wcache_free(lm_ctx *c);
/* Entries and bytes held (tests). */
void lm_wcache_stats(const lm_ctx *c, int *entries, size_t *bytes);

#endif
