/* simrun.h — a simulation run: coded frames (static, or a video of a moving scene) of a
 * spectral cube written with their ground truth into a folder, the library half of
 * `lumosaic simulate`.
 * What it is: the input cube read for a system (its own grid kept, other grids onto 31 bands
 * 400-700 nm), prepared (cropped top-left to the tile; 31 bands mirrored to the system's 41
 * bins, or a cube already on the system's grid kept), lm_forward_simulate / lm_video_frame /
 * the QDO camera (data/qdocam.h) per frame, and the files of the output folder:
 *   frames/frame_NNNN.<png|tif|exr>   bucket 1 (the coded frame)
 *   bucket0/frame_NNNN.<ext>          bucket 0 (opts.bucket0), stored divided by (LEDs - 1)
 *                                     so that white is 1 as in bucket 1
 *   gt/gt_NNNN.exr, gt/gt_NNNN.png    ground truth (spectral EXR, 31 bands 400-700 nm; sRGB)
 *   simulate.json                     what was done (system, noise, seed, motion, files)
 * With a DOE (opts.doe) the frame is the QDO camera's RGB image instead:
 * frames/frame_0000.exr (float R, G, B) and frames/frame_0000.png (8-bit preview).
 * Progress goes to a caller-supplied callback; nothing is printed.
 * What it is not: the forward models (data/forward.c, data/video.c, data/qdocam.c), the cube
 * readers (data/cube_io.c), or the staging of the output folder (the caller hands an existing
 * empty folder and moves it into place). */
#ifndef LM_SIMRUN_H
#define LM_SIMRUN_H
#include "data/cube.h"
#include "data/qdocam.h"
#include "data/system.h"
#include "data/video.h"
#include "tensor/rng.h"

typedef enum lm_simrun_format {
    LM_SIMRUN_PNG = 0, /* 16-bit PNG frames */
    LM_SIMRUN_TIFF,    /* 16-bit TIFF frames (.tif) */
    LM_SIMRUN_EXR      /* float EXR frames */
} lm_simrun_format;

/* "png", "tiff", "exr" (as simulate.json records them) */
const char *lm_simrun_format_name(lm_simrun_format f);

typedef struct lm_simrun_opts {
    const char *input;        /* the input's name: messages and simulate.json */
    const char *doe;          /* NULL; "default" or a DOE description file: the QDO camera */
    int crop;                 /* crop to the tile (else a size off the tile is an error) */
    int bucket0, video;
    lm_simrun_format format;
    double noise;             /* Gaussian sigma = noise x the frame's largest value */
    double photons;           /* shot noise: photo-electrons at full scale (0 = off) */
    double read_noise;        /* electrons with photons, else a fraction of full scale */
    int clip;
    long long bits;           /* quantisation (0 = off) */
    long long frames;         /* frames to simulate (>= 1) */
    long long samples;        /* video: instants per LED window */
    long long seed;           /* noise seed */
    int nthreads;             /* OpenMP threads (0 = default) */
    lm_motion motion;         /* video: the scene's motion */
    /* Called after each frame's files are written (done = 1..total); NULL = none. */
    void (*progress)(void *user, int done, int total);
    void *user;
} lm_simrun_opts;

/* Defaults: 1 frame, LM_VIDEO_DEFAULT_SAMPLES samples, seed 1, PNG, no noise. */
void lm_simrun_opts_default(lm_simrun_opts *o);

typedef struct lm_simrun {
    const lm_simrun_opts *o;
    const lm_system *sys;
    int in_height, in_width; /* the input's size before the crop */
    lm_cube gt0, sim;        /* cropped input: ground-truth bands, and on the system's grid */
    float *b1, *b0, *rgb;    /* frame buffers (b1: 3 planes with the QDO camera) */
    lm_qdocam *qdo;          /* the QDO camera (opts.doe), else NULL */
} lm_simrun;

/* Read the cube at path for sys: a cube on the system's grid kept as it is, other grids onto
 * 31 bands 400-700 nm (lm_cube_read_with); mat_key: the .mat variable (NULL = automatic).
 * Errors: those of lm_cube_read_with. */
lm_status lm_simrun_read(const char *path, const char *mat_key, const lm_system *sys,
                         lm_cube *in, lm_err *err);

/* Prepare a run of opts (kept by pointer, as sys) on the input cube `in` (not kept): the crop,
 * the cube on the system's grid, the QDO camera, the buffers. Errors: LM_ERR_SHAPE ("<input>:
 * size ... is not a multiple of the tile", smaller than the tile, bands that are neither 31 at
 * 400-700 nm nor the system's grid, a 31-band cube with a system of another grid, a DOE with
 * a cube without the 31 bands), those of lm_cube_mirror41 ("<input>: ..."), of the DOE and
 * the camera ("--doe: ..."), LM_ERR_NOMEM ("out of memory"). *r is zeroed first; free it
 * with lm_simrun_free whatever the status. */
lm_status lm_simrun_init(lm_simrun *r, const lm_simrun_opts *opts, const lm_system *sys,
                         const lm_cube *in, lm_err *err);

/* Simulate every frame (the noise stream seeded by opts.seed) and write the files and
 * simulate.json into dir, an existing empty folder. Errors (what was written is left in dir
 * for the caller to remove): LM_ERR_WRITE ("<path>: path too long", "<path>: cannot create a
 * folder: ...", "<path>: cannot write the summary: ..."), those of the simulation ("<input>:
 * ...") and of the file writers. */
lm_status lm_simrun_write(lm_simrun *r, const char *dir, lm_err *err);

void lm_simrun_free(lm_simrun *r);

#endif
