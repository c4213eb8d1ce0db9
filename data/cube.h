/* cube.h — a spectral cube in host memory, the unit that readers produce and the forward model
 * consumes. What it is: bands x height x width float32 (band-major, "CHW"), with the wavelength
 * of each band. What it is not: a tensor (no autograd, no arena): cubes are loaded once, cached
 * by the dataset and outlive training steps. */
#ifndef LM_CUBE_H
#define LM_CUBE_H
#include <stddef.h>
#include "tensor/status.h"

#define LM_CUBE_MAX_BANDS 128

typedef struct lm_cube {
    int bands, height, width;
    float *data;                       /* bands * height * width, data[(b*H + y)*W + x] */
    float wavelength[LM_CUBE_MAX_BANDS]; /* nm, centre of each band */
} lm_cube;

/* Allocate (zeroed) a cube; wavelengths set to start + i*step. Returns LM_OK or LM_ERR_NOMEM /
 * LM_ERR_ARG (non-positive sizes, bands > LM_CUBE_MAX_BANDS). */
lm_status lm_cube_alloc(lm_cube *c, int bands, int height, int width, float wl_start,
                        float wl_step);
void lm_cube_free(lm_cube *c);
static inline float *lm_cube_band(const lm_cube *c, int b)
{
    return c->data + (size_t)b * c->height * c->width;
}
/* Largest value over the cube (0 for an empty cube). */
float lm_cube_max(const lm_cube *c);

#endif
