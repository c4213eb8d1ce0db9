/* cube.c — allocation and small helpers of lm_cube. */
#include "data/cube.h"
#include <stdlib.h>
#include <string.h>

lm_status lm_cube_alloc(lm_cube *c, int bands, int height, int width, float wl_start,
                        float wl_step)
{
    memset(c, 0, sizeof *c);
    if (bands <= 0 || bands > LM_CUBE_MAX_BANDS || height <= 0 || width <= 0) return LM_ERR_ARG;
    c->data = calloc((size_t)bands * height * width, sizeof(float));
    if (!c->data) return LM_ERR_NOMEM;
    c->bands = bands;
    c->height = height;
    c->width = width;
    for (int i = 0; i < bands; i++) c->wavelength[i] = wl_start + wl_step * (float)i;
    return LM_OK;
}

void lm_cube_free(lm_cube *c)
{
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
