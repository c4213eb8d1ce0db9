/* eval_write.h — the result files of an evaluation run (infer/eval_run.h).
 * What it is: into a folder, eval.json (the model, split, seed, noise levels, sensor options,
 * per scene its size and metrics per level and motion row, the means, the rainbow test),
 * eval.csv (scene, noise level, PSNR, SSIM, MAE, SAM; the means as scene "mean") and, with
 * motion rows, eval_motion.csv; with a report, the sample files and report.html
 * (infer/report.h).
 * What it is not: the scoring (infer/eval_run.h) or the staging of the folder (the caller
 * hands an existing folder and moves it into place). */
#ifndef LM_EVAL_WRITE_H
#define LM_EVAL_WRITE_H
#include "infer/eval_run.h"

/* eval.json, eval.csv and (with motion rows) eval_motion.csv into dir; with report, also the
 * report's sample of the first scene at lm_eval_report_level and report.html. r: a run after
 * lm_eval_run_score (its context is used again for the report's reconstruction). Errors:
 * LM_ERR_WRITE ("<path>: cannot write: ..."), those of the report ("report: ..."). */
lm_status lm_eval_write(lm_eval_run *r, const char *dir, int report, lm_err *err);

#endif
