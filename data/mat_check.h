/* mat_check.h — structural checks of a MATLAB .mat file before matio reads it (io_mat.c).
 * What it is: the file's kind from its 128-byte header; for v7.3, the HDF5 superblock at byte
 * 512 (signature, version, field sizes, and its end-of-file address within the file: a cut
 * file is "truncated"); for v5, every top-level variable's tag must lie within the file, and
 * the first variable named each key must be complete: its matrix header (flags, dimensions,
 * name) readable and, for a numeric variable, its real-part data at least dims x the stored
 * type's size, within the variable. A compressed (zlib) variable is inflated for this, never
 * beyond what its header declares.
 * What it is not: a reader (matio reads the values, in a child process: isolate.h), or a check
 * of the other variables' contents. */
#ifndef LM_MAT_CHECK_H
#define LM_MAT_CHECK_H
#include "tensor/status.h"

typedef enum lm_mat_kind {
    LM_MAT_UNKNOWN = 0, /* neither header (e.g. a v4 file): left to matio */
    LM_MAT_V5,
    LM_MAT_V73          /* HDF5 after a 512-byte MATLAB header */
} lm_mat_kind;

#define LM_MAT_CHECK_MAX_KEYS 32 /* keys beyond these are not checked */

/* Check path (keys: NULL-terminated variable names to check in a v5 file). Sets *kind and
 * *file_bytes. LM_OK, LM_ERR_IO (cannot open) or LM_ERR_FORMAT "<path>: truncated ..." /
 * "<path>: corrupt ...", one line. */
lm_status lm_mat_check(const char *path, const char *const *keys, lm_mat_kind *kind,
                       long long *file_bytes, lm_err *e);

#endif
