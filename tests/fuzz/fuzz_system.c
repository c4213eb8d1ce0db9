/* fuzz_system.c — the imaging-system description (data/system.c): the input is the JSON text;
 * CSV paths in it resolve against the bundled data/systems folder (so the real spectra can be
 * reached). A failure must be one line naming the label "fuzz.json". */
#include "tests/fuzz/fuzz_util.h"
#include "data/spectra.h"
#include "data/system.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static char base[1024];
    if (!base[0]) snprintf(base, sizeof base, "%s/systems", lm_data_dir());
    char *text = malloc(size + 1);
    if (!text) abort();
    memcpy(text, data, size);
    text[size] = 0;
    lm_system sys;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_system_parse(text, base, "fuzz.json", &sys, &e);
    fz_check(s, &e, "fuzz.json");
    lm_system_free(&sys);
    free(text);
    return 0;
}
