/* test_safetensors_hostile.c — safetensors files with hostile headers: data offsets
 * that overflow 64-bit arithmetic (the two fuzzed files of ../shared/reliability and generated
 * variants: INT64_MIN/INT64_MAX ends, negative, reversed, non-integer, missing or extra offsets,
 * a header that is not an object, a header length past the file). Each must give LM_ERR_FORMAT
 * (LM_ERR_SHAPE for a shape that is not the model's) with a one-line message naming the file and a reason, through lm_params_load and
 * lm_safetensors_meta; the ASan/UBSan build checks that no signed overflow happens on the way. */
#define _GNU_SOURCE
#include "models/params.h"
#include "tests/check.h"
#include "tests/fixture.h"
#include "tests/shared_dir.h"
#include <stdint.h>
#include <stdlib.h>
#include <unistd.h>

/* The tensor of the fuzzed files: proj.weight 33 x 12 x 1 x 1 (1584 bytes). */
static void make_params(lm_params *p)
{
    lm_err e = {0};
    lm_params_init(p);
    CHECK(lm_params_add(p, "proj.weight", 4, (int[]){33, 12, 1, 1}, 1, &e) != NULL);
    CHECK(lm_params_finalize(p, &e) == LM_OK);
}

/* A safetensors file: header length, the header text (padded to 8 with spaces), data_bytes
 * zero bytes of data. `len_override` (if nonzero) replaces the stored header length. */
static void write_file(const char *path, const char *header, long data_bytes,
                       uint64_t len_override)
{
    FILE *f = fopen(path, "wb");
    CHECK(f != NULL);
    if (!f) return;
    size_t jl = strlen(header), padded = (jl + 7) / 8 * 8;
    uint64_t n = len_override ? len_override : padded;
    for (int i = 0; i < 8; i++) fputc((int)((n >> (8 * i)) & 0xff), f);
    fwrite(header, 1, jl, f);
    for (size_t i = jl; i < padded; i++) fputc(' ', f);
    for (long i = 0; i < data_bytes; i++) fputc(0, f);
    fclose(f);
}

/* Loading (and reading metadata from) `path` must fail cleanly: LM_ERR_FORMAT, one line that
 * names the file and gives a reason (text after "<path>: "). */
static void expect_clean_error(const char *path, const char *why)
{
    lm_params p;
    make_params(&p);
    lm_err e = {0};
    lm_status st = lm_params_load(&p, path, 0, &e);
    const char *after = strstr(e.msg, path);
    after = after ? after + strlen(path) : NULL;
    CHECK_MSG((st == LM_ERR_FORMAT || st == LM_ERR_SHAPE) && after && !strncmp(after, ": ", 2) && strlen(after) > 4 &&
              !strchr(e.msg, '\n') && e.msg[strlen(e.msg) - 1] != ' ',
              "%s: status %d, message '%s'", why, (int)st, e.msg);
    lm_params_free(&p);
    lm_err e2 = {0};
    char *v = lm_safetensors_meta(path, "preset", &e2);
    CHECK_MSG(v == NULL, "%s: metadata read from a hostile file", why);
    free(v);
    CHECK_MSG(!e2.status || (e2.msg[0] && e2.msg[strlen(e2.msg) - 1] != ' '),
              "%s: metadata error without a reason: '%s'", why, e2.msg);
}

static void test_shared_files(void)
{
    static const char *const names[] = {"safetensors-offset-overflow.safetensors",
                                        "safetensors-offset-sub.safetensors"};
    for (int i = 0; i < 2; i++) {
        char path[1200];
        snprintf(path, sizeof path, "%s/reliability/%s", shared_dir(), names[i]);
        if (access(path, R_OK) != 0) {
            fprintf(stderr, "missing fixture %s\n", path);
            CHECK(0);
            continue;
        }
        expect_clean_error(path, names[i]);
    }
}

static void test_generated_offsets(void)
{
    static const char *const offsets[] = {
        "[9223372036854774223, 9223372036854775807]", /* data_start + b overflows */
        "[-9223372036854775808, 1584]",               /* b - a overflows */
        "[0, -9223372036854775808]",
        "[-9223372036854775808, 9223372036854775807]",
        "[9223372036854775807, -9223372036854775808]",
        "[-1584, 0]",
        "[1584, 0]",
        "[0, 1585]",                                   /* past the end of the data */
        "[9223372036854775807, 9223372036854775807]",
        "[0.0, 1584.0]",
        "[\"0\", \"1584\"]",
        "[0]",
        "[0, 1584, 3168]",
        "{\"a\": 0}",
        "null",
    };
    char path[1024], header[512];
    for (size_t i = 0; i < sizeof offsets / sizeof *offsets; i++) {
        snprintf(header, sizeof header, "{\"proj.weight\":{\"dtype\":\"F32\",\"shape\":[33,12,1,1],"
                 "\"data_offsets\":%s}}", offsets[i]);
        tpath(path, "gen.safetensors");
        write_file(path, header, 1584, 0);
        expect_clean_error(path, offsets[i]);
    }
}

static void test_generated_headers(void)
{
    char path[1024];
    static const char *const headers[] = {
        "[1, 2, 3]",       /* valid JSON, not an object: the reason must not be empty */
        "\"text\"",
        "{\"proj.weight\": 5}",
        "{\"proj.weight\":{\"dtype\":\"F32\",\"shape\":[9223372036854775807,12,1,1],"
        "\"data_offsets\":[0,1584]}}",
        "{\"proj.weight\":{\"dtype\":\"F32\",\"shape\":[33,12,1,1],\"data_offsets\":[0,1584]},"
        "\"__metadata__\": 7, \"other\": {\"data_offsets\": [-9223372036854775808, 0]}}",
    };
    for (size_t i = 0; i < sizeof headers / sizeof *headers; i++) {
        tpath(path, "hdr.safetensors");
        write_file(path, headers[i], 1584, 0);
        expect_clean_error(path, headers[i]);
    }
    /* header lengths past the file, up to 2^64 - 1 */
    static const uint64_t lens[] = {UINT64_MAX, UINT64_MAX - 7, (uint64_t)INT64_MAX,
                                    (uint64_t)INT64_MAX + 1, 1u << 20};
    for (size_t i = 0; i < sizeof lens / sizeof *lens; i++) {
        tpath(path, "len.safetensors");
        write_file(path, "{}", 0, lens[i]);
        char why[64];
        snprintf(why, sizeof why, "header length %llu", (unsigned long long)lens[i]);
        expect_clean_error(path, why);
    }
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_st_hostile_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_shared_files);
    RUN(test_generated_offsets);
    RUN(test_generated_headers);
    fixture_cleanup();
    return check_summary();
}
