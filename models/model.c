/* model.c — presets by name and the common model life cycle. */
#include "models/model.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct preset {
    const char *name;
    const char *family;
    lm_han_cfg han;  /* han */
    int width;       /* mcan: feats; srnet: dim; rt: width */
} preset;

static const preset presets[] = {
    {"linear", "linear", {0, 0, 0, 0}, 0},
    {"han-tiny", "han", {2, 2, 16, 4}, 0},
    {"han-g3b2c32", "han", {3, 2, 32, 8}, 0},
    {"han-small", "han", {4, 6, 64, 16}, 0},
    {"han-paper", "han", {10, 18, 128, 16}, 0},
    {"mcan-tiny", "mcan", {0, 0, 0, 0}, 16},
    {"mcan", "mcan", {0, 0, 0, 0}, 64},
    {"srnet-tiny", "srnet", {0, 0, 0, 0}, 8},
    {"srnet", "srnet", {0, 0, 0, 0}, 32},
    {"mst-tiny", "mst", {0, 0, 0, 0}, 1},
    {"mst", "mst", {0, 0, 0, 0}, 3},
    {"mst-coded", "mst-coded", {0, 0, 0, 0}, 3},
    {"rt-8", "rt", {0, 0, 0, 0}, 8},
    {"rt-16", "rt", {0, 0, 0, 0}, 16},
};
#define NPRESETS (int)(sizeof presets / sizeof presets[0])

const char *const *lm_model_presets(void)
{
    static const char *names[NPRESETS + 1];
    for (int i = 0; i < NPRESETS; i++) names[i] = presets[i].name;
    names[NPRESETS] = NULL;
    return names;
}

static const preset *find_preset(const char *name)
{
    for (int i = 0; i < NPRESETS; i++)
        if (!strcmp(presets[i].name, name)) return &presets[i];
    return NULL;
}

lm_model *lm_model_create(const char *name, const lm_mosaic *mosaic, uint64_t seed, lm_err *err)
{
    const preset *ps = find_preset(name);
    if (!ps) {
        char list[512] = "";
        for (int i = 0; i < NPRESETS; i++) {
            strncat(list, presets[i].name, sizeof list - strlen(list) - 3);
            if (i + 1 < NPRESETS) strcat(list, ", ");
        }
        lm_err_set(err, LM_ERR_ARG, "unknown model '%s' (presets: %s)", name, list);
        return NULL;
    }
    lm_model *m = calloc(1, sizeof *m);
    if (!m) {
        lm_err_set(err, LM_ERR_NOMEM, "out of memory creating model %s", name);
        return NULL;
    }
    snprintf(m->preset, sizeof m->preset, "%s", name);
    lm_params_init(&m->params);
    if (mosaic) m->mosaic = *mosaic;
    else lm_mosaic_default(&m->mosaic);
    m->out_channels = LM_MODEL_OUT_CHANNELS;
    m->in_channels = 1;
    lm_status st = LM_ERR_ARG;
    if (!strcmp(ps->family, "han")) st = lm_han_build(m, ps->han, err);
    else if (!strcmp(ps->family, "mcan")) st = lm_mcan_build(m, ps->width, err);
    else if (!strcmp(ps->family, "srnet")) st = lm_srnet_build(m, ps->width, err);
    else if (!strcmp(ps->family, "linear")) st = lm_linear_build(m, err);
    else if (!strncmp(ps->family, "mst", 3)) st = lm_mst_build(m, ps->width, ps->family[3] != 0, err);
    else if (!strcmp(ps->family, "rt")) st = lm_rt_build(m, ps->width, err);
    if (st == LM_OK) st = lm_params_finalize(&m->params, err);
    if (st != LM_OK) {
        lm_model_free(m);
        return NULL;
    }
    lm_rng r;
    lm_rng_seed(&r, seed);
    m->init(m, &r);
    return m;
}

void lm_model_free(lm_model *m)
{
    if (!m) return;
    if (m->free_impl) m->free_impl(m);
    lm_params_free(&m->params);
    free(m);
}

lm_tensor *lm_model_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    if (!lm_check_inputs(c, m->preset, 1, raw)) return NULL;
    char sb[64];
    if (m->in_channels != 1) {
        if (raw->ndim == 4 && raw->shape[1] == m->in_channels) return m->forward(c, m, raw);
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x %d x H x W", m->preset,
                    lm_shape_str(raw, sb, sizeof sb), m->in_channels);
        return NULL;
    }
    if (raw->ndim != 4 || raw->shape[1] != 1 || raw->shape[2] % m->mosaic.ty ||
        raw->shape[3] % m->mosaic.tx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x 1 x H x W with H %% %d == 0 and "
                    "W %% %d == 0", m->preset, lm_shape_str(raw, sb, sizeof sb), m->mosaic.ty,
                    m->mosaic.tx);
        return NULL;
    }
    return m->forward(c, m, raw);
}
