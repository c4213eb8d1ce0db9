/* cmd_info.c — `lumosaic info`: a model's layer table (name, output shape, parameters,
 * multiply-adds) from a dry-run forward that executes no kernel, the list of presets, or a
 * system description's or a DOE description's (QDO baseline optics) summary.
 * What it is not: a benchmark (bench/bench_train). */
#include <stdio.h>
#include <string.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/spectra.h"
#include "models/profile.h"
#include "data/mosaic.h"
#include "data/doe.h"
#include "data/system.h"

static void help(void)
{
    printf("usage: lumosaic info --model NAME [--batch B] [--height H] [--width W] [--csv]\n"
           "       lumosaic info --list\n"
           "       lumosaic info --system FILE\n"
           "       lumosaic info --doe FILE|default\n\n"
           "Describe a model: every conv / transposed conv / linear layer with its output shape,\n"
           "parameters and multiply-accumulates (MACs) for a B x 1 x H x W coded input, and the\n"
           "totals. Nothing is computed: the forward runs on a dry-run backend.\n"
           "MACs count conv/linear layers only (attention matmuls, HAN's CSAM Conv3d and MCAN's\n"
           "fixed bilinear/mosaic convolutions are not counted), as the paper counts them.\n\n"
           "  --model NAME   preset (see --list), or NET+BASE: NET as a residual on BASE\n"
           "  --batch B      batch size (default 1)\n"
           "  --height H     input rows, a multiple of the tile rows (default 66)\n"
           "  --width W      input columns, a multiple of the tile columns (default 64)\n"
           "  --system FILE  system description (default: bundled); alone: print its summary\n"
           "  --doe FILE     a DOE description (QDO baseline optics; 'default' = bundled): its\n"
           "                 summary and PSF figures at 400..700 nm\n"
           "  --csv          machine-readable table (layer,kind,shape,params,macs)\n"
           "  --list         list the model presets, each with what it is for\n"
           "  --help         this text\n");
}

typedef struct info_args {
    const char *model, *system, *doe;
    long long batch, height, width;
    int csv, list;
} info_args;

static int parse(lm_cli *c, info_args *a)
{
    *a = (info_args){.batch = 1, .height = 66, .width = 64};
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--model", &a->model)) ||
            (r = lm_cli_value(c, "--system", &a->system)) ||
            (r = lm_cli_value(c, "--doe", &a->doe)) ||
            (r = lm_cli_int(c, "--batch", 1, 1 << 20, &a->batch)) ||
            (r = lm_cli_int(c, "--height", 1, 1 << 16, &a->height)) ||
            (r = lm_cli_int(c, "--width", 1, 1 << 16, &a->width)) ||
            (r = lm_cli_flag(c, "--csv", &a->csv)) || (r = lm_cli_flag(c, "--list", &a->list))) {
            if (r < 0) return 2;
            continue;
        }
        return lm_cli_unknown(c);
    }
    if (!a->model && !a->list && !a->system && !a->doe)
        return lm_cli_error(c, "--model, --list, --system or --doe is required (see 'lumosaic info "
                            "--help')");
    return 1;
}

static const char *human(double v, char *buf, size_t n)
{
    const char *u[] = {"", "K", "M", "G", "T", "P"};
    int i = 0;
    while (v >= 1000 && i < 5) v /= 1000, i++;
    snprintf(buf, n, i ? "%.3f %s" : "%.0f %s", v, u[i]);
    return buf;
}

static void print_table(const lm_profile *p, const char *model, const info_args *a)
{
    char sh[64], hm[32], hp[32];
    if (!a->csv)
        printf("model %s, input %lldx1x%lldx%lld\n\n%-44s %-6s %-18s %12s %14s\n", model,
               a->batch, a->height, a->width, "layer", "kind", "output", "params", "MACs");
    else
        printf("layer,kind,shape,params,macs\n");
    for (int i = 0; i < p->n; i++) {
        const lm_layer_stat *s = &p->layers[i];
        size_t o = 0;
        for (int d = 0; d < s->ndim; d++)
            o += (size_t)snprintf(sh + o, sizeof sh - o, d ? "x%d" : "%d", s->shape[d]);
        if (a->csv) printf("%s,%s,%s,%ld,%.0f\n", s->name, s->kind, sh, s->params, s->macs);
        else printf("%-44s %-6s %-18s %12ld %14s\n", s->name, s->kind, sh, s->params,
                    human(s->macs, hm, sizeof hm));
    }
    if (a->csv) return;
    printf("\nlayers: %d   layer parameters: %ld   model parameters: %ld (%ld trainable)\n", p->n,
           p->layer_params, p->model_params, p->trainable_params);
    printf("total MACs: %sMAC (%.0f)   per sample: %sMAC\n", human(p->total_macs, hm, sizeof hm),
           p->total_macs, human(p->total_macs / (double)a->batch, hp, sizeof hp));
}

static int load_system(lm_cli *c, const char *path, lm_system *sys)
{
    lm_err e = {0};
    lm_status st = path ? lm_system_load(path, sys, &e) : lm_system_default(sys, &e);
    if (st) {
        lm_system_free(sys);
        lm_cli_error(c, "%s", e.msg);
        return lm_cli_exit_status(st);
    }
    return 0;
}

static int describe_doe(lm_cli *c, const char *path)
{
    lm_err e = {0};
    lm_doe d;
    lm_status st = strcmp(path, "default") ? lm_doe_load(path, &d, &e) : lm_doe_default(&d, &e);
    if (!st) st = lm_doe_describe(&d, stdout, &e);
    lm_doe_free(&d);
    if (!st) return 0;
    lm_cli_error(c, "%s", e.msg);
    return lm_cli_exit_status(st);
}

int lm_cmd_info(int argc, char **argv)
{
    lm_cli c;
    info_args a;
    lm_cli_init(&c, "lumosaic info", argc, argv);
    int r = parse(&c, &a);
    if (r != 1) return r;
    if (a.doe) return describe_doe(&c, a.doe);
    if (a.list) {
        for (const char *const *p = lm_model_presets(); *p; p++)
            printf("%-15s %s\n", *p, lm_model_preset_purpose(*p));
        printf("\nalso: lmmse-K (window K, odd 1..31), lmmse-K-b2, lmmse-K-rfD (D random "
               "features),\nlmmse-K-gG-b2 (the panchromatic guide over G x G, odd G <= K),\n"
               "lmmse-K-riN-b2 (each LED's plane guided-filtered over N x N, odd N 3..31);\n"
               "NET+BASE (e.g. tn-160-nc+lmmse, the bundled demo model): NET trained as a "
               "residual on BASE\n(train --model NET --base RUN; info --model NET+BASE "
               "describes it)\n");
        if (!a.model) return 0;
    }
    lm_system sys;
    if ((r = load_system(&c, a.system, &sys))) return r;
    if (!a.model) {
        lm_system_describe(&sys, stdout);
        lm_system_free(&sys);
        return 0;
    }
    lm_err e = {0};
    lm_mosaic mo;
    lm_model *m = NULL;
    lm_profile p = {0};
    char net[64], base[64]; /* "NET+BASE": the residual as results tables name it */
    int res = lm_model_name_split(a.model, net, base, sizeof net);
    if (lm_mosaic_from_system(&sys, &mo, &e) == LM_OK)
        m = res ? lm_model_create_residual(net, base, &mo, 1, 0, 0.0f, &e)
                : lm_model_create(a.model, &mo, 1, &e);
    lm_system_free(&sys);
    if (m && lm_model_profile(m, (int)a.batch, (int)a.height, (int)a.width, &p, &e) == LM_OK)
        print_table(&p, a.model, &a);
    r = e.status ? (lm_cli_error(&c, "%s", e.msg), lm_cli_exit_status(e.status)) : 0;
    lm_profile_free(&p);
    lm_model_free(m);
    return r;
}
