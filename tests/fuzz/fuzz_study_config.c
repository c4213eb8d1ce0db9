/* fuzz_study_config.c — the study configuration (study/config.c): the input is one JSON file,
 * loaded (with its training fields) and validated. A failure must be one line naming the
 * file. */
#include "tests/fuzz/fuzz_util.h"
#include "study/study.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[512];
    fz_write(p, "study.json", data, size);
    lm_study_cfg cfg;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_study_cfg_load(&cfg, p, &e);
    fz_check(s, &e, p);
    lm_study_cfg_free(&cfg);
    return 0;
}
