/* convert.h — a trained model rewritten with another storage type: F16 halves a model for
 * distribution (computation stays fp32; values are widened exactly when read), F32 restores
 * the training format. What it is: the model's weights (loaded and checked as infer loads them)
 * with every metadata pair of its file kept (the system path rebased to the output's folder).
 * What it is not: quantised inference, or a judge of the result: score the output with
 * `lumosaic eval` against the input (fp16 rounding changes a weight by at most 2^-11 of it). */
#ifndef LM_CONVERT_H
#define LM_CONVERT_H
#include "models/params.h"

/* in_path (a run folder or .safetensors file written by `lumosaic train`, `average` or this)
 * to out_path (.safetensors, written atomically) stored as dt; *rep (may be NULL) receives what
 * rounding changed. Errors: the model loader's (LM_ERR_IO, LM_ERR_FORMAT, ...), LM_ERR_ARG (a
 * value fp16 cannot hold, or out_path is the input file itself), LM_ERR_WRITE. */
lm_status lm_model_convert(const char *in_path, const char *out_path, lm_store_dtype dt,
                           lm_store_report *rep, lm_err *err);

#endif
