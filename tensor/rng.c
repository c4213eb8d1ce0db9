/* rng.c — xoshiro256** seeded by splitmix64; Box-Muller normals. */
#include "tensor/rng.h"
#include <math.h>

static uint64_t splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

void lm_rng_seed(lm_rng *r, uint64_t seed)
{
    uint64_t x = seed;
    for (int i = 0; i < 4; i++) r->s[i] = splitmix64(&x);
    r->has_spare = 0;
    r->spare = 0.0f;
}

lm_rng lm_rng_split(const lm_rng *r, uint64_t stream)
{
    lm_rng out;
    uint64_t x = r->s[0] ^ rotl(r->s[1], 17) ^ rotl(r->s[2], 31) ^ rotl(r->s[3], 47);
    x ^= splitmix64(&stream);
    lm_rng_seed(&out, x);
    return out;
}

uint64_t lm_rng_u64(lm_rng *r)
{
    uint64_t *s = r->s;
    uint64_t result = rotl(s[1] * 5, 7) * 9;
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

uint32_t lm_rng_u32(lm_rng *r) { return (uint32_t)(lm_rng_u64(r) >> 32); }

uint32_t lm_rng_below(lm_rng *r, uint32_t n)
{
    uint32_t limit = (uint32_t)(-n) % n; /* values below this would bias */
    for (;;) {
        uint32_t v = lm_rng_u32(r);
        if (v >= limit) return v % n;
    }
}

float lm_rng_uniform(lm_rng *r) { return (float)(lm_rng_u64(r) >> 40) * (1.0f / 16777216.0f); }

float lm_rng_uniform_range(lm_rng *r, float lo, float hi) { return lo + (hi - lo) * lm_rng_uniform(r); }

float lm_rng_normal(lm_rng *r)
{
    if (r->has_spare) {
        r->has_spare = 0;
        return r->spare;
    }
    double u1, u2;
    do {
        u1 = (double)(lm_rng_u64(r) >> 11) * (1.0 / 9007199254740992.0);
    } while (u1 <= 0.0);
    u2 = (double)(lm_rng_u64(r) >> 11) * (1.0 / 9007199254740992.0);
    double rad = sqrt(-2.0 * log(u1));
    double th = 6.283185307179586 * u2;
    r->spare = (float)(rad * sin(th));
    r->has_spare = 1;
    return (float)(rad * cos(th));
}

void lm_rng_fill_uniform(lm_rng *r, float *x, long n, float lo, float hi)
{
    for (long i = 0; i < n; i++) x[i] = lm_rng_uniform_range(r, lo, hi);
}

void lm_rng_fill_normal(lm_rng *r, float *x, long n, float mean, float std)
{
    for (long i = 0; i < n; i++) x[i] = mean + std * lm_rng_normal(r);
}
