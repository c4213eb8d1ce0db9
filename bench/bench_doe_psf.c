/* bench_doe_psf.c — time of the differentiable PSF (data/doe_psf.c): nb PSFs forward and
 * backward (random output weights) of a DOE file (default: the bundled one, grid 1536), in
 * chunks of `chunk` wavelengths per tape, with peak RSS. Usage:
 *   bench_doe_psf [--doe FILE] [--threads T] [--bands NB] [--chunk K] [--reps R] */
#include "autograd/autograd.h"
#include "data/doe.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char **argv)
{
    const char *file = NULL;
    int threads = 1, nb = 31, chunk = 31, reps = 2;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--doe")) file = argv[i + 1];
        else if (!strcmp(argv[i], "--threads")) threads = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--bands")) nb = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--chunk")) chunk = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--reps")) reps = atoi(argv[i + 1]);
    }
    lm_doe d;
    lm_err e = {0};
    if ((file ? lm_doe_load(file, &d, &e) : lm_doe_default(&d, &e)) != LM_OK) {
        fprintf(stderr, "bench_doe_psf: %s\n", e.msg);
        return 1;
    }
    lm_ctx c;
    lm_ctx_init(&c, threads);
    lm_rng r;
    lm_rng_seed(&r, 1);
    double best = 1e30;
    for (int rep = 0; rep < reps; rep++) {
        double t0 = now();
        for (int b0 = 0; b0 < nb; b0 += chunk) {
            int k = nb - b0 < chunk ? nb - b0 : chunk;
            double lam[64];
            for (int b = 0; b < k; b++) lam[b] = (400.0 + 300.0 * (b0 + b) / (nb > 1 ? nb - 1 : 1)) * 1e-9;
            lm_tensor *t = lm_doe_height_t(&c, &d);
            lm_tensor_set_requires_grad(t, 1);
            lm_tensor *P = lm_doe_psf_t(&c, &d, t, lam, k);
            lm_tensor *w = P ? lm_tensor_uniform(&c, 3, P->shape, &r, -1, 1) : NULL;
            if (!P || lm_backward(&c, P, w) != LM_OK) {
                fprintf(stderr, "bench_doe_psf: %s\n", lm_ctx_message(&c));
                return 1;
            }
            lm_ctx_reset(&c);
        }
        double dt = now() - t0;
        best = dt < best ? dt : best;
    }
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    printf("doe %s: grid %d, m %d, %d PSFs forward+backward in chunks of %d, %d thread(s): "
           "best %.2f s of %d, peak RSS %ld MB\n", d.name, d.grid, d.m, nb, chunk, threads, best,
           reps, ru.ru_maxrss / 1024);
    lm_ctx_free(&c);
    lm_doe_free(&d);
    return 0;
}
