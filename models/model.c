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
    {"lmmse", "lmmse", {0, 0, 0, 0}, 0},
    {"lmmse-rf", "lmmse", {0, 0, 0, 0}, 256},
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

static void unknown_preset(const char *name, lm_err *err)
{
    char list[512] = "";
    for (int i = 0; i < NPRESETS; i++) {
        strncat(list, presets[i].name, sizeof list - strlen(list) - 3);
        if (i + 1 < NPRESETS) strcat(list, ", ");
    }
    lm_err_set(err, LM_ERR_ARG, "unknown model '%s' (presets: %s, lmmse-K, lmmse-K-rfD)", name, list);
}

/* "lmmse-K" or "lmmse-K-rfD": the lmmse window K (odd, 1..31), else 0; *D the random
 * features (0..4096). */
static int lmmse_k(const char *name, int *D)
{
    *D = 0;
    if (strncmp(name, "lmmse-", 6)) return 0;
    char *end;
    long k = strtol(name + 6, &end, 10), d = 0;
    if (end != name + 6 && !strncmp(end, "-rf", 3)) {
        char *e2;
        d = strtol(end + 3, &e2, 10);
        if (e2 == end + 3 || d < 1 || d > 4096) return 0;
        end = e2;
    }
    *D = (int)d;
    return *end || end == name + 6 || k < 1 || k > 31 || k % 2 == 0 ? 0 : (int)k;
}

int lm_model_preset_known(const char *name)
{
    int D;
    return find_preset(name) || lmmse_k(name, &D);
}

/* Declare the preset's parameters into m (not finalized, not initialised). */
static lm_status build(lm_model *m, const char *name, lm_err *err)
{
    const preset *ps = find_preset(name);
    int D = 0, K = lmmse_k(name, &D);
    if (!ps && !K) return unknown_preset(name, err), err->status;
    snprintf(m->preset, sizeof m->preset, "%s", name);
    m->out_channels = LM_MODEL_OUT_CHANNELS;
    m->in_channels = 1;
    m->conv_rows = -1;
    m->noise_sigma = -1.0f;
    m->noise_given = -1.0f;
    if (K) return lm_lmmse_build(m, K, D, err);
    if (!strcmp(ps->family, "han")) return lm_han_build(m, ps->han, err);
    if (!strcmp(ps->family, "mcan")) return lm_mcan_build(m, ps->width, err);
    if (!strcmp(ps->family, "srnet")) return lm_srnet_build(m, ps->width, err);
    if (!strcmp(ps->family, "linear")) return lm_linear_build(m, err);
    if (!strncmp(ps->family, "mst", 3)) return lm_mst_build(m, ps->width, ps->family[3] != 0, err);
    if (!strcmp(ps->family, "rt")) return lm_rt_build(m, ps->width, err);
    if (!strcmp(ps->family, "lmmse")) return lm_lmmse_build(m, 11, ps->width, err);
    return lm_err_set(err, LM_ERR_ARG, "model %s: unknown family %s", name, ps->family);
}

static lm_model *model_new(const lm_mosaic *mosaic, lm_err *err)
{
    lm_model *m = calloc(1, sizeof *m);
    if (!m) {
        lm_err_set(err, LM_ERR_NOMEM, "out of memory creating a model");
        return NULL;
    }
    lm_params_init(&m->params);
    if (mosaic) m->mosaic = *mosaic;
    else lm_mosaic_default(&m->mosaic);
    return m;
}

lm_model *lm_model_create(const char *name, const lm_mosaic *mosaic, uint64_t seed, lm_err *err)
{
    lm_model *m = model_new(mosaic, err);
    if (!m) return NULL;
    lm_status st = build(m, name, err);
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

lm_model *lm_model_create_residual(const char *preset, const char *base_preset,
                                   const lm_mosaic *mosaic, uint64_t seed, int train_base,
                                   float res_init, lm_err *err)
{
    lm_model *m = model_new(mosaic, err), *b = m ? model_new(mosaic, err) : NULL;
    if (!b) return lm_model_free(m), NULL;
    m->base = b;
    lm_status st = build(m, preset, err);
    if (st == LM_OK) { /* the base declares into m's block: "base.*", frozen unless trained */
        b->params = m->params;
        snprintf(b->params.prefix, sizeof b->params.prefix, "base.");
        b->params.frozen = !train_base;
        st = build(b, base_preset, err);
        m->params = b->params;
        m->params.prefix[0] = 0;
        m->params.frozen = 0;
        lm_params_init(&b->params);
    }
    if (st == LM_OK && (m->in_channels != 1 || b->in_channels != 1 ||
                        b->out_channels != m->out_channels))
        st = lm_err_set(err, LM_ERR_ARG, "residual %s on %s: both must map the raw mosaic to %d "
                        "channels", preset, base_preset, m->out_channels);
    int gs[1] = {m->out_channels};
    lm_tensor *g = st == LM_OK ? lm_params_add(&m->params, "res_scale", 1, gs, 1, err) : NULL;
    if (st == LM_OK && !g) st = err->status;
    if (st == LM_OK) st = lm_params_finalize(&m->params, err);
    if (st != LM_OK) return lm_model_free(m), NULL;
    lm_rng r;
    lm_rng_seed(&r, seed);
    m->init(m, &r);
    lm_rng_seed(&r, seed ^ 0x9E3779B97F4A7C15ull);
    b->init(b, &r);
    lm_init_const(g, res_init);
    for (int i = 0; i < m->n_out_layers; i++) { /* the net starts at 0: the model is its base */
        lm_init_const(m->out_layers[i]->w, 0.0f);
        if (m->out_layers[i]->b) lm_init_const(m->out_layers[i]->b, 0.0f);
    }
    m->conv_rows = m->conv_rows < 0 || b->conv_rows < 0 ? -1
                   : m->conv_rows > b->conv_rows ? m->conv_rows : b->conv_rows;
    m->noise_input |= b->noise_input;
    m->res_scale = g;
    return m;
}

void lm_model_free(lm_model *m)
{
    if (!m) return;
    lm_model_free(m->base);
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
    if (!m->base) return m->forward(c, m, raw);
    lm_model *b = m->base;
    b->noise_sigma = m->noise_sigma;
    b->noise_sigma_items = m->noise_sigma_items;
    lm_tensor *y = m->forward(c, m, raw);
    int gs[4] = {1, m->out_channels, 1, 1};
    y = lm_mul(c, y, lm_reshape(c, m->res_scale, 4, gs));
    return lm_add(c, y, b->forward(c, b, raw));
}
