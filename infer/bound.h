/* bound.h — the spectral bound of a camera: how well the 31 bands 400..700 nm can be recovered
 * when every pixel's response to every LED is known (no mosaic: a demosaicing oracle), the
 * library half of `lumosaic bound`.
 * What it is: per pixel p, the LEDs' responses x_l(p) = a_l . r_p (data/system.h; the 31-band
 * cube mirrored to the system's 41 bins, as the forward model reads it), optionally with
 * Gaussian noise of sd k x the largest clean value of the coded frame (eval's convention), and
 * a per-pixel map from them to the 31 bands fitted in closed form (ridge regression, normal
 * equations in double) on training scenes, its ridge chosen on the validation scenes, and
 * scored on the test (or validation) scenes with data/metrics.h:
 *   linear:    31 x (LEDs + 1), the best linear spectral map (one per noise level: the
 *              per-pixel LMMSE estimate with perfect demosaicing);
 *   quadratic: the same plus the LEDs' pairwise products x_i x_j (i <= j), a nonlinear
 *              per-pixel prior fitted the same way.
 * No spatial context enters: a reconstruction that uses neighbouring pixels' spectra (texture,
 * materials) can exceed these figures, a demosaicing method with one LED per pixel cannot
 * exceed them with a per-pixel spectral map of the same form. Both buckets carry the same
 * per-pixel information (bucket 0 is a sum of the other LEDs' responses), so the bound is the
 * same for one and two buckets.
 * What it is not: a model that reads frames (it reads the ground truth), or training. */
#ifndef LM_BOUND_H
#define LM_BOUND_H
#include "data/cube.h"
#include "data/dataset.h"
#include "data/metrics.h"
#include "data/system.h"
#include "tensor/rng.h"

typedef enum lm_bound_map { LM_BOUND_LINEAR = 0, LM_BOUND_QUADRATIC = 1 } lm_bound_map;
#define LM_BOUND_MAPS 2
#define LM_BOUND_MAX_NOISE 16

/* "linear", "quadratic" */
const char *lm_bound_map_name(int map);
/* Features of a map for n LEDs: 1 + n, plus n (n + 1) / 2 products for the quadratic one. */
int lm_bound_features(int nleds, int map);

/* The normal equations of one map, and its solution. */
typedef struct lm_bound_fit {
    int map, nleds, nf;
    double *A;     /* nf x nf: sum of f f^T (lower triangle accumulated) */
    double *B;     /* nf x 31: sum of f y^T */
    double *W;     /* nf x 31 after lm_bound_solve */
    long pixels;   /* pixels accumulated */
} lm_bound_fit;

lm_status lm_bound_fit_init(lm_bound_fit *f, int nleds, int map, lm_err *err);
void lm_bound_fit_free(lm_bound_fit *f);

/* The LEDs' responses of a 31-band cube (400..700 nm, any size): *resp (malloc'ed) holds
 * nleds x H x W. k > 0 adds Gaussian noise of sd k x the largest clean value of the coded
 * frame (each pixel's own LED's response, the system's tile map), drawn from a copy of rng.
 * Errors: LM_ERR_SHAPE (not 31 bands at 400..700 nm, or a system grid other than 380/10/41),
 * LM_ERR_ARG (k < 0, or k > 0 without rng), LM_ERR_NOMEM; messages start with "bound:". */
lm_status lm_bound_responses(const lm_system *sys, const lm_cube *cube31, float k,
                             const lm_rng *rng, float **resp, lm_err *err);
/* Accumulate every pixel of a scene: resp (nleds x H x W, lm_bound_responses) against its
 * truth (31 x H x W, the same cube). */
void lm_bound_add(lm_bound_fit *f, const float *resp, const lm_cube *truth);
/* Solve (A + ridge x mean diagonal x I) W = B. LM_ERR_ARG when nothing was accumulated or
 * ridge < 0, LM_ERR_NUMERIC when the system is singular (raise the ridge). */
lm_status lm_bound_solve(lm_bound_fit *f, double ridge, lm_err *err);
/* out (31 x H x W) = the fitted map of resp. */
void lm_bound_predict(const lm_bound_fit *f, const float *resp, int H, int W, float *out);

/* A run over scenes: fit on the training split's scenes, choose each ridge on the validation
 * split's, score the chosen split. */
typedef struct lm_bound_run_opts {
    const char *const *data;    /* scenes or folders of scenes */
    int ndata;
    const char *system;         /* NULL = the bundled default system */
    const char *mat_key;        /* NULL = automatic */
    int split;                  /* the scored split: LM_SPLIT_TEST or LM_SPLIT_VAL */
    float k[LM_BOUND_MAX_NOISE];/* noise levels (fractions) */
    int nnoise;
    double ridge;               /* relative ridge (lm_bound_solve); < 0: each map's ridge is
                                 * the best of lm_bound_ridge_grid on the validation scenes */
    long long seed;
    /* One line of progress (no newline); NULL = none. */
    void (*log)(void *user, const char *line);
    void *user;
} lm_bound_run_opts;

#define LM_BOUND_RIDGES 7
extern const double lm_bound_ridge_grid[LM_BOUND_RIDGES]; /* 1e-9, 1e-8, ..., 1e-3 */

/* Defaults: split test, one level 0, ridge chosen on the validation scenes (-1), seed 1. */
void lm_bound_run_opts_default(lm_bound_run_opts *o);

/* One scored scene: its name (as lumosaic eval prints it) and metrics per map and level. */
typedef struct lm_bound_scene {
    char name[256];
    lm_metrics m[LM_BOUND_MAPS][LM_BOUND_MAX_NOISE];
} lm_bound_scene;

typedef struct lm_bound_result {
    int nleds, ntrain, nval, nscored;
    long train_pixels;
    lm_metrics m[LM_BOUND_MAPS][LM_BOUND_MAX_NOISE]; /* means over the scored scenes */
    double ridge[LM_BOUND_MAPS][LM_BOUND_MAX_NOISE]; /* the ridge of each map and level */
    lm_bound_scene *scene; /* nscored scenes, in the dataset's order (lm_bound_result_free) */
} lm_bound_result;

/* Free what lm_bound_run allocated in res (safe on a zeroed or already freed result). */
void lm_bound_result_free(lm_bound_result *res);

/* On success res holds the means and each scored scene's metrics (free with
 * lm_bound_result_free); on error nothing is left allocated.
 * Errors: those of the system, the scene listing and the reader ("<path>: ..."); LM_ERR_ARG
 * ("no training scenes among the N given", "no validation scenes ... (give --ridge)", "no
 * scene of split 'S' among the N given");
 * LM_ERR_NUMERIC from the solve. */
lm_status lm_bound_run(const lm_bound_run_opts *o, lm_bound_result *res, lm_err *err);

#endif
