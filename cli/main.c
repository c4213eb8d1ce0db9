/* main.c — the `lumosaic` program: subcommand dispatch and top-level help.
 * Each subcommand is one cli/cmd_*.c file registered in the table below. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "cli/commands.h"
#include "tensor/isa.h"

static const lm_command commands[] = {
    {"version", lm_cmd_version, "print the version and build configuration"},
    /* one line per command (keep alphabetical after version) */
    {"average", lm_cmd_average, "average the weights of trained models of one preset (a soup)"},
    {"bound", lm_cmd_bound, "the spectral bound: every LED at every pixel, no mosaic (oracle)"},
    {"calibrate", lm_cmd_calibrate, "LED gains from ColorChecker frames (NNLS): a new system file"},
    {"coding", lm_cmd_coding, "learn the LED allocation and tile map under shot/read noise"},
    {"convert", lm_cmd_convert, "store a trained model as fp16 (half the file) or fp32"},
    {"eval", lm_cmd_eval, "score a trained model: PSNR/SSIM/MAE/SAM vs noise, rainbow test"},
    {"fit-auto", lm_cmd_fit_auto, "fit infer --model auto: error vs difficulty, cost per model"},
    {"infer", lm_cmd_infer, "reconstruct 31-band cubes from coded frames with a trained model"},
    {"info", lm_cmd_info, "layer table of a model (shapes, parameters, MACs), presets, system"},
    {"render", lm_cmd_render, "render a spectral cube as an sRGB PNG (D65, CIE 1931)"},
    {"report", lm_cmd_report, "one offline HTML page of an infer or eval output: previews, plots"},
    {"simulate", lm_cmd_simulate, "simulate coded frames (static or video) from a spectral cube"},
    {"study", lm_cmd_study, "speed against accuracy: train, score and time presets; charts"},
    {"train", lm_cmd_train, "train a network (config/flags, checkpoints, --resume)"},
};
#define NCOMMANDS (int)(sizeof commands / sizeof commands[0])

static void usage(FILE *f)
{
    fprintf(f, "usage: lumosaic <command> [options]\n\n"
               "Coded-exposure frames to 31-band hyperspectral video (400-700 nm).\n\n"
               "commands:\n");
    for (int i = 0; i < NCOMMANDS; i++)
        fprintf(f, "  %-10s %s\n", commands[i].name, commands[i].summary);
    fprintf(f, "  %-10s %s\n", "help", "show this help (also --help, -h)");
    fprintf(f, "\nRun 'lumosaic <command> --help' for a command's options.\n");
}

/* How OpenMP threads wait. libgomp's default spins ~300,000 times at each
 * barrier before it sleeps: on a machine where another process holds a core, the spinning
 * threads take turns with the one that does the work, and a training step of han-tiny / mcan /
 * srnet on 2 threads took 2.6-3.7x its quiet time (median; passive waiting: 1.8-1.9x). Spinning
 * 1,000 times, then sleeping, costs 5-12 % when the machine is quiet and keeps the busy case
 * within 3-9 % of passive waiting (bench_train, docs/guide/performance.md). libgomp reads the
 * setting when it loads, before main, so for the commands that compute (train, infer, eval, study,
 * simulate, fit-auto) the program sets GOMP_SPINCOUNT=1000 and runs itself again once (~0.2 s
 * of start-up), unless the user chose a policy (OMP_WAIT_POLICY or GOMP_SPINCOUNT set) or
 * LM_KEEP_OMP_WAIT=1. */
static void omp_wait_policy(int argc, char **argv)
{
    static const char *const heavy[] = {"train", "infer", "eval", "study", "simulate", "fit-auto",
                                        "coding", NULL}; /* the commands whose work is parallel */
    int compute = 0;
    for (int i = 0; argc > 1 && heavy[i]; i++) compute |= !strcmp(argv[1], heavy[i]);
    if (!compute || getenv("OMP_WAIT_POLICY") || getenv("GOMP_SPINCOUNT") ||
        getenv("LM_KEEP_OMP_WAIT"))
        return;
    if (setenv("GOMP_SPINCOUNT", "1000", 1) != 0) return;
    execv("/proc/self/exe", argv); /* returns only on failure: go on with the default */
    unsetenv("GOMP_SPINCOUNT");
}

int main(int argc, char **argv)
{
    omp_wait_policy(argc, argv);
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    const char *cmd = argv[1];
    if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(cmd, "--version")) cmd = "version";
    char msg[200]; /* the kernels' instruction set, once, before any command computes */
    if (lm_isa_init(msg, sizeof msg) != LM_OK) {
        fprintf(stderr, "lumosaic: %s\n", msg);
        return 2;
    }
    for (int i = 0; i < NCOMMANDS; i++)
        if (!strcmp(cmd, commands[i].name)) return commands[i].run(argc - 1, argv + 1);
    fprintf(stderr, "lumosaic: unknown command '%s' (see 'lumosaic --help')\n", cmd);
    return 2;
}
