/* cmd_version.c — `lumosaic version`: version and build configuration. */
#include <stdio.h>
#include <string.h>
#include "cli/commands.h"
#include "tensor/isa.h"

#ifndef LM_VERSION
#define LM_VERSION "unknown"
#endif

extern char *openblas_get_config(void);

int lm_cmd_version(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            printf("usage: lumosaic version\n\nPrint the version and build configuration: the "
                   "instruction set the CPU kernels\nuse and why (LM_ISA=generic|avx2|avx512|amx "
                   "chooses a lower one), the CPU, the\nmatrix units, OpenMP and BLAS.\n");
            return 0;
        }
        fprintf(stderr, "lumosaic version: unknown option '%s'\n", argv[i]);
        return 2;
    }
    printf("lumosaic %s\n", LM_VERSION);
    char isa[256];
    lm_isa_describe(isa, sizeof isa);
    printf("isa %s\n", isa);
    const lm_cpu_features *f = lm_cpu_features_get();
    if (f->x86)
        printf("cpu %s (%s): avx2+fma %s, avx512 %s, avx512-bf16 %s, amx-bf16 %s\n",
               f->brand[0] ? f->brand : "unknown", f->vendor, f->avx2_fma ? "yes" : "no",
               f->avx512 ? "yes" : "no", f->avx512_bf16 ? "yes" : "no",
               f->amx_bf16 ? "yes" : "no");
#if defined(__AVX512F__)
    printf("build -march with AVX-512 (LM_NATIVE): runs only on CPUs like the one that built it\n");
#elif defined(__AVX2__)
    printf("build -march with AVX2 (LM_NATIVE): runs only on CPUs like the one that built it\n");
#else
    printf("build portable: the baseline instruction set, kernels chosen at run time\n");
#endif
#ifdef _OPENMP
    printf("openmp %d\n", _OPENMP);
#endif
    printf("blas %s\n", openblas_get_config());
    return 0;
}
