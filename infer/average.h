/* average.h — the weight average of trained models of one preset: a checkpoint average along
 * one run, or a "model soup" of runs that forked from one ancestor (the same weights, trained
 * on with other data or schedules, stay in one basin, and their mean often scores above each).
 * What it is: every parameter the mean of the inputs' (in double, rounded once to float; an
 * element equal in every input, such as a frozen base, is kept bit for bit), written as one
 * .safetensors model that infer, eval and train --base read like a trained model.
 * What it is not: an ensemble of outputs (that costs one inference per model) or a check that
 * the average is any good: score it (lumosaic eval) against its inputs. */
#ifndef LM_AVERAGE_H
#define LM_AVERAGE_H
#include "tensor/tensor.h"

#define LM_AVERAGE_MAX 64 /* models in one average */

/* Average the models at paths[0..n-1] (2..LM_AVERAGE_MAX; run folders or .safetensors files
 * written by `lumosaic train`) into out_path (a .safetensors file, written atomically).
 * Refused (LM_ERR_ARG, naming both files) unless every input has the first's preset, base
 * preset, system description (hash), buckets and frames. The output keeps the first input's
 * system (its path rewritten relative to out_path's folder) and records the inputs
 * ("average_of": each file with its iteration) and the union of their training scenes (so
 * eval still flags them). Other errors: the loaders' (LM_ERR_IO, LM_ERR_FORMAT), LM_ERR_WRITE. */
lm_status lm_model_average(const char *const *paths, int n, const char *out_path, lm_err *err);

#endif
