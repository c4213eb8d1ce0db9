/* status.c — text of the status codes. */
#include "tensor/status.h"
#include <stdarg.h>
#include <stdio.h>
#include <sys/stat.h>

const char *lm_status_str(lm_status s)
{
    switch (s) {
    case LM_OK: return "ok";
    case LM_ERR_SHAPE: return "shape error";
    case LM_ERR_ARG: return "invalid argument";
    case LM_ERR_NOMEM: return "out of memory";
    case LM_ERR_IO: return "I/O error";
    case LM_ERR_FORMAT: return "format error";
    case LM_ERR_BACKEND: return "backend error";
    case LM_ERR_NUMERIC: return "numeric error";
    case LM_ERR_UNSUPPORTED: return "unsupported";
    case LM_ERR_WRITE: return "write error";
    case LM_ERR_INTERRUPTED: return "interrupted";
    }
    return "unknown status";
}

lm_status lm_err_set(lm_err *e, lm_status s, const char *fmt, ...)
{
    if (!e || e->status != LM_OK) return s;
    e->status = s;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->msg, sizeof e->msg, fmt, ap);
    va_end(ap);
    /* one line whatever the arguments hold: a library's message quoting a corrupt file's
     * names, or a path, may carry newlines or other control characters */
    for (char *p = e->msg; *p; p++)
        if ((unsigned char)*p < 0x20 || *p == 0x7f) *p = '?';
    return s;
}

lm_status lm_file_check(const char *path, const char *what, lm_err *e)
{
    struct stat st;
    if (!path || stat(path, &st) != 0 || S_ISREG(st.st_mode)) return LM_OK;
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a folder, expected %s", path,
                          what ? what : "a file");
    return lm_err_set(e, LM_ERR_IO, "%s: is %s, not a regular file", path,
                      S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISSOCK(st.st_mode) ? "a socket"
                      : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device" : "special");
}
