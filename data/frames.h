/* frames.h — coded camera frames on disk: one frame, or an ordered sequence of frames.
 * What it is: read/write one single-channel frame (16-bit PNG/TIFF, or 32-bit float OpenEXR)
 * as a float buffer, and list a sequence given as a numbered pattern (`name_%04d.png`) or a
 * folder. Integer files are normalised to [0, 1] (16-bit: v / 65535, 8-bit: v / 255); float
 * files are returned as stored (negative values allowed, NaN/inf rejected).
 * What it is not: demosaicking or any processing of the mosaic (see the forward model / demosaic
 * code), nor colour images (frames with more than one channel are rejected). */
#ifndef LM_FRAMES_H
#define LM_FRAMES_H
#include "tensor/status.h"

typedef struct lm_frame {
    int height, width;
    int bits;     /* bits per sample in the file: 8 or 16 (integer), 16 (half) or 32 (float) */
    int is_float; /* 1 for EXR / float TIFF */
    float *data;  /* height * width, row-major: data[y*W + x] */
} lm_frame;

/* Read one frame (.png, .tif, .tiff, .exr; case-insensitive). The header is checked before any
 * allocation (see lm_frame_seq_open). On failure *f is zeroed and e says "<path>: <problem>":
 * LM_ERR_IO (missing, a directory), LM_ERR_FORMAT (corrupt, truncated, not single-channel,
 * over a limit), LM_ERR_NUMERIC (NaN/inf), LM_ERR_UNSUPPORTED (extension). */
lm_status lm_frame_read(const char *path, lm_frame *f, lm_err *e);
void lm_frame_free(lm_frame *f);

/* Write one frame, format from path's extension: .png/.tif/.tiff as 16-bit
 * round(clamp(v, 0, 1) * 65535), .exr as 32-bit float (channel "Y", ZIP). NaN (and, for EXR,
 * inf) -> LM_ERR_NUMERIC and nothing is written. Atomic: `<path>.tmp.<pid>` then rename; on
 * failure the temporary file is removed and an existing file at path is left untouched. */
lm_status lm_frame_write(const char *path, int height, int width, const float *data,
                         lm_err *e);

typedef struct lm_frame_seq {
    int count;          /* >= 1 */
    char **paths;       /* count file paths, in frame order */
    int first_index;    /* number of the first frame for a pattern (0 for a folder / file) */
    int height, width;  /* size of the first frame; every frame read must match it */
} lm_frame_seq;

/* Open a sequence. spec is one of:
 *  - a folder: every .png/.tif/.tiff/.exr file in it (hidden files skipped), sorted by name
 *    (byte order, so number frames with zero padding);
 *  - a pattern with one `%d` or `%0Nd` in the file name (e.g. "run/frame_%04d.png"): the files
 *    it produces, by increasing number; the numbers must be consecutive (a gap is an error
 *    naming the missing file);
 *  - a single frame file: a sequence of one.
 * Every frame's header is checked (a single channel of 8/16-bit unsigned, half or float
 * samples; at most LM_MAX_FRAME_PIXELS and no more than the file can hold, data/limits.h; the
 * size of the first frame, which fills height/width) before any pixel is read, so a bad frame
 * anywhere in the sequence fails here. On failure *s is zeroed. */
lm_status lm_frame_seq_open(const char *spec, lm_frame_seq *s, lm_err *e);

/* Read frame i (0-based) of the sequence; a size different from the first frame's is
 * LM_ERR_FORMAT naming the file (a file grown since lm_frame_seq_open is refused from its
 * header, before its pixels are allocated). */
lm_status lm_frame_seq_read(const lm_frame_seq *s, int i, lm_frame *f, lm_err *e);
void lm_frame_seq_free(lm_frame_seq *s);

#endif
