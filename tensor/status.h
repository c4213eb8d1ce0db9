/* status.h — status codes shared by every Lumosaic module.
 * What it is: the enum returned by fallible functions and its text.
 * What it is not: an error-reporting mechanism (see lm_ctx in tensor.h for the sticky
 * per-context error with a message). */
#ifndef LM_STATUS_H
#define LM_STATUS_H

#ifdef __cplusplus
extern "C" {
#endif

typedef enum lm_status {
    LM_OK = 0,
    LM_ERR_SHAPE = -1,       /* incompatible or invalid shapes */
    LM_ERR_ARG = -2,         /* invalid argument value */
    LM_ERR_NOMEM = -3,       /* allocation failed */
    LM_ERR_IO = -4,          /* file could not be read or written */
    LM_ERR_FORMAT = -5,      /* file content is malformed */
    LM_ERR_BACKEND = -6,     /* compute backend failure (e.g. OpenCL) */
    LM_ERR_NUMERIC = -7,     /* NaN / inf where a finite value is required */
    LM_ERR_UNSUPPORTED = -8, /* valid request this build cannot serve */
    LM_ERR_WRITE = -9,       /* an output could not be written (disk full, permissions, a
                              * missing folder): not bad input, unlike LM_ERR_IO on a read */
    LM_ERR_INTERRUPTED = -10 /* stopped on request (a signal's flag) after saving what it could;
                              * the message says what was kept */
} lm_status;

/* Short constant text for a status ("shape error", ...). Never NULL. */
const char *lm_status_str(lm_status s);

/* An error report for code that has no lm_ctx (file readers, configuration, CLI):
 * the first failure's status and a one-line message naming the file and the problem. */
typedef struct lm_err {
    lm_status status;
    char msg[512];
} lm_err;

/* Record the first error into e (e may be NULL). Returns s, so: return lm_err_set(e, ...).
 * The message is kept on one line: control characters (a newline in a quoted name) become '?'. */
lm_status lm_err_set(lm_err *e, lm_status s, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static inline void lm_err_clear(lm_err *e) { if (e) { e->status = LM_OK; e->msg[0] = 0; } }

/* Before a file input is opened: LM_OK when `path` is a regular file (or a link to one), or
 * does not exist (the opener reports that in its own words); else LM_ERR_IO, "<path>: is a
 * folder, expected <what>" or "<path>: is a FIFO (a device, a socket), not a regular file".
 * Only stat(2) is used: a FIFO or a device is refused without being opened, so never blocks. */
lm_status lm_file_check(const char *path, const char *what, lm_err *e);

#ifdef __cplusplus
}
#endif

#endif
