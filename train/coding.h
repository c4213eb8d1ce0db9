/* coding.h — learned coding: the sub-frame allocation and the tile map of the
 * imaging system chosen jointly with the closed-form linear reconstruction (the lmmse floor), under
 * a physical noise model.
 *
 * Why a physical noise model: with the paper's noise (sigma = k x the frame's maximum) and
 * equal-white gains the allocation drops out (every LED's white response is normalised to 1).
 * Here the LEDs' powers are fixed and the allocation sets how much light each phase collects:
 * LED l's response is s_l = n_l / n_l^paper times its paper response (the paper's allocation is
 * taken to be what makes every LED's white response equal, so its implied powers are the
 * paper's equal-white gains), under the budget sum n_l = the paper's total (158 sub-frames).
 * Noise, in units of the paper's white response: shot noise with `photons` photo-electrons at
 * white (Poisson: variance v / photons) and read noise of `read_noise` electrons (variance
 * (read_noise / photons)^2), as `simulate --poisson P --read-noise E` draws it.
 *
 * What it is:
 *  - scene data: each scene's per-LED images U_l = a_l . r (the paper system's responses, 41
 *    bins mirrored from 31) and its 31 bands, scenes divided by their maximum as the dataset
 *    does, split train/val/test by the dataset's rule;
 *  - stationary statistics of the training scenes (a scene's second-order statistics do not
 *    depend on which tile phase a pixel has): R_lm(D) = E[U_l(x) U_m(x + D)] for every offset
 *    D of two pixels of a K x K window, Q_lc(d) = E[U_l(x + d) y_c(x)], means; by FFT
 *    (FFTW). E is one empirical distribution: window centres x over each scene grown by K/2
 *    on every side, the scene zero outside (so every sum is a full correlation, and the
 *    objective is the exact training error of that distribution: a per-lag normalisation
 *    instead is not positive semi-definite, and the map search found codings that exploited
 *    it: +2 dB by the proxy, +0.01 dB by the exact fit);
 *  - the objective: for a coding (tile map, allocation), the mean squared error per band of
 *    the best linear estimator (per tile phase, a K x K window + bias -> 31 bands, ridge
 *    regularised) under the noise, averaged over the phases: L = E|y|^2 - tr(B^T (A + ridge)^-1 B)
 *    per phase, with A, B built from R, Q and the noise; and its exact gradient in the
 *    allocation (so the reconstruction is the inner problem solved in closed form, and the
 *    coding is optimised through it);
 *  - the allocation search: n = total x softmax(theta), Adam on theta with the analytic
 *    gradient, then integers (largest remainders, each LED >= 1) and single-sub-frame moves
 *    while one improves L (the "short fine-tune" of the rounding);
 *  - the tile map search: simulated annealing over swaps of two phases' LEDs at the current
 *    allocation, each candidate scored by L (milliseconds each), then the allocation
 *    re-optimised for the best map;
 *  - validation on real scenes: per tile phase, the lmmse filters fitted exactly on the training
 *    scenes' coded frames (normal equations over every interior pixel, the noise's covariance
 *    added analytically: exact for zero-mean noise), then applied to the validation and test
 *    scenes' frames with noise drawn as `simulate` draws it (Poisson + Gaussian read noise),
 *    PSNR over the 31 bands and the interior pixels (the window inside the scene), per scene.
 *
 * What it is not: a nonlinear network trained through the forward model (the reconstruction
 * here is the closed-form floor; a network on top of a learned system trains with `train
 * --system`), a search over LED spectra, or a model of the LEDs' thermal limits. */
#ifndef LM_CODING_H
#define LM_CODING_H
#include "data/system.h"
#include "tensor/status.h"

#define LM_CODING_BANDS 31

typedef struct lm_coding_scene {
    char name[256];
    int split;        /* LM_SPLIT_TRAIN / VAL / TEST */
    int height, width;
    float *u;         /* nleds x H x W: per-LED images (paper responses) */
    float *y;         /* 31 x H x W: the bands, scene divided by its maximum */
} lm_coding_scene;

typedef struct lm_coding_data {
    int nleds;
    lm_coding_scene *scenes;
    int nscenes;
} lm_coding_data;

typedef struct lm_coding_noise {
    double photons;    /* photo-electrons at the paper's white response (> 0) */
    double read_noise; /* electrons (>= 0) */
} lm_coding_noise;

/* A coding: the tile map (LED index per phase) and the sub-frames per LED (continuous while
 * optimising, integers in a system). */
typedef struct lm_coding {
    int rows, cols;
    int tile_led[LM_SYSTEM_MAX_TILE];
    double subframes[LM_SYSTEM_MAX_LEDS];
} lm_coding;

typedef struct lm_coding_stats {
    int K, nleds, D;   /* window, LEDs, offsets per axis (2K - 1) */
    double *R;         /* D x D x L x L: R[(dy, dx)][l][m] = E[U_l(x) U_m(x + (dy, dx))] */
    double *Q;         /* K x K x L x 31: E[U_l(x + d) y_c(x)], d in [-K/2, K/2]^2 */
    double mu[LM_SYSTEM_MAX_LEDS]; /* E[U_l] */
    double ybar[LM_CODING_BANDS];  /* E[y_c] */
    double yy;         /* E[sum_c y_c^2] */
    double ridge;      /* added to the window diagonal (absolute) */
    double pixels;     /* pixels the means are over */
} lm_coding_stats;

/* The coding of a system (its tile map and allocation). */
void lm_coding_from_system(const lm_system *sys, lm_coding *c);

/* Scenes of the DATA paths (every split), per-LED images under sys (the paper system: its
 * responses define the units). Errors name the file. */
lm_status lm_coding_data_load(const char *const *paths, int npaths, const lm_system *sys,
                              lm_coding_data *d, lm_err *err);
void lm_coding_data_free(lm_coding_data *d);

/* Stationary statistics of the training scenes, window K (odd, 3..15). */
lm_status lm_coding_stats_compute(const lm_coding_data *d, int K, lm_coding_stats *st,
                                  lm_err *err);
void lm_coding_stats_free(lm_coding_stats *st);

/* The objective L (mean squared error per band, averaged over the tile phases) of coding c;
 * paper: the paper's sub-frames per LED (s_l = c->subframes[l] / paper[l]). grad (NULL to
 * skip): dL/d subframes[l], nleds values. Returns L, or a negative value if a system was not
 * positive definite. */
double lm_coding_objective(const lm_coding_stats *st, const lm_coding *c, const double *paper,
                           const lm_coding_noise *nz, double *grad);

typedef struct lm_coding_search_opts {
    int adam_steps;      /* allocation: Adam steps on the softmax logits (default 300) */
    double adam_lr;      /* (default 0.05) */
    int anneal_steps;    /* tile map: annealing swaps per round (default 1500; 0 = no map search) */
    int rounds;          /* map, then allocation, rounds (default 2) */
    uint64_t seed;
    int verbose;         /* progress lines on stderr */
} lm_coding_search_opts;
void lm_coding_search_default_opts(lm_coding_search_opts *o);

/* Optimise c's allocation (integers summing to the paper's total, each >= 1) for L. */
lm_status lm_coding_optimise_allocation(const lm_coding_stats *st, lm_coding *c,
                                        const double *paper, const lm_coding_noise *nz,
                                        const lm_coding_search_opts *o, lm_err *err);
/* Optimise c's tile map (swaps of two phases' LEDs, annealed) and then its allocation, for
 * o->rounds rounds. */
lm_status lm_coding_optimise_map(const lm_coding_stats *st, lm_coding *c, const double *paper,
                                 const lm_coding_noise *nz, const lm_coding_search_opts *o,
                                 lm_err *err);

/* Real-scene validation: filters fitted exactly on the training scenes' frames of coding c,
 * scored on each validation and test scene with drawn noise (seed). psnr[i] per scene of d
 * (NaN for training scenes); *val, *test the means over those splits; *fit_mse (NULL to skip)
 * the fit's expected error per band on its own training pixels (noise included: the exact
 * counterpart of lm_coding_objective's stationary one). */
lm_status lm_coding_validate(const lm_coding_data *d, int K, const lm_coding *c,
                             const double *paper, const lm_coding_noise *nz, uint64_t seed,
                             double *psnr, double *val, double *test, double *fit_mse,
                             lm_err *err);

/* Write sys with coding c (sub-frames, explicit gains = sys's resolved gains, i.e. the LED
 * powers the paper's allocation implies, tile map) as a system JSON at out_path (atomic; the
 * result is loaded back as a check). note goes into "description". */
lm_status lm_coding_write_system(const lm_system *sys, const lm_coding *c, const char *name,
                                 const char *note, const char *out_path, lm_err *err);

#endif
