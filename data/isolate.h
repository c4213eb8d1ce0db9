/* isolate.h — run a library call that may fault on hostile input in a child process.
 * What it is: fork a child that runs fn(fd, arg) and writes its reply into a pipe, with a cap on
 * its address space and CPU time; the parent reads the reply and learns how the child ended.
 * A crash, a hang or a runaway allocation inside the library becomes an error of the caller
 * ("<what>: the reader crashed (signal 11)"), never the death of the program. Used for
 * libmatio/libhdf5 (io_mat.c), which fault on some corrupt files.
 * What it is not: a security sandbox (the child keeps the parent's privileges and files), or a
 * thread pool. The child runs only fn: no OpenMP, no atexit handlers (it ends with _exit). */
#ifndef LM_ISOLATE_H
#define LM_ISOLATE_H
#include <stddef.h>
#include <sys/types.h>
#include "tensor/status.h"

typedef struct lm_isolate_limits {
    size_t mem_bytes; /* address space the child may add to what it inherits */
    int cpu_seconds;  /* CPU time of the child (SIGXCPU, then SIGKILL) */
} lm_isolate_limits;

typedef struct lm_isolate {
    pid_t pid;
    int fd;        /* the read end of the reply pipe */
    long wall_ms;  /* the longest wait for each read of the reply */
    int timed_out; /* a read waited wall_ms: the child is killed by lm_isolate_finish */
} lm_isolate;

/* Child side: the function writes its whole reply with lm_isolate_write and returns. */
typedef void (*lm_isolate_fn)(int fd, void *arg);

/* Start the child. what names the input in messages. LM_ERR_IO if fork or pipe fails. */
lm_status lm_isolate_start(lm_isolate *c, lm_isolate_fn fn, void *arg,
                           const lm_isolate_limits *lim, const char *what, lm_err *e);

/* Parent side: read exactly n bytes of the reply. 0, or -1 if the reply ended early. */
int lm_isolate_read(lm_isolate *c, void *buf, size_t n);

/* Close the pipe and reap the child. LM_OK only if it exited with status 0; otherwise
 * LM_ERR_FORMAT "<what>: <doing> failed: the reader crashed (signal N) | ran out of its time
 * | exited with status N" (the child is killed first if it is still running). */
lm_status lm_isolate_finish(lm_isolate *c, const char *what, const char *doing, lm_err *e);

/* Child side: write all n bytes to fd. 0, or -1 (the parent went away). */
int lm_isolate_write(int fd, const void *buf, size_t n);

#endif
