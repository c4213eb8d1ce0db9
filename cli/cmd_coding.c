/* cmd_coding.c — `lumosaic coding`: learn the sub-frame allocation and the tile map of a system
 * through the closed-form linear reconstruction under shot and read noise (train/coding.h), and
 * score the paper's coding, the learned allocation and the learned map on the real validation
 * and test scenes. Writes OUT/allocation.json and OUT/tilemap.json (system files that simulate,
 * train and infer accept) and OUT/report.json. */
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/system.h"
#include "train/coding.h"
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define MAXDATA 64

static void help(void)
{
    printf("usage: lumosaic coding --data PATH [--data PATH ...] --output DIR [options]\n\n"
           "Learn the LED sub-frame allocation (fixed total) and the tile map of the imaging\n"
           "system for the closed-form linear reconstruction (the lmmse floor) under shot and\n"
           "read noise, and score the paper's coding against them on the real validation and\n"
           "test scenes (the dataset's 80/10/10 split). The LEDs' powers stay those the\n"
           "system's allocation implies (its equal-white gains): more sub-frames, more light.\n\n"
           "options:\n"
           "  --data PATH         scene folder or file (repeatable; needs >= 5 scenes)\n"
           "  --output DIR        output folder (must not exist, or be empty)\n"
           "  --system FILE       the starting system (default: the bundled prototype)\n"
           "  --photons P         photo-electrons at the starting system's white response\n"
           "                      (default 2000)\n"
           "  --read-noise E      read noise in electrons (default 13, a CMV12000-class sensor)\n"
           "  --window K          reconstruction window, odd 3..15 (default 11)\n"
           "  --adam-steps N      allocation: Adam steps on the softmax logits (default 300)\n"
           "  --anneal N          tile map: annealing swaps per round (default 1500; 0 = keep\n"
           "                      the map)\n"
           "  --rounds N          map-then-allocation rounds (default 2)\n"
           "  --seed S            annealing and noise draws (default 1)\n"
           "  --threads T         OpenMP threads\n"
           "  --quiet             no progress lines\n\n"
           "OUT/allocation.json: the learned allocation on the starting map; OUT/tilemap.json:\n"
           "the learned map and its allocation; OUT/report.json: per coding the sub-frames,\n"
           "the map, the proxy PSNR (stationary statistics of the training scenes) and the\n"
           "PSNR per validation/test scene. Simulate with `--poisson P x m` where m is the\n"
           "report's \"full_scale_factor\" (a system file's full scale is its brightest LED's\n"
           "white response).\n");
}

/* max_l n_l / n_l^paper: a written system's full scale over the starting one's */
static double full_scale_factor(const lm_coding *c, const double *paper, int L)
{
    double m = 0;
    for (int l = 0; l < L; l++) m = fmax(m, c->subframes[l] / paper[l]);
    return m;
}

typedef struct run {
    const char *name;
    lm_coding c;
    double proxy, val, test, fit;
    double *psnr;
} run;

static json_t *run_json(const run *r, const lm_system *sys, const lm_coding_data *d,
                        const double *paper)
{
    json_t *o = json_object(), *sub = json_object(), *map = json_array(), *sc = json_object();
    for (int l = 0; l < sys->nleds; l++)
        json_object_set_new(sub, sys->leds[l].name, json_integer(lround(r->c.subframes[l])));
    for (int y = 0; y < r->c.rows; y++) {
        json_t *row = json_array();
        for (int x = 0; x < r->c.cols; x++)
            json_array_append_new(row, json_string(sys->leds[r->c.tile_led[y * r->c.cols + x]].name));
        json_array_append_new(map, row);
    }
    for (int i = 0; i < d->nscenes; i++)
        if (!isnan(r->psnr[i])) json_object_set_new(sc, d->scenes[i].name, json_real(r->psnr[i]));
    json_object_set_new(o, "subframes", sub);
    json_object_set_new(o, "tile_map", map);
    json_object_set_new(o, "proxy_psnr", json_real(-10 * log10(r->proxy)));
    json_object_set_new(o, "fit_psnr", json_real(-10 * log10(r->fit)));
    json_object_set_new(o, "val_psnr", json_real(r->val));
    json_object_set_new(o, "test_psnr", json_real(r->test));
    json_object_set_new(o, "scene_psnr", sc);
    json_object_set_new(o, "full_scale_factor",
                        json_real(full_scale_factor(&r->c, paper, sys->nleds)));
    return o;
}

int lm_cmd_coding(int argc, char **argv)
{
    lm_cli c;
    lm_cli_init(&c, "lumosaic coding", argc, argv);
    const char *data[MAXDATA], *out = NULL, *sysf = NULL;
    int ndata = 0;
    double photons = 2000, read_noise = 13;
    long long K = 11, adam = 300, anneal = 1500, rounds = 2;
    lm_cli_common com = {.seed = 1};
    while (!lm_cli_done(&c)) {
        if (lm_cli_is_help(&c)) return help(), 0;
        const char *v = NULL;
        int r;
        if ((r = lm_cli_value(&c, "--data", &v)) == 1) {
            if (ndata == MAXDATA) return lm_cli_error(&c, "at most %d --data paths", MAXDATA);
            data[ndata++] = v;
            continue;
        }
        if (r < 0 || (r = lm_cli_value(&c, "--output", &out)) ||
            (r = lm_cli_value(&c, "--system", &sysf)) ||
            (r = lm_cli_real(&c, "--photons", 1e-3, 1e12, &photons)) ||
            (r = lm_cli_real(&c, "--read-noise", 0, 1e6, &read_noise)) ||
            (r = lm_cli_int(&c, "--window", 3, 15, &K)) ||
            (r = lm_cli_int(&c, "--adam-steps", 0, 100000, &adam)) ||
            (r = lm_cli_int(&c, "--anneal", 0, 10000000, &anneal)) ||
            (r = lm_cli_int(&c, "--rounds", 1, 100, &rounds)) ||
            (r = lm_cli_common_opt(&c, LM_CLI_THREADS | LM_CLI_SEED | LM_CLI_QUIET,
                                   (long long)1 << 53, &com))) {
            if (r < 0) return LM_EXIT_USAGE;
            continue;
        }
        return lm_cli_unknown(&c);
    }
    if (!ndata || !out) return lm_cli_error(&c, "--data and --output are required (see --help)");
    if (K % 2 == 0) return lm_cli_error(&c, "--window %lld must be odd", K);
    lm_cli_common_apply(&com);
    lm_system sys;
    lm_err e = {0};
    if (sysf ? lm_system_load(sysf, &sys, &e) : lm_system_default(&sys, &e))
        return lm_cli_error(&c, "%s", e.msg);
    char tmp[PATH_MAX];
    int rc = lm_cli_stage_dir(&c, out, tmp, sizeof tmp);
    if (rc) return lm_system_free(&sys), rc;
    if (lm_cli_signals_init(&c, 0)) {
        lm_cli_remove_tree(tmp);
        return lm_system_free(&sys), LM_EXIT_FAILED;
    }
    const int L = sys.nleds;
    double paper[LM_SYSTEM_MAX_LEDS];
    for (int l = 0; l < L; l++) paper[l] = sys.leds[l].subframes;
    lm_coding_noise nz = {photons, read_noise};
    lm_coding_search_opts so;
    lm_coding_search_default_opts(&so);
    so.adam_steps = (int)adam, so.anneal_steps = (int)anneal, so.rounds = (int)rounds;
    so.seed = (uint64_t)com.seed, so.verbose = !com.quiet;
    lm_coding_data d;
    lm_coding_stats st = {0};
    run runs[3] = {{.name = "paper"}, {.name = "learned_allocation"}, {.name = "learned_map"}};
    lm_status s = lm_coding_data_load(data, ndata, &sys, &d, &e);
    clock_t t0 = clock();
    if (!s) s = lm_coding_stats_compute(&d, (int)K, &st, &e);
    double t_stats = (double)(clock() - t0) / CLOCKS_PER_SEC;
    if (!s && !com.quiet)
        fprintf(stderr, "coding: %d scenes, statistics of %.0f training pixels (%.1f s CPU)\n",
                d.nscenes, st.pixels, t_stats);
    for (int k = 0; k < 3 && !s; k++) {
        lm_coding_from_system(&sys, &runs[k].c);
        runs[k].psnr = calloc((size_t)d.nscenes, sizeof(double));
        if (!runs[k].psnr) s = lm_err_set(&e, LM_ERR_NOMEM, "out of memory");
    }
    if (!s) s = lm_coding_optimise_allocation(&st, &runs[1].c, paper, &nz, &so, &e);
    if (!s) {
        runs[2].c = runs[1].c;
        if (anneal > 0) s = lm_coding_optimise_map(&st, &runs[2].c, paper, &nz, &so, &e);
    }
    for (int k = 0; k < 3 && !s; k++) {
        runs[k].proxy = lm_coding_objective(&st, &runs[k].c, paper, &nz, NULL);
        s = lm_coding_validate(&d, (int)K, &runs[k].c, paper, &nz, (uint64_t)com.seed,
                               runs[k].psnr, &runs[k].val, &runs[k].test, &runs[k].fit, &e);
    }
    char path[PATH_MAX + 64], note[1024];
    for (int k = 1; k < 3 && !s; k++) {
        snprintf(path, sizeof path, "%s/%s.json", tmp, k == 1 ? "allocation" : "tilemap");
        snprintf(note, sizeof note, "%s, learned by `lumosaic coding` (%s) for the lmmse floor "
                 "(window %lld) under shot noise (%g photo-electrons at the starting system's "
                 "white response) and %g e- read noise. Gains are the starting system's "
                 "equal-white gains (the LED powers its allocation implies), so an LED's light "
                 "scales with its sub-frames; this file's full scale is its brightest LED's "
                 "white response, %.4g x the starting system's.", sys.name,
                 k == 1 ? "allocation" : "allocation and tile map", K, photons, read_noise,
                 full_scale_factor(&runs[k].c, paper, L));
        char nm[64];
        snprintf(nm, sizeof nm, "learned %s", k == 1 ? "allocation" : "allocation + map");
        s = lm_coding_write_system(&sys, &runs[k].c, nm, note, path, &e);
    }
    if (!s) {
        json_t *rep = json_object(), *cod = json_object();
        json_object_set_new(rep, "system", json_string(sys.path));
        json_object_set_new(rep, "photons", json_real(photons));
        json_object_set_new(rep, "read_noise", json_real(read_noise));
        json_object_set_new(rep, "window", json_integer(K));
        json_object_set_new(rep, "seed", json_integer(com.seed));
        json_object_set_new(rep, "training_pixels", json_real(st.pixels));
        for (int k = 0; k < 3; k++)
            json_object_set_new(cod, runs[k].name, run_json(&runs[k], &sys, &d, paper));
        json_object_set_new(rep, "codings", cod);
        snprintf(path, sizeof path, "%s/report.json", tmp);
        if (json_dump_file(rep, path, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(8)))
            s = lm_err_set(&e, LM_ERR_WRITE, "%s: cannot write", path);
        json_decref(rep);
    }
    if (!s) {
        printf("%-20s %9s %9s %9s %9s  sub-frames (", "coding", "proxy dB", "fit dB", "val dB",
               "test dB");
        for (int l = 0; l < L; l++) printf("%s%s", l ? " " : "", sys.leds[l].name);
        printf(")\n");
        for (int k = 0; k < 3; k++) {
            printf("%-20s %9.3f %9.3f %9.3f %9.3f  ", runs[k].name, -10 * log10(runs[k].proxy),
                   -10 * log10(runs[k].fit), runs[k].val, runs[k].test);
            for (int l = 0; l < L; l++) printf("%s%ld", l ? " " : "", lround(runs[k].c.subframes[l]));
            printf("\n");
        }
        printf("test scenes:");
        for (int i = 0; i < d.nscenes; i++)
            if (d.scenes[i].split == 2) printf(" %s", d.scenes[i].name);
        printf("\n");
    }
    for (int k = 0; k < 3; k++) free(runs[k].psnr);
    lm_coding_stats_free(&st);
    if (d.scenes) lm_coding_data_free(&d);
    lm_system_free(&sys);
    if (s) {
        lm_cli_remove_tree(tmp);
        fprintf(stderr, "lumosaic coding: %s\n", e.msg);
        return lm_cli_exit_status(s);
    }
    if (lm_cli_commit_dir(&c, tmp, out)) return LM_EXIT_FAILED;
    return 0;
}
