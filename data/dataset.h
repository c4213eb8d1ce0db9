/* dataset.h — training/validation/test samples simulated on the fly (system.md §4, §7).
 *
 * What it is: a folder (or list) of scenes in mixed formats (CAVE folders, ARAD/KAUST .mat,
 * spectral EXR), split 80/10/10 by scene deterministically (by a hash of the scene's name, so
 * adding a scene does not reshuffle the others), loaded lazily into a bounded cache. A sample is
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
#include "data/system.h"

typedef enum lm_split { LM_SPLIT_TRAIN = 0, LM_SPLIT_VAL = 1, LM_SPLIT_TEST = 2 } lm_split;

typedef struct lm_dataset_cfg {
    const char *const *paths;   /* scene files/folders, or folders of scenes */
    int npaths;
    const lm_system *sys;       /* forward model (not owned) */
    int patch_h, patch_w;       /* multiples of the tile (default 66 x 64) */
    float synth_fraction;       /* in [0, 1]: share of synthetic samples (paper: 0.33) */
    float noise_min, noise_max; /* Gaussian noise k ~ U[min, max] x max clean value (0, 0.15) */
    int flips;                  /* random horizontal/vertical flips (training split only) */
    uint64_t seed;
    int workers;                /* threads preparing batches ahead (0 = synchronous) */
    int cache_scenes;           /* scenes kept in memory (LRU); 0 = all */
    int val_patches;            /* fixed validation/test samples per split (default 64) */
    float val_noise;            /* noise level k of validation/test samples (default 0) */
} lm_dataset_cfg;

typedef struct lm_dataset lm_dataset;

/* Defaults of system.md: 66 x 64, synth 0.33, noise U[0, 0.15], flips on, 2 workers. */
void lm_dataset_default_cfg(lm_dataset_cfg *cfg);
/* Lists and checks the scenes (reads headers, not pixels). Errors name the file. A split with
 * no scene borrows from the others only if fewer than 3 scenes exist (documented in the
 * message printed by lm_dataset_describe). */
lm_dataset *lm_dataset_open(const lm_dataset_cfg *cfg, lm_err *err);
void lm_dataset_close(lm_dataset *d);
int lm_dataset_num_scenes(const lm_dataset *d, lm_split split);
/* Training batch number `index` (0-based): raw is B x 1 x ph x pw (coded patches, bucket 1),
 * target B x 33 x ph x pw; host buffers owned by the caller. Same index, same numbers. */
lm_status lm_dataset_batch(lm_dataset *d, long index, int batch, float *raw, float *target,
                           lm_err *err);
/* Fixed validation/test sample i (0 <= i < val_patches), same layout as one batch item. */
lm_status lm_dataset_eval_sample(lm_dataset *d, lm_split split, int i, float *raw, float *target,
                                 lm_err *err);
int lm_dataset_eval_count(const lm_dataset *d, lm_split split);
void lm_dataset_describe(const lm_dataset *d, FILE *f);

#endif
