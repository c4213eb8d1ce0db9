/* fuzz_run_config.c — the training run configuration (train/config.c): the input is the JSON
 * text, merged over the defaults and then validated. A failure must be one line naming the
 * label "fuzz.json" (parse) or a field (validation). */
#include "tests/fuzz/fuzz_util.h"
#include "train/train.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size + 1);
    if (!text) abort();
    memcpy(text, data, size);
    text[size] = 0;
    lm_train_cfg cfg;
    lm_train_cfg_default(&cfg);
    lm_err e = {LM_OK, ""};
    lm_status s = lm_train_cfg_parse(&cfg, text, "fuzz.json", &e);
    fz_check(s, &e, "fuzz.json");
    if (s == LM_OK) {
        lm_err_clear(&e);
        fz_check(lm_train_cfg_validate(&cfg, &e), &e, NULL);
    }
    free(text);
    return 0;
}
