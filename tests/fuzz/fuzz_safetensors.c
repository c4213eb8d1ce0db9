/* fuzz_safetensors.c — the safetensors reader (models/safetensors.c): the input is one
 * .safetensors file; its metadata values are read (as `lumosaic infer` reads a model's) and it
 * is loaded into the parameters of the `linear` preset (proj.weight 33 x 12 x 1 x 1,
 * proj.bias 33), with and without extra tensors allowed. A failure must be one line naming
 * the file. */
#include "tests/fuzz/fuzz_util.h"
#include "models/params.h"

static lm_params params;

/* The parameters of the `linear` preset, declared as models/linear.c does. */
static void make_params(void)
{
    lm_err e = {LM_OK, ""};
    lm_params_init(&params);
    int w[4] = {33, 12, 1, 1}, b[1] = {33};
    if (!lm_params_add(&params, "proj.weight", 4, w, 1, &e) ||
        !lm_params_add(&params, "proj.bias", 1, b, 1, &e) ||
        lm_params_finalize(&params, &e) != LM_OK) {
        fprintf(stderr, "fuzz_safetensors: %s\n", e.msg);
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!params.finalized) make_params();
    char p[512];
    fz_write(p, "in.safetensors", data, size);
    const char *keys[4] = {"preset", "system", "system_hash", "format"};
    for (int k = 0; k < 4; k++) {
        lm_err e = {LM_OK, ""};
        char *v = lm_safetensors_meta(p, keys[k], &e);
        if (!v) fz_check(e.status, &e, p);
        free(v);
    }
    for (int extra = 0; extra < 2; extra++) {
        lm_err e = {LM_OK, ""};
        fz_check(lm_params_load(&params, p, extra, &e), &e, p);
    }
    return 0;
}
