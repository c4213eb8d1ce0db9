/* model.h — the common face of every reconstruction network: created by preset name, takes
 * the raw coded patch (B x 1 x H x W) and returns B x 33 x H x W (33-channel target of
 * system.md §3). The demosaic is part of the model (shared code, lm_mosaic_demosaic).
 * What it is not: training or inference loops. */
#ifndef LM_MODEL_H
#define LM_MODEL_H
#include "models/layers.h"

#define LM_MODEL_OUT_CHANNELS 33

/* Capability flags of a preset: one row of the preset table (models/model.c) sets them on
 * lm_model.caps; callers ask lm_model_has, never the family name or the channel count. */
typedef enum lm_model_cap {
    LM_CAP_RGB_INPUT = 1u << 0,   /* input: the 3-channel RGB camera image (the passive MST++
                                   * baseline), not the coded frame */
    LM_CAP_WHOLE_FRAME = 1u << 1, /* global context: runs on the whole frame at once
                                   * (lm_mst_reconstruct), never in windows or strips */
    LM_CAP_OPENCL = 1u << 2,      /* may run on an OpenCL device (--device opencl) */
    LM_CAP_CLOSED_FORM = 1u << 3, /* fitted in closed form (train/fit_lmmse.h) */
    LM_CAP_QDO_OPTICS = 1u << 4,  /* with LM_CAP_RGB_INPUT: the RGB image is seen through the
                                   * QDO baseline's DOE (data/qdocam.h), not a plain lens */
    LM_CAP_TWO_BUCKETS = 1u << 5, /* input: both buckets of the coded frame, B x 2 x H x W
                                   * (bucket 1, then bucket 0 / (LEDs - 1) as `simulate
                                   * --bucket0` stores it); in_channels 2. Presets "<name>-b2" */
    LM_CAP_DOE_LEARNED = 1u << 6, /* with LM_CAP_QDO_OPTICS: training also learns the DOE's
                                   * height map (as the run config's doe_optimise; the run's
                                   * doe.json then holds the learned DOE) */
    LM_CAP_MULTI_FRAME = 1u << 7, /* input: LM_MODEL_MF_FRAMES coded frames (bucket 1) of a
                                   * video, B x 3 x H x W: frame i aligned to its reference
                                   * instant, then frames i-1 and i+1 moved onto frame i's pixel
                                   * grid and instant, LED by LED (lm_align_stack, data/align.h);
                                   * in_channels 3. Presets "<name>-mf3" */
} lm_model_cap;

/* Frames of a multi-frame model's input (the current one and its two neighbours). */
#define LM_MODEL_MF_FRAMES 3

typedef struct lm_model lm_model;
struct lm_model {
    char preset[64];
    char family[16];               /* "han", "mcan", "srnet", "linear", ... */
    lm_params params;
    lm_mosaic mosaic;
    int out_channels;
    int in_channels;               /* channels of the input tensor: 1 = raw coded mosaic
                                    * (default); 2 = both buckets (LM_CAP_TWO_BUCKETS);
                                    * 3 = RGB image (MST++ baseline) or three frames
                                    * (LM_CAP_MULTI_FRAME) */
    lm_tensor *(*forward)(lm_ctx *c, lm_model *m, lm_tensor *raw);
    /* Optional whole-frame host path (no tensors, no gradients, no device): channels
     * [ch0, ch0 + nch) of the output for one H x W raw frame written straight into out (nch
     * planes of H x W), the noise level as forward reads it. infer/whole.c uses it on a host
     * context; NULL = none (the strips of forward). */
    lm_status (*frame_forward)(lm_ctx *c, lm_model *m, const float *frame, int H, int W,
                               int ch0, int nch, float *out, lm_err *err);
    void (*init)(lm_model *m, lm_rng *r);   /* default initialisation, declaration order */
    void (*free_impl)(lm_model *m);
    void *impl;
    /* Capabilities: caps from the preset row; the rest set by the builder. Callers ask these,
     * not the family name. */
    unsigned caps;                 /* lm_model_cap flags (lm_model_has) */
    int conv_rows;                 /* rows of context each output row needs beyond the
                                    * demosaic's (finite receptive field: whole frames run in
                                    * strips, infer/whole.h); -1 = global context (default) */
    int noise_input;               /* 1: forward reads the input's noise level (below) */
    /* The input's Gaussian noise sd in input units (as data/noise_est.h estimates it), for
     * models with noise_input: noise_sigma_items[b] per batch item when non-NULL, else
     * noise_sigma for every item (< 0 = unknown: such a model's forward fails). Set by the
     * caller before each forward (train loop, infer, eval). */
    float noise_sigma;
    const float *noise_sigma_items;
    float noise_given;             /* inference: the level k given by the user (sigma = k x the
                                    * frame's maximum), < 0 = estimate it from each frame */
    /* Residual on a base model (lm_model_create_residual): forward = this net + base. The
     * base's parameters live in this model's block as "base.<name>" (frozen unless made
     * trainable), so checkpoints and devices carry both. */
    lm_model *base;
    lm_tensor *res_scale;          /* residual only: 33 gates on the net's output */
    /* The layers whose outputs add up to the network's output (set by the builder): zeroed
     * in a residual, so it starts exactly at its base while every layer gets gradients. */
    const lm_conv *out_layers[2];
    int n_out_layers;
};

/* Create by preset name (see lm_model_presets); mosaic NULL = lm_mosaic_default. Parameters
 * are declared, allocated and initialised from `seed`. */
lm_model *lm_model_create(const char *preset, const lm_mosaic *mosaic, uint64_t seed,
                          lm_err *err);
void lm_model_free(lm_model *m);
lm_tensor *lm_model_forward(lm_ctx *c, lm_model *m, lm_tensor *raw);
/* The residual model `preset` + `base_preset` (both preset names): the net's parameters as
 * lm_model_create gives them, then the base's under "base." (trainable when train_base), then
 * "res_scale" (33 per-channel gates on the net's output, initialised to res_init). The net's
 * output layers (out_layers) start at zero, so the model equals its base at iteration 0 while
 * the output layers' gradients (a regression of the base's error on the net's features) are
 * non-zero from the first step. Noise level and capabilities pass through. */
lm_model *lm_model_create_residual(const char *preset, const char *base_preset,
                                   const lm_mosaic *mosaic, uint64_t seed, int train_base,
                                   float res_init, lm_err *err);
/* Does m have every flag of caps (lm_model_cap)? */
static inline int lm_model_has(const lm_model *m, unsigned caps) { return (m->caps & caps) == caps; }
/* Buckets of the coded frame the model reads: 2 with LM_CAP_TWO_BUCKETS, else 1 (0 for an
 * RGB-input model). */
static inline int lm_model_buckets(const lm_model *m)
{
    return m->caps & LM_CAP_RGB_INPUT ? 0 : m->caps & LM_CAP_TWO_BUCKETS ? 2 : 1;
}
/* Coded frames the model reads per output frame: LM_MODEL_MF_FRAMES with LM_CAP_MULTI_FRAME,
 * else 1. */
static inline int lm_model_frames(const lm_model *m)
{
    return m->caps & LM_CAP_MULTI_FRAME ? LM_MODEL_MF_FRAMES : 1;
}
/* Planes of a coded model's input: buckets x frames (0 for an RGB-input model). */
static inline int lm_model_coded_planes(const lm_model *m)
{
    return lm_model_buckets(m) * lm_model_frames(m);
}
/* Is name a preset (a listed name, lmmse-K, or either with "-b2")? */
int lm_model_preset_known(const char *name);
/* Why an "lmmse-K-..." name is refused (a window out of range or even), else NULL. */
const char *lm_model_preset_why(const char *name);
/* NULL-terminated list of preset names. */
const char *const *lm_model_presets(void);
/* One line on what a preset is for ("" for a name that is not a preset). */
const char *lm_model_preset_purpose(const char *name);
/* The model's name as results tables, the README and `info --model` write it: its preset, or
 * for a residual "NET+BASE" (e.g. "rt-16-nc+lmmse"). Into out (n bytes, truncated); returns
 * out. */
const char *lm_model_name(const lm_model *m, char *out, size_t n);
/* Split "NET+BASE" into its two presets (each at most n bytes); 1 when name has that form with
 * two known presets, else 0. */
int lm_model_name_split(const char *name, char *net, char *base, size_t n);

/* ---- families (one file each) ---------------------------------------------------------- */
/* noise_cond 1 ("han-tiny-nc"): the head conv's output also gets a per-channel bias
 * proportional to the input's noise sd ("head.0.noise"), as the rt-N-nc branch does. */
typedef struct lm_han_cfg { int groups, blocks, feats, reduction, noise_cond; } lm_han_cfg;
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
/* Closed-form linear floor (models/lmmse.c): per tile phase a K x K raw window (of each input
 * plane: both buckets with LM_CAP_TWO_BUCKETS) -> 33
 * channels, one filter set per noise level of lm_lmmse_sigmas (absolute noise sd of the input),
 * interpolated between levels. Presets "lmmse" (K = 11), "lmmse-K" (odd K), "lmmse-rf" (K = 11
 * plus 256 random ReLU features). */
#define LM_LMMSE_LEVELS 12
extern const float lm_lmmse_sigmas[LM_LMMSE_LEVELS];
lm_status lm_lmmse_build(lm_model *m, int K, int D, lm_err *err);
/* lmmse-b2 plus the panchromatic guide's features (models/lmmse.c; preset "lmmse-guide-b2"):
 * both buckets, K x K windows, and the ratio of bucket 1 to the panchromatic image over a
 * G x G window (odd, at most K), multiplied back by the pixel's panchromatic value: D = G^2 + 1
 * features read out per phase and level, fitted in closed form as lmmse-rf's. */
lm_status lm_lmmse_guide_build(lm_model *m, int K, int G, lm_err *err);
/* G of an lmmse model with the guide, 0 for any other model. */
int lm_lmmse_guide(const lm_model *m);
/* lmmse-b2 plus each LED's plane interpolated by a guided filter (models/lmmse.c; preset
 * "lmmse-gri-b2": K 11, RI 15): both buckets, K x K windows, and for each of the P LEDs the local linear
 * regression of its samples on the panchromatic image over RI x RI windows (odd,
 * LM_LMMSE_GRI_MIN..LM_LMMSE_GRI_MAX), averaged over the windows covering the pixel and
 * evaluated at its panchromatic value; those P planes and the panchromatic image: D = P + 1
 * features read out per phase and level, fitted in closed form as lmmse-rf's. */
#define LM_LMMSE_GRI_MIN 3
#define LM_LMMSE_GRI_MAX 31
lm_status lm_lmmse_gri_build(lm_model *m, int K, int RI, lm_err *err);
/* RI of an lmmse model with the guided interpolation, 0 for any other model. */
int lm_lmmse_gri(const lm_model *m);
/* K of an lmmse model, 0 for any other model. */
int lm_lmmse_window(const lm_model *m);
/* The noise sd of each level of an lmmse model (lm_lmmse_sigmas for any other model). */
const float *lm_lmmse_levels(const lm_model *m);
/* For measurements only (bench_lmmse_levels: a filter fitted for exactly the noise a frame
 * has): replace the levels' sd by sig (sig[0] = 0, strictly increasing, finite) before a fit.
 * Checkpoints hold the default levels only: saving a model with other levels fails. */
lm_status lm_lmmse_set_levels(lm_model *m, const float *sig, lm_err *err);
/* 1 when lm_lmmse_set_levels gave m levels other than lm_lmmse_sigmas. */
int lm_lmmse_custom_levels(const lm_model *m);
/* D > 0 ("lmmse-rf"): also D random ReLU features of the window (a K x K conv 1 -> D, ReLU),
 * read out per phase and level (readout.weight L x P x 33 x D): a nonlinear model whose readout
 * is still fitted in closed form (random-features ridge regression). 0 for plain lmmse. */
int lm_lmmse_features(const lm_model *m);
/* The feature maps relu(features(raw)) (B x D x H x W, zero-padded borders), or the guide's
 * (host only), for the fit. */
lm_tensor *lm_lmmse_feature_maps(lm_ctx *c, const lm_model *m, lm_tensor *raw);
/* Set the filter of (level, phase) from coef[(C*K*K + D + 1) x 33] (rows: window position
 * u * K + v of plane 0 (bucket 1), then of plane 1 (bucket 0) when C = 2, then the D
 * features, last the bias), as the fit produces it. */
lm_status lm_lmmse_set_filter(lm_model *m, int level, int phase, const double *coef, lm_err *err);
/* Real-time: demosaic + raw, two 3x3 convs at `width`, 1x1 head (models/rt.c); with
 * LM_CAP_TWO_BUCKETS the branch's first conv also reads the bucket-0 plane, with
 * LM_CAP_MULTI_FRAME the two neighbour frames' planes (the demosaic is of plane 0). */
/* noise_cond: "-nc" presets, a bias from the input's noise sd in the branch (noise_input). */
lm_status lm_rt_build(lm_model *m, int width, int noise_cond, lm_err *err);
/* Tile resolution (models/tile.c): unshuffle to the tile's phase planes, 3x3 conv to `width`
 * channels, `blocks` residual blocks (1..LM_TILE_MAX_BLOCKS), 1x1 to 33 x phases, shuffle
 * back; noise_cond as rt's. */
#define LM_TILE_MAX_BLOCKS 8
lm_status lm_tile_build(lm_model *m, int width, int blocks, int noise_cond, lm_err *err);
/* The "-nc" presets' bias: B x w x 1 x 1 = LM_NOISE_BIAS_SCALE x each item's noise sd
 * (m->noise_sigma_items, else m->noise_sigma) x weights (w values). NULL with the ctx error set
 * when the model was given no noise level. */
#define LM_NOISE_BIAS_SCALE 10.0f /* sd 0.1 (10 % of a bright frame) -> 1 */
lm_tensor *lm_model_noise_bias(lm_ctx *c, const lm_model *m, lm_tensor *weights, int B);

#endif
