/* eval_write.c — the result files of an evaluation run (eval_write.h).
 * What it is: eval.json, eval.csv and eval_motion.csv written with stdio (paths as absolute
 * paths, strings escaped), and the report's files through infer/report.h.
 * What it is not: the scoring (eval_run.c) or a JSON library's output (the layout is fixed
 * here, number formats included). */
#include "infer/eval_write.h"
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "infer/report.h"
#include "tensor/isa.h"

/* JSON string body: the characters that need escaping in paths. */
static void json_str(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '"' || *s == '\\') fprintf(f, "\\%c", *s);
        else if ((unsigned char)*s < 0x20) fprintf(f, "\\u%04x", (unsigned char)*s);
        else fputc(*s, f);
    }
    fputc('"', f);
}

static void json_metrics(FILE *f, const lm_eval_run_opts *o, const lm_metrics *m, const double *sec,
                         const char *ind)
{
    for (int n = 0; n < o->nnoise; n++)
        fprintf(f, "%s{\"noise_percent\": %g, \"psnr\": %.6f, \"ssim\": %.6f, \"mae\": %.8f, "
                   "\"sam\": %.6f, \"seconds_per_frame\": %.6f}%s\n", ind, 100.0 * o->k[n],
                m[n].psnr, m[n].ssim, m[n].mae, m[n].sam, sec[n], n + 1 < o->nnoise ? "," : "");
}

static void json_motion(FILE *f, const lm_eval_run_opts *o, const lm_eval_motion *m, const char *ind)
{
    for (int k = 0; k < lm_eval_motion_rows(o); k++)
        fprintf(f, "%s{\"noise_percent\": %g, \"speed_px_s\": %g, \"px_per_frame\": %.6f, "
                   "\"psnr_static\": %.6f, "
                   "\"psnr_aligned\": %.6f, \"psnr_unaligned\": %.6f, "
                   "\"ssim_aligned\": %.6f, \"ssim_unaligned\": %.6f, \"mae_aligned\": %.8f, "
                   "\"mae_unaligned\": %.8f, \"sam_aligned\": %.6f, \"sam_unaligned\": %.6f}%s\n",
                ind, 100.0 * m[k].noise, m[k].speed, m[k].px_per_frame, m[k].still.psnr,
                m[k].aligned.psnr,
                m[k].unaligned.psnr, m[k].aligned.ssim,
                m[k].unaligned.ssim, m[k].aligned.mae, m[k].unaligned.mae, m[k].aligned.sam,
                m[k].unaligned.sam, k + 1 < lm_eval_motion_rows(o) ? "," : "");
}

/* A path as an absolute one (the result file is read from anywhere), as given if it does not
 * resolve. */
static void json_path(FILE *f, const char *p)
{
    char *abs = realpath(p, NULL);
    json_str(f, abs ? abs : p);
    free(abs);
}

static void write_json(FILE *f, const lm_eval_run *r)
{
    const lm_eval_run_opts *o = r->o;
    char name[160];
    fprintf(f, "{\n  \"model\": ");
    json_path(f, o->auto_file ? o->auto_file : r->im.weights);
    fprintf(f, ",\n  \"preset\": ");
    json_str(f, o->auto_file ? "auto" : lm_model_name(r->im.model, name, sizeof name));
    if (o->auto_file) { /* the calibrated models and the choice per bin */
        fprintf(f, ",\n  \"auto_tol\": %.10g,\n  \"auto_models\": [", o->auto_tol);
        for (int m = 0; m < r->cal.nmodels; m++) {
            fprintf(f, "%s", m ? ", " : "");
            json_path(f, m ? r->more[m].weights : r->im.weights);
        }
        fprintf(f, "],\n  \"auto_choice\": [");
        for (int b = 0; b < r->cal.nbins; b++) fprintf(f, "%s%d", b ? ", " : "", r->choice[b]);
        fprintf(f, "]");
    }
    fprintf(f, ",\n  \"split\": \"%s\",\n  \"seed\": %lld,\n  \"noise_percent\": [",
            o->scenes ? "chosen" : lm_eval_split_name(o->split), o->seed);
    for (int n = 0; n < o->nnoise; n++) fprintf(f, "%s%g", n ? ", " : "", 100.0 * o->k[n]);
    fprintf(f, "],\n  \"photons\": %.10g,\n  \"read_noise\": %.10g", o->photons, o->read_noise);
    fprintf(f, ",\n  \"precision\": \"%s\"", o->precision == LM_PRECISION_BF16 ? "bf16" : "fp32");
    fprintf(f, ",\n  \"scenes\": [\n");
    for (int i = 0; i < r->nsc; i++) {
        fprintf(f, "    {\"name\": ");
        json_str(f, r->sc[i].name);
        fprintf(f, ", \"path\": ");
        json_path(f, r->sc[i].path);
        fprintf(f, ", \"height\": %d, \"width\": %d, \"results\": [\n", r->sc[i].height,
                r->sc[i].width);
        json_metrics(f, o, r->sc[i].m, r->sc[i].sec, "      ");
        fprintf(f, "    ]");
        if (o->nmotion) {
            fprintf(f, ", \"motion\": [\n");
            json_motion(f, o, r->sc[i].mo, "      ");
            fprintf(f, "    ]");
        }
        fprintf(f, "}%s\n", i + 1 < r->nsc ? "," : "");
    }
    fprintf(f, "  ],\n  \"mean\": [\n");
    json_metrics(f, o, r->mean, r->mean_sec, "    ");
    fprintf(f, "  ]");
    if (o->nmotion) {
        fprintf(f, ",\n  \"motion_speeds_px_s\": [");
        for (int k = 0; k < o->nmotion; k++) fprintf(f, "%s%g", k ? ", " : "", o->speed[k]);
        fprintf(f, "],\n  \"motion_noise_percent\": [");
        for (int k = 0; k < o->nmk; k++) fprintf(f, "%s%g", k ? ", " : "", 100.0 * o->mk[k]);
        fprintf(f, "],\n  \"motion_mean\": [\n");
        json_motion(f, o, r->mo_mean, "    ");
        fprintf(f, "  ]");
    }
    if (o->rainbow > 0)
        fprintf(f, ",\n  \"rainbow\": {\"size\": %d, \"height\": %d, \"width\": %d, "
                   "\"peak_error_mean_nm\": %.4f, \"peak_error_max_nm\": %.4f, \"worst_row\": %d, "
                   "\"psnr\": %.6f, \"ssim\": %.6f, \"mae\": %.8f, \"sam\": %.6f}",
                r->rb.size, r->rb.height, r->rb.width, r->rb.mean_err_nm, r->rb.max_err_nm,
                r->rb.worst_row, r->rb.m.psnr, r->rb.m.ssim, r->rb.m.mae, r->rb.m.sam);
    fprintf(f, "\n}\n");
}

static void write_csv(FILE *f, const lm_eval_run *r)
{
    fprintf(f, "scene,noise_percent,psnr,ssim,mae,sam\n");
    for (int i = 0; i <= r->nsc; i++) {
        const lm_metrics *m = i < r->nsc ? r->sc[i].m : r->mean;
        for (int n = 0; n < r->o->nnoise; n++)
            fprintf(f, "%s,%g,%.6f,%.6f,%.8f,%.6f\n", i < r->nsc ? r->sc[i].name : "mean",
                    100.0 * r->o->k[n], m[n].psnr, m[n].ssim, m[n].mae, m[n].sam);
    }
}

static void write_motion_csv(FILE *f, const lm_eval_run *r)
{
    fprintf(f, "scene,motion_px_s,px_per_frame,psnr_static,psnr_aligned,psnr_unaligned,"
               "ssim_aligned,ssim_unaligned,"
               "mae_aligned,mae_unaligned,sam_aligned,sam_unaligned,noise_percent\n");
    for (int i = 0; i <= r->nsc; i++) {
        const lm_eval_motion *m = i < r->nsc ? r->sc[i].mo : r->mo_mean;
        for (int k = 0; k < lm_eval_motion_rows(r->o); k++)
            fprintf(f, "%s,%g,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.8f,%.8f,%.6f,%.6f,%g\n",
                    i < r->nsc ? r->sc[i].name : "mean", m[k].speed, m[k].px_per_frame,
                    m[k].still.psnr, m[k].aligned.psnr,
                    m[k].unaligned.psnr, m[k].aligned.ssim, m[k].unaligned.ssim,
                    m[k].aligned.mae, m[k].unaligned.mae, m[k].aligned.sam, m[k].unaligned.sam,
                    100.0 * m[k].noise);
    }
}

/* The report's sample files and report.html into dir. */
static lm_status write_report(lm_eval_run *r, const char *dir, lm_err *e)
{
    lm_err me;
    lm_err_clear(&me);
    char page[1200];
    snprintf(page, sizeof page, "%s/report.html", dir);
    const lm_eval_scene_res *s = &r->sc[0];
    lm_status st = lm_report_eval_files(&r->ctx, &r->im, s->path, s->name, r->o->mat_key,
                                        r->o->seed, r->o->k[lm_eval_report_level(r->o)], &r->to,
                                        r->o->rainbow > 0 ? &r->rb : NULL, dir, &me);
    if (!st) st = lm_report_write(dir, page, NULL, NULL, &me);
    return st ? lm_err_set(e, st, "report: %s", me.msg) : LM_OK;
}

lm_status lm_eval_write(lm_eval_run *r, const char *dir, int report, lm_err *e)
{
    char path[1200];
    static const char *const names[3] = {"eval.json", "eval.csv", "eval_motion.csv"};
    for (int k = 0; k < (r->o->nmotion ? 3 : 2); k++) {
        snprintf(path, sizeof path, "%s/%s", dir, names[k]);
        FILE *f = fopen(path, "w");
        if (f) {
            if (k == 2) write_motion_csv(f, r);
            else if (k) write_csv(f, r);
            else write_json(f, r);
        }
        if (!f || ferror(f) | fclose(f))
            return lm_err_set(e, LM_ERR_WRITE, "%s: cannot write: %s", path, strerror(errno));
    }
    return report ? write_report(r, dir, e) : LM_OK;
}
