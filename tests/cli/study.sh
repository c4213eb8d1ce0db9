#!/usr/bin/env bash
# study.sh — end-to-end tests of `lumosaic study` on study/ci.json (linear + mcan-tiny, 100
# iterations each on balloons_crop100, noise 0 and 10 %; the five failure conditions on one
# scene; a narrowband sweep of linear at synthetic shares 0/33/66/100 %): the conditions'
# records (clean first levels equal the clean PSNR, the 3-dB points recomputed here from the
# levels, at least one crossing), the rainbow's per-row peaks (true peaks by formula, mean
# error consistent), the sweep's light records; results.json/csv/md exist, the table
# has a row per preset, the records have sane fields (parameters and multiply-adds larger for
# mcan-tiny, PSNR(0) >= PSNR(10) - 0.5 dB, rainbow), the held-out set is procedural (the scene
# is in the train split) and the output says so; the chart scripts, PNGs and SVGs exist and the
# Pareto files hold exactly the non-dominated points of speed.dat (recomputed here); running
# again skips both finished presets and leaves their weights alone; a preset without
# result.json is measured again from its checkpoint; without gnuplot on PATH the run stops with
# one line (exit 1) unless --no-charts; study/full.json passes --dry-run; bad configs and
# options: one line on stderr, exit 2, nothing written.
# usage: study.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
CI=$ROOT/study/ci.json
S=$T/s

# ---- the CI study --------------------------------------------------------------------------
"$LM" study --config "$CI" --output "$S" --threads 2 --quiet > "$T/out" 2> "$T/err"
check "study run: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/out"
for f in results.json results.csv results.md runs/linear/result.json runs/mcan-tiny/result.json \
         runs/linear/log.csv runs/mcan-tiny/model.safetensors; do
  check "$f written" [ -s "$S/$f" ]
done
check "says the held-out set is procedural" grep -q "test split of the data is empty" "$T/err"
check "table row linear" grep -qE '^\| linear \| [0-9]+ \|' "$S/results.md"
check "table row mcan-tiny" grep -qE '^\| mcan-tiny \| [0-9]+ \|' "$S/results.md"
check "results.md names the procedural set" grep -q "Held-out set: 2 procedural scenes" "$S/results.md"
check "csv: a row per preset and level" \
  [ "$(grep -cE '^(linear|mcan-tiny),(0|10),' "$S/results.csv")" -eq 4 ]
python3 - "$S/results.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
assert j["noise_percent"] == [0, 10], j["noise_percent"]
assert j["held_out"]["kind"] == "procedural" and len(j["held_out"]["scenes"]) == 2
runs = {r["preset"]: r for r in j["runs"]}
assert [r["preset"] for r in j["runs"]] == ["linear", "mcan-tiny"]
for r in runs.values():
    assert r["train"]["iterations"] == 100 and r["run"] == "runs/" + r["preset"], r["train"]
    assert r["params"] > 0 and r["macs_per_frame"] > 0 and r["seconds_per_frame"] > 0, r
    assert r["seconds_per_frame"] <= r["seconds_per_frame_median"] + 1e-12
    assert min(r["timing_runs"]) == r["seconds_per_frame"] and len(r["timing_runs"]) == 2
    assert r["macs_per_frame"] == r["macs_per_window"] * r["windows_per_frame"]
    lv = r["eval"]["levels"]
    assert [l["noise_percent"] for l in lv] == [0, 10] and r["eval"]["scenes"] == 2
    for l in lv:
        assert 5 < l["psnr"] < 100 and 0 < l["ssim"] <= 1 and 0 < l["sam"] < 90, l
    assert lv[0]["psnr"] >= lv[1]["psnr"] - 0.5, lv
    rb = r["rainbow"]
    assert rb["size"] == 96 and 0 <= rb["peak_error_mean_nm"] <= rb["peak_error_max_nm"] <= 300
assert runs["mcan-tiny"]["params"] > runs["linear"]["params"]
assert runs["mcan-tiny"]["macs_per_frame"] > runs["linear"]["macs_per_frame"]
PY
check "results.json fields" [ $? -eq 0 ]

# conditions, the 3-dB points (recomputed here from the levels), rainbow rows, narrowband sweep
python3 - "$S/results.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
want = [("photons", [1000, 100, 30]), ("saturation", [1, 2, 4, 16]), ("led_gain", [0, 5, 20]),
        ("dead_pixels", [0, 1, 5, 30]), ("motion", [0, 120, 480])]
def crossing(lv, p, clean):
    thr = clean - 3.0
    for i in range(len(p)):
        if not (p[i] > thr):
            if i == 0: return lv[0]
            return lv[i - 1] + (p[i - 1] - thr) / (p[i - 1] - p[i]) * (lv[i] - lv[i - 1])
    return None
crossed = 0
for r in j["runs"]:
    c = r["conditions"]
    assert c["scenes"] == 1 and c["drop_db"] == 3 and 5 < c["clean_psnr"] < 100, c
    assert [f["family"] for f in c["families"]] == [w[0] for w in want]
    for f, (name, lv) in zip(c["families"], want):
        assert f["applies"] and [l["level"] for l in f["levels"]] == lv, f
        ps = [l["psnr"] for l in f["levels"]]
        if name in ("saturation", "led_gain", "dead_pixels"):  # first level = the clean frame
            assert abs(ps[0] - c["clean_psnr"]) < 1e-9, (name, ps[0], c["clean_psnr"])
        if name == "motion":
            assert all(5 < l["psnr_unaligned"] < 100 for l in f["levels"])
            assert all(5 < l["psnr_static"] < 100 for l in f["levels"])
            assert [round(l["px_per_frame"], 6) for l in f["levels"]] == [0, 4, 16], f
            assert f["levels"][0]["psnr_static"] == f["levels"][0]["psnr_unaligned"], f
        x = crossing(lv, ps, c["clean_psnr"])
        if x is None:
            assert f["drop_3db"] is None and f["beyond_last_level"], f
        else:
            assert abs(f["drop_3db"] - x) < 1e-6 * max(1, abs(x)) and not f["beyond_last_level"], (f, x)
            crossed += 1
    sat = [l["psnr"] for l in c["families"][1]["levels"]]
    assert sat[-1] < sat[0] - 1, sat  # x16 exposure clips most of the frame
    rows = r["rainbow"]["rows_true_recovered_nm"]
    assert len(rows) == 96
    for y, (t, g) in enumerate(rows):
        assert abs(t - (400 + 300 * (95 - y) / 95)) < 1e-6 and 380 <= g <= 720, (y, t, g)
    err = sum(abs(g - t) for t, g in rows) / len(rows)
    assert abs(err - r["rainbow"]["peak_error_mean_nm"]) < 1e-3, (err, r["rainbow"])
assert crossed >= 1, "no 3-dB crossing exercised"
nb = j["narrowband_sweep"]
assert [n["synth_fraction"] for n in nb] == [0, 0.33, 0.66, 1], nb
for n, tag in zip(nb, ["000", "033", "066", "100"]):
    assert n["preset"] == "linear" and n["run"] == "runs/linear@synth" + tag, n
    assert n["train"]["iterations"] == 100 and 0 <= n["rainbow"]["peak_error_mean_nm"] <= 300
    assert "conditions" not in n and "seconds_per_frame" not in n  # light records
PY
check "conditions, 3-dB points, rainbow rows, narrowband sweep" [ $? -eq 0 ]
check "results.md: failure table" grep -qE '^\| linear \| [0-9.]+ \|( [>0-9.e+ ]+ \|){5}$' "$S/results.md"
check "results.md: narrowband table" grep -qE '^\| 66 % \| [0-9.]+ \|' "$S/results.md"
check "narrowband run trained" [ -s "$S/runs/linear@synth066/model.safetensors" ]

C=$S/charts
for c in accuracy_speed noise_psnr noise_ssim noise_sam train_loss train_val_psnr rainbow_peaks \
         motion narrowband failure_3db cond_photons cond_saturation cond_led_gain \
         cond_dead_pixels cond_motion; do
  check "chart $c.gp" [ -s "$C/$c.gp" ]
  check "chart $c.png is a PNG" bash -c "head -c 8 '$C/$c.png' | od -An -c | grep -q 'P   N   G'"
  check "chart $c.svg is an SVG" grep -q '<svg' "$C/$c.svg"
  check "results.md links $c" grep -qF "(charts/$c.png)" "$S/results.md"
done
python3 - "$C" <<'PY'
import sys
d = sys.argv[1]
pts = [l.split() for l in open(d + "/speed.dat")]
assert len(pts) == 2
for k in range(2):
    p = [(float(r[1]), float(r[2 + k])) for r in pts]
    front = sorted(a for a in p if not any(b != a and b[0] <= a[0] and b[1] >= a[1] for b in p))
    got = [tuple(map(float, l.split())) for l in open(d + "/pareto_%d.dat" % k)]
    assert all(abs(g[0] - f[0]) < 1e-6 * f[0] and abs(g[1] - f[1]) < 1e-5
               for g, f in zip(got, front)) and len(got) == len(front), (k, got, front)
PY
check "Pareto files hold the non-dominated points" [ $? -eq 0 ]

# ---- resume ------------------------------------------------------------------------------
cp "$S/runs/mcan-tiny/model.safetensors" "$T/mcan.st"
cp "$S/runs/linear/result.json" "$T/linear.json"
"$LM" study --config "$CI" --output "$S" --threads 2 --quiet > /dev/null 2> "$T/err2"
check "resume run: $(cat "$T/err2")" [ $? -eq 0 ]
check "resume skips linear" grep -q "linear: done before" "$T/err2"
check "resume skips mcan-tiny" grep -q "mcan-tiny: done before" "$T/err2"
check "resume skips the narrowband runs" [ "$(grep -c 'linear@synth[0-9]*: done before' "$T/err2")" -eq 4 ]
check_not "resume trains nothing" grep -q "training for" "$T/err2"
check "weights untouched" cmp -s "$T/mcan.st" "$S/runs/mcan-tiny/model.safetensors"
rm "$S/runs/linear/result.json"
"$LM" study --config "$CI" --output "$S" --threads 2 --quiet > /dev/null 2> "$T/err3"
check "re-measure run: $(cat "$T/err3")" [ $? -eq 0 ]
check "linear continues from its checkpoint" grep -q "linear: continuing to 100" "$T/err3"
check "mcan-tiny still skipped" grep -q "mcan-tiny: done before" "$T/err3"
python3 - "$T/linear.json" "$S/runs/linear/result.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:])
assert a["eval"] == b["eval"] and a["params"] == b["params"] and a["rainbow"] == b["rainbow"]
assert a["conditions"] == b["conditions"]
assert b["train"]["resumed"] and b["train"]["iterations"] == 100
PY
check "re-measured record: same metrics (deterministic)" [ $? -eq 0 ]

# ---- charts without gnuplot --------------------------------------------------------------
env PATH=/nonexistent "$LM" study --config "$CI" --output "$S" --no-charts --quiet > /dev/null 2> "$T/err4"
check "--no-charts works without gnuplot: $(cat "$T/err4")" [ $? -eq 0 ]
check_not "--no-charts: results.md without chart links" grep -q 'charts/' "$S/results.md"
expect_error "gnuplot missing" 1 "gnuplot not found" "$T/g1" -- env PATH=/nonexistent "$LM" study --config "$CI" --output "$T/g1"

# ---- configs and options -----------------------------------------------------------------
"$LM" study --config "$ROOT/study/full.json" --dry-run > "$T/plan" 2>&1
check "full.json parses: $(cat "$T/plan")" grep -q "presets: linear .*han-paper" "$T/plan"
bad() { # bad NAME PATTERN JSON
  printf '%s\n' "$3" > "$T/$1.json"
  expect_error "config $1" 2 "$2" "$T/o_$1" -- "$LM" study --config "$T/$1.json" --output "$T/o_$1" --no-charts
}
D='"data": ["'$CAVE'"]'
bad syntax "line" '{"version": 1,'
bad version "field 'version'" '{"version": 7, "presets": ["linear"], '"$D"'}'
bad unknown "unknown field 'bogus'" '{"version": 1, "presets": ["linear"], '"$D"', "bogus": 1}'
bad preset "'nonet' is not a model preset" '{"version": 1, "presets": ["nonet"], '"$D"'}'
bad nopresets "field 'presets'" '{"version": 1, '"$D"'}'
bad nodata "field 'data'" '{"version": 1, "presets": ["linear"]}'
bad noise "field 'noise[1]'" '{"version": 1, "presets": ["linear"], '"$D"', "noise": [0, 200]}'
bad trainmodel "field 'train.model'" '{"version": 1, "presets": ["linear"], '"$D"', "train": {"model": "han-tiny"}}'
bad trainfield "batch" '{"version": 1, "presets": ["linear"], '"$D"', "train": {"batch": 0}}'
bad condfam "conditions[0]" '{"version": 1, "presets": ["linear"], '"$D"', "conditions": [{"family": "fog"}]}'
bad condlevel "conditions[0].levels[1]" '{"version": 1, "presets": ["linear"], '"$D"', "conditions": [{"family": "saturation", "levels": [1, 0.5]}]}'
bad condtwice "family 'motion' twice" '{"version": 1, "presets": ["linear"], '"$D"', "conditions": [{"family": "motion"}, {"family": "motion"}]}'
bad nbfrac "narrowband_sweep.fractions[1]" '{"version": 1, "presets": ["linear"], '"$D"', "narrowband_sweep": {"preset": "linear", "fractions": [0, 2]}}'
bad nbpreset "narrowband_sweep" '{"version": 1, "presets": ["linear"], '"$D"', "narrowband_sweep": {"preset": "nonet", "fractions": [0]}}'
bad missingdata "nothing_here" '{"version": 1, "presets": ["linear"], "data": ["nothing_here"]}'
expect_error "missing config file" 2 "cannot open" "$T/o1" -- "$LM" study --config "$T/none.json" --output "$T/o1"
expect_error "missing --config" 2 "--config is required" "$T/o2" -- "$LM" study --output "$T/o2"
expect_error "unknown option" 2 "unknown option" "$T/o3" -- "$LM" study --config "$CI" --bogus --output "$T/o3"
expect_error "bad threads" 2 "--threads" "$T/o4" -- "$LM" study --config "$CI" --threads 0 --output "$T/o4"

finish
