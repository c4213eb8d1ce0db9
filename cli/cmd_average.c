/* cmd_average.c — `lumosaic average`: the weight average of trained models of one preset
 * (infer/average.h). What it is not: an output ensemble, or a judge of the result (eval is). */
#include <stdio.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "infer/average.h"

static void help(void)
{
    printf("usage: lumosaic average --output FILE MODEL MODEL [MODEL ...]\n\n"
           "Average the weights of trained models of one preset into one model: checkpoints of\n"
           "one run (its snapshots), or runs forked from one checkpoint and trained on\n"
           "differently (a \"model soup\"). Every parameter becomes the mean of the models'\n"
           "(elements equal in all of them, such as a frozen base, are kept exactly). The result\n"
           "costs one model's inference; score it with 'lumosaic eval' against the models it\n"
           "came from: models that did not start from one checkpoint rarely average well.\n\n"
           "  MODEL            a run folder (its model.safetensors) or a .safetensors file\n"
           "                   written by 'lumosaic train'; 2 to %d, all of one preset (and\n"
           "                   base), system description, buckets and frames\n"
           "  --output FILE    the model to write (.safetensors), atomically; it records the\n"
           "                   models averaged and the union of their training scenes\n"
           "  --help           this text\n",
           LM_AVERAGE_MAX);
}

int lm_cmd_average(int argc, char **argv)
{
    lm_cli c;
    lm_cli_init(&c, "lumosaic average", argc, argv);
    const char *output = NULL, *models[LM_AVERAGE_MAX + 1];
    int n = 0;
    while (!lm_cli_done(&c)) {
        if (lm_cli_is_help(&c)) {
            help();
            return 0;
        }
        int r = lm_cli_value(&c, "--output", &output);
        if (r < 0) return 2;
        if (r) continue;
        if (c.argv[c.i][0] == '-' && c.argv[c.i][1] == '-') return lm_cli_unknown(&c);
        if (n == LM_AVERAGE_MAX)
            return lm_cli_error(&c, "more than %d models", LM_AVERAGE_MAX);
        models[n++] = c.argv[c.i++];
    }
    if (!output) return lm_cli_error(&c, "--output is required (see 'lumosaic average --help')");
    if (!lm_cli_has_ext(output, ".safetensors"))
        return lm_cli_error(&c, "%s: the output is a .safetensors file", output);
    if (n < 2) return lm_cli_error(&c, "give at least two models to average (%d given)", n);
    lm_err e;
    lm_err_clear(&e);
    if (lm_model_average(models, n, output, &e) != LM_OK) {
        lm_cli_error(&c, "%s", e.msg);
        return lm_cli_exit_status(e.status);
    }
    printf("averaged %d models into %s\n", n, output);
    return 0;
}
