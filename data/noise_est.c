/* noise_est.c — provisional estimator: per phase, median |4c - n - s - e - w| / 0.6745 /
 * sqrt(20) on the phase plane; the smallest over phases. */
#include "data/noise_est.h"
#include <math.h>
#include <stdlib.h>

static int cmpf(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

float lm_noise_estimate(const float *raw, int H, int W, int th, int tw)
{
    if (!raw || th < 1 || tw < 1 || H % th || W % tw || H / th < 3 || W / tw < 3) return -1.0f;
    const int h = H / th, w = W / tw;
    float *r = malloc(sizeof(float) * (size_t)(h - 2) * (w - 2));
    if (!r) return -1.0f;
    float best = INFINITY;
    for (int i = 0; i < th; i++)
        for (int j = 0; j < tw; j++) {
            size_t n = 0;
            for (int y = 1; y < h - 1; y++)
                for (int x = 1; x < w - 1; x++) {
#define P(yy, xx) raw[(size_t)((yy) * th + i) * W + (xx) * tw + j]
                    float v = 4 * P(y, x) - P(y - 1, x) - P(y + 1, x) - P(y, x - 1) - P(y, x + 1);
#undef P
                    r[n++] = fabsf(v);
                }
            qsort(r, n, sizeof *r, cmpf);
            float s = r[n / 2] / 0.6745f / sqrtf(20.0f);
            if (s < best) best = s;
        }
    free(r);
    return best;
}
