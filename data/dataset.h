/* dataset.h — training/validation/test samples simulated on the fly (system.md §4, §7).
 *
 * What it is: a folder (or list) of scenes in mixed formats (CAVE folders, ARAD/KAUST .mat,
 * spectral EXR), loaded lazily into a bounded cache and split by scene group deterministically:
 * variants of one scene (`x_crop150`, `x_256` of a 256 x 256 scene) form a group and share a
 * split; of G groups ranked by a hash of their key, round(G/10) are test, as many val, the
 * rest train (adding a scene moves at most the groups at the two boundaries). A sample is
 * a tile-aligned patch (66 x 64 by default), flipped at random (on the cube, before simulation),
 * mirrored 31 -> 41 bins, passed through the forward model with noise, paired with its
 * 33-channel target. A configurable proportion of samples are synthetic (data/synth.h:
 * narrowband Gaussian spectra as textureless patches, procedural scenes).
 *
 * Determinism: sample i of a split is a pure function of (seed, split, i): it draws from
 * lm_rng_split(seed-rng, i), so batches can be prepared by worker threads in any order and a
 * run resumed at batch k gives the same numbers as an uninterrupted run. Validation and test
 * samples are a fixed list (same every call).
 *
 * What it is not: the forward model itself (forward.h) or file readers (cube_io.h). */
#ifndef LM_DATASET_H
#define LM_DATASET_H
#include <stdint.h>
#include <stdio.h>
#include "data/system.h"

/* (Named lm_data_split, not lm_split: tensor/ops.h has the op lm_split.) */
typedef enum lm_data_split {
    LM_SPLIT_TRAIN = 0,
    LM_SPLIT_VAL = 1,
    LM_SPLIT_TEST = 2
} lm_data_split;

/* The most data preparation threads a dataset runs. */
#define LM_DATASET_MAX_WORKERS 64

typedef struct lm_dataset_cfg {
    const char *const *paths;   /* scene files/folders, or folders of scenes */
    int npaths;
    const lm_system *sys;       /* forward model (not owned) */
    int patch_h, patch_w;       /* multiples of the tile (default 66 x 64) */
    float synth_fraction;       /* in [0, 1]: share of the paper's synthetic samples, textureless
                                 * patches of narrowband Gaussian spectra (paper: 0.33) */
    float procedural_fraction;  /* in [0, 1 - synth_fraction]: share of procedural scenes
                                 * (data/synth.h: textured regions of varied spectra; not in the
                                 * paper); the rest are real scenes */
    float noise_min, noise_max; /* Gaussian noise k ~ U[min, max] x max clean value (0, 0.15) */
    int flips;                  /* random horizontal/vertical flips (training split only) */
    uint64_t seed;
    int workers;                /* threads preparing batches ahead (0 = synchronous; at most
                                 * LM_DATASET_MAX_WORKERS) */
    int cache_scenes;           /* scenes kept in memory (LRU); 0 = all. Never exceeded: when
                                 * every cached scene is in use by a worker, a scene is read for
                                 * that one sample without being cached */
    int val_patches;            /* fixed validation/test samples per split (default 64) */
    float val_noise;            /* noise level k of validation/test samples (default 0) */
    int sensor_clip;            /* 1: after the noise, clip to [0, 1] (the full scale), as a
                                 * sensor or a 16-bit PNG frame holds values (default 0) */
    int sensor_bits;            /* quantise to this many bits (0 = off, 16 = PNG) */
    float clip_fraction;        /* in [0, 1]: share of training samples clipped as sensor_clip
                                 * clips (a frame that went through a 16-bit PNG), the rest
                                 * keeping their negatives (0; sensor_clip 1: all) */
    float clean_fraction;       /* in [0, 1]: share of training samples without noise (no
                                 * Gaussian, shot or read noise; noise_k 0), the rest drawn as
                                 * above: a model that denoises without losing its clean
                                 * accuracy (0) */
    double photons;             /* > 0: shot noise, photo-electrons at full scale (the white
                                 * response of the brightest LED), before the Gaussian k; 0 = off */
    double photons_min;         /* > 0: each training sample's photons drawn log-uniformly in
                                 * [photons_min, photons] (validation and test: photons) */
    float read_noise;           /* read noise: electrons with photons, else a fraction of full
                                 * scale (data/forward.h); 0 = off */
    int batch_stride;           /* the caller asks for batch index + stride after index (data-
                                 * parallel ranks take every stride-th batch): what the workers
                                 * prepare ahead (0 or 1 = the next one) */
    int buckets;                /* 1 (or 0): samples are bucket 1 only (1 plane, the paper);
                                 * 2: bucket 1 and bucket 0 / (LEDs - 1) (2 planes, the stored
                                 * scale of `simulate --bucket0`). Each bucket gets the noise
                                 * independently: Gaussian k x that bucket's own clean maximum
                                 * (the same k), clipping / quantisation on its own full scale
                                 * (lm_forward_bucket0_noise) */
    float illum_jitter;         /* > 0: each training sample's spectra multiplied by a smooth
                                 * tilt exp(t (lambda - 550 nm) / 150 nm), t ~ U[-this, this],
                                 * scaled so its largest band factor is 1 (an illuminant of
                                 * another colour temperature; target and frame alike); 0 = off */
    float gain_jitter;          /* > 0: each training sample's frame simulated with every LED's
                                 * gain times max(0.1, 1 + this x N(0, 1)) (a calibration error:
                                 * the target stays the scene's); 0 = off */
    float scale_jitter;         /* > 0: each training scene sample resampled from a region z
                                 * times the patch, z = (1 + this)^u, u ~ U[-1, 1] (at most
                                 * 1): an area average where z > 1 (finer detail per pixel), a
                                 * bilinear one where z < 1; z capped so the region fits the
                                 * scene; its place anywhere in the scene (not on the tile grid:
                                 * the mosaic is applied after); 0 = off */
    int transpose;              /* 1: each training scene sample transposed with probability
                                 * 1/2 (when the scene holds the turned region); with flips,
                                 * every quarter turn and mirror */
    float fine_fraction;        /* share of procedural scenes with fine narrowband detail
                                 * (lm_synth_fine: strokes, iridescence), drawn after the
                                 * procedural share (the three synthetic shares sum to <= 1) */
    float collage;              /* share of training scene samples with a patch of another
                                 * training scene (any one, anywhere, its own flips) pasted in
                                 * across a straight edge of random direction through the
                                 * middle half of the patch (antialiased over one pixel): more
                                 * edges between materials than 21 scenes hold; 0 = off */
    const char *mat_key;        /* .mat cube variable (NULL or "": automatic, cube_io.h);
                                 * copied by lm_dataset_open */
} lm_dataset_cfg;

#define LM_DATASET_KEY_LEN 64

typedef struct lm_dataset lm_dataset;

/* Defaults of system.md: 66 x 64, synth 0.33, noise U[0, 0.15], flips on, 2 workers. */
void lm_dataset_default_cfg(lm_dataset_cfg *cfg);
/* Scenes are divided by their own maximum when read (system.md §10), so training targets,
 * validation and `lumosaic eval` share one scale.
 * Lists and checks the scenes (reads headers, not pixels: CAVE band 01 and EXR headers; a .mat
 * file, an EXR off the 31-band grid and a scene with a wavelength sidecar are read whole, onto
 * 31 bands 400-700 nm as lm_cube_read_with does, cfg->mat_key choosing the .mat variable;
 * matio offers no cheap header read). A folder is a CAVE scene if it
 * holds band images (or its single sub-folder does, scene/scene/); otherwise it is a folder of
 * scenes: its .mat/.exr files and CAVE scene folders, in name order. Scenes smaller than the
 * patch are left out of the lists (they still count in the split rule below). Errors name the
 * file. A split with no scene borrows from the others only if fewer than 3 scenes exist
 * (documented in the message printed by lm_dataset_describe). */
lm_dataset *lm_dataset_open(const lm_dataset_cfg *cfg, lm_err *err);
void lm_dataset_close(lm_dataset *d);
int lm_dataset_num_scenes(const lm_dataset *d, lm_data_split split);
/* Planes of a sample's raw input: 1 (bucket 1) or 2 (both buckets, cfg.buckets 2). */
int lm_dataset_buckets(const lm_dataset *d);
/* Training batch number `index` (0-based): raw is B x 1 x ph x pw (coded patches, bucket 1;
 * B x 2 x ph x pw with cfg.buckets 2: bucket 1, then bucket 0 / (LEDs - 1)),
 * target B x 33 x ph x pw; host buffers owned by the caller. Same index, same numbers: item j
 * is training sample index * B + j. With workers, batch index + 1 is prepared in the
 * background after each call. Call from one thread at a time. */
lm_status lm_dataset_batch(lm_dataset *d, long index, int batch, float *raw, float *target,
                           lm_err *err);
/* Training sample i (item i % B of batch i / B) as lm_dataset_batch makes it but noise-free:
 * no noise, clipping or quantisation (raw and target in the batch item's layout); its noise
 * level is lm_dataset_sample_info_get's noise_k. For loaders that draw the noise themselves
 * (the multi-frame source: several noisy frames of one sample). Thread-safe as the workers. */
lm_status lm_dataset_sample_clean(lm_dataset *d, long i, float *raw, float *target, lm_err *err);
/* Fixed validation/test sample i (0 <= i < lm_dataset_eval_count), same layout as one batch
 * item: a real scene (scene i mod n of the split), a random tile-aligned position, no flip,
 * noise val_noise drawn from a fixed stream. A split without scenes has no samples (count 0). */
lm_status lm_dataset_eval_sample(lm_dataset *d, lm_data_split split, int i, float *raw,
                                 float *target, lm_err *err);
int lm_dataset_eval_count(const lm_dataset *d, lm_data_split split);
/* Prints the settings, the split rule, each split's scene count and the names of the val and
 * test scenes (the real scenes held out). */
void lm_dataset_describe(const lm_dataset *d, FILE *f);

/* ---- introspection (tests, `lumosaic info`) ------------------------------------------- */
/* The split rule. A scene's name is its file name without extension, or for CAVE the name of
 * the folder holding the band images. Its group key is the name with one trailing
 * `_crop<digits>` removed, or else one trailing `_<digits>` removed when that number equals
 * the scene's height or width (a resolution tag: `clay_256` of 256 x 256 -> `clay`;
 * `ARAD_1K_0001` of 482 x 512 keeps its name). The G groups of the dataset's scenes (all
 * listed scenes, including those smaller than the patch) are sorted by a 64-bit hash of the
 * key (FNV-1a + splitmix; ties by key): the first floor(0.1 G + 0.5) are test, the next
 * floor(0.1 G + 0.5) val, the rest train. So fewer than 5 groups are all train.
 *
 * lm_dataset_group_key writes the key of `name` to out (n bytes, truncated as snprintf) and
 * returns its length. */
int lm_dataset_group_key(const char *name, int height, int width, char *out, size_t n);
/* The split the rule gives scene `name_or_path` (its path as listed, else its name) in this
 * dataset: LM_SPLIT_*, or -1 if no scene has that path or name. Never a borrowed split. */
int lm_dataset_split_of_scene(const lm_dataset *d, const char *name_or_path);
/* 1 if the split's scene list is borrowed (fewer than 3 scenes: a split with no scene of its
 * own reuses them all), else 0. A borrowed list holds no scene of that split: held-out
 * evaluation must not use it. */
int lm_dataset_split_borrowed(const lm_dataset *d, lm_data_split split);
/* Name and path of scene i (0 <= i < lm_dataset_num_scenes(d, split)) of a split; NULL if out
 * of range. */
const char *lm_dataset_scene_name(const lm_dataset *d, lm_data_split split, int i);
const char *lm_dataset_scene_path(const lm_dataset *d, lm_data_split split, int i);

/* One scene of lm_dataset_list_scenes. */
typedef struct lm_dataset_scene {
    char name[256], path[1024];
    lm_data_split split; /* the scene's own split (never a borrowed list's) */
} lm_dataset_scene;
/* The scenes the DATA paths name, split as lm_dataset_open splits them (opened with no workers
 * and no synthetic samples, then closed): the list of `split`, or of every split for split < 0
 * (train, val, test, in that order), each in list order; borrowed lists are skipped and each
 * path comes once; mat_key as lm_dataset_cfg's. *out (free() it) holds *n scenes (possibly none). Errors: those of
 * lm_dataset_open; LM_ERR_NOMEM ("out of memory"). */
lm_status lm_dataset_list_scenes(const char *const *paths, int npaths, const lm_system *sys,
                                 const char *mat_key, int split, lm_dataset_scene **out, int *n,
                                 lm_err *err);

/* The identity of a scene's content on disk: FNV-1a 64 over the bytes of its file, or, for a
 * folder (a CAVE scene), of every regular file in it (hidden files skipped) in name order; 0 if
 * nothing can be read. Names and paths do not enter it: a copied or renamed scene keeps it. */
uint64_t lm_scene_content_hash(const char *path);
/* The content hashes of the scenes of a split (lm_scene_content_hash, "%016x" each, comma
 * separated; "" for none), malloc'ed (NULL: out of memory). */
char *lm_dataset_split_hashes(const lm_dataset *d, lm_data_split split);

typedef enum lm_sample_kind {
    LM_SAMPLE_SCENE = 0,       /* a patch of a real scene */
    LM_SAMPLE_NARROWBAND = 1,  /* synthetic: textureless Gaussian spectrum */
    LM_SAMPLE_PROCEDURAL = 2,  /* synthetic: procedural scene */
    LM_SAMPLE_FINE = 3         /* synthetic: procedural scene with fine narrowband detail */
} lm_sample_kind;

/* What sample i of a split is made of (drawn exactly as lm_dataset_batch /
 * lm_dataset_eval_sample draw it; training sample i is item i % B of batch i / B). */
typedef struct lm_dataset_sample_info {
    lm_sample_kind kind;
    int scene;            /* index in the split's scene list (LM_SAMPLE_SCENE), else -1 */
    int y0, x0;           /* patch top-left in the scene (multiples of the tile), else 0 */
    int flip_h, flip_v;   /* columns / rows reversed (applied to the cube before simulation) */
    float noise_k;        /* Gaussian noise level k */
    float illum_tilt;     /* t of the illumination tilt (0: none) */
    float led_gain[LM_SYSTEM_MAX_LEDS]; /* each LED's gain factor (1: none) */
    float zoom;           /* scene pixels per patch pixel along each axis (1: none) */
    int transpose;        /* patch row y, column x read from the region's row x, column y */
    float sy0, sx0;       /* the region's top-left in scene pixels (y0, x0 without zoom or
                           * transpose); region pixel (a, b) covers [sy0 + a zoom, sy0 +
                           * (a + 1) zoom) x [sx0 + b zoom, ...). Flips apply to the patch. */
    int clip;             /* 1: the noisy frame is clipped to [0, 1] (sensor_clip, or drawn
                           * with probability clip_fraction) */
    int clean;            /* 1: drawn without noise (probability clean_fraction; noise_k 0) */
    int collage;          /* 1: the patch above is blended with a second one (below) */
    int mix_scene;        /* the second patch: its scene (index in the split's list), */
    int mix_y0, mix_x0;   /* its top-left there (any pixel) and flips */
    int mix_flip_h, mix_flip_v;
    float edge_nx, edge_ny, edge_c; /* patch pixel (y, x) takes the second patch with weight
                                     * clamp(0.5 + nx (x + 0.5) + ny (y + 0.5) - c, 0, 1) */
} lm_dataset_sample_info;
lm_status lm_dataset_sample_info_get(const lm_dataset *d, lm_data_split split, long i,
                                     lm_dataset_sample_info *info, lm_err *err);

/* Cache counters: scene loads (file reads) so far, scenes cached now, most ever cached. */
typedef struct lm_dataset_stats {
    long loads;
    int cached, max_cached;
} lm_dataset_stats;
void lm_dataset_get_stats(lm_dataset *d, lm_dataset_stats *st);

#endif
