/* cube.c — allocation and small helpers of lm_cube. */
#include "data/cube.h"
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* Cubes of at least this many bytes are left out of forked children (see dontfork). */
#define DONTFORK_MIN_BYTES (1L << 20)

/* The whole pages inside [p, p + n) get MADV_DONTFORK (on) or MADV_DOFORK (off): a child
 * process (the .mat reader's, data/isolate.c) never reads the caller's cubes, and fork's cost
 * grows with the pages it must share (about 40 ms per GB here), so a dataset cache of cubes
 * would make every .mat read slower. Only pages wholly inside the block are marked (malloc's
 * own bookkeeping lives outside it), and they are unmarked before the block is freed. */
static void dontfork(void *p, size_t n, int on)
{
    if (!p || n < DONTFORK_MIN_BYTES) return;
    uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE), a = ((uintptr_t)p + page - 1) / page * page;
    uintptr_t b = ((uintptr_t)p + n) / page * page;
    if (b > a) madvise((void *)a, b - a, on ? MADV_DONTFORK : MADV_DOFORK);
}

lm_status lm_cube_alloc(lm_cube *c, int bands, int height, int width, float wl_start,
                        float wl_step)
{
    memset(c, 0, sizeof *c);
    if (bands <= 0 || bands > LM_CUBE_MAX_BANDS || height <= 0 || width <= 0) return LM_ERR_ARG;
    c->data = calloc((size_t)bands * height * width, sizeof(float));
    if (!c->data) return LM_ERR_NOMEM;
    dontfork(c->data, (size_t)bands * height * width * sizeof(float), 1);
    c->bands = bands;
    c->height = height;
    c->width = width;
    for (int i = 0; i < bands; i++) c->wavelength[i] = wl_start + wl_step * (float)i;
    return LM_OK;
}

void lm_cube_free(lm_cube *c)
{
    dontfork(c->data, (size_t)c->bands * c->height * c->width * sizeof(float), 0);
    free(c->data);
    memset(c, 0, sizeof *c);
}

float lm_cube_max(const lm_cube *c)
{
    size_t n = (size_t)c->bands * c->height * c->width;
    float m = 0.0f;
    for (size_t i = 0; i < n; i++)
        if (c->data[i] > m) m = c->data[i];
    return m;
}
