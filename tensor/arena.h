/* arena.h — bump allocator for per-step memory (activations, tape, scratch).
 * What it is: allocations are carved from large blocks and released all at once by
 * lm_arena_reset() or back to a mark by lm_arena_rewind(). After a reset the blocks used are
 * coalesced into one block of the high-water size, so a step that repeats the same
 * allocations (a training step, an inference batch) makes no system allocation after warm-up.
 * What it is not: a general-purpose heap (no individual free), nor thread-safe. */
#ifndef LM_ARENA_H
#define LM_ARENA_H
#include <stddef.h>

#define LM_ARENA_ALIGN 64 /* cache line, also enough for any SIMD load */

typedef struct lm_arena_block {
    unsigned char *mem;
    size_t cap;
    size_t used;
} lm_arena_block;

typedef struct lm_arena {
    lm_arena_block *blocks;
    int nblocks, maxblocks;
    int cur;              /* block currently allocated from */
    size_t min_block;     /* size of a new block when nothing larger is needed */
    size_t in_use;        /* bytes handed out since the last reset (with padding) */
    size_t high_water;    /* max in_use since the last coalesce */
    size_t peak;          /* max in_use over the arena's life */
    long sys_allocs;      /* number of malloc calls made for blocks (for tests/benchmarks) */
} lm_arena;

typedef struct lm_arena_mark {
    int block;
    size_t used;
    size_t in_use;
} lm_arena_mark;

/* Initialise with a first block of `initial` bytes (0 = allocate lazily). Returns 0 or -1. */
int lm_arena_init(lm_arena *a, size_t initial);
void lm_arena_free(lm_arena *a);
/* Returns memory aligned to LM_ARENA_ALIGN, or NULL on allocation failure. Never zeroed. */
void *lm_arena_alloc(lm_arena *a, size_t bytes);
lm_arena_mark lm_arena_get_mark(const lm_arena *a);
/* Release everything allocated after `m`. */
void lm_arena_rewind(lm_arena *a, lm_arena_mark m);
/* Release everything; coalesce blocks so that the next identical step fits in one block. */
void lm_arena_reset(lm_arena *a);
/* Total capacity of all blocks. */
size_t lm_arena_capacity(const lm_arena *a);

#endif
