/* align.h — temporal alignment of a coded video frame's LED sub-images (system.md §9).
 * What it is: every LED sub-image of frame i has a timestamp (its window's midpoint over the
 * frame period: frames start frame_period_us apart, 33.3 ms at 30 fps, not exposure + readout =
 * 29.7 ms); each is moved to the reference (lime) timestamp of frame i with dense
 * optical flow (data/flow.h) between the same LED's sub-images of two consecutive frames
 * (same LED, so brightness constancy holds):
 *   LED before the reference (tau = t_ref - t_l > 0): frames i and i+1, frame time t = tau;
 *   LED after it (tau < 0): frames i-1 and i, t = 1 + tau = (1 - t_l) + t_ref;
 *   out = lm_flow_interpolate(first, second, t) (bicubic warps),
 * then the confidence blend below.
 * Edge frames: when the preferred neighbour is missing the other one is used and frame i's
 * sub-image is warped alone (bicubic) under linear motion, out(p) = I_i(p - (tau / dt) F_{i->n}(p))
 * (dt = +1 for frame i+1, -1 for frame i-1); with no neighbour the sub-image is copied.
 * Sub-images are the unshuffled tile phases of a raw frame: plane t holds the pixels with
 * (y mod ty) * tx + (x mod tx) == t, each (H / ty) x (W / tx), row-major.
 * In data/ (not infer/) so that the training loader aligns multi-frame samples with the same
 * code inference uses (models.md, multi-frame input).
 * What it is not: demosaicking, the network, or occlusion handling. */
#ifndef LM_ALIGN_H
#define LM_ALIGN_H
#include "data/system.h"
#include "data/flow.h"

/* Trust in the warp, per pixel (alignment that never hurts). With
 * `confidence` on, each aligned pixel is blended with the unaligned one,
 *   out = cur + c (warped - cur),  c in [0, 1],
 * c ramping from 1 to 0 as the forward-backward inconsistency of the flow, scaled to the
 * warp, |tau| |F_{i->n}(p) + F_{n->i}(p + F_{i->n}(p))| (sub-image pixels; n the neighbour
 * used), goes from fb_tol / 2 to fb_tol: where the two flows disagree (occlusion, content
 * entering the view, an LED's image too dark or too aliased to match) the warp would move the
 * pixel to a wrong place by about that much, and the recorded pixel is the safer guess.
 * Measured (docs/guide/reconstructing.md, "How the alignment works"): on translating CAVE
 * scenes the bicubic warp alone already never does worse than no alignment, and this fallback
 * changes the scores by < 0.001 dB there; with an elliptic region moving over a still CAVE
 * background (occlusion) it lowers the aligned mosaic's RMS error by 0.4 % at 480 px/s and changes nothing at 120-240,
 * while tighter tolerances hurt (fb_tol 1: +4 %, 0.5: +21 % at 480 px/s): a guard, not a gain.
 * Gating small shifts (keeping the recorded pixel where |tau F| < 0.25 px) cost 0.3 dB of the
 * gain at 60 px/s and was dropped. */
typedef struct lm_align_opts {
    int confidence;    /* 1: blend as above (default); 0: warp every pixel */
    float fb_tol;      /* sub-image px, > 0 (default 2) */
} lm_align_opts;

/* The defaults (measured, see docs/guide/reconstructing.md). */
void lm_align_default_opts(lm_align_opts *o);

/* Normalised timestamp of each tile phase: t[p] = midpoint of the window of the LED at phase p,
 * in us from the exposure start, divided by the system's frame_period_us (the time between the
 * starts of consecutive frames, the time base of the video simulator too); writes tile_rows *
 * tile_cols values. *ref = the first phase of the reference LED (lm_system_reference_led:
 * Lime, the LED whose window centre is the ground-truth instant of data/video.h). Errors:
 * LM_ERR_ARG (NULL arguments), message starting "align:". */
lm_status lm_align_phase_times(const lm_system *s, float *t, int *ref, lm_err *e);

/* Align the np sub-images of frame i (cur, np x h x w) to the timestamp t[ref]; prev / next are
 * frames i-1 / i+1 (same layout) or NULL. out (np x h x w, not aliasing the inputs) receives the
 * aligned sub-images; plane ref (and any plane with t[p] == t[ref]) is copied. o: flow options
 * (NULL = medium preset); ao: alignment options (NULL = lm_align_default_opts). Errors: LM_ERR_ARG (NULL cur/t/out, ref outside 0..np-1, np < 1),
 * those of lm_flow_compute (image too small, non-finite pixels), message naming the plane. */
lm_status lm_align_frame(const float *prev, const float *cur, const float *next, int np, int h,
                         int w, const float *t, int ref, const lm_flow_opts *o,
                         const lm_align_opts *ao, float *out, lm_err *e);

/* The multi-frame input of a frame (models.md, LM_CAP_MULTI_FRAME): out = 3 x np x h x w,
 *   [0] frame i aligned to t[ref], equal to lm_align_frame's output (the same side, flows and
 *       arithmetic);
 *   [1] frame i-1 moved onto frame i's planes at t[ref]: under linear motion the point at x at
 *       t[ref] sat, in frame i + dt (dt = -1 here), at x + (1 - tau / dt) F_{i->i+dt}(x)
 *       (tau = t[ref] - t[p], the flow between the same LED's planes of the two frames), so
 *       out(x) = prev(x + (1 + tau) F_{i->i-1}(x)) (bicubic); with the confidence on, blended
 *       towards [0] where the forward-backward check fails (scale |1 - tau / dt|);
 *   [2] frame i+1 the same way (dt = +1: out(x) = next(x + (1 - tau) F_{i->i+1}(x))).
 * A missing neighbour (NULL: the first or last frame of a sequence) is replaced by [0], the
 * current frame aligned. Each plane keeps its LED (phase) in every frame: re-mosaicking each
 * of the three gives coded frames on frame i's pixel grid. Flows per plane and neighbour:
 * both directions (4 per plane with two neighbours, twice lm_align_frame's with the confidence
 * on). Errors as lm_align_frame. */
lm_status lm_align_stack(const float *prev, const float *cur, const float *next, int np, int h,
                         int w, const float *t, int ref, const lm_flow_opts *o,
                         const lm_align_opts *ao, float *out, lm_err *e);

/* The multi-frame model input of raw frame cur (height x width, bucket 1) with its raw
 * neighbours prev / next (NULL at a sequence's ends): out = 3 x height x width, the three
 * planes of lm_align_stack re-mosaicked (frame i aligned, frame i-1 and frame i+1 moved onto
 * it; a missing neighbour = frame i aligned). With aligned 0, or sub-images smaller than
 * lm_flow_min_size(o) (the flow cannot run: a still sample is assumed), the frames as
 * recorded: cur, prev (else cur), next (else cur). o NULL = medium preset, 1 thread. The one
 * path of `infer` and `eval` for multi-frame models (the training loader crops the same planes
 * from its windows). Errors: LM_ERR_SHAPE (not whole tiles), those of lm_align_stack. */
lm_status lm_align_stack_frames(const lm_system *sys, const float *prev, const float *cur,
                                const float *next, int height, int width, int aligned,
                                const lm_flow_opts *o, const lm_align_opts *ao, float *out,
                                lm_err *e);

/* Raw frame (height x width, multiples of ty x tx) -> ty * tx planes (see above).
 * Errors: LM_ERR_SHAPE if the size is not a positive multiple of the tile. */
lm_status lm_align_unshuffle(const float *raw, int height, int width, int ty, int tx,
                             float *planes, lm_err *e);

/* The inverse: ty * tx planes of h x w -> raw frame (h * ty) x (w * tx), pixel (y, x) taken
 * from plane (y mod ty) * tx + (x mod tx). Errors: LM_ERR_SHAPE for non-positive sizes. */
lm_status lm_align_remosaic(const float *planes, int h, int w, int ty, int tx, float *raw,
                            lm_err *e);

#endif
