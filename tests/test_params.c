/* test_params.c — parameter blocks and safetensors round trips / bad files. */
#include "models/params.h"
#include "tests/check.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char tmpdir[256];

static void make_params(lm_params *p, int c)
{
    lm_err e = {0};
    lm_params_init(p);
    CHECK(lm_params_add(p, "head.weight", 4, (int[]){c, 12, 3, 3}, 1, &e) != NULL);
    CHECK(lm_params_add(p, "head.bias", 1, (int[]){c}, 1, &e) != NULL);
    CHECK(lm_params_add(p, "wb.weight", 4, (int[]){12, 1, 5, 7}, 0, &e) != NULL);
    CHECK(lm_params_finalize(p, &e) == LM_OK);
    CHECK(e.status == LM_OK);
}

static void test_blocks_and_counts(void)
{
    lm_params p;
    make_params(&p, 8);
    CHECK(lm_params_count(&p, 0) == 8 * 12 * 9 + 8 + 12 * 35);
    CHECK(lm_params_count(&p, 1) == 8 * 12 * 9 + 8);
    lm_param *w = lm_params_find(&p, "head.weight"), *wb = lm_params_find(&p, "wb.weight");
    CHECK(w && wb && w->t.grad == &w->g && wb->t.grad == NULL);
    CHECK(lm_requires_grad(&w->t) && !lm_requires_grad(&wb->t));
    CHECK(w->t.data >= p.data && w->t.data + lm_tensor_numel(&w->t) <= p.data + p.total);
    CHECK(((uintptr_t)lm_params_find(&p, "head.bias")->t.data % 64) == 0);
    lm_err e = {0};
    CHECK(lm_params_add(&p, "late", 1, (int[]){1}, 1, &e) == NULL && e.status == LM_ERR_ARG);
    lm_params_free(&p);
    lm_params_init(&p);
    lm_err_clear(&e);
    lm_params_add(&p, "a", 1, (int[]){2}, 1, &e);
    CHECK(lm_params_add(&p, "a", 1, (int[]){2}, 1, &e) == NULL && strstr(e.msg, "twice"));
    lm_params_free(&p);
}

static void test_safetensors_round_trip(void)
{
    lm_params a, b;
    make_params(&a, 8);
    make_params(&b, 8);
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (size_t i = 0; i < a.total; i++) a.data[i] = lm_rng_normal(&r);
    char path[300];
    snprintf(path, sizeof path, "%s/w.safetensors", tmpdir);
    lm_err e = {0};
    const char *meta[] = {"model", "han-tiny", "format", "lumosaic"};
    CHECK(lm_params_save(&a, path, meta, 2, &e) == LM_OK);
    CHECK(lm_params_load(&b, path, 0, &e) == LM_OK);
    for (int i = 0; i < a.n; i++)
        CHECK_ARRAY_CLOSE(b.items[i]->t.data, a.items[i]->t.data, lm_tensor_numel(&a.items[i]->t), 0, 0);
    char *m = lm_safetensors_meta(path, "model", &e);
    CHECK(m && !strcmp(m, "han-tiny"));
    free(m);
    /* header length is a multiple of 8 (alignment of the data section) */
    FILE *f = fopen(path, "rb");
    unsigned char l8[8];
    CHECK(fread(l8, 1, 8, f) == 8);
    fclose(f);
    CHECK(l8[0] % 8 == 0);
    lm_params_free(&a);
    lm_params_free(&b);
}

static void test_safetensors_bad_files(void)
{
    lm_params a, other;
    make_params(&a, 8);
    make_params(&other, 4); /* different head width */
    char path[300], bad[300];
    snprintf(path, sizeof path, "%s/a.safetensors", tmpdir);
    lm_err e = {0};
    CHECK(lm_params_save(&a, path, NULL, 0, &e) == LM_OK);
    CHECK(lm_params_load(&other, path, 0, &e) == LM_ERR_SHAPE && strstr(e.msg, "head.weight"));
    lm_err_clear(&e);
    CHECK(lm_params_load(&a, "/nonexistent/x.safetensors", 0, &e) == LM_ERR_IO);
    lm_err_clear(&e);
    /* truncated copy */
    snprintf(bad, sizeof bad, "%s/trunc.safetensors", tmpdir);
    FILE *in = fopen(path, "rb"), *out = fopen(bad, "wb");
    char buf[200];
    size_t n = fread(buf, 1, sizeof buf, in);
    fwrite(buf, 1, n, out);
    fclose(in);
    fclose(out);
    CHECK(lm_params_load(&a, bad, 0, &e) != LM_OK && strstr(e.msg, bad));
    lm_err_clear(&e);
    /* garbage */
    out = fopen(bad, "wb");
    fputs("this is not a safetensors file at all, just text", out);
    fclose(out);
    CHECK(lm_params_load(&a, bad, 0, &e) == LM_ERR_FORMAT);
    lm_err_clear(&e);
    /* a model with fewer tensors: extra names are an error unless allowed */
    lm_params small;
    lm_params_init(&small);
    lm_params_add(&small, "head.bias", 1, (int[]){8}, 1, &e);
    lm_params_finalize(&small, &e);
    CHECK(lm_params_load(&small, path, 0, &e) == LM_ERR_FORMAT && strstr(e.msg, "not part"));
    lm_err_clear(&e);
    CHECK(lm_params_load(&small, path, 1, &e) == LM_OK);
    /* failed save leaves nothing behind */
    char dirpath[300];
    snprintf(dirpath, sizeof dirpath, "%s/no_such_dir/x.safetensors", tmpdir);
    CHECK(lm_params_save(&a, dirpath, NULL, 0, &e) == LM_ERR_WRITE);
    lm_params_free(&a);
    lm_params_free(&other);
    lm_params_free(&small);
}

/* A one-tensor set of n values, for the storage-type tests. */
static void make_vec(lm_params *p, int n)
{
    lm_err e = {0};
    lm_params_init(p);
    CHECK(lm_params_add(p, "v", 1, (int[]){n}, 1, &e) != NULL);
    CHECK(lm_params_finalize(p, &e) == LM_OK);
}

/* F16 storage: values fp16 holds come back bit for bit (normals, subnormals, the largest, signed
 * zero), others round to nearest even; the report counts what fell below the normal range;
 * values fp16 cannot hold are refused with nothing written; BF16 files are read. */
static void test_safetensors_f16(void)
{
    const float in[] = {1.5f, -0.25f, 65504.0f, 0x1p-24f, 3 * 0x1p-20f, -0.0f, 0x1p-14f,
                        1 + 0x1p-11f, 1 + 3 * 0x1p-11f, 65519.0f, 0x1p-26f, 0.1f};
    const float want[] = {1.5f, -0.25f, 65504.0f, 0x1p-24f, 3 * 0x1p-20f, -0.0f, 0x1p-14f,
                          1.0f, 1 + 0x1p-9f, 65504.0f, 0.0f, 0.0999755859375f};
    const int n = (int)(sizeof in / sizeof in[0]);
    lm_params a, b;
    make_vec(&a, n);
    make_vec(&b, n);
    memcpy(a.data, in, sizeof in);
    char path[300], p32[300];
    snprintf(path, sizeof path, "%s/h.safetensors", tmpdir);
    snprintf(p32, sizeof p32, "%s/h32.safetensors", tmpdir);
    lm_err e = {0};
    lm_store_report rep;
    const char *meta[] = {"preset", "x"};
    CHECK(lm_params_save_as(&a, path, meta, 1, LM_STORE_F16, &rep, &e) == LM_OK);
    CHECK(lm_params_save(&a, p32, meta, 1, &e) == LM_OK);
    CHECK(lm_params_load(&b, path, 0, &e) == LM_OK);
    for (int i = 0; i < n; i++) {
        CHECK(memcmp(&b.data[i], &want[i], 4) == 0);
        if (memcmp(&b.data[i], &want[i], 4))
            printf("  value %d: %a, want %a\n", i, b.data[i], want[i]);
    }
    CHECK(rep.subnormal == 2 && rep.zeroed == 1 && !strcmp(rep.worst, "v"));
    CHECK(rep.max_rel > 0 && rep.max_rel < 1e-3);
    FILE *f = fopen(path, "rb"), *g = fopen(p32, "rb");
    CHECK(f && g && fseek(f, 0, SEEK_END) == 0 && fseek(g, 0, SEEK_END) == 0);
    long hsize = ftell(f), fsize = ftell(g); /* the data section is half as long */
    fclose(f), fclose(g);
    CHECK(fsize - hsize == 2 * n);
    char *m = lm_safetensors_meta(path, "preset", &e);
    CHECK(m && !strcmp(m, "x"));
    free(m);
    /* what F16 cannot hold: refused, nothing written */
    char refused[300];
    snprintf(refused, sizeof refused, "%s/r.safetensors", tmpdir);
    const float bad[] = {65520.0f, -1e9f, NAN, INFINITY};
    for (int k = 0; k < 4; k++) {
        memcpy(a.data, in, sizeof in);
        a.data[3] = bad[k];
        lm_err_clear(&e);
        CHECK(lm_params_save_as(&a, refused, NULL, 0, LM_STORE_F16, NULL, &e) == LM_ERR_ARG);
        CHECK(strstr(e.msg, "tensor v") && strstr(e.msg, "F32"));
        CHECK(access(refused, F_OK) != 0);
    }
    /* metadata pairs in order */
    char **kv = NULL;
    CHECK(lm_safetensors_meta_all(path, &kv, &e) == 1 && !strcmp(kv[0], "preset") &&
          !strcmp(kv[1], "x"));
    lm_safetensors_meta_free(kv, 1);
    /* BF16: the upper half of each float */
    char bpath[300];
    snprintf(bpath, sizeof bpath, "%s/b.safetensors", tmpdir);
    char hdr[65]; /* padded with spaces to 64 bytes */
    snprintf(hdr, sizeof hdr, "%-64s",
             "{\"v\":{\"dtype\":\"BF16\",\"shape\":[3],\"data_offsets\":[0,6]}}");
    unsigned char raw[8 + 64];
    size_t hl = strlen(hdr);
    memset(raw, 0, 8);
    raw[0] = (unsigned char)hl;
    memcpy(raw + 8, hdr, hl);
    const uint16_t bv[3] = {0x3fc0, 0xbe80, 0x4780}; /* 1.5, -0.25, 65536 */
    lm_params c;
    make_vec(&c, 3);
    f = fopen(bpath, "wb");
    CHECK(f && fwrite(raw, 1, 8 + hl, f) == 8 + hl && fwrite(bv, 2, 3, f) == 3);
    fclose(f);
    lm_err_clear(&e);
    CHECK(lm_params_load(&c, bpath, 0, &e) == LM_OK);
    CHECK(c.data[0] == 1.5f && c.data[1] == -0.25f && c.data[2] == 65536.0f);
    /* an F16 tensor whose offsets span F32's bytes: refused */
    char h2[65];
    snprintf(h2, sizeof h2, "%-64s",
             "{\"v\":{\"dtype\":\"F16\",\"shape\":[3],\"data_offsets\":[0,12]}}");
    hl = strlen(h2);
    raw[0] = (unsigned char)hl;
    memcpy(raw + 8, h2, hl);
    f = fopen(bpath, "wb");
    CHECK(f && fwrite(raw, 1, 8 + hl, f) == 8 + hl && fwrite(in, 4, 3, f) == 3);
    fclose(f);
    lm_err_clear(&e);
    CHECK(lm_params_load(&c, bpath, 0, &e) == LM_ERR_FORMAT && strstr(e.msg, "6 bytes as F16"));
    lm_params_free(&a);
    lm_params_free(&b);
    lm_params_free(&c);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_test_params_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_blocks_and_counts);
    RUN(test_safetensors_round_trip);
    RUN(test_safetensors_bad_files);
    RUN(test_safetensors_f16);
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}
