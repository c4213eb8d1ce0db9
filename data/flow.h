/* flow.h — dense optical flow between two single-band images, DIS style (Kroeger et al., ECCV
 * 2016), for temporal alignment of same-LED sub-images (system.md §9, models.md §7.2).
 * What it is: a coarse-to-fine (factor 2) pyramid; at each level a grid of square patches, each
 * refined by inverse-compositional Gauss-Newton search on mean-normalised intensities, densified
 * by averaging overlapping patch displacements weighted by 1 / max(1, |photometric error|), then
 * a few red-black SOR sweeps of a variational energy (Charbonnier brightness constancy +
 * gradient constancy + smoothness, data terms normalised by their spatial derivatives);
 * backward bilinear warping with border clamping (bicubic for the interpolated frames);
 * intermediate flows under linear motion.
 * Images are row-major float h x w; intensities are rescaled internally so that the brighter
 * image's maximum is 255 (the weights are those for 8-bit images).
 * What it is not: occlusion reasoning, multi-channel images, tensors or autograd.
 *
 * Flow layout: 2 planes, flow[0 .. h*w) = dx, flow[h*w .. 2*h*w) = dy, in pixels.
 * Convention: F_{0->1}(p) is where pixel p of I0 is found in I1: I0(p) ~ I1(p + F(p)), so
 * lm_flow_warp(I1, F_{0->1}) ~ I0. Deterministic for a given nthreads (and across thread
 * counts: every output value is computed by the same arithmetic whatever the partition). */
#ifndef LM_FLOW_H
#define LM_FLOW_H
#include "tensor/status.h"

typedef struct lm_flow_opts {
    int patch;        /* patch side in pixels (12) */
    int stride;       /* patch grid stride (4 medium, 6 fast) */
    int gn_iters;     /* Gauss-Newton iterations per patch */
    int finest;       /* finest pyramid level computed (0 = full resolution); finer levels
                       * get the flow upsampled bilinearly */
    int var_iters;    /* variational fixed-point iterations per level (0 = none) */
    int sor_iters;    /* red-black SOR sweeps per fixed-point iteration */
    float alpha;      /* smoothness weight (20) */
    float gamma;      /* gradient-constancy weight (1: second derivatives amplify noise) */
    float delta;      /* brightness-constancy weight (5) */
    int nthreads;     /* OpenMP threads (<= 0: 1) */
} lm_flow_opts;

typedef enum lm_flow_preset {
    LM_FLOW_MEDIUM = 0, /* default: full resolution, 12 x 12 patches at stride 4, 16 GN
                         * iterations, 8 x 5 variational sweeps per level */
    LM_FLOW_FAST = 1    /* half resolution (then upsampled), stride 6, 12 GN iterations,
                         * 3 x 5 variational sweeps */
} lm_flow_preset;

/* Fill o with a preset (nthreads = 1). */
void lm_flow_default_opts(lm_flow_opts *o, lm_flow_preset preset);

/* Smallest image side accepted for patch side p: 2 p. */
int lm_flow_min_size(const lm_flow_opts *o);

/* Dense flow F_{0->1} from i0 to i1 (both h x w), written to flow (2 * h * w floats, see
 * above). o may be NULL (medium preset, 1 thread). Errors (message starting "flow:"):
 * LM_ERR_SHAPE if h or w < lm_flow_min_size, LM_ERR_ARG for NULL buffers or bad options,
 * LM_ERR_NUMERIC for non-finite pixels, LM_ERR_NOMEM. flow is untouched on error. */
lm_status lm_flow_compute(const float *i0, const float *i1, int h, int w,
                          const lm_flow_opts *o, float *flow, lm_err *e);

/* Backward warp: out(p) = src(p + s * F(p)) with bilinear sampling, coordinates clamped to
 * the image (border replication). s scales the flow (1 for a plain warp). out != src. */
void lm_flow_warp(const float *src, int h, int w, const float *flow, float s, float *out,
                  int nthreads);

/* The same with Catmull-Rom (bicubic) interpolation: sharper, used for the final warps of
 * temporal alignment (bilinear resampling at half a pixel halves the highest frequencies of
 * these small sub-images). Taps outside the image repeat the border. */
void lm_flow_warp_cubic(const float *src, int h, int w, const float *flow, float s, float *out,
                        int nthreads);
float lm_flow_sample_cubic(const float *img, int h, int w, float x, float y);

/* Bilinear sample of img (h x w) at (x, y), coordinates clamped to [0, w-1] x [0, h-1]. */
float lm_flow_sample(const float *img, int h, int w, float x, float y);

/* Intermediate flows at t in [0, 1] under linear motion (Super-SloMo approximation):
 *   F_{t->0} = -(1-t) t F_{0->1} + t^2 F_{1->0},  F_{t->1} = (1-t)^2 F_{0->1} - t (1-t) F_{1->0}.
 * Each argument is 2 * n floats (n = h * w); outputs may not alias inputs. */
void lm_flow_intermediate(const float *f01, const float *f10, long n, float t, float *ft0,
                          float *ft1);

/* Frame at time t between i0 (t = 0) and i1 (t = 1): computes F_{0->1}, F_{1->0}, the
 * intermediate flows and out = (1-t) warp(i0, F_{t->0}) + t warp(i1, F_{t->1}), both warps
 * bicubic (lm_flow_warp_cubic).
 * t may lie outside [0, 1] (extrapolation, less accurate). Errors as lm_flow_compute. */
lm_status lm_flow_interpolate(const float *i0, const float *i1, int h, int w, float t,
                              const lm_flow_opts *o, float *out, lm_err *e);

/* The interpolation of lm_flow_interpolate from flows already computed (f01 = F_{0->1},
 * f10 = F_{1->0}, 2 * h * w floats each). Errors: LM_ERR_ARG (NULL buffers), LM_ERR_NOMEM. */
lm_status lm_flow_interpolate_flows(const float *i0, const float *i1, int h, int w, float t,
                                    const float *f01, const float *f10, int nthreads,
                                    float *out, lm_err *e);

#endif
