/* simd.h — GCC vector types (also clang's) shared by the CPU conv kernels (conv2d_direct.c,
 * conv2d_depthwise.c, conv2d_winograd.c, sgemm_panel.c): a native-width float vector (16 lanes
 * with AVX-512, else 8) for kernels that only need "as wide as the machine", and a fixed 8-lane
 * one for kernels whose data layout is built around 8 lanes (Winograd tile groups, the 6 x 16
 * panel tile). Unaligned loads and stores go through memcpy (one vmovups). Private to the ops. */
#ifndef LM_OPS_SIMD_H
#define LM_OPS_SIMD_H
#include <stddef.h>
#include <string.h>

#if defined(__AVX512F__)
#define LM_VLN 16
#else
#define LM_VLN 8
#endif
typedef float lm_vfn __attribute__((vector_size(LM_VLN * sizeof(float))));
typedef float lm_vf8 __attribute__((vector_size(8 * sizeof(float))));
typedef int lm_vi8 __attribute__((vector_size(8 * sizeof(int))));

/* Lanes of a and b (0..7 from a, 8..15 from b) picked by eight constant indices (the
 * variadic part; it may be a macro naming them): GCC's __builtin_shuffle takes a mask vector,
 * clang (the fuzz build) has __builtin_shufflevector; both compile to the same permutes. */
#if defined(__clang__)
#define LM_SHUFFLE8(a, b, ...) __builtin_shufflevector(a, b, __VA_ARGS__)
#else
#define LM_SHUFFLE8(a, b, ...) __builtin_shuffle(a, b, (lm_vi8){__VA_ARGS__})
#endif

/* All 8 lanes = x (one broadcast; (lm_vf8){0} + x would add first: -0 + x is not x). */
#define LM_SPLAT8(x) ((lm_vf8){(x), (x), (x), (x), (x), (x), (x), (x)})

static inline lm_vfn lm_loadn(const float *p)
{
    lm_vfn v;
    memcpy(&v, p, sizeof v);
    return v;
}

/* p[0, n) = the first n lanes of v (n <= LM_VLN). */
static inline void lm_storen(float *p, lm_vfn v, int n)
{
    if (n == LM_VLN) {
        memcpy(p, &v, sizeof v);
    } else {
        float t[LM_VLN];
        memcpy(t, &v, sizeof v);
        memcpy(p, t, sizeof(float) * (size_t)n);
    }
}

static inline lm_vf8 lm_load8(const float *p)
{
    lm_vf8 v;
    memcpy(&v, p, sizeof v);
    return v;
}

static inline void lm_store8(float *p, lm_vf8 v) { memcpy(p, &v, sizeof v); }

#endif
