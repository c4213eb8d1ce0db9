/* util.h — small utilities shared by data/ and the layers above it, written once: the FNV-1a
 * hash (of strings, bytes and whole files), "is this a folder", mkdir -p, the one-line
 * error of a configuration file's field, and strict parsing of numbers and lists of them.
 * What it is not: file formats (cube_io.h) or dataset logic (dataset.h). */
#ifndef LM_DATA_UTIL_H
#define LM_DATA_UTIL_H
#include <stddef.h>
#include <stdarg.h>
#include <stdint.h>
#include "tensor/status.h"

/* FNV-1a, 64-bit: start from a basis, feed bytes with lm_fnv1a (chainable). Two bases are in
 * use and must stay as they are (the values are stored or seed the numbers):
 * LM_FNV1A_BASIS, the standard offset basis (the dataset split's group hash), and
 * LM_FNV1A_BASIS_SHORT, the standard one without its last digit, as the first copies wrote it
 * (lm_file_hash, whose value checkpoints record, and the per-scene seeds of eval and study). */
#define LM_FNV1A_BASIS 0xcbf29ce484222325ull
#define LM_FNV1A_BASIS_SHORT 1469598103934665603ull
uint64_t lm_fnv1a(uint64_t h, const void *bytes, size_t n);
/* lm_fnv1a of the bytes of a NUL-terminated string (not the NUL), from basis h. */
uint64_t lm_fnv1a_str(uint64_t h, const char *s);

/* 1 when path names an existing folder (following links), else 0. */
int lm_is_dir(const char *path);
/* mkdir -p path (mode 0777 less the umask): every missing folder of path, parents first.
 * Returns 0, or -1 with errno set and, when failed is non-NULL, the folder that could not be
 * made in failed[fn]. When top is non-NULL, top[tn] receives the first (outermost) folder this
 * call created ("" when all existed), for undoing it. */
int lm_make_dirs(const char *path, char *top, size_t tn, char *failed, size_t fn);

/* "<kind> <label>: <field>: <message>" into e (e.g. "doe file x.json: grid: too small"). */
lm_status lm_err_field(lm_err *e, lm_status s, const char *kind, const char *label,
                       const char *field, const char *fmt, ...)
    __attribute__((format(printf, 6, 7)));
lm_status lm_err_fieldv(lm_err *e, lm_status s, const char *kind, const char *label,
                        const char *field, const char *fmt, va_list ap);

/* Strict numbers, the one parser of every flag, config value and list: the whole text, in
 * decimal ([+-]digits[.digits][e[+-]digits], digits on at least one side of the point); no
 * spaces, hexadecimal, inf or nan. 0, or -1 (not such a number, or out of the type's range). */
int lm_parse_real(const char *s, double *v);
int lm_parse_int(const char *s, long long *v);
/* A comma-separated list of at most `max` such reals, each in [lo, hi]: every element present
 * ("0,,5", ",5" and "5," are refused). Returns the count (>= 1), or -1 with the problem in why
 * (n bytes), e.g. "element 2 is empty", "'0x5' is not a decimal number", "'120' is out of
 * range (0..100)", "more than 8 values". */
int lm_parse_list(const char *s, double lo, double hi, double *v, int max, char *why, size_t n);

/* `to` as a path relative to the folder `from_dir`, both resolved with realpath(3) first (so
 * links and "..": the real locations); e.g. from /a/b/run to /a/data/x: "../../data/x". 0, or
 * -1 when either does not resolve or out (n bytes) is too small (out is then unchanged). */
int lm_path_relative(const char *from_dir, const char *to, char *out, size_t n);

#endif
