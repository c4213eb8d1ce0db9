/* video.h — the video forward model: a coded frame of a moving scene (system.md sections 1, 5).
 * What it is: a motion model that moves a static cube over time (global translation, rotation
 * and zoom, plus independently moving rectangular or elliptic regions), the warp that renders
 * the scene at an instant (bilinear resampling, edge clamping), and the coded-frame simulation
 * where each LED's pixels integrate the scene over that LED's own window: the window is split
 * into `samples` equal parts, the scene is taken at each part's midpoint and the spectra are
 * averaged (motion blur). Frame i starts at i * frame_period_us; its ground truth is the scene
 * at the reference instant (the centre of the Lime LED's window, see lm_video_gt_time_us).
 * Every time comes from the system description (frame_period_us, the LEDs' windows), as in
 * the alignment (data/align.h).
 * What it is not: a renderer of 3-D scenes (occlusion is only "regions are drawn on top"), or
 * temporal alignment (that undoes this motion at inference, infer/).
 *
 * Geometry: pixel centres at integer coordinates (x right, y down). The scene at time t (s) is
 * the input cube moved by the forward map of a point q of the input:
 *     p = c + s(t) R(theta(t)) (q - c) + v t,   theta(t) = rot_deg_s * t,
 *     s(t) = (1 + zoom_pct_s / 100)^t  (compounded: zoom_pct_s > -100),
 * R the rotation matrix [cos -sin; sin cos] acting on (x, y): positive angles turn clockwise
 * as displayed. c = (cx, cy), the image centre ((W-1)/2, (H-1)/2) unless has_centre.
 * A region holds, at t = 0, the input's pixels inside its shape (rectangle or ellipse centred at
 * (cx, cy), full size w x h); at time t the shape and its content are translated by (vx, vy) t
 * and drawn over the background (the later region on top). Each output pixel samples the input
 * at the inverse-mapped point; a sub-pixel position within 1e-9 px of a pixel centre is snapped
 * to it, so an integer displacement copies pixels exactly; positions outside are clamped to the
 * border (edge pixels repeat). */
#ifndef LM_VIDEO_H
#define LM_VIDEO_H
#include "data/cube.h"
#include "data/forward.h"
#include "data/system.h"
#include "tensor/rng.h"
#include "tensor/status.h"

#define LM_VIDEO_MAX_REGIONS 8
#define LM_VIDEO_MAX_SAMPLES 64
#define LM_VIDEO_DEFAULT_SAMPLES 4

typedef enum lm_region_shape { LM_REGION_RECT = 0, LM_REGION_ELLIPSE = 1 } lm_region_shape;

typedef struct lm_motion_region {
    lm_region_shape shape;
    double cx, cy;   /* centre at t = 0, pixels */
    double w, h;     /* full width and height, pixels, > 0 */
    double vx, vy;   /* velocity, pixels per second */
} lm_motion_region;

/* All zero = a still scene. */
typedef struct lm_motion {
    double vx, vy;         /* global translation, pixels per second */
    double rot_deg_s;      /* global rotation about the centre, degrees per second */
    double zoom_pct_s;     /* global scale change, percent per second (compounded), > -100 */
    int has_centre;        /* 0: rotate/zoom about the image centre */
    double cx, cy;
    int nregions;          /* 0 .. LM_VIDEO_MAX_REGIONS */
    lm_motion_region regions[LM_VIDEO_MAX_REGIONS];
} lm_motion;

typedef struct lm_video_opts {
    lm_motion motion;
    int samples;          /* instants per LED window, 1 .. LM_VIDEO_MAX_SAMPLES; 0 = 4 */
    int y0, x0;           /* sensor position of the cube's top-left pixel (tile phases) */
    lm_noise_opts noise;  /* as lm_forward_noise; all zero = noise-free */
    int nthreads;         /* OpenMP threads; 0 = the OpenMP default */
} lm_video_opts;

/* LM_ERR_ARG ("video: motion: ...") for non-finite values, zoom <= -100 %/s, a region count
 * outside 0..LM_VIDEO_MAX_REGIONS or a region size <= 0. */
lm_status lm_motion_check(const lm_motion *m, lm_err *err);
/* The input position (*sx, *sy) that output pixel (x, y) of an H x W scene shows at time t_s
 * (seconds), before snapping and clamping. */
void lm_motion_source(const lm_motion *m, int height, int width, double t_s, double x, double y,
                      double *sx, double *sy);

/* Allocate *out (same bands, size and wavelengths as src) and fill it with the scene at t_s.
 * Works for any band count. Errors: LM_ERR_ARG (bad motion, non-finite time, empty cube),
 * LM_ERR_NOMEM; *out is zeroed on failure. */
lm_status lm_video_warp(const lm_cube *src, const lm_motion *m, double t_s, lm_cube *out,
                        int nthreads, lm_err *err);

/* Start of frame i's exposure: i * frame_period_us (microseconds). */
double lm_video_frame_start_us(const lm_system *sys, int frame);
/* Instant k (0 .. samples-1) of LED led's window, from the exposure start (microseconds):
 * start + (k + 0.5) / samples * (end - start). */
double lm_video_led_instant_us(const lm_system *sys, int led, int k, int samples);
/* The ground-truth instant from the exposure start (microseconds): the centre of the window of
 * the system's reference LED (lm_system_reference_led: Lime; a system without one uses the
 * window that holds the exposure midpoint), the instant alignment moves sub-images to. */
double lm_video_gt_time_us(const lm_system *sys);

/* Frame `frame` (>= 0) of the video of `cube` (on the system's grid, as lm_forward_clean) moving
 * by o->motion: bucket 1 (required, H x W: pixel p = a_{l(p)} . mean over l(p)'s instants of
 * the scene at p), bucket 0 (NULL to skip: sum over the other LEDs l of a_l . mean over l's
 * instants), then o->noise (bucket 1 first, as lm_forward_simulate). gt: NULL, or allocated and
 * set to the scene at the frame's ground-truth instant (same bands as cube). With no motion
 * bucket 1 equals lm_forward_simulate's exactly, noise included, for the same rng state.
 * Errors: those of lm_forward_simulate ("forward: ..."), LM_ERR_ARG ("video: ...") for bad
 * motion, samples or frame; on failure gt is zeroed. */
lm_status lm_video_frame(const lm_system *sys, const lm_cube *cube, const lm_video_opts *o,
                         int frame, lm_rng *rng, float *bucket1, float *bucket0, lm_cube *gt,
                         lm_err *err);

#endif
