/* model_fixture.h — the mosaic the model tests build their networks on: the default system's
 * mosaic with a smooth synthetic response table (a Gaussian per LED), for models that need one
 * (SRNet's response map). Header-only; included by test files that create models. */
#ifndef LM_TEST_MODEL_FIXTURE_H
#define LM_TEST_MODEL_FIXTURE_H
#include "models/model.h"
#include <math.h>

static inline void test_mosaic(lm_mosaic *m)
{
    lm_mosaic_default(m);
    for (int k = 0; k < m->nch; k++)
        for (int j = 0; j < LM_MOSAIC_RESP_CH; j++) {
            float d = (float)(j - 2.5f * k - 3) / 3.0f;
            m->response[k][j] = expf(-0.5f * d * d);
        }
    m->has_response = 1;
}

#endif
