/* cmd_version.c — `lumosaic version`: version and build configuration. */
#include <stdio.h>
#include <string.h>
#include "cli/commands.h"

#ifndef LM_VERSION
#define LM_VERSION "unknown"
#endif

extern char *openblas_get_config(void);

int lm_cmd_version(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            printf("usage: lumosaic version\n\nPrint the version and build configuration.\n");
            return 0;
        }
        fprintf(stderr, "lumosaic version: unknown option '%s'\n", argv[i]);
        return 2;
    }
    printf("lumosaic %s\n", LM_VERSION);
#ifdef _OPENMP
    printf("openmp %d\n", _OPENMP);
#endif
    printf("blas %s\n", openblas_get_config());
    return 0;
}
