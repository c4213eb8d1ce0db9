/* pipeline_internal.h — what pipeline.c and pipeline_frame.c share inside the frame pipeline.
 * What it is not: an interface for other modules (infer/pipeline.h is). */
#ifndef LM_PIPELINE_INTERNAL_H
#define LM_PIPELINE_INTERNAL_H

#include "infer/pipeline.h"

/* A note or warning to the run's callback (printf format). */
void lm_pipe_say(const lm_pipe *p, lm_pipe_note kind, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* e's message prefixed with "prefix: " (the status kept); returns the status. */
lm_status lm_pipe_restate(lm_err *e, const char *prefix);
/* Multi-frame models: the stacking buffers and checks. */
lm_status lm_pipe_mf_init(lm_pipe *p, lm_err *e);
/* Decide whether to align and allocate the buffers. */
lm_status lm_pipe_align_init(lm_pipe *p, lm_err *e);
void lm_pipe_align_free(lm_pipe_align *a);

#endif
