/* cmd_convert.c — `lumosaic convert`: a trained model rewritten with another storage type
 * (infer/convert.h). What it is not: quantised inference; eval judges the result. */
#include <stdio.h>
#include <sys/stat.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "infer/convert.h"

static void help(void)
{
    printf("usage: lumosaic convert --output FILE [--dtype f16|f32] MODEL\n\n"
           "Rewrite a trained model with another storage type. f16 (IEEE half) halves the file\n"
           "for distribution: each weight is rounded to 11 significant bits when written and\n"
           "widened back exactly when read, so inference and training still compute in fp32.\n"
           "f32 writes the training format again. All metadata is kept (the system path follows\n"
           "the new folder). Prints how much rounding changed the weights; score the output\n"
           "with 'lumosaic eval' against the model it came from.\n\n"
           "  MODEL            a run folder (its model.safetensors) or a .safetensors file\n"
           "                   written by 'lumosaic train', 'average' or 'convert'\n"
           "  --output FILE    the model to write (.safetensors), atomically; not MODEL's own\n"
           "                   file (a run keeps its training checkpoint)\n"
           "  --dtype T        f16 (default) or f32; a weight beyond fp16's range (65504) or\n"
           "                   not finite is refused, and nothing is written\n"
           "  --help           this text\n");
}

int lm_cmd_convert(int argc, char **argv)
{
    lm_cli c;
    lm_cli_init(&c, "lumosaic convert", argc, argv);
    static const char *const dtypes[] = {"f32", "f16", NULL};
    const char *output = NULL, *model = NULL;
    int dt = LM_STORE_F16;
    while (!lm_cli_done(&c)) {
        if (lm_cli_is_help(&c)) {
            help();
            return 0;
        }
        int r = lm_cli_value(&c, "--output", &output);
        if (!r) r = lm_cli_choice(&c, "--dtype", dtypes, &dt);
        if (r < 0) return 2;
        if (r) continue;
        if (c.argv[c.i][0] == '-' && c.argv[c.i][1] == '-') return lm_cli_unknown(&c);
        if (model) return lm_cli_error(&c, "one model at a time (%s and %s given)", model,
                                       c.argv[c.i]);
        model = c.argv[c.i++];
    }
    if (!output) return lm_cli_error(&c, "--output is required (see 'lumosaic convert --help')");
    if (!lm_cli_has_ext(output, ".safetensors"))
        return lm_cli_error(&c, "%s: the output is a .safetensors file", output);
    if (!model) return lm_cli_error(&c, "give the model to convert");
    lm_err e;
    lm_err_clear(&e);
    lm_store_report rep;
    if (lm_model_convert(model, output, (lm_store_dtype)dt, &rep, &e) != LM_OK) {
        lm_cli_error(&c, "%s", e.msg);
        return lm_cli_exit_status(e.status);
    }
    struct stat s;
    double mb = stat(output, &s) == 0 ? (double)s.st_size / 1e6 : 0.0;
    printf("wrote %s (%s, %.1f MB)\n", output, dtypes[dt], mb);
    if (dt == LM_STORE_F16)
        printf("rounding: largest relative change of a tensor %.2e (%s); nonzero weights below "
               "fp16's normal range: %ld kept as subnormals, %ld rounded to 0\n",
               rep.max_rel, rep.worst[0] ? rep.worst : "none", rep.subnormal, rep.zeroed);
    return 0;
}
