/* main.c — the `lumosaic` program: subcommand dispatch, --help, version.
 * Subcommands land here as their issues are built (simulate, train, infer, eval, info). */
#include <stdio.h>
#include <string.h>

#ifndef LM_VERSION
#define LM_VERSION "unknown"
#endif

static void usage(FILE *f)
{
    fprintf(f,
            "usage: lumosaic <command> [options]\n"
            "\n"
            "Coded-exposure frames to 31-band hyperspectral video (400-700 nm).\n"
            "\n"
            "commands:\n"
            "  version      print the version and build configuration\n"
            "  help         show this help (also --help, -h)\n"
            "\n"
            "Run 'lumosaic <command> --help' for a command's options.\n");
}

extern char *openblas_get_config(void);

static int cmd_version(int argc, char **argv)
{
    for (int i = 2; i < argc; i++) {
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

int main(int argc, char **argv)
{
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    const char *cmd = argv[1];
    if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(cmd, "version") || !strcmp(cmd, "--version")) return cmd_version(argc, argv);
    fprintf(stderr, "lumosaic: unknown command '%s' (see 'lumosaic --help')\n", cmd);
    return 2;
}
