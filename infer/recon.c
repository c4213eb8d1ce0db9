/* recon.c — one coded frame to a 31-band cube with a loaded model (see recon.h).
 * What it is not: model loading, alignment or file output. */
#include "infer/recon.h"
#include <stdlib.h>
#include <string.h>
#include "infer/tile.h"
#include "infer/whole.h"

void lm_recon_default_opts(lm_recon_opts *o)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    o->batch = to.batch;
    o->tiles = 0;
}

int lm_recon_is_whole(const lm_model *m, const lm_recon_opts *o)
{
    return !o->tiles && lm_whole_halo(m) > 0;
}

lm_status lm_recon_check(const lm_model *m, int height, int width, lm_err *err)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    to = lm_tile_fitted(&to, height, width);
    return lm_tile_check(&to, height, width, m->mosaic.ty, m->mosaic.tx, err);
}

lm_status lm_recon_frame(lm_ctx *c, lm_model *m, const float *in, int height, int width,
                         const lm_recon_opts *o, lm_cube *cube, lm_err *err)
{
    lm_status st = lm_recon_check(m, height, width, err);
    if (st) return st;
    if (lm_recon_is_whole(m, o)) return lm_whole_infer(c, m, in, height, width, cube, err);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    to.batch = o->batch;
    return lm_tile_infer(c, m, in, height, width, &to, cube, err);
}

lm_status lm_recon_camera_frame(lm_ctx *c, const lm_infer_model *im, const float *in,
                                int height, int width, const lm_recon_opts *o, lm_cube *cube,
                                lm_err *err)
{
    lm_model *m = im->model;
    if (!im->remap.active) return lm_recon_frame(c, m, in, height, width, o, cube, err);
    memset(cube, 0, sizeof *cube);
    lm_status st = lm_recon_check(m, height, width, err);
    if (st) return st;
    float *mapped = malloc(sizeof(float) * m->in_channels * (size_t)height * width);
    if (!mapped) return lm_err_set(err, LM_ERR_NOMEM, "out of memory (%d x %d frame)", width,
                                   height);
    float given = m->noise_given;
    m->noise_given = lm_gain_remap_frame(&im->remap, in, m->in_channels, height, width, given,
                                         mapped);
    st = lm_recon_frame(c, m, mapped, height, width, o, cube, err);
    m->noise_given = given;
    free(mapped);
    return st;
}

void lm_recon_clamp(lm_cube *cube)
{
    size_t n = (size_t)cube->bands * cube->height * cube->width;
    for (size_t i = 0; i < n; i++)
        if (cube->data[i] < 0.0f) cube->data[i] = 0.0f;
}
