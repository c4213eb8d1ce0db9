/* rng.h — seeded random number generator with explicit state (xoshiro256**).
 * What it is: a small, fast, reproducible generator; the state is a plain struct that can be
 * copied, saved in checkpoints and split into independent streams.
 * What it is not: cryptographic. Nothing in Lumosaic calls rand(). */
#ifndef LM_RNG_H
#define LM_RNG_H
#include <stdint.h>

typedef struct lm_rng {
    uint64_t s[4];
    int has_spare;   /* Box-Muller keeps its second normal here so draws are reproducible */
    float spare;
} lm_rng;

void lm_rng_seed(lm_rng *r, uint64_t seed);
/* An independent stream derived from (seed of r, stream id): for per-thread / per-sample use.
 * Does not advance r. */
lm_rng lm_rng_split(const lm_rng *r, uint64_t stream);
uint64_t lm_rng_u64(lm_rng *r);
uint32_t lm_rng_u32(lm_rng *r);
/* Uniform integer in [0, n), n > 0, without modulo bias. */
uint32_t lm_rng_below(lm_rng *r, uint32_t n);
/* Uniform float in [0, 1) with 24 random bits. */
float lm_rng_uniform(lm_rng *r);
/* Uniform float in [lo, hi). */
float lm_rng_uniform_range(lm_rng *r, float lo, float hi);
/* Standard normal N(0, 1). */
float lm_rng_normal(lm_rng *r);
void lm_rng_fill_uniform(lm_rng *r, float *x, long n, float lo, float hi);
void lm_rng_fill_normal(lm_rng *r, float *x, long n, float mean, float std);

#endif
