/* api_internal.h — what the two halves of the public C API (data/api.c: systems, cubes,
 * simulation, metrics; infer/api.c: models and reconstruction) share: the handles' contents
 * and the conversion of the library's errors into the API's.
 * What it is not: part of the public header (include/lumosaic.h). */
#ifndef LM_API_INTERNAL_H
#define LM_API_INTERNAL_H
#include "include/lumosaic.h"
#include "data/cube.h"
#include "data/system.h"

struct lm_api_system {
    lm_system sys;
};

struct lm_api_cube {
    lm_cube cube;
};

/* err <- e (status and message); returns the status. */
lm_api_status lm_api_from_err(const lm_err *e, lm_api_error *err);
/* err <- (s, printf-style message); returns s. */
lm_api_status lm_api_fail(lm_api_error *err, lm_api_status s, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* err <- ok; returns LM_API_OK. */
lm_api_status lm_api_ok(lm_api_error *err);

#endif
