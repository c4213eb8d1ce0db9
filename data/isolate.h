/* isolate.h — run a library call that may fault on hostile input in a child process.
 * What it is: start a child that runs an entry (a named function) on an argument and writes its
 * reply into a pipe, with a cap on its address space and CPU time; the parent reads the reply
 * and learns how the child ended. A crash, a hang or a runaway allocation inside the library
 * becomes an error of the caller ("<what>: the reader crashed (signal 11)"), never the death of
 * the program. Used for libmatio/libhdf5 (io_mat.c), which fault on some corrupt files.
 * How: fork, then exec of the entry's helper program (a small executable beside the running
 * one or beside the shared library liblumosaic.so, linked with only the libraries the entry
 * needs) or, without one, of the running program itself (/proc/self/exe), with the entry's
 * name, the argument and the pipe in the environment; a constructor of the entry's file
 * (LM_ISOLATE_ENTRY) finds them before main and runs the entry alone. The helper saves the
 * start of a program with every image library (~0.2 s). A fresh image matters: a child made by
 * fork alone keeps every lock another thread of the parent held at that instant (an
 * allocator's, a library's), and waits on it for ever. Only if exec fails (no /proc) does the
 * forked child run the entry itself.
 * What it is not: a security sandbox (the child keeps the parent's privileges and files), or a
 * thread pool. The child runs only the entry: no main, no OpenMP, no atexit handlers. */
#ifndef LM_ISOLATE_H
#define LM_ISOLATE_H
#include <stddef.h>
#include <sys/types.h>
#include "tensor/status.h"

typedef struct lm_isolate_limits {
    size_t mem_bytes; /* address space the child may add to what it has at its start */
    int cpu_seconds;  /* CPU time of the child (SIGXCPU, then SIGKILL) */
    int fork_only;    /* 1: skip the exec (tests of the fallback) */
} lm_isolate_limits;

/* Child side: the entry writes its whole reply with lm_isolate_write and returns. arg is a copy
 * of the parent's n bytes. */
typedef void (*lm_isolate_fn)(int fd, const void *arg, size_t n);

typedef struct lm_isolate_entry {
    const char *name;   /* unique among the programs' entries; a new argument format, a new name */
    const char *helper; /* file name of a program beside this one that serves it, or NULL */
    lm_isolate_fn run;
} lm_isolate_entry;

/* Defines entry `var` (name, helper, fn; external linkage) and the constructor that serves it in
 * a child. The program that starts children with it must link the file (it does when it names
 * var), and so must the helper. */
#define LM_ISOLATE_ENTRY(var, name, helper, fn)                                          \
    const lm_isolate_entry var = {name, helper, fn};                                     \
    __attribute__((constructor)) static void var##_serve(void) { lm_isolate_serve(&var); }

/* The arguments a child can be given: bytes. */
#define LM_ISOLATE_MAX_ARG 65536

typedef struct lm_isolate {
    pid_t pid;
    int fd;        /* the read end of the reply pipe */
    long wall_ms;  /* the longest wait for each read of the reply */
    int timed_out; /* a read waited wall_ms: the child is killed by lm_isolate_finish */
} lm_isolate;

/* Start the child on n bytes of arg. what names the input in messages. LM_ERR_IO if fork or
 * pipe fails, LM_ERR_ARG if n > LM_ISOLATE_MAX_ARG. */
lm_status lm_isolate_start(lm_isolate *c, const lm_isolate_entry *entry, const void *arg,
                           size_t n, const lm_isolate_limits *lim, const char *what, lm_err *e);

/* Parent side: read exactly n bytes of the reply. 0, or -1 if the reply ended early. */
int lm_isolate_read(lm_isolate *c, void *buf, size_t n);

/* Close the pipe and reap the child. LM_OK only if it exited with status 0; otherwise
 * LM_ERR_FORMAT "<what>: <doing> failed: the reader crashed (signal N) | ran out of its time
 * | exited with status N" (the child is killed first if it is still running). */
lm_status lm_isolate_finish(lm_isolate *c, const char *what, const char *doing, lm_err *e);

/* Child side: write all n bytes to fd. 0, or -1 (the parent went away). */
int lm_isolate_write(int fd, const void *buf, size_t n);

/* Before main (LM_ISOLATE_ENTRY): if this process is a child started for entry, run it and
 * _exit; otherwise return at once. */
void lm_isolate_serve(const lm_isolate_entry *entry);

#endif
