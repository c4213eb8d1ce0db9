/* report.h — one self-contained HTML page for an `infer` or `eval` output folder, the library
 * half of `lumosaic report` and `eval --report`.
 * What it is: reading what the folder holds and writing one HTML file that works offline (no
 * network, everything embedded): the sRGB previews (D65, CIE 1931) of a reconstruction and,
 * where known, of its truth as base64 PNGs; the cube box-averaged down to at most max_side
 * pixels on its long side as base64 16-bit samples, from which the page draws each band, the
 * per-band error map and the spectrum of any clicked pixel (400-700 nm); the metrics as JSON
 * (PSNR / SSIM / MAE / SAM per noise level and scene, PSNR per band of the sample) and the
 * rainbow test's recovered peak against the true one, row by row. The page draws its plots as
 * inline SVG from a small inline script (infer/report_page.html, embedded at build time).
 * An eval folder holds eval.json; with `eval --report` also sample_recon.exr and
 * sample_truth.exr (one scene, prepared as eval scores it, at one noise level; negative
 * outputs clamped to 0), sample.json (that scene, its level and metrics) and rainbow.csv (row,
 * true and recovered peak). An infer folder holds cube_NNNN.exr (one frame is shown).
 * A page's URL may end in #click=X,Y (full-resolution pixel of the previews): the page then
 * clicks that pixel itself once loaded (the browser test uses it).
 * What it is not: a viewer of whole sequences (one frame per page), or the scoring itself
 * (infer/eval.h). */
#ifndef LM_REPORT_H
#define LM_REPORT_H
#include <stddef.h>
#include "infer/eval.h"

#define LM_REPORT_MIN_SIDE 16
#define LM_REPORT_MAX_SIDE 1024
#define LM_REPORT_DEFAULT_SIDE 128

typedef struct lm_report_opts {
    int max_side; /* long side of the embedded cube, LM_REPORT_MIN_SIDE..LM_REPORT_MAX_SIDE */
    int frame;    /* infer folders: the number NNNN of the cube shown (-1: the first) */
} lm_report_opts;

typedef struct lm_report_info {
    int eval;            /* 1: an eval folder, 0: an infer folder */
    int has_sample;      /* a reconstruction is shown (infer: always; eval: with --report's files) */
    int has_truth;       /* its truth too (eval samples) */
    int rainbow_rows;    /* rows of the rainbow plot (0: none) */
    int width, height;   /* the shown cube's full size */
    int side_w, side_h;  /* the embedded cube's size */
    size_t bytes;        /* size of the page written */
    char shown[256];     /* what is shown: a scene name or a cube file name */
} lm_report_info;

void lm_report_default_opts(lm_report_opts *o);

/* Write the page for folder dir to out (atomically: "<out>.tmp.<pid>" renamed; nothing is left
 * on failure). info may be NULL. Errors: LM_ERR_IO (dir missing or unreadable), LM_ERR_WRITE (out
 * cannot be written), LM_ERR_FORMAT (dir holds neither eval.json nor cube_NNNN.exr; eval.json,
 * sample.json or rainbow.csv malformed; sample cubes of different sizes), LM_ERR_ARG (max_side
 * out of range, --frame not in the folder), those of the cube reader; messages name the file. */
lm_status lm_report_write(const char *dir, const char *out, const lm_report_opts *o,
                          lm_report_info *info, lm_err *err);

/* The files `eval --report` adds to an eval folder dir (see above): the scene at path (read
 * with mat_key, NULL = automatic; named name) prepared and reconstructed at noise level k
 * with the noise eval draws for it (seed, the scene's name and k: lm_eval_scene_one), written
 * as sample_recon.exr, sample_truth.exr and sample.json; rb (NULL: none) as rainbow.csv.
 * Each file atomically. Errors: those of the reader, lm_eval_scene_one and the writers. */
lm_status lm_report_eval_files(lm_ctx *c, const lm_infer_model *im, const char *path,
                               const char *name, const char *mat_key, long long seed, float k,
                               const lm_tile_opts *to, const lm_eval_rainbow *rb,
                               const char *dir, lm_err *err);

#endif
