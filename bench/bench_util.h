/* bench_util.h — timing helpers shared by the benchmarks: a monotonic clock and the minimum /
 * median of repeated timings (this VM loses CPU to its host at times, so benchmarks report
 * both, never one timing). */
#ifndef LM_BENCH_UTIL_H
#define LM_BENCH_UTIL_H
#include <stdlib.h>
#include <string.h>
#include <time.h>

static inline double bench_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static inline int bench_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static inline double bench_min(const double *v, int n)
{
    double m = v[0];
    for (int i = 1; i < n; i++) m = v[i] < m ? v[i] : m;
    return m;
}

/* Median of n values (n <= 256); v is not modified. */
static inline double bench_median(const double *v, int n)
{
    double s[256];
    if (n > 256) n = 256;
    memcpy(s, v, sizeof(double) * (size_t)n);
    qsort(s, (size_t)n, sizeof(double), bench_cmp_double);
    return n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

#endif
