/* pipeline.h — the frame pipeline of `lumosaic infer` and of the C API's sequences: coded
 * frames (files or memory) to 31-band cubes, one frame at a time.
 * What it is: a run object that loads the model (a path, the bundled model for 1 or 2
 * buckets, or a calibrated per-window choice, infer/auto.h), reads frames through a frame
 * source (a file sequence read lazily, or the caller's buffers), converts a camera's raw frames
 * (infer/raw.h), rescales other LED gains to the model's, pairs bucket 0 with bucket 1 for
 * two-bucket models, aligns sequences in time (data/align.h: three frames' sub-images held at a
 * time, read one frame ahead), stacks frames for multi-frame models, and reconstructs each
 * frame by the model's path (infer/recon.h) on the CPU or an OpenCL device. Notes and warnings
 * go to a caller-supplied callback; the library prints nothing itself and never exits.
 * What it is not: writing cubes or previews, output folders, MPI (the CLI's cmd_infer.c);
 * the flow or the alignment scheme themselves (data/flow.c, data/align.c). */
#ifndef LM_PIPELINE_H
#define LM_PIPELINE_H

#include "data/align.h"
#include "data/frames.h"
#include "infer/auto.h"
#include "infer/model_io.h"
#include "infer/raw.h"
#include "infer/tile.h"

/* A source of coded frames: count frames of height x width (the first frame's size; every
 * frame read must match it). read(self, i, f, e) fills f with frame i (0-based; the caller
 * frees it with lm_frame_free); name(self, i) names frame i in messages. */
typedef struct lm_frame_src {
    int count, height, width;
    int first_index; /* the number of frame 0 (a numbered pattern's first number, else 0) */
    void *self;
    lm_status (*read)(void *self, int i, lm_frame *f, lm_err *e);
    const char *(*name)(void *self, int i);
} lm_frame_src;

/* A source reading the files of an open sequence (the sequence must outlive the source). */
void lm_frame_src_from_seq(lm_frame_src *s, lm_frame_seq *seq);

typedef enum lm_pipe_note { LM_PIPE_INFO = 0, LM_PIPE_WARNING = 1 } lm_pipe_note;
/* A message of the pipeline: one line without a newline (kind: a note or a warning). */
typedef void (*lm_pipe_msg_fn)(void *user, lm_pipe_note kind, const char *line);

typedef struct lm_pipe_opts {
    const char *model;     /* a model file or run folder, or "auto" */
    const char *auto_file; /* with model "auto": a `lumosaic fit-auto` calibration (NULL: the
                            * bundled model for bundled_buckets buckets) */
    double auto_tol;       /* dB of expected PSNR the auto choice may give up (default 0.5) */
    int bundled_buckets;   /* model "auto" without a calibration, frames from memory: 1 or 2 */
    const char *system;    /* the camera's system file (NULL: the model's) */
    double noise_level;    /* noise-reading models: sd = level x the frame's maximum; < 0
                            * estimates it from each frame (the default) */
    int no_align;          /* 1: sequences are not aligned in time (stacked as recorded) */
    int tiles;             /* 1: patch-wise even where the whole frame could run at once */
    int batch;             /* windows per network call (default 8) */
    lm_raw_opts raw;       /* raw-camera conversion of bucket 1 (zeroed: none) */
    int threads;           /* 0: OpenMP's default */
    const char *device;    /* "cpu", "opencl"; NULL: env LM_DEVICE, else cpu */
    int precision;         /* LM_PRECISION_* */
    lm_pipe_msg_fn msg;    /* NULL: notes and warnings are dropped */
    void *msg_user;
} lm_pipe_opts;

/* model NULL, auto_tol 0.5, noise_level -1, batch 8, the rest zero. */
void lm_pipe_default_opts(lm_pipe_opts *o);

/* Temporal alignment state: the sub-images (np planes of ph x pw) of frames i-1, i, i+1. */
typedef struct lm_pipe_align {
    int on;
    int np, ph, pw, ty, tx, ref;
    float *t;                 /* np normalised timestamps */
    lm_flow_opts fo;
    float *prev, *cur, *next; /* np * ph * pw each; prev / next NULL-able views */
    float *buf[3];            /* the storage behind prev / cur / next */
    float *aligned, *raw;     /* aligned planes, re-mosaicked frame */
    int mf;                   /* multi-frame model: raw frames in fr, the stacked input in mf3 */
    float *fr[3], *mf3;       /* frames i-1, i, i+1 (H x W each); 3 x H x W */
    int next_i;               /* the frame the loaded planes expect next (-1: none) */
} lm_pipe_align;

/* A run. Read its fields, change none of them (the library's own modules excepted). */
typedef struct lm_pipe {
    lm_pipe_opts o;
    int is_auto;              /* a calibrated per-window choice */
    char model_path[1200];    /* the model loaded (the bundled one for "auto") */
    lm_infer_model im;        /* the model (auto: model 0) */
    lm_infer_model more[LM_AUTO_MAX_MODELS]; /* auto: models 1.. */
    lm_model *models[LM_AUTO_MAX_MODELS];
    lm_auto_calib cal;
    int choice[LM_AUTO_MAX_BINS];
    long windows[LM_AUTO_MAX_MODELS];       /* auto: windows per model so far */
    lm_ctx ctx;
    int have_ctx;
    lm_tile_device dev;
    /* frames (lm_pipe_attach .. lm_pipe_detach) */
    char input[1100];         /* files: the input as given ("" for sources) */
    lm_frame_seq seq, seq0;   /* files: the sequences behind src, src0 */
    lm_frame_src src, src0;   /* bucket 1; bucket 0 (count 0: none) */
    float *in2;               /* two-bucket models: bucket 1 then bucket 0, 2 x H x W */
    lm_raw raw;
    double *sat;              /* per frame: the share of saturated pixels (-1: not read) */
    lm_pipe_align al;
    int clip_warned;          /* the note on clipped noisy frames was given */
} lm_pipe;

/* Open a run on files, as `lumosaic infer` does: input (a frame, pattern or folder), bucket0
 * (two-bucket models; NULL: the bucket0/ folder beside the input's frames/). Everything that
 * can be checked before a frame is reconstructed is: model, frames, sizes, buffers, device.
 * *out is NULL on failure (e says why). */
lm_status lm_pipe_open_files(const lm_pipe_opts *o, const char *input, const char *bucket0,
                             lm_pipe **out, lm_err *e);
/* Open a run without frames (the model, its context and device); frames are attached later. */
lm_status lm_pipe_open(const lm_pipe_opts *o, lm_pipe **out, lm_err *e);
/* Frames from sources (src0: bucket 0 for two-bucket models, else NULL; both must outlive
 * the attachment); the sources are copied. Replaces frames attached before. */
lm_status lm_pipe_attach(lm_pipe *p, const lm_frame_src *src, const lm_frame_src *src0,
                         lm_err *e);
void lm_pipe_detach(lm_pipe *p);
void lm_pipe_close(lm_pipe *p);

/* What reconstructing one frame took. */
typedef struct lm_pipe_info {
    double align_s, recon_s; /* seconds: the input (reading, alignment), the reconstruction */
    int aligned;             /* the frame was aligned in time (or stacked aligned) */
    double saturated;        /* share of saturated pixels of the frame as read (0..1) */
} lm_pipe_info;

/* Frame i (0-based) of the attached frames to a new cube (bands 400-700 nm, not clamped).
 * Frames are best taken in order: frame i + 1 reuses frame i's sub-images. */
lm_status lm_pipe_frame(lm_pipe *p, int i, lm_cube *cube, lm_pipe_info *info, lm_err *e);
/* One prepared input (H x W; two-bucket models 2 x H x W) by the run's path. */
lm_status lm_pipe_reconstruct(lm_pipe *p, const float *in, int height, int width,
                              lm_cube *cube, lm_err *e);
/* Frame i's saturated pixels as read (1.0, else 0) into a new frame. */
lm_status lm_pipe_saturation_mask(lm_pipe *p, int i, lm_frame *mask, lm_err *e);

/* The line naming the model and the buckets it read, e.g. "model tn-96-nc+lmmse (FILE):
 * bucket 1"; "" for a per-window choice. */
void lm_pipe_model_line(const lm_pipe *p, char *out, size_t n);
/* The attached frames: count, and frame i's name. */
int lm_pipe_count(const lm_pipe *p);
const char *lm_pipe_frame_name(const lm_pipe *p, int i);

/* The per-window choice over the frames so far. */
typedef struct lm_pipe_auto_summary {
    int nmodels, best;             /* best: the model of the highest expected PSNR */
    const char *preset[LM_AUTO_MAX_MODELS];
    long windows[LM_AUTO_MAX_MODELS], total;
    double psnr_choice, psnr_best; /* the calibration's expected PSNR: this choice, always best */
} lm_pipe_auto_summary;
void lm_pipe_auto_summarize(const lm_pipe *p, lm_pipe_auto_summary *s);

#endif
