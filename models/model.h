/* model.h — the common face of every reconstruction network: created by preset name, takes
 * the raw coded patch (B x 1 x H x W) and returns B x 33 x H x W (33-channel target of
 * system.md §3). The demosaic is part of the model (shared code, lm_mosaic_demosaic).
 * What it is not: training or inference loops. */
#ifndef LM_MODEL_H
#define LM_MODEL_H
#include "models/layers.h"

#define LM_MODEL_OUT_CHANNELS 33

typedef struct lm_model lm_model;
struct lm_model {
    char preset[64];
    char family[16];               /* "han", "mcan", "srnet", "linear", ... */
    lm_params params;
    lm_mosaic mosaic;
    int out_channels;
    int in_channels;               /* channels of the input tensor: 1 = raw coded mosaic
                                    * (default); 3 = RGB image (MST++ baseline) */
    lm_tensor *(*forward)(lm_ctx *c, lm_model *m, lm_tensor *raw);
    void (*init)(lm_model *m, lm_rng *r);   /* default initialisation, declaration order */
    void (*free_impl)(lm_model *m);
    void *impl;
};

/* Create by preset name (see lm_model_presets); mosaic NULL = lm_mosaic_default. Parameters
 * are declared, allocated and initialised from `seed`. */
lm_model *lm_model_create(const char *preset, const lm_mosaic *mosaic, uint64_t seed,
                          lm_err *err);
void lm_model_free(lm_model *m);
lm_tensor *lm_model_forward(lm_ctx *c, lm_model *m, lm_tensor *raw);
/* NULL-terminated list of preset names. */
const char *const *lm_model_presets(void);

/* ---- families (one file each) ---------------------------------------------------------- */
typedef struct lm_han_cfg { int groups, blocks, feats, reduction; } lm_han_cfg;
lm_status lm_han_build(lm_model *m, lm_han_cfg cfg, lm_err *err);
/* MCAN, 3x4 adaptation (models.md §3.2); feats = 64 in the paper-size model. */
lm_status lm_mcan_build(lm_model *m, int feats, lm_err *err);
/* SRNet 12 -> 33 with the response-map input (models.md §4); dim = 32 in the paper. */
lm_status lm_srnet_build(lm_model *m, int dim, lm_err *err);
/* Linear baseline: demosaic + 1x1 conv 12 -> 33. */
lm_status lm_linear_build(lm_model *m, lm_err *err);
/* MST++ (models.md §5), `stages` MSTs; raw_input 0: B x 3 x H x W RGB input (in_channels 3),
 * 1: the raw coded frame demosaiced to the mosaic's channels. Output B x 31 x H x W. */
lm_status lm_mst_build(lm_model *m, int stages, int raw_input, lm_err *err);
/* One whole frame without gradients (MST++'s attention is global: no windows), block by
 * block in scopes so memory stays a few full-resolution feature maps: in = in_channels x H x W
 * (planar, host), out = out_channels x H x W. Own ctx with nthreads (0 = all cores). */
lm_status lm_mst_reconstruct(lm_model *m, const float *in, int H, int W, float *out,
                             int nthreads, lm_err *err);
/* Real-time: demosaic + raw, two 3x3 convs at `width`, 1x1 head (models/rt.c). */
lm_status lm_rt_build(lm_model *m, int width, lm_err *err);

#endif
