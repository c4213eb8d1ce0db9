/* float_bits.h — bit-level float helpers of the elementwise kernels (activation.c,
 * gelu_fast.c): reinterpretation and a branch-free select. Private to the ops. */
#ifndef LM_OPS_FLOAT_BITS_H
#define LM_OPS_FLOAT_BITS_H
#include <stdint.h>
#include <string.h>

static inline int32_t f2i(float f)
{
    int32_t i;
    memcpy(&i, &f, sizeof i);
    return i;
}

static inline float i2f(int32_t i)
{
    float f;
    memcpy(&f, &i, sizeof f);
    return f;
}

/* cond ? a : b as a bitwise blend: both sides are always computed, so the compiler cannot
 * sink them into branches (float operations in a branch block if-conversion, i.e.
 * vectorisation, under the default -ftrapping-math). */
static inline float blend(int cond, float a, float b)
{
    int32_t m = -(int32_t)(cond != 0);
    return i2f((f2i(a) & m) | (f2i(b) & ~m));
}

#endif
