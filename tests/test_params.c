/* test_params.c — parameter blocks and safetensors round trips / bad files. */
#include "models/params.h"
#include "tests/check.h"
#include <stdlib.h>
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

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_test_params_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_blocks_and_counts);
    RUN(test_safetensors_round_trip);
    RUN(test_safetensors_bad_files);
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}
