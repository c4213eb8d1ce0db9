/* status.c — text of the status codes. */
#include "tensor/status.h"

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
    }
    return "unknown status";
}
