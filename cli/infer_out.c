/* infer_out.c — the output side of `lumosaic infer` (cli/infer_out.h): every frame of the
 * pipeline written into a staging folder that is renamed into place at the end, so a failure
 * leaves nothing half-written; cubes clamped at 0 (reflectance is non-negative and the EXR
 * writer rejects negative values); a progress line per frame; under mpirun, rank r of N
 * reconstructs the block of frames [r n / N, (r + 1) n / N) into rank 0's staging folder.
 * What it is not: reading or reconstructing frames (infer/pipeline.h). */
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "cli/infer_out.h"
#include "data/cube_io.h"
#include "data/image.h"
#include "infer/recon.h"
#include "train/dist.h"

void lm_infer_out_msg(void *user, lm_pipe_note kind, const char *line)
{
    (void)user;
    if (kind == LM_PIPE_WARNING) fprintf(stderr, "lumosaic infer: warning: %s\n", line);
    else fprintf(stderr, "%s\n", line);
}

static int fail(const lm_infer_out *w, const lm_err *e, int runtime)
{
    lm_cli_error(w->c, "%s", e->msg);
    return runtime ? LM_EXIT_FAILED : lm_cli_exit_status(e->status);
}

int lm_infer_out_init(lm_infer_out *w, const lm_cli *c, lm_pipe *p, const char *output,
                      int sat_mask, double tol)
{
    memset(w, 0, sizeof *w);
    *w = (lm_infer_out){.c = c, .p = p, .output = output, .sat_mask = sat_mask, .tol = tol};
    float wl[31];
    for (int b = 0; b < 31; b++) wl[b] = 400.0f + 10.0f * b;
    lm_err e;
    lm_err_clear(&e);
    if (lm_srgb_init(&w->srgb, wl, 31, &e)) return fail(w, &e, 1);
    w->rgb = malloc(sizeof(float) * 3 * (size_t)p->src.height * p->src.width);
    if (!w->rgb)
        return lm_cli_error(c, "out of memory (%d x %d frame)", p->src.width, p->src.height), 1;
    return 0;
}

void lm_infer_out_free(lm_infer_out *w) { free(w->rgb); }

/* Frame i's saturated pixels as DIR/saturated_NNNN.png. */
static int write_mask(lm_infer_out *w, int i, int number, lm_err *e)
{
    lm_frame f;
    if (lm_pipe_saturation_mask(w->p, i, &f, e))
        return e->status == LM_ERR_NOMEM ? (lm_cli_error(w->c, "%s", e->msg), 1) : fail(w, e, 0);
    char path[1200];
    snprintf(path, sizeof path, "%s/saturated_%04d.png", w->tmp, number);
    lm_status st = lm_frame_write(path, f.height, f.width, f.data, e);
    lm_frame_free(&f);
    return st ? fail(w, e, 1) : 0;
}

/* Write frame i's cube (clamped to >= 0) and its sRGB preview into the staging folder. */
static int write_frame(lm_infer_out *w, lm_cube *cube, int i, lm_err *e)
{
    const int number = w->p->src.first_index + i;
    lm_recon_clamp(cube);
    char path[1200];
    snprintf(path, sizeof path, "%s/cube_%04d.exr", w->tmp, number);
    if (lm_cube_write_exr(path, cube, e)) return fail(w, e, 1);
    snprintf(path, sizeof path, "%s/srgb_%04d.png", w->tmp, number);
    if (lm_srgb_render(&w->srgb, cube, 1.0f, NULL, w->rgb, e) ||
        lm_image_write_rgb8(path, cube->width, cube->height, w->rgb, e))
        return fail(w, e, 1);
    return w->sat_mask ? write_mask(w, i, number, e) : 0;
}

/* The share of windows per model over the run and the calibration's expected PSNR. */
static void auto_summary(const lm_infer_out *w)
{
    lm_pipe_auto_summary s;
    lm_pipe_auto_summarize(w->p, &s);
    printf("auto (tol %g dB): %ld windows:", w->tol, s.total);
    for (int m = 0; m < s.nmodels; m++)
        printf(" %s %.1f%%", s.preset[m], s.total ? 100.0 * s.windows[m] / s.total : 0.0);
    printf("\ncalibration: expected PSNR %.2f dB with this choice, %.2f dB always %s\n",
           s.psnr_choice, s.psnr_best, s.preset[s.best]);
}

/* The progress line of frame i (after the model line, once, with the first frame done: an
 * error stays alone). */
static void progress(lm_infer_out *w, int i, const lm_pipe_info *in, double total, double wr)
{
    char line[1400];
    lm_pipe_model_line(w->p, line, sizeof line);
    if (line[0] && !w->said_model) fprintf(stderr, "%s\n", line);
    w->said_model = 1;
    char al[48] = "alignment off";
    if (in->aligned) snprintf(al, sizeof al, "alignment %.2f s", in->align_s);
    fprintf(stderr, "frame %d/%d %s: %.2f s (%s, reconstruction %.2f s, writing %.2f s); "
            "saturated %.3f %%\n", i + 1, lm_pipe_count(w->p), lm_pipe_frame_name(w->p, i),
            total, al, in->recon_s, wr, 100.0 * in->saturated);
}

static int run_frames(lm_infer_out *w)
{
    lm_err e;
    lm_err_clear(&e);
    for (int i = w->first; i < w->end; i++) {
        double t0 = omp_get_wtime();
        lm_cube cube;
        lm_pipe_info info;
        if (lm_pipe_frame(w->p, i, &cube, &info, &e)) return fail(w, &e, 0);
        double t1 = omp_get_wtime();
        int rc = write_frame(w, &cube, i, &e);
        lm_cube_free(&cube);
        if (rc) return rc;
        double t2 = omp_get_wtime();
        progress(w, i, &info, t2 - t0, t2 - t1);
    }
    if (w->p->is_auto) auto_summary(w);
    return 0;
}

/* Under mpirun: rank 0 stages the folder and renames it into place once every rank has
 * finished, or removes it when any failed. Returns the job's status (the worst rank's). */
static int run_ranks(lm_infer_out *w, int rc)
{
    int rank = lm_dist_rank(), n = lm_dist_size();
    long v[2] = {rc, (long)getpid()};
    if (rank == 0 && !rc) v[0] = rc = lm_cli_stage_dir(w->c, w->output, w->tmp, sizeof w->tmp);
    long any = rc; /* every rank opened its inputs, and rank 0 staged the output */
    lm_dist_max_long(&any, 1);
    lm_dist_bcast_long(v, 2);
    if (rank > 0) snprintf(w->tmp, sizeof w->tmp, "%s.tmp.%ld", w->output, v[1]);
    if (any) {
        if (rank == 0 && !rc) lm_cli_remove_tree(w->tmp);
        return rc ? rc : (int)any;
    }
    const int count = lm_pipe_count(w->p);
    w->first = (int)((long)count * rank / n);
    w->end = (int)((long)count * (rank + 1) / n);
    rc = run_frames(w);
    any = rc;
    lm_dist_max_long(&any, 1);
    if (rank > 0) return rc ? rc : (int)any;
    if (any) lm_cli_remove_tree(w->tmp);
    else if (lm_cli_commit_dir(w->c, w->tmp, w->output)) rc = 1;
    return rc ? rc : (int)any;
}

int lm_infer_out_run(lm_infer_out *w, int rc)
{
    if (lm_dist_size() > 1) return run_ranks(w, rc);
    if (rc) return rc;
    w->first = 0;
    w->end = lm_pipe_count(w->p);
    rc = lm_cli_stage_dir(w->c, w->output, w->tmp, sizeof w->tmp);
    if (rc) return rc;
    rc = run_frames(w);
    if (rc) lm_cli_remove_tree(w->tmp);
    else if (lm_cli_commit_dir(w->c, w->tmp, w->output)) rc = 1;
    return rc;
}
