/* system.h — the imaging system description: LEDs, sensor QE, gains, tile map, firing order and
 * sub-frame timing (system.md sections 1-4), loaded from a versioned JSON file.
 * What it is: the validated, resolved description — every spectrum binned to the system's
 * wavelength grid, gains resolved, each LED's response vector a_l computed, the sub-frame
 * schedule laid out — plus accessors. The bundled default (data/systems/default.json)
 * reproduces the paper's prototype: 12 LEDs, 158 sub-frames of 150 us, the 3 x 4 map of
 * system.md section 2, equal-white gains, CMV12000 QE.
 * What it is not: the simulator (forward.h) or calibration (fitting gains is done elsewhere; a
 * calibrated system file simply lists its gains).
 *
 * File format, version 1 (unknown fields are errors, so typos are caught):
 *   "version": 1                                  required
 *   "name", "description": strings                optional
 *   "grid": {"start_nm", "step_nm", "count"}      optional, default 380 / 10 / 41
 *   "sensor": {"width", "height", "qe"}           qe required; width/height default 640 x 480
 *   "subframe_us": number > 0                     required
 *   "readout_us": number >= 0                     optional, default 0
 *   "frame_period_us": number                     optional, default 1e6/30; must be >= exposure
 *                                                 + readout
 *   "subframes_total": integer                    optional; must equal the sum over the LEDs
 *   "leds": [{"name", "emission", "subframes", "peak_nm"?}, ...]   required, 1..64 LEDs
 *   "gains": "equal_white" | [number >= 0, ...]   optional, default "equal_white"
 *   "tile_map": [[LED name, ...], ...]            required; rows x cols; an LED may fill several
 *                                                 positions, every LED fills at least one
 *   "firing_order": "raster" | [LED name, ...]    optional; "raster" = order of first appearance
 *                                                 in the tile map read row by row
 * A spectrum ("emission", "qe") is either {"csv": path, "column": name or CSV column number
 * (1 = first value column)} with the path relative to the JSON file, binned by integration over
 * each grid bin and divided by the step (bin mean); or an inline array of `count` numbers
 * already on the grid. "peak_nm" overrides the peak wavelength used to sort LEDs (default: the
 * CSV sample with the largest value, or the centre of the largest inline bin).
 *
 * Response (system.md section 4): a_l = scale * alloc_us_l * gain_l * (qe .* E_l) on the grid,
 * alloc_us_l = subframes_l * subframe_us. "equal_white" gains make sum_b a_l[b] (the response to
 * a perfect white reflector) the same for every LED; `scale` makes the largest of these 1.0
 * (with equal-white gains every LED's white response is then 1.0). That is the frames' scale:
 * 1.0 is a frame's full scale (its largest code), what the brightest LED gives a perfect white
 * reflector. The tile map is the camera's mosaic: pixel (y, x) integrates the LED at
 * tile_map[y mod rows][x mod cols] (`lumosaic info --system` draws it). */
#ifndef LM_SYSTEM_H
#define LM_SYSTEM_H
#include <stdint.h>
#include <stdio.h>
#include "tensor/status.h"

#define LM_SYSTEM_VERSION 1
#define LM_SYSTEM_MAX_LEDS 64
#define LM_SYSTEM_MAX_TILE 256
#define LM_LED_NAME_LEN 32

typedef struct lm_led {
    char name[LM_LED_NAME_LEN];
    int subframes;         /* sub-frames allocated per frame */
    int first_subframe;    /* index of its first sub-frame in the frame */
    double start_us;       /* window [start_us, end_us) from exposure start */
    double end_us;
    double peak_nm;        /* peak emission wavelength (sort key) */
    double gain;           /* gain_l, resolved */
    float *emission;       /* nbins: E_l, bin means on the grid */
    float *response;       /* nbins: a_l */
} lm_led;

typedef struct lm_system {
    int version;
    char name[64];
    char path[512];        /* file it was loaded from (or the label given to lm_system_parse) */
    float grid_start, grid_step;
    int nbins;
    int width, height;     /* sensor size in pixels */
    double subframe_us, readout_us, frame_period_us;
    int nsubframes;        /* S, sub-frames per frame */
    int equal_white;       /* 1 if the gains were "equal_white" */
    double scale;          /* normalisation constant in a_l (see above) */
    float *qe;             /* nbins: sensor QE S, bin means */
    int nleds;
    lm_led *leds;          /* in file order */
    int tile_rows, tile_cols;
    int *tile_led;         /* tile_rows * tile_cols: LED index at tile phase t */
    int *firing;           /* nleds: LED indices in firing order */
    int *by_peak;          /* nleds: LED indices by increasing peak wavelength (UV first) */
    int *subframe_led;     /* nsubframes: LED on during sub-frame s */
} lm_system;

/* Load and validate a system file. Errors: LM_ERR_IO (missing file, missing CSV),
 * LM_ERR_FORMAT (JSON syntax, invalid field, bad CSV) with the message
 * "system file <path>: <field>: <problem>", e.g. "leds[3].subframes: must be a positive
 * integer". sys is zeroed on failure (lm_system_free is still safe). */
lm_status lm_system_load(const char *path, lm_system *sys, lm_err *err);
/* The same from JSON text; CSV paths are relative to base_dir; label names it in messages. */
lm_status lm_system_parse(const char *json_text, const char *base_dir, const char *label,
                          lm_system *sys, lm_err *err);
/* The bundled default: <lm_data_dir()>/systems/default.json (see spectra.h). */
lm_status lm_system_default(lm_system *sys, lm_err *err);
void lm_system_free(lm_system *sys);
/* FNV-1a 64 of a file's bytes (0 if unreadable): the identity of a system description that a
 * trained model records (metadata "system_hash") and inference checks. */
uint64_t lm_file_hash(const char *path);

static inline int lm_system_num_leds(const lm_system *s) { return s->nleds; }
/* a_l, nbins floats. */
static inline const float *lm_system_response(const lm_system *s, int led)
{
    return s->leds[led].response;
}
/* LED index by name, or -1. */
int lm_system_led_index(const lm_system *s, const char *name);
/* Tile phase t = (y mod rows) * cols + (x mod cols) of pixel (y, x) (y, x >= 0). */
static inline int lm_system_tile_phase(const lm_system *s, int y, int x)
{
    return (y % s->tile_rows) * s->tile_cols + (x % s->tile_cols);
}
static inline int lm_system_tile_led(const lm_system *s, int t) { return s->tile_led[t]; }
static inline int lm_system_pixel_led(const lm_system *s, int y, int x)
{
    return s->tile_led[lm_system_tile_phase(s, y, x)];
}
/* LED l's illumination window in microseconds from the exposure start. */
static inline void lm_system_led_window(const lm_system *s, int led, double *start_us,
                                        double *end_us)
{
    *start_us = s->leds[led].start_us;
    *end_us = s->leds[led].end_us;
}
/* Exposure time: nsubframes * subframe_us. */
static inline double lm_system_exposure_us(const lm_system *s)
{
    return s->nsubframes * s->subframe_us;
}
/* Centre of LED l's window, microseconds from the exposure start. */
static inline double lm_system_led_centre_us(const lm_system *s, int led)
{
    return 0.5 * (s->leds[led].start_us + s->leds[led].end_us);
}
/* Frame period: frame i's exposure starts at i * frame_period_us (>= exposure + readout). */
static inline double lm_system_frame_period_us(const lm_system *s) { return s->frame_period_us; }
/* The reference LED of every frame (system.md §5, §9): its window's centre is the instant of a
 * video frame's ground truth and the time temporal alignment moves every sub-image to. The LED
 * named "Lime" (case-insensitive); a system without one uses the LED on during the sub-frame
 * that holds the exposure midpoint. The one definition shared by the video simulator
 * (data/video.h) and the alignment (data/align.h). */
int lm_system_reference_led(const lm_system *s);
/* LED indices by increasing peak wavelength: the network's channel order (UV first). */
static inline const int *lm_system_peak_order(const lm_system *s) { return s->by_peak; }
/* Schedule: the LED on during sub-frame `sub` (I[s, l] = 1 for exactly this l), and whether
 * tile phase t integrates into bucket 1 during it (C_tile[t, s]). */
static inline int lm_system_subframe_led(const lm_system *s, int sub)
{
    return s->subframe_led[sub];
}
static inline int lm_system_subframe_code(const lm_system *s, int sub, int t)
{
    return s->tile_led[t] == s->subframe_led[sub];
}
/* A human-readable summary (LEDs, windows, white responses, tile map) for `lumosaic info`. */
void lm_system_describe(const lm_system *s, FILE *f);

#endif
