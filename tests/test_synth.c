/* test_synth.c — synthetic spectra and scenes (data/synth.h): Gaussian peak position and FWHM at
 * 1 nm (exact), binning against a plain trapezoid reference written here, the peak bin, the
 * draw's ranges, textureless patches, the rainbow's row peaks (true and from the binned cube),
 * the ColorChecker palette against the CSV's values, and procedural scenes (determinism,
 * range, regions with sharp edges, ColorChecker reflectances actually used), plus errors. */
#include "tests/check.h"
#include "data/synth.h"
#include <stdlib.h>

/* Reference bin: trapezoid over the 1 nm samples of [c - 5, c + 5] (integer edges). */
static double ref_bin(const lm_synth_gauss *g, int centre)
{
    double acc = 0.0;
    for (int wl = centre - 5; wl < centre + 5; wl++)
        acc += 0.5 * (lm_synth_gauss_eval(g, wl) + lm_synth_gauss_eval(g, wl + 1));
    return acc;
}

static void test_gauss_peak_and_fwhm_exact(void)
{
    const int centres[4] = {400, 455, 573, 700};
    for (int f = 0; f < LM_SYNTH_NFWHM; f++)
        for (int k = 0; k < 4; k++) {
            lm_synth_gauss g = {1, {centres[k], 0}, lm_synth_fwhm_nm[f]};
            double s[501]; /* 300..800 nm */
            lm_synth_gauss_sample(&g, 300.0, 501, s);
            int arg = 0;
            for (int i = 1; i < 501; i++) arg = s[i] > s[arg] ? i : arg;
            CHECK(300 + arg == centres[k]);
            CHECK(s[arg] == 1.0);
            int c = centres[k] - 300, hw = lm_synth_fwhm_nm[f] / 2;
            CHECK_CLOSE(s[c - hw], 0.5, 1e-12, 0);  /* half maximum at c +- fwhm/2 */
            CHECK_CLOSE(s[c + hw], 0.5, 1e-12, 0);
            CHECK(s[c - hw + 1] > 0.5 && s[c + hw - 1] > 0.5);
            CHECK(s[c - hw - 1] < 0.5 && s[c + hw + 1] < 0.5);
        }
}

static void test_gauss_pair_values(void)
{
    for (int k = 0; k < LM_SYNTH_NSEP; k++) {
        int sep = lm_synth_sep_nm[k];
        lm_synth_gauss g = {2, {500, 500 + sep}, 10};
        double other = exp(-4.0 * log(2.0) * sep * sep / 100.0);
        CHECK_CLOSE(lm_synth_gauss_eval(&g, 500), 1.0 + other, 1e-12, 0);
        CHECK_CLOSE(lm_synth_gauss_eval(&g, 500 + sep), 1.0 + other, 1e-12, 0);
        CHECK(lm_synth_gauss_eval(&g, 500 + sep / 2.0) < 1.0); /* two resolved peaks */
    }
}

static void test_gauss_bins_reference(void)
{
    lm_synth_gauss gs[4] = {{1, {400, 0}, 10}, {1, {543, 0}, 30}, {2, {611, 651}, 20},
                            {1, {700, 0}, 50}};
    lm_err e;
    lm_err_clear(&e);
    for (int k = 0; k < 4; k++) {
        float out[31];
        double ref[31], mx = 0;
        CHECK_MSG(lm_synth_gauss_bins(&gs[k], out, &e) == LM_OK, "%s", e.msg);
        for (int b = 0; b < 31; b++) {
            ref[b] = ref_bin(&gs[k], 400 + 10 * b);
            mx = ref[b] > mx ? ref[b] : mx;
        }
        float rf[31], omax = 0;
        for (int b = 0; b < 31; b++) {
            rf[b] = (float)(ref[b] / mx);
            omax = out[b] > omax ? out[b] : omax;
        }
        CHECK_ARRAY_CLOSE(out, rf, 31, 1e-6, 1e-6);
        CHECK(omax == 1.0f);
    }
    /* the peak bin is the one holding the centre (centres away from bin edges) */
    for (int c = 400; c <= 700; c += 7) {
        if (c % 10 == 5) continue;
        for (int f = 0; f < LM_SYNTH_NFWHM; f++) {
            lm_synth_gauss g = {1, {c, 0}, lm_synth_fwhm_nm[f]};
            float out[31];
            CHECK(lm_synth_gauss_bins(&g, out, &e) == LM_OK);
            int arg = 0;
            for (int b = 1; b < 31; b++) arg = out[b] > out[arg] ? b : arg;
            CHECK_MSG(arg == (c - 395) / 10, "centre %d fwhm %d: peak bin %d", c,
                      lm_synth_fwhm_nm[f], arg);
        }
    }
}

static void test_gauss_draw_ranges(void)
{
    lm_rng r;
    lm_rng_seed(&r, 11);
    int nf[LM_SYNTH_NFWHM] = {0}, ns[LM_SYNTH_NSEP] = {0}, pairs = 0, lo = 0, hi = 0;
    const int N = 3000;
    for (int i = 0; i < N; i++) {
        lm_synth_gauss g;
        lm_synth_gauss_draw(&r, &g);
        CHECK(g.npeaks == 1 || g.npeaks == 2);
        for (int f = 0; f < LM_SYNTH_NFWHM; f++) nf[f] += g.fwhm == lm_synth_fwhm_nm[f];
        for (int p = 0; p < g.npeaks; p++) {
            CHECK(g.centre[p] >= 400 && g.centre[p] <= 700 && g.centre[p] == floor(g.centre[p]));
            lo += g.centre[p] == 400;
            hi += g.centre[p] == 700;
        }
        if (g.npeaks == 2) {
            pairs++;
            for (int s = 0; s < LM_SYNTH_NSEP; s++)
                ns[s] += g.centre[1] - g.centre[0] == lm_synth_sep_nm[s];
        }
    }
    CHECK(pairs > N * 0.45 && pairs < N * 0.55);
    int sf = 0, ss = 0;
    for (int f = 0; f < LM_SYNTH_NFWHM; f++) {
        CHECK(nf[f] > N / 5 * 0.8);
        sf += nf[f];
    }
    for (int s = 0; s < LM_SYNTH_NSEP; s++) {
        CHECK(ns[s] > pairs / 6 * 0.7);
        ss += ns[s];
    }
    CHECK(sf == N && ss == pairs);
    CHECK(lo > 0 && hi > 0); /* both ends reachable */
}

static void test_gauss_patch_uniform(void)
{
    lm_rng r, r2;
    lm_rng_seed(&r, 5);
    r2 = r;
    lm_cube c;
    lm_synth_gauss g, g2;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_synth_gauss_patch(&r, 6, 8, &c, &g, &e) == LM_OK);
    lm_synth_gauss_draw(&r2, &g2);
    CHECK(g.npeaks == g2.npeaks && g.centre[0] == g2.centre[0] && g.fwhm == g2.fwhm);
    float spec[31];
    CHECK(lm_synth_gauss_bins(&g, spec, &e) == LM_OK);
    CHECK(c.bands == 31 && c.height == 6 && c.width == 8 && c.wavelength[30] == 700.0f);
    int bad = 0;
    for (int b = 0; b < 31; b++)
        for (int i = 0; i < 48; i++) bad += lm_cube_band(&c, b)[i] != spec[b];
    CHECK(bad == 0);
    lm_cube_free(&c);
}

static void test_rainbow_rows(void)
{
    CHECK(lm_synth_rainbow_peak(0, 512) == 700.0);
    CHECK(lm_synth_rainbow_peak(511, 512) == 400.0);
    CHECK_CLOSE(lm_synth_rainbow_peak(100, 512) - lm_synth_rainbow_peak(101, 512), 0.587, 1e-3,
                0);
    lm_cube c;
    lm_err e;
    lm_err_clear(&e);
    const int H = 512, W = 4;
    CHECK_MSG(lm_synth_rainbow(H, W, &c, &e) == LM_OK, "%s", e.msg);
    if (!c.data) return;
    int bad_bin = 0, bad_centroid = 0, bad_row = 0;
    for (int y = 0; y < H; y++) {
        double peak = lm_synth_rainbow_peak(y, H), num = 0, den = 0;
        int arg = 0;
        for (int b = 0; b < 31; b++) {
            const float *row = lm_cube_band(&c, b) + (size_t)y * W;
            if (row[0] > lm_cube_band(&c, arg)[(size_t)y * W]) arg = b;
            for (int x = 1; x < W; x++) bad_row += row[x] != row[0];
            num += (400.0 + 10 * b) * row[0];
            den += row[0];
        }
        double frac = fmod(peak - 395.0, 10.0);
        if (frac > 0.6 && frac < 9.4) bad_bin += arg != (int)((peak - 395.0) / 10.0);
        if (peak > 440 && peak < 660) bad_centroid += fabs(num / den - peak) > 0.1;
    }
    CHECK_MSG(bad_bin == 0, "%d rows with the wrong peak bin", bad_bin);
    CHECK_MSG(bad_centroid == 0, "%d rows whose spectral centroid misses the peak", bad_centroid);
    CHECK(bad_row == 0);
    lm_cube_free(&c);
}

static void test_palette(void)
{
    lm_synth_palette p;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_synth_palette_load(&p, &e) == LM_OK, "%s", e.msg);
    CHECK(p.count == 24);
    /* values of the BabelColor CSV: dark skin, white 9.5, red at 400/550/700 nm */
    CHECK_CLOSE(p.refl[0][0], 0.061, 1e-6, 0);
    CHECK_CLOSE(p.refl[0][15], 0.084, 1e-6, 0);
    CHECK_CLOSE(p.refl[0][30], 0.182, 1e-6, 0);
    CHECK_CLOSE(p.refl[18][15], 0.914, 1e-6, 0);
    CHECK_CLOSE(p.refl[14][30], 0.724, 1e-6, 0);
}

/* cosine similarity of a pixel's spectrum with the closest palette patch */
static double best_match(const lm_synth_palette *p, const float *v)
{
    double best = 0;
    for (int k = 0; k < p->count; k++) {
        double ab = 0, aa = 0, bb = 0;
        for (int b = 0; b < 31; b++) {
            ab += v[b] * p->refl[k][b];
            aa += v[b] * v[b];
            bb += p->refl[k][b] * p->refl[k][b];
        }
        double c = ab / sqrt(aa * bb + 1e-30);
        best = c > best ? c : best;
    }
    return best;
}

static void test_scene_properties(void)
{
    lm_synth_palette pal;
    lm_err e;
    lm_err_clear(&e);
    if (lm_synth_palette_load(&pal, &e) != LM_OK) return;
    const int H = 48, W = 64;
    size_t plane = (size_t)H * W;
    int seeds_with_cc = 0, seeds_with_edges = 0, nseeds = 12;
    for (int s = 0; s < nseeds; s++) {
        lm_cube a, b;
        CHECK(lm_synth_scene(100 + s, H, W, &pal, &a, &e) == LM_OK);
        CHECK(lm_synth_scene(100 + s, H, W, &pal, &b, &e) == LM_OK);
        CHECK(memcmp(a.data, b.data, 31 * plane * sizeof(float)) == 0);
        lm_cube_free(&b);
        CHECK(lm_synth_scene(200 + s, H, W, &pal, &b, &e) == LM_OK);
        CHECK(memcmp(a.data, b.data, 31 * plane * sizeof(float)) != 0);
        lm_cube_free(&b);
        int out = 0, cc = 0, edges = 0;
        for (size_t i = 0; i < 31 * plane; i++) out += !(a.data[i] >= 0.0f && a.data[i] <= 1.0f);
        for (size_t i = 0; i < plane; i++) {
            float v[31];
            for (int k = 0; k < 31; k++) v[k] = a.data[k * plane + i];
            cc += best_match(&pal, v) > 0.99999;
            if (i % W + 1 < (size_t)W) /* spectral-shape jump to the right neighbour */
                edges += fabs(a.data[15 * plane + i] - a.data[15 * plane + i + 1]) > 0.1;
        }
        CHECK(out == 0);
        seeds_with_cc += cc > 20;
        seeds_with_edges += edges > 5;
        lm_cube_free(&a);
    }
    CHECK_MSG(seeds_with_cc >= 2, "%d seeds use ColorChecker reflectances", seeds_with_cc);
    CHECK_MSG(seeds_with_edges >= nseeds / 2, "%d seeds with edges", seeds_with_edges);
    /* without a palette no pixel is a ColorChecker patch */
    lm_cube a;
    int cc = 0;
    CHECK(lm_synth_scene(3, H, W, NULL, &a, &e) == LM_OK);
    for (size_t i = 0; i < plane; i++) {
        float v[31];
        for (int k = 0; k < 31; k++) v[k] = a.data[k * plane + i];
        cc += best_match(&pal, v) > 0.99999;
    }
    CHECK(cc == 0);
    lm_cube_free(&a);
}

/* Largest share of a pixel's light in one 10 nm band: a FWHM <= 40 nm Gaussian puts over a
 * fifth of it in its peak band, the procedural scenes' broad spectra (FWHM >= 60 nm, or
 * ColorChecker patches, over a base) far less. */
static double peak_share(const lm_cube *c, size_t i)
{
    const size_t plane = (size_t)c->height * c->width;
    double mx = 0.0, sum = 0.0;
    for (int k = 0; k < 31; k++) {
        const double v = c->data[k * plane + i];
        mx = v > mx ? v : mx, sum += v;
    }
    return sum > 1e-6 ? mx / sum : 0.0;
}

/* lm_synth_fine: deterministic, in [0, 1], the procedural scene of its seed where no detail
 * lies on top, and narrowband detail that the procedural scenes lack, at many hues. */
static void test_fine_detail(void)
{
    lm_synth_palette pal;
    lm_err e;
    lm_err_clear(&e);
    if (lm_synth_palette_load(&pal, &e) != LM_OK) return;
    const int H = 66, W = 64;
    const size_t plane = (size_t)H * W;
    int nseeds = 12, kept_ok = 0;
    double narrow_proc = 0.0;
    int narrow_fine = 0, hue_bins[31] = {0};
    for (int s = 0; s < nseeds; s++) {
        lm_cube a, b, p;
        CHECK(lm_synth_fine(300 + s, H, W, &pal, &a, &e) == LM_OK);
        CHECK(lm_synth_fine(300 + s, H, W, &pal, &b, &e) == LM_OK);
        CHECK(memcmp(a.data, b.data, 31 * plane * sizeof(float)) == 0);
        CHECK(lm_synth_scene(300 + s, H, W, &pal, &p, &e) == LM_OK);
        int out = 0, same = 0, narrow = 0;
        for (size_t i = 0; i < 31 * plane; i++) out += !(a.data[i] >= 0.0f && a.data[i] <= 1.0f);
        for (size_t i = 0; i < plane; i++) {
            int eq = 1;
            for (int k = 0; k < 31 && eq; k++) eq = a.data[k * plane + i] == p.data[k * plane + i];
            same += eq;
            narrow_proc = fmax(narrow_proc, peak_share(&p, i));
            if (peak_share(&a, i) > 0.25) {
                narrow++;
                int best = 0;
                for (int k = 1; k < 31; k++)
                    best = a.data[k * plane + i] > a.data[best * plane + i] ? k : best;
                hue_bins[best]++;
            }
        }
        CHECK(out == 0);
        kept_ok += same > 0 && same < (int)plane; /* detail on top of the procedural scene */
        narrow_fine += narrow > 10;
        lm_cube_free(&a), lm_cube_free(&b), lm_cube_free(&p);
    }
    int hues = 0;
    for (int k = 0; k < 31; k++) hues += hue_bins[k] > 0;
    printf("     %d of %d seeds with narrowband detail (peak bands at %d of 31 wavelengths); "
           "procedural scenes' largest peak share %.3f\n", narrow_fine, nseeds, hues,
           narrow_proc);
    CHECK_MSG(narrow_proc < 0.2, "a procedural scene is narrowband (%.3f)", narrow_proc);
    CHECK_MSG(narrow_fine == nseeds, "%d of %d seeds with narrowband detail", narrow_fine, nseeds);
    CHECK_MSG(kept_ok >= nseeds - 2, "%d of %d seeds keep the procedural scene under the detail",
              kept_ok, nseeds);
    CHECK_MSG(hues >= 20, "narrowband peaks at %d of 31 wavelengths", hues);
}

static void test_errors(void)
{
    lm_err e;
    lm_err_clear(&e);
    lm_synth_gauss g = {3, {500, 0}, 10};
    float out[31];
    CHECK(lm_synth_gauss_bins(&g, out, &e) == LM_ERR_ARG && strstr(e.msg, "synth"));
    lm_err_clear(&e);
    lm_synth_gauss far = {1, {1500, 0}, 10};
    CHECK(lm_synth_gauss_bins(&far, out, &e) == LM_ERR_NUMERIC);
    lm_cube c;
    lm_err_clear(&e);
    CHECK(lm_synth_rainbow(1, 5, &c, &e) == LM_ERR_ARG && strstr(e.msg, "rainbow"));
    lm_err_clear(&e);
    CHECK(lm_synth_scene(1, 0, 5, NULL, &c, &e) == LM_ERR_ARG && strstr(e.msg, "scene"));
}

int main(void)
{
    RUN(test_gauss_peak_and_fwhm_exact);
    RUN(test_gauss_pair_values);
    RUN(test_gauss_bins_reference);
    RUN(test_gauss_draw_ranges);
    RUN(test_gauss_patch_uniform);
    RUN(test_rainbow_rows);
    RUN(test_palette);
    RUN(test_scene_properties);
    RUN(test_fine_detail);
    RUN(test_errors);
    return check_summary();
}
