/* io_mat_wire.h — what the .mat reader's parent (io_mat.c) and child (io_mat_child.c) share:
 * the job, the argument sent to the child, the reply's fixed part, the child's entry.
 * What it is not: a public API (cube_io.h is). */
#ifndef LM_IO_MAT_WIRE_H
#define LM_IO_MAT_WIRE_H
#include "data/isolate.h"
#include "data/mat_check.h"
#include <stdint.h>

#define KEY_LEN 64

typedef struct mat_job {
    const char *path;
    const char *key; /* the caller's, or NULL: the first of mat_keys */
    lm_mat_kind kind;
    long long file_bytes;
} mat_job;

/* The reply's fixed part; nbytes of raw values (class_type's C type, column-major) and nbands
 * doubles (the wavelength variable wl_key, if any) follow when status is LM_OK. */
typedef struct mat_reply {
    int32_t status, class_type, rank, nbands;
    uint64_t dims[3], nbytes;
    char key[KEY_LEN], wl_key[KEY_LEN];
    char msg[480];
} mat_reply;

/* What the parent sends: this, then the path and its NUL. */
typedef struct mat_wire {
    int32_t kind, has_key;
    long long file_bytes;
    char key[KEY_LEN];
} mat_wire;

/* A cube variable's shape (rank 3, each side and the total within data/limits.h); the child
 * checks the header, the parent the reply. LM_OK or LM_ERR_FORMAT naming path and key. */
lm_status lm_mat_check_shape(int rank, const uint64_t *dims, const char *path, const char *key,
                             lm_err *e);

/* The child's entry (data/isolate.h), served by io_mat_child.c and the helper lumosaic-reader. */
extern const lm_isolate_entry lm_mat_entry;

#endif
