/* arena.c — block list bump allocator with coalescing reset. */
#include "tensor/arena.h"
#include <stdlib.h>
#include <string.h>

static size_t round_up(size_t n, size_t a) { return (n + a - 1) / a * a; }

static int add_block(lm_arena *a, size_t cap)
{
    if (a->nblocks == a->maxblocks) {
        int nm = a->maxblocks ? a->maxblocks * 2 : 8;
        lm_arena_block *nb = realloc(a->blocks, (size_t)nm * sizeof *nb);
        if (!nb) return -1;
        a->blocks = nb;
        a->maxblocks = nm;
    }
    cap = round_up(cap, LM_ARENA_ALIGN);
    void *mem = NULL;
    if (posix_memalign(&mem, LM_ARENA_ALIGN, cap) != 0) return -1;
    a->sys_allocs++;
    a->blocks[a->nblocks].mem = mem;
    a->blocks[a->nblocks].cap = cap;
    a->blocks[a->nblocks].used = 0;
    a->nblocks++;
    return 0;
}

int lm_arena_init(lm_arena *a, size_t initial)
{
    memset(a, 0, sizeof *a);
    a->min_block = 1u << 20;
    if (initial > 0 && add_block(a, initial) != 0) return -1;
    return 0;
}

void lm_arena_free(lm_arena *a)
{
    for (int i = 0; i < a->nblocks; i++) free(a->blocks[i].mem);
    free(a->blocks);
    memset(a, 0, sizeof *a);
}

void *lm_arena_alloc(lm_arena *a, size_t bytes)
{
    size_t need = round_up(bytes ? bytes : 1, LM_ARENA_ALIGN);
    while (a->cur < a->nblocks) {
        lm_arena_block *b = &a->blocks[a->cur];
        if (b->cap - b->used >= need) {
            void *p = b->mem + b->used;
            b->used += need;
            a->in_use += need;
            if (a->in_use > a->high_water) a->high_water = a->in_use;
            if (a->in_use > a->peak) a->peak = a->in_use;
            return p;
        }
        if (a->cur + 1 >= a->nblocks) break;
        a->cur++;
        a->blocks[a->cur].used = 0;
    }
    /* New blocks at least double the capacity: a first step that grows the arena makes few
     * blocks, so few block tails are left behind when an allocation does not fit (tails that
     * scratch, since rewound, had touched stay resident: with one block per tensor they made
     * the first step's peak RSS about the arena capacity, well above its high water). Untouched
     * pages of a large block take no memory. */
    size_t cap = need > a->min_block ? need : a->min_block, total = lm_arena_capacity(a);
    if (cap < total) cap = total;
    if (add_block(a, cap) != 0) return NULL;
    a->cur = a->nblocks - 1;
    return lm_arena_alloc(a, bytes);
}

lm_arena_mark lm_arena_get_mark(const lm_arena *a)
{
    lm_arena_mark m;
    m.block = a->cur;
    m.used = a->nblocks ? a->blocks[a->cur].used : 0;
    m.in_use = a->in_use;
    return m;
}

void lm_arena_rewind(lm_arena *a, lm_arena_mark m)
{
    if (a->nblocks == 0) return;
    a->cur = m.block;
    a->blocks[m.block].used = m.used;
    a->in_use = m.in_use;
}

void lm_arena_reset(lm_arena *a)
{
    if (a->nblocks > 1) {
        size_t total = a->high_water > lm_arena_capacity(a) ? a->high_water : lm_arena_capacity(a);
        for (int i = 0; i < a->nblocks; i++) free(a->blocks[i].mem);
        a->nblocks = 0;
        if (add_block(a, total) != 0) a->nblocks = 0; /* next alloc retries */
    }
    if (a->nblocks) a->blocks[0].used = 0;
    a->cur = 0;
    a->in_use = 0;
    a->high_water = 0;
}

size_t lm_arena_capacity(const lm_arena *a)
{
    size_t c = 0;
    for (int i = 0; i < a->nblocks; i++) c += a->blocks[i].cap;
    return c;
}
