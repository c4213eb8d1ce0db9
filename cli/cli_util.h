/* cli_util.h — small helpers shared by the cli/cmd_*.c commands: option parsing and output
 * folders written atomically.
 * What it is: a cursor over argv that matches "--name value" and "--name=value", flags, and
 * integers / reals with range checks; every failure prints ONE line "<prog>: <problem>" to
 * stderr (prog is e.g. "lumosaic simulate") and the caller returns exit status 2. Plus
 * "<dir>.tmp.<pid>" staging folders that are renamed into place on success and removed on
 * failure, so a command never leaves half-written output.
 * What it is not: a general getopt (no short options, no option bundling), or library code
 * (nothing here is used by the library; it may print). */
#ifndef LM_CLI_UTIL_H
#define LM_CLI_UTIL_H
#include <stdatomic.h>
#include <stddef.h>

typedef struct lm_cli {
    const char *prog; /* prefix of error messages, e.g. "lumosaic simulate" */
    int argc;
    char **argv;
    int i;            /* index of the argument being parsed (starts at 1) */
} lm_cli;

void lm_cli_init(lm_cli *c, const char *prog, int argc, char **argv);
/* Nonzero once every argument is consumed. */
int lm_cli_done(const lm_cli *c);
/* Is the current argument "--help" or "-h"? (Does not advance.) */
int lm_cli_is_help(const lm_cli *c);

/* Each matcher looks at the current argument and returns 1 (matched and, for values, parsed:
 * the cursor advances), 0 (not this option: nothing changes) or -1 (matched but wrong: the
 * one-line error is printed). */
/* "--name value" or "--name=value"; a missing value is an error. */
int lm_cli_value(lm_cli *c, const char *name, const char **value);
/* "--name" alone ("--name=x" is an error). */
int lm_cli_flag(lm_cli *c, const char *name, int *flag);
/* A value that must be an integer in [lo, hi] / a finite real in [lo, hi]. */
int lm_cli_int(lm_cli *c, const char *name, long long lo, long long hi, long long *out);
int lm_cli_real(lm_cli *c, const char *name, double lo, double hi, double *out);
/* The options shared by the commands, spelt, bounded and applied the same way everywhere;
 * a command names those it takes (help texts stay with each command). */
typedef struct lm_cli_common {
    long long threads;  /* --threads T: 1..LM_MAX_THREADS; 0 = not given (all cores) */
    const char *device; /* --device D: the backend's name; NULL = not given (env LM_DEVICE,
                         * else cpu; lm_backend_open checks the name) */
    long long seed;     /* --seed S: 0..seed_max; the caller's default when not given */
    int quiet;          /* --quiet: no progress output */
    int precision;      /* --precision fp32|bf16: LM_PRECISION_* (tensor.h); fp32 when not given */
} lm_cli_common;
enum { LM_CLI_THREADS = 1u, LM_CLI_DEVICE = 2u, LM_CLI_SEED = 4u, LM_CLI_QUIET = 8u,
       LM_CLI_PRECISION = 16u };
/* The help line of --precision, the same for every command that takes it. */
#define LM_CLI_PRECISION_HELP                                                                  \
    "  --precision P    fp32 (default) | bf16: operands of the 3x3 convolutions' products\n" \
    "                   rounded to bf16, sums in fp32 (AMX tiles or AVX-512-BF16 where the\n" \
    "                   CPU has them)\n"
/* Match one of the common options in `which` (LM_CLI_* flags), --seed in [0, seed_max]:
 * returns as the matchers above (1, 0 or -1 with the error printed). */
int lm_cli_common_opt(lm_cli *c, unsigned which, long long seed_max, lm_cli_common *o);
/* Set for the process what the common options set: OpenMP's thread count when --threads was
 * given. */
void lm_cli_common_apply(const lm_cli_common *o);
/* A value that must be one of the NULL-terminated `choices`; *out = its index. */
int lm_cli_choice(lm_cli *c, const char *name, const char *const *choices, int *out);

/* Parse a whole string as a number: 0, or -1 (nothing printed). */
int lm_cli_parse_ll(const char *s, long long *out);
int lm_cli_parse_real(const char *s, double *out);

/* Exit statuses, the same for every command (docs/guide/troubleshooting.md). */
enum {
    LM_EXIT_OK = 0,
    LM_EXIT_FAILED = 1,  /* the work failed: cannot write an output (LM_ERR_WRITE), out of
                          * memory, a NaN loss, a device failure */
    LM_EXIT_USAGE = 2    /* bad usage or input: options, configs, unreadable or corrupt files */
};                       /* (and 128 + the signal's number when interrupted: 130, 143) */
/* The exit status of a library error: LM_EXIT_FAILED (cannot write, out of memory, device)
 * or LM_EXIT_USAGE (the rest; LM_ERR_NUMERIC is NaN in the input: a command whose own
 * computation went NaN, such as a training loss, says LM_EXIT_FAILED itself); 0 for LM_OK. */
int lm_cli_exit_status(int status);

/* Print "<prog>: <message>" as one line on stderr. Returns 2 (the bad-usage status). */
int lm_cli_error(const lm_cli *c, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* "<prog>: unknown option '<arg>' (see '<prog> --help')", returns 2. */
int lm_cli_unknown(const lm_cli *c);
/* The current argument as a positional one: appended to out[*n] (out sized for argc) and
 * consumed; an unknown "--option" is reported instead (lm_cli_unknown's status). Returns 0. */
int lm_cli_positional(lm_cli *c, const char **out, int *n);

/* "HxW", each an integer in [lo, hi] (checked before it becomes an int): 0, or -1 (nothing
 * printed). */
int lm_cli_parse_size(const char *s, long long lo, long long hi, int *h, int *w);

/* Case-insensitive: does path end with ext (".png")? */
int lm_cli_has_ext(const char *path, const char *ext);

/* Staging folder for an output folder `dir`: checks that dir does not exist or is an empty
 * folder, then creates "<dir>.tmp.<pid>" (written to tmp, n bytes). Returns 0, or the exit
 * status with a one-line error printed (2: dir is in use or the path too long; 1: the folder
 * cannot be created). */
int lm_cli_stage_dir(const lm_cli *c, const char *dir, char *tmp, size_t n);
/* Rename the staging folder onto dir (replacing an empty dir). 0, or -1 with an error printed
 * (the staging folder is then removed). */
int lm_cli_commit_dir(const lm_cli *c, const char *tmp, const char *dir);
/* Remove a folder and everything in it (staging folders after a failure). */
void lm_cli_remove_tree(const char *dir);

/* SIGINT / SIGTERM. Call once, before the command starts any work. Not graceful: a signal
 * removes the staging folder of lm_cli_stage_dir (if one is in use), prints one line
 * "<prog>: interrupted (SIGINT): partial output removed" and exits at once with 128 + the
 * signal's number (130, 143). Graceful (train): the first signal only sets the flag of
 * lm_cli_signal_flag (the command finishes its step, saves and exits 128 + the number
 * itself); a second one exits at once with 128 + its own number, after any hold is released
 * (lm_cli_signals_hold), naming both signals when they differ. Returns 0, or -1 (cannot
 * install). */
int lm_cli_signals_init(const lm_cli *c, int graceful);
/* Graceful commands: hold(1) ... hold(0) around writes that must not be cut short (a
 * checkpoint and its config); a signal that ends the program waits for the hold to be
 * released. Holds nest. */
void lm_cli_signals_hold(int on);
/* Child processes (on = 1: started, 0: waited for) that a signal ending the program is
 * forwarded to; it then waits for them before it exits (at most 64 at a time). */
void lm_cli_signals_track(long pid, int on);
/* Graceful commands: `note` writes what a stop at once leaves behind (e.g. "the checkpoint in
 * X is kept"), appended to the line "interrupted (SIGINT) again: stopped at once: <note>". */
void lm_cli_signals_note(void (*note)(char *buf, size_t n));
/* 0, or the number of the first signal received. */
const atomic_int *lm_cli_signal_flag(void);
/* "SIGINT", "SIGTERM" or "signal N" */
const char *lm_cli_signal_name(int sig);

#endif
