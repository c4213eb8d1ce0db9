/* params.h — a model's parameters: named tensors in one contiguous block, gradients in a
 * second block, so the optimizer is a flat loop and checkpoints are one write.
 * Two phases: declare every parameter (lm_params_add returns a stable lm_tensor* whose data is
 * set later), then lm_params_finalize allocates both blocks and zeroes them; initialise after.
 * What it is not: an optimizer (train/) or a file format (models/safetensors.c). */
#ifndef LM_PARAMS_H
#define LM_PARAMS_H
#include "tensor/tensor.h"

#define LM_PARAM_NAME_MAX 96

typedef struct lm_param {
    char name[LM_PARAM_NAME_MAX]; /* PyTorch-style dotted name, e.g. "body.0.body.1.weight" */
    lm_tensor t;                   /* flags LM_PARAM (| LM_REQUIRES_GRAD when trainable) */
    lm_tensor g;                   /* gradient view into the grad block */
    int trainable;
    size_t offset;                 /* in floats, into data/grad blocks */
} lm_param;

typedef struct lm_params {
    lm_param **items;
    int n, cap;
    size_t total;                  /* floats over all parameters */
    float *data, *grad;            /* contiguous blocks (after finalize) */
    size_t grad_mapped;            /* bytes when grad is an anonymous mapping (else 0): its
                                    * zero pages take no memory until a gradient is written, so
                                    * inference pays nothing for it */
    int finalized;
    /* While declaring: names get this prefix, and frozen makes every new parameter
     * non-trainable (a frozen base model declared into its residual's block). */
    char prefix[32];
    int frozen;
} lm_params;

void lm_params_init(lm_params *p);
void lm_params_free(lm_params *p);
/* Declare a parameter. Returns its tensor (data valid after finalize) or NULL with err set
 * (duplicate name, bad shape, already finalized, out of memory). */
lm_tensor *lm_params_add(lm_params *p, const char *name, int ndim, const int *shape,
                         int trainable, lm_err *err);
/* Allocate the blocks (zeroed) and point every tensor at its slice. */
lm_status lm_params_finalize(lm_params *p, lm_err *err);
lm_param *lm_params_find(const lm_params *p, const char *name);
long lm_params_count(const lm_params *p, int trainable_only);
void lm_params_zero_grad(lm_params *p);
/* Make every trainable parameter (not) require grad; e.g. off for inference. */
void lm_params_set_requires_grad(lm_params *p, int on);

/* Initialisers (after finalize). */
void lm_init_uniform(lm_tensor *t, lm_rng *r, float bound); /* U(-bound, bound) */
void lm_init_normal(lm_tensor *t, lm_rng *r, float std);
void lm_init_const(lm_tensor *t, float v);

/* safetensors (little-endian tensors after a JSON header), written atomically (temp file +
 * rename). Metadata: optional string pairs (key, value), n_meta pairs. Training writes F32
 * (lm_params_save); a model for distribution may be stored F16 (half the bytes; computation
 * stays fp32: values are widened when read). */
lm_status lm_params_save(const lm_params *p, const char *path, const char *const *meta,
                         int n_meta, lm_err *err);
typedef enum { LM_STORE_F32 = 0, LM_STORE_F16 = 1 } lm_store_dtype;
/* What storing changed (F16: IEEE half, round to nearest even): the largest relative change of
 * one tensor (L2 norm of the change over the tensor's), which tensor, and how many nonzero
 * values fell below fp16's normal range (2^-14: kept as subnormals, fewer bits, or as 0). */
typedef struct lm_store_report {
    double max_rel;
    char worst[LM_PARAM_NAME_MAX];
    long subnormal, zeroed;
} lm_store_report;
/* lm_params_save storing every tensor as dt; rep (may be NULL) receives what F16 rounding
 * changed. A value that is not finite, or beyond fp16's largest (65504), is refused for F16
 * (LM_ERR_ARG naming the tensor): nothing is written. */
lm_status lm_params_save_as(const lm_params *p, const char *path, const char *const *meta,
                            int n_meta, lm_store_dtype dt, lm_store_report *rep, lm_err *err);
/* Load every tensor of p by name from a safetensors file (dtype F32, or F16 / BF16 widened to
 * fp32 exactly); shapes must match; names in the file that p lacks are an error unless
 * allow_extra; names p has that the file lacks are an error. */
lm_status lm_params_load(lm_params *p, const char *path, int allow_extra, lm_err *err);
/* Read one metadata value (malloc'd, caller frees) or NULL if absent. */
char *lm_safetensors_meta(const char *path, const char *key, lm_err *err);
/* Every metadata pair of the file, in its order: *kv receives 2 * count malloc'd strings (key,
 * value, ...; free with lm_safetensors_meta_free). Returns the count (0: none), or -1 with err
 * set (the header loader's errors; LM_ERR_NOMEM). Non-string values are skipped. */
int lm_safetensors_meta_all(const char *path, char ***kv, lm_err *err);
void lm_safetensors_meta_free(char **kv, int count);

#endif
