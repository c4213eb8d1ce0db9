/* main.c — the `lumosaic` program: subcommand dispatch and top-level help.
 * Each subcommand is one cli/cmd_*.c file registered in the table below. */
#include <stdio.h>
#include <string.h>
#include "cli/commands.h"

static const lm_command commands[] = {
    {"version", lm_cmd_version, "print the version and build configuration"},
    /* one line per command (keep alphabetical after version) */
    {"calibrate", lm_cmd_calibrate, "LED gains from ColorChecker frames (NNLS): a new system file"},
    {"eval", lm_cmd_eval, "score a trained model: PSNR/SSIM/MAE/SAM vs noise, rainbow test"},
    {"fit-auto", lm_cmd_fit_auto, "fit infer --model auto: error vs difficulty, cost per model"},
    {"infer", lm_cmd_infer, "reconstruct 31-band cubes from coded frames with a trained model"},
    {"info", lm_cmd_info, "layer table of a model (shapes, parameters, MACs), presets, system"},
    {"render", lm_cmd_render, "render a spectral cube as an sRGB PNG (D65, CIE 1931)"},
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
    if (!strcmp(cmd, "--version")) cmd = "version";
    for (int i = 0; i < NCOMMANDS; i++)
        if (!strcmp(cmd, commands[i].name)) return commands[i].run(argc - 1, argv + 1);
    fprintf(stderr, "lumosaic: unknown command '%s' (see 'lumosaic --help')\n", cmd);
    return 2;
}
