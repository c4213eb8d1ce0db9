/* infer_out.h — the output side of `lumosaic infer`: the staging folder, the files of each
 * frame (cube_NNNN.exr, srgb_NNNN.png, saturated_NNNN.png), progress lines, the auto summary,
 * the frames of each MPI rank.
 * What it is not: the frame pipeline itself (infer/pipeline.h) or option parsing (cmd_infer.c). */
#ifndef LM_CLI_INFER_OUT_H
#define LM_CLI_INFER_OUT_H

#include "cli/cli_util.h"
#include "data/srgb.h"
#include "infer/pipeline.h"

typedef struct lm_infer_out {
    const lm_cli *c;
    lm_pipe *p;
    const char *output;  /* the folder written, atomically */
    int sat_mask;        /* also write saturated_NNNN.png */
    double tol;          /* --auto-tol, for the summary */
    int said_model;      /* the model line is printed */
    lm_srgb srgb;
    float *rgb;
    char tmp[1100];      /* the staging folder */
    int first, end;      /* the frames this process reconstructs: [first, end) */
} lm_infer_out;

/* The pipeline's notes and warnings on stderr ("lumosaic infer: warning: ..." for warnings). */
void lm_infer_out_msg(void *user, lm_pipe_note kind, const char *line);
/* The preview's tables and buffer. 0 or an exit status (printed). */
int lm_infer_out_init(lm_infer_out *w, const lm_cli *c, lm_pipe *p, const char *output,
                      int sat_mask, double tol);
/* Stage the output, reconstruct and write this process's frames, rename the folder into
 * place (or remove it on failure). rc: the status so far (ranks agree on failures). Returns
 * the exit status. */
int lm_infer_out_run(lm_infer_out *w, int rc);
void lm_infer_out_free(lm_infer_out *w);

#endif
