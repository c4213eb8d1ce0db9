/* status.h — status codes shared by every Lumosaic module.
 * What it is: the enum returned by fallible functions and its text.
 * What it is not: an error-reporting mechanism (see lm_ctx in tensor.h for the sticky
 * per-context error with a message). */
#ifndef LM_STATUS_H
#define LM_STATUS_H

typedef enum lm_status {
    LM_OK = 0,
    LM_ERR_SHAPE = -1,       /* incompatible or invalid shapes */
    LM_ERR_ARG = -2,         /* invalid argument value */
    LM_ERR_NOMEM = -3,       /* allocation failed */
    LM_ERR_IO = -4,          /* file could not be read or written */
    LM_ERR_FORMAT = -5,      /* file content is malformed */
    LM_ERR_BACKEND = -6,     /* compute backend failure (e.g. OpenCL) */
    LM_ERR_NUMERIC = -7,     /* NaN / inf where a finite value is required */
    LM_ERR_UNSUPPORTED = -8  /* valid request this build cannot serve */
} lm_status;

/* Short constant text for a status ("shape error", ...). Never NULL. */
const char *lm_status_str(lm_status s);

#endif
